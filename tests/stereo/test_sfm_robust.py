"""The SfM's final robust bundle adjustment (stereo.sfm.robust_refine):
observations with a systematic error must not pull the poses the way they
pull a least-squares adjustment (the temple's rotation error, issue 14)."""

import numpy as np
import pytest

pycolmap = pytest.importorskip("pycolmap")

from lumigraph.stereo.sfm import align_similarity, reprojection_residuals, robust_refine  # noqa: E402

SIGMA = 0.3  # px, Gaussian noise on every keypoint coordinate
SHIFT = 3.0  # px, the systematic error of the bad observations (10 sigma)
BAD = 0.1  # share of bad observations


def _poses(rec):
    out = {}
    for i, im in rec.images.items():
        cw = im.cam_from_world()
        R = cw.rotation.matrix()
        out[i] = (R, -R.T @ cw.translation)
    return out


def _rotation_error_deg(gt, rec):
    """Largest rotation error after the similarity on the centres (the bench's measure)."""
    p = _poses(rec)
    ids = sorted(gt)
    s, Rs, t = align_similarity(np.array([p[i][1] for i in ids]), np.array([gt[i][1] for i in ids]))
    return max(np.degrees(np.arccos(np.clip((np.trace(gt[i][0].T @ p[i][0] @ Rs.T) - 1) / 2, -1, 1)))
               for i in ids)


def _adjust(rec):
    bo = pycolmap.BundleAdjustmentOptions()
    bo.print_summary = False
    bo.refine_focal_length = bo.refine_extra_params = False
    bo.ceres.solver_options.num_threads = 1
    pycolmap.bundle_adjustment(rec, bo)


def test_robust_refinement_resists_systematic_matches():
    o = pycolmap.SyntheticDatasetOptions()
    o.num_rigs, o.num_cameras_per_rig, o.num_frames_per_rig, o.num_points3D = 1, 1, 8, 300
    o.camera_model_id = pycolmap.CameraModelId.SIMPLE_PINHOLE
    o.camera_params = [1280.0, 512.0, 384.0]
    o.num_points2D_without_point3D = 0
    pycolmap.set_random_seed(0)
    truth = pycolmap.synthesize_dataset(o)
    gt = _poses(truth)
    rng = np.random.default_rng(0)
    noisy = pycolmap.Reconstruction(truth)
    bad = []
    for i, im in noisy.images.items():
        for k, p in enumerate(im.points2D):
            if p.has_point3D():
                shift = rng.random() < BAD
                im.points2D[k].xy = p.xy + rng.normal(0, SIGMA, 2) + ([SHIFT, 0.0] if shift else 0.0)
                if shift:
                    bad.append((i, k))
    # least squares with the bad observations, and without them (the error
    # the noise alone leaves: the reference)
    ls = pycolmap.Reconstruction(noisy)
    _adjust(ls)
    clean = pycolmap.Reconstruction(noisy)
    for i, k in bad:
        if clean.points3D[clean.images[i].points2D[k].point3D_id].track.length() > 2:
            clean.delete_observation(i, k)
    _adjust(clean)
    robust = pycolmap.Reconstruction(ls)
    info = robust_refine(robust, refine_intrinsics=False)
    e_ls, e_clean, e_robust = (_rotation_error_deg(gt, r) for r in (ls, clean, robust))
    # the premise: the systematic observations do hurt least squares
    assert e_ls > 2 * e_clean, (e_ls, e_clean)
    # the robust refinement keeps the poses within twice the error of least
    # squares on the clean observations
    assert e_robust < 2 * e_clean, (e_robust, e_clean, info)
    # the scale follows the residuals: above the injected noise (the bad
    # observations inflate the least-squares residuals), far below the shift
    assert SIGMA <= info["sigma_px"] < SHIFT / 3, info
    assert info["scale_px"] == pytest.approx(2.385 * info["sigma_px"])


def test_residuals_of_an_exact_model_are_zero():
    o = pycolmap.SyntheticDatasetOptions()
    o.num_rigs, o.num_cameras_per_rig, o.num_frames_per_rig, o.num_points3D = 1, 1, 3, 20
    o.camera_model_id = pycolmap.CameraModelId.SIMPLE_PINHOLE
    o.camera_params = [1000.0, 500.0, 400.0]
    o.num_points2D_without_point3D = 0
    pycolmap.set_random_seed(1)
    rec = pycolmap.synthesize_dataset(o)
    r = reprojection_residuals(rec)
    assert r.shape == (rec.compute_num_observations(), 2)
    # double-precision projection of exact points: far below any pixel
    assert np.abs(r).max() < 1e-6
    assert robust_refine(rec, refine_intrinsics=False)["loss"] == "none: zero residuals"
