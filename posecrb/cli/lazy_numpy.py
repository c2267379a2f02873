"""Start-up of the command line: four numpy submodules that scipy imports and no command uses load
lazily (docs/decisions/import-hook.md).

scipy >= 1.15 builds its array-API namespace (``scipy._lib.array_api_compat.numpy``, imported by
``scipy.sparse``) by cloning ``numpy``'s public names, which imports every submodule listed in
``numpy.__all__``: ``numpy.f2py`` (a Fortran wrapper generator), ``numpy.testing`` (unittest,
importlib.metadata), ``numpy.ma`` and ``numpy.polynomial``. Every command that needs scipy.sparse
(bounds, solve, fim, crlb, select, timeline, tables, experiments) paid for them, a noticeable
share of a small ``bounds`` or ``solve`` (docs/decisions/import-hook.md), although none uses them;
our own lazy imports cannot avoid it (the cost is inside ``import scipy.sparse``). ``numpy.unique``
without counts consults ``numpy.ma``: the readers avoid it, other paths simply load it then.

The remedy is importlib's documented lazy loading: a meta-path finder that gives those four modules
an ``importlib.util.LazyLoader``, so they are real modules that execute on first attribute access.
Only ``posecrb.cli.main`` installs it: importing posecrb as a library changes nothing in the
caller's interpreter.
"""
from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
from collections.abc import Sequence

UNUSED_AT_START = frozenset({"numpy.f2py", "numpy.testing", "numpy.polynomial", "numpy.ma"})


class DeferredImport(importlib.abc.MetaPathFinder):
    """Import finder that loads the named modules lazily (on first attribute access)."""

    def __init__(self, names: frozenset[str]) -> None:
        self.names = names

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: types.ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in self.names:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        spec.loader = importlib.util.LazyLoader(spec.loader)
        return spec


def defer_unused_imports() -> None:
    """Install the finder (once) for ``UNUSED_AT_START``."""
    if not any(isinstance(finder, DeferredImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, DeferredImport(UNUSED_AT_START))


__all__ = ["UNUSED_AT_START", "DeferredImport", "defer_unused_imports"]
