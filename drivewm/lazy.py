"""Lazy public names of a stage package (PEP 562).

``drivewm --help`` imports every stage's ``commands`` module, and with it the stage package's
``__init__``. A package that exports names through :func:`lazy_exports` imports them on first use,
so building the parser pays for no PyTorch, OpenCV or simulator.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable


def lazy_exports(package: str, exports: dict[str, str]) -> Callable[[str], object]:
    """A module ``__getattr__`` giving ``name`` from ``exports[name]`` (a module path) when first asked."""

    def __getattr__(name: str) -> object:
        if name in exports:
            return getattr(importlib.import_module(exports[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
