"""``lumigraph calib``: calibrate, undistort, stereo, rectify.

A thin layer: parse, load images, call :mod:`lumigraph.calib.calibrate` /
:mod:`lumigraph.calib.undistort` / :mod:`lumigraph.calib.rectify`, save artifacts
atomically with their ``.meta.json`` sidecars. Every input is checked before
anything is written, so a bad input leaves no output behind. Options are
checked by the library (early, by its ``check_*`` functions, where images would
be read first); the command line keeps only what concerns the files: folders
and stack.json, one image size per camera, images against the camera or rig
file, and the board found in at least one image.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from lumigraph.calib.rectify import ALPHA_RANGE
from lumigraph.calib.zhang2000 import MODELS
from lumigraph.capture.commandline import (
    BATCH_HELP,
    add_batch_options,
    add_verb,
    batch_requested,
    check_output_dir,
    check_output_path,
    check_planned,
    input_path,
    make_parser,
    number,
    output_dir,
    output_file,
    progress,
    run,
    say,
    subparsers,
    warn,
)
from lumigraph.capture.device import add_device_option, resolve_device
from lumigraph.capture.errors import InputError
from lumigraph.capture.tiles import add_tile_options

MODEL_CHOICES = ("auto", *MODELS)  # the models calibrate() accepts

EPILOG = """\
examples:
  lumigraph calib calibrate shots/*.png --board checker:10x7:25 --out camera.json
  lumigraph calib calibrate out/scenes/boards --out camera.json   (board from stack.json)
  lumigraph calib undistort --camera camera.json shots/*.png --out undistorted/
  lumigraph calib stereo --left L*.jpg --right R*.jpg --board checker:10x7:1 --out rig.json
  lumigraph calib rectify --rig rig.json left.png right.png --out rectified/

Boards: checker:COLSxROWS:SQUARE or charuco:COLSxROWS:SQUARE:MARKER:DICT, where
COLS x ROWS counts SQUARES (OpenCV's 9x6-corner pattern is checker:10x7:...) and
SQUARE is in any length unit (it becomes the unit of translations).
--model auto (default) fits none, k1, k1k2, k1k2p1p2, k1k2p1p2k3 and rational and
keeps the simplest whose held-out (leave-views-out) error is not significantly
worse than the best; every candidate's score is in camera.json.
"""


def board_spec(text: str):
    """``--board`` text -> a :class:`~lumigraph.calib.detect.BoardSpec`,
    by the board's own parser (an argparse ``type``)."""
    from lumigraph.calib.detect import BoardSpec

    try:
        return BoardSpec.parse(text)
    except InputError as e:
        raise argparse.ArgumentTypeError(e.problem) from None


board_spec.range_text = "checker:COLSxROWS:SQUARE or charuco:COLSxROWS:SQUARE:MARKER:DICT"


def _expand(inputs: list[str], where: str) -> tuple[list[Path], dict]:
    """Image files from a list, or from a folder's stack.json (with its extra info)."""
    if not inputs:
        raise InputError(where, "no input images given")
    paths = [Path(p) for p in inputs]
    if len(paths) == 1 and (paths[0].is_dir() or paths[0].name == "stack.json"):
        folder = paths[0] if paths[0].is_dir() else paths[0].parent
        sj = folder / "stack.json"
        if not sj.is_file():
            raise InputError(folder, "folder has no stack.json; pass the image files instead")
        from lumigraph.capture.io import read_stack_json

        info = read_stack_json(sj)
        # where a bad board in it is reported
        return [folder / n for n in info["images"]], {**info, "_stack": str(sj)}
    for p in paths:
        if not p.is_file():
            raise InputError(p, "file not found")
    return paths, {}


def _read_all(paths: list[Path], args, what: str):
    from lumigraph.capture.io import read_image

    images = []
    for p in progress(paths, total=len(paths), description=f"reading {what}", quiet=args.quiet):
        images.append(read_image(p))
    return images


def _check_sizes(paths, images):
    first = images[0].shape[1::-1]
    for p, im in zip(paths, images, strict=True):
        if im.shape[1::-1] != first:
            raise InputError(p, f"is {im.shape[1]}x{im.shape[0]} but {paths[0].name} is "
                                f"{first[0]}x{first[1]}; calibrate one image size at a time")
    return tuple(int(v) for v in first)


def _board(args, info):
    from lumigraph.calib.detect import BoardSpec

    if args.board is not None:
        return args.board
    if not info.get("board"):
        raise InputError("board", "missing; give e.g. --board checker:10x7:25 (COLSxROWS squares)")
    return BoardSpec.parse(str(info["board"]), where=info.get("_stack", "board"))


def _detect_all(paths, images, board, args, what="images"):
    from lumigraph.calib.detect import detect

    dets = []
    for im in progress(images, total=len(images), description=f"finding {board.kind} corners in {what}",
                       quiet=args.quiet):
        dets.append(detect(im, board))
    found = sum(len(d) > 0 for d in dets)
    if found == 0:
        hint = (f"is the board {board.cols}x{board.rows} squares "
                f"({board.cols - 1}x{board.rows - 1} inner corners)? COLSxROWS counts squares")
        raise InputError(paths[0].parent if len(paths) > 1 else paths[0],
                         f"no {board.spec} board found in any of the {len(paths)} {what}; {hint}")
    for p, d in zip(paths, dets, strict=True):
        if len(d) == 0:
            warn(f"{p}: no board found; skipped")
    return dets


def _exports(args, camera=None, rig=None):
    from lumigraph.calib.export import colmap_cameras, opencv_yaml
    from lumigraph.capture.artifact import atomic_path

    if args.yaml:
        with atomic_path(args.yaml) as tmp:
            tmp.write_text(opencv_yaml(camera or rig.left, rig=rig))
    if args.colmap:
        with atomic_path(args.colmap) as tmp:
            tmp.write_text(colmap_cameras([camera] if rig is None else [rig.left, rig.right]))


def _calibrate(args) -> int:
    from lumigraph.calib.calibrate import calibrate
    from lumigraph.capture.artifact import make_meta

    out = check_output_path(args.out, suffixes=(".json",))
    paths, info = _expand(args.images, "IMAGES")
    board = _board(args, info)
    t0 = time.perf_counter()
    images = _read_all(paths, args, "images")
    _check_sizes(paths, images)
    t1 = time.perf_counter()
    dets = _detect_all(paths, images, board, args)
    t2 = time.perf_counter()
    cam = calibrate(dets, model=args.model, names=[p.name for p in paths], strict=args.strict)
    t3 = time.perf_counter()
    extra = dict(cam.extra, board=board.to_dict(),
                 units=f"translations in the board's square unit (square = {board.square:g})")
    cam = type(cam)(cam.K, cam.dist, cam.image_size, cam.model, extra)
    for w in cam.extra["warnings"]:
        warn(w)
    meta = make_meta("lumigraph.camera", inputs=paths,
                     params={"board": board.spec, "model": args.model, "strict": args.strict},
                     model=cam.extra["model_selection"] | {"candidates": cam.extra["candidates"]},
                     quality={"rms_px": cam.extra["rms_px"], "n_views": sum(v["used"] for v in cam.extra["views"]),
                              "n_points": cam.extra["n_points"]},
                     timings_s={"read": t1 - t0, "detect": t2 - t1, "calibrate": t3 - t2},
                     warnings=cam.extra["warnings"])
    cam.save(out, meta=meta)
    _exports(args, camera=cam)
    fx, fy = cam.focal_px
    say(args, f"{out}: model {cam.model}, RMS {cam.extra['rms_px']:.3f} px, fx {fx:.2f} fy {fy:.2f} "
              f"cx {cam.K[0, 2]:.2f} cy {cam.K[1, 2]:.2f}")
    return 0


def _write_undistorted(u, path: Path, im, target: Path, *, device=None) -> None:
    """One undistorted image, written to ``target`` (16-bit codes keep their
    significant bits)."""
    from lumigraph.capture.io import write_image

    bd = None
    if im.dtype.kind == "u" and im.dtype.itemsize == 2:
        from lumigraph.capture.io import png_significant_bits
        bd = png_significant_bits(path) if path.suffix.lower() == ".png" else 16
    write_image(target, u.apply(im) if device is None else u.apply(im, device=device), bit_depth=bd)


def undistort_image(*, image: str, camera: str, out: str, keep_all: bool = False) -> None:
    """One image of ``calib undistort`` as a batch item (:mod:`lumigraph.capture.batch`):
    the same undistorter and writer as the command's loop, the image written
    atomically to ``out`` with its sidecar."""
    from lumigraph.calib.undistort import undistorter
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.io import read_image

    cam = Camera.load(camera)
    p = Path(image)
    im = read_image(p)
    if im.shape[1::-1] != tuple(cam.image_size):
        raise InputError(p, f"is {im.shape[1]}x{im.shape[0]} but {camera} was calibrated for "
                            f"{cam.image_size[0]}x{cam.image_size[1]}; use that camera's images")
    u = undistorter(cam, keep_all=keep_all)
    write_artifact(out, lambda tmp: _write_undistorted(u, p, im, tmp),
                   meta=make_meta("lumigraph.undistorted_image", inputs=[camera, image],
                                  params={"keep_all": keep_all}))


def _undistort_batch(args, cam, paths: list[Path], names: list[str]) -> int:
    """``calib undistort`` on a Dask cluster: each image one item."""
    from lumigraph.calib.undistort import undistorter
    from lumigraph.capture.artifact import make_meta, write_json
    from lumigraph.capture.batch import Item, report, run_batch

    out = Path(args.out)
    items = [Item(Path(name).stem, inputs=(str(p), str(args.camera)), outputs=(str(out / name),),
                  func="lumigraph.calib.cli:undistort_image",
                  kwargs={"image": str(p), "camera": str(args.camera), "out": str(out / name),
                          "keep_all": bool(args.keep_all)}) for p, name in zip(paths, names, strict=True)]
    result = run_batch(items, out_dir=out, workers=args.workers, scheduler=args.scheduler,
                       quiet=args.quiet, description="undistorting")
    u = undistorter(cam, keep_all=args.keep_all)
    u.camera.save(out / "camera.json", meta=make_meta("lumigraph.camera",
                                                      inputs=[Path(args.camera), *paths],
                                                      params={"keep_all": args.keep_all}))
    write_json(out / "undistorted.json", {"schema": "lumigraph.undistorted", "schema_version": 1,
                                          "images": names, "camera": "camera.json"})
    return report(result, quiet=args.quiet)


def _undistort(args) -> int:
    from lumigraph.calib.undistort import undistorter
    from lumigraph.capture.artifact import atomic_path, make_meta, write_json
    from lumigraph.capture.camera import Camera

    out = check_output_dir(args.out)
    cam = Camera.load(args.camera)
    paths, _ = _expand(args.images, "IMAGES")
    names = [p.stem + ".png" for p in paths]
    for k, (p, name) in enumerate(zip(paths, names, strict=True)):
        if name in names[:k]:
            raise InputError(p, f"would be written as {out / name}, like "
                                f"{paths[names.index(name)]}; rename one")
    # none of the folder's files may replace a photograph (--out = the input folder)
    check_planned([out / n for n in (*names, "camera.json", "undistorted.json")])
    device = resolve_device(args.device)  # before any image is read: a missing GPU is exit 2
    if batch_requested(args):
        return _undistort_batch(args, cam, paths, names)
    u = undistorter(cam, keep_all=args.keep_all)
    plan = _undistort_plan(args, u)
    whole = [] if plan.rows is not None else paths  # by rows: _undistort_by_rows reads them
    images = _read_all(whole, args, "images")
    for p, im in zip(whole, images, strict=True):
        if im.shape[1::-1] != tuple(cam.image_size):
            raise InputError(p, f"is {im.shape[1]}x{im.shape[0]} but {args.camera} was calibrated for "
                                f"{cam.image_size[0]}x{cam.image_size[1]}; use that camera's images")
    out.mkdir(parents=True, exist_ok=True)
    if plan.rows is not None:
        _undistort_by_rows(args, u, paths, names, out, plan)
    for p, im, name in progress(list(zip(whole, images, names[:len(whole)], strict=True)),
                                total=len(whole),
                                description="undistorting", quiet=args.quiet):
        with atomic_path(out / name) as tmp:
            _write_undistorted(u, p, im, tmp, device=device)
    meta = make_meta("lumigraph.camera", inputs=[Path(args.camera), *paths],
                     params={"keep_all": args.keep_all, "device": device.name},
                     extra={"tiles": plan.as_meta(cam.image_size[1])})
    u.camera.save(out / "camera.json", meta=meta)
    write_json(out / "undistorted.json", {"schema": "lumigraph.undistorted", "schema_version": 1,
                                          "images": names, "camera": "camera.json"})
    say(args, f"{out}: {len(names)} undistorted image(s) and camera.json (no distortion)")
    return 0


def _undistort_plan(args, u):
    """Whole or by bands (``--tile``, ``--memory``): the working set per pixel
    is the source rows, the float64 map of the band and its output; the halo
    is how far the lens moves a row (the map's largest vertical shift)."""
    import numpy as np

    from lumigraph.capture.tiles import plan_rows

    w, h = u.camera.image_size
    # the largest vertical shift, on every 64th row (it varies smoothly): memory only
    shift = max(float(np.nanmax(np.abs(u.map_rows(y, y + 1)[1] - y), initial=0.0))
                for y in sorted({*range(0, h, max(1, h // 64)), h - 1}))
    return plan_rows(args.tile, args.memory, width=w, height=h, bytes_per_pixel=96 + 2 * 8,
                     halo=int(np.ceil(shift)) + 2)


def _undistort_by_rows(args, u, paths, names, out, plan) -> None:
    """Each image read (TIFF, OpenEXR) and written (PNG) by bands of rows: the
    pixels :meth:`Undistortion.apply` gives whole."""
    from lumigraph.capture.artifact import atomic_path
    from lumigraph.capture.io import png_significant_bits
    from lumigraph.capture.tiles import PngRowWriter, bands, open_rows

    w, h = u.camera.image_size
    for p, name in progress(list(zip(paths, names, strict=True)), total=len(paths),
                            description="undistorting", quiet=args.quiet):
        src = open_rows(p)
        try:
            if src.shape[1::-1] != (w, h):
                raise InputError(p, f"is {src.shape[1]}x{src.shape[0]} but {args.camera} was "
                                    f"calibrated for {w}x{h}; use that camera's images")
            if src.dtype.kind != "u":
                raise InputError(p, "undistort by rows writes PNG codes: give 8/16-bit images")
            bd = None
            if src.dtype.itemsize == 2:
                bd = png_significant_bits(p) if p.suffix.lower() == ".png" else 16
            with atomic_path(out / name) as tmp:
                wr = PngRowWriter(tmp, w, h, src.shape[2], src.dtype, bit_depth=bd)
                try:
                    for b in bands(h, plan.rows):
                        wr.write(u.apply_rows(src.read, b.y0, b.y1))
                finally:
                    wr.close()
        finally:
            src.close()


def _stereo(args) -> int:
    from lumigraph.calib.calibrate import calibrate_stereo, check_stereo_pairs
    from lumigraph.capture.artifact import make_meta

    out = check_output_path(args.out, suffixes=(".json",))
    lp, linfo = _expand(args.left, "left")
    rp, _ = _expand(args.right, "right")
    check_stereo_pairs(lp, rp)  # the library's rule, before any image is read
    board = _board(args, linfo)
    li = _read_all(lp, args, "left images")
    ri = _read_all(rp, args, "right images")
    lsize = _check_sizes(lp, li)
    rsize = _check_sizes(rp, ri)
    if lsize != rsize:
        raise InputError(rp[0], f"is {rsize[0]}x{rsize[1]} but the left images are {lsize[0]}x{lsize[1]}")
    t0 = time.perf_counter()
    ld = _detect_all(lp, li, board, args, "left images")
    rd = _detect_all(rp, ri, board, args, "right images")
    rig = calibrate_stereo(ld, rd, model=args.model, names=[f"{a.name}|{b.name}" for a, b in zip(lp, rp, strict=True)],
                           strict=args.strict)
    t1 = time.perf_counter()
    for w in rig.extra["warnings"]:
        warn(w)
    rig = type(rig)(rig.left, rig.right, rig.R, rig.T, rig.E, rig.F,
                    dict(rig.extra, board=board.to_dict(),
                         units=f"T in the board's square unit (square = {board.square:g})"))
    meta = make_meta("lumigraph.rig", inputs=[*lp, *rp], params={"board": board.spec, "model": args.model},
                     model={"left": rig.left.model, "right": rig.right.model},
                     quality={"rms_px": rig.extra["rms_px"], "baseline": rig.baseline,
                              "rms_px_left": rig.left.extra["rms_px"], "rms_px_right": rig.right.extra["rms_px"]},
                     timings_s={"detect_and_calibrate": t1 - t0}, warnings=rig.extra["warnings"])
    rig.save(out, meta=meta)
    _exports(args, rig=rig)
    say(args, f"{out}: stereo RMS {rig.extra['rms_px']:.3f} px, baseline {rig.baseline:.4g} "
              f"(board units), {rig.extra['n_pairs']} pairs")
    return 0


RECTIFY_FILES = ("left.png", "right.png", "maps_left.npy", "maps_right.npy",
                 "rectification.json")


def _rectify(args) -> int:
    from lumigraph.calib.rectify import check_rectify_options, rectify
    from lumigraph.capture.artifact import atomic_path, make_meta
    from lumigraph.capture.io import read_image, write_image
    from lumigraph.capture.rig import Rig

    out = check_output_dir(args.out)
    check_rectify_options(alpha=args.alpha)  # the library's rule, before the rig and images load
    if Path(args.left).resolve() == Path(args.right).resolve():
        raise InputError(args.right, "is also the left image; give the right camera's image")
    check_planned([out / n for n in RECTIFY_FILES])
    device = resolve_device(args.device)  # before any file is read: a missing GPU is exit 2
    rig = Rig.load(args.rig)
    left, right = read_image(args.left), read_image(args.right)
    for p, im, cam in ((args.left, left, rig.left), (args.right, right, rig.right)):
        if im.shape[1::-1] != tuple(cam.image_size):
            raise InputError(p, f"is {im.shape[1]}x{im.shape[0]} but the rig's camera is "
                                f"{cam.image_size[0]}x{cam.image_size[1]}")
    try:
        rect = rectify(rig, alpha=args.alpha)
    except InputError:
        raise
    except ValueError as e:  # the rig itself cannot be rectified
        raise InputError(args.rig, str(e)) from None
    lr, rr = rect.apply(left, right, device=device)
    lx, ly, rx, ry = rect.maps()
    out.mkdir(parents=True, exist_ok=True)
    import numpy as np

    for name, im in (("left.png", lr), ("right.png", rr)):
        with atomic_path(out / name) as tmp:
            write_image(tmp, im)
    for name, m in (("maps_left.npy", np.stack([lx, ly], axis=-1)), ("maps_right.npy", np.stack([rx, ry], axis=-1))):
        with atomic_path(out / name) as tmp:
            np.save(tmp, m, allow_pickle=False)
    meta = make_meta("lumigraph.rectification", inputs=[Path(args.rig), Path(args.left), Path(args.right)],
                     params={"alpha": args.alpha, "device": device.name},
                     quality={"focal_px": rect.focal_px, "baseline": rect.baseline})
    rect.save(out / "rectification.json", meta=meta)
    say(args, f"{out}: rectified left.png/right.png, maps_*.npy ((H, W, 2) float32 source x, y), "
              f"rectification.json (f = {rect.focal_px:.2f} px, B = {rect.baseline:.4g})")
    return 0


def build_parser(prog: str = "lumigraph calib"):
    p = make_parser(prog, "Camera calibration, stereo rigs, undistortion and rectification.", epilog=EPILOG)
    sp = subparsers(p)

    c = add_verb(sp, "calibrate", "calibrate one camera from photos of a board",
                 epilog="example:\n  lumigraph calib calibrate shots/*.png --board checker:10x7:25 --out camera.json")
    c.add_argument("images", nargs="+", type=input_path, help="image files, or a folder with stack.json")
    c.add_argument("--board", type=board_spec, help="checker:COLSxROWS:SQUARE or charuco:COLSxROWS:SQUARE:MARKER:DICT "
                                   "(COLSxROWS = squares); default: the stack.json 'board'")
    c.add_argument("--model", default="auto", choices=MODEL_CHOICES, help="distortion model (default auto)")
    c.add_argument("--strict", action="store_true", help="refuse (exit 2) instead of warning on a degenerate view set")
    c.add_argument("--yaml", type=output_file(".yml", ".yaml"), help="also write an OpenCV FileStorage YAML file")
    c.add_argument("--colmap", type=output_file(".txt"), help="also write a COLMAP cameras.txt")
    c.add_argument("--out", required=True, type=output_file(".json"), help="camera.json to write")
    c.set_defaults(func=_calibrate)

    u = add_verb(sp, "undistort", "remove lens distortion from images",
                 epilog="examples:\n  lumigraph calib undistort --camera camera.json shots/*.png --out undistorted/\n"
                        "  lumigraph calib undistort --camera camera.json shots/ --out undistorted/ --workers 2\n"
                        "(with --workers or --scheduler each image is one batch item, written with its "
                        "sidecar, and the folder gets index.json)\n\n" + BATCH_HELP)
    u.add_argument("images", nargs="+", type=input_path, help="image files, or a folder with stack.json")
    u.add_argument("--camera", required=True, type=input_path, help="camera.json of the camera that took the images")
    u.add_argument("--keep-all", action="store_true", help="keep every source pixel (black corners) "
                                                            "instead of cropping to valid pixels")
    u.add_argument("--out", required=True, type=output_dir, help="output folder (undistorted PNGs + camera.json)")
    add_device_option(u)
    add_tile_options(u, "each image", "PNG")
    add_batch_options(u)
    u.set_defaults(func=_undistort)

    s = add_verb(sp, "stereo", "calibrate a stereo rig from simultaneous board photos",
                 epilog="example:\n  lumigraph calib stereo --left L*.jpg --right R*.jpg --board checker:10x7:1 --out rig.json")
    s.add_argument("--left", nargs="+", action="extend", required=True, type=input_path,
                   help="left images (pairwise with --right)")
    s.add_argument("--right", nargs="+", action="extend", required=True, type=input_path,
                   help="right images")
    s.add_argument("--board", type=board_spec, help="board spec (see calibrate)")
    s.add_argument("--model", default="auto", choices=MODEL_CHOICES, help="distortion model of both cameras")
    s.add_argument("--strict", action="store_true", help="refuse instead of warning on degenerate views")
    s.add_argument("--yaml", type=output_file(".yml", ".yaml"), help="also write OpenCV YAML (K1 D1 K2 D2 R T E F)")
    s.add_argument("--colmap", type=output_file(".txt"), help="also write a COLMAP cameras.txt (camera 1 left, 2 right)")
    s.add_argument("--out", required=True, type=output_file(".json"), help="rig.json to write")
    s.set_defaults(func=_stereo)

    r = add_verb(sp, "rectify", "rectify a stereo pair so epipolar lines are rows",
                 epilog="example:\n  lumigraph calib rectify --rig rig.json left.png right.png --out rectified/")
    r.add_argument("left", type=input_path, help="left image")
    r.add_argument("right", type=input_path, help="right image")
    r.add_argument("--rig", required=True, type=input_path, help="rig.json")
    r.add_argument("--alpha", type=number(float, lo=ALPHA_RANGE[0], hi=ALPHA_RANGE[1]), default=0.0,
                   help="0 crops to valid pixels (default), 1 keeps all")
    r.add_argument("--out", required=True, type=output_dir, help="output folder: left.png, right.png, maps_left/right.npy, "
                                                "rectification.json")
    add_device_option(r)
    r.set_defaults(func=_rectify)
    return p


def main(argv=None, prog: str = "lumigraph calib") -> int:
    return run(build_parser(prog), argv)
