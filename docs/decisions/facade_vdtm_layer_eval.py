"""The reflection layer's figures per view (docs/decisions/facade-vdtm.md,
"The layer's gate"): for each seed, the plain blend, the uniform average, the
nearest photograph's texture and the blend with the layer, PSNR over the
model's own surface (the bench's protocol), one ``ROW`` line per view.

Usage::

    OPENBLAS_NUM_THREADS=1 GATE=1 python docs/decisions/facade_vdtm_layer_eval.py 12 13 14

``GATE=0`` fits the layer without its gate; ``LAMBDAS=10,30,100,300`` replaces
the candidate smoothness weights. ``LAYOUT=ring PHOTOS=10 NOVEL=10`` renders
the building photographed all round (the scene's ``layout`` option) instead of
the 240° arc of 8 photographs and 4 novel views. About 90 s of CPU a seed at
640x480 (the arc).
"""

import os
import sys
import time

import numpy as np

import lumigraph.stereo.debevec1996.reflection as RF
from lumigraph.capture.render import render
from lumigraph.stereo.bench_facade_vdtm import _photos, _psnr, _references
from lumigraph.stereo.debevec1996.vdtm import render_vdtm

RF.GATE = os.environ.get("GATE", "1") == "1"
SIZE = (640, 480)


def main(seeds):
    kw = {}
    if os.environ.get("LAMBDAS"):
        kw["lambdas"] = tuple(float(x) for x in os.environ["LAMBDAS"].split(","))
    for seed in seeds:
        s = render("facade", size=SIZE, seed=seed, layout=os.environ.get("LAYOUT", "arc"),
                   photos=int(os.environ.get("PHOTOS", 8)), novel=int(os.environ.get("NOVEL", 4)))
        mesh, photos, _, _ = _photos(s)
        t0 = time.process_time()
        layer = RF.fit_reflection_layer(mesh, photos, **kw)
        print(f"s{seed} fit {time.process_time() - t0:.0f}s {layer.summary()}", flush=True)
        for k, (name, cam) in enumerate(s.gt["novel_cameras"].items()):
            K, R, t = (np.array(cam[x]) for x in "KRt")
            gt, m = s.gt_arrays[f"novel_{k}"], s.gt_arrays[f"novel_model_{k}"]
            pb = _psnr(render_vdtm(mesh, photos, K, R, t, SIZE).image, gt, m)
            pu, pn, _ = _references(mesh, photos, K, R, t, SIZE, gt, m)
            pl = _psnr(render_vdtm(mesh, photos, K, R, t, SIZE, reflection=layer).image, gt, m)
            print(f"ROW s{seed} {name} blend {pb:.2f} uni {pu:.2f} near {pn:.2f} layer {pl:.2f} "
                  f"lu {pl - pu:+.2f} ln {pl - pn:+.2f} lb {pl - pb:+.2f}", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]])
