"""What produced a result: package versions and the machine, for ``run.json`` records."""
from __future__ import annotations

import os
import platform
import sys
from importlib.metadata import PackageNotFoundError, version

from .. import __version__

_DISTRIBUTIONS = ("numpy", "scipy", "pandas", "scikit-sparse", "numba", "click", "rich", "matplotlib",
                  "dask", "distributed")


def versions() -> dict[str, str]:
    """posecrb, Python and every installed dependency that can change a number or a timing."""
    out = {"posecrb": __version__, "python": sys.version.split()[0]}
    for dist in _DISTRIBUTIONS:
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            pass
    return out


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform()}
