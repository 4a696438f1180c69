"""Every option of every command is checked by the parser, before any work.

Structural: each option that takes a value declares what it accepts -- a
range-checked number (:class:`~lumigraph.capture.commandline.Number`), a list
of them, a choice, a path type (input, output file, output folder) or a parse
function of its own -- so a non-numeric, non-finite or out-of-range value is
exit 2 with one line naming the option, and ``--help`` states the range.
Behavioural: every value each numeric option's type calls bad is refused by
the real parser with exit 2 and one ``error: --option: ...`` line.
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

import pytest

from lumigraph.capture.commandline import Number, NumberList
from lumigraph.command import STAGES


def _parsers():
    for name, method in STAGES.items():
        module = importlib.import_module(method.target.split(":")[0])
        build = getattr(module, "build_parser", None)
        assert build is not None, f"{module.__name__} has no build_parser(prog)"
        yield name, build(f"lumigraph {name}")


def _actions(parser, path=()):
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for verb, sub in a.choices.items():
                yield from _actions(sub, (*path, verb))
        elif not isinstance(a, argparse._HelpAction | argparse._VersionAction):
            yield path, a


OPTIONS = [(f"{stage} {' '.join(path)}".strip(), a)
           for stage, p in _parsers() for path, a in _actions(p)]


def _takes_value(a: argparse.Action) -> bool:
    return a.nargs != 0 and not isinstance(a, argparse._StoreConstAction | argparse._CountAction)


@pytest.mark.parametrize("command,action", OPTIONS,
                         ids=[f"{c}:{a.dest}" for c, a in OPTIONS])
def test_every_option_declares_what_it_accepts(command, action):
    if not _takes_value(action):
        return
    t = action.type
    untyped = t is None or t in (str, int, float)
    assert action.choices is not None or not untyped, (
        f"{command} {action.option_strings or action.dest}: give it a type that checks the value "
        "(number(...), numbers(...), input_path, output_file(...), output_dir, or a parse function)")


NUMERIC = [(c, a) for c, a in OPTIONS if isinstance(a.type, Number | NumberList) and a.option_strings]


@pytest.mark.parametrize("command,action", NUMERIC, ids=[f"{c}:{a.dest}" for c, a in NUMERIC])
def test_bad_numbers_are_refused_by_the_parser(command, action, capsys):
    stage, *verb = command.split()
    parser = dict(_parsers())[stage]
    flag = next(o for o in action.option_strings if o.startswith("--"))
    for bad in action.type.bad_examples():
        argv = [*verb, f"{flag}={bad}"]
        with pytest.raises(SystemExit) as e:
            parser.parse_args(argv)
        assert e.value.code == 2, (command, flag, bad)
        err = capsys.readouterr().err.strip().splitlines()
        # the one line names the option (a missing required argument may come first)
        assert any(line.startswith(f"error: {flag}:") or "required" in line for line in err), err
        assert len(err) == 1, err


@pytest.mark.parametrize("command,action", NUMERIC, ids=[f"{c}:{a.dest}" for c, a in NUMERIC])
def test_help_states_the_range(command, action):
    from lumigraph.capture.commandline import _HelpFormatter

    text = _HelpFormatter("x")._get_help_string(action)
    assert action.type.range_text in text


MANY = [(c, a) for c, a in OPTIONS if a.option_strings and a.nargs in ("+", "*")]


@pytest.mark.parametrize("command,action", MANY, ids=[f"{c}:{a.dest}" for c, a in MANY])
def test_a_repeated_list_option_adds_to_the_list(command, action):
    """``--view a.json --view b.json`` means both views: argparse's plain store
    would keep the last list and drop the others without a word."""
    assert isinstance(action, argparse._ExtendAction), (
        f"{command} {action.option_strings}: takes several values, so give it action='extend'")


def test_two_views_given_apart_are_both_rendered(tmp_path):
    parser = dict(_parsers())["stereo"]
    for name in ("m.json", "a.json", "b.json", "c.json"):
        (tmp_path / name).write_text("{}")
    args = parser.parse_args(["facade", "render", "--model", str(tmp_path / "m.json"), "--photos",
                              str(tmp_path), "--view", str(tmp_path / "a.json"), "--view",
                              str(tmp_path / "b.json"), str(tmp_path / "c.json"), "--out",
                              str(tmp_path / "o")])
    assert [Path(p).name for p in args.view] == ["a.json", "b.json", "c.json"]
