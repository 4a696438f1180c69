"""Model-based stereo (Debevec, Taylor & Malik 1996): detail on a rough model
from a wide-baseline key/offset pair.

P. E. Debevec, C. J. Taylor and J. Malik, "Modeling and Rendering
Architecture from Photographs: A hybrid geometry- and image-based approach",
SIGGRAPH 1996, doi:10.1145/237170.237191 (reference ch. 5, §5.3.2, "Stage 3.
Model-based stereo", Figs. 5.12 and 5.13).

Two photographs taken far apart foreshorten a surface differently, so plain
window matching (eq. 5.1) between them fails. Given a *rough model* of the
scene (a facade plane, a block, without its detail), the *offset* image is
projected onto the model and re-rendered from the *key* viewpoint: the
*warped offset image* (Fig. 5.12c). Where the real surface lies on the model
the warped image equals the key image; detail off the model appears as a
small disparity along the key image's epipolar lines (Fig. 5.13), which
window matching recovers. Here that search is parametrised by the offset
``δ`` of the surface from the model along each key ray (in the unit of the
rig's ``T``): the key pixel ``x`` with unit-``z`` ray ``r(x)`` and model
depth ``z_m(x)`` is tried at the 3-D point

    X(δ) = (z_m(x) + δ) · r(x)            (key camera frame; eq. 5.2's ray)

projected into the offset camera (``x_offset = R X + T``, with its lens
distortion) and the offset image sampled there (bilinear, ``cv2.remap``),
giving ``warped_δ``; ``δ = 0`` is exactly the warped offset image of
Fig. 5.12c. Stepping ``δ`` moves the sample along the epipolar line of ``x``
in the offset image, i.e. along the key image's epipolar line in the warped
image. The step is chosen so that the sample moves at most one offset-image
pixel per step. The depth along the key camera's ``z`` is ``z_m + δ``.

Two matching costs along that search (``cost``):

- ``"sgm"`` (the default): semi-global matching on the model-warped search
  (H. Hirschmüller, "Stereo processing by semiglobal matching and mutual
  information", TPAMI 30(2), 2008, doi:10.1109/TPAMI.2007.1166; the issue
  that asked for it: "model-based stereo can use the same cost and
  aggregation along its search" as :mod:`lumigraph.stereo.hirschmuller2008`).
  Per ``δ`` the warped offset luma ``warped_δ`` is census-transformed in the
  key view's geometry (9×7, so both codes cover the same patch of the model:
  the foreshortening is undone by the warp) and compared with the key's
  census code by Hamming distance, summed over a 3×3 box: the cost volume
  ``C(x, δ)`` (``H × W × steps``; Hirschmüller & Scharstein, TPAMI 31(9),
  2009, doi:10.1109/TPAMI.2008.221, for census as SGM's cost). ``C`` is
  aggregated along 8 paths with the ``δ`` step in the place of the disparity
  (eqs. 13–14, ``P1`` for one step, ``P2`` adapted to the key image's
  intensity step; :func:`lumigraph.stereo.hirschmuller2008.aggregate`, the
  compiled kernel ``stereo/_sgm.c``), and the best ``δ`` of the sum ``S``
  refined by a parabola through ``S``. The tests below that judge a match by
  its cost use eq. 5.1's mean squared difference of the recovered surface
  (each key pixel's offset image sample at its own ``δ``, over the
  ``window`` box); the uniqueness test uses ``S``.
- ``"ssd"``: for each ``δ`` the mean squared difference over a ``window ×
  window`` box (eq. 5.1); the best ``δ`` per pixel (winner-take-all) is
  refined by a parabola through its neighbours.

On the bench's facade sweep (``lumigraph bench stereo``, views 20-65° apart;
share of seen key pixels off by > 1 % of depth) the SGM cost reads 0.070 /
0.084 / 0.136 / 0.219 at 20 / 35 / 50 / 65°, the SSD cost 0.168 / 0.189 /
0.258 / 0.334 and OpenCV StereoSGBM on the rectified pair 0.114 / 0.156 /
0.228 / 0.414 (its best window): docs/decisions/model-stereo-sgm.md.

A pixel is left unknown (NaN) when

- the model is absent there (``model_depth`` NaN or ``<= 0``);
- its model point is not seen by the offset camera: outside the offset
  frame, behind it, or hidden by a nearer part of the model (a z-buffer of
  the model in the offset view);
- its window lacks texture: the key image's window standard deviation is
  below ``texture_snr · σ`` (``σ`` the key image's noise, estimated);
- the best ``δ`` is not unique: some ``δ`` more than one step away costs
  less than ``(1 + uniqueness)`` times the best (``S`` with ``cost="sgm"``);
- the best ``δ`` lies at either end of the range: the surface is probably
  farther from the model than ``max_offset`` (a wrong model or range);
- the best cost is implausibly high for a true match: above ``max_cost``
  times the key window's variance (a point of the key view hidden from the
  offset camera by detail the model lacks, e.g. the reveal of a recess).
- its recovered point lies behind a better-matching recovered point on the
  same offset pixel (half-occlusion);
- it fails the left-right check: the same search run with the roles
  swapped (the offset view as key, the model re-seen from the offset camera
  by :func:`model_in_offset_view`) finds, on the offset pixel the key
  point lands on, a point that projects back more than ``left_right``
  units of ``1 + k`` key pixels from the key pixel (``k`` key pixels per
  offset pixel, from the model's key-to-offset map). This is
  what refuses most key pixels the *relief* hides from the offset camera
  (the model says they are visible, so no model test can).

Examples
--------
>>> from lumigraph.capture.scenes.model_stereo import render_facade
>>> from lumigraph.capture.rig import Rig
>>> s = render_facade(size=(128, 96), seed=0, rng=np.random.default_rng(0), supersample=2, noise=0.5)
>>> g = s.gt["rig"]
>>> rig = Rig.from_dict(g)
>>> res = model_stereo(s.images[0], s.images[1], s.gt_arrays["model_depth"], rig, max_offset=0.35,
...                    window=7)
>>> err = np.abs(res.depth - s.gt_arrays["depth"])   # metres; the relief is 0.18-0.27 m deep
>>> bool(0 < np.nanmedian(err) < 0.05), bool(res.valid_fraction > 0.5)
(True, True)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError

MAX_STEPS = 257
WINDOW_RANGE = (3, 63)  # odd SSD window sides model_stereo accepts
COSTS = ("ssd", "sgm")  # the matching costs model_stereo offers
# cost="sgm": census cost box, and the path penalties per box pixel (census
# bits) of hirschmuller2008.aggregate; how they were chosen:
# docs/decisions/model-stereo-sgm.md
SGM = {"cost_window": 3, "p1": 12, "p2": 200, "edge": 8, "paths": 8}


@dataclass(frozen=True)
class ModelStereo:
    """Depth of a key view recovered as offsets from a rough model.

    Attributes
    ----------
    depth : ndarray, (H, W) float32
        ``z`` in the key camera frame (unit of the rig's ``T``): ``model_depth
        + offset``; NaN where unknown.
    offset : ndarray, (H, W) float32
        ``δ``, the surface's offset from the model along the key ray, measured
        in key-camera ``z`` (positive = behind the model); NaN where unknown.
    warped : ndarray, (H, W) or (H, W, C) float32
        The offset image projected onto the model and seen from the key
        camera (``δ = 0``, Fig. 5.12c), in the offset image's code values;
        NaN where the model is absent or its point is unseen by the offset
        camera.
    cost : ndarray, (H, W) float32
        Best mean squared difference (key-image code values², eq. 5.1; with
        ``cost="sgm"`` that of the recovered surface, each key pixel's
        offset sample at its own ``δ``); NaN where never computed.
    valid : ndarray, (H, W) bool
        Where ``depth`` is known.
    info : dict
        Parameters, the ``δ`` range and step, the noise estimate, the pixel
        counts each test rejected, timings and warnings.
    """

    depth: np.ndarray
    offset: np.ndarray
    warped: np.ndarray
    cost: np.ndarray
    valid: np.ndarray
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        d = np.asarray(self.depth)
        if d.ndim != 2 or d.dtype != np.float32:
            raise ValueError(f"depth: expected (H, W) float32, got {d.shape} {d.dtype}")
        for name in ("offset", "cost", "valid"):
            if np.shape(getattr(self, name)) != d.shape:
                raise ValueError(f"{name}: expected shape {d.shape}, got {np.shape(getattr(self, name))}")
        if np.shape(self.warped)[:2] != d.shape:
            raise ValueError(f"warped: expected shape {d.shape}[+C], got {np.shape(self.warped)}")
        if not np.array_equal(np.isfinite(d), np.asarray(self.valid, bool)):
            raise ValueError("valid: must be exactly where depth is finite")
        if (d <= 0).any():  # NaN compares False
            raise ValueError("depth: values must be > 0 (in front of the key camera)")

    @property
    def valid_fraction(self) -> float:
        """Share of all key pixels with a depth."""
        return float(np.mean(self.valid))

    def save(self, path, *, meta: dict) -> None:
        """Write the depth as PFM (NaN stored as inf) with its ``.meta.json``."""
        from lumigraph.capture.artifact import write_artifact
        from lumigraph.capture.io import write_pfm

        write_artifact(path, lambda tmp: write_pfm(tmp, self.depth), meta=meta)


# ----------------------------------------------------------------- geometry
def key_rays(camera, shape) -> np.ndarray:
    """Unit-``z`` rays ``(H, W, 3)`` float64 of every key pixel centre, in the
    key camera frame (lens distortion inverted by :meth:`Camera.unproject`)."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return camera.unproject(np.stack([xs.ravel(), ys.ravel()], axis=1)).reshape(h, w, 3)


def _project_offset(rig, a, z):
    """Offset-image pixels ``(H, W, 2)`` and offset-frame depth ``(H, W)`` of
    the key-frame points ``z · r`` given ``a = R r`` (so ``x_o = z a + T``)."""
    Xo = a * z[..., None] + rig.T
    px = rig.right.project(Xo.reshape(-1, 3)).reshape(*z.shape, 2)
    return px, Xo[..., 2]


def _inside(px, size):
    w, h = size
    with np.errstate(invalid="ignore"):
        return ((px[..., 0] > -0.5) & (px[..., 0] < w - 0.5) & (px[..., 1] > -0.5)
                & (px[..., 1] < h - 0.5))


def _model_visible(px, zo, ok, size, tolerance, *, close=True):
    """Which model points (``ok``) the offset camera sees: a z-buffer of the
    model splatted at the nearest offset pixel, its gaps closed by a 3×3
    minimum (the model is sampled at the key image's density), and a point
    counted as hidden only when something is nearer by more than
    ``tolerance`` (an array, same unit as ``zo``)."""
    import cv2

    w, h = size
    zbuf = np.full((h, w), np.inf, np.float32)
    ix = np.rint(px[ok]).astype(np.intp)
    np.minimum.at(zbuf, (ix[:, 1], ix[:, 0]), zo[ok].astype(np.float32))
    if close:
        zbuf = cv2.erode(zbuf, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
    vis = np.zeros(zo.shape, bool)
    vis[ok] = zo[ok] <= zbuf[ix[:, 1], ix[:, 0]] + tolerance[ok]
    return vis


def _hidden_by_better(px, zo, cost, ok, size, tolerance):
    """Recovered points (``ok``) that lie behind the nearest recovered point
    on the same offset pixel by more than ``tolerance · zo`` while matching
    worse than it (higher ``cost``). The cost condition keeps a wrong, too
    near match from hiding correct points behind it."""
    w, _ = size
    idx = np.flatnonzero(ok)
    ix = np.rint(px.reshape(-1, 2)[idx]).astype(np.intp)
    pid = ix[:, 1] * w + ix[:, 0]
    z = zo.ravel()[idx]
    order = np.lexsort((z, pid))
    pid_s = pid[order]
    first = np.r_[True, pid_s[1:] != pid_s[:-1]]
    head = order[np.maximum.accumulate(np.where(first, np.arange(len(order)), 0))]
    near_z = np.empty_like(z)
    near_c = np.empty_like(z)
    near_z[order] = z[head]
    near_c[order] = cost.ravel()[idx][head]
    out = np.zeros(ok.shape, bool)
    out.ravel()[idx] = (z > near_z * (1 + tolerance)) & (cost.ravel()[idx] > near_c)
    return out


def model_in_offset_view(model_depth: np.ndarray, rig) -> np.ndarray:
    """The rough model seen from the offset camera: its offset-frame ``z`` per
    offset pixel, by forward projection and a z-buffer.

    The model is only given as a key-view depth map, so it is resampled on a
    grid ``f`` times finer than the key pixels (bilinear in depth, ``f`` the
    smallest integer that keeps the samples under half an offset pixel apart
    at the 99th percentile of the key-to-offset stretch, at most 4), each
    sample projected into the offset camera and the nearest surface kept per
    offset pixel. Bilinear samples straddling a model discontinuity (the four
    neighbours' depths differ by more than 5 %) are dropped rather than
    bridged, so no phantom surface joins two model pieces.

    Parameters
    ----------
    model_depth : ndarray, (H, W)
        Key-camera ``z`` of the model per key pixel; NaN or ``<= 0`` = absent.
    rig : capture.rig.Rig
        ``left`` = key, ``right`` = offset, ``x_offset = R x_key + T``.

    Returns
    -------
    ndarray, (H', W') float64
        Offset-camera ``z`` of the nearest model point on each offset pixel
        (``rig.right.image_size``), NaN where no model point projects.

    Examples
    --------
    >>> from lumigraph.capture.camera import Camera
    >>> from lumigraph.capture.rig import Rig
    >>> K = np.array([[40., 0, 19.5], [0, 40, 14.5], [0, 0, 1]])
    >>> cam = Camera(K, np.zeros(5), (40, 30))
    >>> a = np.radians(20)
    >>> R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    >>> T = -R @ [4 * np.sin(a), 0, 4 - 4 * np.cos(a)]   # 20 deg round, aiming at (0, 0, 4)
    >>> rig = Rig.from_pose(cam, cam, R, T)
    >>> zo = model_in_offset_view(np.full((30, 40), 4.0), rig)   # a fronto-parallel plane, 4 m
    >>> X = cam.unproject(np.array([[20.0, 15.0]])) * zo[15, 20]   # back to the key frame
    >>> bool(abs((rig.R.T @ (X[0] - rig.T))[2] - 4.0) < 0.02), bool(np.isfinite(zo[2:-2, 4:]).all())
    (True, True)
    """
    zm = _check_model(model_depth, rig)
    h, w = zm.shape
    wo, ho = rig.right.image_size
    px0, _ = _project_offset(rig, key_rays(rig.left, (h, w)) @ rig.R.T, np.where(np.isfinite(zm), zm, 1.0))
    px0 = np.where(np.isfinite(zm)[..., None], px0, np.nan)
    steps = np.concatenate([np.linalg.norm(np.diff(px0, axis=1), axis=-1).ravel(),
                            np.linalg.norm(np.diff(px0, axis=0), axis=-1).ravel()])
    steps = steps[np.isfinite(steps)]
    stretch = float(np.percentile(steps, 99)) if steps.size else 1.0
    f = int(np.clip(np.ceil(2 * stretch), 1, 4))
    # sample positions on [0, W-1] x [0, H-1] at spacing 1/f (the key grid included)
    xs = np.arange((w - 1) * f + 1) / f
    ys = np.arange((h - 1) * f + 1) / f
    x0 = np.minimum(np.floor(xs).astype(np.intp), w - 2) if w > 1 else np.zeros(len(xs), np.intp)
    y0 = np.minimum(np.floor(ys).astype(np.intp), h - 2) if h > 1 else np.zeros(len(ys), np.intp)
    ax, ay = xs - x0, ys - y0
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    num = np.zeros((len(ys), len(xs)))
    bad = np.zeros((len(ys), len(xs)), bool)
    lo = np.full((len(ys), len(xs)), np.inf)
    hi = np.full((len(ys), len(xs)), -np.inf)
    for yy, wy in ((y0, 1 - ay), (y1, ay)):
        for xx, wx in ((x0, 1 - ax), (x1, ax)):
            wgt = wy[:, None] * wx[None, :]
            z = zm[yy[:, None], xx[None, :]]
            used = wgt > 0
            bad |= used & ~np.isfinite(z)
            num += np.where(used & np.isfinite(z), wgt * np.nan_to_num(z), 0.0)
            lo = np.where(used, np.fmin(lo, z), lo)
            hi = np.where(used, np.fmax(hi, z), hi)
    keep = ~bad & (hi <= 1.05 * lo)
    gy, gx = np.meshgrid(ys, xs, indexing="ij")
    pts = np.stack([gx[keep], gy[keep]], axis=1)
    X = rig.left.unproject(pts) * num[keep][:, None]
    Xo = X @ rig.R.T + rig.T
    px = rig.right.project(Xo)
    zo = Xo[:, 2]
    ok = (zo > 0) & _inside(px, (wo, ho))
    ix = np.rint(px[ok]).astype(np.intp)
    zbuf = np.full(ho * wo, np.inf)
    np.minimum.at(zbuf, ix[:, 1] * wo + ix[:, 0], zo[ok])
    zbuf[~np.isfinite(zbuf)] = np.nan
    return zbuf.reshape(ho, wo)


def _round_trip(rig, depth, rev_depth, model_px):
    """How far a key point comes back: key pixel ``x`` → its point (``depth``
    along the key ray) → the nearest offset pixel ``c`` → the point the
    reverse search found on ``c``'s ray (``rev_depth``, offset-frame ``z``) →
    back into the key image at ``x'``.

    Returns two ``(H, W)`` arrays: ``|x' − x|`` in key pixels (NaN where
    ``depth`` is unknown, the point leaves the offset frame or the reverse
    search has no depth on ``c``), and the unit it is judged in, ``1 + k``
    key pixels, ``k`` the largest key displacement per offset pixel: the
    inverted smallest singular value of the Jacobian of the model's
    key-to-offset map ``model_px`` (H, W, 2), > 1 where the offset view sees
    the model more obliquely than the key view (its median where the
    Jacobian is undefined, at the model's edges). A correct pair of matches comes back
    within ``0.5 + 1.21 k < 1.25 (1 + k)``: each search's sub-step error is
    at most half a step, and a step moves the sample by at most one pixel
    (the reverse step: one key pixel; the forward step: one offset pixel,
    ``k`` key pixels), and rounding ``y`` to ``c`` adds ``√2/2`` offset
    pixels, ``0.71 k`` key pixels."""
    h, w = depth.shape
    dist = np.full((h, w), np.nan)
    unit = np.full((h, w), np.nan)
    known = np.isfinite(depth)
    if not known.any():
        return dist, unit
    J = np.stack([np.gradient(model_px, axis=1), np.gradient(model_px, axis=0)], axis=-1)
    finite = np.isfinite(J).all(axis=(-1, -2))
    smin = np.linalg.svd(np.where(finite[..., None, None], J, 0.0), compute_uv=False)[..., -1]
    k = np.where(finite & (smin > 1e-6), 1.0 / np.maximum(smin, 1e-6), np.nan)
    k = np.where(np.isfinite(k), k, np.nanmedian(k) if np.isfinite(k).any() else 1.0)
    rays = key_rays(rig.left, (h, w))
    px = rig.right.project((rays * np.where(known, depth, 1.0)[..., None]) @ rig.R.T
                           + rig.T).reshape(h, w, 2)
    wo, ho = rig.right.image_size
    ys, xs = np.nonzero(known)
    y = px[ys, xs]
    inside = _inside(y, (wo, ho))
    c = np.rint(np.clip(np.nan_to_num(y), 0, [wo - 1, ho - 1]))
    z = rev_depth[c[:, 1].astype(np.intp), c[:, 0].astype(np.intp)].astype(np.float64)
    Y = rig.right.unproject(c) * z[:, None]
    x2 = rig.left.project((Y - rig.T) @ rig.R)  # x_key = Rᵀ (x_offset − T)
    dist[ys, xs] = np.where(inside, np.hypot(x2[:, 0] - xs, x2[:, 1] - ys), np.nan)
    unit[known] = 1 + k[known]
    return dist, unit


def _reverse_rig(rig):
    """The rig with the roles swapped: offset as key (``x_key = Rᵀ x_offset − Rᵀ T``)."""
    from lumigraph.capture.rig import Rig

    return Rig.from_pose(rig.right, rig.left, rig.R.T, -rig.R.T @ rig.T)


def _remap(image, px):
    import cv2

    mx = np.ascontiguousarray(px[..., 0], np.float32)
    my = np.ascontiguousarray(px[..., 1], np.float32)
    bad = ~np.isfinite(mx) | ~np.isfinite(my)
    mx[bad] = -10.0
    my[bad] = -10.0
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def warp_offset(offset: np.ndarray, model_depth: np.ndarray, rig, *, delta: float = 0.0) -> np.ndarray:
    """The offset image projected onto the model (shifted by ``delta`` along
    the key rays) and seen from the key camera (Fig. 5.12c for ``delta = 0``).

    Parameters
    ----------
    offset : ndarray, (H', W') or (H', W', C)
        The offset view (``rig.right``), any numeric dtype.
    model_depth : ndarray, (H, W)
        Key-camera ``z`` of the rough model per key pixel (``rig.left``'s
        size); NaN or ``<= 0`` where the model is absent.
    rig : capture.rig.Rig
        ``left`` = key camera, ``right`` = offset camera,
        ``x_offset = R x_key + T``.
    delta : float, keyword-only
        Offset from the model along the key ray, in key-camera ``z``.

    Returns
    -------
    ndarray, (H, W) or (H, W, C) float32
        In the offset image's code values; NaN where the model is absent or
        its point falls outside the offset frame or behind the camera (no
        visibility test: see :func:`model_stereo` for that).
    """
    img = np.asarray(offset)
    zm = _check_model(model_depth, rig)
    _check_image("offset", img, rig.right.image_size)
    rays = key_rays(rig.left, zm.shape)
    px, zo = _project_offset(rig, rays @ rig.R.T, zm + delta)
    ok = np.isfinite(zm) & (zo > 0) & _inside(px, rig.right.image_size)
    out = _remap(np.ascontiguousarray(img, np.float32), px)
    out[~ok] = np.nan
    return out


# -------------------------------------------------------------- validation
def _check_image(name, img, size):
    if img.ndim not in (2, 3) or img.shape[1::-1] != tuple(size):
        raise InputError(name, f"expected an image of {size[0]}x{size[1]} (the rig's), "
                               f"got array shape {img.shape}")


def _check_model(model_depth, rig):
    from lumigraph.capture.rig import Rig

    if not isinstance(rig, Rig):
        raise TypeError(f"rig: expected a capture.rig.Rig, got {type(rig).__name__}")
    zm = np.asarray(model_depth, np.float64)
    w, h = rig.left.image_size
    if zm.shape != (h, w):
        raise InputError("model_depth", f"expected shape ({h}, {w}) (the key camera's), got {zm.shape}")
    zm = np.where(zm > 0, zm, np.nan)  # NaN compares False: absent stays absent
    if not np.isfinite(zm).any():
        raise InputError("model_depth", "no finite positive depth (the model is absent everywhere)")
    return zm


def check_model_stereo_options(*, max_offset: float, window: int = 9, step: float | None = None,
                               texture_snr: float = 1.0, uniqueness: float = 0.02,
                               max_cost: float = 1.0, left_right: float | None = 1.25,
                               cost: str = "sgm") -> float:
    """Check :func:`model_stereo`'s options before any image is loaded
    (``model_stereo`` checks them again itself); ``max_offset`` as a float.

    Raises
    ------
    InputError
        Naming the argument: ``max_offset`` not finite and > 0, ``window`` not
        an odd integer in [3, 63], ``step`` outside ``(0, max_offset]``,
        ``texture_snr``/``uniqueness``/``max_cost`` below 0 (or NaN),
        ``left_right`` not finite and > 0 (``None`` disables the check).

    Examples
    --------
    >>> check_model_stereo_options(max_offset=0.35)
    0.35
    >>> check_model_stereo_options(max_offset=0.35, window=8)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: window: expected an odd integer in [3, 63], got 8
    """
    max_offset = float(max_offset)
    if not (np.isfinite(max_offset) and max_offset > 0):
        raise InputError("max_offset", f"expected a finite value > 0, got {max_offset}")
    if not (isinstance(window, int | np.integer) and window % 2 == 1
            and WINDOW_RANGE[0] <= window <= WINDOW_RANGE[1]):
        raise InputError("window", f"expected an odd integer in [3, 63], got {window!r}")
    if step is not None and not (np.isfinite(step) and 0 < step <= max_offset):
        raise InputError("step", f"expected a value in (0, max_offset={max_offset}], got {step}")
    for name, v in (("texture_snr", texture_snr), ("uniqueness", uniqueness), ("max_cost", max_cost)):
        if not v >= 0:
            raise InputError(name, f"expected a value >= 0, got {v}")
    if left_right is not None and not (np.isfinite(left_right) and left_right > 0):
        raise InputError("left_right", f"expected a finite value > 0 or None, got {left_right}")
    if cost not in COSTS:
        raise InputError("cost", f"expected one of {', '.join(COSTS)}, got {cost!r}")
    return max_offset


# ------------------------------------------------- the steps of model_stereo
def _check_inputs(key, offset, model_depth, rig, *, max_offset, window, step, texture_snr,
                  uniqueness, max_cost, left_right, cost="sgm"):
    """Check the images against the rig, the model and every option:
    ``(model depth with NaN where absent, key, offset, max_offset)``."""
    zm = _check_model(model_depth, rig)
    key = np.asarray(key)
    offset = np.asarray(offset)
    _check_image("key", key, rig.left.image_size)
    _check_image("offset", offset, rig.right.image_size)
    max_offset = check_model_stereo_options(
        max_offset=max_offset, window=window, step=step, texture_snr=texture_snr,
        uniqueness=uniqueness, max_cost=max_cost, left_right=left_right, cost=cost)
    return zm, key, offset, max_offset


# model_std: pixels whose model depth can be off by more than max_offset within
# this many σ are not answered; the range widens by as many median σ (3: a
# Gaussian error leaves ±3σ with probability 0.3 %)
MODEL_STD_K = 3.0


def _follow_model_std(zm, model_std, max_offset):
    """``(model depth, max_offset)`` following the model's σ (see
    :func:`model_stereo`'s ``model_std``)."""
    sd = np.asarray(model_std, np.float64)
    if sd.shape != zm.shape:
        raise InputError("model_std", f"expected the model depth's shape {zm.shape}, got {sd.shape}")
    has = np.isfinite(zm)
    if np.any(sd[has] < 0) or np.isnan(sd[has]).any():
        raise InputError("model_std", "expected standard deviations >= 0 (inf: the model may "
                                      "leave the pixel) wherever there is a model")
    keep = has & (MODEL_STD_K * sd <= max_offset)
    if not keep.any():
        raise InputError("model_std", f"the model's depth is uncertain by more than max_offset="
                                      f"{max_offset} / {MODEL_STD_K:g} at every pixel: widen "
                                      "max_offset or mark more edges")
    return np.where(keep, zm, np.nan), max_offset + MODEL_STD_K * float(np.median(sd[keep]))


def _key_noise(key, gk, noise_sigma):
    """The key image's noise σ (code values): as given, or estimated from its
    luma ``gk`` and floored at the quantisation noise of integer codes."""
    from lumigraph.stereo.luma import noise_sigma_smooth_blocks

    if noise_sigma is not None:
        return float(noise_sigma)
    quant = 1 / np.sqrt(12) * (257.0 if key.dtype == np.uint16 else 1.0)
    return max(noise_sigma_smooth_blocks(gk), quant if key.dtype.kind in "ui" else 0.0)


@dataclass(frozen=True)
class _ModelView:
    """The model at ``δ = 0`` as the offset camera sees it, per key pixel:
    ``a = R r`` (the key rays in the offset frame's orientation),
    ``has_model``, the offset-image position ``px0`` (H, W, 2) and depth
    ``zo0``, ``seen`` (in front, inside the frame, not hidden by the model)
    and ``zz``, the model depth where seen (NaN elsewhere)."""

    a: np.ndarray
    has_model: np.ndarray
    px0: np.ndarray
    zo0: np.ndarray
    seen: np.ndarray
    zz: np.ndarray


def _model_view(rig, zm, *, max_offset):
    """Project the model into the offset camera and z-buffer it: which key
    pixels' model points the offset camera sees."""
    size_o = rig.right.image_size
    rays = key_rays(rig.left, zm.shape)
    a = rays @ rig.R.T
    has_model = np.isfinite(zm)
    px0, zo0 = _project_offset(rig, a, np.where(has_model, zm, 1.0))
    in_front = has_model & (zo0 > 0) & np.isfinite(px0).all(axis=-1)
    seen = in_front & _inside(px0, size_o)
    tol = np.maximum(0.02 * np.abs(zo0), max_offset)
    seen &= _model_visible(px0, zo0, seen, size_o, tol)
    return _ModelView(a, has_model, px0, zo0, seen, np.where(seen, zm, np.nan))


def _delta_steps(rig, zm, view, *, max_offset, step, warnings):
    """The searched offsets ``δ``: ``(deltas, step, px_per_unit)``, by default
    one step per offset-image pixel of epipolar motion (99th percentile of
    the seen pixels), at most ``MAX_STEPS`` (a warning says when coarsened)."""
    seen = view.seen
    eps = 1e-3 * max_offset
    px1, _ = _project_offset(rig, view.a, np.where(seen, zm + eps, 1.0))
    rate = np.linalg.norm(px1 - view.px0, axis=-1)[seen] / eps  # px per unit delta
    if not seen.any():
        raise InputError("model_depth", "no model point is seen by the offset camera "
                                        "(check the rig and the model)")
    px_per_unit = float(np.percentile(rate, 99))
    if step is None:
        step = 1.0 / max(px_per_unit, 1e-12)
    n_half = int(np.ceil(max_offset / step))
    if 2 * n_half + 1 > MAX_STEPS:
        n_half = (MAX_STEPS - 1) // 2
        warnings.append(f"delta step coarsened to {max_offset / n_half:.4g} to stay within "
                        f"{MAX_STEPS} steps")
    step = max_offset / n_half
    return np.arange(-n_half, n_half + 1) * step, step, px_per_unit


def _cost_volume(gk, go, rig, zm, view, deltas, *, window):
    """Eq. 5.1 per ``δ`` as a masked box mean: ``(len(deltas), H, W)``
    float32 mean squared luma difference between the key and the offset
    image sampled at ``z_m + δ``; inf where not computed (the point unseen,
    or under half the window seen)."""
    import cv2

    h, w = zm.shape
    size_o = rig.right.image_size
    seen = view.seen
    box = (window, window)
    gk_valid = np.where(seen, gk, 0).astype(np.float32)
    costs = np.full((len(deltas), h, w), np.inf, np.float32)
    zsafe = np.where(seen, zm, 1.0)
    for i, dlt in enumerate(deltas):
        px, zo = _project_offset(rig, view.a, zsafe + dlt)
        m = seen & (zo > 0) & _inside(px, size_o)
        warped = _remap(go, px)
        diff2 = np.where(m, (gk_valid - warped) ** 2, 0).astype(np.float32)
        mf = m.astype(np.float32)
        num = cv2.boxFilter(diff2, -1, box, normalize=False, borderType=cv2.BORDER_CONSTANT)
        den = cv2.boxFilter(mf, -1, box, normalize=False, borderType=cv2.BORDER_CONSTANT)
        ok = m & (den >= 0.5 * window * window)
        costs[i][ok] = num[ok] / den[ok]
    return costs


@dataclass(frozen=True)
class _Decision:
    """Winner-take-all over ``δ`` and the per-pixel tests, each ``(H, W)``:
    the ``best`` index and its ``cost``, whether a cost was ``computed``,
    the key window's variance ``var``, and the tests ``textured``,
    ``unique``, ``plausible`` and ``inner`` (not at either end of the
    range); ``passed`` = all of them."""

    best: np.ndarray
    cost: np.ndarray
    computed: np.ndarray
    var: np.ndarray
    textured: np.ndarray
    unique: np.ndarray
    plausible: np.ndarray
    inner: np.ndarray
    passed: np.ndarray


def _decide(costs, gk, *, sigma, window, texture_snr, uniqueness, max_cost):
    """Pick each pixel's best ``δ`` and run the texture, uniqueness,
    plausible-cost and range-end tests on it."""
    best, bestc, second = _winner(costs)
    computed = np.isfinite(bestc)
    var = _window_variance(gk, window)
    textured = var >= (texture_snr * sigma) ** 2
    with np.errstate(invalid="ignore"):
        unique = ~(second <= (1 + uniqueness) * bestc)
        plausible = bestc <= 2 * sigma ** 2 + max_cost * var
    inner = (best > 0) & (best < len(costs) - 1)
    passed = computed & textured & unique & inner & plausible
    return _Decision(best, bestc, computed, var, textured, unique, plausible, inner, passed)


def _winner(costs):
    """Winner-take-all over ``δ``: each pixel's best index, its cost, and the
    best cost more than one step from it (for the uniqueness test)."""
    n, h, w = costs.shape
    best = np.argmin(costs, axis=0)
    rows, cols = np.mgrid[0:h, 0:w]
    bestc = costs[best, rows, cols]
    masked = costs.copy()
    for k in (-1, 0, 1):
        masked[np.clip(best + k, 0, n - 1), rows, cols] = np.inf
    return best, bestc, masked.min(axis=0)


def _window_variance(gk, window):
    """The key luma's variance in each ``window × window`` box (code values²)."""
    import cv2

    box = (window, window)
    mean = cv2.boxFilter(gk, -1, box, borderType=cv2.BORDER_REFLECT)
    return np.maximum(cv2.boxFilter(gk * gk, -1, box, borderType=cv2.BORDER_REFLECT) - mean * mean, 0)


def _subpixel_fraction(costs, best, bestc, inner):
    """Parabola through the costs at ``best ± 1``: the fraction of a step
    (in [-0.5, 0.5]) its minimum lies from ``best``; 0 at the range's ends."""
    n, h, w = costs.shape
    rows, cols = np.mgrid[0:h, 0:w]
    i0 = np.clip(best - 1, 0, n - 1)
    i2 = np.clip(best + 1, 0, n - 1)
    cm, cp = costs[i0, rows, cols], costs[i2, rows, cols]
    with np.errstate(invalid="ignore", divide="ignore"):
        den = cm - 2 * bestc + cp
        frac = np.where(inner & (den > 0), 0.5 * (cm - cp) / den, 0.0)
    return np.clip(np.nan_to_num(frac), -0.5, 0.5)


def _half_occluded(rig, view, depth, valid, bestc, *, tolerance):
    """Half-occlusion: a key pixel the offset camera cannot see (hidden by
    detail the model lacks) still gets a best delta, but its recovered point
    then lies behind another, better-matching recovered point on the same
    offset pixel."""
    size_o = rig.right.image_size
    pxr, zor = _project_offset(rig, view.a, np.where(valid, depth, 1.0))
    okr = valid & (zor > 0) & _inside(pxr, size_o)
    return _hidden_by_better(pxr, zor, bestc, okr, size_o, tolerance)


def _left_right(key, offset, zm, rig, view, depth, valid, *, left_right, warnings, noise_sigma,
                **search):
    """Left-right check: the same search with the roles swapped (the offset
    view as key, the model re-seen from it) must send the offset pixel a key
    point lands on back to that key pixel, within ``left_right`` round-trip
    units. Returns the inconsistent pixels and a record of the reverse search."""
    rev_model = model_in_offset_view(zm, rig)
    if not np.isfinite(rev_model).any():
        warnings.append("left-right check: no model point projects into the offset view; "
                        "every pixel refused")
        return valid.copy(), None
    rev = model_stereo(offset, key, rev_model, _reverse_rig(rig), max_median_cost=None,
                       left_right=None, noise_sigma=noise_sigma, **search)
    back, unit = _round_trip(rig, np.where(valid, depth, np.nan), rev.depth,
                             np.where(view.seen[..., None], view.px0, np.nan))
    reverse_info = {"steps": rev.info["steps"], "step": rev.info["step"],
                    "valid_fraction": rev.valid_fraction,
                    "round_trip_px_median": float(np.nanmedian(back)) if np.isfinite(back).any()
                    else None,
                    "round_trip_unit_px_median": float(np.nanmedian(unit)) if np.isfinite(unit).any()
                    else None}
    # where the reverse search refused the offset pixel there is no verdict
    return valid & (back > left_right * unit), reverse_info


def _rejections(view, dec, occluded, inconsistent):
    """How many key pixels each test refused, in this order, a pixel counted
    under the first test it failed (pixels with no computed cost under none)."""
    has, seen, tex, comp = view.has_model, view.seen, dec.textured, dec.computed
    inner, unique = dec.inner, dec.unique
    return {"no_model": int((~has).sum()),
            "unseen_by_offset": int((has & ~seen).sum()),
            "no_texture": int((seen & ~tex).sum()),
            "at_range_limit": int((seen & tex & comp & ~inner).sum()),
            "not_unique": int((seen & tex & comp & inner & ~unique).sum()),
            "implausible_cost": int((seen & tex & comp & inner & unique & ~dec.plausible).sum()),
            "occluded": int(occluded.sum()),
            "left_right": int(inconsistent.sum())}


def _median_cost_over_variance(bestc, var, judged, sigma):
    """How well the model explains the images: the median over the judged
    pixels of ``(best cost − 2σ²) / var(window)`` (inf when none)."""
    if not judged.any():
        return float("inf")
    return float(np.median((bestc[judged] - 2 * sigma ** 2) / np.maximum(var[judged], 1e-12)))


def _check_fit(fit, *, max_median_cost, max_offset):
    """Refuse the result (:class:`EstimationError` on ``model_depth``) when
    the model does not explain the images."""
    if max_median_cost is not None and not fit <= max_median_cost:
        from lumigraph.capture.errors import EstimationError

        raise EstimationError("model_depth", f"the model does not explain the images: the median best "
                                             f"cost is {fit:.2f} x the window variance (limit "
                                             f"{max_median_cost:g}; chance matches cost about 1-2 x); "
                                             "the model or the rig is wrong, or the detail lies "
                                             f"farther than max_offset={max_offset:g} from the model")


# ------------------------------------------------- the SGM cost (cost="sgm")
def _codes8(gk, go, *, eight_bit):
    """Both lumas as 8-bit codes for the census (float32, not yet rounded):
    as they are when both images are 8-bit (``eight_bit``), else scaled so
    that the pair's joint range spans 0-255 (as
    :func:`lumigraph.stereo.hirschmuller2008.match` does; a float image in
    [0, 1] would otherwise round to two codes).

    >>> k, o = _codes8(np.float32([[0.0, 0.5]]), np.float32([[1.0, 0.25]]), eight_bit=False)
    >>> k.tolist(), o.tolist()
    ([[0.0, 127.5]], [[255.0, 63.75]])
    """
    if eight_bit:
        return gk, go
    lo = min(float(np.nanmin(gk)), float(np.nanmin(go)))
    hi = max(float(np.nanmax(gk)), float(np.nanmax(go)))
    s = np.float32(255.0 / max(hi - lo, 1e-12))
    return (gk - np.float32(lo)) * s, (go - np.float32(lo)) * s


def _census_cost_volume(gk, go, rig, zm, view, deltas, *, cost_window=SGM["cost_window"],
                       kernel=None):
    """The census matching cost of every key pixel at every ``δ``:
    ``(H, W, len(deltas))`` uint16, and where it was computed: ``(H, W)``
    bool, the pixels seen at some ``δ``.

    Per ``δ`` the offset luma is warped into the key view through the point
    ``(z_m + δ) · r`` (as :func:`_cost_volume` does for eq. 5.1), rounded to
    8-bit codes, and census-transformed in the key view's geometry (so the
    census windows of both images cover the same patch of the model: the
    foreshortening between the views is undone by the model); the cost is
    the Hamming distance between the two 9×7 census codes (Hirschmüller &
    Scharstein 2009; :func:`lumigraph.stereo.hirschmuller2008.census`),
    summed over a ``cost_window²`` box (edges replicated). Where the point
    is not seen (outside the offset frame, behind it, or the model point
    hidden) the pixel costs the largest Hamming distance, ``CENSUS_MAX``.

    ``gk``, ``go``: key and offset luma as 8-bit codes (float, unrounded);
    ``view``, ``deltas`` as :func:`model_stereo` builds them.
    """
    import cv2

    from lumigraph.stereo.hirschmuller2008 import CENSUS_MAX, census

    h, w = zm.shape
    size_o = rig.right.image_size
    ck = census(np.clip(np.rint(gk), 0, 255).astype(np.uint8), kernel=kernel)
    go = np.ascontiguousarray(go, np.float32)
    # every model pixel is warped (not only the seen ones): its value enters
    # the census codes of its seen neighbours
    zsafe = np.where(view.has_model, zm, 1.0)
    out = np.empty((h, w, len(deltas)), np.uint16)
    box = (cost_window, cost_window)
    computed = np.zeros((h, w), bool)
    for i, dlt in enumerate(deltas):
        px, zo = _project_offset(rig, view.a, zsafe + dlt)
        m = view.seen & (zo > 0) & _inside(px, size_o)
        warped = np.clip(np.rint(_remap(go, px)), 0, 255).astype(np.uint8)
        ham = np.bitwise_count(ck ^ census(warped, kernel=kernel)).astype(np.float32)
        ham[~m] = CENSUS_MAX
        computed |= m
        if cost_window > 1:
            ham = cv2.boxFilter(ham, -1, box, normalize=False, borderType=cv2.BORDER_REPLICATE)
        out[..., i] = np.rint(ham).astype(np.uint16)
    return out, computed


def _sgm_winner(S):
    """Winner-take-all over ``S`` (H, W, n) uint16: the best index, ``S``
    there and at the index either side (the edge value repeated at the
    range's ends) and the best ``S`` more than one step away (uniqueness).
    ``S`` is overwritten (no copy of the volume: it is not needed after)."""
    n = S.shape[2]
    best = S.argmin(axis=2)
    at = lambda i: np.take_along_axis(S, i[..., None], 2)[..., 0].astype(np.int64)  # noqa: E731
    sb, sm, sp = at(best), at(np.maximum(best - 1, 0)), at(np.minimum(best + 1, n - 1))
    for k in (-1, 0, 1):
        np.put_along_axis(S, np.clip(best + k, 0, n - 1)[..., None], np.iinfo(np.uint16).max, 2)
    return best, sb, sm, sp, S.min(axis=2).astype(np.int64)


def _surface_cost(gk, go, rig, zm, view, dlt, *, window):
    """Eq. 5.1's mean squared difference of the recovered surface: the
    offset luma sampled at each key pixel's own ``z_m + δ`` against the key
    luma, over the ``window²`` box (masked as :func:`_cost_volume`; inf
    where under half the window is seen). With ``cost="sgm"`` it stands in
    for the SSD cost at the winner in the tests that judge a match by it
    (plausible cost, half-occlusion, the model's fit)."""
    import cv2

    box = (window, window)
    ok = view.seen & np.isfinite(dlt)
    px, zo = _project_offset(rig, view.a, np.where(ok, zm + np.nan_to_num(dlt), 1.0))
    m = ok & (zo > 0) & _inside(px, rig.right.image_size)
    diff2 = np.where(m, (gk - _remap(go, px)) ** 2, 0).astype(np.float32)
    num = cv2.boxFilter(diff2, -1, box, normalize=False, borderType=cv2.BORDER_CONSTANT)
    den = cv2.boxFilter(m.astype(np.float32), -1, box, normalize=False, borderType=cv2.BORDER_CONSTANT)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(m & (den >= 0.5 * window * window), num / den, np.inf).astype(np.float32)


def _decide_sgm(S, computed, gk, go, rig, zm, view, deltas, step, *, sigma, window, texture_snr,
                uniqueness, max_cost, subpixel):
    """Winner-take-all over the aggregated cost ``S`` (H, W, n; overwritten),
    the parabola through ``S`` at the best ``δ`` ± one step, and the same
    per-pixel tests as :func:`_decide` (uniqueness on ``S``; the plausible
    cost on :func:`_surface_cost`). Returns the decision and the sub-step
    fraction."""
    best, sb, sm, sp, second = _sgm_winner(S)
    n = S.shape[2]
    inner = (best > 0) & (best < n - 1)
    frac = np.zeros(best.shape)
    if subpixel:
        den = sm + sp - 2 * sb
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where(inner & (den > 0), 0.5 * (sm - sp) / np.maximum(den, 1), 0.0)
        frac = np.clip(frac, -0.5, 0.5)
    dlt = np.where(computed, deltas[best] + frac * step, np.nan)
    cost = _surface_cost(gk, go, rig, zm, view, dlt, window=window)
    computed = computed & np.isfinite(cost)
    var = _window_variance(gk, window)
    textured = var >= (texture_snr * sigma) ** 2
    unique = ~(second <= (1 + uniqueness) * sb)
    with np.errstate(invalid="ignore"):
        plausible = cost <= 2 * sigma ** 2 + max_cost * var
    passed = computed & textured & unique & inner & plausible
    return _Decision(best, cost, computed, var, textured, unique, plausible, inner, passed), frac


# ---------------------------------------------------------------- matching
def model_stereo(key: np.ndarray, offset: np.ndarray, model_depth: np.ndarray, rig, *,
                 max_offset: float, step: float | None = None, window: int = 9,
                 texture_snr: float = 1.0, uniqueness: float = 0.02, max_cost: float = 1.0,
                 occlusion_tolerance: float | None = 0.01, max_median_cost: float | None = 0.8,
                 left_right: float | None = 1.25, subpixel: bool = True,
                 noise_sigma: float | None = None, cost: str = "sgm",
                 model_std: np.ndarray | None = None) -> ModelStereo:
    """Depth of the key view as offsets from a rough model (model-based stereo).

    Parameters
    ----------
    key, offset : ndarray, (H, W) or (H, W, C)
        Key and offset images as captured (same dtype family; compared as
        Rec. 601 luma in code values). Sizes must be the rig's.
    model_depth : ndarray, (H, W)
        Key-camera ``z`` of the rough model per key pixel centre, unit of the
        rig's ``T``; NaN (or ``<= 0``) where there is no model.
    rig : capture.rig.Rig
        ``left`` = key camera, ``right`` = offset camera, ``x_offset = R
        x_key + T``; lens distortion of either camera is handled exactly
        (rays by ``Camera.unproject``, projection by ``Camera.project``).
    max_offset : float, keyword-only
        Largest ``|δ|`` searched, unit of ``T``: the detail's depth off the
        model, with margin.
    step : float, optional
        ``δ`` step; default: the step that moves the offset-image sample by
        one pixel at the 99th percentile of the pixels (most move less).
        The number of steps is capped at ``MAX_STEPS`` (a warning says so).
    window : int
        Odd side of the SSD box (3..63), eq. 5.1; with ``cost="sgm"`` the box
        of the texture and plausible-cost tests and of the surface's cost.
    texture_snr : float
        Minimum key window standard deviation in units of the noise ``σ``
        (0 disables).
    uniqueness : float
        Every ``δ`` more than one step from the best must cost more than
        ``(1 + uniqueness)`` times the best (0 disables).
    max_cost : float
        The best mean squared difference may be at most ``2 σ² + max_cost ·
        var(window)`` (``inf`` disables): a chance match costs about twice
        the window variance, a true one the noise ``2σ²`` plus resampling.
        Measured on the ``model-stereo`` scene (window 9): 1.0 instead of
        ``inf`` cuts the matched pixels the offset camera cannot see from
        3790 to 2699 of 5115 but raises the share of visible pixels off by
        more than 1 % of the depth from 0.155 to 0.186 (missing counts).
        With ``cost="sgm"`` (tuning renders, views 27.5 / 42.5 / 57.5°
        apart, seed 1), 1.0 instead of ``inf``: key pixels hidden by the
        relief refused 0.65 → 0.67, 0.76 → 0.81, 0.73 → 0.83, error 0.077 →
        0.093, 0.082 → 0.110, 0.149 → 0.171 (kept at 1.0 for both costs).
    occlusion_tolerance : float or None
        Half-occlusion test: a recovered point lying behind the nearest
        recovered point on the same offset pixel by more than this fraction of
        its offset-camera depth, and matching worse than it, is refused
        (``None`` disables).
    max_median_cost : float or None
        Refuse the whole result (:class:`~capture.errors.EstimationError`)
        when the median over the judged pixels of ``(best cost − 2σ²) /
        var(window)`` exceeds this: the model does not explain the images.
        On the ``model-stereo`` scene (window 9) the correct model gives
        0.28, a model off by ±0.2-0.3 m 0.30-0.59, one off by ±0.6 m (beyond
        ``max_offset`` 0.35) 1.1; with ``cost="sgm"`` 0.14, 0.16-0.38 and
        0.98-1.09 (the surface's cost at the winners). ``None`` disables.
    left_right : float or None
        Left-right check tolerance in round-trip units of ``1 + k`` key
        pixels (``k`` the key pixels per offset pixel; a correct pair comes
        back within ``0.5 + 1.21 k``, so 1.25 units covers it for any ``k``).
        An offset pixel the reverse search leaves unknown gives no verdict
        (the key pixel is kept). ``None`` disables it (one search instead of
        two: about a third of the time). Measured
        on ``model-stereo`` 320x240, window 9 (seed 0; seeds 1-4 within
        0.002), key pixels hidden by the relief refused / bench error (share
        of seen pixels off by > 1 % of depth) without → with the check:
        20°: 0.40 → 0.51 / 0.163 → 0.168; 30°: 0.50 → 0.64 / 0.178 → 0.189;
        50°: 0.56 → 0.75 / 0.228 → 0.258; 65°: 0.55 → 0.72 / 0.293 → 0.334.
        The refused correct pixels lie within a window of depth edges.
        With ``cost="sgm"``, bench error (seed 0) without → with the check:
        20°: 0.061 → 0.070; 35°: 0.070 → 0.084; 50°: 0.114 → 0.136; 65°:
        0.176 → 0.219; hidden key pixels refused with it 0.41 / 0.77 / 0.82
        / 0.82 (0.25-0.33 without it on the tuning renders).
    subpixel : bool
        Parabola refinement of the best step.
    noise_sigma : float, optional
        Noise of the key image in code values; estimated when not given
        (:func:`lumigraph.stereo.luma.noise_sigma_smooth_blocks`, at least the 8-bit
        quantisation noise ``1/√12``).
    cost : {"sgm", "ssd"}
        Matching cost along the search: census aggregated along 8 paths by
        semi-global matching (the default; its settings in ``SGM``) or the
        SSD window cost of eq. 5.1 (the paper's). The SGM cost's error on the
        bench's facade sweep is 0.41-0.66 x the SSD cost's and 0.53-0.61 x
        StereoSGBM's on the rectified pair, in about the same time (the
        left-right check's second search dominates either).
    model_std : ndarray, (H, W), optional
        Standard deviation of ``model_depth`` per key pixel, for a fitted
        model (:func:`lumigraph.stereo.debevec1996.raster.model_depth_sigma`
        from a Façade solve's covariance): the search follows the model's
        own uncertainty. A pixel where ``MODEL_STD_K`` σ exceeds
        ``max_offset`` is not answered (the model can be another surface
        there: an edge within its error), and the range widens by
        ``MODEL_STD_K`` × the median σ (the model's error on top of the
        detail's). ``None``: the model is taken as exact.

    Returns
    -------
    ModelStereo

    Raises
    ------
    InputError
        Naming the argument: sizes that do not match the rig, no model (or
        none the offset camera sees), a bad option
        (:func:`check_model_stereo_options` checks the options alone, before
        the images are loaded).
    TypeError
        ``rig`` is not a :class:`~lumigraph.capture.rig.Rig`.
    EstimationError
        The model does not explain the images (``max_median_cost``).
    """
    from lumigraph.stereo.luma import luma_codes

    t0 = time.perf_counter()
    zm, key, offset, max_offset = _check_inputs(
        key, offset, model_depth, rig, max_offset=max_offset, window=window, step=step,
        texture_snr=texture_snr, uniqueness=uniqueness, max_cost=max_cost, left_right=left_right,
        cost=cost)
    if model_std is not None:
        zm, max_offset = _follow_model_std(zm, model_std, max_offset)
    gk, go = luma_codes(key), luma_codes(offset)
    sigma = _key_noise(key, gk, noise_sigma)
    warnings: list[str] = []
    # the model seen from the offset camera (δ = 0): which key pixels can match
    view = _model_view(rig, zm, max_offset=max_offset)
    # the δ steps: one offset-image pixel of epipolar motion each
    deltas, step, px_per_unit = _delta_steps(rig, zm, view, max_offset=max_offset, step=step,
                                             warnings=warnings)
    n = len(deltas)
    t_scan = time.perf_counter()
    if cost == "sgm":
        # census cost along the model-warped search, aggregated along 8 paths
        # (Hirschmüller 2008, eqs. 13-14) with δ steps in place of disparities
        from lumigraph.stereo.hirschmuller2008 import _kernel, aggregate

        kernel = _kernel()
        k8, o8 = _codes8(gk, go, eight_bit=key.dtype == np.uint8 and offset.dtype == np.uint8)
        census_costs, computed = _census_cost_volume(k8, o8, rig, zm, view, deltas, kernel=kernel)
        nb = SGM["cost_window"] ** 2
        S = aggregate(census_costs, np.clip(np.rint(k8), 0, 255).astype(np.uint8), p1=SGM["p1"] * nb,
                      p2=SGM["p2"] * nb, edge=SGM["edge"], paths=SGM["paths"], kernel=kernel)
        del census_costs
        t_decide = time.perf_counter()
        # decision: winner-take-all on the aggregated cost, the parabola, the tests
        dec, frac = _decide_sgm(S, computed, gk, go, rig, zm, view, deltas, step, sigma=sigma,
                                window=window, texture_snr=texture_snr, uniqueness=uniqueness,
                                max_cost=max_cost, subpixel=subpixel)
        del S
    else:
        costs = _cost_volume(gk, go, rig, zm, view, deltas, window=window)
        t_decide = time.perf_counter()
        # decision: winner-take-all, the per-pixel tests, the parabola
        dec = _decide(costs, gk, sigma=sigma, window=window, texture_snr=texture_snr,
                      uniqueness=uniqueness, max_cost=max_cost)
        frac = (_subpixel_fraction(costs, dec.best, dec.cost, dec.inner) if subpixel
                else np.zeros(zm.shape))
    valid = dec.passed.copy()
    dlt = np.where(valid, deltas[dec.best] + frac * step, np.nan)
    depth = (view.zz + dlt).astype(np.float32)
    valid &= depth > 0
    # the two visibility checks: half-occlusion, then left-right
    occluded = np.zeros(zm.shape, bool)
    if occlusion_tolerance is not None and valid.any():
        occluded = _half_occluded(rig, view, depth, valid, dec.cost, tolerance=occlusion_tolerance)
        valid &= ~occluded
    t_check = time.perf_counter()
    inconsistent = np.zeros(zm.shape, bool)
    reverse_info = None
    if left_right is not None and valid.any():
        inconsistent, reverse_info = _left_right(
            key, offset, zm, rig, view, depth, valid, left_right=left_right, warnings=warnings,
            max_offset=max_offset, window=window, texture_snr=texture_snr, uniqueness=uniqueness,
            max_cost=max_cost, occlusion_tolerance=occlusion_tolerance, subpixel=subpixel,
            noise_sigma=noise_sigma, cost=cost)
        valid &= ~inconsistent
    depth[~valid] = np.nan
    t_lr = time.perf_counter()
    dlt = np.where(valid, dlt, np.nan).astype(np.float32)

    # the warped offset image of Fig. 5.12c, every channel
    warped0 = _remap(np.ascontiguousarray(offset, np.float32), view.px0)
    warped0[~view.seen] = np.nan

    # the record, and the refusal of a model that does not explain the images
    seen = view.seen
    counts = _rejections(view, dec, occluded, inconsistent)
    fit = _median_cost_over_variance(dec.cost, dec.var, seen & dec.textured & dec.computed, sigma)
    _check_fit(fit, max_median_cost=max_median_cost, max_offset=max_offset)
    limited = counts["at_range_limit"] / max(1, int((seen & dec.textured).sum()))
    if limited > 0.2:
        warnings.append(f"{limited:.0%} of the textured pixels matched best at the end of the "
                        f"δ range ±{max_offset:g}: the surface is farther from the model than "
                        "max_offset there (a wrong model or too small a range)")
    t1 = time.perf_counter()
    info = {"max_offset": max_offset, "step": float(step), "steps": n,
            "delta_range": [float(deltas[0]), float(deltas[-1])],
            "px_per_unit_delta_p99": px_per_unit, "window": int(window),
            "texture_snr": texture_snr, "uniqueness": uniqueness, "max_cost": max_cost,
            "subpixel": subpixel, "left_right": left_right, "reverse": reverse_info,
            "cost": cost, "sgm": dict(SGM) if cost == "sgm" else None,
            "noise_sigma": float(sigma),
            "noise_sigma_source": "given" if noise_sigma is not None else "estimated",
            "rejected": counts, "seen_fraction": float(seen.mean()),
            "median_cost_over_variance": fit, "max_median_cost": max_median_cost,
            "valid_fraction": float(valid.mean()),
            "valid_fraction_of_seen": float(valid.sum() / max(1, seen.sum())),
            "warnings": warnings,
            "timings_s": {"prepare": t_scan - t0, "scan": t_decide - t_scan,
                          "decide": t1 - t_decide - (t_lr - t_check), "left_right": t_lr - t_check}}
    cost = np.where(dec.computed, dec.cost, np.nan).astype(np.float32)
    return ModelStereo(depth, dlt, warped0, cost, valid, info)
