"""``lumigraph stereo facade``: Façade's photogrammetric modelling, file to file.

The verb group is added to ``lumigraph stereo`` by :func:`add_facade`;
``solve`` and ``automark`` live here. A FOLDER holds ``stack.json`` (naming
the photographs), ``blocks.json`` (:func:`~lumigraph.stereo.debevec1996.model.load_blocks`),
``edges.json`` (:func:`~lumigraph.stereo.debevec1996.edges.load_edges`) and
``camera.json`` (the photographs' shared intrinsics, or ``--camera``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lumigraph.capture.commandline import (
    add_verb,
    check_output_dir,
    check_planned,
    input_path,
    number,
    output_dir,
    output_file,
    say,
    warn,
)
from lumigraph.capture.errors import InputError

SOLVE_EPILOG = """\
FOLDER holds:
  stack.json    {"images": ["photo_00.png", ...]}: the photographs
  blocks.json   the block model and its starting values; at least one length fixed (the scale):
    {"blocks": [{"name": "house", "kind": "box",
                 "params": {"width": {"value": 10, "fixed": true}, "depth": 6, "height": 6}},
                {"name": "roof", "kind": "wedge", "parent": "house",
                 "params": {"width": {"same_as": "house/width"},
                            "depth": {"same_as": "house/depth"}, "height": 2.5}}]}
    kinds: box, wedge (gable roof, ridge along x), pyramid (width x, depth y, height z up),
    extrusion: a polygon extruded along "axis" z (footprint in x,y; up by height), y (profile in
    x,z; depth centred) or x (profile in y,z; width centred); each coordinate a number or a
    linear expression of the block's params, e.g. an L footprint:
      {"name": "hall", "kind": "extrusion", "axis": "z", "params": {"w": 8, "notch": 3, ...},
       "polygon": [[0, 0], ["w", 0], ["w", "notch"], [2, "notch"], [2, 5], [0, 5]]}
    (edges hall/bottom-<i>, hall/top-<i>: polygon edge i on each cap; hall/side-<i>);
    placement on the parent: "on": top (default) | base | offset (param offset_z),
    "x": centre | left | right | offset (offset_x), "y": centre | front | back | offset (offset_y)
    edges are named block/edge: house/top-front, house/front-left (vertical), roof/ridge,
    roof/rake-front-left, spire/hip-back-right, ... (front = -y, left = -x)
  edges.json    {"photographs": {"photo_00.png": [{"edge": "house/top-front",
                                                   "segment": [x0, y0, x1, y1]}, ...]}}
  camera.json   the photographs' intrinsics (one camera), unless --camera names another
(--blocks, --edges and --camera name other files than the folder's. To solve again after adding
marks, from where a solve ended: --blocks OUT/blocks.json --rough-poses OUT/model.json, and a
new --out.)
Writes into --out: model.json (every parameter's value and first-order std, every camera's
pose with std), blocks.json (the fitted model), model.obj and model.ply (the mesh),
cameras/<photo>.json (camera.json with cam_from_world), COLMAP's text model (cameras.txt,
images.txt, points3D.txt: the model's vertices) and overlay/<photo>.png (marked segments in
green, mis-marked ones in magenta, the marked edges reprojected in red, every other model edge
in blue, each mark's RMS distance in px).
A mark farther than 5x --noise-px from its reprojected edge is reported and left out; a
photograph with fewer than 3 marks is left out (warning). Marks that leave a parameter or a
pose unconstrained: exit 2 naming them, then per unknown the unmarked edges (photo edge) that
would constrain it, in the order to mark them (each the best with those before it marked).
Hand marks and automark's proposals ("proposed": true), 8 or more of each: each kind's endpoint
noise is estimated and each mark weighted by its kind's (printed; model.json sigma_px_by_kind);
the σ of every parameter follows from both. Marks that fit worse than --noise-px can explain
(beyond the χ² 0.1 % limit; each kind on its own) are said in a warning: some are off their
edges, and the σ do not cover that.
"""

AUTOMARK_EPILOG = """\
Solves from the marks already in FOLDER/edges.json (or --edges) (at least 4 per photograph work well),
detects line segments in each photograph (OpenCV's fast line detector), refines each to
sub-pixel precision and proposes those that match a reprojected model edge within
--max-angle degrees and --max-distance px, over at least half their length. Writes an
edges.json with the hand marks and the proposals ("proposed": true); run 'solve' on it.
What the marks leave free is tried from two starts (the rough model as given, and with those
parameters first set by the detected lines they explain); where the kept run's marks fit
worse than --noise-px explains, it runs once more from that run's solved values, and where
that run fits the noise (or rejects fewer hand marks, or holds fewer parameters) keeps, of
all the ends, one whose marks fit the noise before one with more proposals. Each start's end (hand marks rejected, parameters held, proposals, σ̂,
whether it fits the noise) is printed where more than one was tried, and recorded in the
output's meta ("starts").
"""


def add_facade(sp) -> None:
    """Add the ``facade`` verb group (``solve``, ``automark``) to
    ``lumigraph stereo``'s verbs ``sp``."""
    g = add_verb(sp, "facade", "Façade photogrammetric modelling: block model and cameras from "
                 "marked edges (Debevec, Taylor & Malik 1996)",
                 epilog="verbs: solve, automark, depth, render (see 'lumigraph stereo facade VERB "
                        "--help')")
    fs = g.add_subparsers(title="facade verbs", dest="facade_verb", metavar="VERB",
                          parser_class=type(g))
    fs.required = True

    v = add_verb(fs, "solve", "fit the block parameters and the camera poses to the marked edges",
                 epilog=SOLVE_EPILOG)
    v.add_argument("folder", type=input_path,
                   help="folder with stack.json, blocks.json, edges.json, camera.json")
    _common(v)
    v.add_argument("--free-focal", action="store_true",
                   help="also fit one focal-length scale shared by every photograph")
    v.add_argument("--no-robust", action="store_true",
                   help="skip the search for mis-marked edges (plain least squares)")
    v.add_argument("--out", required=True, type=output_dir,
                   help="folder for model.json, the mesh, the cameras and the overlays")
    v.set_defaults(func=_solve)

    v = add_verb(fs, "automark", "propose edge marks: detected line segments matched to the "
                 "reprojected model", epilog=AUTOMARK_EPILOG)
    v.add_argument("folder", type=input_path,
                   help="folder with stack.json, blocks.json, edges.json (a few hand marks), "
                        "camera.json")
    _common(v)
    v.add_argument("--max-angle", type=number(float, lo=0.1, hi=20), default=3.0,
                   help="largest angle between a detected segment and the reprojected edge "
                        "(degrees, default 3)")
    v.add_argument("--max-distance", type=number(float, lo=0.5, hi=100), default=6.0,
                   help="largest distance of a detected segment's ends from the reprojected "
                        "edge (px, default 6)")
    v.add_argument("--out", required=True, type=output_file(".json"),
                   help="the edges.json to write (hand marks and proposals)")
    v.set_defaults(func=_automark)

    from lumigraph.stereo.debevec1996.cli_vdtm import add_verbs  # depth, render (VDTM)

    add_verbs(fs)


def _common(v) -> None:
    v.add_argument("--blocks", type=input_path,
                   help="the block model and its starting values (default FOLDER/blocks.json): "
                        "another model of the same photographs, or an earlier solve's blocks.json")
    v.add_argument("--edges", type=input_path,
                   help="the marked edges (default FOLDER/edges.json; e.g. automark's output)")
    v.add_argument("--camera", type=input_path,
                   help="camera.json of the photographs (default FOLDER/camera.json)")
    v.add_argument("--rough-poses", type=input_path,
                   help="a JSON with \"cameras\": {photo: {\"R\": 3x3}}: rough rotations to "
                        "start from (default: from each photograph's vanishing directions); a "
                        "gt.json works, and so does an earlier solve's model.json, to solve "
                        "again from where it ended after adding marks")
    v.add_argument("--noise-px", type=number(float, lo=0.01, hi=100), default=1.0,
                   help="the marks' endpoint noise (px, default 1): the robust loss's scale")


# ----------------------------------------------------------------- loading
def _folder(args):
    """(folder, photos, images, model, marks path, K per photo, camera)."""
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.io import read_image, read_stack_json
    from lumigraph.stereo.debevec1996.model import load_blocks

    folder = Path(args.folder)
    if not folder.is_dir():
        raise InputError(folder, "expected a folder with stack.json, blocks.json, edges.json")
    sj = folder / "stack.json"
    if not sj.exists():
        raise InputError(folder, "folder has no stack.json naming the photographs")
    photos = list(read_stack_json(sj)["images"])
    images = {}
    for i, name in enumerate(photos):
        if not (folder / name).is_file():
            raise InputError(sj, f"key 'images[{i}]': {name} is not a file in {folder}")
        images[name] = read_image(folder / name)
    model = load_blocks(_blocks_path(args, folder))
    cam_path = Path(args.camera) if args.camera else folder / "camera.json"
    camera = Camera.load(cam_path)
    for name, img in images.items():
        if tuple(img.shape[1::-1]) != tuple(camera.image_size):
            raise InputError(folder / name, f"is {img.shape[1]}x{img.shape[0]}, the camera "
                                            f"({cam_path}) is {camera.image_size[0]}x"
                                            f"{camera.image_size[1]}")
    return folder, photos, images, model, camera, cam_path


def _blocks_path(args, folder):
    return Path(args.blocks) if args.blocks else folder / "blocks.json"


def _rough(args, photos):
    if not args.rough_poses:
        return None
    from lumigraph.capture.artifact import load_json_artifact
    from lumigraph.capture.schema import require, require_object

    path = args.rough_poses
    body = load_json_artifact(path, "rough poses")
    cams = require(body, "cameras", "object", path=path)
    out = {}
    for p in photos:
        if p in cams:
            require_object(cams[p], path=path, where=f"cameras.{p}", what="a pose (R)", keys=("R",))
            R = require(cams[p], "R", "matrix", shape=(3, 3), path=path, where=f"cameras.{p}")
            U, _, Vt = np.linalg.svd(R)
            out[p] = U @ Vt
    return out


def _undistorted(marks, camera):
    """Marks with endpoints undistorted (the solver is pinhole)."""
    from dataclasses import replace

    if not np.any(camera.dist):
        return marks
    out = []
    for m in marks.marks:
        ray = camera.unproject(m.segment.reshape(2, 2))
        uv = ray @ camera.K.T
        out.append(replace(m, segment=(uv[:, :2] / uv[:, 2:]).ravel()))
    return replace(marks, marks=tuple(out))


# ----------------------------------------------------------------- solve
def _solve(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.stereo.debevec1996.automark import refusal_lines, unconstrained_spots
    from lumigraph.stereo.debevec1996.edges import load_edges
    from lumigraph.stereo.debevec1996.outputs import planned_outputs, save_solution
    from lumigraph.stereo.debevec1996.solve import Unconstrained, check_solve_options, solve_facade

    check_solve_options(noise_px=args.noise_px, max_iterations=200)
    out = check_output_dir(args.out)
    folder, photos, images, model, camera, cam_path = _folder(args)
    check_planned([out / n for n in planned_outputs(photos)])
    sizes = {p: img.shape[1::-1] for p, img in images.items()}
    edges_path = Path(args.edges) if args.edges else folder / "edges.json"
    marks = load_edges(edges_path, model=model, photographs=photos, image_sizes=sizes)
    rough = _rough(args, photos)
    try:
        sol = solve_facade(model, _undistorted(marks, camera), {p: camera.K for p in photos},
                           rough_rotations=rough, free_focal=args.free_focal,
                           noise_px=args.noise_px, robust=not args.no_robust, where=str(edges_path))
    except Unconstrained as e:
        # after the one line, per refused unknown, the unmarked edges that
        # would constrain it, in the order to mark them (as the view's page)
        spots = unconstrained_spots(model, _undistorted(marks, camera), {p: camera.K for p in photos},
                                    sizes, e.unknowns, noise_px=args.noise_px, where=str(edges_path))
        raise Unconstrained(e.where, e.unknowns, details=refusal_lines(spots),
                            at_solution=e.at_solution) from None
    for w in sol.warnings:
        warn(w)
    meta = make_meta("lumigraph.facade.model",
                     inputs=[folder / "stack.json", _blocks_path(args, folder), edges_path, cam_path,
                             *[folder / p for p in photos]]
                     + ([args.rough_poses] if args.rough_poses else []),
                     params={"noise_px": args.noise_px, "free_focal": args.free_focal,
                             "robust": not args.no_robust},
                     quality={"rms_px": sol.rms_px, "sigma_px": sol.sigma_px,
                              "sigma_px_by_kind": dict(sol.sigma_px_by_kind) or None,
                              "outliers": len(sol.outliers), "dropped": sol.dropped},
                     timings_s={"solve": sol.seconds}, warnings=sol.warnings)
    save_solution(out, sol, photos, images, marks, camera, meta=meta)
    kinds = sol.sigma_px_by_kind
    noise = (f"; endpoint noise hand {kinds['hand']:.2f} px, proposed {kinds['proposed']:.2f} px"
             if kinds else "")
    say(args, f"{len(sol.poses)} photographs, {len(sol.mark_rms_px)} marks, RMS {sol.rms_px:.3f} "
              f"px{noise} -> {out}/model.json, model.obj, model.ply, cameras/, overlay/")
    return 0


# ----------------------------------------------------------------- automark
def _automark(args) -> int:
    from lumigraph.capture.artifact import make_meta, save_json_artifact
    from lumigraph.stereo.debevec1996.automark import automark, check_automark_options
    from lumigraph.stereo.debevec1996.edges import load_edges

    check_automark_options(max_angle_deg=args.max_angle, max_distance_px=args.max_distance)
    folder, photos, images, model, camera, cam_path = _folder(args)
    edges_path = Path(args.edges) if args.edges else folder / "edges.json"
    if os.path.abspath(args.out) == os.path.abspath(edges_path):
        raise InputError(args.out, f"would replace the input {edges_path}; write the "
                                     "proposals to another file")
    sizes = {p: img.shape[1::-1] for p, img in images.items()}
    marks = load_edges(edges_path, model=model, photographs=photos, image_sizes=sizes)
    if np.any(camera.dist):
        raise InputError(cam_path, "automatic marking needs undistorted photographs "
                                   "('lumigraph calib undistort' them first)")
    res = automark(model, _undistorted(marks, camera), images, {p: camera.K for p in photos},
                   rough_rotations=_rough(args, photos), noise_px=args.noise_px,
                   max_angle_deg=args.max_angle, max_distance_px=args.max_distance,
                   where=str(edges_path))
    for w in res.warnings:
        warn(w)
    meta = make_meta("lumigraph.facade.edges",
                     inputs=[folder / "stack.json", _blocks_path(args, folder), edges_path, cam_path,
                             *[folder / p for p in photos]],
                     params={"max_angle_deg": args.max_angle, "max_distance_px": args.max_distance,
                             "noise_px": args.noise_px},
                     quality={"proposed": res.proposed, "hand": len(marks.marks),
                              "starts": res.candidates},
                     warnings=res.warnings)
    save_json_artifact(args.out, res.marks.to_dict(), meta=meta)
    if len(res.candidates) > 1:
        say(args, "starts: " + "; ".join(
            f"{c['start']} ({c['hand_marks_rejected']} hand marks rejected, {c['held']} held, "
            f"{c['proposed']} proposed, σ̂ {c['sigma_px']:.2f} px"
            + ("" if c["fits_noise"] else ", beyond the noise given")
            + ("" if c.get("hand_marks_fit_noise", True) else ", hand marks beyond their noise")
            + ")"
            + (" <- kept" if c["chosen"] else "")
            for c in res.candidates))
    say(args, f"{len(marks.marks)} hand marks, {res.proposed} proposed -> {args.out}")
    return 0
