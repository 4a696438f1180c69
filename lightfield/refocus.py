"""Digital refocusing by shift-and-add, focal stacks, depth and all-in-focus images.

Shift-and-add evaluates reference eq. 5.9 (Ng et al. 2005, "Light Field
Photography with a Hand-held Plenoptic Camera", Stanford CTSR 2005-02) on the
sub-aperture views: the refocused photograph is the average of the views, each
shifted by the slope times its offset from the grid centre,

    E_s(x, y) = 1/(U V) sum_{u, v} L_{u, v}(x - s (v - vc), y - s (u - uc)),

expressed on the centre view's pixel grid (eq. 5.9 up to its 1/alpha
magnification and 1/(alpha^2 F^2) scale, which only rename the output pixels
and brightness). Shifts are separable subpixel resamplings with a choice of
kernel (``KERNELS``); borders extend by mirror symmetry. ``linear`` is the
bilinear baseline; ``lanczos3`` (default) and ``cubic`` (Keys, a = -1/2) keep
the texture's high frequencies that bilinear interpolation smooths away.

The Fourier-slice method (Ng 2005, eqs. 5.10-5.11) is in
:mod:`lightfield.ng2005`; :func:`refocus` and :func:`focal_stack` run a method
by its CLI name from the registry :data:`METHODS`
(:data:`lightfield.methods.REFOCUS_METHODS`).

Examples
--------
>>> import numpy as np
>>> from lumigraph.lightfield.field import LightField
>>> rng = np.random.default_rng(0)
>>> base = rng.random((20, 24, 1)).astype(np.float32)
>>> views = np.stack([np.stack([np.roll(base, (-(u - 1), -(v - 1)), (0, 1)) for v in range(3)])
...                   for u in range(3)])
>>> out = shift_and_add(LightField(views), 1.0)      # integer slope: exact away from borders
>>> float(np.abs(out[3:-3, 3:-3] - base[3:-3, 3:-3]).max()) < 1e-6
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.lightfield.field import LightField
from lumigraph.lightfield.methods import REFOCUS_METHODS as METHODS

KERNELS = ("linear", "cubic", "lanczos3", "bspline3")


def _taps(kernel: str, frac: float) -> tuple[int, np.ndarray]:
    """(first tap offset, weights) to sample at ``n + frac`` from samples ``n + t``."""
    if kernel == "linear":
        return 0, np.array([1.0 - frac, frac])
    if kernel == "cubic":  # Keys (1981), a = -1/2
        a = -0.5
        t = np.arange(-1, 3) - frac
        x = np.abs(t)
        w = np.where(x <= 1, (a + 2) * x ** 3 - (a + 3) * x ** 2 + 1,
                     np.where(x < 2, a * x ** 3 - 5 * a * x ** 2 + 8 * a * x - 4 * a, 0.0))
        return -1, w
    if kernel == "bspline3":  # on prefiltered coefficients (Unser 1999)
        t = np.abs(np.arange(-1, 3) - frac)
        w = np.where(t < 1, 2 / 3 - t ** 2 + t ** 3 / 2, np.where(t < 2, (2 - t) ** 3 / 6, 0.0))
        return -1, w
    if kernel == "lanczos3":
        t = np.arange(-2, 4) - frac
        w = np.sinc(t) * np.sinc(t / 3.0)
        return -2, w / w.sum()
    raise ValueError(f"kernel: expected one of {', '.join(KERNELS)}, got {kernel!r}")


def _shift_axis(img: np.ndarray, shift: float, axis: int, kernel: str, pad: int) -> np.ndarray:
    """Sample ``img`` at ``i + shift`` along ``axis`` (img already padded by ``pad``)."""
    n = img.shape[axis] - 2 * pad
    base = math.floor(shift)
    frac = shift - base
    if frac < 1e-9 and kernel != "bspline3":
        sl = [slice(None)] * img.ndim
        sl[axis] = slice(pad + base, pad + base + n)
        return img[tuple(sl)]
    first, w = _taps(kernel, frac)
    out = None
    for k, wk in enumerate(w):
        sl = [slice(None)] * img.ndim
        start = pad + base + first + k
        sl[axis] = slice(start, start + n)
        term = img[tuple(sl)] * np.float32(wk)
        out = term if out is None else out + term
    return out


def shift_view(view: np.ndarray, dx: float, dy: float, *, kernel: str = "lanczos3") -> np.ndarray:
    """Sample ``view`` (H, W, C) at ``(x + dx, y + dy)`` with mirror borders.

    >>> v = np.arange(12, dtype=np.float32).reshape(3, 4, 1)
    >>> shift_view(v, 1.0, 0.0)[0, :3, 0].tolist()
    [1.0, 2.0, 3.0]
    """
    pad = int(math.ceil(max(abs(dx), abs(dy)))) + 4
    h, w = view.shape[:2]
    if kernel == "bspline3":
        view = spline_coefficients(view)
    if pad >= min(h, w):
        padded = np.pad(view, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
    else:
        padded = np.pad(view, ((pad, pad), (pad, pad), (0, 0)), mode="symmetric")
    tmp = _shift_axis(padded, dx, 1, kernel, pad)
    return np.ascontiguousarray(_shift_axis(tmp, dy, 0, kernel, pad))


def spline_coefficients(view: np.ndarray) -> np.ndarray:
    """Cubic B-spline coefficients of a view along y and x (mirror boundary), float32."""
    from scipy.ndimage import spline_filter1d

    c = spline_filter1d(view.astype(np.float64), 3, axis=0, mode="reflect")
    return spline_filter1d(c, 3, axis=1, mode="reflect").astype(np.float32)


def shift_and_add(lf: LightField, slope: float, *, kernel: str = "lanczos3") -> np.ndarray:
    """Refocus at ``slope`` (px per view step) by shift-and-add (eq. 5.9).

    Parameters
    ----------
    lf : LightField
        Views (U, V, H, W, C) float32 linear.
    slope : float
        Focus: a point of disparity ``slope`` comes out sharp.
    kernel : {"linear", "cubic", "lanczos3"}
        Subpixel interpolation ("linear" is the bilinear baseline).

    Returns
    -------
    ndarray, (H, W, C) float32
        The refocused photograph on the centre view's pixel grid.
    """
    if kernel not in KERNELS:
        raise ValueError(f"kernel: expected one of {', '.join(KERNELS)}, got {kernel!r}")
    u, v = lf.grid
    uc, vc = lf.center
    acc = np.zeros(lf.data.shape[2:], np.float32)
    for i in range(u):
        for j in range(v):
            acc += shift_view(lf.data[i, j], -slope * (j - vc), -slope * (i - uc), kernel=kernel)
    return acc / np.float32(u * v)


def refocusable_slopes(lf: LightField) -> float:
    """Ng's bound on exact refocusing as a slope: ``|s| <= alpha_scale dx/du = 1``
    px per view step (views at most one pixel apart on the focal plane)."""
    return 1.0


def check_refocus_range(lf: LightField, slopes) -> list[str]:
    """Warnings for slopes outside Ng's exact refocusing range (Ng 2005, §6:
    ``|1 - 1/alpha| <= dx/du``): beyond it the refocused image aliases.
    A slope that is not finite is refused (``InputError`` naming ``slopes``)."""
    lo, hi = lf.alpha_range()
    out = []
    if not np.all(np.isfinite(np.asarray(slopes, np.float64))):
        raise InputError("slopes", f"expected finite slopes, got {list(slopes)}")
    for s in slopes:
        if abs(s) > refocusable_slopes(lf) + 1e-12:
            a = lf.alpha_from_slope(s)
            out.append(f"slope {s:.4g} (alpha {a:.4g}) is outside Ng's exact refocusing range "
                       f"|1 - 1/alpha| <= dx/du = {1 / lf.alpha_scale:.4g}, i.e. alpha in "
                       f"[{lo:.4g}, {hi:.4g}], |slope| <= 1 px/view: expect aliasing "
                       "(ghosted copies) in defocused regions")
    return out


def shift_and_add_stack(lf: LightField, slopes, *, kernel: str = "lanczos3") -> np.ndarray:
    """:func:`shift_and_add` at each slope: ``(N, H, W, C)`` float32 (the
    ``shift-add`` entry of :data:`METHODS`)."""
    return np.stack([shift_and_add(lf, float(s), kernel=kernel) for s in slopes])


def focal_stack(lf: LightField, slopes, *, method: str = "shift-add", device="cpu",
                **options) -> np.ndarray:
    """Refocus at each slope: (N, H, W, C) float32.

    ``method`` is a name in :data:`METHODS`, or ``"auto"`` (:func:`choose_method`);
    ``options`` go to that method. ``device`` (:mod:`lumigraph.capture.device`):
    ``"cpu"`` runs the numpy methods, a torch device their ports in
    :mod:`lightfield.refocus_torch` (same result within float32 rounding).
    """
    slopes = [float(s) for s in slopes]
    if method == "auto":
        method = choose_method(lf, len(slopes))
    m = METHODS.resolve(method)
    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.lightfield import refocus_torch

            port = {"shift-add": refocus_torch.shift_and_add_stack_torch,
                    "fourier": refocus_torch.refocus_stack_torch}[m.name]
            return port(lf, slopes, device=dev, **options)
    return m(lf, slopes, **options)


def choose_method(lf: LightField, n_slopes: int) -> str:
    """``fourier`` when the one-time 4-D FFT plus n cheap slices beats n
    shift-and-add passes. Cost model, in shift-and-add refocuses (measured by
    ``lumigraph bench lightfield``, single-threaded, 9x9 views of 512x512x3,
    with the band-limited slice of docs/decisions/fourier-refocus.md): one
    4-D FFT ~ 3 (0.83 s against 0.273 s), one slice ~ 0.1 (the column-blocked
    slice: 0.8x the 0.13 of the one before it, measured side by side); so
    Fourier wins from 4 depths on.

    >>> choose_method(None, 3), choose_method(None, 4)
    ('shift-add', 'fourier')
    """
    fft_cost, slice_cost = 3.0, 0.1
    return "fourier" if fft_cost + slice_cost * n_slopes < n_slopes else "shift-add"


@dataclass(frozen=True)
class DisparityEstimate:
    """A disparity map from a light field (px per view step, centre view).

    Attributes
    ----------
    disparity : ndarray (H, W) float32
        Best focus slope per pixel (parabola-refined).
    confidence : ndarray (H, W) float32
        Cost contrast ``1 - min/median`` over the slopes (0 = flat cost).
    slopes : ndarray (N,) float64
        Candidate slopes.
    """

    disparity: np.ndarray
    confidence: np.ndarray
    slopes: np.ndarray

    def __post_init__(self):
        if self.disparity.shape != self.confidence.shape:
            raise ValueError("confidence: must match disparity's shape")

    def depth(self, lf: LightField) -> np.ndarray:
        """Depth (units of spacing) = focal_px spacing / disparity; NaN where <= 0."""
        if lf.focal_px is None:
            raise InputError("focal_px", "the light field has no focal length")
        d = self.disparity.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(d > 0, lf.focal_px * lf.spacing / d, np.nan)
        return z.astype(np.float32)


# the parabola refining the best candidate needs a neighbour on each side
MIN_DISPARITY_CANDIDATES = 3


def check_disparity_window(window) -> int:
    """The cost aggregation window of :func:`estimate_disparity`: an odd
    integer >= 1 (pixels), or ``InputError`` naming ``window``.

    >>> check_disparity_window(7)
    7
    >>> check_disparity_window(4)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: window: expected an odd integer >= 1 (pixels), got 4
    """
    if isinstance(window, bool) or not isinstance(window, int | np.integer) \
            or window < 1 or window % 2 == 0:
        raise InputError("window", f"expected an odd integer >= 1 (pixels), got {window!r}")
    return int(window)


def check_disparity_slopes(slopes) -> np.ndarray:
    """The candidate disparities of :func:`estimate_disparity`, checked before
    the light field is at hand: at least 3, strictly increasing (float64).

    >>> check_disparity_slopes(np.linspace(-1, 1, 5)).tolist()
    [-1.0, -0.5, 0.0, 0.5, 1.0]
    >>> check_disparity_slopes([1.0, 0.5, 0.0])
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: slopes: expected increasing candidates, got 1 .. 0
    """
    slopes = np.asarray(slopes, np.float64)
    if slopes.ndim != 1 or len(slopes) < MIN_DISPARITY_CANDIDATES:
        raise InputError("slopes", f"expected at least {MIN_DISPARITY_CANDIDATES} candidates, "
                                   f"got {slopes}")
    if not np.all(np.isfinite(slopes)):
        raise InputError("slopes", f"expected finite candidates, got {slopes}")
    if not np.all(np.diff(slopes) > 0):
        raise InputError("slopes", f"expected increasing candidates, got {slopes[0]:g} .. {slopes[-1]:g}")
    return slopes


def estimate_disparity(lf: LightField, slopes, *, window: int = 7,
                       kernel: str = "linear") -> DisparityEstimate:
    """Depth from the light field by angular consistency (the correspondence cue
    of refocusing): at the right slope the shifted views agree, so the
    per-pixel variance across views, box-averaged over ``window``, is least.

    Parameters
    ----------
    lf : LightField
    slopes : sequence of float
        Candidate disparities, evenly spaced; at least 3, strictly increasing
        (:func:`check_disparity_slopes`).
    window : int
        Side of the box over which the cost is aggregated (odd, >= 1;
        :func:`check_disparity_window`).

    Returns
    -------
    DisparityEstimate
    """
    from scipy.ndimage import uniform_filter

    slopes = check_disparity_slopes(slopes)
    window = check_disparity_window(window)
    u, v = lf.grid
    uc, vc = lf.center
    cost = np.empty((len(slopes),) + lf.data.shape[2:4], np.float32)
    for k, s in enumerate(slopes):
        acc = np.zeros(lf.data.shape[2:], np.float32)
        acc2 = np.zeros_like(acc)
        for i in range(u):
            for j in range(v):
                sh = shift_view(lf.data[i, j], -s * (j - vc), -s * (i - uc), kernel=kernel)
                acc += sh
                acc2 += sh * sh
        var = (acc2 / (u * v) - (acc / (u * v)) ** 2).mean(-1)
        cost[k] = uniform_filter(np.maximum(var, 0), window, mode="nearest")
    best = cost.argmin(0)
    k = np.clip(best, 1, len(slopes) - 2)
    c0 = np.take_along_axis(cost, (k - 1)[None], 0)[0]
    c1 = np.take_along_axis(cost, k[None], 0)[0]
    c2 = np.take_along_axis(cost, (k + 1)[None], 0)[0]
    den = c0 - 2 * c1 + c2
    off = np.where(den > 1e-12, 0.5 * (c0 - c2) / np.where(den > 1e-12, den, 1), 0.0)
    off = np.where(best == k, np.clip(off, -0.5, 0.5), 0.0)
    step = slopes[1] - slopes[0]
    disp = slopes[best] + off * step
    med = np.median(cost, 0)
    conf = 1.0 - cost.min(0) / np.maximum(med, 1e-12)
    return DisparityEstimate(disp.astype(np.float32), conf.astype(np.float32), slopes)


def all_in_focus(stack: np.ndarray, slopes, disparity: np.ndarray) -> np.ndarray:
    """Per pixel, the focal-stack slice nearest the pixel's disparity.

    Parameters
    ----------
    stack : (N, H, W, C) focal stack at ``slopes``; disparity : (H, W).

    >>> st = np.stack([np.zeros((2, 2, 1)), np.ones((2, 2, 1))])
    >>> all_in_focus(st, [0.0, 1.0], np.array([[0.1, 0.9], [0.6, 0.0]]))[..., 0].tolist()
    [[0.0, 1.0], [1.0, 0.0]]
    """
    slopes = np.asarray(slopes, np.float64)
    idx = np.abs(disparity[None] - slopes[:, None, None]).argmin(0)
    return np.take_along_axis(stack, idx[None, ..., None], 0)[0]


def refocus(lf: LightField, slope: float, *, method: str = "shift-add", device="cpu",
            **options) -> np.ndarray:
    """One photograph refocused at ``slope`` by the method named as on the
    command line (:data:`METHODS`); ``(H, W, C)`` float32.

    A method that prepares for a range of slopes (it takes ``max_slope``) is
    prepared for this one, at least 1e-3.
    """
    m = METHODS.resolve(method)
    if "max_slope" in m.options:
        options.setdefault("max_slope", max(abs(slope), 1e-3))
    return focal_stack(lf, [slope], method=m.name, device=device, **options)[0]
