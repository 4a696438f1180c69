"""``lumigraph flow``: optical flow and Sand-Teller video matching between two
images, written as a Middlebury ``.flo`` plus a confidence/probability EXR.

Thin layer: parse, load, call :mod:`lumigraph.stereo.flow_methods` (which checks
the options, before any image is read), save.
"""

from __future__ import annotations

from pathlib import Path

from lumigraph.capture.commandline import (
    BATCH_HELP,
    add_batch_options,
    batch_requested,
    check_output_path,
    check_planned,
    input_path,
    make_parser,
    number,
    output_file_or_dir,
    run,
    say,
    warn,
)
from lumigraph.capture.errors import InputError
from lumigraph.stereo.pyramid import MAX_LEVELS
from lumigraph.stereo.pyramid_flow import MAX_MEDIAN_RADIUS

EPILOG = """\
examples:
  lumigraph render flow --out out/scenes/flow
  lumigraph flow out/scenes/flow/frame00.png out/scenes/flow/frame01.png \\
      --out out/flow/flow.flo --viz out/flow/flow.png
  lumigraph flow a.png b.png --preset accurate --out sharp.flo   # accuracy end (~10-15x slower)
  lumigraph flow a.png b.png --preset fast --out quick.flo       # speed end (~DIS-medium's time)
  lumigraph flow take1.png take2.png --method video-matching --out match.flo
  lumigraph flow a.png b.png --method pyramid --median-radius 10 --out lk.flo

Writes OUT (.flo: forward flow, I0(x, y) <-> I1(x + dx, y + dy), pixels,
I0 the first image (the reference), I1 the second (the moving one);
unknown = 1e10), OUT with .flo replaced by .prob.exr (one float channel Y in
[0, 1]: for dis and pyramid methods the confidence = texture x forward-backward
consistency (near 0 on textureless areas and occlusions), for video-matching the Sand-Teller matching probability), and
OUT.meta.json (pyramid levels chosen and every candidate's score, timings,
quality figures). --viz writes a Middlebury colour-coded PNG.

Given more than two images, the flow between each consecutive pair is written
to the --out folder as flow_000.flo (frame 0 -> 1), flow_001.flo, ..., each
with its .prob.exr and .meta.json, plus index.json summarising every pair;
--viz then names a folder for the pictures:
  lumigraph render flow-sequence --out out/scenes/seq
  lumigraph flow out/scenes/seq/frame*.png --out out/flow/seq --viz out/flow/seq-viz
A sequence runs on a Dask cluster with --workers N or --scheduler ADDRESS:
each pair is then one item, and index.json is the batch's index (below).

""" + BATCH_HELP


def _load(path: str):
    from lumigraph.capture import io

    p = Path(path)
    img = io.read_image(p)
    if img.size == 0 or min(img.shape[:2]) < 8:
        raise InputError(p, f"image is empty or too small ({img.shape}); need at least 8x8 pixels")
    return img


def _outputs(args):
    """(flow paths, picture paths or Nones) per consecutive pair, checked
    before any work: two images write the files named; a sequence writes
    flow_NNN.flo (frame NNN -> NNN + 1) into the --out folder and, with
    --viz, flow_NNN.png into the --viz folder."""
    from lumigraph.capture.commandline import check_output_dir

    n = len(args.images) - 1
    if n == 1:
        out = check_output_path(args.out, suffixes=(".flo",))
        viz = None if args.viz is None else Path(args.viz)
        if viz is not None and viz.suffix.lower() != ".png":
            raise InputError("viz", f"{viz}: two images give one picture; name it .png")
        return [out], [viz]
    if Path(args.out).suffix.lower() == ".flo":
        raise InputError("out", f"{len(args.images)} frames give {n} flows: name a folder, "
                                  f"not one file ({args.out})")
    out = check_output_dir(args.out)
    if args.viz is not None and Path(args.viz).suffix:
        raise InputError("viz", f"for a sequence name a folder for the pictures, not {args.viz}")
    viz = check_output_dir(args.viz) if args.viz is not None else None
    flows = [out / f"flow_{i:03d}.flo" for i in range(n)]
    pictures = [viz / f"flow_{i:03d}.png" if viz is not None else None for i in range(n)]
    # the folders' files, before any work: none may replace an input (--out = the frames' folder)
    from lumigraph.stereo.pyramid_flow import prob_path

    check_planned([*flows, *map(prob_path, flows), out / "index.json"])
    if viz is not None:
        check_planned(pictures, where="--viz")
    return flows, pictures


def _derived(args):
    """The probability image written beside a two-image --out (a sequence's
    lie in its --out folder)."""
    from lumigraph.stereo.pyramid_flow import prob_path

    if len(args.images) == 2 and Path(args.out).suffix.lower() == ".flo":
        return [("--out", prob_path(args.out))]
    return []


def _flow_batch(args, outs, vizs) -> int:
    """A sequence on a Dask cluster (``--workers``/``--scheduler``): each pair
    is one item, the two-image command itself writing ``flow_NNN.flo``."""
    from lumigraph.capture.batch import Item, report, run_batch
    from lumigraph.capture.commandline import batch_item_argv
    from lumigraph.stereo.pyramid_flow import prob_path

    items = []
    for i, (out, viz) in enumerate(zip(outs, vizs, strict=True)):
        a, b = args.images[i], args.images[i + 1]
        add = ["--out", str(out), *(["--viz", str(viz)] if viz is not None else [])]
        items.append(Item(out.stem, inputs=(str(a), str(b)),
                          outputs=(*([str(viz)] if viz is not None else []), str(prob_path(out)),
                                   str(out)),
                          func="lumigraph.capture.batch:run_command",
                          kwargs={"module": "lumigraph.stereo.flow_cli", "prog": "lumigraph flow",
                                  "argv": batch_item_argv(args, [a, b], drop=("out", "viz"),
                                                          add=add)}))
    result = run_batch(items, out_dir=outs[0].parent, workers=args.workers,
                       scheduler=args.scheduler, quiet=args.quiet, description="flow")
    return report(result, quiet=args.quiet)


def _flow(args) -> int:
    import time

    import numpy as np

    from lumigraph.capture import io
    from lumigraph.capture.artifact import make_meta, write_artifact, write_json
    from lumigraph.capture.commandline import progress
    from lumigraph.stereo.flow_methods import FLOW_METHODS, check_options
    from lumigraph.stereo.pyramid_flow import prob_path

    if len(args.images) < 2:
        raise InputError(args.images[0], "flow needs at least two images")
    outs, vizs = _outputs(args)
    options = check_options(args.method, preset=args.preset, levels=args.levels, window=args.window,
                            iterations=args.iterations, finest_level=args.finest_level,
                            median_radius=args.median_radius)
    if len(outs) > 1 and batch_requested(args):
        return _flow_batch(args, outs, vizs)
    frames = [_load(p) for p in args.images]
    for p, im in zip(args.images[1:], frames[1:], strict=True):
        i0 = frames[0]
        if im.shape[:2] != i0.shape[:2]:
            raise InputError(p, f"is {im.shape[1]}x{im.shape[0]} but {args.images[0]} is "
                                f"{i0.shape[1]}x{i0.shape[0]}; flow needs images of one size")
        if im.ndim != i0.ndim or (im.ndim == 3 and im.shape[2] != i0.shape[2]):
            raise InputError(p, "has a different number of channels than " + args.images[0])
    method = FLOW_METHODS.resolve(args.method)
    params = {"method": args.method, "preset": args.preset, "levels": args.levels, "window": args.window,
              "iterations": args.iterations, "finest_level": args.finest_level,
              "median_radius": args.median_radius}
    summary = []
    pairs = range(len(outs))
    for i in progress(pairs, total=len(outs), description="flow", quiet=args.quiet or len(outs) == 1):
        a, b, out = args.images[i], args.images[i + 1], outs[i]
        say(args, f"flow ({args.method}): {a} -> {b}")
        t0 = time.perf_counter()
        res = method(frames[i], frames[i + 1], **options)
        dt = time.perf_counter() - t0
        info = res.info
        for w in info.get("warnings", ()):
            warn(f"{a} -> {b}: {w}")
        quality = {**info.get("quality", {}), "occluded_fraction": float(res.occluded.mean())}
        meta = make_meta("lumigraph.flow", inputs=[a, b], params=params,
                         model={"levels": res.levels, "level_choice": info.get("level_choice")},
                         quality=quality, timings_s={"flow": dt},
                         warnings=[f"{a} -> {b}: {w}" for w in info.get("warnings", ())],
                         extra={"diagnostics": {k: v for k, v in info.items()
                                                if k not in ("quality", "level_choice", "timings_s")},
                                "probability_file": str(prob_path(out))})
        res.save(out, meta=meta)
        if vizs[i] is not None:
            from lumigraph.stereo.flow_colour import flow_to_colour

            pic = flow_to_colour(np.where(res.occluded[..., None] & args.mask_viz, np.nan, res.flow))
            write_artifact(vizs[i], lambda p, pic=pic: io.write_image(p, pic),
                           meta=make_meta("lumigraph.flow.viz", inputs=[out],
                                          params={"coding": "middlebury"}))
        say(args, f"wrote {out} and {prob_path(out)} ({res.levels} levels, {dt:.2f} s)")
        summary.append({"from": a, "to": b, "flow": out.name, "levels": res.levels,
                        "seconds": dt, **quality})
    if len(outs) > 1:
        index = outs[0].parent / "index.json"
        body = {"schema": "lumigraph.flow-sequence", "params": params,
                "convention": "flow_NNN.flo maps frame NNN to frame NNN + 1", "pairs": summary}
        write_artifact(index, lambda p: write_json(p, body),
                       meta=make_meta("lumigraph.flow-sequence", inputs=list(args.images),
                                      params=params,
                                      quality={"pairs": len(summary),
                                               "mean_occluded_fraction": float(np.mean(
                                                   [x["occluded_fraction"] for x in summary]))},
                                      timings_s={"flow": float(sum(x["seconds"] for x in summary))}))
        say(args, f"wrote {len(outs)} flows and {index}")
    return 0


def build_parser(prog: str = "lumigraph flow"):
    from lumigraph.stereo.flow_methods import FLOW_METHODS

    methods = FLOW_METHODS.help_text()
    p = make_parser(prog, "Dense correspondence between two images: optical flow (default: dense "
                    "inverse search, --preset fast|default|accurate; or the coarse-to-fine "
                    "pyramid) or Sand-Teller video matching.\n\nmethods:\n" + methods,
                    epilog=EPILOG)
    p.add_argument("images", nargs="+", metavar="IMAGE", type=input_path,
                   help="two images (reference, moving), or a sequence: flows between "
                        "consecutive frames")
    p.add_argument("--out", required=True, type=output_file_or_dir(".flo"),
                   help="output flow file (.flo) for two images; a folder for a sequence")
    p.add_argument("--method", choices=FLOW_METHODS.names, default="dis",
                   help="flow method (default: dis)")
    p.add_argument("--preset", choices=("fast", "default", "accurate"), default=None,
                   help="dis only: fast (about DIS-medium's time, more accurate), default "
                        "(about 1.5-2x its time), accurate (below DeepFlow's time, occlusions filled); "
                        "each a point on "
                        "`lumigraph bench flow`'s speed-error curve (default: default)")
    p.add_argument("--levels", type=number(int, lo=1, hi=MAX_LEVELS, allow=("auto",)), default="auto",
                   help="pyramid methods: levels, or 'auto' from the estimated largest motion "
                        "(default); with video-matching a number selects the paper's pyramid "
                        "search instead of the default dense search")
    p.add_argument("--window", type=number(int, lo=3, odd=True), default=9,
                   help="pyramid methods: matching window side, odd (default 9)")
    p.add_argument("--iterations", type=number(int, lo=1), default=3, help="pyramid methods: warps per level (default 3)")
    p.add_argument("--median-radius", type=number(int, lo=0, hi=MAX_MEDIAN_RADIUS), default=0,
                   help="0: a 3x3 median after each warp (default). R > 0: a colour-guided "
                        "weighted median of radius R px after each level (Sun, Roth & Black): "
                        "sharper motion boundaries, slower; the bench's accuracy end uses 10")
    p.add_argument("--finest-level", type=number(int, lo=0, hi=MAX_LEVELS - 1), default=0,
                   help="stop refining at this pyramid level and upsample (1: half size, about "
                        "4x faster, a little less accurate; default 0: full size)")
    p.add_argument("--viz", type=output_file_or_dir(".png"), help="(a folder, for a sequence) also write a Middlebury colour-coded picture (.png)")
    p.add_argument("--mask-viz", action="store_true",
                   help="paint occluded/unreliable pixels black in --viz")
    add_batch_options(p)
    p.set_defaults(func=_flow, derived_outputs=_derived)
    return p


def main(argv=None, prog: str = "lumigraph flow") -> int:
    return run(build_parser(prog), argv)
