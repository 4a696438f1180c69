"""Dense inverse search optical flow (Kroeger, Timofte, Dai, Van Gool 2016,
*Fast Optical Flow using Dense Inverse Search*, ECCV, doi:10.1007/978-3-319-46493-0_29),
lumigraph's default flow.

The inner solver is OpenCV's implementation of the paper
(``cv2.DISOpticalFlow``): per pyramid level, patches of ``patch_size`` px on a
grid of ``patch_stride`` px are aligned by inverse-compositional
Gauss-Newton (their eq. 2-4, ``descent_iterations`` steps), propagated to
their neighbours, and densified by the overlap-weighted average of eq. 5. What
we add around it, each a handful of OpenCV/numpy passes at full size:

* **finest scale 0** and **no variational step per level** in the default (DIS's
  "medium" preset runs 5 at every level): one step per level costs as much
  as the whole patch search and gains less than solving at full size (our
  bench, ``docs/decisions/flow-default.md``);
* a **5x5 median** of the dense field (the robust filtering of Sun, Roth &
  Black 2010, doi:10.1109/CVPR.2010.5539939), which removes the isolated
  bad patches the densification averages in;
* for the accurate end, **variational refinement at full size** (the energy of the DIS
  paper's §2.3: brightness and gradient constancy, robust smoothness; solved
  by ``cv2.VariationalRefinement``, ``refine_iterations`` fixed-point steps of
  ``refine_sor_iterations`` sweeps, weight ``refine_smoothness``), on frames
  **pre-smoothed** by ``presmooth`` px (the search sees them too): at full
  size the patches and the energy meet the sensor noise a half-size finest
  level averages away, and in low-texture regions only a converged
  smoothness term recovers the flow;
* for the accurate end, the search **both ways**, the forward-backward
  inconsistent pixels (occluded or wrong) **filled** by the consistent flow
  of their colour region (:func:`fill_inconsistent`, an edge-aware
  interpolation as in EpicFlow) before the refinement, and a
  **luma-guided weighted median** (``cv2.ximgproc``) that keeps motion
  boundaries on image edges; optionally **fusion** of the fields of several
  patch sizes (per pixel the one with the lowest windowed colour residual,
  as in fusion moves, Lempitsky et al. 2008);
* **large motion**: DIS's coarsest level reaches about half a patch there,
  ``patch_size / 2 * 2**coarsest`` px, and OpenCV picks ``coarsest`` from the
  image size (about a width / 8), and a small frame's coarse levels are too
  small to match anyway. When tiled phase correlation
  (:func:`stereo.pyramid.estimate_max_motion`) finds more than half that,
  DIS's coarsest level is seeded with the per-pixel best of the tiles'
  translations (:func:`initial_flow`); flow that still ends near the reach
  is said in a warning;
* a **confidence**: texture (smallest structure-tensor eigenvalue against the
  image's own noise) times forward-backward consistency.

Examples
--------
>>> import cv2
>>> rng = np.random.default_rng(0)
>>> a = cv2.GaussianBlur(rng.random((96, 128)), (0, 0), 2)
>>> a = np.clip(a / a.max() * 255, 0, 255).astype(np.uint8)
>>> b = np.roll(a, (1, 3), axis=(0, 1))          # moving = reference shifted by (3, 1)
>>> r = dense_inverse_search(a, b)
>>> np.round(np.median(r.flow[16:-16, 16:-16], axis=(0, 1)), 1).tolist()
[3.0, 1.0]
>>> bool((dense_inverse_search(a, a).flow == 0).all())   # identical frames: zero, exactly
True
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.stereo.pyramid_flow import FlowResult

# Seed DIS (initial_flow) when the estimated motion exceeds this fraction of
# its reach: well inside the reach the coarse levels find the motion alone.
SEED_FRACTION = 0.5


@dataclass(frozen=True)
class Preset:
    """One point on the speed-error curve (``lumigraph bench flow``).

    Attributes
    ----------
    patch_size : int
        Patch side (px), DIS's ``theta_ps``.
    patch_stride : int
        Grid step of the patches (px), ``< patch_size``; smaller is denser,
        slower, more accurate.
    descent_iterations : int
        Inverse-compositional Gauss-Newton steps per patch (``theta_it``).
    level_refine_iterations : int
        Variational refinement steps DIS runs at each level, inside the
        pyramid (its own ``theta_vo``; DIS-medium uses 5).
    refine_iterations : int
        Fixed-point steps of the full-size variational refinement (0: none).
    median : int
        Side of the median applied to the dense field (0: none; 3 or 5).
    fuse_patch_sizes : tuple of int
        Further patch sizes whose fields are fused with the main one.
    wmf_radius : int
        Radius (px) of the final luma-guided weighted median (0: none).
    fill_occlusions : bool
        Also search backward; average the two where they agree and replace
        the forward-backward inconsistent pixels by the consistent flow of
        their colour region (:func:`fill_inconsistent`) before the
        refinement (doubles the search).
    presmooth : float
        Sigma (px) of a Gaussian applied to both grey frames before the
        search and the refinement (0: none). At full size the search and the
        energy see the sensor noise that a half-size finest level averages
        away; DeepFlow pre-smooths by 0.6 px for the same reason.
    refine_smoothness : float
        Weight of the smoothness term of the full-size refinement (the DIS
        paper's alpha; DIS itself uses 20).
    refine_sor_iterations : int
        Successive over-relaxation sweeps per fixed-point step of the
        full-size refinement (DIS: 5). Smoothness spreads about one pixel
        per sweep: low-texture regions need many.
    """

    patch_size: int = 8
    patch_stride: int = 4
    descent_iterations: int = 16
    level_refine_iterations: int = 1
    refine_iterations: int = 0
    median: int = 5
    fuse_patch_sizes: tuple = ()
    wmf_radius: int = 0
    fill_occlusions: bool = False
    presmooth: float = 0.0
    refine_smoothness: float = 20.0
    refine_sor_iterations: int = 5


PRESETS = {
    # About DIS-medium's time, more accurate: a sparse patch search at full size.
    "fast": Preset(patch_stride=6, descent_iterations=8, level_refine_iterations=0,
                   refine_iterations=0, median=5),
    # The default: a denser search at full size (stride 5 saves ~20 % but
    # loses market_5's large motion, 24.2 px vs 15.4), no variational step:
    # one step per level cost as much as the whole patch search (CPU time on
    # Sintel 3.2-3.5x DIS-medium with it, 1.6x without) and 10 descent steps
    # instead of 16 recover its accuracy on the tuning scenes
    # (docs/decisions/flow-default.md), the median.
    "default": Preset(patch_stride=4, descent_iterations=10, level_refine_iterations=0,
                      refine_iterations=0, median=5),
    # The accuracy end: denser patches, both directions with the
    # forward-backward inconsistent pixels filled from their colour region,
    # full-size refinement, the weighted median (stride 2 or fusion with
    # 16-px patches cost more and lose market_5's large motion;
    # docs/decisions/flow-default.md). The refinement pre-smooths the frames
    # by 0.6 px, runs 10 fixed-point steps of 20 sweeps with twice DIS's
    # smoothness: on smooth, low-texture, noisy scenes (a rendered cloth
    # scene) the 5 x 5 steps left the patch noise in (EPE 1.03x DIS-medium's,
    # 0.62x with these), at no loss on Sintel beyond market_5's chaotic
    # large motion (0.46 -> 0.49x).
    "accurate": Preset(patch_stride=3, descent_iterations=16, level_refine_iterations=0,
                       refine_iterations=10, median=5, wmf_radius=7, fill_occlusions=True,
                       presmooth=0.6, refine_smoothness=40.0, refine_sor_iterations=20),
}


def check_options(*, preset: str = "default", **overrides) -> Preset:
    """The :class:`Preset` named, with ``overrides`` of its fields, checked.

    Raises
    ------
    InputError
        Naming the preset or the field out of range.

    Examples
    --------
    >>> check_options(preset="fast").patch_stride
    6
    >>> check_options(preset="default", patch_stride=8).patch_stride
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: patch_stride: expected 1..7 (below patch_size 8), got 8
    """
    if preset not in PRESETS:
        raise InputError("preset", f"expected one of {', '.join(PRESETS)}, got {preset!r}")
    unknown = set(overrides) - set(Preset.__dataclass_fields__)
    if unknown:
        raise InputError(sorted(unknown)[0], "not an option of dense inverse search; "
                                             f"choose from {', '.join(Preset.__dataclass_fields__)}")
    p = replace(PRESETS[preset], **{k: v for k, v in overrides.items() if v is not None})
    if not 4 <= p.patch_size <= 64:
        raise InputError("patch_size", f"expected 4..64 px, got {p.patch_size}")
    if not 1 <= p.patch_stride < p.patch_size:
        raise InputError("patch_stride", f"expected 1..{p.patch_size - 1} (below patch_size "
                                         f"{p.patch_size}), got {p.patch_stride}")
    if p.descent_iterations < 1:
        raise InputError("descent_iterations", f"expected >= 1, got {p.descent_iterations}")
    if not 0 <= p.level_refine_iterations <= 100:
        raise InputError("level_refine_iterations",
                         f"expected 0..100, got {p.level_refine_iterations}")
    if not 0 <= p.refine_iterations <= 100:
        raise InputError("refine_iterations", f"expected 0..100, got {p.refine_iterations}")
    if p.median not in (0, 3, 5):
        raise InputError("median", f"expected 0, 3 or 5, got {p.median}")
    if not 0 <= p.wmf_radius <= 64:
        raise InputError("wmf_radius", f"expected 0..64 px, got {p.wmf_radius}")
    if not 0 <= p.presmooth <= 5:
        raise InputError("presmooth", f"expected 0..5 px, got {p.presmooth}")
    if not 0 < p.refine_smoothness <= 1000:
        raise InputError("refine_smoothness", f"expected > 0 and <= 1000, got {p.refine_smoothness}")
    if not 1 <= p.refine_sor_iterations <= 100:
        raise InputError("refine_sor_iterations",
                         f"expected 1..100, got {p.refine_sor_iterations}")
    return p


def coarsest_scale(shape: tuple[int, int], patch_size: int) -> int:
    """The coarsest pyramid scale OpenCV's DIS uses on a frame of ``shape``
    (its own rule: motion up to about a quarter of the width, and a level at
    least a patch tall).

    >>> coarsest_scale((240, 320), 8), coarsest_scale((436, 1024), 8)
    (3, 5)
    """
    h, w = shape
    return max(0, min(int(math.log2(max(h, w) / (4.0 * patch_size)) + 0.5),
                      int(math.log2(min(h, w) / patch_size))))


def reach_px(shape: tuple[int, int], patch_size: int) -> float:
    """Largest motion (px, full size) the coarsest level can find: half a
    patch there (the Gauss-Newton steps converge within a patch's basin).

    >>> reach_px((240, 320), 8), reach_px((436, 1024), 8)
    (32.0, 128.0)
    """
    return patch_size / 2 * 2.0 ** coarsest_scale(shape, patch_size)


def _gray8(img: np.ndarray) -> np.ndarray:
    import cv2

    from lumigraph.stereo.luma import luma_normalised

    a = np.asarray(img)
    if a.dtype == np.uint8:
        if a.ndim == 2:
            return np.ascontiguousarray(a)
        if a.ndim == 3 and a.shape[2] == 1:
            return np.ascontiguousarray(a[..., 0])
        if a.ndim == 3 and a.shape[2] in (3, 4):
            return cv2.cvtColor(np.ascontiguousarray(a[..., :3]), cv2.COLOR_RGB2GRAY)
    return np.clip(np.rint(luma_normalised(a) * 255), 0, 255).astype(np.uint8)


def _colour8(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] >= 3:
        a = a[..., :3]
        if a.dtype == np.uint8:
            return np.ascontiguousarray(a)
        scale = 255.0 / np.iinfo(a.dtype).max if a.dtype.kind in "ui" else 255.0
        return np.clip(np.rint(a * scale), 0, 255).astype(np.uint8)
    return _gray8(a)


def _dis(p: Preset, patch_size: int):
    import cv2

    d = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    d.setFinestScale(0)
    d.setPatchSize(patch_size)
    d.setPatchStride(max(1, min(p.patch_stride * patch_size // p.patch_size, patch_size - 1)))
    d.setGradientDescentIterations(p.descent_iterations)
    d.setVariationalRefinementIterations(p.level_refine_iterations)
    d.setUseMeanNormalization(True)
    d.setUseSpatialPropagation(True)
    return d


def _search(g0, g1, p: Preset, patch_size: int, init):
    """DIS at full size; ``init`` (or None) seeds its coarsest level."""
    d = _dis(p, patch_size)
    return d.calc(g0, g1, None if init is None else init.copy())


def initial_flow(g0: np.ndarray, g1: np.ndarray, shifts) -> np.ndarray:
    """A piecewise-constant seed for motion beyond DIS's reach: per pixel, the
    candidate translation (``shifts``, px, from tiled phase correlation, plus
    zero) whose windowed residual ``|I0 - I1(x + s)|`` is lowest, chosen at
    <= 160 px and median-filtered (labels), then scaled up. Float32 ``(H, W, 2)``.

    >>> a = (np.indices((64, 64)).sum(0) % 7 * 30).astype(np.uint8)
    >>> f = initial_flow(a, np.roll(a, 5, axis=1), [(5.0, 0.0)])
    >>> np.median(f[..., 0]), np.median(f[..., 1])
    (np.float32(5.0), np.float32(0.0))
    """
    import cv2

    h, w = g0.shape
    k = 1
    while max(h, w) / k > 160:
        k *= 2
    a = cv2.resize(g0, (w // k, h // k), interpolation=cv2.INTER_AREA).astype(np.float32)
    b = cv2.resize(g1, (w // k, h // k), interpolation=cv2.INTER_AREA).astype(np.float32)
    cands = [(0.0, 0.0), *[(float(x), float(y)) for x, y in shifts]]
    win = max(5, (max(a.shape) // 10) | 1)
    costs = []
    for dx, dy in cands:
        m = np.float32([[1, 0, dx / k], [0, 1, dy / k]])
        wb = cv2.warpAffine(b, m, (a.shape[1], a.shape[0]), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                            borderMode=cv2.BORDER_REPLICATE)
        costs.append(cv2.boxFilter(np.abs(a - wb), -1, (win, win)))
    lab = cv2.medianBlur(np.argmin(np.stack(costs), axis=0).astype(np.uint8), 5)
    lab = cv2.resize(lab, (w, h), interpolation=cv2.INTER_NEAREST)
    return np.ascontiguousarray(np.float32(cands)[lab])


def _median(flow, k):
    import cv2

    if k == 0:
        return flow
    return np.dstack([cv2.medianBlur(np.ascontiguousarray(flow[..., c]), k) for c in (0, 1)])


def _warp(img, flow):
    import cv2

    from lumigraph.stereo.pyramid import grid

    X, Y = grid(flow.shape[:2])
    return cv2.remap(img, X + flow[..., 0], Y + flow[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def _fuse(c0, c1, flows, window=9):
    """Per pixel, the field whose windowed residual ``|I0 - I1(x + f)|`` is lowest."""
    import cv2

    a = c0.astype(np.float32)
    b = c1.astype(np.float32)
    costs = []
    for f in flows:
        r = np.abs(a - _warp(b, f))
        costs.append(cv2.boxFilter(r.sum(axis=2) if r.ndim == 3 else r, -1, (window, window)))
    k = np.argmin(np.stack(costs), axis=0)
    return np.take_along_axis(np.stack(flows), k[None, ..., None], axis=0)[0]


def variational_refine(g0: np.ndarray, g1: np.ndarray, flow: np.ndarray,
                       iterations: int, *, smoothness: float = 20.0,
                       sor_iterations: int = 5) -> np.ndarray:
    """``iterations`` fixed-point steps of the variational refinement of the
    DIS paper (§2.3, eq. 6-7: brightness and gradient constancy, robust
    smoothness; OpenCV's ``VariationalRefinement``, DIS's data weights
    delta 5, gamma 10) on uint8 grey frames ``g0``, ``g1``, starting from
    ``flow`` (px, ``(H, W, 2)``); ``smoothness`` is the paper's alpha (DIS:
    20), ``sor_iterations`` the relaxation sweeps per step (DIS: 5). A new
    float32 array (``flow`` itself when ``iterations`` is 0).

    >>> a = np.tile((np.arange(32) * 8 % 256).astype(np.uint8), (32, 1))
    >>> variational_refine(a, a, np.zeros((32, 32, 2), np.float32), 2).any()
    np.False_
    """
    import cv2

    if iterations == 0:
        return flow
    v = cv2.VariationalRefinement_create()
    # DIS's own refinement weights (alpha smoothness, delta brightness, gamma gradient).
    v.setAlpha(float(smoothness))
    v.setDelta(5.0)
    v.setGamma(10.0)
    v.setSorIterations(int(sor_iterations))
    v.setFixedPointIterations(iterations)
    out = np.ascontiguousarray(flow, np.float32).copy()
    v.calc(g0, g1, out)
    return out


# The weighted median's guide in steps of this many codes. OpenCV's filter
# keeps one histogram per distinct guide value, so its time follows their
# count: 64 levels instead of 256 cut it by a third (Venus 140 -> 90 ms), and
# with weights exp(-d^2 / 2 sigma^2) at sigma = 25.5 codes a step of 4 moves a
# weight by a few percent; chosen on the tuning cases (EPE within 0.3 % or
# better, the accurate call 12-19 % sooner; docs/decisions/flow-default.md).
WMF_GUIDE_STEP = 4


def _wmf(flow, guide, radius):
    import cv2

    if radius == 0:
        return flow
    guide = guide & np.uint8(256 - WMF_GUIDE_STEP)  # floor to a multiple of the step
    # One component at a time: the filter takes 1 or 3 channels and filters
    # each alone, so the same field as a 3-channel pass with a zero third
    # channel (checked bit-equal), ~10 % sooner.
    out = []
    for c in (0, 1):
        # The filter draws from OpenCV's global generator: seeded, the flow
        # depends on its inputs alone (as in stereo.pyramid_flow._median).
        cv2.setRNGSeed(0)
        out.append(cv2.ximgproc.weightedMedianFilter(guide, np.ascontiguousarray(flow[..., c]),
                                                     radius, sigma=25.5))
    return np.dstack(out).astype(np.float32)


def _one_way(g0, g1, c0, c1, p: Preset, init, finish=True):
    return _pinned(_one_way_pinned, g0, g1, c0, c1, p, init, finish)


def _pinned(fn, *args):
    import cv2

    # OpenCV's DIS splits the frame into one stripe per thread, and its
    # spatial propagation runs within a stripe: the answer depends on the
    # thread count. One thread gives byte-stable results on every machine.
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        return fn(*args)
    finally:
        cv2.setNumThreads(threads)


def _one_way_pinned(g0, g1, c0, c1, p: Preset, init, finish=True):
    f = _search(g0, g1, p, p.patch_size, init)
    if p.fuse_patch_sizes:
        f = _fuse(c0, c1, [f] + [_search(g0, g1, p, s, init) for s in p.fuse_patch_sizes])
    f = _median(f, p.median)
    return _finish(g0, c0, g1, f, p) if finish else f


def _finish(g0, c0, g1, f, p: Preset):
    import cv2

    f = variational_refine(g0, g1, f, p.refine_iterations, smoothness=p.refine_smoothness,
                           sor_iterations=p.refine_sor_iterations)
    # The median is guided by luma, not colour: OpenCV clusters a colour
    # guide's values on every call, 10-20 % of the accurate preset's time,
    # for 0-3 % of its EPE on the tuning scenes (docs/decisions/flow-default.md).
    guide = c0 if c0.ndim == 2 else cv2.cvtColor(c0, cv2.COLOR_RGB2GRAY)
    return _wmf(f, guide, p.wmf_radius)


def fill_inconsistent(guide: np.ndarray, flow: np.ndarray, inconsistent: np.ndarray, *,
                      lam: float = 1000.0, sigma_colour: float = 5.0) -> np.ndarray:
    """``flow`` (px, ``(H, W, 2)``) with its ``inconsistent`` pixels (bool
    ``(H, W)``: forward-backward check failed, i.e. occluded or wrong)
    replaced by the consistent flow of their colour region: the ratio
    ``FGS(w f) / FGS(w)`` of two fast global smoother passes (Min et al.
    2014, doi:10.1109/TIP.2014.2366600) guided by ``guide`` (uint8, grey or
    RGB), ``w`` = consistent. An occluded pixel has no match in the other
    frame; it moves with the visible surface it belongs to, as in the
    edge-aware interpolation of EpicFlow (Revaud et al. 2015). Float32.

    >>> g = np.zeros((16, 16), np.uint8); g[:, 8:] = 200
    >>> f = np.zeros((16, 16, 2), np.float32); f[:, 8:, 0] = 3
    >>> bad = np.zeros((16, 16), bool); bad[4:12, 10:14] = True
    >>> f[bad] = 50
    >>> float(np.abs(fill_inconsistent(g, f, bad)[bad, 0] - 3).max()) < 0.1
    True
    """
    fill = weighted_fill(guide, flow, (~inconsistent).astype(np.float32), lam=lam,
                         sigma_colour=sigma_colour)
    return np.where(inconsistent[..., None], fill, flow).astype(np.float32)


def weighted_fill(guide: np.ndarray, flow: np.ndarray, weight: np.ndarray, *,
                  lam: float = 1000.0, sigma_colour: float = 5.0) -> np.ndarray:
    """The ``weight``-weighted (``(H, W)``, >= 0) edge-aware average of
    ``flow`` at every pixel, ``FGS(w f) / FGS(w)``: OpenCV's fast global
    smoother (Min et al. 2014) guided by ``guide`` (uint8, grey or RGB;
    smoothness ``lam``, colour difference ``sigma_colour`` codes at which
    it cuts). Where no weight reaches, 0. Float32 ``(H, W, 2)``.

    >>> g = np.zeros((8, 8), np.uint8)
    >>> f = np.ones((8, 8, 2), np.float32); w = np.zeros((8, 8), np.float32); w[0, 0] = 1
    >>> bool(np.allclose(weighted_fill(g, f, w), 1, atol=1e-3))
    True
    """
    import cv2

    moments = np.dstack([flow * weight[..., None], weight]).astype(np.float32)
    num = cv2.ximgproc.fastGlobalSmootherFilter(guide, moments, lam, sigma_colour)
    return (num[..., :2] / np.maximum(num[..., 2:3], 1e-4)).astype(np.float32)


def texture_confidence(gray8: np.ndarray, *, window: int = 9) -> np.ndarray:
    """In [0, 1]: the smallest eigenvalue of the structure tensor
    (``window`` px box at full size, central differences) against that of
    noise alone, ``lambda / (lambda + 25 lambda_noise)``; a textureless
    window's tensor is noise only, so it scores near 0 (noise sigma:
    Immerkaer 1996). Computed at half size (a quarter of the cost; texture
    over a 9-px window is a smooth quantity) and scaled back up.

    >>> flat = np.full((32, 32), 128, np.uint8)
    >>> float(texture_confidence(flat).max())
    0.0
    """
    import cv2

    from lumigraph.stereo.luma import noise_sigma_immerkaer

    h, w = gray8.shape
    g = gray8.astype(np.float32) * np.float32(1 / 255)
    if min(h, w) >= 32:
        g = cv2.pyrDown(g)
        window = max(3, (window // 2) | 1)
    ix = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=1, scale=0.5, borderType=cv2.BORDER_REPLICATE)
    iy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=1, scale=0.5, borderType=cv2.BORDER_REPLICATE)
    box = lambda x: cv2.boxFilter(x, -1, (window, window), borderType=cv2.BORDER_REFLECT)  # noqa: E731
    jxx, jyy, jxy = box(ix * ix), box(iy * iy), box(ix * iy)
    lam = np.maximum(0.5 * (jxx + jyy) - np.sqrt(0.25 * (jxx - jyy) ** 2 + jxy ** 2), 0)
    # White noise of sigma gives E[Ix^2] = sigma^2 / 2 with central differences
    # (sigma measured on the image the tensor is taken on); 8-bit
    # quantisation puts a floor of 1/255/sqrt(12) under sigma.
    sigma = max(noise_sigma_immerkaer(g), 1 / 255 / math.sqrt(12))
    lam_noise = sigma ** 2 / 2
    conf = (lam / (lam + 25 * lam_noise)).astype(np.float32)
    if conf.shape != (h, w):
        conf = cv2.resize(conf, (w, h), interpolation=cv2.INTER_LINEAR)
    return conf


def dense_inverse_search(reference: np.ndarray, moving: np.ndarray, *, preset: str = "default",
                         max_motion_px: float | None = None, consistency: bool = True,
                         patch_size: int | None = None, patch_stride: int | None = None,
                         descent_iterations: int | None = None,
                         level_refine_iterations: int | None = None,
                         refine_iterations: int | None = None, median: int | None = None,
                         wmf_radius: int | None = None) -> FlowResult:
    """Forward optical flow from ``reference`` to ``moving`` by dense inverse search.

    Parameters
    ----------
    reference, moving : ndarray, ``(H, W)`` or ``(H, W, 3)``, RGB
        ``reference(x) <-> moving(x + flow(x))``; uint8/uint16 codes or float
        in [0, 1]; one shape, at least 8x8 px.
    preset : {"fast", "default", "accurate"}
        A point on the speed-error curve (:data:`PRESETS`); the keyword
        options below override its fields.
    max_motion_px : float, optional
        Expected largest motion (px); default: estimated by tiled phase
        correlation. Beyond half :func:`reach_px` DIS is seeded with the
        tiles' translations (:func:`initial_flow`).
    consistency : bool
        Also compute the backward flow; forward-backward inconsistent pixels
        are marked occluded and get confidence 0 (doubles the cost).
    patch_size, patch_stride, descent_iterations, level_refine_iterations, refine_iterations, median, wmf_radius
        Override the preset (:class:`Preset`).

    Returns
    -------
    FlowResult
        ``flow`` (px), ``confidence`` (texture x consistency), ``occluded``;
        ``levels`` = DIS's coarsest scale + 1; ``info["warnings"]`` says when
        the motion may exceed what the coarsest level reaches.

    Raises
    ------
    InputError
        Different shapes, an empty or tiny frame (``moving``/``reference``),
        or an option out of range (named).
    """
    t0 = time.perf_counter()
    a, b = np.asarray(reference), np.asarray(moving)
    if a.size == 0 or b.size == 0 or min(a.shape[:2]) < 8 or min(b.shape[:2]) < 8:
        raise InputError("reference" if a.size == 0 or min(a.shape[:2]) < 8 else "moving",
                         f"expected a frame of at least 8x8 px, got {a.shape} and {b.shape}")
    if a.shape != b.shape:
        raise InputError("moving", f"expected the shape of reference {a.shape}, got {b.shape}; "
                                   "flow needs frames of one size")
    p = check_options(preset=preset, patch_size=patch_size, patch_stride=patch_stride,
                      descent_iterations=descent_iterations,
                      level_refine_iterations=level_refine_iterations,
                      refine_iterations=refine_iterations,
                      median=median, wmf_radius=wmf_radius)
    g0, g1 = _gray8(a), _gray8(b)
    need_colour = bool(p.fuse_patch_sizes or p.wmf_radius)
    c0, c1 = (_colour8(a), _colour8(b)) if need_colour else (g0, g1)
    shape = g0.shape
    warnings: list[str] = []
    reach = reach_px(shape, p.patch_size)
    if max_motion_px is None:
        from lumigraph.stereo.pyramid import estimate_max_motion

        motion, tiles = estimate_max_motion(g0.astype(np.float32), g1.astype(np.float32))
        source = "estimated"
    else:
        motion, source, tiles = float(max_motion_px), "given", None
        if motion > SEED_FRACTION * reach:
            from lumigraph.stereo.pyramid import estimate_max_motion

            tiles = estimate_max_motion(g0.astype(np.float32), g1.astype(np.float32))[1]
    seed_b = seed_f = None
    shifts = []
    if motion > SEED_FRACTION * reach:
        shifts = [t["shift_px"] for t in tiles if t["response"] > 0.1] if tiles else []
        if shifts:
            seed_f = initial_flow(g0, g1, shifts)
            if consistency or p.fill_occlusions:
                seed_b = initial_flow(g1, g0, [(-x, -y) for x, y in shifts])
    levels = coarsest_scale(shape, p.patch_size) + 1
    identical = np.array_equal(a, b)
    s0, s1 = g0, g1  # what the search and the refinement see
    if p.presmooth > 0:
        import cv2

        s0, s1 = (cv2.GaussianBlur(g, (0, 0), p.presmooth) for g in (g0, g1))
    if identical:
        # Identical frames: zero is the exact minimiser of every term.
        fwd = np.zeros((*shape, 2), np.float32)
    elif p.fill_occlusions:
        from lumigraph.stereo.pyramid import forward_backward

        raw = _one_way(s0, s1, c0, c1, p, seed_f, finish=False)
        raw_b = _one_way(s1, s0, c1, c0, p, seed_b, finish=False)
        inconsistent, _ = forward_backward(raw, raw_b)
        # Where the two agree they are two estimates of one motion: their
        # mean (the backward one negated, taken where the forward one lands).
        bw = _warp(raw_b, raw)
        raw = np.where(inconsistent[..., None], raw, 0.5 * (raw - bw)).astype(np.float32)
        fwd = _pinned(_finish, s0, c0, s1, fill_inconsistent(c0, raw, inconsistent), p)
    else:
        fwd = _one_way(s0, s1, c0, c1, p, seed_f)
    t_fwd = time.perf_counter() - t0
    limit = reach + max((float(np.hypot(*s_)) for s_ in shifts), default=0.0)
    top = float(np.percentile(np.hypot(fwd[..., 0], fwd[..., 1]), 99.9))
    if motion > limit:
        warnings.append(f"motion of {motion:.0f} px ({source}) is beyond the {limit:.0f} px the "
                        "coarsest level reaches (with its seed); larger motion is not found")
    elif top > 0.8 * limit:
        warnings.append(f"flow reaches {top:.0f} px, near the {limit:.0f} px the coarsest level "
                        "reaches (with its seed); larger motion may be missed")
    tex = texture_confidence(g0)
    occluded = np.zeros(shape, bool)
    info = {"method": "dense inverse search (Kroeger et al. 2016; OpenCV DIS inner solver)",
            "preset": preset, "settings": asdict(p), "max_motion_px": motion,
            "motion_source": source, "reach_px": reach,
            "level_choice": {"levels": levels, "coarsest_scale": levels - 1, "reach_px": reach,
                             "max_motion_px": motion, "source": source,
                             "candidates": tiles or []},
            "seed_shifts_px": [list(map(float, x)) for x in shifts], "warnings": warnings}
    if consistency and not identical and p.fill_occlusions:
        occluded = inconsistent  # the check before the fill (the fill makes them agree)
        info["occluded_fraction"] = float(occluded.mean())
    elif consistency and not identical:  # identical: every pixel is seen in both
        from lumigraph.stereo.pyramid import forward_backward

        bwd = _one_way(s1, s0, c1, c0, p, seed_b)
        occluded, rt = forward_backward(fwd, bwd)
        info["occluded_fraction"] = float(occluded.mean())
    conf = np.where(occluded, 0.0, tex).astype(np.float32)
    info["quality"] = {"mean_confidence": float(conf.mean()),
                       "low_confidence_fraction": float((conf < 0.1).mean())}
    info["timings_s"] = {"forward": t_fwd, "total": time.perf_counter() - t0}
    return FlowResult(fwd, conf, occluded, levels, info)
