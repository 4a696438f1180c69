"""The files of a Façade solve (``lumigraph stereo facade solve``): the model
with its uncertainties, the mesh, the cameras and the overlays.

``model.json``::

    {"schema": "lumigraph.facade.model", "schema_version": 1,
     "parameters": {"house/depth": {"value": 6.0, "std": 0.002, "fixed": false}, ...},
     "parameter_covariance": {"names": [free names], "matrix": n x n} (or null),
     "cameras": {"photo_00.png": {"K": 3x3, "R": 3x3, "t": [3], "centre": [3],
                                  "std": {"rotation_rad": [3], "t": [3], "centre": [3]}}},
     "focal_scale": {"value", "std"}, "sigma_px",
     "sigma_px_by_kind": {"hand", "proposed"} (or null), "rms_px",
     "marks": [{"photo", "edge", "rms_px"}], "outliers": [...], "dropped": [...]}

Every parameter name of the model (shared and fixed ones too) is a key, as
in a rendered scene's ``gt.json``. ``R, t``: ``x_cam = R x_world + t``;
``rotation_rad`` is the std of a small rotation applied in the camera frame.
``parameter_covariance`` is the free parameters' first-order covariance
(their correlations: what ``stereo facade depth --std-out`` propagates to
the depth).

>>> mesh_obj_text(np.zeros((3, 3)), np.array([[0, 1, 2]])).splitlines()[-1]
'f 1 2 3'
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lumigraph.capture.errors import InputError

MODEL_SCHEMA = "lumigraph.facade.model"


def _stem(photo: str) -> str:
    return Path(photo).stem


def planned_outputs(photos) -> list[str]:
    """Every file ``save_solution`` writes, relative to the output folder."""
    return (["model.json", "blocks.json", "model.obj", "model.ply", "cameras.txt", "images.txt",
             "points3D.txt"] + [f"cameras/{_stem(p)}.json" for p in photos]
            + [f"overlay/{_stem(p)}.png" for p in photos])


def model_dict(sol) -> dict:
    """``model.json``'s body (module docstring)."""
    fixed = {n: bool(sol.model.fixed[sol.model.slot_of(n)]) for n in sol.params}
    cams = {}
    for p, (R, t) in sol.poses.items():
        s = sol.pose_std[p]
        cams[p] = {"K": sol.K[p].tolist(), "R": R.tolist(), "t": t.tolist(),
                   "centre": (-R.T @ t).tolist(),
                   "std": {k: np.asarray(v).tolist() for k, v in s.items()}}
    free = list(sol.model.parameter_names)
    cov = None  # the free parameters' covariance block (the solve's first unknowns)
    if tuple(sol.unknowns[:len(free)]) == tuple(free):
        cov = {"names": free,
               "matrix": np.asarray(sol.covariance)[:len(free), :len(free)].tolist()}
    return {"schema": MODEL_SCHEMA, "schema_version": 1,
            "parameters": {n: {"value": v, "std": sol.std[n], "fixed": fixed[n]}
                           for n, v in sol.params.items()},
            "parameter_covariance": cov,
            "cameras": cams,
            "focal_scale": {"value": sol.focal_scale, "std": sol.focal_scale_std},
            "sigma_px": sol.sigma_px, "sigma_px_by_kind": dict(sol.sigma_px_by_kind) or None,
            "rms_px": sol.rms_px,
            "marks": [{"photo": p, "edge": e, "rms_px": r} for p, e, r in sol.mark_rms_px],
            "outliers": [{"photo": p, "edge": e, "rms_px": r} for p, e, r in sol.outliers],
            "dropped": list(sol.dropped)}


def mesh_obj_text(vertices, faces) -> str:
    """A Wavefront OBJ of a triangle mesh (1-based indices)."""
    lines = ["# lumigraph facade model"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.asarray(vertices, float)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces, int)]
    return "\n".join(lines) + "\n"


# OBJ statements read_obj passes over: texture and normal data, groups,
# materials, smoothing, lines and points, free-form geometry.
_OBJ_SKIPPED = frozenset({"vt", "vn", "vp", "o", "g", "s", "mg", "usemtl", "mtllib", "l", "p",
                          "cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm",
                          "trim", "hole", "scrv", "sp", "end", "con", "lod", "bevel",
                          "c_interp", "d_interp", "usemap", "maplib", "shadow_obj",
                          "trace_obj", "ctech", "stech"})


def read_obj(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a Wavefront OBJ mesh (what :func:`mesh_obj_text` writes, and others'):
    ``(vertices (N, 3) float64, faces (M, 3) int64)``, 0-based.

    ``v x y z [w | r g b]`` gives a vertex (its first three numbers); ``f`` a
    polygon of ``k >= 3`` vertex references (``i``, ``i/t``, ``i//n`` or
    ``i/t/n``; 1-based, negative counts back from the last vertex so far),
    split into the fan ``(v0, vi, vi+1)``, keeping its winding. Texture,
    normal, group and material statements are passed over; comments (``#``) and
    blank lines too.

    Raises
    ------
    InputError
        Naming the file and the line: an unknown statement, a vertex without
        three numbers, a face of fewer than three vertices, a reference that is
        not an integer or names no vertex defined before it; or a file that is
        not text.

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "quad.obj")
    >>> _ = open(p, "w").write("v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nf 1/1 2/2 3/3 -1/4\\n")
    >>> v, f = read_obj(p)
    >>> v.shape, f.tolist()
    ((4, 3), [[0, 1, 2], [0, 2, 3]])
    """
    p = Path(path)
    try:
        text = p.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise InputError(p, "file not found") from None
    except OSError as e:
        raise InputError(p, f"cannot read ({e.strerror or e})") from None
    except UnicodeDecodeError as e:
        raise InputError(p, f"not a text OBJ file (byte {e.start} is not UTF-8)") from None
    verts: list[tuple[float, float, float]] = []
    tris: list[tuple[int, int, int]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        head, args = parts[0], parts[1:]
        if head == "v":
            try:
                xyz = tuple(float(a) for a in args)
            except ValueError:
                xyz = ()
            if len(xyz) not in (3, 4, 6, 7) or not all(math.isfinite(c) for c in xyz):
                raise InputError(p, f"line {number}: a vertex is 'v x y z' (finite numbers, "
                                    f"then an optional w or r g b), got {line.strip()!r}")
            verts.append(xyz[:3])
        elif head == "f":
            refs = []
            for a in args:
                first = a.split("/", 1)[0]
                try:
                    i = int(first)
                except ValueError:
                    i = 0
                k = i - 1 if i > 0 else len(verts) + i  # 1-based; negative: from the end
                if i == 0 or not 0 <= k < len(verts):
                    raise InputError(p, f"line {number}: {a!r} names no vertex (there are "
                                        f"{len(verts)} before this line; indices are 1-based)")
                refs.append(k)
            if len(refs) < 3:
                raise InputError(p, f"line {number}: a face needs 3 or more vertices, got "
                                    f"{len(refs)}")
            tris += [(refs[0], refs[j], refs[j + 1]) for j in range(1, len(refs) - 1)]
        elif head not in _OBJ_SKIPPED:
            raise InputError(p, f"line {number}: {head!r} is not an OBJ statement (read: v, f; "
                                "passed over: vt, vn, g, o, usemtl, ...)")
    return (np.array(verts, np.float64).reshape(-1, 3), np.array(tris, np.int64).reshape(-1, 3))


def mesh_ply_bytes(vertices, faces) -> bytes:
    """A binary little-endian PLY of a triangle mesh (double vertices)."""
    V = np.asarray(vertices, "<f8")
    F = np.asarray(faces, "<i4")
    head = ("ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
            f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
    rec = np.empty(len(F), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rec["n"], rec["i"] = 3, F
    return head.encode("ascii") + V.tobytes() + rec.tobytes()


def colmap_text(sol, photos) -> dict[str, str]:
    """COLMAP's text model (PINHOLE cameras, one per photograph; images with
    their poses; the model's vertices as 3-D points without tracks)."""
    cams = ["# Camera list with one line of data per camera:",
            "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    ims = ["# Image list with two lines of data per image:",
           "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
           "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    k = 0
    for p in photos:
        if p not in sol.poses:
            continue
        k += 1
        K = sol.K[p]
        w, h = sol.image_sizes[p] if hasattr(sol, "image_sizes") else (0, 0)
        cams.append(f"{k} PINHOLE {w} {h} {K[0, 0]:.17g} {K[1, 1]:.17g} {K[0, 2]:.17g} {K[1, 2]:.17g}")
        R, t = sol.poses[p]
        x, y, z, wq = Rotation.from_matrix(R).as_quat()
        if wq < 0:
            x, y, z, wq = -x, -y, -z, -wq
        ims.append(f"{k} {wq:.17g} {x:.17g} {y:.17g} {z:.17g} {t[0]:.17g} {t[1]:.17g} {t[2]:.17g} "
                   f"{k} {p}")
        ims.append("")
    pts = ["# 3D point list with one line of data per point:",
           "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"]
    for i, v in enumerate(sol.model.vertices()):
        pts.append(f"{i + 1} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g} 200 200 200 0")
    return {"cameras.txt": "\n".join(cams) + "\n", "images.txt": "\n".join(ims) + "\n",
            "points3D.txt": "\n".join(pts) + "\n"}


def overlay(image, sol, photo, marks) -> np.ndarray:
    """The photograph (8-bit BGR→RGB) with the marked segments (green; the
    left-out ones magenta), the marked edges reprojected (red), the other
    model edges (blue), and each mark's RMS distance (px)."""
    import cv2

    from lumigraph.stereo.debevec1996.solve import project_model_edges

    img = np.asarray(image)
    if img.dtype == np.uint16:
        img = (img / 257.0).round().astype(np.uint8)
    elif img.dtype != np.uint8:
        img = np.clip(np.asarray(img, float) * 255.0, 0, 255).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, 2)
    img = np.ascontiguousarray(img[..., :3])
    if photo not in sol.poses:
        return img
    R, t = sol.poses[photo]
    proj = project_model_edges(sol.model, sol.K[photo], R, t)
    marked = {m.edge for m in marks.of(photo)}
    out = {(p, e) for p, e, _ in sol.outliers}
    rms = {}
    for p, e, r in sol.mark_rms_px:
        if p == photo:
            rms[e] = r

    def line(a, b, colour, width=1):
        if np.all(np.isfinite(a)) and np.all(np.isfinite(b)):
            cv2.line(img, tuple(int(round(v * 16)) for v in a), tuple(int(round(v * 16)) for v in b),
                     colour, width, cv2.LINE_AA, shift=4)

    for name, (a, b) in proj.items():
        if name not in marked:
            line(a, b, (60, 110, 255))
    for name, (a, b) in proj.items():
        if name in marked:
            line(a, b, (255, 40, 40))
    for m in marks.of(photo):
        s = m.segment
        bad = (photo, m.edge) in out
        line(s[:2], s[2:], (255, 0, 255) if bad else (0, 220, 0), 2)
        mid = (s[:2] + s[2:]) / 2
        txt = "out" if bad else f"{rms.get(m.edge, float('nan')):.2f}"
        cv2.putText(img, txt, (int(mid[0]) + 3, int(mid[1]) - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                    (255, 255, 0), 1, cv2.LINE_AA)
    return img


def save_solution(out, sol, photos, images, marks, camera, *, meta: dict) -> None:
    """Write every file of :func:`planned_outputs` into ``out``."""
    from lumigraph.capture.artifact import dumps_json, write_artifact
    from lumigraph.capture.io import write_image

    out = Path(out)
    (out / "cameras").mkdir(parents=True, exist_ok=True)
    (out / "overlay").mkdir(parents=True, exist_ok=True)
    write_artifact(out / "model.json", lambda tmp: tmp.write_text(dumps_json(model_dict(sol))),
                   meta=meta)
    write_artifact(out / "blocks.json", lambda tmp: tmp.write_text(dumps_json(sol.model.to_dict())),
                   meta=meta)
    mesh = sol.model.mesh()
    write_artifact(out / "model.obj",
                   lambda tmp: tmp.write_text(mesh_obj_text(mesh.vertices, mesh.faces)), meta=meta)
    write_artifact(out / "model.ply",
                   lambda tmp: tmp.write_bytes(mesh_ply_bytes(mesh.vertices, mesh.faces)), meta=meta)

    class _Sized:  # the solution with the photographs' sizes, for COLMAP's cameras.txt
        def __init__(self, s):
            self.__dict__.update(poses=s.poses, K=s.K, model=s.model,
                                 image_sizes={p: images[p].shape[1::-1] for p in images})

    for name, text in colmap_text(_Sized(sol), photos).items():
        write_artifact(out / name, lambda tmp, text=text: tmp.write_text(text), meta=meta)
    for p in photos:
        body = camera.to_dict()
        if p in sol.poses:
            R, t = sol.poses[p]
            body["K"] = sol.K[p].tolist()
            body["cam_from_world"] = {"R": R.tolist(), "t": t.tolist()}
            body["pose_std"] = {k: np.asarray(v).tolist() for k, v in sol.pose_std[p].items()}
        else:
            body["solved"] = False
        write_artifact(out / "cameras" / f"{_stem(p)}.json",
                       lambda tmp, body=body: tmp.write_text(dumps_json(body)), meta=meta)
        write_artifact(out / "overlay" / f"{_stem(p)}.png",
                       lambda tmp, p=p: write_image(tmp, overlay(images[p], sol, p, marks)),
                       meta=meta)
