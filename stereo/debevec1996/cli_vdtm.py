"""``lumigraph stereo facade depth`` and ``… render``: a block model's depth
from a camera (the rough model of ``stereo model-based``) and view-dependent
texture mapping. Added to the ``facade`` verb group by :func:`add_verbs`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from lumigraph.capture.commandline import (
    add_verb,
    check_planned,
    input_path,
    number,
    output_file,
    output_file_or_dir,
    progress,
    say,
    warn,
)
from lumigraph.capture.errors import InputError

DEPTH_EPILOG = """\
--model is a blocks.json (the starting model, or the fitted one a solve writes) or a solve's
model.json (its values applied to the blocks.json beside it). --camera is a camera.json with
its pose, "cam_from_world": {"R": 3x3, "t": [3]} (x_cam = R x_world + t): a solve's
cameras/<photo>.json, or a rendered facade's cameras/ or novel/ file. The depth is the camera
z of the model (the model's unit), exact per pixel centre; no model = inf in the PFM, NaN in
a .npy. It is what 'lumigraph stereo model-based --model' takes.
"""

RENDER_EPILOG = """\
Renders the model from --view, each pixel textured from the photographs that see its surface
point (visibility by each photograph's depth of the model, --tolerance), weighted by
(angle between the new and the photograph's viewing rays)^-power over the --neighbours
nearest, tapered to 0 at the next (--method blend; Debevec, Taylor & Malik 1996; the taper of
Buehler et al. 2001), or the same weights among at most three photographs per plane of the
model, the three the blend weights most over it, projected onto the plane by homographies with
each photograph's visibility of each plane computed once (--method view-map; Debevec, Yu &
Borshukov 1998).
Model pixels no photograph sees are filled from their neighbours; pixels off the model are 0.
Where one photograph alone sees a point, its colour is that photograph's from every view:
highlights and reflections there cannot follow the new view. Each view's line gives that
share of its model pixels (both methods; the view map's visibility of a plane is a little
stricter, so its share is a little larger), the meta keeps it, and past a fifth of the view a
warning says so; a photograph of those surfaces from a second place is the remedy.
--photos names a folder with stack.json; each photograph's pose comes from --cameras DIR
(<stem>.json per photograph, default FOLDER/cameras) or, with a model.json, from its
"cameras". 8-bit/16-bit photographs give a PNG or EXR of code values; EXR photographs
(linear radiance) stay linear: write .exr.

Several views (--view A.json B.json ..., --view given more than once, or a folder of
camera.json files, taken in name order) render in one call: the photographs' depth maps and
visibility (and, for view-map, the polygons' view maps) are prepared once and shared, which
is most of a small view's cost. --out is then a folder: <view name>.png per view (.exr
when the photographs are linear radiance), each with its .meta.json, and index.json listing
them:

  lumigraph stereo facade render --model solve/model.json --photos photos \\
      --view photos/novel --method view-map --out renders/

--reflection (blend only) first fits a reflection layer: per orientation of the model's
planes, the part of the colour that moves with the view as a reflection of a far environment
(or a highlight under a far light) does, a function of the mirror direction estimated from the
differences between the photographs at each point, and moves each photograph's sample to the
new view with it before blending. Each orientation keeps the plain blend unless the layer
predicts each photograph, left out in turn, clearly better; the choice is printed. On a plane
of two materials (glass in brick) the layer is switched off where it explains the photographs'
differences worse than no layer (the share is printed). It suits
glossy facades and windows reflecting the sky; it costs a fit (seconds to a minute) shared by
every view:

  lumigraph stereo facade render --model solve/model.json --photos photos \\
      --view photos/novel --reflection --out renders/
"""


def add_verbs(fs) -> None:
    """Add ``depth`` and ``render`` to the ``facade`` verbs ``fs``."""
    v = add_verb(fs, "depth", "the block model's depth map from a camera (the rough model for "
                 "'stereo model-based')", epilog=DEPTH_EPILOG)
    v.add_argument("--model", required=True, type=input_path,
                   help="blocks.json, or a solve's model.json (with blocks.json beside it)")
    v.add_argument("--camera", required=True, type=input_path,
                   help="camera.json with cam_from_world (the pose)")
    v.add_argument("--out", required=True, type=output_file(".pfm", ".npy"),
                   help="depth .pfm (inf = no model) or .npy (NaN = no model)")
    v.add_argument("--std-out", type=output_file(".pfm", ".npy"),
                   help="also the depth's standard deviation from the fitted parameters' "
                        "covariance (--model must be a solve's model.json): what 'stereo "
                        "model-based --model-std' takes; inf where a model edge may cross the pixel")
    v.set_defaults(func=_depth)

    v = add_verb(fs, "pair", "the rig.json of two posed cameras (key = left, offset = right), "
                 "for 'stereo model-based --rig'",
                 epilog="Each camera is a camera.json with cam_from_world (a solve's "
                        "cameras/<photo>.json): the rig's R, T are the offset camera's pose "
                        "relative to the key camera's, x_offset = R x_key + T.")
    v.add_argument("--key", required=True, type=input_path, help="the key camera (posed camera.json)")
    v.add_argument("--offset", required=True, type=input_path,
                   help="the offset camera (posed camera.json)")
    v.add_argument("--out", required=True, type=output_file(".json"), help="rig.json")
    v.set_defaults(func=_pair)

    v = add_verb(fs, "render", "view-dependent texture mapping: the model seen from a new camera, "
                 "textured from the photographs", epilog=RENDER_EPILOG)
    v.add_argument("--model", required=True, type=input_path,
                   help="blocks.json, or a solve's model.json (with blocks.json beside it)")
    v.add_argument("--photos", required=True, type=input_path,
                   help="folder with stack.json naming the photographs")
    v.add_argument("--cameras", type=input_path,
                   help="folder of <photo stem>.json posed cameras (default FOLDER/cameras, or "
                        "the cameras of a model.json)")
    v.add_argument("--view", required=True, type=input_path, nargs="+", action="extend",
                   help="camera.json with cam_from_world: the new viewpoint; several, or a "
                        "folder of them, render in one call (--out a folder)")
    v.add_argument("--method", choices=("blend", "view-map"), default="blend",
                   help="blend: every photograph, per-pixel angle weights (default); view-map: "
                        "at most three per plane, projective texture mapping (faster)")
    v.add_argument("--reflection", action="store_true",
                   help="blend only: fit a reflection layer at infinity per plane orientation from "
                        "the photographs (glossy surfaces reflecting a far environment) and move "
                        "each photograph's sample to the new view with it; each orientation keeps "
                        "the plain blend unless the layer predicts held-out photographs clearly "
                        "better (the choice is printed and kept in the meta)")
    v.add_argument("--tolerance", type=number(float, lo=0, lo_open=True, hi=1), default=0.01,
                   help="visibility: relative depth difference still on the same surface "
                        "(default 0.01)")
    v.add_argument("--power", type=number(float, lo=0, lo_open=True, hi=64), default=None,
                   help="weights fall as angle^-power (default: the library's, 1 = the paper's)")
    v.add_argument("--neighbours", type=number(int, lo=0, hi=64), default=None,
                   help="only the N nearest photographs by angle blend, each weight tapered to 0 "
                        "at the next nearest (default: the library's, 2); 0 = every photograph "
                        "that sees the point")
    v.add_argument("--out", required=True, type=output_file_or_dir(".png", ".exr"),
                   help="the rendered view (.png, or .exr to keep linear values); for several "
                        "views a folder (NAME.png or .exr per view, and index.json)")
    v.set_defaults(func=_render)


def _depth(args) -> int:
    from lumigraph.capture.artifact import make_meta, write_artifact
    from lumigraph.capture.io import write_pfm
    from lumigraph.stereo.debevec1996.raster import model_depth, model_depth_sigma
    from lumigraph.stereo.debevec1996.vdtm import (
        load_fitted_model,
        load_model_mesh,
        load_posed_camera,
    )

    mesh, _ = load_model_mesh(args.model)
    cam, R, t = load_posed_camera(args.camera)
    fitted = load_fitted_model(args.model) if args.std_out else None
    t0 = time.perf_counter()
    z = model_depth(mesh, cam.K, R, t, cam.image_size, dist=cam.dist)
    dt = time.perf_counter() - t0
    out = Path(args.out)
    if fitted is not None:
        model, values, cov = fitted
        sd = model_depth_sigma(model, values, cov, cam.K, R, t, cam.image_size, dist=cam.dist)
        sout = Path(args.std_out)
        smeta = make_meta("lumigraph.depth-std", inputs=[args.model, args.camera],
                          extra={"what": "first-order standard deviation of the model's depth "
                                         "from its parameters' covariance (the model's unit); "
                                         "inf: a model edge may cross the pixel; no model = "
                                         + ("inf" if sout.suffix.lower() == ".pfm" else "NaN")})
        if sout.suffix.lower() == ".pfm":
            write_artifact(sout, lambda tmp: write_pfm(tmp, np.where(np.isnan(sd), np.inf, sd)
                                                       .astype(np.float32)), meta=smeta)
        else:
            write_artifact(sout, lambda tmp: np.save(tmp, sd, allow_pickle=False), meta=smeta)
    meta = make_meta("lumigraph.depth", inputs=[args.model, args.camera],
                     quality={"model_fraction": float(np.isfinite(z).mean())},
                     timings_s={"total": dt},
                     extra={"convention": "depth = z in the camera frame, the model's unit; "
                                          "no model = " + ("inf" if out.suffix.lower() == ".pfm"
                                                           else "NaN")})
    if out.suffix.lower() == ".pfm":
        write_artifact(out, lambda tmp: write_pfm(tmp, np.where(np.isnan(z), np.inf, z)), meta=meta)
    else:
        write_artifact(out, lambda tmp: np.save(tmp, z, allow_pickle=False), meta=meta)
    if not np.isfinite(z).any():
        warn(f"the model is nowhere in view of {args.camera}: the depth map is empty")
    say(args, f"wrote {out} ({100 * np.isfinite(z).mean():.0f}% of pixels on the model)")
    return 0


def _pair(args) -> int:
    from lumigraph.capture.artifact import make_meta
    from lumigraph.stereo.debevec1996.vdtm import load_posed_camera, rig_between

    key, off = load_posed_camera(args.key), load_posed_camera(args.offset)
    args.arg_flags = {**(getattr(args, "arg_flags", None) or {}), "offset": args.offset}
    rig = rig_between(key, off)
    rig.save(args.out, meta=make_meta("lumigraph.rig", inputs=[args.key, args.offset],
                                      extra={"left": "key", "right": "offset"}))
    say(args, f"wrote {args.out} (baseline {np.linalg.norm(rig.T):.4g})")
    return 0


def _photographs(args, model_body):
    """The photographs of ``--photos`` with their posed cameras."""
    from lumigraph.capture.io import read_image, read_stack_json
    from lumigraph.capture.rig import require_rotation
    from lumigraph.capture.schema import require
    from lumigraph.stereo.debevec1996.vdtm import Photograph, load_posed_camera

    folder = Path(args.photos)
    sj = folder / "stack.json"
    if not folder.is_dir() or not sj.is_file():
        raise InputError(folder, "expected a folder with stack.json naming the photographs")
    names = list(read_stack_json(sj)["images"])
    cams_dir = Path(args.cameras) if args.cameras else None
    if cams_dir is None and model_body is None:
        cams_dir = folder / "cameras"
    photos, kinds = [], set()
    for i, name in enumerate(names):
        path = folder / name
        if not path.is_file():
            raise InputError(sj, f"key 'images[{i}]': {name} is not a file in {folder}")
        img = read_image(path)
        if cams_dir is not None:
            cp = cams_dir / f"{Path(name).stem}.json"
            if not cp.is_file():
                raise InputError(cams_dir, f"no camera for {name}: expected {cp.name} (a camera.json "
                                           "with cam_from_world)")
            cam, R, t = load_posed_camera(cp)
            K, size, where = cam.K, cam.image_size, cp
        else:
            cams = model_body.get("cameras")
            if not isinstance(cams, dict) or name not in cams:
                raise InputError(args.model, f"key 'cameras': no pose for {name} (left out of the "
                                             "solve?); give --cameras")
            c = cams[name]
            R = require_rotation(c, "R", path=args.model, where=f"cameras.{name}")
            t = require(c, "t", "matrix", shape=(3,), path=args.model, where=f"cameras.{name}")
            K = require(c, "K", "matrix", shape=(3, 3), path=args.model, where=f"cameras.{name}")
            size, where = img.shape[1::-1], args.model
        if tuple(img.shape[1::-1]) != tuple(size):
            raise InputError(path, f"is {img.shape[1]}x{img.shape[0]}, its camera ({where}) is for "
                                   f"{size[0]}x{size[1]} images")
        kinds.add(img.dtype.kind if img.dtype.kind == "f" else img.dtype.name)
        photos.append(Photograph(img.astype(np.float32), np.asarray(K, float), np.asarray(R, float),
                                 np.asarray(t, float)))
    if not photos:
        raise InputError(sj, "names no photographs")
    if len(kinds) > 1:
        raise InputError(folder, f"photographs mix kinds ({', '.join(sorted(kinds))}): blend one kind")
    return photos, kinds.pop()


def _views(args) -> list[Path]:
    """The camera files of ``--view``: each file given, a folder's ``*.json`` in name order."""
    views = []
    for v in args.view:
        v = Path(v)
        if v.is_dir():
            found = sorted(v.glob("*.json"))
            found = [f for f in found if not f.name.endswith(".meta.json")]
            if not found:
                raise InputError(v, "a folder of views holds no camera.json files (*.json)")
            views += found
        else:
            views.append(v)
    stems = [v.stem for v in views]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise InputError(views[stems.index(dup[0])], f"two views are named {dup[0]!r}: each view's "
                                                     "output is named after its camera file")
    return views


def _render(args) -> int:
    from lumigraph.capture.artifact import make_meta, write_artifact, write_json
    from lumigraph.capture.io import write_exr, write_image
    from lumigraph.stereo.debevec1996.vdtm import (
        DEFAULT_NEIGHBOURS,
        DEFAULT_POWER,
        load_model_mesh,
        load_posed_camera,
        prepare_photographs,
        prepare_view_maps,
        render_vdtm,
    )

    if args.reflection and args.method != "blend":
        raise InputError("reflection", "the reflection layer corrects the blend: use "
                                         "the blend method")
    out = Path(args.out)
    views = _views(args)
    single = len(views) == 1 and out.suffix.lower() in (".png", ".exr")
    if len(views) > 1 and out.suffix.lower() in (".png", ".exr"):
        raise InputError(out, f"{len(views)} views write a folder (one image per view, and "
                              "index.json); name a folder")
    mesh, body = load_model_mesh(args.model)
    cams = [load_posed_camera(v) for v in views]  # every view read before any work
    photos, kind = _photographs(args, body)
    if single and kind == "f" and out.suffix.lower() != ".exr":
        raise InputError(out, "the photographs are linear radiance (float): write .exr to keep "
                              "them linear")
    ext = out.suffix.lower() if single else (".exr" if kind == "f" else ".png")
    targets = [out] if single else [out / f"{v.stem}{ext}" for v in views]
    if not single:
        check_planned([*targets, out / "index.json"])
    power = DEFAULT_POWER if args.power is None else args.power
    neighbours = DEFAULT_NEIGHBOURS if args.neighbours is None else args.neighbours
    # shared by every view: the photographs' depth maps and visibility, and the view maps
    t0 = time.perf_counter()
    photos = prepare_photographs(mesh, photos, tolerance=args.tolerance)
    maps = (prepare_view_maps(mesh, photos, tolerance=args.tolerance)
            if args.method == "view-map" else None)
    layer, layer_summary = None, None
    if args.reflection:
        from lumigraph.stereo.debevec1996.reflection import fit_reflection_layer

        say(args, f"fitting the reflection layer to {len(photos)} photographs (leaving each out in "
                  "turn)...")
        layer = fit_reflection_layer(
            mesh, photos, tolerance=args.tolerance, power=power, neighbours=neighbours,
            progress=lambda it: progress(it, total=len(it), description="plane orientations",
                                         quiet=getattr(args, "quiet", False)))
        layer_summary = layer.summary()
        for g in layer_summary:
            sc = g["held_out_mse"]
            # a plane left without a layer: its best candidate's score, to show how near it came
            chosen = (g["chosen"] if g["used"]
                      else min((k for k in sc if k != "none"), key=sc.get, default="none"))
            say(args, f"  planes facing {g['normal']}: "
                      f"{'layer ' + chosen if g['used'] else 'plain blend'} (held-out MSE none "
                      f"{sc['none']:.1f}, {'layer' if g['used'] else 'best layer ' + chosen} "
                      f"{sc[chosen]:.1f}, {g['held_out_samples']} samples"
                      + (f"; off on {100 * g['gated_off_fraction']:.0f}% of the planes, where it "
                         "explains the photographs' differences worse than none"
                         if g["used"] else "") + ")")
        if not any(g["used"] for g in layer_summary):
            warn("--reflection: no plane orientation's layer predicts held-out photographs better "
                 "than the plain blend; rendering the plain blend")
    prepared = time.perf_counter() - t0
    index = {}
    for k, (view, (cam, R, t), target) in enumerate(zip(views, cams, targets, strict=True)):
        t0 = time.perf_counter()
        res = render_vdtm(mesh, photos, cam.K, R, t, cam.image_size, method=args.method,
                          tolerance=args.tolerance, power=power, neighbours=neighbours, maps=maps,
                          reflection=layer)
        dt = time.perf_counter() - t0
        img = res.image
        if img.shape[2] == 1:
            img = img[..., 0]
        warnings = []
        if res.info["hole_fraction"] > 0.2:
            warnings.append(f"{view.name}: {100 * res.info['hole_fraction']:.0f}% of the model in "
                            "view is seen by no photograph (filled from its neighbours)")
            warn(warnings[-1])
        one = res.info["seen_by_one_fraction"]
        if one is not None and one > 0.2:
            warnings.append(f"{view.name}: {100 * one:.0f}% of the model in view is seen by one "
                            "photograph only: its colour there is that photograph's, and "
                            "highlights and reflections do not follow the view")
            warn(warnings[-1])
        quality = {"model_fraction": float(res.model.mean()),
                   "hole_fraction": res.info["hole_fraction"],
                   "seen_by_one_fraction": one,
                   "photographs_per_pixel": res.info["photographs_per_pixel"]}
        meta = make_meta("lumigraph.vdtm", inputs=[args.model, Path(args.photos) / "stack.json", view],
                         warnings=warnings,
                         params={"method": args.method, "tolerance": args.tolerance, "power": power,
                                 "neighbours": neighbours, "reflection": bool(args.reflection)},
                         quality=quality,
                         timings_s={"total": dt, "shared_preparation": prepared,
                                    **res.info["timings_s"]},
                         extra={"what": "view-dependent texture mapping of the model "
                                        "(Debevec, Taylor & Malik 1996); 0 off the model",
                                "shared_preparation": f"the photographs' depth and visibility"
                                                      f"{' and the view maps' if maps else ''}"
                                                      f"{' and the reflection layer' if layer else ''}, "
                                                      f"once for {len(views)} view(s)",
                                **({"reflection_layer": layer_summary} if layer_summary else {})})
        if target.suffix.lower() == ".exr":
            write_artifact(target, lambda tmp, img=img: write_exr(tmp, np.ascontiguousarray(
                img, np.float32)), meta=meta)
        else:
            hi = 65535 if kind == "uint16" else 255
            codes = np.clip(np.rint(img), 0, hi).astype(np.uint16 if hi == 65535 else np.uint8)
            write_artifact(target, lambda tmp, codes=codes: write_image(tmp, codes), meta=meta)
        index[target.name] = {"view": str(view), **quality, "warnings": warnings,
                              "seconds": dt}
        say(args, f"{'' if single else f'view {k + 1}/{len(views)}: '}wrote {target} "
                  f"({args.method}, {100 * res.model.mean():.0f}% of pixels on the model, "
                  f"{100 * res.info['hole_fraction']:.1f}% of them filled"
                  + (f", {100 * one:.0f}% seen by one photograph only" if one is not None else "")
                  + ")")
    if not single:
        meta = make_meta("lumigraph.vdtm-index", inputs=[args.model, Path(args.photos) / "stack.json",
                                                         *views],
                         params={"method": args.method, "tolerance": args.tolerance,
                                 "power": power, "neighbours": neighbours},
                         timings_s={"shared_preparation": prepared,
                                    "views": sum(v["seconds"] for v in index.values())})
        write_artifact(out / "index.json", lambda tmp: write_json(tmp, index), meta=meta)
        say(args, f"rendered {len(views)} views into {out} (shared preparation {prepared:.2f} s)")
    return 0
