"""``lumigraph flow``: optical flow and Sand-Teller video matching between two
images, written as a Middlebury ``.flo`` plus a confidence/probability EXR.

Thin layer: parse, validate, load, call :mod:`stereo.flow_methods`, save.
"""

from __future__ import annotations

from pathlib import Path

from capture.command import check_output_path, make_parser, run, say
from capture.errors import InputError

EPILOG = """\
examples:
  lumigraph render flow --out out/scenes/flow
  lumigraph flow out/scenes/flow/frame00.png out/scenes/flow/frame01.png \\
      --out out/flow/flow.flo --viz out/flow/flow.png
  lumigraph flow take1.png take2.png --method video-matching --out match.flo
  lumigraph flow a.png b.png --median-radius 10 --out sharp.flo     # accuracy end
  lumigraph flow a.png b.png --finest-level 1 --iterations 1 --out quick.flo  # speed end

Writes OUT (.flo: forward flow, I0(x, y) <-> I1(x + dx, y + dy), pixels;
unknown = 1e10), OUT with .flo replaced by .prob.exr (one float channel Y in
[0, 1]: for pyramid methods the confidence = texture x forward-backward
consistency, for video-matching the Sand-Teller matching probability), and
OUT.meta.json (pyramid levels chosen and every candidate's score, timings,
quality figures). --viz writes a Middlebury colour-coded PNG.
"""


def _levels(text: str):
    if text == "auto":
        return "auto"
    try:
        n = int(text)
    except ValueError:
        raise InputError("--levels", f"expected 'auto' or an integer >= 1, got {text!r}") from None
    if not 1 <= n <= 12:
        raise InputError("--levels", f"expected 1..12 levels, got {n}")
    return n


def _load(path: str):
    from capture import io

    p = Path(path)
    img = io.read_image(p)
    if img.size == 0 or min(img.shape[:2]) < 8:
        raise InputError(p, f"image is empty or too small ({img.shape}); need at least 8x8 pixels")
    return img


def _flow(args) -> int:
    import time

    import numpy as np

    from capture import io
    from capture.artifact import make_meta, write_artifact
    from stereo.flow_methods import FLOW_METHODS
    from stereo.pyramid_flow import prob_path

    out = check_output_path(args.out, suffixes=(".flo",))
    if args.viz is not None:
        check_output_path(args.viz, suffixes=(".png",))
    levels = _levels(args.levels)
    if args.window < 3 or args.window % 2 == 0:
        raise InputError("--window", f"expected an odd size >= 3, got {args.window}")
    if args.median_radius < 0 or args.median_radius > 64:
        raise InputError("--median-radius", f"expected 0..64 pixels, got {args.median_radius}")
    if args.finest_level < 0:
        raise InputError("--finest-level", f"expected a level >= 0, got {args.finest_level}")
    if levels != "auto" and args.finest_level >= levels:
        raise InputError("--finest-level", f"must be below --levels ({levels}), got {args.finest_level}")
    if args.method == "video-matching" and (args.median_radius or args.finest_level):
        raise InputError("--method", "video-matching takes no --median-radius or --finest-level "
                                     "(pyramid methods only)")
    i0, i1 = _load(args.image0), _load(args.image1)
    if i0.shape[:2] != i1.shape[:2]:
        raise InputError(args.image1, f"is {i1.shape[1]}x{i1.shape[0]} but {args.image0} is "
                                      f"{i0.shape[1]}x{i0.shape[0]}; flow needs two images of one size")
    if i0.ndim != i1.ndim or (i0.ndim == 3 and i0.shape[2] != i1.shape[2]):
        raise InputError(args.image1, "has a different number of channels than " + args.image0)
    fn, _ = FLOW_METHODS[args.method]
    say(args, f"flow ({args.method}): {args.image0} -> {args.image1}")
    t0 = time.perf_counter()
    res = fn(i0, i1, levels=levels, window=args.window, iterations=args.iterations,
             finest_level=args.finest_level, median_radius=args.median_radius)
    dt = time.perf_counter() - t0
    info = res.info
    meta = make_meta("lumigraph.flow", inputs=[args.image0, args.image1],
                     params={"method": args.method, "levels": args.levels, "window": args.window,
                             "iterations": args.iterations, "finest_level": args.finest_level,
                             "median_radius": args.median_radius},
                     model={"levels": res.levels, "level_choice": info.get("level_choice")},
                     quality={**info.get("quality", {}),
                              "occluded_fraction": float(res.occluded.mean())},
                     timings_s={"flow": dt},
                     extra={"diagnostics": {k: v for k, v in info.items()
                                            if k not in ("quality", "level_choice", "timings_s")},
                            "probability_file": str(prob_path(out))})
    res.save(out, meta=meta)
    if args.viz is not None:
        from stereo.flow_colour import flow_to_colour

        pic = flow_to_colour(np.where(res.occluded[..., None] & args.mask_viz, np.nan, res.flow))
        write_artifact(args.viz, lambda p: io.write_image(p, pic),
                       meta=make_meta("lumigraph.flow.viz", inputs=[out],
                                      params={"coding": "middlebury"}))
    say(args, f"wrote {out} and {prob_path(out)} ({res.levels} levels, {dt:.2f} s)")
    return 0


def main(argv=None, prog="lumigraph flow") -> int:
    from stereo.flow_methods import FLOW_METHODS

    methods = "\n".join(f"  {k:<15} {d}" for k, (_, d) in FLOW_METHODS.items())
    p = make_parser(prog, "Dense correspondence between two images: optical flow (coarse-to-fine "
                    "pyramid) or Sand-Teller video matching.\n\nmethods:\n" + methods,
                    epilog=EPILOG)
    p.add_argument("image0", help="first (primary) image")
    p.add_argument("image1", help="second (secondary) image, same size")
    p.add_argument("--out", required=True, help="output flow file (.flo)")
    p.add_argument("--method", choices=sorted(FLOW_METHODS), default="pyramid",
                   help="flow method (default: pyramid)")
    p.add_argument("--levels", default="auto",
                   help="pyramid levels, or 'auto' from the estimated largest motion (default)")
    p.add_argument("--window", type=int, default=9, help="matching window side, odd (default 9)")
    p.add_argument("--iterations", type=int, default=3, help="warps per level (default 3)")
    p.add_argument("--median-radius", type=int, default=0,
                   help="0: a 3x3 median after each warp (default). R > 0: a colour-guided "
                        "weighted median of radius R px after each level (Sun, Roth & Black): "
                        "sharper motion boundaries, slower; the bench's accuracy end uses 10")
    p.add_argument("--finest-level", type=int, default=0,
                   help="stop refining at this pyramid level and upsample (1: half size, about "
                        "4x faster, a little less accurate; default 0: full size)")
    p.add_argument("--viz", help="also write a Middlebury colour-coded picture (.png)")
    p.add_argument("--mask-viz", action="store_true",
                   help="paint occluded/unreliable pixels black in --viz")
    p.set_defaults(func=_flow)
    return run(p, argv)
