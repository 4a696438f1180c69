"""``lumigraph lightfield``: import, decode, refocus, render and depth (thin layer:
parse, load, call the library, save).

The library checks every value it takes (spacing, focal length, the grid's
view count, refocus values, the render position, the depth candidates), early
through its ``check_*`` functions where files would be read first; the
command line keeps the text parsing, what concerns files (a folder without
stack.json, a rig with the wrong number of cameras, a white image of another
size, output names), flags that disagree (--spacing against the rig's), and
refuses to write a view whose every ray leaves the slab."""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path

from lumigraph.capture.commandline import (
    BATCH_HELP,
    NumberList,
    add_batch_options,
    add_verb,
    batch_requested,
    check_output_dir,
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

EPILOG = """\
examples:
  lumigraph lightfield import views/*.png --grid 5x5 --spacing 0.05 --focal-px 800 --out lf
  lumigraph lightfield import out/scenes/lightfield-array --out lf     (rendered folder)
  lumigraph lightfield import views/*.png --grid 5x5 --rig rig.json --out lf  (rectified)
  lumigraph lightfield decode raw.png --white white.png --views 5 --out lf
  lumigraph lightfield import views/*.png --grid 5x5 --out lf   (no spacing: refocus by slope)
  lumigraph lightfield refocus lf --slope 0.5 --out focus.exr
  lumigraph lightfield refocus lf --slope -2 -1 0 1 --out stack/
  lumigraph lightfield refocus lf --depth 2 3 4 5 6 7 8 9 10 12 --method auto --out stack/
  lumigraph lightfield render lf --position 0.5 0.5 0 --focus-slope 0.4 --out view.exr
  lumigraph lightfield depth lf --slopes -1,1,41 --out disparity.pfm
  (number lists: '--slope -2 -1 0', '--slope -2,-1,0' and '--slope=-2,-1,0' are the same)

A light field folder holds view-UU-VV.exr (linear float32, row-major, U = row)
and lightfield.json (grid, spacing, focal_px). Refocus by --slope (px per view
step: a point of that disparity comes out sharp), --depth (units of --spacing:
slope = focal_px * spacing / depth) or --alpha (Ng's virtual sensor position:
slope = alpha_scale * (1 - 1/alpha)). Without --spacing at import, world
units are grid steps and --depth / --focus-depth are refused.
"""


def grid_text(text: str) -> tuple[int, int]:
    """``--grid`` text -> ``(rows, cols)`` by the grid's own parser (an argparse ``type``)."""
    from lumigraph.capture.scenes.lightfield import parse_grid

    try:
        return parse_grid(text)
    except InputError as e:
        raise argparse.ArgumentTypeError(e.problem) from None


grid_text.range_text = "ROWSxCOLS, 1..64 each, at least 2 views"


class SlopeRange(NumberList):
    """``MIN,MAX,N``: N evenly spaced candidate disparities from MIN to MAX
    (MIN < MAX, N an integer, at least the library's
    :data:`~lumigraph.lightfield.refocus.MIN_DISPARITY_CANDIDATES`)."""

    def __init__(self):
        from lumigraph.lightfield.refocus import MIN_DISPARITY_CANDIDATES

        super().__init__(number(float), length=3)
        self.min_n = MIN_DISPARITY_CANDIDATES

    @property
    def range_text(self) -> str:
        return f"MIN,MAX,N with MIN < MAX and N an integer >= {self.min_n}"

    def __call__(self, text: str):
        lo, hi, n = super().__call__(text)
        if not lo < hi or n != int(n) or n < self.min_n:
            raise argparse.ArgumentTypeError(f"expected {self.range_text}, got {text!r}")
        return lo, hi, int(n)

    def bad_examples(self) -> list[str]:
        return [*super().bad_examples(), "1,-1,5", "-1,1,2.5", f"-1,1,{self.min_n - 1}"]


SPACING_UNKNOWN = "spacing_unknown"


def _need_spacing(lf, folder) -> None:
    """Refuse a depth (world units) on a light field imported without ``--spacing``."""
    if SPACING_UNKNOWN in (lf.info or {}):
        raise InputError(Path(folder) / "lightfield.json",
                         "has no camera spacing (imported without --spacing), so a depth cannot "
                         "be turned into a slope; import again with --spacing (and --focal-px), "
                         "or give --slope / --alpha")


# options taking a list of numbers: '--slope -2 -1 0', '--slope=-2,-1,0',
# '--slope -2,-1,0' and '--slope=-2 -1 0' all mean the same
LIST_OPTIONS = ("--slope", "--alpha", "--depth", "--slopes")
MANY_VALUES = ("--slope", "--alpha", "--depth")  # nargs="+": also any word, as argparse would
_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:inf|infinity|nan)"
_NUMBER_LIST = re.compile(rf"^(?:{_NUM})(?:,(?:{_NUM}))*$", re.I)


def join_number_lists(argv) -> list[str]:
    """``argv`` with each list option's values joined into one ``--opt=a,b,c`` token.

    argparse reads ``-2,-1`` as an option and stops ``--opt=-2`` at its first
    value; joined, every spelling reaches the option's :func:`numbers` type
    (which names the option for a bad value). The options of several values
    take every following word that is not an option, as argparse does;
    ``--slopes`` (one value) only number lists, so a positional after it stays.

    Examples
    --------
    >>> join_number_lists(["lf", "--slope=-2", "-1", "0", "--out", "o"])
    ['lf', '--slope=-2,-1,0', '--out', 'o']
    >>> join_number_lists(["--slopes", "-1", "1,41", "lf", "-q"])
    ['--slopes=-1,1,41', 'lf', '-q']
    """
    argv = [str(a) for a in argv]
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if tok == "--":
            out.extend(argv[i:])
            break
        name, eq, val = tok.partition("=")
        if name in LIST_OPTIONS:
            vals = [val] if eq else []
            j = i + 1
            while j < len(argv) and (_NUMBER_LIST.match(argv[j]) or (
                    name in MANY_VALUES and not argv[j].startswith("-"))):
                vals.append(argv[j])
                j += 1
            if vals:
                out.append(f"{name}={','.join(vals)}")
                i = j
                continue
        out.append(tok)
        i += 1
    return out


def _values(groups) -> list[float]:
    """The values of a repeated ``numbers`` option (``--slope 1 2,3``), flattened."""
    return [v for g in groups for v in g]


def _lightfield_files(folder: Path, grid) -> list[Path]:
    """The files :meth:`LightField.save` writes into ``folder`` for ``grid``."""
    from lumigraph.lightfield.field import view_name

    u, v = grid
    return [folder / view_name(i, j) for i in range(u) for j in range(v)] + [
        folder / "lightfield.json"]


# ---------------------------------------------------------------------- import
def _import(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.capture.io import read_image, read_stack_json
    from lumigraph.capture.rig import CameraArray
    from lumigraph.capture.scenes.lightfield import parse_grid
    from lumigraph.lightfield.field import check_from_images, from_images

    inputs = [Path(p) for p in args.images]
    out = check_output_dir(args.out)
    args.plane_depth = float(args.plane_depth)  # the parser lets "inf" through as it is
    info, linear, bit_depth = {}, args.linear, None
    if len(inputs) == 1 and inputs[0].is_dir():
        sj = inputs[0] / "stack.json"
        if not sj.exists():
            raise InputError(inputs[0], "folder has no stack.json; pass the view files instead")
        stack = read_stack_json(sj)
        info = stack.get("lightfield", {})
        files = [inputs[0] / n for n in stack.get("images", [])]
        linear = linear or bool(stack.get("linear", False))
        bit_depth = stack.get("bit_depth")
    else:
        files = inputs
    if args.grid is not None:
        grid = args.grid
    elif "grid" in info:
        grid = parse_grid("x".join(map(str, info["grid"])), name=str(inputs[0] / "stack.json"))
    else:
        raise InputError("grid", "give the camera grid, e.g. --grid 5x5 (rows x columns)")
    spacing = args.spacing if args.spacing is not None else info.get("spacing")
    posed = args.rig is not None or "cameras" in info
    # without a spacing the views are still a light field: refocus by slope or alpha
    # works; world units are then grid steps and depths are refused (_need_spacing)
    spacing_known = spacing is not None or posed
    focal = args.focal_px if args.focal_px is not None else info.get("focal_px")
    # the library's rules, before any view is read (posed: the spacing is fitted below)
    check_from_images(len(files), grid=grid, spacing=1.0 if spacing is None else spacing,
                      focal_px=focal)
    check_planned(_lightfield_files(out, grid))  # --out = the views' folder: none replaced
    cameras = None
    if args.rig is not None:
        cameras = (CameraArray.load(args.rig), args.rig)
    elif "cameras" in info:
        where = inputs[0] / "stack.json"
        cameras = (CameraArray.from_dict(info["cameras"], where=where, key="lightfield.cameras"),
                   where)
    images = [read_image(f) for f in files]
    lf = from_images(images, grid=grid, spacing=spacing or 1.0, focal_px=focal, linear=linear,
                     bit_depth=bit_depth, names=[str(f) for f in files])
    info_out = {"source": [str(f) for f in files],
                "decoded": "linear" if linear else "sRGB -> linear"}
    if not spacing_known:
        info_out[SPACING_UNKNOWN] = ("imported without --spacing: world units are grid steps; "
                                     "depths need the spacing")
    quality, warnings = {}, []
    if cameras is not None:
        lf, quality, warnings = _rectify(lf, cameras, args, grid, files, spacing)
        focal = lf.focal_px
        info_out["rectified"] = quality
    lf = type(lf)(lf.data, spacing=lf.spacing, focal_px=lf.focal_px, info=info_out)
    lf.save(out, meta=make_meta("lumigraph.lightfield", inputs=files,
                                params={"grid": list(grid), "spacing": lf.spacing,
                                        "focal_px": focal, "linear": linear,
                                        "rig": str(args.rig) if args.rig else None,
                                        "plane_depth": args.plane_depth,
                                        "grid_tolerance": args.grid_tolerance},
                                quality=quality, warnings=warnings))
    if not spacing_known:
        say(args, "no --spacing: refocus by --slope or --alpha; --depth needs the spacing")
    say(args, f"wrote {grid[0]}x{grid[1]} views of {lf.size[0]}x{lf.size[1]} to {out}")
    return 0


def _rectify(lf, cameras, args, grid, files, spacing):
    from lumigraph.lightfield.field import LightField
    from lumigraph.lightfield.rectify import rectify_views

    array, where = cameras
    if len(array.cameras) != len(files):
        raise InputError(where, f"has {len(array.cameras)} cameras for {len(files)} views")
    u, v = grid
    views = [lf.data[i, j] for i in range(u) for j in range(v)]
    r = rectify_views(views, list(array.cameras), list(array.cam_from_world), grid=grid,
                      tolerance=args.grid_tolerance, plane_depth=args.plane_depth,
                      names=[str(f) for f in files])
    s = r.array.spacing
    if spacing is not None and abs(spacing - s) > args.grid_tolerance * s:
        raise InputError("spacing", f"{spacing:g} disagrees with the {s:.6g} fitted to the "
                                    "camera centres; omit --spacing to use the rig's")
    warnings = []
    if r.outside.max() > 0.01:
        warnings.append(f"rectified views map up to {100 * r.outside.max():.1f}% outside their "
                        "source images (filled by mirror extension)")
    for w_ in warnings:
        warn(w_)
    quality = {"fitted_spacing": s, "max_centre_offset_steps": float(r.array.residuals.max()),
               "focal_px": float(r.K[0, 0]), "max_outside_fraction": float(r.outside.max()),
               "ref_from_world": r.array.ref_from_world.tolist(),
               "plane_depth": args.plane_depth}
    return LightField(r.views, spacing=s, focal_px=float(r.K[0, 0])), quality, warnings


# ---------------------------------------------------------------------- decode
def _decode(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.capture.io import read_image, read_stack_json
    from lumigraph.lightfield.lenslet import decode

    out = check_output_dir(args.out)
    raw, white = read_image(args.raw), read_image(args.white)
    if raw.shape[:2] != white.shape[:2]:
        raise InputError(args.white, f"is {white.shape[1]}x{white.shape[0]} but the raw is "
                                     f"{raw.shape[1]}x{raw.shape[0]}; use the white image of "
                                     "the same camera")
    views = args.views
    sj = Path(args.raw).parent / "stack.json"
    if views is None and sj.exists():
        lens = read_stack_json(sj).get("lenslet", {})
        views = lens.get("views", [None])[0]
        args.arg_flags = {**(getattr(args, "arg_flags", None) or {}), "views": str(sj)}
    # the views' names wait for the decode, which bounds their number by the lenslets
    check_planned([out / "lightfield.json"])
    t0 = time.perf_counter()
    result = decode(raw, white, views=views, lattice=args.lattice)
    g = result.grid
    check_planned(_lightfield_files(out, result.lightfield.grid))
    result.lightfield.save(out, meta=make_meta(
        "lumigraph.lightfield", inputs=[args.raw, args.white],
        params={"views": views, "lattice": args.lattice}, model={"grid": g.to_dict()},
        quality={"lattice_rms_residual_px": g.residual_px},
        timings_s={"decode": time.perf_counter() - t0}))
    say(args, f"{g.lattice} grid: pitch {g.pitch_px:.3f} px, rotation {g.rotation_deg:.3f} deg, "
              f"{g.rows}x{g.cols} lenslets; wrote {out}")
    return 0


# --------------------------------------------------------------------- refocus
def _refocus_batch(args, kind: str, given: list[float], out: Path) -> int:
    """Many values on a Dask cluster (``--workers``/``--scheduler``): each value
    one item, ``refocus-NNN.exr`` written by the one-value command. Its
    ``--method`` as given: ``auto`` is then one value's choice (shift-add);
    the whole set's Fourier slice shares one 4-D FFT, which items cannot."""
    from lumigraph.capture.batch import Item, report, run_batch
    from lumigraph.capture.commandline import batch_item_argv

    items = []
    for k, g in enumerate(given):
        target = out / f"refocus-{k:03d}.exr"
        add = [f"--{kind}={g!r}", "--out", str(target)]
        items.append(Item(target.stem, inputs=(str(args.lightfield),), outputs=(str(target),),
                          func="lumigraph.capture.batch:run_command",
                          kwargs={"module": "lumigraph.lightfield.cli", "prog": "lumigraph lightfield",
                                  "argv": batch_item_argv(args, [args.lightfield],
                                                          drop=("out", "alpha", "depth", "slope"),
                                                          add=add)}))
    result = run_batch(items, out_dir=out, workers=args.workers, scheduler=args.scheduler,
                       quiet=args.quiet, description="refocusing")
    return report(result, quiet=args.quiet)


def lightfield_folders(paths) -> list[Path] | None:
    """The light fields of a batch: several light-field folders (or their
    ``lightfield.json``), or one folder of such folders; None when ``paths``
    is one light field."""
    ins = [Path(p) for p in paths]
    folders = [p.parent if p.name == "lightfield.json" and p.is_file() else p for p in ins]
    if len(folders) > 1:
        return folders
    if folders[0].is_dir() and not (folders[0] / "lightfield.json").exists():
        subs = sorted(d for d in folders[0].iterdir()
                      if d.is_dir() and (d / "lightfield.json").is_file())
        if subs:
            return subs
    return None


def _refocus_fields(args, folders: list[Path], given: list[float]) -> int:
    """Several light fields: each one item, the single command on that light
    field with every option the batch was given, writing ``OUT/NAME.exr``
    (one value) or the folder ``OUT/NAME/`` (several: its focal stack in one
    pass, so Fourier slice keeps its shared FFT)."""
    from lumigraph.capture.batch import command_item, item_name, run_items
    from lumigraph.capture.commandline import batch_item_argv

    out = Path(args.out)
    if out.suffix.lower() == ".exr":
        raise InputError("out", f"{out}: {len(folders)} light fields write a folder (one result "
                                "per light field) and index.json; name a folder")
    items = []
    for f in folders:
        if not (f / "lightfield.json").is_file():
            raise InputError(f, "not a light-field folder (no lightfield.json); make one with "
                                "'lumigraph lightfield import' or 'decode'")
        name = item_name(f)
        target = out / (f"{name}.exr" if len(given) == 1 else name)
        # several values: the folder's index.json carries the sidecar (the
        # images are written with it, as one result set)
        outputs = (str(target),) if len(given) == 1 else (str(target / "index.json"),)
        items.append(command_item(name, inputs=(f,), outputs=outputs,
                                  module="lumigraph.lightfield.cli", prog="lumigraph lightfield",
                                  argv=batch_item_argv(args, [f], add=["--out", str(target)])))
    return run_items(items, out_dir=out, args=args, description="refocusing")


def _refocus(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact, write_json
    from lumigraph.capture.device import resolve_device
    from lumigraph.capture.io import write_exr
    from lumigraph.lightfield.field import LightField
    from lumigraph.lightfield.methods import REFOCUS_METHODS
    from lumigraph.lightfield.refocus import check_refocus_range, choose_method, focal_stack

    dev = resolve_device(args.device)  # before the light field is read
    given, kind = next((_values(g), k) for g, k in ((args.alpha, "alpha"), (args.depth, "depth"),
                                                    (args.slope, "slope")) if g is not None)
    folders = lightfield_folders(args.lightfield)
    if folders is not None:
        return _refocus_fields(args, folders, given)
    args.lightfield = args.lightfield[0]
    out = Path(args.out)
    single = len(given) == 1
    if single and out.suffix.lower() != ".exr":
        raise InputError("out", f"{out}: one value writes one image; name it .exr")
    if not single and out.suffix.lower() == ".exr":
        raise InputError("out", f"{out}: {len(given)} values write a folder of refocus-NNN.exr "
                                "and index.json; name a folder")
    if not single:
        check_planned([out / f"refocus-{k:03d}.exr" for k in range(len(given))]
                      + [out / "index.json"])
    lf = LightField.load(args.lightfield)
    if kind == "depth":
        _need_spacing(lf, args.lightfield)
    if kind == "alpha":
        slopes = [lf.slope_from_alpha(a) for a in given]
    elif kind == "depth":
        slopes = [lf.slope_from_depth(z) for z in given]
    else:
        slopes = list(given)
    warnings = check_refocus_range(lf, slopes)
    for w in warnings:
        warn(w)
    method = args.method
    reason = "requested"
    if method == "auto":
        method = choose_method(lf, len(slopes))
        reason = (f"auto: {len(slopes)} value(s); Fourier slice pays its one-time 4-D FFT "
                  f"back from about 6 values")
    if not single and batch_requested(args):
        return _refocus_batch(args, kind, given, out)
    m = REFOCUS_METHODS.resolve(method)
    options = {k: v for k, v in (("kernel", args.kernel),) if k in m.options}
    t0 = time.perf_counter()
    images = focal_stack(lf, slopes, method=m.name, device=dev, **options)
    timing = {"total": time.perf_counter() - t0}
    meta = make_meta("lumigraph.refocus", inputs=[Path(args.lightfield) / "lightfield.json"],
                     params={kind: given, "slopes": slopes, "kernel": args.kernel,
                             "device": dev.name},
                     model={"method": method, "why": reason}, timings_s=timing,
                     warnings=warnings)
    if single:
        img = images[0]
        write_artifact(out, lambda p: write_exr(p, img[..., 0] if img.shape[2] == 1 else img),
                       meta=meta)
    else:
        out.mkdir(parents=True, exist_ok=True)
        index = {}
        for k, (img, s, g) in enumerate(zip(images, slopes, given, strict=True)):
            name = f"refocus-{k:03d}.exr"
            write_exr(out / name, img[..., 0] if img.shape[2] == 1 else np.asarray(img))
            index[name] = {kind: g, "slope": s}
        write_artifact(out / "index.json", lambda p: write_json(p, index), meta=meta)
    say(args, f"refocused {len(slopes)} value(s) by {method} in {timing['total']:.2f} s -> {out}")
    return 0


# ---------------------------------------------------------------------- render
def _render(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import write_exr
    from lumigraph.lightfield.field import LightField
    from lumigraph.lightfield.levoy1996 import render_view

    out = Path(args.out)  # .exr, the parser's
    lf = LightField.load(args.lightfield)
    if args.focus_depth is not None:
        _need_spacing(lf, args.lightfield)
        slope = lf.slope_from_depth(args.focus_depth)
    else:
        slope = args.focus_slope
    view = render_view(lf, args.position, focus_slope=slope, interpolation=args.interpolation)
    frac = float(view.valid.mean())
    if frac == 0:
        raise InputError("position", f"{tuple(args.position)}: every ray leaves the light "
                                     "slab; put the pinhole over the camera grid")
    rgba = np.concatenate([view.image if view.image.shape[2] == 3 else
                           np.repeat(view.image[..., :1], 3, -1),
                           view.valid[..., None].astype(np.float32)], -1)
    warnings = [] if frac == 1 else [f"{100 * (1 - frac):.1f}% of rays leave the slab "
                                     "(alpha = 0 there)"]
    for w in warnings:
        warn(w)
    write_artifact(out, lambda p: write_exr(p, rgba), meta=make_meta(
        "lumigraph.novel-view", inputs=[Path(args.lightfield) / "lightfield.json"],
        params={"position": list(args.position), "focus_slope": slope,
                "interpolation": args.interpolation},
        quality={"valid_fraction": frac}, warnings=warnings))
    say(args, f"wrote {out} (alpha = valid rays, {100 * frac:.1f}%)")
    return 0


# ----------------------------------------------------------------------- depth
def _depth(args) -> int:
    import numpy as np

    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import write_exr, write_pfm
    from lumigraph.lightfield.field import LightField
    from lumigraph.lightfield.methods import DEPTH_METHODS
    from lumigraph.lightfield.refocus import (
        all_in_focus,
        check_disparity_slopes,
        check_disparity_window,
        focal_stack,
    )

    out = Path(args.out)  # .pfm, the parser's
    lo, hi, n = args.slopes  # MIN < MAX, N an integer (the parser's)
    # the library's rules, before the light field loads
    slopes = check_disparity_slopes(np.linspace(lo, hi, n))
    method = DEPTH_METHODS.resolve(args.method)
    options = {}
    if args.window is not None:
        if "window" not in method.options:
            raise InputError("window", f"applies to the variance method, not {args.method}")
        options["window"] = check_disparity_window(args.window)
    if args.edges != "soft":
        if "soft_edges" not in method.options:
            raise InputError("edges", f"applies to the wang2015 method, not {args.method}")
        options["soft_edges"] = False
    lf = LightField.load(args.lightfield)
    est = method(lf, slopes, **options)
    inputs = [Path(args.lightfield) / "lightfield.json"]
    params = {"method": args.method, "slopes": [lo, hi, int(n)], **options}
    low = float(np.mean(est.confidence < 0.3))
    warnings = []
    if low > 0.5:
        warnings.append(f"{100 * low:.0f}% of the pixels have confidence < 0.3 (little texture "
                        "or parallax): the disparity there is a guess")
        warn(warnings[-1])
    write_artifact(out, lambda p: write_pfm(p, est.disparity), meta=make_meta(
        "lumigraph.disparity", inputs=inputs, params=params, warnings=warnings,
        quality={"median_confidence": float(np.median(est.confidence)),
                 "low_confidence_fraction": low}))
    if args.confidence:
        write_artifact(args.confidence, lambda p: write_pfm(p, est.confidence), meta=make_meta(
            "lumigraph.disparity-confidence", inputs=inputs, params=params))
    if args.all_in_focus:
        stack = focal_stack(lf, slopes, method="auto")
        aif = all_in_focus(stack, slopes, est.disparity)
        write_artifact(args.all_in_focus, lambda p: write_exr(p, aif), meta=make_meta(
            "lumigraph.all-in-focus", inputs=inputs,
            params={"slopes": [lo, hi, int(n)]}))
    say(args, f"wrote {out}")
    return 0


def build_parser(prog: str = "lumigraph lightfield"):
    positive = number(float, lo=0, lo_open=True)
    p = make_parser(prog, "Light fields: import camera arrays, decode lenslet raws, refocus "
                          "(shift-and-add, Fourier slice), render novel views, estimate depth.",
                    epilog=EPILOG)
    sp = subparsers(p)

    v = add_verb(sp, "import", "build a light-field folder from row-major views")
    v.add_argument("images", nargs="+", type=input_path,
                   help="view images (row-major), or a rendered folder")
    v.add_argument("--grid", type=grid_text, help="ROWSxCOLS, e.g. 5x5")
    v.add_argument("--spacing", type=positive, help="camera spacing (world units)")
    v.add_argument("--focal-px", type=positive, help="focal length of the views in pixels")
    v.add_argument("--linear", action="store_true",
                   help="integer views are linear codes (default: sRGB, decoded to linear)")
    v.add_argument("--rig", type=input_path, help="camera poses: JSON {\"cameras\": [camera.json entries with "
                                 "cam_from_world {R, t}], row-major}; the views are undistorted "
                                 "and rectified onto a regular planar array (default: the "
                                 "cameras in a rendered folder's stack.json, if any)")
    v.add_argument("--plane-depth", type=number(float, lo=0, lo_open=True, allow=("inf",)),
                   default=float("inf"),
                   help="reference plane depth for --rig (world units; default inf)")
    v.add_argument("--grid-tolerance", type=positive, default=0.1,
                   help="largest camera-centre offset from its grid node, in grid steps")
    v.add_argument("--out", required=True, type=output_dir, help="light-field folder")
    v.set_defaults(func=_import, arg_flags={"poses": "--rig", "cameras": "--rig",
                                            "plane_depth": "--plane-depth",
                                            "tolerance": "--grid-tolerance"})

    v = add_verb(sp, "decode", "decode a lenslet raw into sub-aperture views")
    from lumigraph.lightfield.lenslet import MIN_VIEWS

    v.add_argument("raw", type=input_path, help="lenslet raw image (linear)")
    v.add_argument("--white", required=True, type=input_path, help="white image of the same camera")
    v.add_argument("--views", type=number(int, lo=MIN_VIEWS),
                   help="views per microimage side, at most its width in pixels "
                        "(default: stack.json beside RAW, else 1 per px)")
    v.add_argument("--lattice", choices=("auto", "square", "hex"), default="auto")
    v.add_argument("--out", required=True, type=output_dir, help="light-field folder")
    v.set_defaults(func=_decode)

    from lumigraph.lightfield.methods import REFOCUS_METHODS

    v = add_verb(sp, "refocus", "refocused photographs (one file, or a folder + index.json)",
                 epilog="methods:\n" + REFOCUS_METHODS.help_text() +
                        "\n  auto       shift-add for up to 3 values, fourier from 4 on\n\n"
                        "With --workers or --scheduler, several values are a batch: each value "
                        "one item (refocus-NNN.exr with its sidecar, by the one-value command: "
                        "auto is then shift-add), and index.json is the batch's index.\n\n"
                        "Several light fields (LF1 LF2 ..., or one folder of light-field folders) "
                        "are a batch, in this process by default: each light field one item, "
                        "the one-light-field command writing OUT/NAME.exr (one value) or the "
                        "folder OUT/NAME/ (several values).\n\n"
                        + BATCH_HELP)
    v.add_argument("lightfield", nargs="+", type=input_path,
                   help="light-field folder; several (or one folder of them) are a batch")
    g = v.add_mutually_exclusive_group(required=True)
    g.add_argument("--alpha", nargs="+", action="extend", type=numbers(positive),
                   help="Ng's alpha values")
    g.add_argument("--depth", nargs="+", action="extend", type=numbers(positive),
                   help="focal depths (units of spacing)")
    g.add_argument("--slope", nargs="+", action="extend", type=numbers(number(float)),
                   help="slopes, px per view step")
    v.add_argument("--method", choices=(*REFOCUS_METHODS.names, "auto"), default="auto",
                   help="refocusing method (see below; default auto)")
    v.add_argument("--kernel", choices=("linear", "cubic", "lanczos3"), default="lanczos3",
                   help="shift-add's interpolation (default lanczos3)")
    v.add_argument("--out", required=True, type=output_file_or_dir(".exr"), help="OUT.exr for one value, a folder for several")
    add_device_option(v)
    add_batch_options(v)
    v.set_defaults(func=_refocus)

    v = add_verb(sp, "render", "render a novel pinhole view from the light slab")
    v.add_argument("lightfield", type=input_path, help="light-field folder")
    v.add_argument("--position", nargs=3, type=number(float), required=True, metavar=("X", "Y", "Z"),
                   help="pinhole position (world units, relative to the grid centre)")
    fg = v.add_mutually_exclusive_group()
    fg.add_argument("--focus-slope", type=number(float), default=0.0,
                    help="disparity of the slab's (s, t) plane (default 0: infinity)")
    fg.add_argument("--focus-depth", type=positive, help="depth of the (s, t) plane")
    v.add_argument("--interpolation", choices=("quadrilinear", "uv-bilinear"),
                   default="quadrilinear")
    v.add_argument("--out", required=True, type=output_file(".exr"), help="view.exr (RGBA, A = valid ray)")
    v.set_defaults(func=_render)

    from lumigraph.lightfield.methods import DEPTH_METHODS

    v = add_verb(sp, "depth", "disparity, confidence (and all-in-focus image) from the light field",
                 epilog="methods:\n" + DEPTH_METHODS.help_text())
    v.add_argument("lightfield", type=input_path, help="light-field folder")
    v.add_argument("--slopes", type=SlopeRange(), default=(-2.0, 2.0, 41),
                   help="MIN,MAX,N: N candidate disparities from MIN to MAX (px per view step; "
                        "default -2,2,41)")
    v.add_argument("--method", choices=DEPTH_METHODS.names, default=DEPTH_METHODS.names[0],
                   help=f"depth method (see below; default {DEPTH_METHODS.names[0]})")
    v.add_argument("--window", type=number(int, lo=1, odd=True),
                   help="variance method: cost aggregation window side (px; default 7)")
    v.add_argument("--edges", choices=("soft", "hard"), default="soft",
                   help="wang2015: at depth edges, soft (default) gives a mixed pixel a disparity "
                        "between the two surfaces by its colour (lower squared error, but "
                        "'flying pixels' in a point cloud); hard keeps every pixel on one "
                        "surface (use it before triangulating)")
    v.add_argument("--confidence", type=output_file(".pfm"),
                   help="also write the confidence in [0, 1] (PFM)")
    v.add_argument("--all-in-focus", type=output_file(".exr"), help="also write the all-in-focus image (EXR)")
    v.add_argument("--out", required=True, type=output_file(".pfm"), help="disparity.pfm")
    v.set_defaults(func=_depth)
    return p


def main(argv=None, prog: str = "lumigraph lightfield") -> int:
    import sys

    argv = sys.argv[1:] if argv is None else argv
    return run(build_parser(prog), join_number_lists(argv))
