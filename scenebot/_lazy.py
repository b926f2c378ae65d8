"""Lazy re-exports for packages whose modules import heavy libraries (OpenCV, pycolmap).

The workflow imports the config (and so each stage package's ``config`` module) at every
start; a package ``__init__`` that eagerly imported its algorithms would slow every
``snakemake`` call by about a second.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable


def lazy_getattr(package: str, modules: Iterable[str]) -> Callable[[str], object]:
    """A module ``__getattr__`` that finds ``name`` in ``modules`` on first use."""
    modules = tuple(modules)

    def __getattr__(name: str):
        for module in modules:
            mod = importlib.import_module(module)
            if hasattr(mod, name):
                return getattr(mod, name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
