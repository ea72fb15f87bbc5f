"""Suite-wide set-up: a whole-suite session first fills numba's kernel cache on both cores (tests/warm_kernels.py)."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
WHOLE_SUITE = 200  # tests collected: below this (one file, -k), the tests compile what they need themselves


def pytest_collection_finish(session):
    if len(session.items) < WHOLE_SUITE or os.environ.get("ROCKDEM_NO_WARM"):
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
