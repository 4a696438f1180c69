"""Exceptions that carry a user-facing reason.

The command line turns :class:`InputError` and :class:`EstimationError` into
exit status 2 and one line ``error: <file>: <problem>`` (an
:class:`EstimationError`'s ``details`` follow it, indented); anything else is an
internal fault (exit 1). Both are ``ValueError`` subclasses, so library callers
can catch them the ordinary way.
"""

from __future__ import annotations

import os


class InputError(ValueError):
    """Bad input or bad usage: a file that is missing, unreadable, truncated, of
    the wrong kind or inconsistent with the others, or an option out of range.

    Parameters
    ----------
    where : str or os.PathLike
        The file (or, for an option, ``--name``) the problem is about.
    problem : str
        What is wrong and, where there is one, what to do about it.

    Examples
    --------
    >>> str(InputError("a.png", "not found"))
    'a.png: not found'
    """

    def __init__(self, where: str | os.PathLike, problem: str):
        self.where = os.fspath(where)
        self.problem = problem
        super().__init__(f"{self.where}: {problem}")


class EstimationError(ValueError):
    """A fit or reconstruction that the data cannot support (degenerate views,
    too few valid pixels, no convergence). ``where`` names the input;
    ``details``, lines the command line prints after its one line (what to do
    about it, item by item: a refused solve's edges to mark).

    >>> e = EstimationError("edges.json", "too few marks", details=("mark photo_00.png's roof",))
    >>> str(e), e.details
    ('edges.json: too few marks', ("mark photo_00.png's roof",))
    """

    def __init__(self, where: str | os.PathLike, problem: str, *, details=()):
        self.where = os.fspath(where)
        self.problem = problem
        self.details = tuple(details)
        super().__init__(f"{self.where}: {problem}")


class UnusableResult(Exception):
    """The work ran but its result cannot be used (an SfM that registered too
    few views): the command line exits 3 with one line ``error: <where>:
    <problem>`` and writes nothing. ``where`` names the input."""

    def __init__(self, where: str | os.PathLike, problem: str):
        self.where = os.fspath(where)
        self.problem = problem
        super().__init__(f"{self.where}: {problem}")


def caused_by_interrupt(exc: BaseException | None) -> bool:
    """True when ``exc`` is a ``KeyboardInterrupt`` or was raised while handling
    one: a Ctrl-C during an import can surface as the ``RuntimeError`` (or
    ``ImportError``) that wraps it, and is still the user's interrupt.

    Examples
    --------
    >>> try:
    ...     try:
    ...         raise KeyboardInterrupt
    ...     except KeyboardInterrupt as k:
    ...         raise RuntimeError("Error calling __set_name__") from k
    ... except RuntimeError as e:
    ...     caused_by_interrupt(e)
    True
    >>> caused_by_interrupt(ValueError("x"))
    False
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False
