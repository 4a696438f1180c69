"""Public names of a package, loaded on first use.

A stage's ``__init__`` lists the names a user may import from it, each with
the module that defines it, in one place; the module is imported only when the
name is first used, so ``import lumigraph.hdr`` stays cheap (``make`` starts
Python once per stage). After scikit-image's use of ``lazy_loader``.

Examples
--------
>>> __getattr__, __dir__, __all__ = attach("pkg", {"sqrt": "math", "pi": "math"})
>>> __all__
['pi', 'sqrt']
>>> __getattr__("sqrt")(16.0)
4.0
>>> __getattr__("tau")
Traceback (most recent call last):
...
AttributeError: module 'pkg' has no attribute 'tau'
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping


def attach(package: str, names: Mapping[str, str]
           ) -> tuple[Callable[[str], object], Callable[[], list[str]], list[str]]:
    """``(__getattr__, __dir__, __all__)`` for ``package``, whose public
    ``names`` map each name to the module (dotted path) that defines it."""
    names = dict(names)

    def __getattr__(name: str):
        if name in names:
            return getattr(importlib.import_module(names[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(names)

    return __getattr__, __dir__, sorted(names)
