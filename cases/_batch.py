"""The study runner: serial, or under mpirun with rank 0 handing out cases (dynamic load balancing).

Every case runs in a case process (a child of its rank, one per rank, reused from case to case) so that a
case past its time limit is killed with its process group while the rank carries on, and rank 0's main thread
stays free to hand out cases and write the table while its own case process computes: rank 0 runs cases too.

Messages (MPI, pickled): a rank sends ("ready",) and then ("done", index, row) or ("died", index, reason)
after each case; rank 0 answers ("case", index, attempt) or ("stop",). Waits poll (Iprobe + short sleeps, select
on the case process's pipe): Open MPI's blocking receive spins a core, which a study on few cores cannot spare.

Faults:
- a case that raises: status "failed", error = the exception's one line (traceback in the case's error.txt);
- a case past its time limit: its process group is killed, status "timeout";
- a case process that dies (killed, crashed interpreter): the case is handed out again, preferably to another
  rank; the second death is recorded as "failed" with the signal;
- a rank that dies: Open MPI ends the whole job (mpirun kills the other ranks; case processes die with their
  rank through PR_SET_PDEATHSIG). Started again, the study skips the cases in the table and runs the rest:
  in-flight cases of the killed job were never written, so none is lost and none is duplicated.
- mpirun killed (SIGKILL): its ranks run on; each notices within 0.5 s that its parent has gone, kills its case
  process and exits (rank 0 after closing the table), so a restart does not meet a run still writing.

The table (rank 0 only): OUTDIR/results.jsonl then OUTDIR/results.csv get each row as one write, flushed and
fsynced. results.csv is the record: on a restart a torn last line (a crash inside a write) is dropped, and
JSON lines whose case is not in results.csv are dropped; any other line that is not a row of the study's table
(not UTF-8 or CSV or JSON, the wrong number of cells, an unknown status or case, a case twice) stops the run with
one line naming the file and the line (:func:`check_table`), before any case runs. When every case is in, both files are rewritten in
case order (temporary file, fsync, atomic rename), so serial and MPI runs give the same files (apart from the
wall_s and rank columns).
A lock (flock on OUTDIR/.lock) stops two runs writing one folder. OUTDIR/runs.jsonl gets one line per
completed run (ranks, cases run, wall time).

The output folder (sgim/outdir.py's rule): a new or empty folder, or one holding the same study (a restart);
a folder with other files and no study is refused, as is one holding a different study unless --force, which
removes that study's own files only (study_files: the tables, study.json, runs.jsonl, report.md, report/ and
cases/ID/ of its cases; files added by hand stay). The marker .rockdem-output lists them.
"""
from __future__ import annotations

import csv
import fcntl
import io
import json
import math
import os
import pickle
import select
import shutil
import signal
import struct
import subprocess
import sys
import time
import traceback
from collections import deque
from pathlib import Path

from sgim.cli import CliError
from sgim.outdir import write_marker
from sgim.readback import BadFile

FIXED_COLUMNS = ("case_id", "status", "error", "wall_s", "rank")
POLL_S = 0.002
MAX_ATTEMPTS = 2
EXIT_ORPHANED = 137
_HDR = struct.Struct("<Q")
REPO = Path(__file__).resolve().parent.parent


# --------------------------------------------------------------------------------------------- MPI
def world():
    """COMM_WORLD when launched by mpirun with more than one rank, else None (mpi4py is not imported)."""
    size = 1
    for var in ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS"):
        if os.environ.get(var, "").isdigit():
            size = max(size, int(os.environ[var]))
    if size <= 1:
        return None
    try:
        from mpi4py import MPI
    except ImportError:
        raise CliError("launched by mpirun with several ranks but mpi4py is not installed "
                       "(pip install mpi4py)") from None
    comm = MPI.COMM_WORLD
    return comm if comm.Get_size() > 1 else None


class Orphaned(Exception):
    """mpirun (the rank's parent) has gone: the job was killed."""


class _Launcher:
    """Notices when mpirun has gone (a rank then has a new parent): `check()` raises Orphaned."""

    def __init__(self):
        self.ppid = os.getppid()
        self.next = time.perf_counter() + 0.5

    def check(self):
        now = time.perf_counter()
        if now >= self.next:
            self.next = now + 0.5
            if os.getppid() != self.ppid:
                raise Orphaned("the launcher (mpirun) has gone")


def _poll_recv(comm, source, launcher):
    from mpi4py import MPI

    st = MPI.Status()
    while not comm.Iprobe(source=source, tag=MPI.ANY_TAG, status=st):
        launcher.check()
        time.sleep(POLL_S / 2)
    return comm.recv(source=st.Get_source(), tag=st.Get_tag()), st.Get_source()


# --------------------------------------------------------------------------------------------- case process
def _send(fd, obj):
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    os.write(fd, _HDR.pack(len(data)))
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_exact(fd, n):
    chunks = []
    while n:
        b = os.read(fd, n)
        if not b:
            return None
        chunks.append(b)
        n -= len(b)
    return b"".join(chunks)


def _recv(fd):
    head = _read_exact(fd, _HDR.size)
    if head is None:
        return None
    body = _read_exact(fd, _HDR.unpack(head)[0])
    return None if body is None else pickle.loads(body)


def _child_env(study_dir, rank):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_", "OPAL_"))}
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env.setdefault(var, "1")  # one core per case
    paths = [str(REPO), str(study_dir)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    env["PYTHONPATH"] = os.pathsep.join(paths)
    env["PYTHONUNBUFFERED"] = "1"
    env["ROCKDEM_STUDY_PARENT"] = str(os.getpid())
    env["ROCKDEM_STUDY_RANK"] = str(rank)
    return env


class CaseProcess:
    """One case process of this rank; `submit` a request, then `poll` for its outcome."""

    def __init__(self, study_dir, rank=0):
        self.study_dir = study_dir
        self.rank = rank
        self.proc = None
        self.deadline = None
        self.busy = None

    def start(self):
        """Start the case process now (it is started on demand otherwise)."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()

    def _start(self):
        self.proc = subprocess.Popen([sys.executable, "-m", "cases._batch"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=_child_env(self.study_dir, self.rank),
                                     start_new_session=True, bufsize=0)

    def fileno(self):
        return self.proc.stdout.fileno()

    def submit(self, request, timeout):
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.busy = request
        self.t0 = time.perf_counter()
        self.deadline = None if timeout is None else self.t0 + timeout
        self.timeout = timeout
        try:
            _send(self.proc.stdin.fileno(), request)
        except (BrokenPipeError, OSError):
            pass  # seen as a death by poll

    def poll(self, wait):
        """The outcome dict of the running case, or None if it is still running after `wait` seconds."""
        if self.deadline is not None:
            wait = max(0.0, min(wait, self.deadline - time.perf_counter())) if wait is not None else \
                max(0.0, self.deadline - time.perf_counter())
        ready, _, _ = select.select([self.proc.stdout], [], [], wait)
        if ready:
            msg = _recv(self.fileno())
            if msg is not None:
                self.busy = None
                return msg
            rc = self.proc.wait()
            self._reap()
            sig = -rc if rc < 0 else None
            try:
                name = f" ({signal.Signals(sig).name})" if sig else ""
            except ValueError:
                name = ""
            why = f"killed by signal {sig}{name}" if sig else f"exited with status {rc}"
            self.busy = None
            self.start()  # the next case finds it ready
            return {"status": "died", "error": f"case process {why}"}
        if self.deadline is not None and time.perf_counter() >= self.deadline:
            wall = time.perf_counter() - self.t0
            self.kill()
            self.busy = None
            self.start()
            return {"status": "timeout", "error": f"time limit of {self.timeout:g} s exceeded (killed)",
                    "wall_s": wall}
        return None

    def _reap(self):
        for f in (self.proc.stdin, self.proc.stdout):
            try:
                f.close()
            except OSError:
                pass
        self.proc = None

    def kill(self):
        if self.proc is None:
            return
        from adapters.process import kill_group

        kill_group(self.proc)
        self._reap()

    def close(self):
        if self.proc is None:
            return
        try:
            self.proc.stdin.close()  # the case process ends at EOF
            self.proc.wait(timeout=5)
        except (OSError, subprocess.TimeoutExpired):
            self.kill()
            return
        self._reap()


def _child_main():
    """The case process: read requests on stdin, run the evaluator, answer on (the original) stdout."""
    try:  # die with the rank
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
        if str(os.getppid()) != os.environ.get("ROCKDEM_STUDY_PARENT", str(os.getppid())):
            os._exit(1)
    except (OSError, AttributeError):
        pass
    fin, fout = os.dup(0), os.dup(1)
    devnull = os.open(os.devnull, os.O_RDWR)
    os.dup2(devnull, 0)
    os.dup2(2, 1)
    saved_err = os.dup(2)
    from cases.study import resolve_evaluator

    cache = {}
    while True:
        req = _recv(fin)
        if req is None:
            return 0
        case_dir = Path(req["case_dir"])
        shutil.rmtree(case_dir, ignore_errors=True)
        case_dir.mkdir(parents=True)
        scene = case_dir / "scene.toml"
        scene.write_text(req["scene_text"])
        log = os.open(case_dir / "log.txt", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(log, 1)
        os.dup2(log, 2)
        os.close(log)
        t0 = time.perf_counter()
        try:
            key = (req["engine"], req["study_dir"])
            if key not in cache:
                cache[key] = resolve_evaluator(req["engine"], req["study_dir"]).fn
            out = cache[key](scene, case_dir, dict(req["params"]))
            values = _check_results(out, req["results"])
            answer = {"status": "ok", "error": "", "results": values}
        except BaseException as exc:  # noqa: BLE001 - every failure becomes a row
            if isinstance(exc, KeyboardInterrupt):
                raise
            (case_dir / "error.txt").write_text(traceback.format_exc())
            answer = {"status": "failed", "error": one_line(exc), "results": {}}
        answer["wall_s"] = time.perf_counter() - t0
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved_err, 1)
        os.dup2(saved_err, 2)
        _send(fout, answer)


def one_line(exc):
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    name = type(exc).__name__
    line = f"{name}: {msg}" if msg else name
    return line if len(line) <= 500 else line[:497] + "..."


def _check_results(out, names):
    if not isinstance(out, dict):
        raise TypeError(f"evaluator returned {type(out).__name__}, not a dict of results")
    values = {}
    for name in names:
        if name not in out:
            raise KeyError(f"evaluator returned no {name!r} (it returned: {', '.join(map(str, out)) or 'nothing'})")
        v = out[name]
        if hasattr(v, "item") and getattr(v, "shape", None) == ():
            v = v.item()
        if not isinstance(v, (bool, int, float, str)):
            raise TypeError(f"result {name!r} is a {type(v).__name__}, not a scalar")
        values[name] = v
    return values


# --------------------------------------------------------------------------------------------- the table
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


class Table:
    """results.csv + results.jsonl, append-only, one fsynced write per row (see the module doc)."""

    def __init__(self, outdir, param_paths, result_names):
        self.outdir = Path(outdir)
        self.columns = list(FIXED_COLUMNS) + [f"p:{p}" for p in param_paths] + list(result_names)
        self.param_paths = list(param_paths)
        self.result_names = list(result_names)
        self.csv_path = self.outdir / "results.csv"
        self.jsonl_path = self.outdir / "results.jsonl"
        self.done = {}  # case_id -> status
        self._recover()
        self.fcsv = open(self.csv_path, "a", encoding="utf-8", newline="")
        self.fjson = open(self.jsonl_path, "a", encoding="utf-8")
        if self.fcsv.tell() == 0:
            self._write(self.fcsv, self._line(self.columns))

    @staticmethod
    def _line(cells):
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(cells)
        return buf.getvalue()

    @staticmethod
    def _write(fh, text):
        fh.write(text)
        fh.flush()
        os.fdatasync(fh.fileno())

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
        for no, line in enumerate(_text(path, self._complete_bytes(path)).splitlines(keepends=True), 1):
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
        self.fcsv.close()
        self.fjson.close()
        self._rewrite(self.csv_path, keep)
        self.done = {}
        self.__init__(self.outdir, self.param_paths, self.result_names)

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
        self.fcsv.close()
        self.fjson.close()
        rank = {cid: i for i, cid in enumerate(order)}
        records = self._records()
        rows = sorted(records[1:], key=lambda rec: rank.get(rec[1][0], len(rank)))
        self._rewrite(self.csv_path, [self._line(cells) for no, cells in records[:1] + rows])
        jl = self._json_lines()
        self._rewrite(self.jsonl_path, [ln for no, cid, ln in sorted(jl, key=lambda r: rank.get(r[1], len(rank)))])

    def close(self):
        for fh in (self.fcsv, self.fjson):
            if not fh.closed:
                fh.close()


# --------------------------------------------------------------------------------------------- runner
def _request(study, outdir, case):
    return {"case_dir": str(outdir / "cases" / case.case_id), "scene_text": study.case_scene_text(case),
            "params": case.params, "engine": study.engine, "results": list(study.results),
            "study_dir": str(study.path.parent.resolve())}


STUDY_COMMAND = "cases study run"


def study_files(case_ids):
    """What a study writes in its output folder (a name ending in '/': a folder, all of it the study's)."""
    return ["study.json", "results.csv", "results.jsonl", "runs.jsonl", "report.md", "report/",
            *(f"cases/{cid}/" for cid in case_ids)]


def _check_folder(outdir):
    """Refuse (CliError) an existing output folder that holds neither this tool's study nor nothing."""
    from sgim.outdir import MARKER, folder_entries, read_marker, shown_names

    label = f"-o = {str(outdir)!r}"
    if not outdir.exists():
        return
    if not outdir.is_dir():
        raise CliError(f"{outdir}: {label}: output exists and is not a folder")
    marker = read_marker(outdir)
    if marker is None:
        entries = [n for n in folder_entries(outdir) if n != ".lock"]
        if entries and not (outdir / "study.json").is_file():  # with study.json: a study from before the marker
            raise CliError(f"{label}: folder exists and holds files this tool did not write ({shown_names(entries)}); "
                           "choose a new folder")
    elif not marker:
        raise CliError(f"{label}: {MARKER} in the folder is not an output marker of this tool; choose a new folder")
    elif marker["command"] != STUDY_COMMAND:
        raise CliError(f"{label}: folder holds an earlier output of {marker['command']}, not of a study; "
                       "choose a new folder")


def _remove_study(outdir, old):
    """Remove the files of the study whose study.json is `old` (files added by hand stay)."""
    ids = [c.get("case_id") for c in old.get("cases", []) if isinstance(c, dict)]
    for name in study_files(i for i in ids if isinstance(i, str) and i and "/" not in i and i not in (".", "..")):
        p = outdir / name.rstrip("/")
        if p.is_symlink() or (p.is_file() and not name.endswith("/")):
            p.unlink()
        elif p.is_dir() and name.endswith("/"):
            shutil.rmtree(p)
    try:
        (outdir / "cases").rmdir()
    except OSError:
        pass


def _prepare(study, outdir, force=False):
    _check_folder(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    lock = open(outdir / ".lock", "a+")
    try:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.close()
        raise CliError(f"{outdir}: -o = {str(outdir)!r}: another study run is writing this folder") from None
    info = study.to_json()
    sj = outdir / "study.json"
    same = False
    if sj.exists():
        from sgim.readback import read_json

        try:
            old = read_json(sj, "a study.json")
        except BadFile:
            lock.close()
            raise
        same = all(old.get(k) == json.loads(json.dumps(info[k])) for k in ("cases", "engine", "results"))
        if not same and not force:
            lock.close()
            raise CliError(f"{outdir}: -o = {str(outdir)!r}: holds a different study (its study.json differs in "
                           "cases, engine or results): use a new output folder, or --force to replace it")
        if not same:
            _remove_study(outdir, old)
    if not same:
        tmp = sj.with_name("study.json.tmp")
        tmp.write_text(json.dumps(info, indent=1))
        os.replace(tmp, sj)
    return lock


def run_study(study, outdir, timeout=None, comm=None, progress=None, retry_failed=False, force=False):
    """Run every case not yet in OUTDIR/results.csv. Serial when comm is None; otherwise call on every rank
    (rank 0 hands out cases and writes the table, all ranks run cases). Returns a summary dict on rank 0.
    `force`: a folder holding a different study has that study's files removed first (see _prepare)."""
    outdir = Path(outdir).resolve()
    timeout = timeout if timeout is not None else study.timeout
    if comm is not None and comm.Get_rank() != 0:
        _worker(comm, study, outdir, timeout)
        return {}
    size = 1 if comm is None else comm.Get_size()
    t0 = time.perf_counter()
    local = CaseProcess(study.path.parent.resolve())
    local.start()  # its imports overlap with the set-up
    try:
        lock = _prepare(study, outdir, force=force)
        table = Table(outdir, [p.path for p in study.params], study.results)
        ids = {c.case_id for c in study.cases}
        for cid, no in table.line_of.items():
            if cid not in ids:
                table.close()
                lock.close()
                raise BadFile(table.csv_path, f"line {no}: case {cid} is not a case of this study")
        if retry_failed:
            table.drop({"failed", "timeout"})
        # the marker only once the tables read back: a refused restart leaves the folder as it was
        write_marker(outdir, STUDY_COMMAND, study_files(c.case_id for c in study.cases) + [".lock"])
    except BaseException:
        local.kill()
        if comm is not None:
            for r in range(1, size):
                comm.send(("stop",), dest=r)
        raise
    todo = [i for i, c in enumerate(study.cases) if c.case_id not in table.done]
    total, done0 = len(study.cases), len(table.done)
    stats = {"ok": 0, "failed": 0, "timeout": 0}
    for s in table.done.values():
        stats[s] = stats.get(s, 0) + 1
    if progress:
        progress(f"{study.name}: {total} cases, {done0} already in {outdir / 'results.csv'}, {len(todo)} to run "
                 f"on {size} rank(s), engine {study.engine}")
    state = {"last": 0.0, "ran": 0}

    def record(i, row, rank):
        case = study.cases[i]
        row["rank"] = rank
        table.add(case, row)
        stats[row["status"]] = stats.get(row["status"], 0) + 1
        state["ran"] += 1
        now = time.perf_counter()
        n = done0 + state["ran"]
        if progress and (now - state["last"] >= 1.0 or n == total or row["status"] != "ok"):
            state["last"] = now
            el = now - t0
            eta = el / state["ran"] * (total - n)
            extra = f"  {case.case_id} {row['status']}: {row['error']}" if row["status"] != "ok" else ""
            progress(f"{n}/{total} cases done, {stats['failed']} failed, {stats['timeout']} timeout, "
                     f"ETA {eta:.0f} s{extra}")

    try:
        if comm is None:
            _serial(study, outdir, todo, timeout, local, record)
        else:
            try:
                _master(comm, study, outdir, todo, timeout, local, record)
            except Orphaned:
                local.kill()
                table.close()
                try:
                    print(f"cases study: mpirun has gone: stopped with {len(table.done)}/{total} cases in the "
                          "table (run the same command again to finish)", file=sys.stderr, flush=True)
                except OSError:
                    pass
                os._exit(EXIT_ORPHANED)
    except BaseException:
        local.kill()  # Ctrl-C or an error of the runner: the running case goes with it
        raise
    finally:
        local.close()
        if len(table.done) == total:
            table.finish([c.case_id for c in study.cases])
        table.close()
        lock.close()
    summary = {"outdir": str(outdir), "total": total, "done": len(table.done), "ran": state["ran"], "ranks": size,
               "wall_s": time.perf_counter() - t0, **{k: stats.get(k, 0) for k in ("ok", "failed", "timeout")},
               "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    with open(outdir / "runs.jsonl", "a") as fh:  # one line per run of the study (restarts included)
        fh.write(json.dumps(summary) + "\n")
    return summary


def _died_row(outcome, attempts):
    return {"status": "failed", "error": f"{outcome['error']} on {attempts} attempts", "wall_s": None,
            "results": {}}


def _serial(study, outdir, todo, timeout, local, record):
    for i in todo:
        for attempt in range(1, MAX_ATTEMPTS + 1):
            local.submit(_request(study, outdir, study.cases[i]), timeout)
            out = None
            while out is None:
                out = local.poll(None)
            if out["status"] != "died":
                record(i, out, 0)
                break
            if attempt == MAX_ATTEMPTS:
                record(i, _died_row(out, attempt), 0)


def _master(comm, study, outdir, todo, timeout, local, record):
    from mpi4py import MPI

    queue = deque((i, 1, None) for i in todo)  # (case index, attempt, rank to avoid)
    size = comm.Get_size()
    inflight = {}  # rank -> (i, attempt)
    waiting = set()  # ranks with nothing to do
    stopped = set()
    st = MPI.Status()
    launcher = _Launcher()

    def take(rank):
        for k, (i, attempt, avoid) in enumerate(queue):
            if avoid != rank or all(r == rank for r in range(size) if r not in stopped):
                del queue[k]
                return i, attempt
        return None if not queue else queue.popleft()[:2]

    def give(rank):
        job = take(rank)
        if job is None:
            return False
        inflight[rank] = job
        if rank == 0:
            local.submit(_request(study, outdir, study.cases[job[0]]), timeout)
        else:
            comm.send(("case", job[0], job[1]), dest=rank)
        return True

    def finished(rank, i, outcome):
        job = inflight.pop(rank)
        if outcome["status"] == "died":
            if job[1] < MAX_ATTEMPTS:
                queue.appendleft((i, job[1] + 1, rank))
            else:
                record(i, _died_row(outcome, job[1]), rank)
        else:
            record(i, outcome, rank)

    give(0)
    while queue or inflight or len(stopped) < size - 1:
        launcher.check()
        # requests and results from the other ranks
        while comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=st):
            src = st.Get_source()
            msg = comm.recv(source=src, tag=st.Get_tag())
            if msg[0] == "done":
                finished(src, msg[1], msg[2])
            elif msg[0] == "died":
                finished(src, msg[1], msg[2])
            waiting.add(src)
        for r in sorted(waiting):
            if give(r):
                waiting.discard(r)
        if 0 not in inflight and queue:
            give(0)
        if not queue and not inflight:
            for r in sorted(waiting):
                comm.send(("stop",), dest=r)
                stopped.add(r)
            waiting.clear()
            if len(stopped) >= size - 1:
                break
            time.sleep(POLL_S)
            continue
        if 0 in inflight:
            out = local.poll(POLL_S)
            if out is not None:
                finished(0, inflight[0][0], out)
                if queue:
                    give(0)
        else:
            time.sleep(POLL_S)


def _worker(comm, study, outdir, timeout):
    rank = comm.Get_rank()
    local = CaseProcess(study.path.parent.resolve(), rank)
    local.start()
    launcher = _Launcher()
    try:
        comm.send(("ready",), dest=0)
        while True:
            msg, _ = _poll_recv(comm, 0, launcher)
            if msg[0] != "case":
                break
            i = msg[1]
            local.submit(_request(study, outdir, study.cases[i]), timeout)
            out = None
            while out is None:
                out = local.poll(0.5)
                launcher.check()
            out["rank"] = rank
            comm.send(("died" if out["status"] == "died" else "done", i, out), dest=0)
    except Orphaned:
        local.kill()
        os._exit(EXIT_ORPHANED)
    finally:
        local.close()


if __name__ == "__main__":
    sys.exit(_child_main())
