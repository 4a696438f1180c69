"""Score model-based stereo settings on the renders of docs/decisions/model-stereo-sgm.md.

Usage::

    OPENBLAS_NUM_THREADS=1 python docs/decisions/model_stereo_sgm_tuning.py ANGLES SEED TEXTURELESS \\
        CONFIGS [peers]

``ANGLES`` comma-separated degrees between the views, ``SEED`` the render
seed, ``TEXTURELESS`` 1 for the scene's flat grey sign, ``CONFIGS`` a JSON
list of ``model_stereo`` keyword sets (an ``"sgm"`` entry overrides the
module's ``SGM`` settings), ``peers`` adds StereoSGBM (windows 3, 5) and our
SSD (9, 15) on the rectified pair. The tuning set was ``27.5,42.5,57.5 1 0``
and ``42.5 1 1``; the bench's cases (``20,35,50,65 0 0``) are reported on.

Prints per angle and setting: the bench's error (share of seen key pixels
missing or off by > 1 % of depth), the density, and the share of key pixels
hidden by the relief that are refused (``h``).
"""

import functools
import importlib
import json
import sys

import cv2

import lumigraph.capture.render as render_module
from lumigraph.stereo import bench_stereo as bench

ms = importlib.import_module("lumigraph.stereo.debevec1996.model_stereo")


def main(argv):
    cv2.setNumThreads(1)
    angles = [float(a) for a in argv[0].split(",")]
    seed, textureless = int(argv[1]), argv[2] == "1"
    configs = json.loads(argv[3])
    peers = len(argv) > 4
    opts = {"textureless": True} if textureless else {}
    render_module.render = functools.partial(render_module.render, seed=seed, **opts)
    base = dict(ms.SGM)
    for a in angles:
        data = bench._model_case(a)
        row = []
        for cfg in configs:
            cfg = dict(cfg)
            ms.SGM.clear()
            ms.SGM.update(base)
            ms.SGM.update(cfg.pop("sgm", {}))
            d = ms.model_stereo(data["key"], data["offset"], data["model"], data["rig"],
                                max_offset=data["max_offset"], **cfg).depth
            e = bench._error(data, d)
            row.append(f"{e['error']:.4f}/{e['density']:.2f}/h{e['hidden_refused']:.2f}")
        if peers:
            row += [f"sgbm{w} {bench._error(data, bench._plain_sgbm(data, w))['error']:.4f}"
                    for w in (3, 5)]
            row += [f"ssd{w} {bench._error(data, bench._plain_ssd(data, w))['error']:.4f}"
                    for w in (9, 15)]
        print(a, seed, textureless, " | ".join(row), flush=True)
    ms.SGM.clear()
    ms.SGM.update(base)


if __name__ == "__main__":
    main(sys.argv[1:])
