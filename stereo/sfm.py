"""Unordered multi-view reconstruction (structure from motion) through pycolmap.

SIFT features, exhaustive matching with geometric verification, incremental
mapping and bundle adjustment are COLMAP's (the field's standard, wrapped by
pycolmap 4.x), followed by one more bundle adjustment under a robust (Cauchy)
loss scaled to the residuals' own noise (:func:`robust_refine`: a few
systematic matches otherwise tilt every pose alike). This module feeds it our
images and, when given, our ``camera.json`` as fixed intrinsics, and turns its
reconstruction into our
conventions: ``cam_from_world`` poses, pixel centres at integer coordinates
(COLMAP puts the first pixel's centre at 0.5), points with colours.

Input problems are caught before COLMAP runs: fewer than two images, images of
different sizes, an empty image, and duplicate views (identical images: zero
baseline, nothing to triangulate) raise :class:`capture.errors.InputError`;
a scene COLMAP cannot register raises :class:`capture.errors.EstimationError`.

COLMAP reads images from files, so :func:`reconstruct` writes the arrays into
a private temporary folder and removes it afterwards.

Reference: J. L. Schönberger and J.-M. Frahm, "Structure-from-Motion
Revisited", CVPR 2016, doi:10.1109/CVPR.2016.445 (reference ch. 5, §5.1.5:
reconstruction from many views). Similarity alignment: S. Umeyama, "Least-
squares estimation of transformation parameters between two point patterns",
IEEE TPAMI 13(4), 1991, doi:10.1109/34.88573.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> src = rng.normal(size=(6, 3))
>>> R = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])
>>> s, R_est, t_est = align_similarity(src, 2.5 * src @ R.T + [1, 2, 3])
>>> round(s, 9), bool(np.allclose(R_est, R))
(2.5, True)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import EstimationError, InputError

# SIFT contrast threshold. COLMAP's 0.02/3 drops most features of a pale
# object on a dark background: on the Middlebury temple ring (640x480) it
# registers 13 of 16 views; 0.002 registers all 16 (docs/decisions/sfm.md).
PEAK_THRESHOLD = 0.002
# Registration thresholds: COLMAP asks 30 inliers and a 25 % inlier ratio
# to register a view; three temple views seen across a 42 degree gap have
# 15-30 (13 of 16 registered). A looser registration is safe here because
# assess() judges the model as a whole afterwards (the exit-3 checks).
MAPPER = {"abs_pose_min_num_inliers": 15, "abs_pose_min_inlier_ratio": 0.1}

# assess()'s bounds (docs/decisions/sfm.md): a radial term beyond 1 bends
# the image edge by more than its own size; a focal more than 30 % off a
# known prior is a different camera or a failed self-calibration; points seen
# under rays closer than 2 degrees have a depth error of 1/(f·θ) per pixel
# of noise (3 % at f = 1000 px), and COLMAP keeps points down to 1.5 degrees.
MAX_ABS_K1 = 1.0
FOCAL_TOLERANCE = 0.30
MIN_MEDIAN_RAY_ANGLE_DEG = 2.0

# The final bundle adjustment's robust loss (docs/decisions/sfm.md, "a robust
# final bundle adjustment"): Cauchy, its scale CAUCHY_C times the residuals'
# own noise (1.4826 x the median absolute residual coordinate of COLMAP's
# least-squares model). 2.385 is the Cauchy constant with 95 % of least
# squares' efficiency under Gaussian noise (Holland & Welsch 1977), so inliers
# keep nearly full weight while the few matches off by a pixel or more (edge
# and specular features) stop pulling every pose the same way.
CAUCHY_C = 2.385


@dataclass(frozen=True)
class Reconstruction:
    """Cameras and points recovered from an unordered image set.

    Attributes
    ----------
    image_names : tuple of str
        One per input image, in input order.
    registered : ndarray, (N,) bool
        Whether each image's pose was recovered.
    cam_from_world_R : ndarray, (N, 3, 3) float64
    cam_from_world_t : ndarray, (N, 3) float64
        ``x_cam = R x_world + t`` (NaN for unregistered images). The world
        frame and scale are COLMAP's (arbitrary similarity).
    camera : capture.camera.Camera
        The shared camera (fixed when given, else as estimated).
    points : ndarray, (P, 3) float64
    colors : ndarray, (P, 3) uint8
    track_length : ndarray, (P,) int
    info : dict
        Counts, mean reprojection error (px), options, timings, per view the
        most verified matches it shares with another view
        (``verified_matches``), the median largest ray angle of the points
        (``median_ray_angle_deg``).
    colmap_text : dict
        COLMAP's text model, ``{"cameras.txt": str, "images.txt": str,
        "points3D.txt": str}`` (COLMAP's own conventions: pixel centres at
        +0.5, image names as given).
    """

    image_names: tuple[str, ...]
    registered: np.ndarray
    cam_from_world_R: np.ndarray
    cam_from_world_t: np.ndarray
    camera: object
    points: np.ndarray
    colors: np.ndarray
    track_length: np.ndarray
    info: dict = field(default_factory=dict, compare=False)
    colmap_text: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        n = len(self.image_names)
        if self.cam_from_world_R.shape != (n, 3, 3) or self.cam_from_world_t.shape != (n, 3):
            raise ValueError("cam_from_world_R, cam_from_world_t: expected (N, 3, 3) and (N, 3)")
        if self.points.shape != (len(self.colors), 3):
            raise ValueError("points, colors: expected (P, 3) each")

    @property
    def centres(self) -> np.ndarray:
        """Camera centres ``(N, 3)`` in the world frame, ``-Rᵀ t`` (NaN if unregistered)."""
        return -np.einsum("nji,nj->ni", self.cam_from_world_R, self.cam_from_world_t)

    def cameras_dict(self) -> dict:
        """Our ``cameras.json`` layout: the shared camera and one pose per image."""
        cam = self.camera.to_dict()
        views = []
        for i, name in enumerate(self.image_names):
            v = {"image": name, "registered": bool(self.registered[i])}
            if self.registered[i]:
                v["cam_from_world"] = {"R": self.cam_from_world_R[i].tolist(),
                                       "t": self.cam_from_world_t[i].tolist()}
            views.append(v)
        return {"schema": "lumigraph.cameras", "schema_version": 1, "camera": cam, "views": views}

    OUTPUTS = ("cameras.json", "points.ply", "cameras.txt", "images.txt", "points3D.txt")

    def save(self, folder, *, meta: dict) -> None:
        """Write ``points.ply``, ``cameras.json`` and COLMAP's text model
        (``cameras.txt``, ``images.txt``, ``points3D.txt``), each with its
        sidecar, into ``folder`` (the names in ``OUTPUTS``)."""
        from pathlib import Path

        from lumigraph.capture.artifact import dumps_json, write_artifact
        from lumigraph.capture.io import write_ply

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        write_artifact(folder / "cameras.json",
                       lambda tmp: tmp.write_text(dumps_json(self.cameras_dict())), meta=meta)
        write_artifact(folder / "points.ply", lambda tmp: write_ply(tmp, self.points, self.colors),
                       meta=meta)
        for name, text in self.colmap_text.items():
            write_artifact(folder / name, lambda tmp, text=text: tmp.write_text(text), meta=meta)


def align_similarity(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity ``dst ≈ s R src + t`` (Umeyama 1991).

    Parameters
    ----------
    src, dst : ndarray, (N, 3), N >= 3 and not collinear

    Returns
    -------
    s : float
    R : ndarray, (3, 3) rotation (det +1)
    t : ndarray, (3,)
    """
    src = np.asarray(src, np.float64)
    dst = np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(src) < 3:
        raise ValueError(f"src, dst: expected two (N >= 3, 3) arrays, got {src.shape} and {dst.shape}")
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    E = np.eye(3)
    E[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = U @ E @ Vt
    var = (a ** 2).sum() / len(src)
    if var <= 0:
        raise ValueError("src: all points coincide")
    s = float(np.trace(np.diag(S) @ E) / var)
    return s, R, md - s * R @ ms


def check_views(images, names) -> None:
    """Refuse inputs COLMAP would fail on obscurely (see the module docstring)."""
    if len(images) < 2:
        raise InputError("images", f"structure from motion needs at least 2 images, got {len(images)}")
    shape0 = images[0].shape[:2]
    for im, n in zip(images, names, strict=True):
        if im.size == 0:
            raise InputError(n, "empty image")
        if im.shape[:2] != shape0:
            raise InputError(n, f"size {im.shape[1]}x{im.shape[0]} differs from {names[0]}'s "
                                f"{shape0[1]}x{shape0[0]}; give images of one camera")
        if float(np.ptp(im)) == 0:
            raise InputError(n, "image is blank (one value everywhere): nothing to match")
    # duplicate views: identical content up to noise (mean |difference| below
    # one code value) means zero baseline
    small = [np.asarray(im, np.float32)[::4, ::4] for im in images]
    for i in range(len(small)):
        for j in range(i + 1, len(small)):
            if float(np.mean(np.abs(small[i] - small[j]))) < 1.0:
                raise InputError(names[j], f"duplicate view of {names[i]} (the images are the same): "
                                           "a second view must move the camera; drop one")


def reconstruct(images, names, *, camera=None, focal_prior_px: float | None = None,
                centres_prior=None, centre_sigma: float | None = None,
                seed: int = 0, threads: int = 2,
                max_features: int = 4096, peak_threshold: float = PEAK_THRESHOLD) -> Reconstruction:
    """Reconstruct cameras and sparse points from an unordered image set.

    Parameters
    ----------
    images : sequence of ndarray, (H, W) or (H, W, 3) uint8/uint16
        The views (one camera, so one size).
    names : sequence of str
        One file name per image (kept in the result).
    camera : capture.camera.Camera, optional
        Known intrinsics: held fixed in bundle adjustment. Without it COLMAP
        estimates a SIMPLE_RADIAL camera from a focal guess.
    focal_prior_px : float, optional
        Without ``camera``: the focal length expected (px; from EXIF or a
        spec sheet), COLMAP's starting value, and what :func:`assess` holds
        the estimate to.
    centres_prior : ndarray, (N, 3), optional
        Known camera centres (world frame, NaN rows for unknown ones): COLMAP's
        position priors (``use_prior_position``). The result is then in this
        frame and scale instead of an arbitrary similarity.
    centre_sigma : float, optional
        Standard deviation of each prior centre coordinate (the priors' unit;
        default 1 % of the spread of the given centres).
    seed : int
        COLMAP's random seed (every RANSAC: two-view verification, initial
        pair, registration). Same images, camera and seed: the same bytes,
        whatever ``threads`` is.
    threads : int
        CPU threads for feature extraction and matching. Mapping runs on one
        thread: multi-threaded bundle adjustment (Ceres) is not reproducible
        run to run, by COLMAP's own account; COLMAP only threads it above
        50 000 residuals, so small sets lose nothing.
    max_features : int
        SIFT features per image.
    peak_threshold : float
        SIFT's difference-of-Gaussian contrast threshold (COLMAP's default is
        0.0067). Lower keeps the faint features of low-contrast objects on
        dark backgrounds (see ``PEAK_THRESHOLD``).

    Returns
    -------
    Reconstruction
        The largest model COLMAP found, refined by :func:`robust_refine`
        (``info["final_bundle_adjustment"]``: the residual noise and the
        loss scale; the mapping timing includes it).

    Raises
    ------
    InputError
        See :func:`check_views`; a camera whose size differs from the images.
    EstimationError
        Fewer than two images registered.
    """
    import time

    import pycolmap


    names = [os.path.basename(str(n)) for n in names]
    if len(set(names)) != len(names):
        raise InputError("images", "two images share a file name; rename one")
    check_views(images, names)
    h, w = images[0].shape[:2]
    if camera is not None and tuple(camera.image_size) != (w, h):
        raise InputError("camera", f"camera is for {camera.image_size[0]}x{camera.image_size[1]} "
                                   f"images, the views are {w}x{h}")
    t0 = time.perf_counter()
    # COLMAP logs every step to stderr; a pipeline stage keeps stderr for
    # warnings and errors
    old_level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 2
    try:
        priors = _check_priors(centres_prior, centre_sigma, len(images))
        models, files, verified, tmarks, robust = _run_colmap(images, names, camera, focal_prior_px, priors,
                                                      seed, threads, max_features, peak_threshold, t0)
    finally:
        pycolmap.logging.minloglevel = old_level
    t_feat, t_match, t_map = tmarks
    return _result(models, files, verified, names, camera, (w, h), seed,
                   (t0, t_feat, t_match, t_map), robust)


def _check_priors(centres, sigma, n):
    """``(centres (N, 3), sigma)`` checked, or None without priors."""
    if centres is None:
        return None
    c = np.asarray(centres, np.float64)
    if c.shape != (n, 3):
        raise InputError("centres_prior", f"expected ({n}, 3) camera centres, got shape {c.shape}")
    known = np.isfinite(c).all(axis=1)
    if known.sum() < 3:
        raise InputError("centres_prior", "fewer than 3 known camera centres: they cannot fix a frame")
    spread = float(np.linalg.norm(c[known] - c[known].mean(0), axis=1).max())
    if spread == 0:
        raise InputError("centres_prior", "the known camera centres coincide")
    if sigma is None:
        sigma = 0.01 * spread
    if not (np.isfinite(sigma) and sigma > 0):
        raise InputError("centre_sigma", f"expected a positive standard deviation, got {sigma!r}")
    return c, float(sigma)


def _run_colmap(images, names, camera, focal_prior_px, priors, seed, threads, max_features,
                peak_threshold, t0):
    import tempfile
    import time
    from pathlib import Path

    import cv2
    import pycolmap

    with tempfile.TemporaryDirectory(prefix="lumigraph-sfm-") as tmp:
        tmp = Path(tmp)
        img_dir = tmp / "images"
        img_dir.mkdir()
        for im, n in zip(images, names, strict=True):
            a = np.asarray(im)
            if a.dtype == np.uint16:
                a = (a / 257.0).round().astype(np.uint8)
            if a.ndim == 3:
                a = a[..., :3][..., ::-1]
            cv2.imwrite(str(img_dir / (Path(n).stem + ".png")), np.ascontiguousarray(a))
        files = [Path(n).stem + ".png" for n in names]
        ro = pycolmap.ImageReaderOptions()
        if camera is not None:
            K, dist = camera.K, camera.dist
            # COLMAP's pixel centres sit at +0.5
            fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5
            ro.camera_model = "FULL_OPENCV" if dist.size == 8 else "OPENCV"
            params = [fx, fy, cx, cy, *dist[:4]] + ([dist[4], *dist[5:8]] if dist.size == 8 else [])
            if dist.size != 8 and dist.size > 4 and dist[4] != 0:
                ro.camera_model = "FULL_OPENCV"
                params = [fx, fy, cx, cy, *dist[:5], 0.0, 0.0, 0.0]
            ro.camera_params = ",".join(repr(float(p)) for p in params)
        elif focal_prior_px is not None:
            # a starting focal (COLMAP refines it); its own guess is 1.2 x the
            # longer side
            h, w = images[0].shape[:2]
            ro.camera_model = "SIMPLE_RADIAL"
            ro.camera_params = ",".join(repr(float(p)) for p in (focal_prior_px, w / 2, h / 2, 0.0))
        eo = pycolmap.FeatureExtractionOptions()
        eo.num_threads = threads
        eo.sift.max_num_features = max_features
        eo.sift.peak_threshold = peak_threshold
        pycolmap.set_random_seed(seed)
        db = tmp / "database.db"
        # The extractor's threads store each image when its features are done,
        # and the image ids (which order matching and mapping) would follow
        # that race; importing the images first, one thread in input order,
        # fixes the ids, and the threads then only fill in the features.
        pycolmap.Database.open(db).close()
        pycolmap.import_images(db, img_dir, camera_mode=pycolmap.CameraMode.SINGLE, image_names=files,
                               options=ro)
        if priors is not None:
            _write_priors(db, files, *priors)
        pycolmap.extract_features(db, img_dir, image_names=files, camera_mode=pycolmap.CameraMode.SINGLE,
                                  reader_options=ro, extraction_options=eo, device=pycolmap.Device.cpu)
        t_feat = time.perf_counter()
        mo = pycolmap.FeatureMatchingOptions()
        mo.num_threads = threads
        # a seeded RANSAC per image pair: without it the pairs share one
        # generator, drawn from in whatever order the threads take the pairs
        vo = pycolmap.TwoViewGeometryOptions()
        vo.ransac.random_seed = seed
        pycolmap.match_exhaustive(db, matching_options=mo, verification_options=vo,
                                  device=pycolmap.Device.cpu)
        t_match = time.perf_counter()
        opts = pycolmap.IncrementalPipelineOptions()
        opts.random_seed = seed
        opts.num_threads = 1  # see `threads` in reconstruct()'s docstring
        for k, v in MAPPER.items():
            setattr(opts.mapper, k, v)
        if priors is not None:
            opts.use_prior_position = True
        if camera is not None:
            opts.ba_refine_focal_length = False
            opts.ba_refine_principal_point = False
            opts.ba_refine_extra_params = False
        (tmp / "sparse").mkdir()
        models = pycolmap.incremental_mapping(db, img_dir, tmp / "sparse", options=opts)
        if models:
            best = max(models.values(), key=lambda r: r.num_reg_images())
            robust = robust_refine(best, refine_intrinsics=camera is None,
                                   pose_priors=db_pose_priors(db) if priors is not None else None)
        t_map = time.perf_counter()
        verified = _verified_matches(db, files)
    return models, files, verified, (t_feat, t_match, t_map), robust if models else None


def db_pose_priors(db_path) -> list:
    """The pose priors stored in a COLMAP database (see :func:`_write_priors`)."""
    import pycolmap

    db = pycolmap.Database.open(db_path)
    try:
        return list(db.read_all_pose_priors())
    finally:
        db.close()


def reprojection_residuals(rec) -> np.ndarray:
    """Every observation's reprojection residual ``(M, 2)`` (px, projection
    minus keypoint) in a pycolmap reconstruction."""
    out = []
    for im in rec.images.values():
        if not im.has_pose:
            continue
        obs = [(p.xy, p.point3D_id) for p in im.points2D if p.has_point3D()]
        if not obs:
            continue
        xy = np.array([o[0] for o in obs])
        X = np.array([rec.points3D[o[1]].xyz for o in obs])
        cw = im.cam_from_world()
        Xc = X @ cw.rotation.matrix().T + cw.translation
        out.append(rec.cameras[im.camera_id].img_from_cam(Xc, check_cheirality=False) - xy)
    return np.concatenate(out) if out else np.zeros((0, 2))


def robust_refine(rec, *, refine_intrinsics: bool, pose_priors=None) -> dict:
    """Bundle-adjust a pycolmap reconstruction in place under a Cauchy loss
    scaled to its own residual noise.

    COLMAP's global bundle adjustment minimises squared reprojection error
    (Schönberger & Frahm 2016, eq. 3 with the trivial loss), so a few
    observations off by a pixel or more weigh as much as hundreds of good
    ones. Here the residual noise is estimated robustly from the least-
    squares model, ``σ = 1.4826 · median |r|`` over the residual
    coordinates (the MAD estimate), and the model is refined once more with
    ``ρ(s) = a² log(1 + s / a²)``, ``s = |r|²``, ``a = CAUCHY_C · σ`` (Ceres'
    CauchyLoss; Triggs et al., "Bundle Adjustment — A Modern Synthesis",
    2000, §3.3 on robust cost functions). One pass with the scale held: re-
    estimating σ from the robust fit shrinks it further each time (the fit
    itself makes the inliers agree better).

    Parameters
    ----------
    rec : pycolmap.Reconstruction
        Refined in place.
    refine_intrinsics : bool
        Also refine the focal length and the extra (distortion) parameters
        (the principal point stays, as in COLMAP's mapper).
    pose_priors : list of pycolmap.PosePrior, optional
        Position priors kept in the cost (the model then stays in their frame).

    Returns
    -------
    dict
        ``{"loss": "cauchy", "sigma_px", "scale_px", "rms_before_px", "rms_after_px"}``.

    Examples
    --------
    >>> import pycolmap
    >>> robust_refine(pycolmap.Reconstruction(), refine_intrinsics=False)["loss"]
    'none: no observations'
    """
    import pycolmap

    r = reprojection_residuals(rec)
    if r.size == 0:
        return {"loss": "none: no observations"}
    sigma = 1.4826 * float(np.median(np.abs(r)))
    scale = CAUCHY_C * sigma
    if not sigma > 1e-9:  # numerically exact (a synthetic model): nothing to down-weight
        return {"loss": "none: zero residuals", "sigma_px": sigma}
    bo = pycolmap.BundleAdjustmentOptions()
    bo.print_summary = False
    bo.refine_focal_length = bo.refine_extra_params = refine_intrinsics
    bo.refine_principal_point = False
    bo.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    bo.ceres.loss_function_scale = scale
    # one thread: Ceres' threaded solve is not reproducible run to run
    bo.ceres.solver_options.num_threads = 1
    if pose_priors:
        config = pycolmap.BundleAdjustmentConfig()
        for i in rec.reg_image_ids():
            config.add_image(i)
        pycolmap.create_pose_prior_bundle_adjuster(
            bo, pycolmap.PosePriorBundleAdjustmentOptions(), config, pose_priors, rec).solve()
    else:
        pycolmap.bundle_adjustment(rec, bo)
    after = reprojection_residuals(rec)
    return {"loss": "cauchy", "sigma_px": sigma, "scale_px": scale,
            "rms_before_px": float(np.sqrt(np.mean(np.sum(r ** 2, 1)))),
            "rms_after_px": float(np.sqrt(np.mean(np.sum(after ** 2, 1))))}


def _write_priors(db_path, files, centres, sigma) -> None:
    """Known camera centres as COLMAP position priors (Cartesian, isotropic sigma)."""
    import pycolmap

    db = pycolmap.Database.open(db_path)
    try:
        ids = {im.name: im for im in db.read_all_images()}
        for f, c in zip(files, centres, strict=True):
            if not np.isfinite(c).all():
                continue
            db.write_pose_prior(pycolmap.PosePrior(
                corr_data_id=ids[f].data_id, position=np.asarray(c, np.float64),
                position_covariance=np.eye(3) * sigma ** 2,
                coordinate_system=pycolmap.PosePriorCoordinateSystem.CARTESIAN))
    finally:
        db.close()


def _verified_matches(db_path, files) -> list[int]:
    """Per image, the most geometrically verified matches it shares with any
    other image (why a view did not register, when it did not)."""
    import pycolmap

    best = dict.fromkeys(files, 0)
    db = pycolmap.Database.open(db_path)
    try:
        names = {im.image_id: im.name for im in db.read_all_images()}
        for pid, n in zip(*db.read_two_view_geometry_num_inliers(), strict=True):
            for i in pycolmap.pair_id_to_image_pair(pid):
                best[names[i]] = max(best[names[i]], int(n))
    finally:
        db.close()
    return [best[f] for f in files]


def _result(models, files, verified, names, camera, size, seed, marks, robust=None):
    import pycolmap

    from lumigraph.capture.camera import Camera

    w, h = size
    t0, t_feat, t_match, t_map = marks
    order = sorted(range(len(names)), key=lambda i: verified[i])
    shown = ", ".join(f"{names[i]} ({verified[i]} verified matches)" for i in order[:4])
    shown += f" and {len(names) - 4} more" if len(names) > 4 else ""
    if not models:
        if max(verified, default=0) >= 100:  # COLMAP's init_min_num_inliers: they match well
            raise EstimationError("images", "no pair of views could start a model although they "
                                            "match: too small a baseline between the views (or a "
                                            f"plane seen from one spot): {shown}")
        raise EstimationError("images", "COLMAP registered no image pair: too little overlap or "
                                        f"texture between the views: {shown}")
    rec = max(models.values(), key=lambda r: r.num_reg_images())
    if rec.num_reg_images() < 2:
        raise EstimationError("images", f"fewer than two views could be registered: {shown}")
    n = len(names)
    Rs = np.full((n, 3, 3), np.nan)
    ts = np.full((n, 3), np.nan)
    reg = np.zeros(n, bool)
    index = {f: i for i, f in enumerate(files)}
    for im in rec.images.values():
        if not im.has_pose:
            continue
        i = index[im.name]
        cw = im.cam_from_world()
        Rs[i] = cw.rotation.matrix()
        ts[i] = cw.translation
        reg[i] = True
    cam = next(iter(rec.cameras.values()))
    if camera is None:
        f, cx, cy = cam.params[:3]
        k1 = cam.params[3] if len(cam.params) > 3 else 0.0
        est = Camera(np.array([[f, 0, cx - 0.5], [0, f, cy - 0.5], [0, 0, 1]]), [k1, 0, 0, 0, 0],
                     (w, h), "k1", {"source": f"COLMAP {cam.model.name}"})
    else:
        est = camera
    pts = list(rec.points3D.values())
    P = np.array([p.xyz for p in pts]).reshape(-1, 3)
    C = np.array([p.color for p in pts], np.uint8).reshape(-1, 3)
    L = np.array([p.track.length() for p in pts], int)
    centres = -np.einsum("nji,nj->ni", Rs, ts)
    id_index = {im.image_id: index[im.name] for im in rec.images.values()}
    angles = [_max_ray_angle(p.xyz, centres[[id_index[e.image_id] for e in p.track.elements]])
              for p in pts]
    info = {"method": "pycolmap incremental SfM", "pycolmap": pycolmap.__version__,
            "verified_matches": dict(zip(names, verified, strict=True)),
            "median_ray_angle_deg": float(np.median(angles)) if angles else 0.0,
            "registered": int(reg.sum()), "images": n, "points": len(P),
            "models_found": len(models),
            "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()),
            "fixed_intrinsics": camera is not None, "seed": seed,
            "final_bundle_adjustment": robust,
            "timings_s": {"features": t_feat - t0, "matching": t_match - t_feat,
                          "mapping": t_map - t_match}}
    return Reconstruction(tuple(names), reg, Rs, ts, est, P, C, L, info,
                          colmap_text=_colmap_text(rec, dict(zip(files, names, strict=True))))


def _max_ray_angle(x, centres) -> float:
    """The widest angle (degrees) between the rays from ``centres`` to ``x``."""
    d = centres - x
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return float(np.degrees(np.arccos(np.clip((d @ d.T).min(), -1.0, 1.0))))


def _colmap_text(rec, rename: dict) -> dict:
    """COLMAP's text model as strings, the images under their given names."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory(prefix="lumigraph-sfm-text-") as tmp:
        rec.write_text(tmp)
        text = {n: (Path(tmp) / n).read_text() for n in ("cameras.txt", "images.txt", "points3D.txt")}
    lines = text["images.txt"].split("\n")
    first = next((i for i, ln in enumerate(lines) if not ln.startswith("#")), len(lines))
    for i in range(first, len(lines), 2):  # image lines alternate with their 2-D point lines
        if not lines[i]:
            continue
        head, _, name = lines[i].rpartition(" ")
        lines[i] = f"{head} {rename.get(name, name)}"
    text["images.txt"] = "\n".join(lines)
    return text


def assess(rec: Reconstruction, *, min_registered: float = 0.5,
           focal_prior_px: float | None = None) -> list[str]:
    """Why a reconstruction cannot be used; an empty list when it can.

    A model is refused (each reason one phrase) when

    * fewer than ``min_registered`` of the views (and fewer than two)
      registered — the views left out are named with the most verified
      matches each shares with another view;
    * the intrinsics were estimated from two views only (the focal length
      of one shared camera is not determined by two views);
    * the estimated radial term is beyond ``MAX_ABS_K1``, or the focal
      length is more than ``FOCAL_TOLERANCE`` off ``focal_prior_px``;
    * the points are seen under a median widest ray angle below
      ``MIN_MEDIAN_RAY_ANGLE_DEG`` (views too close together: depth, and
      with it the poses, are not determined).

    Parameters
    ----------
    rec : Reconstruction
    min_registered : float in [0, 1]
    focal_prior_px : float, optional
        The focal length expected (EXIF, spec sheet); without it the focal
        is not checked (COLMAP keeps it within 0.1-10x its 1.2x-width guess).

    Returns
    -------
    list of str

    Examples
    --------
    >>> from lumigraph.capture.camera import Camera
    >>> cam = Camera(np.diag([500., 500, 1]), [2.0, 0, 0, 0, 0], (64, 48), "k1", {})
    >>> R = np.repeat(np.eye(3)[None], 2, 0)
    >>> rec = Reconstruction(("a.png", "b.png"), np.array([True, False]), R, np.zeros((2, 3)),
    ...                      cam, np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0, int),
    ...                      {"verified_matches": {"a.png": 9, "b.png": 9}})
    >>> for r in assess(rec): print(r)
    registered 1 of 2 views, fewer than 0.5 of them (2); not registered: b.png (9 verified matches)
    radial distortion k1 = 2 is beyond +-1 (a failed self-calibration)
    """
    n = len(rec.image_names)
    got = int(rec.registered.sum())
    need = max(2, int(np.ceil(min_registered * n)))
    why = []
    if got < need:
        vm = rec.info.get("verified_matches", {})
        left = [f"{name} ({vm[name]} verified matches)" if name in vm else name
                for name, ok in zip(rec.image_names, rec.registered, strict=True) if not ok]
        shown = ", ".join(left[:4]) + (f" and {len(left) - 4} more" if len(left) > 4 else "")
        why.append(f"registered {got} of {n} views, fewer than {min_registered:g} of them "
                   f"({need}); not registered: {shown}")
    estimated = not rec.info.get("fixed_intrinsics", False)
    if estimated and got == 2:
        why.append("the camera was estimated from two views, which do not determine the focal "
                   "length; give the intrinsics (camera.json) or more views")
    if estimated:
        k1 = float(rec.camera.dist[0]) if rec.camera.dist.size else 0.0
        if abs(k1) > MAX_ABS_K1:
            why.append(f"radial distortion k1 = {k1:.3g} is beyond +-{MAX_ABS_K1:g} "
                       "(a failed self-calibration)")
        f = float(rec.camera.K[0, 0])
        if focal_prior_px is not None and abs(f / focal_prior_px - 1) > FOCAL_TOLERANCE:
            why.append(f"estimated focal {f:.0f} px is {100 * abs(f / focal_prior_px - 1):.0f} % off "
                       f"the expected {focal_prior_px:.0f} px (more than "
                       f"{100 * FOCAL_TOLERANCE:.0f} %)")
    ang = rec.info.get("median_ray_angle_deg")
    if ang is not None and got >= 2 and ang < MIN_MEDIAN_RAY_ANGLE_DEG:
        why.append(f"the views are too close together: points are seen under a median ray angle "
                   f"of {ang:.2g} deg (below {MIN_MEDIAN_RAY_ANGLE_DEG:g}), so depth and poses are "
                   "not determined; move the camera more between views")
    return why


def exif_focal_px(path, size) -> float | None:
    """Focal length in pixels from a file's EXIF (35 mm equivalent, or the
    focal length and the focal-plane resolution), None when absent.

    ``size`` is the image's ``(width, height)``. The 35 mm equivalent is
    taken over the longer side (36 mm), as COLMAP does.
    """
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow is a dependency of matplotlib
        return None
    try:
        with Image.open(path) as im:
            exif = im.getexif().get_ifd(0x8769)
    except Exception:  # noqa: BLE001 - no EXIF is not an error
        return None
    f35 = exif.get(0xA405)  # FocalLengthIn35mmFilm
    if f35:
        return float(f35) * max(size) / 36.0
    f, xres, unit = exif.get(0x920A), exif.get(0xA20E), exif.get(0xA210, 2)
    if f and xres:
        mm_per_unit = {2: 25.4, 3: 10.0, 4: 1.0}.get(int(unit))
        if mm_per_unit:
            return float(f) * float(xres) / mm_per_unit
    return None


def centre_error(rec: Reconstruction, gt_centres: np.ndarray) -> dict:
    """Camera-centre error after the best similarity alignment to ground truth.

    Returns ``{"max", "rms"}`` (GT units) over registered views, the fitted
    ``scale`` and the count of views used.
    """
    gt = np.asarray(gt_centres, np.float64)
    c = rec.centres
    ok = rec.registered
    if ok.sum() < 3:
        raise EstimationError("reconstruction", "fewer than 3 registered views: cannot align")
    s, R, t = align_similarity(c[ok], gt[ok])
    e = np.linalg.norm((s * c[ok] @ R.T + t) - gt[ok], axis=1)
    return {"max": float(e.max()), "rms": float(np.sqrt(np.mean(e ** 2))), "scale": s,
            "aligned_views": int(ok.sum())}


def rotation_error_deg(rec: Reconstruction, gt_R: np.ndarray, gt_centres: np.ndarray) -> float:
    """Largest rotation error (degrees) of the registered views after the
    similarity that best aligns the camera centres to ground truth (the
    gauge :func:`centre_error` uses); ``gt_R`` is ``(N, 3, 3)`` cam_from_world."""
    ok = rec.registered
    if ok.sum() < 3:
        raise EstimationError("reconstruction", "fewer than 3 registered views: cannot align")
    _, R, _ = align_similarity(rec.centres[ok], np.asarray(gt_centres, np.float64)[ok])
    err = [np.arccos(np.clip((np.trace(np.asarray(gt_R)[i].T @ rec.cam_from_world_R[i] @ R.T) - 1) / 2,
                             -1.0, 1.0)) for i in np.flatnonzero(ok)]
    return float(np.degrees(max(err)))

