"""The study runner: serial, or under mpirun with rank 0 handing out cases (dynamic load balancing).

Every rank starts one case server (cases/lib/_caseserver.py: imports and the evaluator's warm-up once) that forks a
fresh process for every case, so a case's module state, resource limits, memory and crash never reach the next
case, and the tables of a serial and an MPI run are equal for any evaluator. The server enforces the time limit
(the case's process group is killed) and --memory-limit (RLIMIT_AS in the case's process); rank 0's main thread
stays free to hand out cases and write the table while its own cases compute: rank 0 runs cases too. While cases
are short (median under PREFETCH_BELOW_S) each rank holds a second case queued in its server, so that the next
case starts without a round trip to rank 0. --reuse-process runs the cases in the server itself, one after the
other (no fork: less overhead; a case's state then reaches the next).

Messages (MPI, pickled): rank 0 sends ("case", index, attempt) or ("stop",); a rank answers ("done", index, row)
after each case (row status "died" when the case's process died without answering). Waits poll (Iprobe + short
sleeps, select on the case server's pipe): Open MPI's blocking receive spins a core, which a study on few cores
cannot spare.

Faults:
- a case that raises: status "failed", error = the exception's one line (traceback in the case's error.txt);
  past --memory-limit: "memory limit of N MB per case exceeded (MemoryError ...)";
- a case past its time limit: its process group is killed, status "timeout";
- a case process that dies (killed, crashed interpreter, a signal past the memory limit): the case is handed out
  again, preferably to another rank; the second death is recorded as "failed" with the signal;
- a rank that dies: Open MPI ends the whole job (mpirun kills the other ranks; case servers and cases die with
  their parent through PR_SET_PDEATHSIG). Started again, the study skips the cases in the table and runs the
  rest: in-flight cases of the killed job were never written, so none is lost and none is duplicated.
- mpirun killed (SIGKILL): its ranks run on; each notices within 0.5 s that its parent has gone, kills its case
  server and exits (rank 0 after closing the table), so a restart does not meet a run still writing.
- SIGTERM (a batch scheduler at the end of the job's time, or mpirun forwarding it): the rank stops like Ctrl-C:
  the running cases are killed, the table is closed, exit status 143; the same command finishes the study.

The table (rank 0 only): results.csv and results.jsonl, crash-safe and restartable (cases/lib/table.py).
A lock (flock on OUTDIR/.lock) stops two runs writing one folder. OUTDIR/runs.jsonl gets one line per
completed run (ranks, cases run, wall time).

The output folder (sgim/outdir.py's rule): a new or empty folder, or one holding the same study (a restart);
a folder with other files and no study is refused, as is one holding a different study unless --force, which
removes that study's own files only (study_files: the tables, study.json, runs.jsonl, report.md, report/,
versions/ and cases/ID/ of its cases; files added by hand stay). The marker .rockdem-output lists them.
study.json holds the study's fingerprint (Study.fingerprint: the study file, the base scene, every file it
names, the evaluator's module): a restart whose inputs differ is refused with one line naming what changed,
unless --new-version, which moves the earlier tables and cases to versions/vN/ and runs every case again.
"""
from __future__ import annotations

import fcntl
import json
import math
import os
import select
import shutil
import signal
import subprocess
import sys
import time
from collections import deque
from pathlib import Path

from adapters.process import kill_group
from sgim.common import CliError
from sgim.outdir import MARKER, folder_entries, read_marker, shown_names, write_marker
from sgim.readback import BadFile, read_json

from .table import Table

POLL_S = 0.002
MAX_ATTEMPTS = 2
EXIT_ORPHANED = 137
REPO = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------------------------- MPI
# mpi4py is imported inside the functions below, only under mpirun: a serial run neither needs it installed
# nor pays MPI's start-up
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
from ._caseserver import _exit_reason, _recv, _send, one_line  # noqa: E402,F401 - the lean case server module
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
    """The case server of this rank: a process started once (imports, the evaluator's warm-up) that forks a fresh
    child for every case. `submit` requests (several may queue: they run one after the other), `poll` for
    outcomes, in submission order."""

    def __init__(self, study_dir, rank=0):
        self.study_dir = study_dir
        self.rank = rank
        self.proc = None
        self.pending = deque()  # (tag, timeout) in submission order
        self.front_t0 = None
        self.reuse = False

    def start(self):
        """Start the case server now (it is started on demand otherwise)."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()

    def _start(self):
        self.warming = True  # until the server has imported the evaluator and run its warm-up
        self.proc = subprocess.Popen([sys.executable, "-m", "cases.lib._caseserver"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=_child_env(self.study_dir, self.rank),
                                     start_new_session=True, bufsize=0)

    def fileno(self):
        return self.proc.stdout.fileno()

    def submit(self, tag, request, timeout, memory_mb=None):
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        if not self.pending:
            self.front_t0 = time.perf_counter()
        self.pending.append((tag, timeout))
        try:
            _send(self.proc.stdin.fileno(), {**request, "timeout": timeout, "memory_mb": memory_mb})
        except (BrokenPipeError, OSError):
            pass  # seen as a death by poll

    def _backstop(self):
        """The time after which a case server that neither answers nor dies is killed: the front case's limit
        (enforced by the server itself) plus a minute; with --reuse-process the limit itself (the case runs in
        the server)."""
        timeout = self.pending[0][1] if self.pending else None
        if timeout is None:
            return None
        if self.warming:  # imports and kernel compilation (a cold numba cache) are not the case's time
            return self.front_t0 + max(timeout + 60.0, WARM_LIMIT_S)
        return self.front_t0 + timeout + (0.0 if self.reuse else 60.0)

    def poll(self, wait):
        """[(tag, outcome dict)] of the cases finished within `wait` seconds (None: until one finishes)."""
        if not self.pending:
            if wait:
                time.sleep(wait)
            return []
        back = self._backstop()
        if back is not None:
            left = max(0.0, back - time.perf_counter())
            wait = left if wait is None else min(wait, left)
        out = []
        while self.pending:
            ready, _, _ = select.select([self.proc.stdout], [], [], wait if not out else 0)
            if not ready:
                break
            msg = _recv(self.fileno())
            if isinstance(msg, dict) and msg.get("warmed"):
                self.warming = False
                self.front_t0 = time.perf_counter()
                continue
            if msg is None:  # the case server died: every queued case is reported died (and handed out again)
                rc = self.proc.wait()
                self._reap()
                why = _exit_reason(rc)
                out += [(tag, {"status": "died", "error": f"case server {why}"}) for tag, _ in self.pending]
                self.pending.clear()
                break
            tag, _ = self.pending.popleft()
            self.front_t0 = time.perf_counter()
            out.append((tag, msg))
        if not out and back is not None and time.perf_counter() >= back:
            tag, timeout = self.pending.popleft()
            self.kill()
            out.append((tag, {"status": "timeout", "error": f"time limit of {timeout:g} s exceeded (killed)",
                              "wall_s": timeout}))
            out += [(t, {"status": "died", "error": "case server killed"}) for t, _ in self.pending]
            self.pending.clear()
        return out

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
        kill_group(self.proc)
        self._reap()

    def close(self):
        if self.proc is None:
            return
        try:
            self.proc.stdin.close()  # the case server ends at EOF
            self.proc.wait(timeout=5)
        except (OSError, subprocess.TimeoutExpired):
            self.kill()
            return
        self._reap()


# --------------------------------------------------------------------------------------------- runner
def _request(study, outdir, case):
    return {"case_dir": str(outdir / "cases" / case.case_id), "scene_text": study.case_scene_text(case),
            "params": case.params, "engine": study.engine, "results": list(study.results),
            "study_dir": str(study.path.parent.resolve())}


STUDY_COMMAND = "cases study run"


def study_files(case_ids):
    """What a study writes in its output folder (a name ending in '/': a folder, all of it the study's)."""
    return ["study.json", "results.csv", "results.jsonl", "runs.jsonl", "report.md", "report/", "versions/",
            *(f"cases/{cid}/" for cid in case_ids)]


def _check_folder(outdir):
    """Refuse (CliError) an existing output folder that holds neither this tool's study nor nothing."""
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


def _old_ids(old):
    ids = [c.get("case_id") for c in old.get("cases", []) if isinstance(c, dict)]
    return [i for i in ids if isinstance(i, str) and i and "/" not in i and i not in (".", "..")]


def _remove_study(outdir, old):
    """Remove the files of the study whose study.json is `old` (files added by hand stay)."""
    for name in study_files(_old_ids(old)):
        p = outdir / name.rstrip("/")
        if p.is_symlink() or (p.is_file() and not name.endswith("/")):
            p.unlink()
        elif p.is_dir() and name.endswith("/"):
            shutil.rmtree(p)
    try:
        (outdir / "cases").rmdir()
    except OSError:
        pass


def _archive_study(outdir, old):
    """Move the files of the study whose study.json is `old` to OUTDIR/versions/vN/ (--new-version); N is
    returned. Earlier versions stay where they are."""
    versions = outdir / "versions"
    n = 1
    while (versions / f"v{n}").exists():
        n += 1
    dest = versions / f"v{n}"
    dest.mkdir(parents=True)
    for name in study_files(_old_ids(old)):
        if name == "versions/":
            continue
        p = outdir / name.rstrip("/")
        if p.exists() or p.is_symlink():
            target = dest / name.rstrip("/")
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(p, target)
    try:
        (outdir / "cases").rmdir()
    except OSError:
        pass
    return n


def fingerprint_changes(old, new):
    """The entries of fingerprint `new` that differ from `old` (added, removed or changed), in one phrase."""
    changed = [k for k in new if k in old and old[k] != new[k]]
    added = [k for k in new if k not in old]
    removed = [k for k in old if k not in new]
    parts = [f"{k} changed" for k in changed] + [f"{k} added" for k in added] + [f"{k} gone" for k in removed]
    return ", ".join(parts)


def _prepare(study, outdir, force=False, new_version=False):
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
    write = True
    if sj.exists():
        try:
            old = read_json(sj, "a study.json")
        except BadFile:
            lock.close()
            raise
        old_eval = old.get("evaluator", old.get("engine"))
        same = old_eval == info["evaluator"] and all(old.get(k) == json.loads(json.dumps(info[k]))
                                                     for k in ("cases", "results"))
        old_fp = old.get("fingerprint")
        changes = fingerprint_changes(old_fp, info["fingerprint"]) if isinstance(old_fp, dict) else ""
        info["version"] = int(old.get("version", 1)) if isinstance(old.get("version", 1), int) else 1
        if same and not changes:
            write = not isinstance(old_fp, dict)  # a study.json from before fingerprints gets one
        elif new_version:
            info["version"] = _archive_study(outdir, old) + 1
        elif not same and force:
            _remove_study(outdir, old)
        else:
            lock.close()
            if not same:
                raise CliError(f"{outdir}: -o = {str(outdir)!r}: holds a different study (its study.json differs in "
                               "cases, evaluator or results): use a new output folder, --new-version to keep it in "
                               "versions/, or --force to replace it")
            raise CliError(f"{outdir}: -o = {str(outdir)!r}: the study's inputs changed since its table was begun "
                           f"({changes}): run with --new-version (the earlier results move to versions/) or "
                           "write to a new folder")
    else:
        info["version"] = 1
    if write:
        tmp = sj.with_name("study.json.tmp")
        tmp.write_text(json.dumps(info, indent=1))
        os.replace(tmp, sj)
    return lock


class Terminated(BaseException):
    """SIGTERM (a scheduler ending the job): stop like Ctrl-C; the finished cases are in the table."""


def _on_sigterm(signum, frame):
    raise Terminated()


def run_study(study, outdir, timeout=None, comm=None, progress=None, retry_failed=False, force=False,
              new_version=False, memory_mb=None, reuse=False):
    """Run every case not yet in OUTDIR/results.csv. Serial when comm is None; otherwise call on every rank
    (rank 0 hands out cases and writes the table, all ranks run cases). Returns a summary dict on rank 0.
    `force`: a folder holding a different study has that study's files removed first; `new_version`: a folder
    holding this study with other inputs (or another study) has them moved to versions/vN/ (see _prepare).
    `memory_mb`: the address-space limit of every case. `reuse`: run the cases in the rank's case server itself,
    one after the other (no fork per case: faster, but a case's state, limits and crashes reach the next)."""
    outdir = Path(outdir).resolve()
    timeout = timeout if timeout is not None else study.timeout
    try:
        signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread
        pass
    if comm is not None and comm.Get_rank() != 0:
        _worker(comm, study, outdir, timeout, memory_mb, reuse)
        return {}
    size = 1 if comm is None else comm.Get_size()
    t0 = time.perf_counter()
    local = CaseProcess(study.path.parent.resolve())
    local.start()  # its imports overlap with the set-up
    try:
        lock = _prepare(study, outdir, force=force, new_version=new_version)
        try:
            table = Table(outdir, [p.path for p in study.params], study.results, [c.case_id for c in study.cases])
        except BaseException:
            lock.close()
            raise
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
                 f"on {size} rank(s), evaluator {study.engine}")
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

    run = _Run(study, outdir, timeout, memory_mb, record, reuse)
    try:
        if comm is None:
            _serial(run, todo, local)
        else:
            try:
                _master(comm, run, todo, local)
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
        local.kill()  # Ctrl-C, SIGTERM or an error of the runner: the running cases go with it
        raise
    finally:
        local.close()
        if len(table.done) == total:
            table.finish([c.case_id for c in study.cases])
        table.close()
        lock.close()
    summary = {"outdir": str(outdir), "study": study.name, "total": total, "done": len(table.done),
               "ran": state["ran"], "ranks": size, "wall_s": time.perf_counter() - t0,
               **{k: stats.get(k, 0) for k in ("ok", "failed", "timeout")},
               "results_csv": str(outdir / "results.csv"),
               "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    with open(outdir / "runs.jsonl", "a") as fh:  # one line per run of the study (restarts included)
        fh.write(json.dumps(summary) + "\n")
    return summary


class _Run:
    """What every loop needs: the requests of cases, the limits, the table's record function."""

    def __init__(self, study, outdir, timeout, memory_mb, record, reuse=False):
        self.study, self.outdir, self.timeout, self.memory_mb, self.record = study, outdir, timeout, memory_mb, record
        self.reuse = reuse

    def submit(self, local, i, attempt):
        local.reuse = self.reuse
        local.submit((i, attempt), {**_request(self.study, self.outdir, self.study.cases[i]), "reuse": self.reuse},
                     self.timeout, self.memory_mb)


def _died_row(outcome, attempts):
    return {"status": "failed", "error": f"{outcome['error']} on {attempts} attempts", "wall_s": None,
            "results": {}}


# cases queued in a case server beyond the running one: the next case starts the moment one ends (no round trip
# to rank 0); only while cases are short, so that no case waits behind a long one while a rank is idle
PREFETCH_BELOW_S = 0.25
WARM_LIMIT_S = 3600.0  # a case server's imports and warm-up (kernel compilation) before its first case


def _serial(run, todo, local):
    queue = deque((i, 1) for i in todo)
    while queue or local.pending:
        while queue and len(local.pending) < 2:
            run.submit(local, *queue.popleft())
        for (i, attempt), out in local.poll(None):
            if out["status"] != "died":
                run.record(i, out, 0)
            elif attempt < MAX_ATTEMPTS:
                queue.appendleft((i, attempt + 1))
            else:
                run.record(i, _died_row(out, attempt), 0)


def _master(comm, run, todo, local):
    from mpi4py import MPI

    queue = deque((i, 1, None) for i in todo)  # (case index, attempt, rank to avoid)
    size = comm.Get_size()
    inflight = {r: [] for r in range(size)}  # rank -> [(i, attempt)]
    stopped = set()
    st = MPI.Status()
    launcher = _Launcher()
    walls = deque(maxlen=16)

    def depth():
        """Cases a rank holds: 1 for long cases; for short ones enough to cover rank 0's answer time (POLL_S)
        five times over, 2 to 8."""
        if len(walls) < 2:
            return 1
        med = sorted(walls)[len(walls) // 2]
        return 1 if med >= PREFETCH_BELOW_S else int(min(8, max(2, math.ceil(5 * POLL_S / max(med, 1e-6)))))

    def take(rank):
        for k, (i, attempt, avoid) in enumerate(queue):
            if avoid != rank or all(r == rank for r in range(size) if r not in stopped):
                del queue[k]
                return i, attempt
        return None if not queue else queue.popleft()[:2]

    def fill(rank):
        while len(inflight[rank]) < depth() and queue:
            job = take(rank)
            inflight[rank].append(job)
            if rank == 0:
                run.submit(local, *job)
            else:
                comm.send(("case", job[0], job[1]), dest=rank)

    def finished(rank, i, outcome):
        job = next(j for j in inflight[rank] if j[0] == i)
        inflight[rank].remove(job)
        if outcome.get("wall_s") is not None:
            walls.append(outcome["wall_s"])
        if outcome["status"] == "died":
            if job[1] < MAX_ATTEMPTS:
                queue.appendleft((i, job[1] + 1, rank))
            else:
                run.record(i, _died_row(outcome, job[1]), rank)
        else:
            run.record(i, outcome, rank)

    fill(0)
    while True:
        launcher.check()
        while comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=st):
            src = st.Get_source()
            msg = comm.recv(source=src, tag=st.Get_tag())
            if msg[0] == "done":
                finished(src, msg[1], msg[2])
        for r in range(size):
            if r not in stopped:
                fill(r)
        if not queue:
            for r in range(1, size):
                if r not in stopped and not inflight[r]:
                    comm.send(("stop",), dest=r)
                    stopped.add(r)
            if len(stopped) >= size - 1 and not inflight[0]:
                break
        if inflight[0]:
            for (i, _), out in local.poll(POLL_S):
                finished(0, i, out)
        else:
            time.sleep(POLL_S)


def _worker(comm, study, outdir, timeout, memory_mb, reuse=False):
    from mpi4py import MPI

    rank = comm.Get_rank()
    local = CaseProcess(study.path.parent.resolve(), rank)
    local.start()
    launcher = _Launcher()
    run = _Run(study, outdir, timeout, memory_mb, None, reuse)
    st = MPI.Status()
    try:
        while True:
            launcher.check()
            stop = False
            while comm.Iprobe(source=0, tag=MPI.ANY_TAG, status=st):
                msg = comm.recv(source=0, tag=st.Get_tag())
                if msg[0] != "case":
                    stop = True
                    break
                run.submit(local, msg[1], msg[2])
            if stop:
                break
            for (i, _), out in local.poll(POLL_S if local.pending else None):
                out["rank"] = rank
                comm.send(("done", i, out), dest=0)
            if not local.pending:
                time.sleep(POLL_S / 2)
    except Orphaned:
        local.kill()
        os._exit(EXIT_ORPHANED)
    except BaseException:
        local.kill()
        raise
    finally:
        local.close()

