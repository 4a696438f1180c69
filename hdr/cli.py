"""``lumigraph hdr``: response curves, radiance merge, alignment, tone mapping,
HDR file conversion. Parses, loads, calls the library, saves."""

from __future__ import annotations

import argparse
import inspect
import time
from pathlib import Path

from lumigraph.capture.commandline import (
    BATCH_HELP,
    add_batch_options,
    add_verb,
    batch_requested,
    check_planned,
    input_path,
    make_parser,
    number,
    numbers,
    output_dir,
    output_file,
    output_file_or_dir,
    run,
    say,
    subparsers,
    warn,
)
from lumigraph.capture.device import add_device_option
from lumigraph.capture.errors import InputError
from lumigraph.capture.exposure import check_brightness_order
from lumigraph.hdr.methods import ALIGN_METHODS, RESPONSE_METHODS, TONEMAP_METHODS

EPILOG = """\
examples:
  lumigraph render bracket --out out/bracket
  lumigraph hdr response out/bracket --method debevec --out out/hdr/response.json --plot out/hdr/curve.png
  lumigraph hdr merge out/bracket --response out/hdr/response.json --out out/hdr/radiance.exr
  lumigraph hdr tonemap out/hdr/radiance.exr --method reinhard-local --out out/hdr/tonemapped.png
  lumigraph hdr align IMG_*.jpeg --out aligned/
  lumigraph hdr convert out/hdr/radiance.exr out/hdr/radiance.hdr
  lumigraph render bracket_video --out out/video
  lumigraph hdr video out/video --response out/hdr/response.json --out out/hdr/video --tonemap

Inputs are image files in bracket order or a folder with stack.json; exposure
times come from EXIF or stack.json unless --times gives them (fractions such
as 1/250 are fine). Every output gets a <output>.meta.json sidecar.
"""


MERGE_EPILOG = """\
examples:
  lumigraph hdr merge out/bracket --response response.json --out radiance.exr
  lumigraph hdr merge shots/ --response response.json --out radiance/            (shots/*/stack.json)
  lumigraph hdr merge shots/ --response response.json --out radiance/ --workers 2
  lumigraph hdr merge shots/ --response response.json --out radiance/ --scheduler tcp://10.0.0.5:8786

""" + BATCH_HELP


# The library names the times by its argument; --times sets them.
TIMES_FLAG = {"exposure_times_s": "--times"}
# ... and the noise model by its two arguments; --noise sets both.
NOISE_FLAG = {"full_well_e": "--noise", "read_noise_e": "--noise"}


def _mask_path(out) -> Path:
    """The flags PNG that ``hdr merge`` writes beside its radiance map."""
    return Path(out).with_name(Path(out).stem + ".mask.png")


MERGE_EXTS = (".exr", ".hdr", ".tif", ".tiff", ".pfm")  # what 'hdr merge' writes


def _times(args):
    return list(args.times) if args.times else None


def _load(args, *, need_times=True):
    """The bracket and its exposures: the stack reader's effective exposure
    (an aperture bracket's f-numbers applied), as every HDR verb uses them."""
    from lumigraph.capture.io import read_stack

    stack = read_stack(args.images, times=_times(args), need_times=need_times,
                       bit_depth=args.bit_depth)
    if stack.images.dtype.kind == "f":
        raise InputError(stack.paths[0], "float images are already linear; merge needs code values "
                                         "(integer PNG/TIFF/JPEG/RAW)")
    times = stack.effective_exposure_times_s
    args.order_warnings = [] if times is None else check_brightness_order(
        stack.images, times, stack.paths, force=args.force)  # exit 2 naming the files
    for w in args.order_warnings:
        warn(w)
    return stack, times


def _reference_time(text: str) -> tuple[str, float]:
    """``--reference-time FILE=SECONDS``: an image of the bracket and its exact
    exposure time (a fraction such as 1/250 is fine), > 0 and finite."""
    from fractions import Fraction

    name, sep, value = text.rpartition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected FILE=SECONDS, got {text!r}")
    try:
        x = float(Fraction(value.strip()))
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"cannot read {value!r} as seconds") from None
    if not (x > 0 and x < float("inf")):
        raise argparse.ArgumentTypeError(f"expected seconds > 0, got {value!r}")
    return name, x


_reference_time.__name__ = "reference time"


def _reference_times(args, stack) -> dict[int, float]:
    """``--reference-time`` as the library's ``{image index: seconds}``, each FILE
    matched to the bracket's images by path or by file name."""
    out: dict[int, float] = {}
    for name, secs in args.reference_time or ():
        hits = [i for i, p in enumerate(stack.paths)
                if Path(p) == Path(name) or Path(p).name == Path(name).name]
        if len(hits) != 1:
            raise InputError("reference_times", f"{name} is not one of the bracket's images "
                                                f"({', '.join(Path(p).name for p in stack.paths)})")
        out[hits[0]] = secs
    return out


def _response(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta
    from lumigraph.hdr.debevec1997 import check_smoothness
    from lumigraph.hdr.mitsunaga1999 import check_order
    from lumigraph.hdr.samples import check_samples

    # --out and --plot were checked by run() before this (suffix, writable,
    # not an input, not a folder), each under its own flag
    out = Path(args.out)
    check_smoothness(args.smoothness)
    check_order(args.order)
    if args.samples is not None:
        check_samples(args.samples)  # the fits' own range, before the bracket is read
    stack, times = _load(args, need_times=args.method != "linear" and not args.linear)
    method = "linear" if (args.linear or stack.linear) else args.method
    if method == "linear" and args.method != "linear":
        say(args, "input is linear (RAW, float or declared linear in stack.json): no response "
                  "curve is needed; writing the identity response")
    m = RESPONSE_METHODS.resolve(method)
    fn = m.load()
    opts = {"bit_depth": stack.bit_depth}
    # Default: the method's own (Robertson's per-code means need 5000 pixels
    # where a smoothness-regularised fit needs 600).
    default = inspect.signature(fn).parameters.get("samples")
    samples = args.samples if args.samples is not None else (
        None if default is None else default.default)
    if "smoothness" in m.options:
        opts["smoothness"] = args.smoothness
    if "order" in m.options:
        opts["order"] = args.order
    if "samples" in m.options:
        opts["samples"] = samples
        opts["rng"] = np.random.default_rng(args.seed)
    if args.reference_time:
        if "reference_times" not in inspect.signature(fn).parameters:
            raise InputError("reference_times", f"only mitsunaga-nayar refines the exposures; "
                                                f"for {method} give the exact times with --times")
        opts["reference_times"] = _reference_times(args, stack)
    if args.noise is not None:
        if "noise" not in m.options:
            raise InputError("noise", f"applies to the debevec method, not {method}")
        opts["noise"] = tuple(args.noise)
    t0 = time.perf_counter()
    curve = fn(stack.images, times, **opts)
    dt = time.perf_counter() - t0
    for w in curve.warnings:
        warn(w)
    meta = make_meta("lumigraph.response", inputs=stack.paths,
                     params={"method": method, "times_s": times,
                             "samples": samples if "samples" in m.options else None,
                             "seed": args.seed, "bit_depth": stack.bit_depth,
                             "bit_depth_source": stack.bit_depth_source,
                             "exif_orientation": list(stack.orientations),
                             "noise": (dict(zip(("full_well_e", "read_noise_e"), args.noise,
                                                strict=True)) | {"source": "given (--noise)"})
                             if args.noise is not None else None},
                     model={"method": curve.method, "selection": curve.selection},
                     quality=curve.fit, timings_s={"fit": dt},
                     warnings=(*args.order_warnings, *curve.warnings))
    curve.save(out, meta=meta)
    if args.plot:
        plot_curve(curve, args.plot)
    say(args, f"wrote {out} ({curve.method}, {curve.bit_depth}-bit, {dt:.2f} s)")
    return 0


def plot_curve(curve, path) -> None:
    """Plot ``ln f⁻¹(z)`` per channel against the code value to a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from lumigraph.capture.artifact import atomic_path

    z = np.arange(curve.code_max + 1)
    fig, ax = plt.subplots(figsize=(5, 4))
    for ch, col in zip(range(curve.channels), ("tab:red", "tab:green", "tab:blue"), strict=False):
        ax.plot(curve.g[ch], z, color=col, lw=1.2, label=f"channel {ch}")
    ax.set_xlabel("ln exposure  g(z) = ln f⁻¹(z)")
    ax.set_ylabel("code value z")
    ax.set_title(f"response: {curve.method}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)



def _check_curve(curve, stack, path, what, *, channels=None):
    """The response must be for the stack's bit depth and channels."""
    channels = stack.images.shape[-1] if channels is None else channels
    if stack.bit_depth is not None and stack.bit_depth != curve.bit_depth:
        raise InputError(path, f"curve is {curve.bit_depth}-bit but the {what} are "
                               f"{stack.bit_depth}-bit; recover a curve at this depth")
    if curve.channels not in (1, channels):
        raise InputError(path, f"curve has {curve.channels} channels, the {what} "
                               f"{channels}")

def _noise_pair(text: str) -> list[float]:
    """``--noise FULL_WELL_E,READ_NOISE_E``: two numbers, each within
    :func:`lumigraph.hdr.merge.check_noise`'s range (its message, naming which)."""
    from lumigraph.hdr.merge import check_noise

    parts = [t.strip() for t in text.split(",")]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected FULL_WELL_E,READ_NOISE_E (two numbers), got "
                                         f"{text!r}")
    vals = []
    for t in parts:
        try:
            vals.append(float(t))  # NaN and inf too: check_noise says which one is wrong
        except ValueError:
            raise argparse.ArgumentTypeError(f"cannot read {t!r} as a number") from None
    try:  # the library's ranges (and messages): a full well > 0, a read noise >= 0, finite
        return list(check_noise("variance", *vals))
    except InputError as e:
        raise argparse.ArgumentTypeError(e.problem) from None


_noise_pair.__name__ = "noise"


def _noise(args) -> tuple[dict, dict]:
    """The variance weights' sensor noise: ``--noise FULL_WELL_E,READ_NOISE_E`` or the
    library's defaults (not estimated from the stack). Returns the arguments
    for ``merge`` (none when not given) and the record of what was used and
    where it came from; the library checks them before any image is read."""
    from lumigraph.hdr.merge import check_noise

    if args.noise is None:
        fw, rn = check_noise(args.weights)
        return {}, {"full_well_e": fw, "read_noise_e": rn,
                    "source": "library default (not estimated from the images)"}
    fw, rn = check_noise(args.weights, *args.noise)  # two numbers: the parser's type
    given = {"full_well_e": fw, "read_noise_e": rn}
    return given, {**given, "source": "given (--noise)"}


def _merge_batch(args, brackets: list[Path]) -> int:
    """``hdr merge B1 B2 ... --out DIR`` (or a folder of brackets): each bracket
    is one item, ``DIR/<bracket>.exr`` and its mask, merged by the very
    command that merges one bracket."""
    from lumigraph.capture.batch import command_item, item_name, run_items
    from lumigraph.capture.commandline import batch_item_argv
    from lumigraph.hdr.response import ResponseCurve

    out = Path(args.out)
    _noise(args)  # the options every item uses, checked once before any work
    ResponseCurve.load(args.response)  # and the file every item reads: a bad one is exit 2
    if out.suffix.lower() in MERGE_EXTS:
        raise InputError("out", f"{len(brackets)} brackets give {len(brackets)} radiance maps: "
                                f"name a folder, not one file ({out})")
    items = []
    for b in brackets:
        name = item_name(b)
        target = out / f"{name}.exr"
        items.append(command_item(name, inputs=(b, args.response),
                                  outputs=(_mask_path(target), target),
                                  module="lumigraph.hdr.cli", prog="lumigraph hdr",
                                  argv=batch_item_argv(args, [b], add=["--out", str(target)])))
    return run_items(items, out_dir=out, args=args, description="merging")


def _merge(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.batch import stack_folders
    from lumigraph.capture.device import resolve_device
    from lumigraph.capture.io import write_exr, write_image
    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.response import ResponseCurve

    brackets = stack_folders(args.images)
    if brackets is not None:
        return _merge_batch(args, brackets)
    out = Path(args.out)
    dev = resolve_device(args.device)  # before the bracket is read
    if out.suffix.lower() not in MERGE_EXTS:
        raise InputError("out", f"one bracket gives one radiance map: name a file ending in "
                                f"{' or '.join(MERGE_EXTS)} (a folder is for several brackets)")
    given, noise = _noise(args)
    curve = ResponseCurve.load(args.response)
    plan = _merge_plan(args)
    if plan.rows is not None:
        return _merge_by_rows(args, plan, curve, given, noise)
    stack, times = _load(args)
    _check_curve(curve, stack, args.response, "images")
    t0 = time.perf_counter()
    m = merge(stack.images, times, curve, weights=args.weights, deghost=args.deghost,
              device=dev, **given)
    dt = time.perf_counter() - t0
    for w in m.warnings:
        warn(w)
    meta = make_meta("lumigraph.radiance", inputs=[*stack.paths, args.response],
                     params={"weights": args.weights, "deghost": args.deghost, "times_s": times,
                             "device": dev.name,
                             "response_method": curve.method,
                             "noise": noise if args.weights == "variance" else None,
                             "bit_depth": stack.bit_depth,
                             "bit_depth_source": stack.bit_depth_source,
                             "exif_orientation": list(stack.orientations)},
                     quality=m.stats, timings_s={"merge": dt},
                     warnings=(*args.order_warnings, *m.warnings),
                     extra={**MERGE_META, "tiles": plan.as_meta(stack.images.shape[1])})
    mask_path = _mask_path(out)
    flags = np.bitwise_or.reduce(m.flags, axis=2).astype(np.uint8)
    write_artifact(mask_path, lambda p: write_image(p, flags),
                   meta=make_meta("lumigraph.radiance_mask", inputs=stack.paths))
    if out.suffix.lower() == ".exr":
        write_artifact(out, lambda p: write_exr(p, m.radiance), meta=meta)
    else:
        from lumigraph.hdr.formats import write_hdr_image

        write_artifact(out, lambda p: write_hdr_image(p, m.radiance), meta=meta)
    say(args, f"wrote {out} and {mask_path.name} ({dt:.2f} s)")
    return 0


MERGE_META = {"units": "relative radiance: f^-1(z)/t, f^-1(z_mid)=z_mid/z_max",
              "mask": "flags PNG beside the output: 1 clipped everywhere (lower bound), 2 black "
                      "everywhere (upper bound), 4 ghost"}


def _merge_plan(args):
    """Whole or by bands (``--tile``, ``--memory``; :func:`capture.tiles.plan_rows`)."""
    import numpy as np

    from lumigraph.capture.tiles import TilePlan, plan_rows, stack_geometry
    from lumigraph.hdr.tiled import merge_bytes_per_pixel

    if args.tile == "off":
        return TilePlan(None, 0, "--tile off: the whole image at once")
    geo = stack_geometry(args.images)
    if geo is None:
        if args.tile is None:
            return TilePlan(None, 0, "whole: the images are not in a format read by rows "
                                     "(TIFF, OpenEXR)")
        from lumigraph.capture.io import _stack_files
        from lumigraph.capture.tiles import open_rows

        files = _stack_files(args.images)[0]
        s = open_rows(files[0])  # read whole (the meta says so); only its size is used here
        geo = (len(files), *s.shape, np.dtype(s.dtype).itemsize)
    p, h, w, c, isz = geo
    per, band = merge_bytes_per_pixel(p, c, isz)
    return plan_rows(args.tile, args.memory, width=w, height=h, bytes_per_pixel=per,
                     band_bytes_per_pixel=band)


def _merge_by_rows(args, plan, curve, given, noise) -> int:
    """``hdr merge`` by bands of rows: the radiance as scanline OpenEXR and the
    mask PNG written band by band (the same bytes, resp. pixels, as whole)."""
    from contextlib import ExitStack

    import numpy as np

    from lumigraph.capture.artifact import atomic_path, make_meta
    from lumigraph.capture.exposure import check_brightness_order
    from lumigraph.capture.tiles import (
        ExrRowWriter,
        PngRowWriter,
        finish_artifact,
        read_stack_rows,
    )
    from lumigraph.hdr.tiled import merge_rows

    out = Path(args.out)
    if out.suffix.lower() != ".exr":
        raise InputError(out, f"by bands ({plan.reason}) the radiance is written by rows as "
                              "OpenEXR: name it .exr (or give --tile off to merge it whole)")
    t0 = time.perf_counter()
    stack = read_stack_rows(args.images, times=_times(args), need_times=True,
                            bit_depth=args.bit_depth, rows=plan.rows)
    with ExitStack() as cleanup:
        cleanup.callback(stack.close)
        if stack.dtype.kind == "f":
            raise InputError(stack.paths[0], "float images are already linear; merge needs code "
                                             "values (integer PNG/TIFF/JPEG/RAW)")
        times = stack.effective_exposure_times_s
        order_warnings = check_brightness_order(
            stack.sample, times, stack.paths, force=args.force,
            max_pixels=stack.sample.shape[1] * stack.sample.shape[2])
        for w in order_warnings:
            warn(w)
        _check_curve(curve, stack, args.response, "images", channels=stack.shape[2])
        h, w, c = stack.shape
        mask_path = _mask_path(out)
        t1 = time.perf_counter()
        with atomic_path(out) as tmp, atomic_path(mask_path) as tmp_mask:
            rad = ExrRowWriter(tmp, w, h, c)
            cleanup.callback(rad.close)
            flags = PngRowWriter(tmp_mask, w, h, 1, np.uint8)
            cleanup.callback(flags.close)
            r = merge_rows(stack, times, curve, rows=plan.rows, write_radiance=rad.write,
                           write_flags=flags.write, weights=args.weights, deghost=args.deghost,
                           **given)
            rad.close()
            flags.close()
            dt = time.perf_counter() - t1
            for msg in r.warnings:
                warn(msg)
            finish_artifact(mask_path, tmp_mask,
                            make_meta("lumigraph.radiance_mask", inputs=stack.paths))
            tiles = {**plan.as_meta(h),
                     "read_whole": [s.path for s in stack.sources if s.whole]}
            meta = make_meta("lumigraph.radiance", inputs=[*stack.paths, args.response],
                             params={"weights": args.weights, "deghost": args.deghost,
                                     "times_s": times, "response_method": curve.method,
                                     "noise": noise if args.weights == "variance" else None,
                                     "bit_depth": stack.bit_depth,
                                     "bit_depth_source": stack.bit_depth_source,
                                     "exif_orientation": [s.orientation
                                                          for s in stack.sources]},
                             quality=r.stats,
                             timings_s={"first_pass": t1 - t0, "merge": dt},
                             warnings=(*order_warnings, *r.warnings),
                             extra={**MERGE_META, "tiles": tiles})
            finish_artifact(out, tmp, meta)
    say(args, f"wrote {out} and {mask_path.name} ({dt:.2f} s, {r.bands} bands of {plan.rows} "
              "rows)")
    return 0


def _align(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_json
    from lumigraph.capture.io import read_stack, write_image, write_stack_json
    from lumigraph.hdr.ward2003 import check_align_options

    out = Path(args.out)
    check_align_options(reference=args.reference, levels=args.levels)
    stack = read_stack(args.images, times=_times(args))
    if stack.images.dtype.kind == "f":
        raise InputError(stack.paths[0], "align works on code values (PNG/TIFF/JPEG)")
    check_align_options(reference=args.reference, levels=args.levels, count=len(stack.paths))
    names = [Path(src).stem + ".png" for src in stack.paths]
    seen: dict[str, str] = {}
    for name, src in zip(names, stack.paths, strict=True):
        if name in seen:  # two inputs would be written to one file
            raise InputError(src, f"has the same name as {seen[name]}; the aligned images are "
                                  f"named after their inputs ({name}): rename one")
        seen[name] = src
    # every file of the folder, before the (slow) alignment: 'align D --out D'
    # would replace the original exposures
    check_planned([out / n for n in (*names, "stack.json", "stack.json.meta.json")])
    aligned, shifts = ALIGN_METHODS.resolve(args.method)(stack.images, reference=args.reference,
                                                         levels=args.levels)
    out.mkdir(parents=True, exist_ok=True)
    for img, name in zip(aligned, names, strict=True):
        write_image(out / name, img if img.shape[-1] > 1 else img[..., 0],
                    bit_depth=stack.bit_depth if img.dtype == np.uint16 else None)
    info = {k: v for k, v in stack.info.items() if k not in ("images", "schema", "schema_version")}
    if stack.exposure_times_s is not None:
        info["exposure_times_s"] = list(stack.exposure_times_s)
    info["bit_depth"] = stack.bit_depth
    info["mtb_shifts_px"] = [list(s) for s in shifts]
    write_json(out / "stack.json.meta.json",
               make_meta("lumigraph.aligned_stack", inputs=stack.paths,
                         params={"levels": args.levels, "reference": args.reference},
                         quality={"shifts_px": shifts}))
    write_stack_json(out, names, **info)
    say(args, f"aligned {len(names)} images into {out}; shifts (dx, dy): {shifts}")
    return 0


def _tonemap(args) -> int:
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.device import resolve_device
    from lumigraph.capture.io import write_image
    from lumigraph.hdr.formats import read_hdr_image
    from lumigraph.hdr.reinhard2002 import check_key

    out = Path(args.out)
    check_key(args.key)  # before the radiance is read
    dev = resolve_device(args.device)
    plan = _tonemap_plan(args)
    if plan.rows is not None:
        return _tonemap_by_rows(args, plan)
    img = read_hdr_image(args.input)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    args.arg_flags = {"radiance": args.input}  # the library checks it; name the file it came from
    ldr = TONEMAP_METHODS.resolve(args.method)(img, key=args.key, bit_depth=args.bit_depth,
                                               device=dev)
    meta = make_meta("lumigraph.tonemapped", inputs=[args.input],
                     params={"method": args.method, "key": args.key, "bit_depth": args.bit_depth,
                             "device": dev.name},
                     extra={"tiles": plan.as_meta(img.shape[0])})
    write_artifact(out, lambda p: write_image(p, ldr), meta=meta)
    say(args, f"wrote {out}")
    return 0


def _tonemap_plan(args):
    """Whole or by bands: only OpenEXR radiance is read by rows."""
    from lumigraph.capture.io import EXR_EXTS
    from lumigraph.capture.tiles import ExrRows, TilePlan, plan_rows
    from lumigraph.hdr.reinhard2002 import local_halo
    from lumigraph.hdr.tiled import tonemap_bytes_per_pixel

    halo = local_halo() if args.method == "reinhard-local" else 0
    if args.tile == "off":
        return TilePlan(None, halo, "--tile off: the whole image at once")
    if Path(args.input).suffix.lower() not in EXR_EXTS:
        if args.tile is None:
            return TilePlan(None, halo, "whole: only OpenEXR radiance is read by rows")
        from lumigraph.hdr.formats import read_hdr_image

        h, w = read_hdr_image(args.input).shape[:2]  # read whole (the meta says so)
        c = 3
    else:
        src = ExrRows(args.input)
        (h, w, c), _ = src.shape, src.close()
    per, band = tonemap_bytes_per_pixel(args.method, c, args.bit_depth)
    return plan_rows(args.tile, args.memory, width=w, height=h, bytes_per_pixel=per,
                     band_bytes_per_pixel=band, halo=halo)


def _tonemap_by_rows(args, plan) -> int:
    """``hdr tonemap`` by bands: statistics first, then band by band to a PNG
    or TIFF written by rows (the same pixels as whole)."""
    from contextlib import ExitStack

    from lumigraph.capture.artifact import atomic_path, make_meta
    from lumigraph.capture.io import EXR_EXTS
    from lumigraph.capture.tiles import ArrayRows, ExrRows, finish_artifact, row_writer
    from lumigraph.hdr.tiled import tonemap_rows

    out = Path(args.out)
    if Path(args.input).suffix.lower() in EXR_EXTS:
        src = ExrRows(args.input)
    else:
        from lumigraph.hdr.formats import read_hdr_image

        src = ArrayRows(read_hdr_image(args.input), args.input)
    args.arg_flags = {"radiance": args.input}  # the library checks it; name the file it came from
    t0 = time.perf_counter()
    with ExitStack() as cleanup:
        cleanup.callback(src.close)
        h, w, _ = src.shape
        dtype = "uint8" if args.bit_depth == 8 else "uint16"
        with atomic_path(out) as tmp:
            writer = row_writer(tmp, w, h, 3, dtype, rows=plan.rows)
            # closed inside atomic_path: a writer thread (TIFF) must be done with
            # the temporary before an error's cleanup removes it
            try:
                r = tonemap_rows(src, rows=plan.rows, write=writer.write, method=args.method,
                                 key=args.key, bit_depth=args.bit_depth)
            finally:
                writer.close()
            meta = make_meta("lumigraph.tonemapped", inputs=[args.input],
                             params={"method": args.method, "key": args.key,
                                     "bit_depth": args.bit_depth},
                             quality=r.stats, timings_s={"tonemap": time.perf_counter() - t0},
                             extra={"tiles": {**plan.as_meta(h),
                                              "read_whole": [src.path] if src.whole else []}})
            finish_artifact(out, tmp, meta)
    say(args, f"wrote {out} ({r.bands} bands of {plan.rows} rows)")
    return 0


def _convert(args) -> int:
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.hdr.formats import read_hdr_image, write_hdr_image

    out = Path(args.output)
    img = read_hdr_image(args.input)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    meta = make_meta("lumigraph.hdr_image", inputs=[args.input],
                     params={"logluv_bits": args.logluv_bits, "half": args.half})
    write_artifact(out, lambda p: write_hdr_image(p, img, logluv_bits=args.logluv_bits,
                                                  half=args.half), meta=meta)
    say(args, f"wrote {out}")
    return 0


def _frame_meta(src, response, i: int, exposure_s: float, params: dict, quality: dict) -> dict:
    """The sidecar of an HDR video's frame ``i`` (one run, or one batch item)."""
    from lumigraph.capture.artifact import make_meta

    return make_meta("lumigraph.radiance", inputs=[src, response],
                     params={"frame": i, "exposure_s": exposure_s, **params}, quality=quality,
                     extra={"method": "kang2003",
                            "units": "relative radiance: f^-1(z)/t, f^-1(z_mid)=z_mid/z_max",
                            "flags": "per pixel-channel in quality: 8 warped from neighbours, "
                                     "16 fallback (clipping bound), 4 neighbour rejected"})


def video_frame(*, paths: list[str], times: list[float], index: int, first: int,
                bit_depth: int | None, response: str, window: int, consistency_sigma: float,
                device: str, out: str) -> list[str]:
    """One batch item of ``hdr video``: frame ``first + index`` of the video,
    from its neighbour frames ``paths`` (their ``times``, effective seconds),
    written to ``out`` with its sidecar. Kang et al. complete a frame from
    frames i-1..i+1 only, so this is the single run's frame to the bit
    (:func:`lumigraph.hdr.kang2003.hdr_video`'s ``only``). Returns the frame's
    warnings."""
    from lumigraph.capture.artifact import write_artifact
    from lumigraph.capture.device import resolve_device
    from lumigraph.capture.io import read_stack, write_exr
    from lumigraph.hdr.kang2003 import hdr_video
    from lumigraph.hdr.response import ResponseCurve

    curve = ResponseCurve.load(response)
    stack = read_stack(paths, times=times, need_times=True, bit_depth=bit_depth)
    v = hdr_video(stack.images, stack.effective_exposure_times_s, curve, window=window,
                  consistency_sigma=consistency_sigma, device=resolve_device(device),
                  only=[index])
    quality = {**v.frames[0], "frame": first + index}  # indices into the whole video
    if "pair" in quality["flow"]:
        quality["flow"] = {**quality["flow"], "pair": [first + k for k in quality["flow"]["pair"]]}
    write_artifact(out, lambda p: write_exr(p, v.radiance[0]),
                   meta=_frame_meta(paths[index], response, first + index, v.exposure_times_s[0],
                                    v.params, quality))
    return list(v.warnings)


def _video_batch(args, stack) -> int:
    """``hdr video`` on a Dask cluster (``--workers``/``--scheduler``): each
    output frame one item, whose inputs are its neighbour frames; then, in
    this process, ``video.meta.json`` from the frames' sidecars and, with
    ``--tonemap``, the temporal tone mapping, streaming over the written
    frames. ``stack`` is the frames' :class:`capture.io.StackHeader`: this
    process holds one frame at a time, whatever the video's length."""
    import json

    import numpy as np

    from lumigraph.capture.artifact import make_meta, meta_path, write_artifact, write_json
    from lumigraph.capture.batch import Item, report, run_batch
    from lumigraph.capture.io import read_exr, write_image
    from lumigraph.hdr.kang2003 import (
        frame_log_stats,
        frames_used,
        tonemap_frame,
        video_exposure,
    )

    out = Path(args.out)
    n = len(stack.paths)
    times = list(stack.effective_exposure_times_s)
    items = []
    for i in range(n):
        r = frames_used(i, n)
        lo, hi = r.start, r.stop
        target = out / f"frame_{i:03d}.exr"
        items.append(Item(target.stem, inputs=(*stack.paths[lo:hi], str(args.response)),
                          outputs=(str(target),), func="lumigraph.hdr.cli:video_frame",
                          kwargs={"paths": list(stack.paths[lo:hi]), "times": times[lo:hi],
                                  "index": i - lo, "first": lo, "bit_depth": stack.bit_depth,
                                  "response": str(args.response), "window": args.window,
                                  "consistency_sigma": args.consistency_sigma,
                                  "device": args.device, "out": str(target)}))
    result = run_batch(items, out_dir=out, workers=args.workers, scheduler=args.scheduler,
                       quiet=args.quiet, description="hdr video")
    status = report(result, quiet=args.quiet)
    if result.failed:
        return status
    frames = [json.loads(meta_path(out / f"frame_{i:03d}.exr").read_text())["quality"]
              for i in range(n)]
    params = json.loads(meta_path(out / "frame_000.exr").read_text())["params"]
    params = {k: v for k, v in params.items() if k not in ("frame", "exposure_s")}
    tm = None
    if args.tonemap:
        # tonemap_video one frame in memory at a time, to the bit: only each
        # frame's log-average and log-max cross frames, so one pass over the
        # written frames gathers them, a second maps and writes each frame
        tm = video_exposure([frame_log_stats(read_exr(out / f"frame_{i:03d}.exr"))
                             for i in range(n)], key=args.key, temporal=args.temporal)
        for i, src in enumerate(stack.paths):
            png = tonemap_frame(read_exr(out / f"frame_{i:03d}.exr"), tm, i)
            write_artifact(out / f"frame_{i:03d}.png", lambda p, png=png: write_image(p, png),
                           meta=make_meta("lumigraph.tonemapped", inputs=[src], params=tm.params,
                                          quality={"log_average": float(tm.log_average[i]),
                                                   "log_average_used":
                                                       float(tm.log_average_used[i])}))
            del png
    shares = {k: float(np.mean([f["sources"][k] for f in frames])) for k in frames[0]["sources"]}
    warnings = [w for o in result.outcomes for w in o.warnings]
    summary = make_meta("lumigraph.hdr_video", inputs=[*stack.paths, args.response],
                        params={"times_s": times, **params, "tonemap": bool(args.tonemap),
                                "key": args.key, "temporal": args.temporal,
                                "bit_depth": stack.bit_depth,
                                "bit_depth_source": stack.bit_depth_source},
                        quality={"mean_sources": shares,
                                 "flicker": None if tm is None else tm.flicker, "frames": frames},
                        timings_s={"batch": result.wall_s}, warnings=warnings,
                        extra={"engine": result.engine})
    write_json(out / "video.meta.json", summary)
    return status


def _video(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact, write_json
    from lumigraph.capture.commandline import progress
    from lumigraph.capture.device import resolve_device
    from lumigraph.capture.io import read_stack, scan_stack, write_exr, write_image
    from lumigraph.hdr.kang2003 import (
        check_temporal,
        check_video_options,
        hdr_video,
        tonemap_video,
    )
    from lumigraph.hdr.reinhard2002 import check_key
    from lumigraph.hdr.response import ResponseCurve

    out = Path(args.out)
    # the library's own ranges, before the frames are read
    check_temporal(args.temporal)
    check_key(args.key)
    check_video_options(window=args.window, consistency_sigma=args.consistency_sigma)
    dev = resolve_device(args.device)
    curve = ResponseCurve.load(args.response)
    batch = batch_requested(args)
    if batch:
        # the items read their own frames: here only what every item is given
        # (times, bit depth) and the checks, one decoded frame at a time -- a
        # video can be thousands of frames
        stack = scan_stack(args.frames, times=_times(args), need_times=True,
                           bit_depth=args.bit_depth)
        dtype, channels = stack.dtype, stack.shape[-1]
    else:
        stack = read_stack(args.frames, times=_times(args), need_times=True,
                           bit_depth=args.bit_depth)
        dtype, channels = stack.images.dtype, stack.images.shape[-1]
    # hdr_video checks its frames (at least 2 of them); an error about them
    # names the input they came from
    args.arg_flags = {**TIMES_FLAG,
                      "frames": stack.paths[0] if len(stack.paths) == 1 else str(args.frames[0])}
    if dtype.kind == "f":
        raise InputError(stack.paths[0], "float frames are already linear; HDR video needs "
                                         "code values (integer PNG/TIFF)")
    _check_curve(curve, stack, args.response, "frames", channels=channels)
    planned = [f"frame_{i:03d}.exr" for i in range(len(stack.paths))]
    if args.tonemap:
        planned += [f"frame_{i:03d}.png" for i in range(len(stack.paths))]
    check_planned([out / n for n in (*planned, *(n + ".meta.json" for n in planned),
                                     "video.meta.json")])
    if batch:
        return _video_batch(args, stack)
    t0 = time.perf_counter()
    v = hdr_video(stack.images, stack.effective_exposure_times_s, curve, window=args.window,
                  consistency_sigma=args.consistency_sigma, device=dev,
                  progress=lambda it: progress(it, total=stack.images.shape[0],
                                               description="hdr video", quiet=args.quiet))
    dt = time.perf_counter() - t0
    for w in v.warnings:
        warn(w)
    tm = tonemap_video(v.radiance, key=args.key, temporal=args.temporal) if args.tonemap else None
    out.mkdir(parents=True, exist_ok=True)
    for i, src in enumerate(stack.paths):
        write_artifact(out / f"frame_{i:03d}.exr", lambda p, i=i: write_exr(p, v.radiance[i]),
                       meta=_frame_meta(src, args.response, i, v.exposure_times_s[i], v.params,
                                        v.frames[i]))
        if tm is not None:
            write_artifact(out / f"frame_{i:03d}.png", lambda p, i=i: write_image(p, tm.images[i]),
                           meta=make_meta("lumigraph.tonemapped", inputs=[src],
                                          params=tm.params,
                                          quality={"log_average": float(tm.log_average[i]),
                                                   "log_average_used":
                                                       float(tm.log_average_used[i])}))
    shares = {k: float(np.mean([f["sources"][k] for f in v.frames])) for k in v.frames[0]["sources"]}
    summary = make_meta("lumigraph.hdr_video", inputs=[*stack.paths, args.response],
                        params={"times_s": list(v.exposure_times_s), **v.params,
                                "tonemap": bool(args.tonemap), "key": args.key,
                                "temporal": args.temporal, "bit_depth": stack.bit_depth,
                                "bit_depth_source": stack.bit_depth_source},
                        quality={"mean_sources": shares,
                                 "flicker": None if tm is None else tm.flicker,
                                 "frames": list(v.frames)},
                        timings_s={"hdr_video": dt}, warnings=v.warnings)
    write_json(out / "video.meta.json", summary)
    say(args, f"wrote {len(stack.paths)} frames to {out} ({dt:.2f} s); mean share from current "
              f"{shares['current']:.2f}, neighbours "
              f"{shares['previous'] + shares['next'] + shares['both']:.2f}, "
              f"fallback {shares['fallback']:.2f}")
    return 0


def _methods_epilog(registry) -> str:
    return f"{registry.kind} methods:\n{registry.help_text()}"


# The ranges below are the library's own (its check_* functions and constants):
# the parser refuses a bad value before any file is read, the library again.
TIMES = numbers(number(float, lo=0, lo_open=True), length=(1, None))


def _bit_depth_option(v, what: str) -> None:
    """``--bit-depth N`` of the verbs that read code values (response, merge, video)."""
    v.add_argument("--bit-depth", type=number(int, lo=1, hi=16), default=None, metavar="N",
                   help=f"bits of the {what}' codes, saturation at 2^N-1 (default: detected: "
                        "stack.json, PNG sBIT, left-aligned codes with empty low bits, else the "
                        "smallest of 8/10/12/14/16 bits holding the largest code; the meta "
                        "records how); codes above 2^N-1 are an error naming the file")


def build_parser(prog: str = "lumigraph hdr"):
    """The ``lumigraph hdr`` parser: every verb, every option typed."""
    from lumigraph.capture.tiles import add_tile_options
    from lumigraph.hdr.formats import HDR_EXTS
    from lumigraph.hdr.kang2003 import MIN_WINDOW
    from lumigraph.hdr.kang2003 import hdr_video as _hv
    from lumigraph.hdr.merge import WEIGHTS
    from lumigraph.hdr.mitsunaga1999 import MAX_ORDER, MIN_ORDER
    from lumigraph.hdr.samples import MIN_SAMPLES
    from lumigraph.hdr.ward2003 import MAX_LEVELS, MIN_LEVELS

    key = number(float, lo=0, lo_open=True)
    p = make_parser(prog, "HDR imaging: response curves, radiance maps, alignment, tone mapping.",
                    epilog=EPILOG)
    sp = subparsers(p)
    v = add_verb(sp, "response", "recover the camera response from a bracket",
                 epilog=_methods_epilog(RESPONSE_METHODS))
    v.add_argument("images", nargs="+", type=input_path,
                   help="bracket images, or a folder with stack.json")
    v.add_argument("--method", choices=RESPONSE_METHODS.names, default="debevec",
                   help="response method (listed below)")
    v.add_argument("--times", type=TIMES,
                   help="exposure times T1,T2,... (seconds; default EXIF/stack.json)")
    v.add_argument("--out", required=True, type=output_file(".json"), help="response.json")
    v.add_argument("--plot", type=output_file(".png"), help="also plot the curve to this PNG")
    v.add_argument("--linear", action="store_true", help="the data are linear: identity response")
    v.add_argument("--smoothness", default="auto", type=number(float, lo=0, allow=("auto",)),
                   help="Debevec λ, or auto (the L-curve corner; the discrepancy principle under "
                        "heavy noise)")
    v.add_argument("--order", default="auto",
                   type=number(int, lo=MIN_ORDER, hi=MAX_ORDER, allow=("auto",)),
                   help="Mitsunaga-Nayar polynomial order, or auto")
    v.add_argument("--samples", type=number(int, lo=MIN_SAMPLES),
                   help="pixels sampled (default 600; robertson 5000, for its per-code means)")
    v.add_argument("--seed", type=number(int, lo=0), default=0,
                   help="seed of the pixel sampling")
    v.add_argument("--reference-time", type=_reference_time, action="append",
                   metavar="FILE=SECONDS",
                   help="mitsunaga-nayar: an exposure known exactly (repeatable). The data fix "
                        "the ratios only up to a common power: one reference fixes the scale, "
                        "two (e.g. the shortest and longest) also the power")
    v.add_argument("--noise", metavar="FULL_WELL_E,READ_NOISE_E", type=_noise_pair,
                   help="debevec: the sensor's noise (electrons at the top code, read noise in "
                        "electrons RMS) for the bias correction at the dark and bright ends "
                        "(default: estimated from the bracket)")
    _bit_depth_option(v, "images")
    v.set_defaults(func=_response, arg_flags={**TIMES_FLAG, **NOISE_FLAG, "noise": "--noise",
                                              "reference_times": "--reference-time"})
    v = add_verb(sp, "merge", "merge a bracket (or a batch of brackets) into radiance maps",
                 epilog=MERGE_EPILOG)
    v.add_argument("images", nargs="+", type=input_path,
                   help="bracket images, or a folder with stack.json; for a batch several such "
                        "folders (or their stack.json files), or one folder of them")
    v.add_argument("--response", required=True, type=input_path,
                   help="response.json from 'hdr response'")
    v.add_argument("--times", type=TIMES, help="exposure times T1,T2,... (seconds)")
    v.add_argument("--out", required=True, type=output_file_or_dir(*MERGE_EXTS),
                   help="radiance.exr (or .hdr, .tif LogLuv, .pfm); the flags PNG "
                        "NAME.mask.png is written beside it. A batch: a folder, which gets "
                        "BRACKET.exr and BRACKET.mask.png per bracket and index.json")
    v.add_argument("--weights", choices=WEIGHTS, default="variance")
    v.add_argument("--deghost", action="store_true", help="leave out moving content")
    v.add_argument("--noise", metavar="FULL_WELL_E,READ_NOISE_E", type=_noise_pair,
                   help="sensor noise for the variance weights: electrons at saturation and read "
                        "noise in electrons RMS (default 10000,5; not estimated from the images)")
    _bit_depth_option(v, "images")
    add_device_option(v)
    add_tile_options(v, "the bracket", "the radiance as OpenEXR (.exr only) and its mask PNG")
    add_batch_options(v)
    v.set_defaults(func=_merge, arg_flags={**TIMES_FLAG, **NOISE_FLAG},
                   derived_outputs=lambda a: [("--out", _mask_path(a.out))]
                   if Path(a.out).suffix.lower() in MERGE_EXTS else [])
    v = add_verb(sp, "align", "align a hand-held bracket (Ward's median threshold bitmaps)",
                 epilog=_methods_epilog(ALIGN_METHODS))
    v.add_argument("images", nargs="+", type=input_path,
                   help="bracket images, or a folder with stack.json")
    v.add_argument("--method", choices=ALIGN_METHODS.names, default="mtb",
                   help="alignment method (listed below)")
    v.add_argument("--out", required=True, type=output_dir,
                   help="output folder (aligned PNGs + stack.json)")
    v.add_argument("--times", type=TIMES, help="exposure times T1,T2,... to record in stack.json")
    v.add_argument("--reference", type=number(int, lo=0), default=None,
                   help="reference image index (default the middle one)")
    v.add_argument("--levels", type=number(int, lo=MIN_LEVELS, hi=MAX_LEVELS), default=6,
                   help="pyramid levels (shift <= 2**levels)")
    v.set_defaults(func=_align)
    v = add_verb(sp, "tonemap", "tone-map a radiance map to an sRGB image",
                 epilog=_methods_epilog(TONEMAP_METHODS))
    v.add_argument("input", type=input_path, help="radiance (.exr, .hdr, LogLuv .tif, .pfm)")
    v.add_argument("--method", choices=TONEMAP_METHODS.names, default="reinhard",
                   help="tone-mapping operator (listed below)")
    v.add_argument("--key", type=key, default=0.18, help="scene key (0.18 middle grey)")
    v.add_argument("--bit-depth", type=int, choices=(8, 16), default=8)
    v.add_argument("--out", required=True, type=output_file(".png", ".tif", ".tiff"),
                   help="image.png")
    add_device_option(v)
    add_tile_options(v, "the radiance map", "PNG and TIFF")
    v.set_defaults(func=_tonemap)
    v = add_verb(sp, "video", "HDR video from alternating exposures (Kang et al. 2003)",
                 epilog="With --workers or --scheduler the frames are a batch: each output "
                        "frame one item, reading the frames it is registered with (its "
                        "neighbours; at an end also the frame two away), the same radiance as "
                        "one run; --tonemap and video.meta.json follow in this process, and "
                        "index.json is the batch's index.\n\n" + BATCH_HELP)
    v.add_argument("frames", nargs="+", type=input_path,
                   help="frames in time order, or a folder with stack.json")
    v.add_argument("--response", required=True, type=input_path,
                   help="response.json from 'hdr response'")
    v.add_argument("--times", type=TIMES, help="exposure time of each frame T1,T2,... (seconds)")
    v.add_argument("--out", required=True, type=output_dir,
                   help="output folder (frame_NNN.exr [+ .png], video.meta.json)")
    v.add_argument("--tonemap", action="store_true", help="also write tone-mapped frame_NNN.png")
    v.add_argument("--key", type=key, default=0.18, help="tone-mapping key (0.18 middle grey)")
    v.add_argument("--temporal", type=number(int, lo=1, odd=True), default=5,
                   help="frames the tone-mapping log-average is smoothed over (1 = none)")
    v.add_argument("--window", type=number(int, lo=MIN_WINDOW, odd=True), default=9,
                   help="flow window, px (default 9)")
    sigma = inspect.signature(_hv).parameters["consistency_sigma"].default
    v.add_argument("--consistency-sigma", type=number(float, lo=0, lo_open=True), default=sigma,
                   help="reject warped neighbours further than this many noise sigma (default "
                        f"{sigma:g}, chosen as docs/decisions/hdr-video-consistency-sigma.md "
                        "records)")
    _bit_depth_option(v, "frames")
    add_device_option(v)
    add_batch_options(v)
    v.set_defaults(func=_video, arg_flags=TIMES_FLAG)
    v = add_verb(sp, "convert", "convert between EXR, RGBE .hdr, LogLuv TIFF and PFM")
    v.add_argument("input", type=input_path, help="an HDR image (.exr, .hdr, LogLuv .tif, .pfm)")
    v.add_argument("output", type=output_file(*HDR_EXTS),
                   help="the converted image; its extension chooses the format")
    v.add_argument("--logluv-bits", type=int, choices=(24, 32), default=32)
    v.add_argument("--half", action="store_true", help="EXR: half floats")
    v.set_defaults(func=_convert)
    return p


def main(argv=None, prog="lumigraph hdr") -> int:
    return run(build_parser(prog), argv)
