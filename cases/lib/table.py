"""The results table of a study (rank 0 only): OUTDIR/results.jsonl then OUTDIR/results.csv get each row as one
write, flushed to the kernel at once (a killed runner loses nothing) and fdatasynced by a thread within milliseconds
(a machine crash: group commit, no case waits for the disk). Cells are quoted whenever they hold anything but plain
text (csv_line), so any character a result holds (line breaks, U+2028, NUL, quotes) reads back in its cell.
results.csv is the record: on a restart a torn last line (a crash inside a write) is dropped, JSON lines whose case
is not in results.csv are dropped and rows whose JSON line is missing run again; any other line that is not a row of
the study's table (not UTF-8 or CSV or JSON, the wrong number of cells, an unknown status or case, a case twice)
stops the run with one line naming the file and the line (:func:`check_table`), before any case runs. When every
case is in, both files are rewritten in case order (temporary file, fsync, atomic rename), so serial and MPI runs
give the same files (apart from the wall_s and rank columns). The runner is cases/lib/_batch.py; the report
(cases/lib/report.py) reads the table back through :func:`csv_records` and :func:`check_table`.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import threading
from pathlib import Path

from sgim.common import CliError
from sgim.readback import BadFile

FIXED_COLUMNS = ("case_id", "status", "error", "wall_s", "rank")

# A cell is quoted when it holds anything but plain text: the delimiter, the quote, any character that some
# reader takes for a line end (\r, \n, \v, \f, \x1c-\x1e, \x85, U+2028, U+2029), any other control character,
# or space at either end. Quoted cells keep every character; csv.reader reads them back whole.
_NEEDS_QUOTES = re.compile(r'[,"\x00-\x1f\x7f\x85\u2028\u2029]|^\s|\s$')


def _quote(cell):
    return '"' + cell.replace('"', '""') + '"' if _NEEDS_QUOTES.search(cell) else cell


def csv_line(cells):
    """One results.csv record (cells are str) ending in \\n; reads back cell for cell (csv.reader, newline="")."""
    return ",".join(_quote(c) for c in cells) + "\n"


def _cell(v):
    if v is None:
        return ""
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, dict)):
        return json.dumps(v)
    return str(v)


def _json_value(v):
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)  # JSON has no nan/inf
    return v


def _fsync_dir(path):
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


STATUSES = ("ok", "failed", "timeout")


def _text(path, data):
    """`data` (bytes of `path`) as UTF-8 text; BadFile naming the line of an undecodable byte."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise BadFile(path, f"line {line}: not UTF-8 text") from None


def csv_records(path, data):
    """[(line number, cells)] of the CSV text `data` (bytes read from `path`): a record whose quoted cell holds a
    line break counts from its first line. BadFile naming the line of text that is not UTF-8 or not CSV."""
    text = _text(path, data)
    reader = csv.reader(io.StringIO(text, newline=""))
    out, start = [], 1
    try:
        for cells in reader:
            out.append((start, cells))
            start = reader.line_num + 1
    except csv.Error as exc:
        raise BadFile(path, f"line {reader.line_num}: not a CSV line ({exc})") from None
    return out


def check_table(path, records, columns=None):
    """The records of a results table (results.csv), checked: a header starting with the fixed columns (equal to
    `columns` when given), every row with one cell per column, a case id, a status of ok / failed / timeout,
    wall_s a number or empty, rank an integer or empty, no case twice. BadFile naming the file and line."""
    if not records:
        return records
    no, header = records[0]
    if columns is not None and header != list(columns):
        raise CliError(f"{path}: the table's columns differ from this study's "
                       f"({', '.join(header[:8])}...): write to a new output folder")
    if tuple(header[:len(FIXED_COLUMNS)]) != FIXED_COLUMNS:
        raise BadFile(path, f"line {no}: not a results table (its columns start {', '.join(header[:5])!r}, "
                            f"expected {', '.join(FIXED_COLUMNS)})")
    seen = {}
    for no, cells in records[1:]:
        if len(cells) != len(header):
            raise BadFile(path, f"line {no}: {len(cells)} cells, expected {len(header)} (one per column)")
        cid, status, _, wall, rank = cells[:5]
        if not cid:
            raise BadFile(path, f"line {no}: case_id is empty")
        if cid in seen:
            raise BadFile(path, f"line {no}: case {cid} repeats line {seen[cid]}")
        seen[cid] = no
        if status not in STATUSES:
            raise BadFile(path, f"line {no}: status = {status!r}: must be one of {', '.join(STATUSES)}")
        try:
            if wall:
                float(wall)
            if rank:
                int(rank)
        except ValueError:
            raise BadFile(path, f"line {no}: wall_s = {wall!r}, rank = {rank!r}: must be numbers") from None
    return records


class _Syncer:
    """A thread that fdatasyncs the table's files after rows were written (group commit): the rows are in the
    kernel the moment they are written, on the disk a sync later, and no case waits for the disk."""

    def __init__(self, files):
        self.fds = [f.fileno() for f in files]
        self.event = threading.Event()
        self.stopping = False
        self.thread = threading.Thread(target=self._loop, name="table-sync", daemon=True)
        self.thread.start()

    def dirty(self):
        self.event.set()

    def _sync(self):
        for fd in self.fds:
            try:
                os.fdatasync(fd)
            except OSError:
                pass

    def _loop(self):
        while not self.stopping:
            self.event.wait()
            self.event.clear()
            self._sync()

    def stop(self):
        if self.thread is None:
            return
        self.stopping = True
        self.event.set()
        self.thread.join()
        self.thread = None
        self._sync()


class Table:
    """results.csv + results.jsonl, append-only, one fsynced write per row (see the module doc)."""

    def __init__(self, outdir, param_paths, result_names, case_ids=None):
        self.outdir = Path(outdir)
        self.case_ids = None if case_ids is None else set(case_ids)
        self.columns = list(FIXED_COLUMNS) + [f"p:{p}" for p in param_paths] + list(result_names)
        self.param_paths = list(param_paths)
        self.result_names = list(result_names)
        self.csv_path = self.outdir / "results.csv"
        self.jsonl_path = self.outdir / "results.jsonl"
        self.done = {}  # case_id -> status
        self._recover()
        self.fcsv = open(self.csv_path, "a", encoding="utf-8", newline="")
        self.fjson = open(self.jsonl_path, "a", encoding="utf-8")
        self._syncer = _Syncer([self.fjson, self.fcsv])
        if self.fcsv.tell() == 0:
            self._write(self.fcsv, self._line(self.columns))

    @staticmethod
    def _line(cells):
        return csv_line(cells)

    def _write(self, fh, text):
        fh.write(text)
        fh.flush()  # in the kernel: a killed runner loses nothing
        self._syncer.dirty()  # on the disk within milliseconds (a machine crash)

    @staticmethod
    def _complete_bytes(path):
        """The file's complete lines as bytes (a torn last line, the trace of a crash inside a write, is cut off
        the file)."""
        if not path.exists():
            return b""
        data = path.read_bytes()
        cut = data.rfind(b"\n") + 1
        if cut != len(data):
            with open(path, "r+b") as fh:
                fh.truncate(cut)
                fh.flush()
                os.fsync(fh.fileno())
        return data[:cut]

    def _records(self):
        """[(line number, cells)] of results.csv, checked (:func:`check_table`)."""
        return check_table(self.csv_path, csv_records(self.csv_path, self._complete_bytes(self.csv_path)),
                           self.columns)

    def _json_lines(self):
        """[(line number, case id, line)] of results.jsonl (every complete line a JSON object with a case_id)."""
        path = self.jsonl_path
        out = []
        text = _text(path, self._complete_bytes(path))
        lines = [ln + "\n" for ln in text.split("\n")[:-1]]  # only \n ends a line (JSON escapes the others)
        for no, line in enumerate(lines, 1):
            try:
                rec = json.loads(line)
            except ValueError:
                raise BadFile(path, f"line {no}: not a JSON line of the results table") from None
            cid = rec.get("case_id") if isinstance(rec, dict) else None
            if not isinstance(cid, str) or not cid:
                raise BadFile(path, f"line {no}: not a row of the results table (no case_id)")
            out.append((no, cid, line))
        return out

    def _recover(self):
        """Read the table back (a restart): every complete line must be a row of this study's table (BadFile naming
        the file and line otherwise); the finished cases go to ``done``. JSON lines whose case is not in
        results.csv (written just before a crash, or dropped by --retry-failed) are dropped."""
        records = self._records()
        self.done, self.line_of = {}, {}
        for no, cells in records[1:]:
            if self.case_ids is not None and cells[0] not in self.case_ids:
                raise BadFile(self.csv_path, f"line {no}: case {cells[0]} is not a case of this study")
            self.done[cells[0]] = cells[1]
            self.line_of[cells[0]] = no
        jl = self._json_lines()
        keep, seen = [], {}
        for no, cid, line in jl:
            if cid in seen:
                raise BadFile(self.jsonl_path, f"line {no}: case {cid} repeats line {seen[cid]}")
            seen[cid] = no
            if cid in self.done:
                keep.append(line)
        if len(keep) != len(jl):
            self._rewrite(self.jsonl_path, keep)
        lost = [cid for cid in self.done if cid not in seen]
        if lost:  # rows on the disk without their JSON line (a machine crash between the two): run them again
            self._rewrite(self.csv_path, [self._line(cells) for no, cells in records
                                          if no == records[0][0] or cells[0] not in lost])
            for cid in lost:
                del self.done[cid], self.line_of[cid]

    def _rewrite(self, path, lines):
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.writelines(lines)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(self.outdir)

    def drop(self, statuses):
        """Forget rows with these statuses (they run again)."""
        records = self._records()
        keep = [self._line(cells) for no, cells in records[:1]] + \
            [self._line(cells) for no, cells in records[1:] if cells[1] not in statuses]
        self._syncer.stop()
        self.fcsv.close()
        self.fjson.close()
        self._rewrite(self.csv_path, keep)
        self.done = {}
        self.__init__(self.outdir, self.param_paths, self.result_names, self.case_ids)

    def add(self, case, row):
        rec = {"case_id": case.case_id, "status": row["status"], "error": row.get("error", ""),
               "wall_s": row.get("wall_s"), "rank": row.get("rank")}
        for p in self.param_paths:
            rec[f"p:{p}"] = case.params.get(p)
        res = row.get("results", {})
        for r in self.result_names:
            rec[r] = res.get(r)
        self._write(self.fjson, json.dumps({k: _json_value(v) for k, v in rec.items()}) + "\n")
        self._write(self.fcsv, self._line([_cell(rec[c]) for c in self.columns]))
        self.done[case.case_id] = row["status"]

    def finish(self, order):
        """All cases in: rewrite both files in case order (atomic)."""
        self._syncer.stop()
        self.fcsv.close()
        self.fjson.close()
        rank = {cid: i for i, cid in enumerate(order)}
        records = self._records()
        rows = sorted(records[1:], key=lambda rec: rank.get(rec[1][0], len(rank)))
        self._rewrite(self.csv_path, [self._line(cells) for no, cells in records[:1] + rows])
        jl = self._json_lines()
        self._rewrite(self.jsonl_path, [ln for no, cid, ln in sorted(jl, key=lambda r: rank.get(r[1], len(rank)))])

    def close(self):
        self._syncer.stop()
        for fh in (self.fcsv, self.fjson):
            if not fh.closed:
                fh.close()
