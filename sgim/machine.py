"""What a result was computed on: CPU model, logical cores and the versions of the numerical stack.

Benchmarks print `machine_line()` at the top of their tables and store `machine_info()` under "machine" in
their JSON; `sgim build` and `dda run` write `machine_info()` into summary.json. Nothing here imports the
numerical packages: a version comes from the imported module when it is loaded, else from the installed
package's metadata.
"""
from __future__ import annotations

import os
import platform
import sys
from importlib import metadata

PACKAGES = ("numpy", "numba", "llvmlite", "scipy")


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo on Linux), else platform.processor(), else 'unknown CPU'."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() in ("model name", "Processor", "cpu model") and value.strip():
                    return " ".join(value.split())
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def package_version(name: str) -> str | None:
    """The version of an imported module, else of the installed distribution, else None."""
    mod = sys.modules.get(name)
    v = getattr(mod, "__version__", None) if mod is not None else None
    if v:
        return str(v)
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def machine_info() -> dict:
    """{"cpu", "cores" (logical), "platform", "python", "numpy", "numba", "llvmlite", "scipy"} (JSON-ready)."""
    info = {"cpu": cpu_model(), "cores": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version()}
    for name in PACKAGES:
        info[name] = package_version(name)
    return info


def machine_line(info: dict | None = None) -> str:
    """One line: 'CPU model, N cores, python X, numpy X, numba X, llvmlite X, scipy X'."""
    info = machine_info() if info is None else info
    cores = info.get("cores")
    parts = [info.get("cpu") or "unknown CPU", f"{cores} core{'s' if cores != 1 else ''}",
             f"python {info.get('python')}"]
    parts += [f"{name} {info[name]}" for name in PACKAGES if info.get(name)]
    return ", ".join(parts)
