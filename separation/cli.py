"""``lumigraph separate``: direct/global separation of projector-lit captures.

Thin layer: parse, load and linearise the captures, call
:func:`separation.separate`, write ``direct.exr``, ``global.exr``, ``mask.png``
(each with ``.meta.json``). ``lumigraph separate patterns`` writes the projector
patterns the methods expect.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from lumigraph.capture.commandline import (
    BATCH_HELP,
    add_batch_options,
    check_planned,
    input_path,
    make_parser,
    number,
    output_dir,
    parse_size,
    run,
    say,
    warn,
)
from lumigraph.capture.device import add_device_option, resolve_device
from lumigraph.capture.errors import InputError

EPILOG = """\
examples:
  lumigraph render projector --out out/scenes/projector
  lumigraph separate out/scenes/projector --method checker --out out/separation
  lumigraph separate cap/checker_*.png --method checker --b 0.1 --out sep/
  lumigraph separate cap/s0.png cap/s1.png cap/s2.png --method sinusoid --out sep/
  lumigraph separate raw8/*.png --method checker --response response.json --out sep/
  lumigraph separate Curtain.mpg --method occluder --stride 2 --out sep/
  lumigraph separate patterns --kind checker --size 1024x768 --square 8 --shifts 4 --out pat/
  lumigraph separate stacks/ --method checker --out sep/ --workers 2   (stacks/*/stack.json)
  lumigraph separate big/*.tif --method checker --b 0.1 --tile-rows auto --memory 1GB --out sep/
  lumigraph separate big/s*.tif --method sinusoid --tile-rows 512 --out sep/

Inputs: linear images (EXR, PFM; 16-bit PNG/TIFF are taken as linear codes),
or 8-bit captures with --response (from 'lumigraph hdr'). A folder with a
stack.json from 'lumigraph render projector' supplies the method's images,
the all-black/all-white frames and the pattern layout. Checker images may
come in any order: each board's complement is found from the captures (a
board plus its complement is the all-lit image), and a board without one is
refused; sinusoid phases likewise. Without --b the black level is measured from
--black/--white frames when given, else taken as 0.

A video (.mpg, .avi, .mkv, .mp4, ...; read through OpenCV/FFmpeg) is one
input: its frames, every --stride-th, at most --max-frames, are the
captures; without --response its codes are linearised with the BT.709 curve.

mask.png: 0 trusted; otherwise 1 never lit, 2 saturated, 4 L+ - L- within noise.

""" + BATCH_HELP


def _linear(stack, response, where):
    """Captures as float32 linear values, the quantisation step and the clip level."""
    import numpy as np

    imgs = stack.images
    if imgs.dtype.kind == "f":
        return imgs.astype(np.float32), 0.0, None
    bd = int(stack.bit_depth or 8 * imgs.dtype.itemsize)
    if response is not None:
        if response.bit_depth != bd:
            raise InputError("--response", f"curve is for {response.bit_depth}-bit codes, "
                                           f"the images are {bd}-bit")
        c = imgs.shape[-1]
        if response.channels not in (1, c):
            raise InputError("--response", f"curve has {response.channels} channels, "
                                           f"the images have {c}")
        lin = response.linearize(imgs).astype(np.float32)
        top = float(np.max(response.exposure_table()))
        return lin, top / (2 ** bd - 1), top * 0.999
    if imgs.dtype == np.uint8:
        raise InputError(where, "8-bit captures are not linear; give --response response.json "
                                "(from 'lumigraph hdr response')")
    top = 2 ** bd - 1
    return (imgs.astype(np.float32) / top), 1.0 / top, 1.0


def _resolve(args):
    """The capture files, the black/white frames, the layout's complements and
    lit fraction (a stack.json folder supplies them), or the video input."""
    from lumigraph.capture.io import read_stack_json
    from lumigraph.separation.video import video_input

    inputs = [Path(p) for p in args.images]
    video = video_input(inputs, max_frames=args.max_frames, stride=args.stride)
    if video is not None:
        return inputs, None, None, None, args.alpha, video
    black = white = None
    complement_of = None
    alpha = args.alpha
    folder = inputs[0] if len(inputs) == 1 and inputs[0].is_dir() else None
    if folder is not None and (folder / "stack.json").exists():
        info = read_stack_json(folder / "stack.json")
        sets = info.get("sets")
        if sets:
            if args.method not in sets:
                raise InputError(folder / "stack.json", f"no image set for method {args.method!r} "
                                                        f"(has {', '.join(sorted(sets))})")
            inputs = [folder / n for n in sets[args.method]]
            flat = sets.get("flat")
            if flat and args.black is None and args.white is None and args.b is None:
                black, white = folder / flat[0], folder / flat[1]
            pat = info.get("patterns", {}).get(args.method, {})
            if args.method == "checker" and pat.get("complement_of"):
                complement_of = pat["complement_of"]
            if alpha is None and pat.get("lit_fraction") and args.method in ("checker", "occluder"):
                alpha = float(pat["lit_fraction"][0])
    return inputs, args.black or black, args.white or white, complement_of, alpha, None


def _flat_frames(black, white, shape):
    """The black/white frames, read whole, each checked against the captures' ``shape`` (H, W, C)."""
    from lumigraph.capture.io import read_stack

    extra, files = {}, []
    for name, p in (("black", black), ("white", white)):
        if p is not None:
            s = read_stack([p])
            if s.images.shape[1:] != tuple(shape):
                raise InputError(p, f"is {s.images.shape[2]}x{s.images.shape[1]}, the captures are "
                                    f"{shape[1]}x{shape[0]}")
            extra[name] = s
            files.append(str(p))
    return extra, files


def _flat_rows(black, white, shape, *, rows):
    """:func:`_flat_frames` opened for reading by rows (:func:`capture.tiles.read_stack_rows`:
    the bit depth decided as whole), each checked against the captures' ``shape``."""
    from lumigraph.capture.tiles import read_stack_rows

    frames, files = {}, []
    try:
        for name, p in (("black", black), ("white", white)):
            if p is not None:
                st = read_stack_rows([p], rows=rows)
                frames[name] = st
                if st.shape != tuple(shape):
                    raise InputError(p, f"is {st.shape[1]}x{st.shape[0]}, the captures are "
                                        f"{shape[1]}x{shape[0]}")
                files.append(str(p))
    except BaseException:
        for st in frames.values():
            st.close()
        raise
    return frames, files


def _load(args, resolved):
    from lumigraph.capture.io import read_stack
    from lumigraph.separation.video import read_video_stack

    inputs, black, white, complement_of, alpha, video = resolved
    if video is not None:
        return (read_video_stack(video, max_frames=args.max_frames, stride=args.stride), {},
                [str(video)], None, args.alpha)
    stack = read_stack(inputs)
    files = list(stack.paths)
    extra, flat_files = _flat_frames(black, white, stack.images.shape[1:])
    files += flat_files
    return stack, extra, files, complement_of, alpha


def _separate_batch(args, stacks: list[Path]) -> int:
    """``separate S1 S2 ... --out DIR`` (or a folder of stacks): each stack is
    one item, ``DIR/<stack>/`` written by the very command that separates one."""
    from lumigraph.capture.batch import command_item, item_name, run_items
    from lumigraph.capture.commandline import batch_item_argv
    from lumigraph.capture.io import read_stack
    from lumigraph.separation.result import FILES
    from lumigraph.separation.separate import check_options

    # the options and files every item uses, checked before any work: exit 2, not N failures
    check_options(alpha=args.alpha, b=args.b, tile=args.tile, noise_sigma=args.noise,
                  saturation=args.saturation)
    if args.response:
        from lumigraph.hdr.response import ResponseCurve

        ResponseCurve.load(args.response)
    for p in (args.black, args.white):
        if p:
            read_stack([p])
    out = Path(args.out)
    shared = [str(p) for p in (args.response, args.black, args.white) if p]
    items = []
    for st in stacks:
        target = out / item_name(st)
        items.append(command_item(item_name(st), inputs=(st, *shared),
                                  outputs=[target / f for f in FILES],
                                  module="lumigraph.separation.cli", prog="lumigraph separate",
                                  argv=batch_item_argv(args, [st], add=["--out", str(target)])))
    return run_items(items, out_dir=out, args=args, description="separating")


def _separate(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.separation import separate
    from lumigraph.separation.result import FILES
    from lumigraph.separation.separate import check_options

    # before any capture is read
    check_options(alpha=args.alpha, b=args.b, tile=args.tile, noise_sigma=args.noise,
                  saturation=args.saturation)
    from lumigraph.capture.batch import stack_folders

    stacks = stack_folders(args.images)
    if stacks is not None:
        return _separate_batch(args, stacks)
    out = Path(args.out)
    # 'separate D --out D' would put them beside the captures: refused now, not after the work
    check_planned([out / n for f in FILES for n in (f, f + ".meta.json")])
    device = resolve_device(args.device)  # before any capture is read: a missing GPU is exit 2
    response = None
    if args.response:
        from lumigraph.hdr.response import ResponseCurve

        response = ResponseCurve.load(args.response)
    t0 = time.perf_counter()
    resolved = _resolve(args)
    plan = _plan(args, resolved, device)
    if plan.rows is not None:
        return _separate_rows(args, resolved, plan, response, device, t0)
    stack, extra, files, complement_of, alpha = _load(args, resolved)
    where = stack.paths[0]
    if response is None and "video" in stack.info:
        from lumigraph.separation.video import video_response

        response = video_response(stack.images.shape[-1])
        warn(f"{files[0]}: codes linearised with the ITU-R BT.709 curve (the MPEG default; the "
             "stream declares none); give --response for a measured curve")
    images, quant, sat = _linear(stack, response, where)
    bw = {k: _linear(v, response, v.paths[0])[0][0] for k, v in extra.items()}
    if args.saturation is not None:
        sat = args.saturation
    t1 = time.perf_counter()
    sep = separate(images, method=args.method, alpha=alpha, b=args.b, black=bw.get("black"),
                   white=bw.get("white"), complement_of=complement_of, estimator=args.estimator,
                   noise_sigma=args.noise, quant_step=quant, saturation=sat, tile=args.tile,
                   names=stack.paths, device=device)
    t2 = time.perf_counter()
    meta = make_meta("lumigraph.separation", inputs=files,
                     params={"method": args.method, "alpha": alpha, "b_given": args.b,
                             "estimator": args.estimator,
                             "response": args.response or (response and response.method),
                             "video": stack.info.get("video"),
                             "noise": args.noise, "saturation": sat, "tile": args.tile,
                             "images": len(images), "device": device.name},
                     timings_s={"load": t1 - t0, "separate": t2 - t1},
                     extra={"tiles": plan.as_meta(images.shape[1])})
    sep.save(out, meta=meta)
    for w in sep.warnings:
        warn(w)
    q = sep.quality["mask_counts"]
    say(args, f"separated {len(images)} image(s) with {args.method}: "
              f"{q['valid']}/{q['total']} pixels trusted -> {out}/direct.exr, global.exr, mask.png")
    return 0


def _plan(args, resolved, device):
    """Whole or by bands (``--tile-rows``, ``--memory``; :func:`capture.tiles.plan_rows`)."""
    from lumigraph.capture.tiles import TilePlan, plan_rows, stack_geometry
    from lumigraph.separation.tiled import TILED_METHODS

    inputs, black, white, _, _, video = resolved
    if args.tile_rows == "off":
        return TilePlan(None, 0, "--tile-rows off: the whole image at once")
    why = None
    if args.method not in TILED_METHODS:  # (every method is: a future one may not be)
        why = f"method {args.method!r} is not done by bands"
    elif video is not None:
        why = "a video is decoded whole"
    elif device.uses_torch:
        why = f"the {device.name} estimator runs whole"
    geo = None if why else stack_geometry(inputs)
    if geo is None and why is None:
        if args.tile_rows is None:
            return TilePlan(None, 0, "whole: the captures are not in a format read by rows "
                                     "(TIFF, OpenEXR)")
        import numpy as np

        from lumigraph.capture.io import _stack_files
        from lumigraph.capture.tiles import open_rows

        files = _stack_files(inputs)[0]
        src = open_rows(files[0])  # read whole (the meta says so); only its size is used here
        try:
            geo = (len(files), *src.shape, np.dtype(src.dtype).itemsize)
        finally:
            src.close()
    if why is not None:
        if args.tile_rows is None:
            return TilePlan(None, 0, f"whole: {why}")
        where = "method" if args.method not in TILED_METHODS else (
            "device" if device.uses_torch else "images")
        raise InputError(where, f"cannot work by bands: {why}; use --tile-rows off")
    n, h, w, c, itemsize = geo
    # per pixel of a band: the codes, the linear float32 stack, the reordered copy and the
    # pair temporaries (about 3 float32 per capture), the outputs, the writers' copies, masks
    per = c * (n * (itemsize + 16) + 56)
    # the black/white frames are read by bands too: their codes, float32 and float64 copies
    # and the ratios (the black level's passes run one at a time, before the captures' split)
    if black or white:
        per = max(per, c * 2 * (itemsize + 4 + 8 + 8))
    from lumigraph.separation.residue import PERCENTILE_BYTES

    # held whatever the band: the exact order statistics' histograms of the black level or
    # the occluder's lit fraction (the outputs are written band by band)
    held = 2 * PERCENTILE_BYTES
    halo = 0
    if args.method != "checker" or args.estimator == "maxmin":  # (max/min: pairs or not)
        from lumigraph.separation.separate import residue_window

        # no complement pairs: the spatial residue check's box means (float64 prefix and
        # window sums of the global and mean images) and a halo of half its box; single's
        # tiles, one tile row beyond the band and its halo (its bilinear tile centres)
        per += 48 * c
        held += 2 * PERCENTILE_BYTES  # the exact percentiles' histograms
        halo = residue_window(args.tile) // 2 + (2 * args.tile if args.method == "single" else 0)
    budget = None if args.memory is None else args.memory
    from lumigraph.capture.tiles import DEFAULT_MEMORY

    left = (DEFAULT_MEMORY if budget is None else budget) - held
    if left <= 0:
        raise InputError("memory", f"{(held / 1e9):.2f} GB of histograms do not fit; raise it")
    plan = plan_rows(args.tile_rows, left, width=w, height=h, bytes_per_pixel=per, halo=halo)
    return plan


def _separate_rows(args, resolved, plan, response, device, t0) -> int:
    """``separate`` reading the captures by bands and writing its outputs by bands
    (:func:`separation.tiled.separate_rows`, :class:`separation.result.SeparationWriter`)."""
    from types import SimpleNamespace

    from lumigraph.capture.artifact import make_meta
    from lumigraph.capture.tiles import read_stack_rows
    from lumigraph.separation.result import SeparationWriter
    from lumigraph.separation.tiled import separate_rows

    inputs, black, white, complement_of, alpha, _ = resolved
    out = Path(args.out)
    stack = read_stack_rows(inputs, rows=plan.rows)
    cleanup = [stack]
    try:
        h, w, c = stack.shape
        where = stack.paths[0]

        def linear(y0, y1):
            return _linear(SimpleNamespace(images=stack.read(y0, y1), bit_depth=stack.bit_depth),
                           response, where)

        _, quant, sat = linear(0, 1)
        flats, flat_files = _flat_rows(black, white, (h, w, c), rows=plan.rows)
        for st in flats.values():
            cleanup.append(st)
        read_flat = None
        if len(flats) == 2:  # both: the black level is measured from them, read by bands

            def read_flat(y0, y1):
                return tuple(_linear(SimpleNamespace(images=flats[k].read(y0, y1),
                                                     bit_depth=flats[k].bit_depth),
                                     response, flats[k].paths[0])[0][0]
                             for k in ("black", "white"))

            read_flat(0, 1)  # a frame that cannot be linearised: refused before any work
        if args.saturation is not None:
            sat = args.saturation
        t1 = time.perf_counter()
        # each band's direct, global and mask go to their files as they are computed
        with SeparationWriter(out, width=w, height=h, channels=c) as files:
            sep = separate_rows(lambda y0, y1: linear(y0, y1)[0], height=h, rows=plan.rows,
                                count=len(stack.paths), write=files.write, method=args.method,
                                alpha=alpha, b=args.b, read_flat=read_flat,
                                complement_of=complement_of,
                                estimator=args.estimator, noise_sigma=args.noise,
                                quant_step=quant, saturation=sat, tile=args.tile,
                                names=stack.paths)
            read_whole = [s.path for st in cleanup for s in st.sources if s.whole]
            t2 = time.perf_counter()
            meta = make_meta("lumigraph.separation", inputs=[*stack.paths, *flat_files],
                             params={"method": args.method, "alpha": alpha, "b_given": args.b,
                                     "estimator": args.estimator,
                                     "response": args.response or (response and response.method),
                                     "video": None, "noise": args.noise, "saturation": sat,
                                     "tile": args.tile, "images": len(stack.paths),
                                     "device": device.name},
                             timings_s={"load": t1 - t0, "separate": t2 - t1},
                             extra={"tiles": {**plan.as_meta(h), "read_whole": read_whole}})
            files.finish(meta=meta, method=sep.method, params=sep.params, quality=sep.quality,
                         warnings=sep.warnings)
    finally:
        for st in cleanup:
            st.close()
    for msg in sep.warnings:
        warn(msg)
    q = sep.quality["mask_counts"]
    say(args, f"separated {len(stack.paths)} image(s) with {args.method} in "
              f"{-(-h // plan.rows)} bands of {plan.rows} rows: {q['valid']}/{q['total']} pixels "
              f"trusted -> {out}/direct.exr, global.exr, mask.png")
    return 0


def _patterns(args) -> int:
    from lumigraph.capture import patterns as pt

    size = args.size
    kinds = ["checker", "sinusoid", "stripe", "occluder", "flat"] if args.kind == "all" else [args.kind]
    if args.alpha is not None:
        pt.check_lit_fraction(args.alpha)  # whatever the kind
    out = Path(args.out)
    sets = []
    for k in kinds:
        if k == "checker":
            sets.append(pt.checker_set(size, square=args.square, shifts=args.shifts))
        elif k == "block":
            sets.append(pt.block_set(size, alpha=0.5 if args.alpha is None else args.alpha,
                                     tile=args.tile_cells, cell=args.square))
        elif k == "sinusoid":
            sets.append(pt.sinusoid_set(size, period=args.period))
        elif k == "stripe":
            sets.append(pt.stripe_set(size, period=args.period))
        elif k == "occluder":
            sets.append(pt.occluder_set(size, period=args.period, width=args.width))
        else:
            sets.append(pt.flat_set(size))
    for ps in sets:
        dest = out / ps.kind if len(sets) > 1 else out
        ps.save(dest)
        say(args, f"wrote {len(ps)} {ps.kind} pattern(s) at {size[0]}x{size[1]} -> {dest}")
    return 0


def _size(text: str) -> tuple[int, int]:
    """``--size WxH`` as ``(width, height)``, each side 8..20000 px."""
    try:
        return parse_size(text)
    except InputError as e:
        raise argparse.ArgumentTypeError(e.problem) from None


_size.__name__ = "size"


def build_patterns_parser(prog: str = "lumigraph separate patterns"):
    """The parser of ``lumigraph separate patterns``; each bound is the least
    value the pattern functions of :mod:`lumigraph.capture.patterns` accept
    (they check the rest: ``--square`` a multiple of ``--shifts``, …)."""
    from lumigraph.capture.patterns import KINDS

    p = make_parser(prog, "Write projector patterns (PNG, projector resolution) "
                    "and a stack.json, in the order the separation expects.", epilog=EPILOG)
    p.add_argument("--kind", default="checker", choices=[*KINDS, "all"])
    p.add_argument("--size", default=(1024, 768), type=_size, metavar="WxH",
                   help="projector resolution WxH (default 1024x768)")
    p.add_argument("--square", type=number(int, lo=1), default=8,
                   help="checker square (px) / block cell (px)")
    p.add_argument("--shifts", type=number(int, lo=1), default=4,
                   help="checker shift steps per axis (divides --square)")
    p.add_argument("--period", type=number(int, lo=2), default=16,
                   help="sinusoid/stripe/occluder period (px)")
    p.add_argument("--width", type=number(int, lo=1), default=2, help="occluder bar width (px)")
    p.add_argument("--alpha", type=number(float, lo=0, hi=1, lo_open=True, hi_open=True),
                   default=None, help="lit fraction of 'block' patterns")
    p.add_argument("--tile-cells", type=number(int, lo=2), default=4,
                   help="block tile size in cells")
    p.add_argument("--out", required=True, type=output_dir, help="output folder")
    # the pattern functions' arguments that differ from the flags' dests
    p.set_defaults(func=_patterns, arg_flags={"tile": "--tile-cells", "cell": "--square"})
    return p


def build_parser(prog: str = "lumigraph separate"):
    """The ``lumigraph separate`` parser (the ``patterns`` verb is
    :func:`build_patterns_parser`: a positional list of captures cannot share
    a parser with verbs). Bounds are :func:`separation.separate.check_options`'s."""
    from lumigraph.separation.methods import METHODS
    from lumigraph.separation.separate import MIN_TILE

    p = make_parser(prog, "Separate direct and global light from captures under high-frequency "
                    "projector patterns (Nayar et al. 2006).",
                    epilog=f"{EPILOG}\nmethods:\n{METHODS.help_text()}\n")
    p.add_argument("images", nargs="+", type=input_path,
                   help="captures (files, or a folder with stack.json); for a batch several "
                        "such folders, or one folder of them (DIR/<stack>/ each)")
    p.add_argument("--method", default="checker", choices=METHODS.names,
                   help="separation method (listed below)")
    p.add_argument("--alpha", type=number(float, lo=0, hi=1, lo_open=True, hi_open=True),
                   default=None, help="lit fraction of the patterns (default 0.5)")
    p.add_argument("--b", type=number(float, lo=0, hi=1, hi_open=True), default=None,
                   help="projector black level")
    p.add_argument("--black", type=input_path,
                   help="capture under an all-black projector frame (to measure b)")
    p.add_argument("--white", type=input_path,
                   help="capture under an all-white projector frame (to measure b)")
    p.add_argument("--response", type=input_path,
                   help="response.json for 8-bit (non-linear) captures")
    p.add_argument("--estimator", default="pairs", choices=["pairs", "maxmin"],
                   help="checker: noise-robust pairs (default) or the textbook max/min")
    p.add_argument("--noise", type=number(float, lo=0), default=0.0,
                   help="known noise std per capture (linear)")
    p.add_argument("--saturation", type=number(float, lo=0, lo_open=True), default=None,
                   help="linear clip level")
    p.add_argument("--tile", type=number(int, lo=MIN_TILE), default=16,
                   help="tile size for --method single (px)")
    from lumigraph.capture.tiles import MIN_ROWS, parse_memory

    p.add_argument(
        "--tile-rows", type=number(int, lo=MIN_ROWS, allow=("auto", "off")), default=None,
        metavar="ROWS|auto|off",
        help="read the captures in bands of ROWS full-width rows (the whole-image analysis "
             "first, then the per-pixel split) and write direct.exr, global.exr and mask.png "
             "band by band, so memory is bounded by the band, not the stack; the files are "
             "the same as whole, to the byte. auto: the tallest band within --memory; off: "
             "whole. Default: whole when it fits --memory, else auto (the meta's 'tiles' says "
             "which). Every method (and the --black/--white frames); a video and a torch "
             "--device run whole. Without complement pairs (sinusoid, single, "
             "occluder) the residue check reads each band with a halo and takes two more "
             "passes (the occluder's measured lit fraction three). Read by rows: TIFF and "
             "OpenEXR (other formats are read whole). Named --tile-rows, not --tile "
             "as in 'hdr merge': --tile is the single method's tile")
    p.add_argument(
        "--memory", type=parse_memory, default=None, metavar="SIZE",
        help="memory budget for --tile-rows auto and the default, e.g. 1GB, 512MB, 2GiB "
             "(default 2GB)")
    p.add_argument("--max-frames", type=number(int, lo=1), default=None,
                   help="video input: keep at most this many frames")
    p.add_argument("--stride", type=number(int, lo=1), default=1,
                   help="video input: keep every n-th frame")
    p.add_argument("--out", required=True, type=output_dir,
                   help="output folder (direct.exr, global.exr, mask.png)")
    add_device_option(p)
    for a in p._actions:
        if a.dest == "device":
            a.help += (". Ported here: the per-pixel estimators of every method; the "
                       "pairing, the noise model and the masks run on the CPU")
    add_batch_options(p)
    p.set_defaults(func=_separate, arg_flags={"noise_sigma": "--noise"})
    return p


def main(argv=None, prog="lumigraph separate") -> int:
    import sys

    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "patterns":
        return run(build_patterns_parser(f"{prog} patterns"), argv[1:])
    return run(build_parser(prog), argv)
