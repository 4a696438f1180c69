"""Where a VDTM view's error lies (docs/decisions/facade-vdtm.md, "Four more
fresh seeds"): per plane orientation of the glossy building, and per
material on it (the scene's own mirror weight: brick, glass, window frame),
the mean squared error of the blend, the blend with the reflection layer
and the nearest photograph's texture over the model's own surface (the
bench's mask), and each one's share of the view's mean.

Usage::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/facade_vdtm_plane_errors.py SEED VIEW[,VIEW...]

About 60 s of CPU a seed at 640x480 (the layer's fit).
"""

import os
import sys

import numpy as np

import lumigraph.capture.scenes.facade as scene
from lumigraph.capture.render import render
from lumigraph.stereo.bench_facade_vdtm import _photos
from lumigraph.stereo.debevec1996.reflection import fit_reflection_layer
from lumigraph.stereo.debevec1996.vdtm import render_vdtm

SIZE = (640, 480)
MATERIALS = ((None, "any"), (0.25, "brick"), (1.0, "glass"), (0.05, "frame"), (0.0, "matte"))


def main(seed, views):
    s = render("facade", size=SIZE, seed=seed, photos=int(os.environ.get("PHOTOS", 8)),
               novel=int(os.environ.get("NOVEL", 4)))
    mesh, photos, _, _ = _photos(s)
    layer = fit_reflection_layer(mesh, photos)
    building = scene.Building(scene.true_values())
    V, F, n_model, n_solid = scene._scene_mesh(building)
    kinds = np.full(len(F), 3)
    frames = scene._face_frames(V, F)
    nz = frames[0][:, 2]
    owner = building.mesh().face_block
    for i in range(n_solid):  # as the scene's renderer classifies its faces
        kind = building.kinds[owner[i]] if i < n_model else "box"
        kinds[i] = 0 if abs(nz[i]) < 1e-9 else 2 if nz[i] > 0.999 else 1 if kind != "box" else 2
    for view in views:
        cam = list(s.gt["novel_cameras"].values())[view]
        K, R, t = (np.array(cam[x]) for x in "KRt")
        C = -R.T @ t
        j = int(np.argmin([np.linalg.norm(p.centre - C) for p in photos]))
        depth, face, rays = scene._scene_raster(V, F, n_solid, K, R, t, SIZE)
        hit = face.ravel() >= 0
        X = C + (rays.reshape(-1, 3) @ R)[hit] * depth.ravel()[hit, None]
        n = frames[0]
        _, _, _, kr = scene._materials(X, face.ravel()[hit], kinds, *frames, False)
        mirror = np.full(SIZE[0] * SIZE[1], -1.0)
        mirror[hit] = kr
        mirror = mirror.reshape(SIZE[1], SIZE[0])
        normal = np.full((SIZE[1] * SIZE[0], 3), np.nan)
        normal[hit] = n[face.ravel()[hit]]
        normal = normal.reshape(SIZE[1], SIZE[0], 3)
        gt, m = s.gt_arrays[f"novel_{view}"], s.gt_arrays[f"novel_model_{view}"] > 0
        images = {"blend": render_vdtm(mesh, photos, K, R, t, SIZE).image,
                  "layer": render_vdtm(mesh, photos, K, R, t, SIZE, reflection=layer).image,
                  "nearest": render_vdtm(mesh, [photos[j]], K, R, t, SIZE).image}

        def mse(img, sel, gt=gt):
            return float(((img - gt) ** 2)[sel].mean())

        print(f"s{seed} view_{view}: nearest photograph {j}; " +
              ", ".join(f"{k} {mse(v, m):.1f}" for k, v in images.items()))
        for k in np.unique(np.round(normal[m], 2), axis=0):
            plane = m & (np.abs(normal - k).sum(-1) < 0.03)
            for kv, name in MATERIALS:
                sel = plane if kv is None else plane & (np.abs(mirror - kv) < 1e-9)
                if sel.sum() < 200:
                    continue
                share = sel.sum() / m.sum()
                print(f"  normal {k} {name:5s} share {share:.3f}: share of the mean " +
                      " ".join(f"{a} {mse(v, sel) * share:.1f}" for a, v in images.items()) +
                      " | MSE " + " ".join(f"{a} {mse(v, sel):.1f}" for a, v in images.items()))


if __name__ == "__main__":
    main(int(sys.argv[1]), [int(v) for v in sys.argv[2].split(",")])
