"""Suite-wide set-up: a whole-suite session first fills numba's kernel cache on both cores (tests/warm_kernels.py),
and the tests that need both cores to themselves are marked ``serial``.

``./go test`` without arguments runs the suite in two parts: ``-n 2 -m "not serial"`` (pytest-xdist, one worker
per core), then ``-m serial`` alone. Serial are the modules that start two processes of their own (mpirun -n 2,
LIGGGHTS on two ranks, the fuzz test's two workers, the portability test's compiles) or assert a wall-clock
limit (a time limit that must cut a run, a real process that must refuse within seconds): beside another
worker, MPI ranks that poll for messages wait for a core, and a wall-clock bound measures the neighbour.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
WHOLE_SUITE = 200  # tests collected: below this (one file, -k), the tests compile what they need themselves
SERIAL = {"test_study", "test_fuzz", "test_portability", "test_adapters_liggghts", "test_corrupt_files",
          "test_adapters_cli", "test_adapters_yade", "test_crossval", "test_liggghts_walls", "test_limits"}


def pytest_configure(config):
    config.addinivalue_line("markers", "serial: needs both cores to itself (./go test runs it after the rest)")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if Path(str(item.fspath)).stem in SERIAL:
            item.add_marker("serial")


def _xdist_worker():
    return "PYTEST_XDIST_WORKER" in os.environ


def pytest_sessionstart(session):
    # under -n the controller collects nothing: for the whole suite (no paths given) it warms the cache once,
    # before the workers start their tests
    opt = session.config.option
    if getattr(opt, "numprocesses", None) and not opt.file_or_dir and not _xdist_worker():
        _warm()


def pytest_collection_finish(session):
    if len(session.items) >= WHOLE_SUITE and not _xdist_worker():
        _warm()


def _warm():
    if os.environ.get("ROCKDEM_NO_WARM"):
        return
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rockdem-warm-") as tmp:
        procs = {}
        for half in ("sgim", "dda"):
            work = Path(tmp) / half
            work.mkdir()
            procs[half] = subprocess.Popen([sys.executable, str(HERE / "warm_kernels.py"), half, str(work)],
                                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        failed = {h: p.communicate()[0] for h, p in procs.items() if p.wait() != 0}
    # a failing warm-up is not a result: the tests that use those kernels run them and report
    note = "; ".join(f"{h} half failed: {out.strip().splitlines()[-1] if out.strip() else '?'}"
                     for h, out in failed.items())
    print(f"\nnumba kernels compiled or loaded on both cores in {time.perf_counter() - t0:.1f} s"
          + (f" ({note})" if note else ""), file=sys.stderr)
