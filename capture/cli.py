"""``lumigraph render``: synthetic scenes with exact ground truth, written to a folder.

A thin layer over :mod:`lumigraph.capture.render`: parse, render, save. The
library validates the scene, its options, the size and the seed; the command
line only turns text into values and maps each argument to its flag.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from lumigraph.capture.artifact import make_meta, write_json
from lumigraph.capture.commandline import (
    make_parser,
    number,
    output_dir,
    parse_size,
    run,
    say,
    show_progress,
)
from lumigraph.capture.errors import InputError

EPILOG = """\
examples:
  lumigraph render --list
  lumigraph render sample --out out/sample --size 64x48 --seed 3 --noise 2
  lumigraph render bracket --out out/bracket --bit-depth 12      (HDR bracket)

The folder gets the captured images (integer code values, as a camera delivers
them), stack.json (accepted as input by every stage), gt.json and gt/*.npy
(exact ground truth). Scene options are given as --name VALUE; --list shows
them all. Renders are cached by (scene, options, size, seed) in
$LUMIGRAPH_CACHE (default ~/.cache/lumigraph); --no-cache renders afresh.
"""


def _list(args) -> int:
    from lumigraph.capture.render import scenes

    for name, spec in sorted(scenes().items()):
        w, h = spec.default_size
        print(f"{name}  (default size {w}x{h})\n    {spec.summary}")
        for o in spec.options:
            print(f"    {o.describe()}")
        print()
    return 0


def _size(text: str) -> tuple[int, int]:
    """``--size WxH`` as ``(width, height)``; the scene checks the range
    (:meth:`lumigraph.capture.render.SceneSpec.check_size`)."""
    try:
        return parse_size(text, limits=None)
    except InputError as e:
        raise argparse.ArgumentTypeError(e.problem) from None


_size.__name__ = "size"


def _scene(text: str) -> str:
    """A scene name of :data:`lumigraph.capture.render.SCENES`."""
    from lumigraph.capture.render import SCENES

    if text not in SCENES:
        raise argparse.ArgumentTypeError(f"unknown scene {text!r}; choose from "
                                         f"{', '.join(sorted(SCENES))} (see --list)")
    return text


_scene.__name__ = "scene"


def _scene_options(extra: list[str]) -> dict[str, str]:
    opts, i = {}, 0
    while i < len(extra):
        tok = extra[i]
        if not tok.startswith("--") or tok == "--":
            raise InputError(tok, "unexpected argument; scene options are --name VALUE")
        if "=" in tok:
            k, v = tok[2:].split("=", 1)
            i += 1
        else:
            if i + 1 >= len(extra):
                raise InputError(tok, "missing value")
            k, v = tok[2:], extra[i + 1]
            i += 2
        opts[k] = v
    return opts


def _render(args) -> int:
    extra = args.extra
    from lumigraph.capture.render import get_scene, render

    if args.scene is None:
        raise InputError("SCENE", "name a scene to render, or use --list")
    if args.out is None:
        raise InputError("--out", "give the output folder, e.g. --out out/" + args.scene)
    spec = get_scene(args.scene)
    # the scene's renderer names its options; the command line reports their flags
    given = _scene_options(extra)
    args.arg_flags = {k.replace("-", "_"): "--" + k.replace("_", "-")
                      for k in [*(o.name for o in spec.options), *given]}
    # text -> values and the scene's own checks (names, kinds, ranges, finite),
    # all before anything is rendered or written
    size = spec.check_size(args.size) if args.size else None
    opts = spec.parse_options(given)
    out = Path(args.out)
    if show_progress(args.quiet):  # on a terminal only: piped stderr keeps to one error line
        say(args, f"rendering {args.scene} -> {out}")
    result = render(args.scene, size=size, seed=args.seed, cache=not args.no_cache, **opts)
    result.save(out)
    write_json(out / "stack.json.meta.json",
               make_meta("lumigraph.render", params=result.params, extra={"scene": args.scene}))
    say(args, f"wrote {len(result.images)} image(s), stack.json and ground truth to {out}")
    return 0


def build_parser(prog: str = "lumigraph render"):
    """The ``lumigraph render`` parser. A scene's own options are not in it:
    they are known once the scene is, and :func:`main` hands them over
    unparsed to the scene's spec (:meth:`SceneSpec.parse_options`)."""
    p = make_parser(prog, "Render a synthetic scene with exact ground truth.", epilog=EPILOG)
    p.add_argument("scene", nargs="?", type=_scene, metavar="SCENE",
                   help="scene name (see --list)")
    p.add_argument("--out", type=output_dir, help="output folder")
    p.add_argument("--size", type=_size, metavar="WxH",
                   help="image size WIDTHxHEIGHT (default: the scene's test size)")
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="random seed (default 0)")
    p.add_argument("--list", action="store_true", help="list every scene and its options")
    p.add_argument("--no-cache", action="store_true", help="render afresh, bypass the cache")
    p.set_defaults(func=lambda args: _list(args) if args.list else _render(args))
    return p


def main(argv=None, prog="lumigraph render") -> int:
    # Scene options are only known once the scene is: run() hands them over unparsed.
    return run(build_parser(prog), argv, allow_extra=True)
