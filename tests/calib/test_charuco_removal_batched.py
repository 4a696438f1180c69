"""The batched ChArUco marker removal (calib/detect.py: all markers'
homographies, boxes and warp matrices at once, segment sums for the blur's
fit, a partial sort for the paint's percentile) gives the results of the
one-marker-at-a-time code it replaced (tests/calib/_charuco_removal_reference.py,
kept verbatim), on whole boards, a strong lens (markers from the 1.5-square
blocks) and crops that cut the board (markers half outside the image)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from lumigraph.calib import detect as D
from lumigraph.capture.render import render

# by path: "calib" on sys.path is the library's stage folder, not this one
_spec = importlib.util.spec_from_file_location("_charuco_removal_reference",
                                               Path(__file__).with_name("_charuco_removal_reference.py"))
R = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(R)

# float rounding only: a thousandth of a code (the render's read noise is ~1 code)
CLEAN_TOL = 1e-3
# cornerSubPix stops once its step is below its eps: a rounding-level change of
# the image may stop it one step earlier or later, so corners agree to that eps
CORNER_TOL = D._SUBPIX_CRITERIA[2]


@pytest.fixture(scope="module")
def views():
    out = []
    for size, seed, blur, lens in (((320, 240), 21, 0.6, "normal"), ((640, 480), 9, 0.8, "strong")):
        s = render("boards", size=size, seed=seed, views=2, board="charuco", blur=blur, distortion=lens)
        board = D.BoardSpec.parse(s.stack["board"])
        for im in s.images:
            w, h = im.shape[1], im.shape[0]
            for crop in (im, im[:, : int(0.55 * w)], im[:, int(0.4 * w):], im[: h // 2]):
                out.append((np.ascontiguousarray(crop), board))
    return out


def _reference_detect(image, board, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(D, "_paint_out_markers", R._paint_out_markers)
        m.setattr(D, "_refine_without_markers", R._refine_without_markers)
        return D.detect(image, board)


def test_removal_matches_the_reference(views):
    import cv2

    n = 0
    for image, board in views:
        gray = D.to_gray8(image)
        det = cv2.aruco.CharucoDetector(board._charuco())
        corners, ids, _, _ = det.detectBoard(gray)
        if ids is None or len(ids) < 6:
            continue
        ids = ids.ravel().astype(np.int64)
        pts = corners.reshape(-1, 2).astype(np.float64)
        new, old = D._remove_markers(gray, ids, pts, board), R._remove_markers(gray, ids, pts, board)
        assert (new is None) == (old is None)
        if new is None:
            continue
        assert new[1] == old[1]  # the same markers modelled
        assert np.abs(new[0] - old[0]).max() <= CLEAN_TOL
        n += 1
    assert n >= 10


def test_detection_matches_the_reference(views, monkeypatch):
    # the removal's own path (the model fit, the default last step, replaces it)
    monkeypatch.setattr(D, "FIT_MODEL", False)
    n = 0
    for image, board in views:
        new, old = D.detect(image, board), _reference_detect(image, board, monkeypatch)
        assert np.array_equal(new.ids, old.ids)
        if len(new):
            assert np.abs(new.image_points - old.image_points).max() <= CORNER_TOL
            n += 1
    assert n >= 10


def test_p95_is_numpys_percentile():
    rng = np.random.default_rng(0)
    for k in range(400):
        size = int(rng.integers(1, 300))
        v = rng.integers(0, 256, size).astype(np.uint8) if k % 2 else (rng.random(size) * 255).astype(np.float32)
        assert D._p95(v.copy()) == np.percentile(v, 95)


def test_four_point_homographies_are_opencvs():
    import cv2

    rng = np.random.default_rng(1)
    src = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float64)[None] * rng.uniform(5, 50, (20, 1, 1))
    dst = src * rng.uniform(0.5, 3, (20, 1, 1)) + rng.uniform(-4, 4, (20, 4, 2)) + rng.uniform(0, 600, (20, 1, 2))
    src, dst = src.astype(np.float32).astype(np.float64), dst.astype(np.float32).astype(np.float64)
    ours = D._homographies_4(src, dst)
    for H, s, d in zip(ours, src, dst, strict=True):
        ref = cv2.getPerspectiveTransform(s.astype(np.float32), d.astype(np.float32))
        # double rounding of an 8x8 solve (condition number ~1e4 here)
        assert np.abs(H - ref).max() <= 1e-9 * np.abs(ref).max()
