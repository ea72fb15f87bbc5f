"""The case server of a study rank: one process per rank, started once, that runs every case in a fresh child.

    python -m cases.lib._caseserver      (started by cases/lib/_batch.py's CaseProcess; requests on stdin, answers on stdout)

The server imports the evaluator (and runs its warm-up, e.g. kernel compilation) once and never runs a case
itself: each case runs in a child forked from it, so every case starts from the same state (no module globals,
memory, resource limits or crashes of an earlier case), whatever rank and whatever cases ran before: serial and
MPI tables are equal for any evaluator. The next child is forked while the current case runs (a spare waiting
for its request on a pipe), so the fork's cost overlaps with the case when a core is free.

A child: its own process group (a time limit kills what the case started too), dies with the server
(PR_SET_PDEATHSIG), RLIMIT_AS = --memory-limit, its folder cases/<id>/ with scene.toml and log.txt (stdout and
stderr), then ``fn(scene_path, case_dir, params)``; the answer (status, error, results, wall_s) goes back on a
pipe, then ``os._exit``. The server enforces the time limit (SIGKILL to the group: status "timeout") and reports
a child that dies without answering ("died", with the signal) so that the rank can hand the case out again.

Only the standard library is imported here (and the evaluator's module, when the first request names it, with the
registry cases/lib/evaluators.py): a small server forks faster.
"""
from __future__ import annotations

import gc
import os
import pickle
import resource
import select
import shutil
import signal
import struct
import sys
import time
import traceback
from pathlib import Path

_HDR = struct.Struct("<Q")


# --------------------------------------------------------------------------------------------- messages
def _send(fd, obj):
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(_HDR.pack(len(data)) + data)
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


def _exit_reason(status):
    """'killed by signal 9 (SIGKILL)' or 'exited with status 3' for a return code (negative: a signal)."""
    sig = -status if status < 0 else None
    if not sig:
        return f"exited with status {status}"
    try:
        name = f" ({signal.Signals(sig).name})"
    except ValueError:
        name = ""
    return f"killed by signal {sig}{name}"


def one_line(exc):
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    name = type(exc).__name__
    line = f"{name}: {msg}" if msg else name
    return line if len(line) <= 500 else line[:497] + "..."


def _bad_char(text):
    return next(k for k, ch in enumerate(text) if 0xD800 <= ord(ch) <= 0xDFFF)


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
        if isinstance(v, str):
            try:
                v.encode("utf-8")
            except UnicodeEncodeError:
                raise ValueError(f"result {name!r} is text that is not valid Unicode (a lone surrogate at "
                                 f"character {_bad_char(v)})") from None
        values[name] = v
    return values


# --------------------------------------------------------------------------------------------- the server
_PRCTL = None


def _pdeathsig():
    """Die with the parent (Linux): SIGKILL when the process that started this one ends."""
    global _PRCTL
    try:
        if _PRCTL is None:
            import ctypes  # lazy: only on the first call (see the module doc)

            _PRCTL = ctypes.CDLL(None, use_errno=True).prctl
        _PRCTL(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _run_case(req, fn, saved_err, set_limit=True):
    """In the forked child: limits, the case folder, the evaluator; returns the answer."""
    mem = req.get("memory_mb")
    if mem and set_limit:
        lim = int(mem * 1024 * 1024)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    case_dir = Path(req["case_dir"])
    if case_dir.exists():
        shutil.rmtree(case_dir, ignore_errors=True)
    case_dir.mkdir(parents=True)
    scene = case_dir / "scene.toml"
    with open(scene, "w", encoding="utf-8") as fh:
        fh.write(req["scene_text"])
    log = os.open(case_dir / "log.txt", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    t0 = time.perf_counter()
    try:
        out = fn(scene, case_dir, dict(req["params"]))
        answer = {"status": "ok", "error": "", "results": _check_results(out, req["results"])}
    except BaseException as exc:  # noqa: BLE001 - every failure becomes a row
        try:
            (case_dir / "error.txt").write_text(traceback.format_exc())
        except BaseException:  # noqa: BLE001 - e.g. no memory left to format it
            pass
        msg = one_line(exc)
        if mem and isinstance(exc, MemoryError):
            msg = f"memory limit of {mem:g} MB per case exceeded ({msg})"
        answer = {"status": "failed", "error": msg, "results": {}}
    answer["wall_s"] = time.perf_counter() - t0
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:  # noqa: BLE001
        pass
    os.dup2(saved_err, 1)
    os.dup2(saved_err, 2)
    return answer


_LIMITED = [False]


def _run_inline(req, fn, saved_err):
    """--reuse-process: the case in the server itself (its time limit is the rank's: it kills the server)."""
    if req.get("memory_mb") and not _LIMITED[0]:
        lim = int(req["memory_mb"] * 1024 * 1024)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
        _LIMITED[0] = True
    return _run_case(req, fn, saved_err, set_limit=False)


class _Spare:
    """A child forked ahead of its case, waiting for the request on a pipe."""

    def __init__(self, fns, keep_fds, saved_err):
        gc.freeze()  # the server's objects out of the collector's sight: a case's collections do not touch
        # (copy) their pages
        req_r, self.req_w = os.pipe()
        self.ans_r, ans_w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the case process
            code = 0
            try:
                os.setpgid(0, 0)  # its own process group: a time limit kills what the case started too
                _pdeathsig()
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                for fd in (self.req_w, self.ans_r, *keep_fds):
                    os.close(fd)
                req = _recv(req_r)
                if req is not None:
                    key = (req["engine"], req["study_dir"])
                    fn = fns.get(key)
                    if fn is None:
                        from cases.lib.evaluators import resolve_evaluator  # lazy: see the module doc

                        fn = resolve_evaluator(*key).fn
                    _send(ans_w, _run_case(req, fn, saved_err))
            except BaseException:  # noqa: BLE001 - the server sees a death
                code = 70
            os._exit(code)
        os.close(req_r)
        os.close(ans_w)
        self.pid = pid
        try:
            os.setpgid(pid, pid)  # here too: the group exists before any kill
        except OSError:
            pass

    def start(self, req):
        _send(self.req_w, req)
        os.close(self.req_w)
        self.req_w = None

    def cancel(self):
        if self.req_w is not None:
            os.close(self.req_w)  # the spare reads EOF and exits
        os.close(self.ans_r)
        os.waitpid(self.pid, 0)

    def kill(self):
        for f in (os.killpg, os.kill):
            try:
                f(self.pid, signal.SIGKILL)
            except OSError:
                pass

    def wait(self, timeout, mem):
        """The answer of the case (its time limit enforced)."""
        t0 = time.perf_counter()
        deadline = None if timeout is None else t0 + timeout
        chunks = []
        timed_out = False
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.perf_counter())
            ready, _, _ = select.select([self.ans_r], [], [], wait)
            if not ready:
                timed_out = True
                break
            b = os.read(self.ans_r, 1 << 16)
            if not b:
                break
            chunks.append(b)
        os.close(self.ans_r)
        data = b"".join(chunks)
        complete = len(data) >= _HDR.size and len(data) == _HDR.size + _HDR.unpack(data[:_HDR.size])[0]
        if timed_out or complete:
            self.kill()  # the group, before the case is reaped (its pid cannot have been reused yet)
            os.waitpid(self.pid, 0)
            if timed_out:
                return {"status": "timeout", "error": f"time limit of {timeout:g} s exceeded (killed)",
                        "wall_s": time.perf_counter() - t0}
            return pickle.loads(data[_HDR.size:])
        _, status = os.waitpid(self.pid, 0)
        try:
            os.killpg(self.pid, signal.SIGKILL)  # anything the case left running
        except OSError:
            pass
        why = _exit_reason(-os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status))
        if mem:
            why += f" (memory limit {mem:g} MB per case)"
        return {"status": "died", "error": f"case process {why}"}


def main():
    """Read requests on stdin, run each in a fresh child, answer on (the original) stdout, in order."""
    _pdeathsig()
    if str(os.getppid()) != os.environ.get("ROCKDEM_STUDY_PARENT", str(os.getppid())):
        os._exit(1)
    fin, fout = os.dup(0), os.dup(1)
    devnull = os.open(os.devnull, os.O_RDWR)
    os.dup2(devnull, 0)
    os.dup2(2, 1)
    saved_err = os.dup(2)
    fns = {}
    spare = None
    try:
        while True:
            req = _recv(fin)
            if req is None:
                return 0
            key = (req["engine"], req["study_dir"])
            if key not in fns:
                from cases.lib.evaluators import resolve_evaluator  # lazy: see the module doc

                ev = resolve_evaluator(*key)
                fns[key] = ev.fn
                if spare is not None:  # forked before this evaluator was known
                    spare.cancel()
                    spare = None
                if ev.warm is not None:  # one-off work (kernel compilation) that every forked case then inherits
                    Path(req["case_dir"]).mkdir(parents=True, exist_ok=True)
                    warm_scene = Path(req["case_dir"]) / "scene.toml"
                    warm_scene.write_text(req["scene_text"])
                    os.dup2(devnull, 1)
                    os.dup2(devnull, 2)
                    try:
                        ev.warm(warm_scene)
                    except Exception:  # noqa: BLE001 - the case itself reports what is wrong
                        pass
                    finally:
                        sys.stdout.flush()
                        sys.stderr.flush()
                        os.dup2(saved_err, 1)
                        os.dup2(saved_err, 2)
                _send(fout, {"warmed": True})  # the rank starts the case's clock now (compilation is not the case's)
            sys.stdout.flush()
            sys.stderr.flush()
            if req.get("reuse"):  # --reuse-process: the case runs here (no fork); its state stays for the next
                _send(fout, _run_inline(req, fns[key], saved_err))
                continue
            case = spare if spare is not None else _Spare(fns, (fin, fout), saved_err)
            case.start(req)
            spare = _Spare(fns, (fin, fout), saved_err)  # forked while the case runs
            _send(fout, case.wait(req.get("timeout"), req.get("memory_mb")))
    finally:
        if spare is not None:
            spare.cancel()


if __name__ == "__main__":
    sys.exit(main())
