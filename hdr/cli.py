"""``lumigraph hdr``: response curves, radiance merge, alignment, tone mapping,
HDR file conversion. Parses, loads, calls the library, saves."""

from __future__ import annotations

import inspect
import time
from pathlib import Path

from lumigraph.capture.commandline import (
    add_verb,
    check_output_dir,
    check_output_path,
    make_parser,
    output_dir,
    output_file,
    parse_floats,
    run,
    say,
    subparsers,
    warn,
)
from lumigraph.capture.errors import InputError
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


# The library names the times by its argument; --times sets them.
TIMES_FLAG = {"exposure_times_s": "--times"}
# ... and the noise model by its two arguments; --noise sets both.
NOISE_FLAG = {"full_well_e": "--noise", "read_noise_e": "--noise"}


def _mask_path(out) -> Path:
    """The flags PNG that ``hdr merge`` writes beside its radiance map."""
    return Path(out).with_name(Path(out).stem + ".mask.png")


def _times(args):
    return parse_floats(args.times, name="--times") if args.times else None


def _load(args, *, need_times=True):
    """The bracket and its exposures: the stack reader's effective exposure
    (an aperture bracket's f-numbers applied), as every HDR verb uses them."""
    from lumigraph.capture.io import read_stack

    stack = read_stack(args.images, times=_times(args), need_times=need_times)
    if stack.images.dtype.kind == "f":
        raise InputError(stack.paths[0], "float images are already linear; merge needs code values "
                                         "(integer PNG/TIFF/JPEG/RAW)")
    return stack, stack.effective_exposure_times_s


def _response(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta
    from lumigraph.hdr.samples import check_samples

    out = check_output_path(args.out, suffixes=(".json",))
    if args.plot:
        check_output_path(args.plot, suffixes=(".png",))
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
        opts["smoothness"] = "auto" if args.smoothness == "auto" else _num(args.smoothness,
                                                                            "--smoothness")
    if "order" in m.options:
        opts["order"] = "auto" if args.order == "auto" else int(_num(args.order, "--order"))
    if "samples" in m.options:
        opts["samples"] = samples
        opts["rng"] = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    curve = fn(stack.images, times, **opts)
    dt = time.perf_counter() - t0
    for w in curve.warnings:
        warn(w)
    meta = make_meta("lumigraph.response", inputs=stack.paths,
                     params={"method": method, "times_s": times,
                             "samples": samples if "samples" in m.options else None,
                             "seed": args.seed, "bit_depth": stack.bit_depth},
                     model={"method": curve.method, "selection": curve.selection},
                     quality=curve.fit, timings_s={"fit": dt}, warnings=curve.warnings)
    curve.save(out, meta=meta)
    if args.plot:
        plot_curve(curve, args.plot)
    say(args, f"wrote {out} ({curve.method}, {curve.bit_depth}-bit, {dt:.2f} s)")
    return 0


def _num(text, name):
    try:
        return float(text)
    except ValueError:
        raise InputError(name, f"expected a number or 'auto', got {text!r}") from None


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



def _check_curve(curve, stack, path, what):
    """The response must be for the stack's bit depth and channels."""
    if stack.bit_depth is not None and stack.bit_depth != curve.bit_depth:
        raise InputError(path, f"curve is {curve.bit_depth}-bit but the {what} are "
                               f"{stack.bit_depth}-bit; recover a curve at this depth")
    if curve.channels not in (1, stack.images.shape[-1]):
        raise InputError(path, f"curve has {curve.channels} channels, the {what} "
                               f"{stack.images.shape[-1]}")

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
    vals = parse_floats(args.noise, name="--noise")
    if len(vals) != 2:
        raise InputError("--noise", f"expected FULL_WELL_E,READ_NOISE_E (two numbers), got "
                                    f"{args.noise!r}")
    fw, rn = check_noise(args.weights, *vals)
    given = {"full_well_e": fw, "read_noise_e": rn}
    return given, {**given, "source": "given (--noise)"}


def _merge(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import write_exr, write_image
    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.response import ResponseCurve

    out = check_output_path(args.out, suffixes=(".exr", ".hdr", ".tif", ".tiff", ".pfm"))
    given, noise = _noise(args)
    curve = ResponseCurve.load(args.response)
    stack, times = _load(args)
    _check_curve(curve, stack, args.response, "images")
    t0 = time.perf_counter()
    m = merge(stack.images, times, curve, weights=args.weights, deghost=args.deghost, **given)
    dt = time.perf_counter() - t0
    for w in m.warnings:
        warn(w)
    meta = make_meta("lumigraph.radiance", inputs=[*stack.paths, args.response],
                     params={"weights": args.weights, "deghost": args.deghost, "times_s": times,
                             "response_method": curve.method,
                             "noise": noise if args.weights == "variance" else None},
                     quality=m.stats, timings_s={"merge": dt}, warnings=m.warnings,
                     extra={"units": "relative radiance: f^-1(z)/t, f^-1(z_mid)=z_mid/z_max",
                            "mask": "flags PNG beside the output: 1 clipped everywhere (lower "
                                    "bound), 2 black everywhere (upper bound), 4 ghost"})
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


def _align(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_json
    from lumigraph.capture.io import read_stack, write_image, write_stack_json

    out = check_output_dir(args.out)
    stack = read_stack(args.images, times=_times(args))
    if stack.images.dtype.kind == "f":
        raise InputError(stack.paths[0], "align works on code values (PNG/TIFF/JPEG)")
    aligned, shifts = ALIGN_METHODS.resolve(args.method)(stack.images, reference=args.reference,
                                                         levels=args.levels)
    out.mkdir(parents=True, exist_ok=True)
    names = []
    for img, src in zip(aligned, stack.paths, strict=True):
        name = Path(src).stem + ".png"
        write_image(out / name, img if img.shape[-1] > 1 else img[..., 0],
                    bit_depth=stack.bit_depth if img.dtype == np.uint16 else None)
        names.append(name)
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
    from lumigraph.capture.io import write_image
    from lumigraph.hdr.formats import read_hdr_image

    out = check_output_path(args.out, suffixes=(".png", ".tif", ".tiff"))
    img = read_hdr_image(args.input)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    args.arg_flags = {"radiance": args.input}  # the library checks it; name the file it came from
    ldr = TONEMAP_METHODS.resolve(args.method)(img, key=args.key, bit_depth=args.bit_depth)
    meta = make_meta("lumigraph.tonemapped", inputs=[args.input],
                     params={"method": args.method, "key": args.key, "bit_depth": args.bit_depth})
    write_artifact(out, lambda p: write_image(p, ldr), meta=meta)
    say(args, f"wrote {out}")
    return 0


def _convert(args) -> int:
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.hdr.formats import HDR_EXTS, read_hdr_image, write_hdr_image

    out = check_output_path(args.output, suffixes=HDR_EXTS)
    img = read_hdr_image(args.input)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    meta = make_meta("lumigraph.hdr_image", inputs=[args.input],
                     params={"logluv_bits": args.logluv_bits, "half": args.half})
    write_artifact(out, lambda p: write_hdr_image(p, img, logluv_bits=args.logluv_bits,
                                                  half=args.half), meta=meta)
    say(args, f"wrote {out}")
    return 0


def _video(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact, write_json
    from lumigraph.capture.commandline import progress
    from lumigraph.capture.io import read_stack, write_exr, write_image
    from lumigraph.hdr.kang2003 import check_temporal, hdr_video, tonemap_video
    from lumigraph.hdr.response import ResponseCurve

    out = check_output_dir(args.out)
    check_temporal(args.temporal)  # tonemap_video's own range, before the frames are read
    curve = ResponseCurve.load(args.response)
    stack = read_stack(args.frames, times=_times(args), need_times=True)
    # hdr_video checks its frames (at least 2 of them); an error about them
    # names the input they came from
    args.arg_flags = {**TIMES_FLAG,
                      "frames": stack.paths[0] if len(stack.paths) == 1 else str(args.frames[0])}
    if stack.images.dtype.kind == "f":
        raise InputError(stack.paths[0], "float frames are already linear; HDR video needs "
                                         "code values (integer PNG/TIFF)")
    _check_curve(curve, stack, args.response, "frames")
    t0 = time.perf_counter()
    v = hdr_video(stack.images, stack.effective_exposure_times_s, curve, window=args.window,
                  consistency_sigma=args.consistency_sigma,
                  progress=lambda it: progress(it, total=stack.images.shape[0],
                                               description="hdr video", quiet=args.quiet))
    dt = time.perf_counter() - t0
    for w in v.warnings:
        warn(w)
    tm = tonemap_video(v.radiance, key=args.key, temporal=args.temporal) if args.tonemap else None
    out.mkdir(parents=True, exist_ok=True)
    for i, src in enumerate(stack.paths):
        meta = make_meta("lumigraph.radiance", inputs=[src, args.response],
                         params={"frame": i, "exposure_s": v.exposure_times_s[i], **v.params},
                         quality=v.frames[i],
                         extra={"method": "kang2003",
                                "units": "relative radiance: f^-1(z)/t, f^-1(z_mid)=z_mid/z_max",
                                "flags": "per pixel-channel in quality: 8 warped from neighbours, "
                                         "16 fallback (clipping bound), 4 neighbour rejected"})
        write_artifact(out / f"frame_{i:03d}.exr", lambda p, i=i: write_exr(p, v.radiance[i]),
                       meta=meta)
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
                                "temporal": args.temporal},
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


def main(argv=None, prog="lumigraph hdr") -> int:
    p = make_parser(prog, "HDR imaging: response curves, radiance maps, alignment, tone mapping.",
                    epilog=EPILOG)
    sp = subparsers(p)
    v = add_verb(sp, "response", "recover the camera response from a bracket",
                 epilog=_methods_epilog(RESPONSE_METHODS))
    v.add_argument("images", nargs="+", help="bracket images, or a folder with stack.json")
    v.add_argument("--method", choices=RESPONSE_METHODS.names, default="debevec",
                   help="response method (listed below)")
    v.add_argument("--times", help="exposure times T1,T2,... (seconds; default EXIF/stack.json)")
    v.add_argument("--out", required=True, type=output_file(".json"), help="response.json")
    v.add_argument("--plot", type=output_file(".png"), help="also plot the curve to this PNG")
    v.add_argument("--linear", action="store_true", help="the data are linear: identity response")
    v.add_argument("--smoothness", default="auto", help="Debevec λ, or auto (the L-curve corner; the discrepancy principle under heavy noise)")
    v.add_argument("--order", default="auto", help="Mitsunaga-Nayar order 1..10, or auto")
    v.add_argument("--samples", type=int,
                   help="pixels sampled (default 600; robertson 5000, for its per-code means)")
    v.add_argument("--seed", type=int, default=0, help="seed of the pixel sampling")
    v.set_defaults(func=_response, arg_flags=TIMES_FLAG)
    v = add_verb(sp, "merge", "merge a bracket into a radiance map")
    v.add_argument("images", nargs="+", help="bracket images, or a folder with stack.json")
    v.add_argument("--response", required=True, help="response.json from 'hdr response'")
    v.add_argument("--times", help="exposure times T1,T2,... (seconds)")
    v.add_argument("--out", required=True, type=output_file(".exr", ".hdr", ".tif", ".tiff", ".pfm"), help="radiance.exr (or .hdr, .tif LogLuv, .pfm)")
    v.add_argument("--weights", choices=("variance", "hat"), default="variance")
    v.add_argument("--deghost", action="store_true", help="leave out moving content")
    v.add_argument("--noise", metavar="FULL_WELL_E,READ_NOISE_E",
                   help="sensor noise for the variance weights: electrons at saturation and read "
                        "noise in electrons RMS (default 10000,5; not estimated from the images)")
    v.set_defaults(func=_merge, arg_flags={**TIMES_FLAG, **NOISE_FLAG},
                   derived_outputs=lambda a: [("--out", _mask_path(a.out))])
    v = add_verb(sp, "align", "align a hand-held bracket (Ward's median threshold bitmaps)",
                 epilog=_methods_epilog(ALIGN_METHODS))
    v.add_argument("images", nargs="+")
    v.add_argument("--method", choices=ALIGN_METHODS.names, default="mtb",
                   help="alignment method (listed below)")
    v.add_argument("--out", required=True, type=output_dir, help="output folder (aligned PNGs + stack.json)")
    v.add_argument("--times", help="exposure times T1,T2,... to record in stack.json")
    v.add_argument("--reference", type=int, default=None, help="reference image index")
    v.add_argument("--levels", type=int, default=6, help="pyramid levels (shift <= 2**levels)")
    v.set_defaults(func=_align)
    v = add_verb(sp, "tonemap", "tone-map a radiance map to an sRGB image",
                 epilog=_methods_epilog(TONEMAP_METHODS))
    v.add_argument("input", help="radiance (.exr, .hdr, LogLuv .tif, .pfm)")
    v.add_argument("--method", choices=TONEMAP_METHODS.names, default="reinhard",
                   help="tone-mapping operator (listed below)")
    v.add_argument("--key", type=float, default=0.18, help="scene key (0.18 middle grey)")
    v.add_argument("--bit-depth", type=int, choices=(8, 16), default=8)
    v.add_argument("--out", required=True, type=output_file(".png", ".tif", ".tiff"), help="image.png")
    v.set_defaults(func=_tonemap)
    v = add_verb(sp, "video", "HDR video from alternating exposures (Kang et al. 2003)")
    v.add_argument("frames", nargs="+", help="frames in time order, or a folder with stack.json")
    v.add_argument("--response", required=True, help="response.json from 'hdr response'")
    v.add_argument("--times", help="exposure time of each frame T1,T2,... (seconds)")
    v.add_argument("--out", required=True, type=output_dir, help="output folder (frame_NNN.exr [+ .png])")
    v.add_argument("--tonemap", action="store_true", help="also write tone-mapped frame_NNN.png")
    v.add_argument("--key", type=float, default=0.18, help="tone-mapping key (0.18 middle grey)")
    v.add_argument("--temporal", type=int, default=5,
                   help="frames the tone-mapping log-average is smoothed over (odd; 1 = none)")
    v.add_argument("--window", type=int, default=9, help="flow window, odd px (default 9)")
    from lumigraph.hdr.kang2003 import hdr_video as _hv

    sigma = inspect.signature(_hv).parameters["consistency_sigma"].default
    v.add_argument("--consistency-sigma", type=float, default=sigma,
                   help="reject warped neighbours further than this many noise sigma (default "
                        f"{sigma:g}, chosen as docs/decisions/hdr-video-consistency-sigma.md "
                        "records)")
    v.set_defaults(func=_video, arg_flags=TIMES_FLAG)
    v = add_verb(sp, "convert", "convert between EXR, RGBE .hdr, LogLuv TIFF and PFM")
    v.add_argument("input")
    v.add_argument("output", type=output_file(".exr", ".hdr", ".pic", ".rgbe", ".tif", ".tiff", ".pfm"))
    v.add_argument("--logluv-bits", type=int, choices=(24, 32), default=32)
    v.add_argument("--half", action="store_true", help="EXR: half floats")
    v.set_defaults(func=_convert)
    return run(p, argv)
