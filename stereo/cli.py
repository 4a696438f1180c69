"""``lumigraph stereo``: block-matching stereo, depth, triangulation and SfM, file to file.

Parses, loads, calls :mod:`stereo.block_matching`, :mod:`stereo.triangulate`,
:mod:`stereo.sfm` and :mod:`calib.rectify`, and saves. Every file goes through
its artifact's one parser: :meth:`Rig.load <lumigraph.capture.rig.Rig.load>`
(``rig.json``, or a rendered scene's ``gt.json`` with a ``rig`` entry),
:meth:`Camera.load <lumigraph.capture.camera.Camera.load>` (``camera.json`` or a
``gt.json`` with a ``camera`` entry) and :meth:`Rectification.load
<lumigraph.calib.rectify.Rectification.load>` (``rectification.json`` from
``lumigraph calib rectify``, used as saved).

The library checks every value it takes and names the argument; where files
would be read first, the command calls its ``check_*`` function early
(:func:`~lumigraph.stereo.block_matching.check_match_options`,
:func:`~lumigraph.stereo.block_matching.check_rectified`,
:func:`~lumigraph.stereo.debevec1996.check_model_stereo_options`). The command
line keeps the text parsing, what concerns files (an empty image, images of
different sizes, images against the rig or rectification file, the tracks and
model files) and output names, and maps each library argument to its flag or
to the file it came from. An SfM that registers too few views ran but has no
usable result: exit 3 (``EXIT_UNUSABLE``), one line, nothing written.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from lumigraph.capture.commandline import (
    BATCH_HELP,
    add_batch_options,
    add_verb,
    check_output_dir,
    check_output_path,
    check_planned,
    input_path,
    make_parser,
    number,
    output_dir,
    output_file,
    output_file_or_dir,
    run,
    say,
    subparsers,
    warn,
)
from lumigraph.capture.device import add_device_option, resolve_device
from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.stereo.block_matching import WINDOW_RANGE
from lumigraph.stereo.debevec1996 import WINDOW_RANGE as MODEL_WINDOW_RANGE
from lumigraph.stereo.debevec1996.model_stereo import COSTS as MODEL_COSTS
from lumigraph.stereo.match_methods import MATCH_METHODS
from lumigraph.stereo.triangulate import ANGLE_RANGE_DEG
from lumigraph.stereo.triangulate import METHODS as TRIANGULATION_METHODS

EPILOG = """\
examples:
  lumigraph render stereo-pair --out out/pair
  lumigraph stereo match out/pair/left.png out/pair/right.png --max-disp 48 --out out/disparity.pfm
  lumigraph stereo match L.png R.png --rig rig.json --max-disp 64 --out d.pfm   (rectifies first)
  lumigraph calib rectify --rig rig.json L.png R.png --out rectified
  lumigraph stereo match L.png R.png --rectification rectified/rectification.json --max-disp 64 --out d.pfm
  lumigraph stereo depth d.pfm --rectification rectified/rectification.json --image L.png --out points.ply
  lumigraph stereo depth out/disparity.pfm --rig out/pair/gt.json --image out/pair/left.png --out out/points.ply
  lumigraph render model-stereo --out out/facade
  lumigraph stereo model-based out/facade/key.png out/facade/offset.png --rig out/facade/gt.json \
      --model out/facade/gt/model_depth.npy --max-offset 0.35 --out out/facade_depth.pfm
  lumigraph stereo triangulate tracks.json --out points.json
  lumigraph stereo sfm out/views/*.png --camera out/views/gt.json --out out/sfm
  lumigraph stereo facade solve FOLDER --out out/facade   (FOLDER: stack.json, blocks.json, edges.json)

Disparity: left image is the reference, x_right = x_left - d, unknown = inf in the PFM.
"""

TRIANGULATE_EPILOG = """\
correspondence files:
  tracks.json (any number of views):
    {"views": [{"camera": <camera.json contents>, "cam_from_world": {"R": 3x3, "t": [3]}}, ...],
     "tracks": [[[x, y] or null for each view], ...],
     "pixel_sigma": 0.5}                       (optional; --pixel-sigma overrides)
  matches.txt with --rig rig.json (two views): one match per line, "x_left y_left x_right y_right",
    '#' starts a comment; the world frame is the left camera's.
Pixels are distorted image coordinates, pixel centres at integers.
Output: .ply (finite points) or .json (every point with covariance, ray angle,
reprojection RMS and flags). Rays closer than --min-angle degrees to parallel
are flagged (a warning is printed); parallel rays give points at infinity,
written as directions in the .json and left out of the .ply.
"""


# ----------------------------------------------------------------- loading


def _point_colours(img: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """8-bit RGB colours of the image's pixels where ``ok``: 16-bit scaled
    down, grey repeated over three channels, alpha dropped."""
    if img.dtype == np.uint16:
        img = (img / 257.0).round().astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return img[..., :3][ok].astype(np.uint8)


def _read(path):
    from lumigraph.capture.io import read_image

    img = read_image(path)
    if img.size == 0 or min(img.shape[:2]) == 0:
        raise InputError(path, "empty image")
    return img


def _rectification(args, pair=None):
    """The rectification of ``--rectification`` (used as saved) or computed
    from ``--rig``, and the file it came from. With ``pair`` given, ``((left
    file, image), (right file, image))``, the images must be the size the rig
    was calibrated for: one image off is that image's fault, both off the
    rig's (or the rectification's)."""
    from lumigraph.calib.rectify import Rectification, rectify
    from lumigraph.capture.rig import Rig

    if getattr(args, "rectification", None):
        src, what = args.rectification, "rectification"
        rect = Rectification.load(src)
        rig = rect.rig
    else:
        src, what = args.rig, "rig"
        rig = Rig.load(src)
        rect = None
    if pair is not None:
        off = [(f, im) for (f, im), cam in zip(pair, (rig.left, rig.right), strict=True)
               if tuple(cam.image_size) != im.shape[1::-1]]
        w, h = rig.left.image_size
        if len(off) == 1:
            f, im = off[0]
            raise InputError(f, f"is {im.shape[1]}x{im.shape[0]} but the {what} ({src}) is for "
                                f"{w}x{h} images, like the other image of the pair")
        if off:
            sizes = sorted({f"{im.shape[1]}x{im.shape[0]}" for _, im in pair})
            raise InputError(src, f"{what} is for {w}x{h} images, the pair is "
                                  f"{' and '.join(sizes)}")
    if rect is None:
        try:
            rect = rectify(rig)
        except ValueError as e:
            raise InputError(src, str(e)) from None
    return rect, src


def _distinct_files(left, right) -> None:
    """The same file as both views gives nothing to match: refused, naming the second."""
    try:
        same = Path(left).samefile(right)
    except OSError:
        return  # the reader names a missing file
    if same:
        raise InputError(right, "is also the left image; give the other view of the pair")


# ------------------------------------------------------------------ verbs
def _device_help(parser, what: str) -> None:
    """Append what the command ports to the shared --device help."""
    for a in parser._actions:
        if a.dest == "device":
            a.help = f"{a.help}. {what}"


_IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".exr", ".pfm")


def _match_batch(args) -> int:
    """``stereo match LEFT_DIR RIGHT_DIR --out DIR``: the pairs are the images
    of one name in both folders, each one item written by the one-pair
    command as ``DIR/<name>.pfm``."""
    from lumigraph.capture.batch import command_item, run_items
    from lumigraph.capture.commandline import batch_item_argv

    lefts, rights = Path(args.left), Path(args.right)
    out = Path(args.out)
    if out.suffix.lower() == ".pfm":
        raise InputError("out", f"two folders give a disparity map per pair: name a folder, not "
                                f"{out}")
    names = sorted(p.name for p in lefts.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    missing = [n for n in names if not (rights / n).is_file()]
    if not names:
        raise InputError(lefts, "no images in this folder (a batch pairs the images of one name "
                                "in the left and the right folder)")
    if missing:
        raise InputError(rights / missing[0], f"the left folder has {missing[0]} but this is "
                                              "missing; a batch pairs images of one name")
    # the files every pair shares, read before any work: a bad one is exit 2, not N failed items
    if args.rig:
        from lumigraph.capture.rig import Rig

        Rig.load(args.rig)
    if args.rectification:
        from lumigraph.calib.rectify import Rectification

        Rectification.load(args.rectification)
    shared = [str(p) for p in (args.rig, args.rectification) if p]
    items = []
    for n in names:
        target = out / (Path(n).stem + ".pfm")
        items.append(command_item(Path(n).stem, inputs=(lefts / n, rights / n, *shared),
                                  outputs=(target,), module="lumigraph.stereo.cli",
                                  prog="lumigraph stereo",
                                  argv=batch_item_argv(args, [lefts / n, rights / n],
                                                       add=["--out", str(target)])))
    return run_items(items, out_dir=out, args=args, description="matching")


def _match(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.stereo.block_matching import (
        RECTIFIED_MIN_MATCHES,
        check_match_options,
        check_rectified,
        match,
    )
    from lumigraph.stereo.hirschmuller2008 import DEFAULTS as SGM_DEFAULTS
    from lumigraph.stereo.hirschmuller2008 import check_sgm_options
    from lumigraph.stereo.hirschmuller2008 import match as sgm_match

    if Path(args.left).is_dir() and Path(args.right).is_dir():
        return _match_batch(args)
    out = check_output_path(args.out, suffixes=(".pfm",))
    _distinct_files(args.left, args.right)
    device = resolve_device(args.device)  # before any image is read: a missing GPU is exit 2
    left, right = _read(args.left), _read(args.right)
    rectifying = bool(args.rig or args.rectification)
    if left.shape[:2] != right.shape[:2] and not rectifying:  # with a rig, it says who is off
        raise InputError(args.right, f"size {right.shape[1]}x{right.shape[0]} differs from the left "
                                     f"image's {left.shape[1]}x{left.shape[0]}")
    # the library names the images "left" and "right": report their files
    args.arg_flags = {**(getattr(args, "arg_flags", None) or {}), "left": args.left, "right": args.right}
    window = args.window  # an odd integer or "auto" (the parser's)
    sgm = args.method == "sgm"
    defaults = SGM_DEFAULTS if sgm else {"uniqueness": 0.02, "lr_tolerance": 3}
    uniqueness = defaults["uniqueness"] if args.uniqueness is None else args.uniqueness
    lr_tolerance = defaults["lr_tolerance"] if args.lr_tolerance is None else args.lr_tolerance
    # the library's rules, before the pair is rectified and checked
    if sgm:
        check_sgm_options(left.shape, max_disp=args.max_disp, cost=args.cost,
                          uniqueness=uniqueness, lr_tolerance=lr_tolerance)
    else:
        check_match_options(left.shape, max_disp=args.max_disp, window=window,
                            texture_snr=args.texture_snr, uniqueness=uniqueness,
                            channels=args.channels, prefilter=args.prefilter,
                            lr_tolerance=lr_tolerance)
    t0 = time.perf_counter()
    params = {"method": args.method, "max_disp": args.max_disp, "uniqueness": uniqueness,
              "lr_tolerance": lr_tolerance}
    params["texture_snr"] = args.texture_snr
    params["device"] = device.name
    params.update({"cost": args.cost} if sgm else
                  {"window": window, "channels": args.channels, "prefilter": args.prefilter})
    model: dict = {}
    inputs = [args.left, args.right]
    if rectifying:
        rect, src = _rectification(args, ((args.left, left), (args.right, right)))
        inputs.append(src)
        left, right = rect.apply(left, right, device=device)
        model["rectification"] = {"R1": rect.R1, "P1": rect.P1, "P2": rect.P2, "Q": rect.Q,
                                  "focal_px": rect.focal_px, "baseline": rect.baseline}
        say(args, f"rectified with {src} (f = {rect.focal_px:.1f} px, B = {rect.baseline:.4g})")
    else:
        off = check_rectified(left, right, remedy="give the rig with --rig rig.json")
        model["rectification_check"] = off
        if off["matches"] < RECTIFIED_MIN_MATCHES:
            warn(f"only {off['matches']} feature matches: could not confirm the pair is rectified")
    if sgm:
        res = sgm_match(left, right, max_disp=args.max_disp, cost=args.cost, uniqueness=uniqueness,
                        lr_tolerance=lr_tolerance, texture_snr=args.texture_snr, device=device)
        model["sgm"] = res.info
    else:
        res = match(left, right, max_disp=args.max_disp, window=window, texture_snr=args.texture_snr,
                    uniqueness=uniqueness, lr_tolerance=lr_tolerance, channels=args.channels,
                    prefilter=args.prefilter, device=device)
        model["block_matching"] = res.info
    warnings = list(res.info.get("warnings", []))
    for w in warnings:
        warn(w)
    dt = time.perf_counter() - t0
    meta = make_meta("lumigraph.disparity", inputs=inputs, params=params, model=model,
                     quality={"valid_fraction": res.valid_fraction,
                              "median_disparity": float(np.nanmedian(res.disparity))
                              if res.valid_fraction > 0 else None},
                     timings_s={"total": dt}, warnings=warnings,
                     extra={"convention": "left reference, x_right = x_left - d, unknown = inf"})
    res.save(out, meta=meta)
    say(args, f"wrote {out} ({100 * res.valid_fraction:.0f}% of pixels matched)")
    return 0


def _depth(args) -> int:
    import cv2

    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import read_pfm, write_ply

    out = check_output_path(args.out, suffixes=(".ply",))
    disp = read_pfm(args.disparity)
    if disp.ndim != 2:
        raise InputError(args.disparity, f"expected a one-channel disparity PFM, got shape {disp.shape}")
    if not (args.rig or args.rectification):
        return _depth_from_focal(args, out, disp)
    given = [f for f, v in (("--focal-px", args.focal_px), ("--baseline", args.baseline),
                            ("--cx", args.cx), ("--cy", args.cy), ("--doffs", args.doffs)) if v is not None]
    if given:
        raise InputError(given[0], "belongs to a pair without a rig; the rig or rectification file "
                                   "already gives the focal length and baseline: drop it")
    rect, src = _rectification(args)
    rig = rect.rig
    if disp.shape[::-1] != tuple(rect.image_size):
        raise InputError(args.disparity, f"size {disp.shape[1]}x{disp.shape[0]} differs from the "
                                         f"rectified size {rect.image_size[0]}x{rect.image_size[1]}")
    pts = rect.reproject(disp).astype(np.float64)
    frame = "rectified left camera"
    if args.frame == "left":
        pts = pts @ rect.R1  # rect_from_cam = R1, so cam = R1^T rect (row vectors)
        frame = "original left camera"
    ok = np.isfinite(pts).all(axis=2)
    if args.max_depth is not None:  # > 0, the parser's
        ok &= pts[..., 2] <= args.max_depth
    colors = None
    if args.image:
        img = _read(args.image)
        if img.shape[1::-1] != tuple(rig.left.image_size):
            raise InputError(args.image, f"size {img.shape[1]}x{img.shape[0]} differs from the rig's "
                                         f"{rig.left.image_size[0]}x{rig.left.image_size[1]}")
        lx, ly, _, _ = rect.maps()
        img = cv2.remap(np.ascontiguousarray(img), lx, ly, cv2.INTER_LINEAR)
        colors = _point_colours(img, ok)
    if not ok.any():
        if args.max_depth is not None and np.isfinite(pts).all(axis=2).any():
            raise EstimationError("max_depth", f"no point is nearer than {args.max_depth:g} (rig "
                                               "units); nothing to write")
        raise EstimationError(args.disparity, "no valid disparity: nothing to reproject")
    meta = make_meta("lumigraph.points", inputs=[args.disparity, src] + ([args.image] if args.image else []),
                     params={"frame": frame, "max_depth": args.max_depth},
                     quality={"points": int(ok.sum()), "of_pixels": int(disp.size)},
                     extra={"focal_px": rect.focal_px, "baseline": rect.baseline})
    write_artifact(out, lambda tmp: write_ply(tmp, pts[ok], colors), meta=meta)
    say(args, f"wrote {int(ok.sum())} points to {out} ({frame} frame)")
    return 0


def _depth_from_focal(args, out, disp) -> int:
    """Points of a rectified pair known only by its focal length and
    baseline (Middlebury's calib.txt): Z = baseline f / (d + doffs), X = (x -
    cx) Z / f, Y = (y - cy) Z / f in the left camera's frame."""
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import write_ply

    if args.focal_px is None or args.baseline is None:
        raise InputError("--focal-px", "give the rig (--rig or --rectification) or, for a rectified pair "
                                  "without one, --focal-px and --baseline")
    h, w = disp.shape
    f, b = args.focal_px, args.baseline
    cx = (w - 1) / 2 if args.cx is None else args.cx
    cy = (h - 1) / 2 if args.cy is None else args.cy
    doffs = args.doffs or 0.0
    d = disp.astype(np.float64) + doffs
    ok = np.isfinite(d) & (d > 0)
    z = np.where(ok, b * f / np.where(ok, d, 1.0), np.inf)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([(x - cx) * z / f, (y - cy) * z / f, z], axis=2)
    if args.max_depth is not None:
        ok &= z <= args.max_depth
    colors = None
    if args.image:
        img = _read(args.image)
        if img.shape[:2] != disp.shape:
            raise InputError(args.image, f"size {img.shape[1]}x{img.shape[0]} differs from the "
                                         f"disparity's {w}x{h}; give the rectified left image")
        colors = _point_colours(img, ok)
    if not ok.any():
        if args.max_depth is not None and (np.isfinite(d) & (d > 0)).any():
            raise EstimationError("max_depth", f"no point is nearer than {args.max_depth:g}; "
                                               "nothing to write")
        raise EstimationError(args.disparity, "no valid disparity (finite and above -doffs): "
                                              "nothing to reproject")
    meta = make_meta("lumigraph.points", inputs=[args.disparity] + ([args.image] if args.image else []),
                     params={"frame": "rectified left camera", "max_depth": args.max_depth,
                             "focal_px": f, "baseline": b, "cx": cx, "cy": cy, "doffs": doffs},
                     quality={"points": int(ok.sum()), "of_pixels": int(disp.size)},
                     extra={"convention": "Z = baseline * focal_px / (d + doffs), X = (x - cx) Z / "
                                          "focal_px, Y = (y - cy) Z / focal_px (Middlebury calib.txt)"})
    write_artifact(out, lambda tmp: write_ply(tmp, pts[ok], colors), meta=meta)
    say(args, f"wrote {int(ok.sum())} points to {out} (rectified left camera frame)")
    return 0


def _load_tracks(args):
    from lumigraph.capture.rig import Rig
    from lumigraph.stereo.triangulate import read_tracks

    p = Path(args.correspondences)
    if p.suffix.lower() == ".json":
        return read_tracks(p)
    if not args.rig:
        raise InputError(p, "a text file of matches needs --rig rig.json (or give a tracks .json)")
    if not p.is_file():
        raise InputError(p, "file not found")
    try:
        rows = np.loadtxt(p, comments="#", ndmin=2)
    except ValueError as e:
        raise InputError(p, f"cannot read matches ({e}); expected 'x_left y_left x_right y_right' per line") from None
    if rows.shape[1] != 4 or len(rows) == 0:
        raise InputError(p, f"expected 4 columns per line and at least one line, got shape {rows.shape}")
    rig = Rig.load(args.rig)
    px = np.stack([rows[:, :2], rows[:, 2:]])
    return [rig.left, rig.right], [(np.eye(3), np.zeros(3)), (rig.R, rig.T)], px, None


def _triangulate(args) -> int:
    from lumigraph.capture.artifact import dumps_json, make_meta, write_artifact
    from lumigraph.capture.io import write_ply
    from lumigraph.stereo.triangulate import triangulate

    out = check_output_path(args.out, suffixes=(".ply", ".json"))
    cams, poses, px, sigma = _load_tracks(args)
    if args.pixel_sigma is not None:
        sigma = args.pixel_sigma
    else:  # the tracks file's pixel_sigma, else the default; a bad one is that file's
        sigma = 0.5 if sigma is None else sigma
        args.arg_flags = {**(getattr(args, "arg_flags", None) or {}),
                          "pixel_sigma": args.correspondences}
    try:
        tri = triangulate(px, cams, poses, method=args.method, pixel_sigma=float(sigma),
                          min_angle_deg=args.min_angle)
    except InputError:
        raise  # pixel_sigma: run() reports --pixel-sigma, or the tracks file
    except ValueError as e:
        raise InputError(args.correspondences, str(e)) from None
    for w in tri.warnings:
        warn(w)
    meta = make_meta("lumigraph.points", inputs=[args.correspondences] + ([args.rig] if args.rig else []),
                     params={"method": args.method, "pixel_sigma": sigma, "min_angle_deg": args.min_angle},
                     quality={"points": len(tri.points),
                              "median_reprojection_rms_px": float(np.nanmedian(tri.reprojection_rms))
                              if np.isfinite(tri.reprojection_rms).any() else None,
                              "median_sigma": float(np.nanmedian(tri.sigma))
                              if np.isfinite(tri.sigma).any() else None},
                     warnings=tri.warnings, model=tri.info)
    if out.suffix.lower() == ".ply":
        fin = ~tri.at_infinity
        write_artifact(out, lambda tmp: write_ply(tmp, tri.points[fin]), meta=meta)
    else:
        doc = {"schema": "lumigraph.triangulation", "schema_version": 1, "info": tri.info,
               "points": [{"xyz": None if tri.at_infinity[i] else tri.points[i].tolist(),
                           "direction": tri.points_h[i, :3].tolist() if tri.at_infinity[i] else None,
                           "covariance": None if tri.at_infinity[i] else tri.covariance[i].tolist(),
                           "sigma": None if tri.at_infinity[i] else float(tri.sigma[i]),
                           "angle_deg": float(tri.angle_deg[i]),
                           "reprojection_rms_px": float(tri.reprojection_rms[i]),
                           "near_parallel": bool(tri.near_parallel[i]),
                           "at_infinity": bool(tri.at_infinity[i])} for i in range(len(tri.points))]}
        write_artifact(out, lambda tmp: tmp.write_text(dumps_json(doc)), meta=meta)
    say(args, f"wrote {len(tri.points)} points to {out}")
    return 0


def _sfm(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.capture.camera import Camera
    from lumigraph.stereo.sfm import Reconstruction, assess, exif_focal_px, reconstruct

    out = check_output_dir(args.out)
    check_planned([out / n for n in Reconstruction.OUTPUTS])
    images = [_read(p) for p in args.images]
    camera = Camera.load(args.camera) if args.camera else None
    n = len(images)
    prior, prior_from = args.focal_px, "--focal-px"
    if camera is None and prior is None:
        size = images[0].shape[1::-1]
        found = [f for f in (exif_focal_px(p, size) for p in args.images) if f]
        if found:
            prior, prior_from = float(np.median(found)), "EXIF"
    centres = _prior_centres(args.poses, args.images) if args.poses else None
    try:
        rec = reconstruct(images, [str(p) for p in args.images], camera=camera,
                          focal_prior_px=prior if camera is None else None,
                          centres_prior=centres, centre_sigma=args.pose_sigma, seed=args.seed)
    except EstimationError as e:  # COLMAP ran and registered fewer than two views
        _unusable(args.images, f"registered fewer than 2 of {n} views ({e.problem}); nothing written")
    why = assess(rec, min_registered=args.min_registered,
                 focal_prior_px=prior if camera is None else None)
    if why:
        _unusable(args.images, "; ".join(why) + "; nothing written")
    got = rec.info["registered"]
    warnings = []
    if got < n:
        left = [m for m, ok in zip(rec.image_names, rec.registered, strict=True) if not ok]
        warnings.append(f"registered {got} of {n} views; not registered: {', '.join(left)} "
                        "(cameras.json marks them)")
        warn(warnings[-1])
    meta = make_meta("lumigraph.sfm", inputs=[*args.images] + ([args.camera] if args.camera else [])
                     + ([args.poses] if args.poses else []),
                     params={"seed": args.seed, "fixed_intrinsics": camera is not None,
                             "min_registered": args.min_registered,
                             "pose_priors": bool(args.poses), "pose_sigma": args.pose_sigma,
                             "focal_prior_px": prior if camera is None else None,
                             "focal_prior_from": prior_from if camera is None and prior else None},
                     quality={k: rec.info[k] for k in ("registered", "images", "points",
                                                       "mean_reprojection_error_px",
                                                       "median_ray_angle_deg")},
                     timings_s=rec.info["timings_s"], model=rec.info, warnings=warnings)
    rec.save(out, meta=meta)
    say(args, f"registered {got}/{n} views, {rec.info['points']} points "
              f"-> {out}/cameras.json, points.ply and COLMAP's cameras.txt, images.txt, points3D.txt")
    return 0


def _prior_centres(path, images):
    """Camera centres (N, 3) from a cameras.json (``views``: ``image``,
    ``cam_from_world``), matched to the images by file name; NaN where absent."""
    import json

    try:
        doc = json.loads(Path(path).read_text())
        poses = {os.path.basename(v["image"]): v["cam_from_world"] for v in doc["views"]
                 if v.get("cam_from_world")}
        C = np.full((len(images), 3), np.nan)
        for i, p in enumerate(images):
            cw = poses.get(os.path.basename(str(p)))
            if cw is not None:
                R, t = np.asarray(cw["R"], float).reshape(3, 3), np.asarray(cw["t"], float).reshape(3)
                C[i] = -R.T @ t
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(path, f"expected a cameras.json with views of image and cam_from_world "
                               f"{{R, t}} ({type(e).__name__}: {e})") from None
    if np.isfinite(C).all(axis=1).sum() < 3:
        raise InputError(path, "gives the pose of fewer than 3 of the images (matched by file name); "
                               "at least 3 fix the frame")
    return C


def _unusable(images, problem: str):
    """Exit 3, one line naming the images' folder: the work ran but its result
    is not usable (nothing is written)."""
    from lumigraph.capture.errors import UnusableResult

    folder = os.path.commonpath([os.path.abspath(p) for p in images])
    raise UnusableResult(folder if os.path.isdir(folder) else os.path.dirname(folder), problem)


def _read_model(path):
    """A rough model's key-view depth: PFM (inf = absent) or a ``.npy`` array."""
    from lumigraph.capture.io import read_pfm

    p = Path(path)
    if p.suffix.lower() == ".npy":
        if not p.is_file():
            raise InputError(p, "file not found")
        try:  # mapped, not read: a header claiming a huge array costs nothing until the
            # size check against the key image (the file holds fewer bytes: refused here)
            z = np.load(p, mmap_mode="r", allow_pickle=False)
        except (ValueError, OSError, EOFError) as e:
            raise InputError(p, f"not a .npy array ({e})") from None
    else:
        z = read_pfm(p)
    if z.ndim != 2 or z.dtype.kind != "f":
        raise InputError(p, f"expected a one-channel float depth map, got shape {z.shape} {z.dtype}")
    return z


def _model_based(args) -> int:
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import write_image
    from lumigraph.capture.rig import Rig
    from lumigraph.stereo.debevec1996 import check_model_stereo_options, model_stereo

    out = check_output_path(args.out, suffixes=(".pfm",))
    left_right = args.left_right or None  # the flag's 0 turns the check off
    max_cost = float(args.max_cost)  # "inf" (the parser allows it) disables the test
    # the library's rules, before any file is read
    check_model_stereo_options(max_offset=args.max_offset, window=args.window, step=args.step,
                               texture_snr=args.texture_snr, uniqueness=args.uniqueness,
                               max_cost=max_cost, left_right=left_right, cost=args.cost)
    _distinct_files(args.key, args.offset)
    key, off = _read(args.key), _read(args.offset)
    if key.shape[:2] != off.shape[:2]:
        raise InputError(args.offset, f"size {off.shape[1]}x{off.shape[0]} differs from the key image's "
                                      f"{key.shape[1]}x{key.shape[0]}")
    model = _read_model(args.model)
    if model.shape != key.shape[:2]:
        raise InputError(args.model, f"size {model.shape[1]}x{model.shape[0]} differs from the key "
                                     f"image's {key.shape[1]}x{key.shape[0]}")
    std = None
    if args.model_std is not None:
        std = _read_model(args.model_std)
        if std.shape != model.shape:
            raise InputError(args.model_std, f"size {std.shape[1]}x{std.shape[0]} differs from the "
                                             f"model's {model.shape[1]}x{model.shape[0]}")
    rig = Rig.load(args.rig)
    for cam, name in ((rig.left, "left (key)"), (rig.right, "right (offset)")):
        if tuple(cam.image_size) != (key.shape[1], key.shape[0]):
            raise InputError(args.rig, f"the {name} camera is for {cam.image_size[0]}x{cam.image_size[1]} "
                                       f"images, the pair is {key.shape[1]}x{key.shape[0]}")
    # the library names its inputs: report their files
    args.arg_flags = {**(getattr(args, "arg_flags", None) or {}), "key": args.key,
                      "offset": args.offset, "model_depth": args.model, "rig": args.rig,
                      "model_std": args.model_std}
    t0 = time.perf_counter()
    try:
        res = model_stereo(key, off, model, rig, max_offset=args.max_offset, window=args.window,
                           step=args.step, texture_snr=args.texture_snr, uniqueness=args.uniqueness,
                           max_cost=max_cost, left_right=left_right, cost=args.cost,
                           model_std=std)
    except (InputError, EstimationError):
        raise
    except ValueError as e:
        raise InputError(args.model, str(e)) from None
    dt = time.perf_counter() - t0
    for w in res.info["warnings"]:
        warn(w)
    params = {"max_offset": args.max_offset, "window": args.window, "step": args.step,
              "texture_snr": args.texture_snr, "uniqueness": args.uniqueness,
              "max_cost": max_cost, "left_right": left_right, "cost": args.cost,
              "model_std": None if args.model_std is None else str(args.model_std)}
    info = {k: v for k, v in res.info.items() if k not in ("warnings", "timings_s")}
    meta = make_meta("lumigraph.depth", inputs=[args.key, args.offset, args.model, args.rig,
                                                *([args.model_std] if args.model_std else [])],
                     params=params, model={"model_based_stereo": info},
                     quality={"valid_fraction": res.valid_fraction,
                              "valid_fraction_of_seen": res.info["valid_fraction_of_seen"],
                              "median_abs_offset": float(np.nanmedian(np.abs(res.offset)))
                              if res.valid.any() else None},
                     timings_s={"total": dt, **res.info["timings_s"]}, warnings=res.info["warnings"],
                     extra={"convention": "depth = z in the key (left) camera frame, unit of the "
                                         "rig's T; unknown = inf",
                            "delta_range": res.info["delta_range"], "delta_step": res.info["step"]})
    if args.warped:
        wimg = np.nan_to_num(res.warped, nan=0.0)
        hi = 65535 if off.dtype == np.uint16 else 255
        wimg = np.clip(np.rint(wimg), 0, hi).astype(np.uint16 if hi == 65535 else np.uint8)
        wmeta = make_meta("lumigraph.warped-offset", inputs=[args.offset, args.model, args.rig],
                          params={"delta": 0.0},
                          extra={"what": "offset image projected onto the model, seen from the key "
                                         "camera (Debevec et al. 1996, Fig. 5.12c); 0 = unseen"})
        write_artifact(args.warped, lambda tmp: write_image(tmp, wimg), meta=wmeta)
    res.save(out, meta=meta)
    say(args, f"wrote {out} ({100 * res.valid_fraction:.0f}% of pixels; δ in "
              f"[{res.info['delta_range'][0]:.3g}, {res.info['delta_range'][1]:.3g}] step "
              f"{res.info['step']:.3g})")
    return 0


def build_parser(prog: str = "lumigraph stereo"):
    positive = number(float, lo=0, lo_open=True)
    p = make_parser(prog, "Block-matching stereo, depth from disparity, triangulation and "
                          "structure from motion.", epilog=EPILOG)
    sp = subparsers(p)

    v = add_verb(sp, "match", "dense disparity of a stereo pair (semi-global matching, or SSD "
                              "block matching, eq. 5.1)",
                 epilog="A pair without --rig or --rectification must already be rectified "
                        "(checked from matched features: vertical offsets > 1 px are refused).\n"
                        "--method sgm (default): semi-global matching (Hirschmueller 2008) on a "
                        "9x7 census cost, robust to an exposure change between the views; pixels "
                        "failing the left-right, uniqueness or speckle tests, and pixels whose best "
                        "match is --max-disp (a warning says when the range looks too small), are "
                        "unknown (inf).\n"
                        "--method ssd: SSD window matching; --window auto picks per pixel the "
                        "smallest of 5, 9, 15 whose texture passes --texture-snr; the choice is "
                        "recorded in the .meta.json. --window, --channels and --prefilter apply to "
                        "ssd only, --cost to sgm only.\n\n"
                        "A sequence of pairs: LEFT and RIGHT are folders, the images of one name "
                        "in both are a pair:\n"
                        "  lumigraph stereo match left/ right/ --max-disp 64 --out disp/ --workers 2\n\n"
                        + BATCH_HELP)
    v.add_argument("left", type=input_path,
                   help="left image (the reference); for a batch, a folder of left images")
    v.add_argument("right", type=input_path,
                   help="right image; for a batch, a folder of right images of the same names")
    g = v.add_mutually_exclusive_group()
    g.add_argument("--rig", type=input_path, help="rig.json (or a scene gt.json): rectify the pair first")
    g.add_argument("--rectification", type=input_path,
                   help="rectification.json from 'lumigraph calib rectify': rectify the pair "
                        "with it, as saved")
    v.add_argument("--max-disp", type=number(int, lo=1), required=True,
                   help="largest disparity searched (px), below the image width")
    v.add_argument("--method", choices=MATCH_METHODS.names, default="sgm",
                   help="; ".join(f"{m.name}: {m.help}" for m in MATCH_METHODS.values()))
    v.add_argument("--cost", choices=("census", "ssd"), default="census",
                   help="sgm's matching cost: census (default; robust to exposure changes) or "
                        "ssd (truncated mean squared difference over 3x3)")
    v.add_argument("--window", type=number(int, lo=WINDOW_RANGE[0], hi=WINDOW_RANGE[1], odd=True,
                                           allow=("auto",)),
                   default="auto", help="odd window side, or auto (default)")
    v.add_argument("--texture-snr", type=number(float, lo=0), default=1.0,
                   help="minimum window signal std in units of the noise sigma (default 1.0; "
                        "sgm: over 21x21, flatter pixels are unknown)")
    v.add_argument("--uniqueness", type=number(float, lo=0), default=None,
                   help="second-best must cost (1+u) times the best (default 0.005 sgm, 0.02 ssd)")
    v.add_argument("--lr-tolerance", type=number(int, lo=-1), default=None,
                   help="left-right check tolerance in px, -1 disables (default 2 sgm, 3 ssd)")
    v.add_argument("--channels", choices=("luma", "color"), default="luma",
                   help="compare luma (default) or the sum over R, G, B (slower; helps "
                        "colourful scenes of equal-luma hues)")
    v.add_argument("--prefilter", choices=("none", "local-mean"), default="local-mean",
                   help="ssd: local-mean (default) matches each image minus its 9x9 mean, the "
                        "right one's contrast matched to the left's, clipped (StereoBM's "
                        "normalised response): cancels a gain/offset between the views; none "
                        "matches the raw luma (better only for views of one exposure)")
    v.add_argument("--out", required=True, type=output_file_or_dir(".pfm"),
                   help="disparity .pfm (unknown stored as inf); for a batch a folder, which gets "
                        "NAME.pfm per pair and index.json")
    add_device_option(v)
    _device_help(v, "Ported here: sgm's aggregation along the paths (its census, costs and "
                    "checks stay on the CPU), ssd's cost volume and aggregation, and the "
                    "rectification with --rig/--rectification")
    add_batch_options(v)
    v.set_defaults(func=_match)

    v = add_verb(sp, "depth", "3-D points from a disparity map and its rig (PLY, with colours)",
                 epilog="Without a rig: a rectified pair known by --focal-px and --baseline "
                        "(Middlebury calib.txt: f, baseline, cx, cy of cam0, doffs = cx1 - cx0): "
                        "Z = baseline f / (d + doffs), X = (x - cx) Z / f, Y = (y - cy) Z / f, in "
                        "the baseline's unit; --image is then the rectified left image.")
    v.add_argument("disparity", type=input_path, help="disparity .pfm from 'stereo match'")
    g = v.add_mutually_exclusive_group()
    g.add_argument("--rig", type=input_path,
                   help="the rig the pair was rectified with (rig.json or gt.json)")
    g.add_argument("--rectification", type=input_path,
                   help="the rectification.json the pair was rectified with")
    v.add_argument("--focal-px", type=positive, help="without a rig: focal length of the rectified pair (px)")
    v.add_argument("--baseline", type=positive,
                   help="without a rig: distance between the camera centres (its unit is the points')")
    v.add_argument("--cx", type=number(float), help="without a rig: principal point x (px; default the "
                                                    "image centre)")
    v.add_argument("--cy", type=number(float), help="without a rig: principal point y (px; default the "
                                                    "image centre)")
    v.add_argument("--doffs", type=number(float), help="without a rig: x offset of the right principal "
                                                       "point, added to d (px; default 0)")
    v.add_argument("--image", type=input_path, help="the ORIGINAL left image, for point colours")
    v.add_argument("--frame", choices=("left", "rectified"), default="left",
                   help="points in the original left camera frame (default) or the rectified one")
    v.add_argument("--max-depth", type=positive, help="drop points farther than this (rig units)")
    v.add_argument("--out", required=True, type=output_file(".ply"), help="points .ply")
    v.set_defaults(func=_depth)

    v = add_verb(sp, "model-based", "depth of a key view as detail on a rough model, from a "
                 "wide-baseline key/offset pair (Debevec, Taylor & Malik 1996)",
                 epilog="The offset image is projected onto the model and seen from the key camera "
                        "(--warped writes it); each key pixel's offset from the model along its ray "
                        "is searched in [-M, M] (--cost sgm: census cost aggregated along 8 paths "
                        "by semi-global matching, the default; --cost ssd: SSD window matching, "
                        "eq. 5.1). Unknown pixels "
                        "(no model, unseen by the offset camera, no texture, ambiguous, at the end of "
                        "the range, occluded) are inf in the PFM.")
    v.add_argument("key", type=input_path, help="key image (the reference view, the rig's left camera)")
    v.add_argument("offset", type=input_path, help="offset image (the rig's right camera)")
    v.add_argument("--rig", required=True, type=input_path,
                   help="rig.json or a scene gt.json: left = key, right = offset")
    v.add_argument("--model", required=True, type=input_path,
                   help="the rough model's depth seen from the key camera (.pfm, inf = no model, "
                        "or .npy, NaN = no model), z in the rig's unit")
    v.add_argument("--max-offset", type=positive, required=True,
                   help="largest offset of the detail from the model searched (rig's unit)")
    v.add_argument("--model-std", type=input_path,
                   help="the model depth's standard deviation per pixel (.pfm/.npy, as 'stereo "
                        "facade depth --std-out' writes): pixels whose model may be off by more "
                        "than --max-offset/3 are not answered, the search widens by 3x the median")
    v.add_argument("--window", type=number(int, lo=MODEL_WINDOW_RANGE[0], hi=MODEL_WINDOW_RANGE[1],
                                           odd=True),
                   default=9, help="odd window side of the SSD cost, and of the texture and "
                                   "--max-cost tests (default 9)")
    v.add_argument("--cost", choices=MODEL_COSTS, default="sgm",
                   help="matching cost along the search: sgm (census, aggregated along 8 paths; "
                        "default, lower error at every angle of the bench) or ssd (eq. 5.1)")
    v.add_argument("--step", type=positive,
                   help="offset step, at most --max-offset (default: one offset-image pixel)")
    v.add_argument("--texture-snr", type=number(float, lo=0), default=1.0,
                   help="minimum window signal std in units of the noise sigma (default 1.0; "
                        "flatter pixels are unknown)")
    v.add_argument("--uniqueness", type=number(float, lo=0), default=0.02,
                   help="every other offset must cost (1+u) times the best (default 0.02)")
    v.add_argument("--max-cost", type=number(float, lo=0, allow=("inf",)), default=1.0,
                   help="refuse matches costing more than 2 sigma^2 + this x window variance "
                        "(default 1.0; inf disables)")
    v.add_argument("--left-right", type=number(float, lo=0), default=1.25,
                   help="left-right check: the same search from the offset view must map back "
                        "within this many units of 1 + (key px per offset px) (default 1.25, which "
                        "covers a correct pair; 0 disables it, about 3x faster)")
    v.add_argument("--warped", type=output_file(".png"), help="also write the warped offset image (PNG)")
    v.add_argument("--out", required=True, type=output_file(".pfm"), help="depth .pfm (key camera z; unknown stored as inf)")
    v.set_defaults(func=_model_based)

    v = add_verb(sp, "triangulate", "3-D points with uncertainty from correspondences",
                 epilog=TRIANGULATE_EPILOG)
    v.add_argument("correspondences", type=input_path,
                   help="tracks .json, or a matches text file with --rig")
    v.add_argument("--rig", type=input_path, help="rig.json for a two-view matches text file")
    v.add_argument("--method", choices=TRIANGULATION_METHODS.names, default="refined",
                   help="; ".join(f"{m.name}: {m.help}" for m in TRIANGULATION_METHODS.values()))
    v.add_argument("--pixel-sigma", type=positive,
                   help="pixel noise std for the covariance (default: the tracks file's, else 0.5)")
    v.add_argument("--min-angle", type=number(float, lo=ANGLE_RANGE_DEG[0], hi=ANGLE_RANGE_DEG[1]),
                   default=0.5, help="flag rays closer to parallel (deg)")
    v.add_argument("--out", required=True, type=output_file(".ply", ".json"), help="points .ply or .json")
    v.set_defaults(func=_triangulate)

    v = add_verb(sp, "sfm", "unordered multi-view reconstruction (pycolmap)",
                 epilog="Writes cameras.json, points.ply and COLMAP's text model (cameras.txt, "
                        "images.txt, points3D.txt) into --out.\n"
                        "Exit status 3 (nothing written), one line saying why: fewer than "
                        "--min-registered of the views registered (each view left out is named with "
                        "the verified matches it has); intrinsics estimated from two views only; "
                        "an estimated |k1| > 1 or a focal more than 30 %% off --focal-px (or the "
                        "EXIF focal); views too close together (median ray angle under 2 deg). "
                        "Views left out above --min-registered are listed in cameras.json "
                        "(registered: false), on stderr and in the .meta.json warnings.")
    v.add_argument("images", nargs="+", type=input_path, help="the views (one camera, one size)")
    v.add_argument("--camera", type=input_path,
                   help="camera.json (or a scene gt.json): known, fixed intrinsics")
    v.add_argument("--focal-px", type=positive,
                   help="without --camera: the focal length expected (px), COLMAP's start; "
                        "an estimate more than 30%% off it is refused (default: EXIF, if any)")
    v.add_argument("--poses", type=input_path,
                   help="cameras.json with known poses (views: image, cam_from_world): their centres "
                        "are position priors, and the model comes out in their frame and scale")
    v.add_argument("--pose-sigma", type=positive,
                   help="std of each known centre coordinate, in its unit (default 1%% of their spread)")
    v.add_argument("--seed", type=number(int, lo=0, hi=2**31 - 1), default=0,
                   help="COLMAP's random seed (default 0)")
    v.add_argument("--min-registered", type=number(float, lo=0, hi=1), default=0.5,
                   help="fraction of the views that must register for a usable result "
                        "(default 0.5; at least two views always)")
    v.add_argument("--out", required=True, type=output_dir,
                   help="folder for cameras.json, points.ply and the COLMAP text model")
    v.set_defaults(func=_sfm, arg_flags={"images": "IMAGES"})

    from lumigraph.stereo.debevec1996.cli import add_facade

    add_facade(sp)
    return p


def main(argv=None, prog: str = "lumigraph stereo") -> int:
    return run(build_parser(prog), argv)
