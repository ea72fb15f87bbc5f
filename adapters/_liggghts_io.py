"""LIGGGHTS files and process: the data file, full-precision dumps, and an engine driven through stdin.

``write_data`` writes a LIGGGHTS data file (``atom_style hybrid granular molecular``: ``id type x y z diameter
density molecule``) with an optional ``Bond Coeffs`` + ``Bonds`` section (one bond type per bond);
``read_dump`` reads a ``write_dump ... custom`` text file written with %.17g; ``Driver`` runs LIGGGHTS (or
mpirun + LIGGGHTS) with its input on a pipe, so that a runner can send commands, wait for a marker line that a
LIGGGHTS ``print`` writes, look at the state, and continue.
"""
from __future__ import annotations

import os
import re
import selectors
import subprocess
import time

import numpy as np

from .process import ProcessOutcome, die_with_parent, error_line, kill_group

DUMP_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz")
DUMP_FORMAT = " ".join(["%d"] + ["%.17g"] * (len(DUMP_COLUMNS) - 1))
MARK = "@@ROCKDEM"
_MARK_RE = re.compile(r"^@@ROCKDEM (\d+) (\d+)\s*$")


def _write_rows(fh, fmt, cols, chunk=100_000):
    """Rows of the columns `cols` formatted with `fmt` (one %-format for a whole row), in chunks."""
    n = len(cols[0]) if cols else 0
    for s in range(0, n, chunk):
        rows = zip(*(c[s:s + chunk].tolist() for c in cols))
        fh.write("".join(fmt % r for r in rows))


def write_data(path, centers, radii, density, types, mol, n_types, box, bonds=None, title="rockdem"):
    """LIGGGHTS data file. `bonds`: None or (i, j, K, r0) arrays (0-based sphere indices; bond k gets type
    k + 1 with harmonic coefficients K, r0)."""
    n = len(radii)
    nb = 0 if bonds is None else len(bonds[0])
    with open(path, "w") as fh:
        fh.write(f"LIGGGHTS data file: {title}\n\n{n} atoms\n{n_types} atom types\n")
        if bonds is not None:
            fh.write(f"{nb} bonds\n{max(nb, 1)} bond types\n")
        for a, ax in enumerate("xyz"):
            fh.write(f"{box[0][a]:.17g} {box[1][a]:.17g} {ax}lo {ax}hi\n")
        if bonds is not None:
            fh.write("\nBond Coeffs\n\n")
            if nb:
                bi, bj, K, r0 = bonds
                _write_rows(fh, "%d %.17g %.17g\n", [np.arange(1, nb + 1), np.asarray(K, float),
                                                      np.asarray(r0, float)])
            else:
                fh.write("1 0 1\n")
        fh.write("\nAtoms\n\n")
        c = np.asarray(centers, float)
        _write_rows(fh, "%d %d %.17g %.17g %.17g %.17g %.17g %d\n",
                    [np.arange(1, n + 1), np.asarray(types, np.int64), c[:, 0], c[:, 1], c[:, 2],
                     2.0 * np.asarray(radii, float), np.broadcast_to(np.asarray(density, float), (n,)),
                     np.asarray(mol, np.int64)])
        if bonds is not None and nb:
            bi, bj, K, r0 = bonds
            fh.write("\nBonds\n\n")
            ids = np.arange(1, nb + 1)
            _write_rows(fh, "%d %d %d %d\n", [ids, ids, np.asarray(bi, np.int64) + 1, np.asarray(bj, np.int64) + 1])


def read_dump(path):
    """(ids (n,), values (n, 9): x y z vx vy vz omegax omegay omegaz) of a custom text dump."""
    with open(path, "rb") as fh:
        head = [fh.readline() for _ in range(9)]
        if not head[0].startswith(b"ITEM: TIMESTEP"):
            raise ValueError(f"{path}: not a LIGGGHTS dump")
        n = int(head[3])
        cols = head[8].split()[2:]
        body = fh.read()
    vals = np.array(body.split(), dtype=float)
    if vals.size != n * len(cols):
        raise ValueError(f"{path}: truncated dump ({vals.size} values for {n} atoms x {len(cols)} columns)")
    vals = vals.reshape(n, len(cols))
    return vals[:, 0].astype(np.int64), vals[:, 1:]


class DriverError(RuntimeError):
    """The engine stopped (exit or time limit) before the awaited marker; ``outcome`` says how."""

    def __init__(self, outcome: ProcessOutcome):
        super().__init__(outcome.error_line or "engine stopped")
        self.outcome = outcome


class Driver:
    """An engine process reading its input from a pipe; merged stdout/stderr copied to `log`.

    ``send(lines)`` writes commands; ``wait_mark(k, deadline)`` reads output until the line ``@@ROCKDEM k N``
    (from a LIGGGHTS ``print``) and returns N; ``close(deadline)`` ends the input and waits for the exit."""

    def __init__(self, cmd, cwd, log, env=None, on_line=None):
        full_env = dict(os.environ, OMPI_MCA_rmaps_base_oversubscribe="1")
        full_env.update(env or {})
        self.t0 = time.perf_counter()
        self.log = open(log, "w")
        self.on_line = on_line
        self.tail = []
        self.buf = b""
        self.eof = False
        self.timed_out = False
        self.proc = subprocess.Popen(cmd, cwd=str(cwd), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, env=full_env, start_new_session=True, bufsize=0,
                                     preexec_fn=die_with_parent)
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.proc.stdout, selectors.EVENT_READ)

    def send(self, lines):
        try:
            self.proc.stdin.write(("\n".join(lines) + "\n").encode())
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):
            pass  # the engine is gone: the next wait reports why

    def _line(self, line):
        self.log.write(line + "\n")
        self.tail.append(line)
        if len(self.tail) > 400:
            del self.tail[:-200]
        if self.on_line:
            self.on_line(line)

    def _read(self, deadline):
        """Read what is available (up to 1 s); returns the new complete lines. Sets eof / timed_out."""
        left = None if deadline is None else deadline - time.perf_counter()
        if left is not None and left <= 0:
            self.timed_out = True
            return []
        events = self.sel.select(timeout=min(left, 1.0) if left is not None else 1.0)
        if not events:
            if self.proc.poll() is not None:
                # drain what is left
                try:
                    chunk = os.read(self.proc.stdout.fileno(), 1 << 20)
                except OSError:
                    chunk = b""
                if not chunk:
                    self.eof = True
                    return self._split(final=True)
                self.buf += chunk
                return self._split()
            return []
        chunk = os.read(self.proc.stdout.fileno(), 1 << 20)
        if not chunk:
            self.eof = True
            return self._split(final=True)
        self.buf += chunk
        return self._split()

    def _split(self, final=False):
        *lines, self.buf = self.buf.split(b"\n")
        if final and self.buf:
            lines.append(self.buf)
            self.buf = b""
        out = [raw.decode("utf-8", "replace") for raw in lines]
        for line in out:
            self._line(line)
        self.log.flush()
        return out

    def wait_mark(self, k, deadline):
        while True:
            for line in self._read(deadline):
                m = _MARK_RE.match(line.strip())
                if m and int(m.group(1)) == k:
                    return int(m.group(2))
            if self.eof or self.timed_out:
                raise DriverError(self.finish())

    def finish(self, kill=None):
        """Stop (kill the group on a time limit), wait for the exit; the ProcessOutcome."""
        if kill or self.timed_out:
            kill_group(self.proc)
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            rc = self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            kill_group(self.proc)
            rc = self.proc.wait()
        while not self.eof:
            self._read(time.perf_counter() + 1.0)
            if self.timed_out:
                break
        self.sel.close()
        try:
            self.proc.stdout.close()
        except OSError:
            pass
        self.log.close()
        return ProcessOutcome(rc=rc, timed_out=bool(self.timed_out or kill), wall_s=time.perf_counter() - self.t0,
                              error_line=error_line(self.tail), tail=self.tail[-200:])

    def close(self, deadline):
        """End the input (the engine exits at end of input) and wait; the ProcessOutcome."""
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        while not self.eof:
            self._read(deadline)
            if self.timed_out:
                break
        return self.finish()
