"""Where the numba kernels' compiled code is cached: one folder per version of the kernels' source.

numba's own cache (``cache=True``) is invalidated when the file that defines a kernel changes, but not when a
kernel it calls from another file changes: the caller's cached machine code keeps the old callee. After an
edit or an upgrade of ``dda/_fcp.py``, say, the block engine's step kernel in ``dda/_integrate.py`` would go
on with the old contact points, and two machines (or a warm and a cold cache) would compute different results
from the same source. So the cache folder is keyed by a hash of every Python file of the packages whose
kernels call each other (sgim, dda) that use numba: any change to any of them starts a new cache.

The folder is ``$NUMBA_CACHE_DIR/numba-HASH`` when NUMBA_CACHE_DIR is set, else
``${XDG_CACHE_HOME:-~/.cache}/rockdem/numba-HASH``; the four most recently used folders are kept. ``configure``
runs when ``sgim`` or ``dda`` is imported, before any kernel module, and sets NUMBA_CACHE_DIR for numba (and
for the subprocesses the tools start, which then use the same folder).
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

_PACKAGES = ("sgim", "dda")
_KEEP = 4
_done = False


def source_hash() -> str:
    """sha1 (12 hex digits) of the Python files of sgim and dda that use numba, in a fixed order."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha1()
    for pkg in _PACKAGES:
        for f in sorted((root / pkg).glob("*.py")):
            text = f.read_bytes()
            if b"numba" in text:
                h.update(f"{pkg}/{f.name}\0".encode())
                h.update(text)
    return h.hexdigest()[:12]


def cache_dir() -> Path:
    """The cache folder of this source version (see the module docstring)."""
    cur = os.environ.get("NUMBA_CACHE_DIR")
    ours = os.environ.get("ROCKDEM_NUMBA_CACHE_BASE")
    if cur and ours and Path(cur).parent == Path(ours) and Path(cur).name.startswith("numba-"):
        base = Path(ours)  # set by configure in the process that started this one
    elif cur:
        base = Path(cur)
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "rockdem"
    return base / f"numba-{source_hash()}"


def _prune(folder: Path):
    """Remove all but the _KEEP most recently used sibling cache folders of other source versions."""
    try:
        sibs = [p for p in folder.parent.iterdir() if p.is_dir() and p.name.startswith("numba-") and p != folder]
        sibs.sort(key=lambda p: p.stat().st_mtime, reverse=True)
        for p in sibs[_KEEP - 1:]:
            shutil.rmtree(p, ignore_errors=True)
    except OSError:
        pass


def configure():
    """Point numba's cache at the folder of this source version (idempotent)."""
    global _done
    if _done:
        return
    _done = True
    folder = cache_dir()
    try:
        new = not folder.exists()
        folder.mkdir(parents=True, exist_ok=True)
        os.utime(folder)
        if new:
            _prune(folder)
    except OSError:
        return  # an unwritable place: numba keeps its own default
    os.environ["ROCKDEM_NUMBA_CACHE_BASE"] = str(folder.parent)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # numba read its configuration at import: set it there too
        from numba.core import config  # only when numba is already loaded (this module must not load it)

        config.CACHE_DIR = str(folder)
