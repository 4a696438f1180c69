"""The helpers every stage's ``cli.py`` uses: the parser with the project's
error convention, :func:`run`, option parsers, progress and output checks.

A stage's ``cli.py`` builds its parser with :func:`make_parser`, adds verbs
with :func:`add_verb`, and returns :func:`run`; the ``lumigraph`` dispatcher
itself is :mod:`lumigraph.command` (the shell, on top of every stage).

Exit status (DESIGN §5): 0 success; 2 bad input or usage, with one line
``error: <file>: <problem>`` on stderr (traceback only with ``--debug``);
1 an internal fault.

Examples
--------
>>> p = make_parser("demo", "A demo command.")
>>> p.add_argument("--n", type=int, default=1)  # doctest: +ELLIPSIS
_StoreAction(...)
>>> p.set_defaults(func=lambda args: print("n =", args.n))
>>> run(p, ["--n", "3"])
n = 3
0
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Iterable, Sequence
from pathlib import Path

from lumigraph.capture.errors import EstimationError, InputError

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error and exit status 2."""

    def error(self, message):  # noqa: D401 - argparse API
        sys.stderr.write(f"error: {self.prog}: {message} (see '{self.prog} --help')\n")
        raise SystemExit(EXIT_USAGE)


def make_parser(prog: str, description: str, *, epilog: str | None = None) -> argparse.ArgumentParser:
    """An ArgumentParser with the shared options ``--quiet`` and ``--debug``.

    ``description`` and ``epilog`` keep their line breaks, so a stage's
    ``--help`` can teach with examples.
    """
    p = _Parser(prog=prog, description=description, epilog=epilog,
                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_common(p)
    return p


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", "-q", action="store_true", help="no progress output")
    p.add_argument("--debug", action="store_true", help="show tracebacks for errors")


def subparsers(p: argparse.ArgumentParser, *, title: str = "verbs"):
    """A verbs sub-parser group whose parsers share the project's parser class."""
    sp = p.add_subparsers(title=title, dest="verb", metavar="VERB", parser_class=_Parser)
    sp.required = True
    return sp


def add_verb(sp, name: str, help: str, *, description: str | None = None,
             epilog: str | None = None) -> argparse.ArgumentParser:
    """Add a verb with the shared options and the project's help formatting."""
    v = sp.add_parser(name, help=help, description=description or help, epilog=epilog,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    add_common(v)
    return v


def argument_flags(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """Library argument name -> the command-line flag that sets it.

    Library errors name the function's argument (``smoothness``,
    ``exposure_times_s``), never a flag; only the command line knows its
    flags. Every option of the parser and of the verbs chosen in ``args``
    maps its ``dest`` to its first long flag; a verb adds the names that
    differ from its dests with ``set_defaults(arg_flags={"exposure_times_s":
    "--times"})``.

    Examples
    --------
    >>> p = make_parser("t", "t")
    >>> _ = p.add_argument("--pixel-sigma", type=float)
    >>> p.set_defaults(arg_flags={"exposure_times_s": "--times"})
    >>> flags = argument_flags(p, p.parse_args([]))
    >>> flags["pixel_sigma"], flags["exposure_times_s"]
    ('--pixel-sigma', '--times')
    """
    flags: dict[str, str] = {}
    todo = [parser]
    while todo:
        p = todo.pop()
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                chosen = getattr(args, a.dest, None) if a.dest != argparse.SUPPRESS else None
                if chosen in a.choices:
                    todo.append(a.choices[chosen])
            elif a.option_strings and a.dest not in ("help",):
                longs = [o for o in a.option_strings if o.startswith("--")]
                flags.setdefault(a.dest, (longs or a.option_strings)[0])
    flags.update(getattr(args, "arg_flags", None) or {})
    return flags


def run(parser: argparse.ArgumentParser, argv: Sequence[str] | None, *,
        allow_extra: bool = False) -> int:
    """Parse ``argv`` and call ``args.func(args)`` under the error convention.

    With ``allow_extra`` unknown ``--name VALUE`` pairs are kept, unparsed, in
    ``args.extra`` (for options only known once a positional is, such as a
    scene's own options). An :class:`InputError` or :class:`EstimationError`
    whose ``where`` names a library argument is reported under the flag that
    sets it (:func:`argument_flags`).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if allow_extra:
            args, extra = parser.parse_known_args(argv)
            args.extra = extra
        else:
            args = parser.parse_args(argv)
    except SystemExit as e:
        return int(e.code or 0)
    debug = getattr(args, "debug", False) or "--debug" in argv
    try:
        rc = args.func(args)
        return EXIT_OK if rc is None else int(rc)
    except (InputError, EstimationError) as e:
        if debug:
            traceback.print_exc()
        where = argument_flags(parser, args).get(e.where, e.where)
        sys.stderr.write(f"error: {where}: {e.problem}\n")
        return EXIT_USAGE
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted; nothing half-written was left behind\n")
        return 130
    except Exception as e:  # an internal fault: say so, and how to see more
        if debug:
            traceback.print_exc()
        else:
            sys.stderr.write(f"error: internal: {type(e).__name__}: {e} "
                             "(rerun with --debug for the traceback, and report it)\n")
        return EXIT_INTERNAL


def parse_floats(text: str, *, name: str) -> list[float]:
    """``"1/30,0.1,2"`` -> floats; fractions allowed (exposure times)."""
    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            if "/" in part:
                a, b = part.split("/")
                out.append(float(a) / float(b))
            else:
                out.append(float(part))
        except (ValueError, ZeroDivisionError):
            raise InputError(name, f"cannot read {part!r} as a number") from None
    return out


def parse_size(text: str, *, name: str = "--size",
               limits: tuple[int, int] | None = (8, 20000)) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)`` (width, height), each side within
    ``limits``; ``limits=None`` only parses, for a library function that checks
    the size itself (``lumigraph.capture.render.render``)."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise InputError(name, f"expected WIDTHxHEIGHT such as 640x480, got {text!r}") from None
    if limits is not None:
        lo, hi = limits
        if w < lo or h < lo or w > hi or h > hi:
            raise InputError(name, f"impossible size {w}x{h}; each side must be {lo}..{hi} pixels")
    return w, h


def show_progress(quiet: bool) -> bool:
    """Progress bars only on a terminal, and never with ``--quiet``."""
    return not quiet and sys.stderr.isatty()


def progress(items: Iterable, *, total: int | None = None, description: str = "",
             quiet: bool = False) -> Iterable:
    """Iterate ``items`` with a rich progress bar on a terminal, silently otherwise."""
    if not show_progress(quiet):
        yield from items
        return
    from rich.progress import Progress

    with Progress(transient=True) as bar:
        task = bar.add_task(description, total=total)
        for item in items:
            yield item
            bar.advance(task)


def say(args, message: str) -> None:
    """An informational line on stderr, unless ``--quiet``."""
    if not getattr(args, "quiet", False):
        sys.stderr.write(message + "\n")


def warn(message: str) -> None:
    """A warning line on stderr (always shown)."""
    sys.stderr.write(f"warning: {message}\n")


def check_output_path(out: str | os.PathLike, *, suffixes: Iterable[str] | None = None) -> Path:
    """Validate an ``--out`` path before any work is done."""
    p = Path(out)
    if suffixes is not None:
        suffixes = tuple(suffixes)
        if p.suffix.lower() not in suffixes:
            raise InputError("--out", f"{p}: expected a file ending in {' or '.join(suffixes)}")
    if p.exists() and p.is_dir() and suffixes is not None:
        raise InputError("--out", f"{p} is a folder, expected a file name")
    return p


def check_output_dir(out: str | os.PathLike) -> Path:
    """Validate an ``--out`` folder before any work is done: it may exist, but
    as a folder."""
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise InputError("--out", f"{p} exists and is not a folder")
    return p
