"""The helpers every stage's ``cli.py`` uses: the parser with the project's
error convention, :func:`run`, option parsers, progress and output checks.

A stage's ``cli.py`` builds its parser with :func:`make_parser`, adds verbs
with :func:`add_verb`, and returns :func:`run`; the ``lumigraph`` dispatcher
itself is :mod:`lumigraph.command` (the shell, on top of every stage).

Exit status (DESIGN §5): 0 success; 2 bad input or usage, with one line
``error: <file>: <problem>`` on stderr (traceback only with ``--debug``);
1 an internal fault; 3 a result that cannot be used; 4 a batch
(:mod:`lumigraph.capture.batch`) in which some items failed, each named on
its own ``error: <item>: <reason>`` line while the others completed.

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
import contextlib
import errno
import math
import os
import re
import sys
import traceback
from collections.abc import Iterable, Sequence
from fractions import Fraction
from pathlib import Path

from lumigraph.capture.errors import (
    EstimationError,
    InputError,
    UnusableResult,
    caused_by_interrupt,
)

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_UNUSABLE, EXIT_PARTIAL = 0, 1, 2, 3, 4
EXIT_INTERRUPTED = 130
# Images over this many pixels are refused from their header, before decoding
# (a decompression bomb); --max-pixels or $LUMIGRAPH_MAX_PIXELS raise it.
DEFAULT_MAX_PIXELS = 2**28


class Number:
    """An argparse ``type`` for a finite number in a range, stated in ``--help``.

    ``lo``/``hi`` are inclusive bounds unless ``lo_open``/``hi_open``; NaN and
    infinities are refused. ``range_text`` is what ``--help`` shows and
    ``bad_examples()`` gives values outside the range (for the tests).

    Examples
    --------
    >>> positive = number(float, lo=0, lo_open=True)
    >>> positive("0.5"), positive.range_text
    (0.5, 'a number > 0')
    >>> positive("nan")
    Traceback (most recent call last):
    argparse.ArgumentTypeError: expected a number > 0, got 'nan'
    """

    def __init__(self, kind=float, *, lo=None, hi=None, lo_open=False, hi_open=False,
                 odd=False, allow=()):
        self.kind, self.lo, self.hi = kind, lo, hi
        self.lo_open, self.hi_open, self.odd = lo_open, hi_open, odd
        self.allow = tuple(allow)  # words accepted as they are ("auto")
        self.__name__ = "integer" if kind is int else "number"

    @property
    def range_text(self) -> str:
        noun = "an odd integer" if self.odd else ("an integer" if self.kind is int else "a number")
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.lo_open else '>='} {self.lo:g}")
        if self.hi is not None:
            parts.append(f"{'<' if self.hi_open else '<='} {self.hi:g}")
        text = f"{noun} {' and '.join(parts)}" if parts else noun
        if self.allow:
            text += " or " + " or ".join(self.allow)
        return text

    def __call__(self, text: str):
        if text in self.allow:
            return text
        try:
            if self.kind is int:
                v = int(text)
            else:
                v = float(Fraction(text)) if "/" in text else float(text)
        except (ValueError, ZeroDivisionError, TypeError):
            raise argparse.ArgumentTypeError(f"expected {self.range_text}, got {text!r}") from None
        if not math.isfinite(v) or not self.holds(v):
            raise argparse.ArgumentTypeError(f"expected {self.range_text}, got {text!r}")
        return v

    def holds(self, v) -> bool:
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            return False
        if self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)):
            return False
        return not (self.odd and v % 2 != 1)

    def bad_examples(self) -> list[str]:
        out = ["nan", "abc"] + ([] if self.kind is int else ["inf"])
        if self.kind is int:
            out.append("2.5")
        if self.lo is not None:
            out.append(f"{self.lo - (0 if self.lo_open else 1)}")
        if self.hi is not None:
            out.append(f"{self.hi + (0 if self.hi_open else 1)}")
        if self.odd:
            out.append(str(2 * int(self.lo or 1) + 2))
        return [b for b in out if b not in self.allow]  # "inf" is fine where allowed

    def __repr__(self):
        return f"number({self.range_text})"


def number(kind=float, **bounds) -> Number:
    """An argparse ``type``: a finite ``kind`` (int or float) within bounds
    (see :class:`Number`)."""
    return Number(kind, **bounds)


class NumberList:
    """An argparse ``type`` for ``"1,2,3"``: each item a :class:`Number`,
    ``length`` items (an int or ``(min, max)``), fractions allowed; negative
    numbers work as ``--slopes=-1,0,1`` or ``--slopes -1,0,1``."""

    def __init__(self, item: Number, *, length=None, increasing=False):
        self.item, self.length, self.increasing = item, length, increasing
        self.__name__ = "list"

    @property
    def range_text(self) -> str:
        if isinstance(self.length, int):
            n = f"{self.length} comma-separated values"
        elif self.length:
            lo, hi = self.length
            n = f"{lo}..{hi} comma-separated values" if hi else f"{lo} or more comma-separated values"
        else:
            n = "comma-separated values"
        inc = ", increasing" if self.increasing else ""
        return f"{n}{inc}, each {self.item.range_text}"

    def __call__(self, text: str):
        parts = [t.strip() for t in str(text).split(",")]
        try:
            vals = [self.item(t) for t in parts]
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(f"expected {self.range_text}, got {text!r}") from None
        n = len(vals)
        if isinstance(self.length, int) and n != self.length or (
                isinstance(self.length, tuple) and (n < self.length[0] or
                                                     (self.length[1] and n > self.length[1]))):
            raise argparse.ArgumentTypeError(f"expected {self.range_text}, got {n} in {text!r}")
        if self.increasing and any(b <= a for a, b in zip(vals, vals[1:], strict=False)):
            raise argparse.ArgumentTypeError(f"expected {self.range_text}, got {text!r}")
        return vals

    def bad_examples(self) -> list[str]:
        good = self.item.lo if self.item.lo is not None and not self.item.lo_open else (
            (self.item.lo or 0) + 1)
        n = self.length if isinstance(self.length, int) else (self.length[0] if self.length else 1)
        out = [",".join([self.item.bad_examples()[0]] * n), "1,,2"]
        if isinstance(self.length, int) or self.length:
            out.append(",".join([f"{good:g}"] * (n + 1 if isinstance(self.length, int) else 0)) or "")
        return [o for o in out if o]


def numbers(item: Number, **kw) -> NumberList:
    """An argparse ``type``: comma-separated :class:`Number` items."""
    return NumberList(item, **kw)


class OutputPath(str):
    """A path an option writes (``kind`` "file" or "dir"): :func:`run` checks it
    before any work (see :func:`prepare_output`)."""

    kind = "file"


class _OutDir(OutputPath):
    kind = "dir"


class InputPath(str):
    """A path a command reads: never written by that command."""


def output_file(*suffixes: str):
    """An argparse ``type`` for an output file, optionally restricted to
    ``suffixes`` (``output_file(".png")``)."""

    def parse(text: str) -> OutputPath:
        if not text:
            raise argparse.ArgumentTypeError("expected a file name, got ''")
        if suffixes and Path(text).suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(f"{text}: expected a file ending in "
                                             f"{' or '.join(suffixes)}")
        return OutputPath(text)

    parse.__name__ = "output file"
    parse.range_text = f"a file ending in {' or '.join(suffixes)}" if suffixes else None
    return parse


def output_dir(text: str) -> OutputPath:
    """An argparse ``type`` for an output folder."""
    if not text:
        raise argparse.ArgumentTypeError("expected a folder name, got ''")
    return _OutDir(text)


output_dir.__name__ = "output folder"


def output_file_or_dir(*suffixes: str):
    """An argparse ``type`` for an output that is a file when it ends in one of
    ``suffixes`` and a folder otherwise (one result, or a folder of several)."""

    def parse(text: str) -> OutputPath:
        if not text:
            raise argparse.ArgumentTypeError("expected a file or folder name, got ''")
        return OutputPath(text) if Path(text).suffix.lower() in suffixes else _OutDir(text)

    parse.__name__ = "output file or folder"
    return parse


def input_path(text: str) -> InputPath:
    """An argparse ``type`` for a path a command reads."""
    if not text:
        raise argparse.ArgumentTypeError("expected a path, got ''")
    return InputPath(text)


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error and exit status 2."""

    def error(self, message):  # noqa: D401 - argparse API
        # "argument --key: must be > 0" -> "error: --key: must be > 0": the
        # option first, as every other error names its file or option first.
        m = re.match(r"argument ([^:]+): (.*)", message, re.S)
        where, what = (m.group(1).split("/")[-1], m.group(2)) if m else (self.prog, message)
        sys.stderr.write(f"error: {where}: {what} (see '{self.prog} --help')\n")
        raise SystemExit(EXIT_USAGE)


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps line breaks and states each typed option's accepted range."""

    def _get_help_string(self, action):
        text = action.help or ""
        rng = getattr(action.type, "range_text", None)
        if rng and rng not in text and action.help is not argparse.SUPPRESS:
            text = f"{text} [{rng}]" if text else f"[{rng}]"
        return text


def make_parser(prog: str, description: str, *, epilog: str | None = None) -> argparse.ArgumentParser:
    """An ArgumentParser with the shared options ``--quiet`` and ``--debug``.

    ``description`` and ``epilog`` keep their line breaks, so a stage's
    ``--help`` can teach with examples.
    """
    p = _Parser(prog=prog, description=description, epilog=epilog,
                formatter_class=_HelpFormatter)
    add_common(p)
    return p


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", "-q", action="store_true", help="no progress output")
    p.add_argument("--debug", action="store_true",
                   help="show tracebacks for errors and the messages of the libraries we call")
    p.add_argument("--force", action="store_true",
                   help="replace a file beside the inputs that this command did not write "
                        "(its own earlier outputs are replaced anyway; an input, never); for "
                        "hdr, also accept exposure times whose order contradicts the images' "
                        "brightness (warned, not refused)")
    p.add_argument("--max-pixels", type=number(int, lo=1), metavar="N",
                   help=f"refuse images larger than N pixels, read from the header before decoding "
                        f"(default {DEFAULT_MAX_PIXELS}, or $LUMIGRAPH_MAX_PIXELS)")


def subparsers(p: argparse.ArgumentParser, *, title: str = "verbs"):
    """A verbs sub-parser group whose parsers share the project's parser class."""
    sp = p.add_subparsers(title=title, dest="verb", metavar="VERB", parser_class=_Parser)
    sp.required = True
    return sp


def add_verb(sp, name: str, help: str, *, description: str | None = None,
             epilog: str | None = None) -> argparse.ArgumentParser:
    """Add a verb with the shared options and the project's help formatting."""
    v = sp.add_parser(name, help=help, description=description or help, epilog=epilog,
                      formatter_class=_HelpFormatter)
    add_common(v)
    return v


def scheduler_address(text: str) -> str:
    """An argparse ``type`` for a Dask scheduler address (``tcp://HOST:PORT``)."""
    m = re.fullmatch(r"(tcp|tls|ucx|inproc)://[^\s:/]+(:\d+)?/?", text or "")
    if not m:
        raise argparse.ArgumentTypeError(f"expected a scheduler address such as "
                                         f"tcp://10.0.0.5:8786, got {text!r}")
    return text


scheduler_address.__name__ = "scheduler address"


BATCH_HELP = """batches (independent items: several brackets, frames, images or stacks):
  in-process by default; --workers N starts a local Dask cluster of N worker
  processes (one thread each); --scheduler tcp://HOST:PORT (or
  $DASK_SCHEDULER_ADDRESS) uses a running cluster ('dask scheduler' on one
  machine, 'dask worker tcp://HOST:8786 --nthreads 1' on each). The output
  folder gets index.json (items, status, input hashes; times and workers in
  its .meta.json); a rerun skips the items already written with the same
  inputs and options.
  Exit status 0 all done, 2 bad input found before any work, 4 some items
  failed (each named on an 'error: ITEM: reason' line; the others are written).
"""


def add_batch_options(v: argparse.ArgumentParser) -> None:
    """``--workers`` and ``--scheduler``: where a batch's items run
    (:mod:`lumigraph.capture.batch`)."""
    v.add_argument("--workers", type=number(int, lo=1, hi=1024), default=None, metavar="N",
                   help="batch: run the items on a local Dask cluster of N worker processes")
    v.add_argument("--scheduler", type=scheduler_address, default=None, metavar="ADDRESS",
                   help="batch: run the items on the Dask cluster at ADDRESS (tcp://HOST:PORT; "
                        "default $DASK_SCHEDULER_ADDRESS); neither option: in this process")


def batch_requested(args: argparse.Namespace) -> bool:
    """Whether the command line asks for a cluster (``--workers``,
    ``--scheduler`` or ``$DASK_SCHEDULER_ADDRESS``)."""
    return (getattr(args, "workers", None) is not None or getattr(args, "scheduler", None) is not None
            or bool(os.environ.get("DASK_SCHEDULER_ADDRESS")))


def item_options(parser: argparse.ArgumentParser, argv: Sequence[str], *,
                 drop: Iterable[str] = ()) -> list[str]:
    """The option tokens of ``argv`` that every item of a batch repeats: the
    positionals (the batch's inputs, the verb words) are left out, and so are
    the options whose ``dest`` is in ``drop`` (``out``, the batch options),
    whose values differ per item.

    Examples
    --------
    >>> p = make_parser("t", "t")
    >>> _ = p.add_argument("images", nargs="+")
    >>> _ = p.add_argument("--out")
    >>> _ = p.add_argument("--weights", nargs=2)
    >>> item_options(p, ["a", "b", "--weights", "1", "2", "--out=o", "-q", "c"], drop=["out"])
    ['--weights', '1', '2', '-q']
    """
    drop = {*drop, "workers", "scheduler"}
    by_flag = {o: a for a in parser._actions for o in a.option_strings}
    longs = [o for o in by_flag if o.startswith("--")]
    kept: list[str] = []
    tokens = list(argv)
    i = 0
    while i < len(tokens):
        t = tokens[i]
        i += 1
        if t == "--":
            break  # the rest are positionals
        if not t.startswith("-") or t == "-" or re.fullmatch(r"-\d.*", t):
            continue  # a positional
        flag, eq, _ = t.partition("=")
        a = by_flag.get(flag)
        if a is None and flag.startswith("--"):  # argparse accepts a unique prefix
            hits = [o for o in longs if o.startswith(flag)]
            a = by_flag[hits[0]] if len(hits) == 1 else None
        if a is None:
            kept.append(t)
            continue
        values: list[str] = []
        if not eq:
            n = a.nargs
            if n is None:
                n = 1
            if isinstance(n, int):
                values, i = tokens[i:i + n], i + n
            elif n == "?":
                if i < len(tokens) and not tokens[i].startswith("-"):
                    values, i = [tokens[i]], i + 1
            else:  # "*", "+": up to the next option
                while i < len(tokens) and (not tokens[i].startswith("-")
                                           or re.fullmatch(r"-\d.*", tokens[i])):
                    values.append(tokens[i])
                    i += 1
        if a.dest not in drop:
            kept += [t, *values]
    return kept


def batch_item_argv(args: argparse.Namespace, inputs: Sequence[str], *,
                    drop: Iterable[str] = ("out",), add: Sequence[str] = ()) -> list[str]:
    """One item's command line (for :func:`lumigraph.capture.batch.run_command`):
    the verb, the item's ``inputs``, every option the batch was given except
    those in ``drop`` and the batch options, then ``add`` (``["--out", ITEM]``)."""
    opts = item_options(args.batch_parser, args.batch_argv, drop=drop)
    return [*args.batch_verbs, *map(str, inputs), *opts, *add]


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
    for _, a in _chosen_actions(parser, args):
        if a.option_strings:
            longs = [o for o in a.option_strings if o.startswith("--")]
            flags.setdefault(a.dest, (longs or a.option_strings)[0])
    flags.update(getattr(args, "arg_flags", None) or {})
    return flags


def run(parser: argparse.ArgumentParser, argv: Sequence[str] | None, *,
        allow_extra: bool = False) -> int:
    """Parse ``argv`` and call ``args.func(args)`` under the error convention.

    Before ``args.func`` runs, every output the parser declares
    (:func:`output_file`, :func:`output_dir`) is checked: writable, not one of
    the inputs (:func:`input_path` values and any other argument naming an
    existing file), not held by another run (a lock), and a commit a killed run
    left in its folder is completed. The command's writes then form one result
    set (:func:`lumigraph.capture.artifact.result_set`): all visible together
    at the end, or none. Messages that foreign libraries print on stderr are
    kept back (shown with ``--debug``), so an error is one line.

    With ``allow_extra`` unknown ``--name VALUE`` pairs are kept, unparsed, in
    ``args.extra`` (for options only known once a positional is, such as a
    scene's own options). An :class:`InputError` or :class:`EstimationError`
    whose ``where`` names a library argument is reported under the flag that
    sets it (:func:`argument_flags`).
    """
    from lumigraph.capture import artifact

    outermost = _RUNS[0] == 0  # not an item that a batch runs in-process
    if outermost:
        _RUNS[1] = None
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
    if getattr(args, "max_pixels", None):
        os.environ["LUMIGRAPH_MAX_PIXELS"] = str(args.max_pixels)
    producer = " ".join([_command_name(parser.prog), *_verbs(parser, args)])
    # a batch verb builds its items' command lines from these (batch_item_argv)
    args.batch_argv, args.batch_prog = argv, parser.prog
    args.batch_verbs, args.batch_parser = _verbs(parser, args), _chosen_parser(parser, args)
    locks: list[_Lock] = []
    held = None
    _RUNS[0] += 1
    with _foreign_messages(debug) as said:
        try:
            inputs, outputs = declared_paths(parser, args)
            for folder in {Path(i) if os.path.isdir(i) else Path(i).parent for i in inputs}:
                # an input written by a run that was killed while committing its
                # results: finish that commit first, so we never read a mixed set
                artifact.recover_commits(folder)
            with artifact.guard(inputs, producer=producer, force=getattr(args, "force", False)) as g:
                for where, path, kind in outputs:
                    locks.append(prepare_output(path, kind=kind, where=where, guard=g))
                asked = getattr(args, "workers", None) is not None or \
                    getattr(args, "scheduler", None) is not None
                if asked:
                    from lumigraph.capture.batch import RUNS
                    before = RUNS[0]
                with artifact.result_set([(p, k) for _, p, k in outputs]):
                    rc = args.func(args)
                    # the work is done: a Ctrl-C from here on would land in the
                    # commit or on the way out, and report "nothing written" over
                    # a written result; it is held off until the command ends
                    # (a batch's items are the batch's to stop: not held)
                    if outermost:
                        held = _hold_interrupts()
                if outermost:
                    _RUNS[1] = EXIT_OK if rc is None else int(rc)
                if asked and RUNS[0] == before:
                    warn("--workers/--scheduler: these inputs are one item, not a batch; it ran "
                         "in this process")
            return EXIT_OK if rc is None else int(rc)
        except (InputError, EstimationError) as e:
            if debug:
                traceback.print_exc()
            where = argument_flags(parser, args).get(e.where, e.where)
            said.error(f"error: {where}: {_one_line(e.problem)}")
            for line in getattr(e, "details", ()):   # after the one line: what to do, item by item
                said.error(f"  {_one_line(line)}")
            return EXIT_USAGE
        except UnusableResult as e:  # the work ran; its result is not usable: nothing written
            if debug:
                traceback.print_exc()
            said.error(f"error: {e.where}: {_one_line(e.problem)}")
            return EXIT_UNUSABLE
        except KeyboardInterrupt:
            if outermost and _RUNS[1] is not None:  # it landed after the commit: the result stands
                return _RUNS[1]
            said.error("error: interrupted; nothing half-written was left behind")
            return 130
        except OSError as e:
            if e.errno in _ENVIRONMENT_ERRNOS:  # the disk or the folder, not our code
                if debug:
                    traceback.print_exc()
                name = _final_name(e.filename) if e.filename else "output"
                said.error(f"error: {name}: {e.strerror or e} (check the folder exists, is "
                           "writable and has space)")
                return EXIT_USAGE
            return _internal(e, debug, said)
        except Exception as e:  # an internal fault: say so, and how to see more
            if caused_by_interrupt(e):  # a Ctrl-C wrapped by the import it landed in
                said.error("error: interrupted; nothing half-written was left behind")
                return EXIT_INTERRUPTED
            return _internal(e, debug, said)
        finally:
            for lock in locks:
                lock.release()
            _release_interrupts(held)
            _RUNS[0] -= 1


# [how many run() calls are under way in this process (a batch runs its items
# through run() too), the outermost one's exit status once its result is
# committed (None before)]
_RUNS: list = [0, None]


def _hold_interrupts():
    """Ctrl-C does nothing until :func:`_release_interrupts`; returns the
    handler to restore (None off the main thread, where Python delivers no
    signal)."""
    import signal

    try:
        return signal.signal(signal.SIGINT, lambda signum, frame: None)
    except ValueError:
        return None


def _release_interrupts(held) -> None:
    if held is not None:
        import signal

        signal.signal(signal.SIGINT, held)


def committed_status() -> int | None:
    """For the outermost Ctrl-C handlers (the console script, ``python -m``):
    the exit status of a command that had already committed its result when
    the interrupt landed on its way out (it ends with that status); None when
    it had not."""
    return _RUNS[1]


_MODULE_STAGES = {"capture": "render", "separation": "separate", "stereo.flow_cli": "flow"}


def _command_name(prog: str) -> str:
    """``"lumigraph hdr"`` whichever way it was started (``python -m
    lumigraph.hdr``, ``python -m lumigraph.capture`` = ``lumigraph render``):
    the name an output's sidecar records as its producer."""
    words = prog.split()
    if words[:2] == ["python", "-m"] and len(words) > 2 and words[2].startswith("lumigraph."):
        module = words[2][len("lumigraph."):]
        return " ".join(["lumigraph", _MODULE_STAGES.get(module, module), *words[3:]])
    return prog


def _internal(e: BaseException, debug: bool, said) -> int:
    if debug:
        traceback.print_exc()
    else:
        said.error(f"error: internal: {type(e).__name__}: {_one_line(str(e))} "
                   "(rerun with --debug for the traceback, and report it)")
    return EXIT_INTERNAL


def _one_line(text: str) -> str:
    """A message on one line (foreign libraries' messages span several)."""
    return " ".join(str(text).split())


_ENVIRONMENT_ERRNOS = {errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC, errno.EDQUOT,
                       errno.ENOTDIR, errno.EISDIR, errno.ENAMETOOLONG, errno.EEXIST,
                       errno.ELOOP, errno.EMFILE, errno.EFBIG}


def _final_name(name) -> str:
    """The artifact a temporary file stands for (``.x.exr.ab12.tmp.exr`` -> ``x.exr``)."""
    p = Path(os.fsdecode(name))
    m = re.match(r"^\.(.+)\.[A-Za-z0-9_]+\.tmp(\.[^.]*)?$", p.name)
    return str(p.with_name(m.group(1))) if m else str(p)


def _verbs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    out = []
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            chosen = getattr(args, a.dest, None)
            if chosen in a.choices:
                out.append(chosen)
                out += _verbs(a.choices[chosen], args)
    return out


def _chosen_parser(parser: argparse.ArgumentParser, args: argparse.Namespace):
    """The (sub-)parser of the verb chosen in ``args``."""
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            chosen = getattr(args, a.dest, None)
            if chosen in a.choices:
                return _chosen_parser(a.choices[chosen], args)
    return parser


def _chosen_actions(parser: argparse.ArgumentParser, args: argparse.Namespace):
    todo = [parser]
    while todo:
        p = todo.pop()
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                chosen = getattr(args, a.dest, None)
                if chosen in a.choices:
                    todo.append(a.choices[chosen])
            elif a.dest not in ("help", argparse.SUPPRESS):
                yield p, a


def declared_paths(parser: argparse.ArgumentParser, args: argparse.Namespace):
    """``(inputs, outputs)`` of a parsed command line.

    Outputs are the values of options typed :func:`output_file` /
    :func:`output_dir`, as ``(flag or name, path, "file" | "dir")``, and the
    files a verb names with ``set_defaults(derived_outputs=lambda args:
    [(flag, path), ...])`` (a mask written beside ``--out``). Inputs
    are the values typed :func:`input_path`, and every other string value that
    names an existing file or folder: whatever a command reads is protected
    from its writes, declared or not.
    """
    inputs: list[str] = []
    outputs: list[tuple[str, Path, str]] = []
    derived = getattr(args, "derived_outputs", None)
    if derived is not None:  # files a command writes beside a declared one (merge's mask)
        outputs += [(where, Path(p), "file") for where, p in derived(args)]
    for _, a in _chosen_actions(parser, args):
        if a.dest == "derived_outputs":
            continue
        value = getattr(args, a.dest, None)
        values = value if isinstance(value, list | tuple) else [value]
        name = next((o for o in a.option_strings if o.startswith("--")), a.dest)
        for v in values:
            if isinstance(v, OutputPath):
                outputs.append((name, Path(v), v.kind))
            elif isinstance(v, str) and v and not v.startswith("-"):
                try:
                    if os.path.exists(v):
                        inputs.append(v)
                except (OSError, ValueError):
                    pass
    return inputs, outputs


class _Lock:
    """An exclusive lock on one output path, held for the run (flock on a file
    in a per-user folder named after the path's hash, so nothing is added to
    the user's folders and an output folder need not exist yet)."""

    def __init__(self, path: Path, where: str):
        import fcntl
        import hashlib
        import tempfile

        real = os.path.realpath(path)
        folder = Path(tempfile.gettempdir()) / f"lumigraph-{os.getuid()}" / "locks"
        folder.mkdir(parents=True, exist_ok=True)
        self.file = folder / (hashlib.sha1(real.encode()).hexdigest()[:24] + ".lock")
        for _ in range(20):
            fd = os.open(self.file, os.O_RDWR | os.O_CREAT, 0o600)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                other = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
                os.close(fd)
                raise InputError(where, f"{path}: another lumigraph run (pid {other}) is writing "
                                        "this output; wait for it to finish or choose another "
                                        "output") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.file).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)  # its holder removed it as we opened it: take the new one
        else:  # pragma: no cover - would need 20 races in a row
            raise InputError(where, f"{path}: could not lock this output")
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self.fd = fd

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.file)  # still held: nobody can take it between the two calls
        except FileNotFoundError:
            pass
        os.close(self.fd)
        self.fd = None


def check_writable(path: str | os.PathLike, *, where: str, kind: str = "file") -> Path:
    """Refuse (InputError naming ``where``) an output that cannot be written,
    before any work: a parent that is a file, or a folder that refuses a new
    file (probed by creating and removing one, which also holds for root and
    read-only mounts)."""
    import tempfile

    p = Path(path)
    if kind == "file" and p.is_dir():
        raise InputError(where, f"{p} is a folder; give a file name")
    if kind == "dir" and p.exists() and not p.is_dir():
        raise InputError(where, f"{p} exists and is not a folder")
    folder = p if kind == "dir" else p.parent
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(where, f"{p}: cannot create it, because {probe} is a file, not a folder")
    try:  # an unnamed file where the system allows (O_TMPFILE): nothing to leave behind
        tempfile.TemporaryFile(prefix=".lumigraph-probe.", dir=probe).close()
    except OSError as e:
        raise InputError(where, f"{p}: cannot write in {probe} ({e.strerror}); choose a writable "
                                "folder") from None
    if kind == "file" and p.exists() and not os.access(p, os.W_OK) and os.getuid() != 0:
        # os.replace works on a read-only file in a writable folder, but the user made it read-only
        raise InputError(where, f"{p} is read-only; remove it or choose another output")
    return p


def prepare_output(path: str | os.PathLike, *, kind: str = "file", where: str = "--out",
                   guard=None) -> _Lock:
    """Everything checked about one output before any work: writable, not an
    input (``guard``), not being written by another run (returns the held
    lock); then a commit that a killed run left is completed and temporaries
    it left are removed."""
    from lumigraph.capture import artifact

    p = Path(path)
    check_writable(p, where=where, kind=kind)
    if guard is not None and kind == "file":
        guard.check(p, where=where)
    lock = _Lock(p, where)
    folder = p if kind == "dir" else p.parent
    artifact.recover_commits(folder)
    artifact.remove_stale_temps(p, kind=kind)
    return lock


class _Said:
    """What a run says: its warnings are held until the end and shown if the
    run did its work; a run that fails says one line, its error."""

    def __init__(self, stream):
        self.stream = stream
        self.held: list[str] = []
        self.failed = False

    def error(self, line: str) -> None:
        self.failed = True
        self.stream.write(line + "\n")
        self.stream.flush()


_ACTIVE: list[_Said] = []  # the run in progress (warn() holds its lines there)


@contextlib.contextmanager
def _foreign_messages(debug: bool):
    """Keep back what foreign libraries print (libpng, OpenEXR, COLMAP's glog
    on file descriptor 2, Python warnings raised outside lumigraph): a run's
    stderr is our lines only. ``--debug`` shows them at the end."""
    import tempfile
    import warnings

    stream = sys.stderr
    try:
        real = stream.fileno() == 2
    except (AttributeError, OSError, ValueError):
        real = False  # a test's captured stream: nothing to redirect
    saved = cap = None
    if real:
        stream.flush()
        saved = os.dup(2)
        cap = tempfile.TemporaryFile()
        os.dup2(cap.fileno(), 2)
        sys.stderr = os.fdopen(os.dup(saved), "w", buffering=1, encoding=stream.encoding,
                               errors="backslashreplace")
    said = _Said(sys.stderr)
    _ACTIVE.append(said)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            yield said
        finally:
            _ACTIVE.remove(said)
            ours = [w for w in caught if _is_ours(w.filename)]
            lines = said.held + [f"warning: {w.message}" for w in ours]
            lines = [ln for i, ln in enumerate(lines) if ln not in lines[:i]]
            if not said.failed:
                for ln in lines:
                    sys.stderr.write(ln + "\n")
            elif debug:  # a failed run's one line stays the last; the rest only on request
                for ln in lines:
                    said.stream.write(f"debug: held back: {ln}\n")
            if debug:
                for w in caught:
                    if w not in ours:
                        sys.stderr.write(f"debug: {w.category.__name__}: {w.message} "
                                         f"({w.filename}:{w.lineno})\n")
            if real:
                sys.stderr.flush()
                os.dup2(saved, 2)
                os.close(saved)
                sys.stderr.close()
                sys.stderr = stream
                cap.seek(0)
                text = cap.read().decode(errors="replace")
                cap.close()
                if debug and text.strip():
                    stream.write("debug: messages from the libraries called:\n" + text)
                    stream.flush()


def _is_ours(filename: str) -> bool:
    here = Path(__file__).resolve().parent.parent  # the repository (or site-packages) root
    try:
        rel = Path(filename).resolve().relative_to(here)
    except ValueError:
        return False
    return rel.parts[0] in ("capture", "calib", "hdr", "stereo", "lightfield", "separation",
                            "lumigraph") and ".venv" not in rel.parts


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
    """A warning line on stderr (always shown, ``--quiet`` or not). Within
    :func:`run` it is held and shown when the command has done its work, so a
    command that fails says exactly one line, its error."""
    if _ACTIVE:
        _ACTIVE[-1].held.append(f"warning: {message}")
    else:
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


def check_planned(paths: Iterable[str | os.PathLike], *, where: str = "--out") -> None:
    """Check, before any work, files a command will write whose names are
    known only once its inputs are (an output folder's contents): none may
    replace an input or a file beside the inputs that this command did not
    write (:class:`lumigraph.capture.artifact.OutputGuard`). Outside
    :func:`run` there is no guard and nothing to check."""
    from lumigraph.capture.artifact import current_guard

    g = current_guard()
    if g is not None:
        for p in paths:
            g.check(p, where=where)


def module_main(module: str, prog: str) -> int:
    """``python -m lumigraph.<stage>``: import the stage's command and run it,
    with Ctrl-C during the (slow) imports ending as cleanly as during the work."""
    try:
        import importlib

        return importlib.import_module(module).main(prog=prog)
    except KeyboardInterrupt:
        if (status := committed_status()) is not None:
            return status
        sys.stderr.write("error: interrupted; nothing was written\n")
        return EXIT_INTERRUPTED
    except Exception as e:
        if not caused_by_interrupt(e):  # a Ctrl-C wrapped by the import it landed in
            raise
        sys.stderr.write("error: interrupted; nothing was written\n")
        return EXIT_INTERRUPTED
