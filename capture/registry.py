"""Method registries: one shape for every ``--method`` choice in lumigraph.

A stage that offers a choice of methods keeps one :class:`Registry` of
:class:`Method` entries: the name the command line accepts, the callable it
runs (a ``"module:attribute"`` string imported on first use, so listing the
choices for ``--help`` stays cheap), a one-line help, the keyword options the
method understands, and the fixed keyword arguments the name implies (two
names may run one function in two modes). The CLI's ``choices`` and its help
text are generated from the registry, so they cannot drift from what exists.

Examples
--------
>>> reg = Registry("rounding", [
...     Method("floor", "math:floor", "round down"),
...     Method("ceil", "math:ceil", "round up"),
... ])
>>> reg.names
('floor', 'ceil')
>>> reg["ceil"](2.1)
3
>>> reg.resolve("nearest")
Traceback (most recent call last):
...
lumigraph.capture.errors.InputError: method: unknown rounding method 'nearest'; choose from floor, ceil
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from lumigraph.capture.errors import InputError


@dataclass(frozen=True)
class Method:
    """One registered method.

    Parameters
    ----------
    name : str
        The name the command line and the library accept (``"mitsunaga-nayar"``).
    target : str
        ``"package.module:attribute"`` of the callable, imported on first use.
    help : str
        One line for ``--help``.
    options : tuple of str
        The keyword options the method understands (for help and checks).
    bound : mapping
        Keyword arguments this name always passes (``{"mode": "local"}``);
        a caller's own keyword of the same name is refused.
    """

    name: str
    target: str
    help: str
    options: tuple[str, ...] = ()
    bound: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if ":" not in self.target:
            raise ValueError(f"target: expected 'module:attribute', got {self.target!r}")
        object.__setattr__(self, "options", tuple(self.options))
        object.__setattr__(self, "bound", MappingProxyType(dict(self.bound)))

    def load(self) -> Callable[..., Any]:
        """The callable itself (imports its module)."""
        module, attr = self.target.split(":")
        return getattr(importlib.import_module(module), attr)

    def __call__(self, *args, **kwargs):
        clash = sorted(set(kwargs) & set(self.bound))
        if clash:
            raise TypeError(f"{self.name}: {', '.join(clash)} is fixed by the method name")
        return self.load()(*args, **{**self.bound, **kwargs})


class Registry(Mapping[str, Method]):
    """An ordered, read-only ``name -> Method`` mapping for one kind of method.

    ``kind`` names what is chosen (``"response"``, ``"flow"``) in messages.
    """

    def __init__(self, kind: str, methods: Iterable[Method]):
        self.kind = kind
        self._methods: dict[str, Method] = {}
        for m in methods:
            if not isinstance(m, Method):
                raise TypeError(f"methods: expected Method entries, got {type(m).__name__}")
            if m.name in self._methods:
                raise ValueError(f"methods: {m.name!r} registered twice for {kind}")
            self._methods[m.name] = m

    def __getitem__(self, name: str) -> Method:
        return self._methods[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._methods)

    def __len__(self) -> int:
        return len(self._methods)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {list(self._methods)})"

    @property
    def names(self) -> tuple[str, ...]:
        """The names, in registration order (the CLI's ``choices``)."""
        return tuple(self._methods)

    def resolve(self, name: str, *, argument: str = "method") -> Method:
        """The method registered as ``name``; :class:`InputError` naming
        ``argument`` and listing the choices otherwise."""
        try:
            return self._methods[name]
        except (KeyError, TypeError):
            raise InputError(argument, f"unknown {self.kind} method {name!r}; choose from "
                                       f"{', '.join(self._methods)}") from None

    def help_text(self, *, indent: str = "  ") -> str:
        """One line per method, for a ``--help`` epilog."""
        width = max((len(n) for n in self._methods), default=0)
        return "\n".join(f"{indent}{m.name:<{width}}  {m.help}" for m in self._methods.values())
