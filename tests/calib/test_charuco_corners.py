"""ChArUco corners are refined as accurately as a checkerboard's (the markers
painted out before ``cornerSubPix``), so calibration from them does not drop
terms the data support."""

import numpy as np

from lumigraph.calib.detect import BoardSpec, detect
from lumigraph.capture.render import render


def _corner_errors(board):
    s = render("boards", size=(320, 240), seed=4, views=5, board=board)
    spec = BoardSpec.parse(s.stack["board"])
    e = []
    for im, gt in zip(s.images, s.gt_arrays["corners"], strict=True):
        d = detect(im, spec)
        e.append(np.linalg.norm(d.image_points - gt[d.ids], axis=1))
    return np.concatenate(e)


def test_charuco_corners_as_accurate_as_the_checkerboards():
    ch, ck = _corner_errors("charuco"), _corner_errors("checker")
    rms_ch, rms_ck = np.sqrt(np.mean(ch ** 2)), np.sqrt(np.mean(ck ** 2))
    # the same camera, poses and noise: the RMS of N squared errors has a
    # relative standard error of about 1/sqrt(2N) each; allow 3 of the
    # difference's (the detector's own refinement was 3-4x the checkerboard's)
    se = np.hypot(1 / np.sqrt(2 * len(ch)), 1 / np.sqrt(2 * len(ck)))
    assert rms_ch <= rms_ck * (1 + 3 * se), (rms_ch, rms_ck)
