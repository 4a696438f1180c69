"""Hard calibration cases (DESIGN §7): each meets its bound or is refused/warned
about clearly — never silently wrong."""

import numpy as np
import pytest

from lumigraph.calib.calibrate import calibrate
from lumigraph.calib.detect import BoardSpec, detect
from lumigraph.capture.errors import EstimationError
from lumigraph.capture.render import render


def _dets(s):
    board = BoardSpec.parse(s.stack["board"])
    return [detect(im, board) for im in s.images]


def test_strong_distortion_auto_picks_a_rich_enough_model():
    s = render("boards", size=(320, 240), seed=12, views=12, distortion="strong")
    cam = calibrate(_dets(s))
    Kt = np.array(s.gt["camera"]["K"])
    assert cam.model not in ("none", "k1")
    # at 320x240 (f ~ 290 px) and ~0.05 px detection noise, sigma_f ~ 0.1 px: 0.3 % is > 5 sigma
    assert 0 < abs(cam.K[0, 0] / Kt[0, 0] - 1) < 0.003
    assert 0 < np.hypot(*(cam.K[:2, 2] - Kt[:2, 2])) < 1.0
    simple = calibrate(_dets(s), model="k1")
    assert abs(simple.K[0, 0] / Kt[0, 0] - 1) > abs(cam.K[0, 0] / Kt[0, 0] - 1)


def test_near_degenerate_poses_warn_naming_the_focal_length():
    s = render("boards", size=(320, 240), seed=13, views=8, poses="fronto")
    cam = calibrate(_dets(s))
    assert any("fronto-parallel" in w for w in cam.extra["warnings"])
    assert {"fx", "fy"} <= set(cam.extra["poorly_determined"])
    with pytest.raises(EstimationError, match="fx"):
        calibrate(_dets(s), strict=True)


def test_few_views_warn():
    s = render("boards", size=(320, 240), seed=14, views=3)
    cam = calibrate(_dets(s))
    assert any("only 3 usable views" in w for w in cam.extra["warnings"])
