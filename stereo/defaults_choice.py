"""Reproduce the choice of ``lumigraph.stereo.block_matching.match`` defaults
(the decision, its data and its figures:
``docs/decisions/stereo-block-matching-defaults.md``): a grid over the
decision parameters, scored on the rendered capture/ pairs only, subject to
the hard cases of the issue.

Run ``python -m lumigraph.stereo.defaults_choice`` (about 3 minutes on 2 cores); it
prints every grid point's score and feasibility, then the ten best feasible
points. Score: the mean bad-2.0 of the bench's ``pair`` and ``pair-hard``
cases (320x240) at windows 5, 9 and 15. Feasible: on a textureless card,
more than 90 % unknown and fewer than 10 % wrong at windows 5, 9 and auto,
with the textured rest at least 75 % matched; and more than 60 % of the
occluded pixels refused at windows 5, 9 and 15 on the plain and the occluder
pair (240x180). The Middlebury pairs take no part.
"""

from __future__ import annotations

import itertools

import numpy as np

GRID = {"texture_snr": (0.25, 0.5, 1.0), "uniqueness": (0.0, 0.02, 0.05),
        "distinct": (0.0, 0.2, 0.5), "lr_tolerance": (1, 2, 3, 4, 6)}


def _occluded(scene):
    gt = scene.gt_arrays["disparity"]
    occ = ~np.isfinite(gt)
    occ[:, : int(np.nanmax(gt)) + 2] = False  # the left band has no partner at all
    return occ


def feasible(kw, *, card_scene, occlusion_scenes) -> tuple[bool, str]:
    """Whether the parameters ``kw`` meet the hard cases, and the figure that decided."""
    from scipy import ndimage

    from lumigraph.stereo.block_matching import match

    s = card_scene
    gt = s.gt_arrays["disparity"]
    card = ndimage.binary_erosion(np.abs(s.gt_arrays["depth"] - 2.6) < 1e-9, iterations=8)
    rest = np.isfinite(gt) & ~ndimage.binary_dilation(card, iterations=16)
    for w in (5, 9, "auto"):
        d = match(s.images[0], s.images[1], max_disp=47, window=w, **kw).disparity
        if not (np.isnan(d[card]).mean() > 0.9 and (np.abs(d[card] - gt[card]) > 2).mean() < 0.1):
            return False, f"textureless card at window {w}"
        if not np.isfinite(d[rest]).mean() > 0.75:
            return False, f"textured rest at window {w}"
    worst = 1.0
    for s in occlusion_scenes:
        occ = _occluded(s)
        for w in (5, 9, 15):
            d = match(s.images[0], s.images[1], max_disp=47, window=w, **kw).disparity
            worst = min(worst, float(np.isnan(d[occ]).mean()))
    return worst > 0.6, f"occluded refused >= {worst:.3f}"


def main() -> None:
    from lumigraph.capture.render import render
    from lumigraph.stereo.bench_stereo import _error, _pair
    from lumigraph.stereo.block_matching import match

    cases = [_pair((320, 240)), _pair((320, 240), textureless=True, occluders=2)]
    card_scene = render("stereo-pair", size=(240, 180), textureless=True)
    occlusion_scenes = [render("stereo-pair", size=(240, 180), occluders=2),
                        render("stereo-pair", size=(240, 180))]
    rows = []
    for values in itertools.product(*GRID.values()):
        kw = dict(zip(GRID, values, strict=True))
        ok, why = feasible(kw, card_scene=card_scene, occlusion_scenes=occlusion_scenes)
        score = float(np.mean([_error(c, match(c["left"], c["right"], max_disp=c["max_disp"],
                                                   window=w, **kw).disparity)["error"]
                               for c in cases for w in (5, 9, 15)]))
        rows.append((score, ok, why, kw))
        print(f"{score:.4f} {'feasible' if ok else 'infeasible'} ({why}) {kw}", flush=True)
    print("best feasible:")
    for score, _, why, kw in sorted((r for r in rows if r[1]), key=lambda r: r[0])[:10]:
        print(f"{score:.4f} ({why}) {kw}")


if __name__ == "__main__":
    main()
