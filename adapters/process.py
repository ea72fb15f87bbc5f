"""Engine subprocesses: found on PATH, run unbuffered with a time limit, their error line surfaced as ours.

``run_process(cmd, cwd, log, timeout)`` runs one engine process in its own process group (killed by the
kernel if the caller dies: ``die_with_parent``), copies its merged
stdout/stderr to ``log`` line by line (and to ``on_line``), kills the whole group when the time limit passes,
and returns a :class:`ProcessOutcome` (exit status, timed out, wall time, the engine's error line).
"""
from __future__ import annotations

import os
import re
import selectors
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass

ENGINES = {"yade": "yade", "liggghts": "liggghts", "mpirun": "mpirun"}
# lines that carry an engine's own error message: LIGGGHTS/LAMMPS "ERROR: ...", a Python exception line
# (YADE scripts), or our scripts' "FATAL: ..." lines
_ERROR = re.compile(r"^(ERROR( on proc \d+)?:.*|FATAL:.*|[A-Za-z_.]*(Error|Exception): .*)$")


class EngineError(RuntimeError):
    """An engine that is missing, failed or ran out of time (one line for the user); ``result`` keeps what
    the run wrote before it stopped (a RunResult marked incomplete, or None)."""

    def __init__(self, message, result=None):
        super().__init__(message)
        self.result = result


def die_with_parent():
    """Run in an engine's child process before exec: ask Linux to SIGKILL it when the process that started it
    dies (PR_SET_PDEATHSIG), so an engine never outlives a killed caller (a study case past its time limit,
    a killed rank). Elsewhere a no-op."""
    try:
        import ctypes  # Linux only: loaded where it is used

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def find_engine(name):
    """Absolute path of an engine executable, or EngineError naming what to install."""
    exe = shutil.which(ENGINES.get(name, name))
    if exe is None:
        pkg = {"mpirun": "openmpi-bin"}.get(name, name)
        raise EngineError(f"{name}: not found on PATH (install the Debian package '{pkg}', see README set-up)")
    return exe


@dataclass
class ProcessOutcome:
    rc: int
    timed_out: bool
    wall_s: float
    error_line: str
    tail: list

    @property
    def ok(self):
        return self.rc == 0 and not self.timed_out


def error_line(lines):
    """The engine's own error message among its output lines (the last one that looks like an error)."""
    for line in reversed(lines):
        s = line.strip()
        if _ERROR.match(s):
            return s
    return ""


def unbuffered(cmd):
    """`cmd` run with unbuffered stdio where stdbuf exists (LIGGGHTS errors on one rank never reach the log
    otherwise)."""
    sb = shutil.which("stdbuf")
    return [sb, "-o0", "-e0", *cmd] if sb else list(cmd)


def run_process(cmd, cwd, log, timeout=None, on_line=None, env=None):
    """Run `cmd` in `cwd`; merged output goes to the file `log` and each line to `on_line(line)`. Kills the
    process group after `timeout` seconds. Returns a ProcessOutcome (never raises for the engine's failures)."""
    t0 = time.perf_counter()
    tail = []
    full_env = dict(os.environ, PYTHONUNBUFFERED="1", OMPI_MCA_rmaps_base_oversubscribe="1")
    full_env.update(env or {})
    with open(log, "w") as fh:
        proc = subprocess.Popen(cmd, cwd=str(cwd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=full_env, start_new_session=True, bufsize=0,
                                preexec_fn=die_with_parent)
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        buf = b""
        timed_out = False
        while True:
            left = None if timeout is None else timeout - (time.perf_counter() - t0)
            if left is not None and left <= 0:
                timed_out = True
                break
            events = sel.select(timeout=min(left, 1.0) if left is not None else 1.0)
            if not events:
                if proc.poll() is not None:
                    break
                continue
            chunk = os.read(proc.stdout.fileno(), 65536)
            if not chunk:
                break
            buf += chunk
            *lines, buf = buf.split(b"\n")
            for raw in lines:
                line = raw.decode("utf-8", "replace")
                fh.write(line + "\n")
                tail.append(line)
                if on_line:
                    on_line(line)
            del tail[:-200]
            fh.flush()
        if timed_out:
            kill_group(proc)
        if buf:
            line = buf.decode("utf-8", "replace")
            fh.write(line + "\n")
            tail.append(line)
        rc = proc.wait()
        sel.close()
        proc.stdout.close()
    return ProcessOutcome(rc=rc, timed_out=timed_out, wall_s=time.perf_counter() - t0, error_line=error_line(tail),
                          tail=tail[-200:])


def kill_group(proc):
    """SIGTERM then SIGKILL the process group of `proc` (an engine and its MPI ranks)."""
    for sig, wait in ((signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue


def describe_failure(engine, outcome: ProcessOutcome, log):
    """One line for a failed engine run: its own error line, or the exit status and where the log is."""
    if outcome.timed_out:
        return f"{engine}: time limit of {outcome.wall_s:.0f} s exceeded (killed; log {log})"
    msg = outcome.error_line or (outcome.tail[-1].strip() if outcome.tail else "")
    return f"{engine}: exit status {outcome.rc}: {msg or 'no output'} (log {log})"


__all__ = ["EngineError", "ProcessOutcome", "die_with_parent", "find_engine", "run_process", "unbuffered", "kill_group",
           "describe_failure", "error_line"]
