"""The torch path of Nayar et al. 2006's per-pixel estimators (checker pairs
and max/min, three-phase sinusoid, occluder max/min), one code path for
torch's CPU device and CUDA.

Nayar, Krishnan, Grossberg and Raskar, "Fast Separation of Direct and Global
Components of a Scene using High Frequency Illumination", ACM SIGGRAPH 2006,
doi:10.1145/1141911.1141977 (reference ch. 8, eqs. 8.12–8.14). The equations,
units and shapes are those of :mod:`lumigraph.separation.nayar2006`; each
function here returns what its namesake there returns.

The arithmetic is the numpy path's, operation for operation, in float32:
sums over the stack axis run one image after another (as numpy reduces an
outer axis), so that thresholds such as a pair's decisiveness
(``|t| >= keep·top``) see the same values and decide alike; a scalar enters
an operation as float32, as under numpy's promotion rules. What is left to
rounding differences is stated in ``tests/device/test_separation_torch.py``.
The tile method ``single`` sorts each tile on the device and
interpolates the tile values as OpenCV's ``resize`` does; its tile means are
numpy's pairwise sums in another order (a bound, not equality). The noise
model, pairing and masks stay on numpy.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.patterns import checker_set
>>> ps = checker_set((8, 8), square=2, shifts=2)
>>> stack = np.stack([0.6 * p + 0.1 for p in ps.images])[..., None].astype(np.float32)
>>> d, g, info = checker(stack, complement_of=ps.complement_of, device="torch-cpu")
>>> bool(np.allclose(d, 0.6, atol=1e-6) and np.allclose(g, 0.2, atol=1e-6))
True
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.device import resolve_device, to_numpy, to_torch, torch_modules
from lumigraph.separation import nayar2006


def _seq_sum(x):
    """Sum over axis 0, one slice after another (numpy's order for an outer axis)."""
    s = x[0].clone()
    for k in range(1, x.shape[0]):
        s += x[k]
    return s


def _solve(lp, lm, *, alpha, b, alpha_minus):
    ap, am, det = nayar2006._coefficients(alpha, alpha_minus, b)
    return (am * lp - ap * lm) / det, (lm - b * lp) / det


def pair_extremes(a, complement_of, *, keep: float = 0.75, sigma=None):
    """:func:`nayar2006.pair_extremes` on a ``(N, ...)`` float32 tensor;
    returns tensors ``l_plus, l_minus`` (float32) and ``pairs_used`` (int16)."""
    torch, _ = torch_modules()
    pairs = sorted({(min(i, j), max(i, j)) for i, j in enumerate(complement_of) if j >= 0 and j != i})
    if not pairs:
        raise ValueError("complement_of: no complementary pairs in the set")
    i0 = torch.as_tensor([p[0] for p in pairs], device=a.device)
    i1 = torch.as_tensor([p[1] for p in pairs], device=a.device)
    t = a[i0] - a[i1]
    ssum = a[i0] + a[i1]
    c = t.abs()
    if sigma is None:
        sig = torch.zeros((), dtype=torch.float32, device=a.device)
    else:
        sig = torch.as_tensor(np.asarray(sigma, np.float32), device=a.device)
    var_t = 2.0 * (sig * sig)
    half = torch.sort(c, dim=0).values[len(pairs) // 2:]
    top = _seq_sum(half) / np.float32(half.shape[0])
    use = (c >= keep * top) | (top <= 3.0 * torch.sqrt(var_t))
    n = _seq_sum(use.to(torch.int64))
    # float32 sums over an int64 count: numpy divides in float64 from here on
    n_safe = n.clamp(min=1).to(torch.float64)
    mean_sum = _seq_sum(ssum * use).to(torch.float64) / n_safe
    ms = _seq_sum(t * t * use).to(torch.float64) / n_safe
    contrast = torch.sqrt(torch.clamp(ms - nayar2006.DEBIAS * var_t.to(torch.float64), min=0.0))
    lp = (0.5 * (mean_sum + contrast)).to(torch.float32)
    lm = (0.5 * (mean_sum - contrast)).to(torch.float32)
    return lp, lm, n.to(torch.int16)


def checker(images: np.ndarray, *, alpha: float = 0.5, b: float = 0.0, complement_of=None,
            estimator: str = "pairs", sigma=None, device="torch-cpu"):
    """:func:`nayar2006.checker` through torch on ``device``; same arguments
    and returns (numpy), ``sigma`` given or estimated as there."""
    torch, _ = torch_modules()
    dev = resolve_device(device)
    a = nayar2006.validate_stack(images, need=2, method="checker")
    n = len(a)
    if complement_of is None:
        from lumigraph.separation.pairing import find_pairs

        complement_of = find_pairs(a).complement_of if estimator == "pairs" else [-1] * n
    complement_of = list(complement_of)
    if len(complement_of) != n:
        raise ValueError(f"complement_of: expected {n} entries, got {len(complement_of)}")
    if estimator not in ("pairs", "maxmin"):
        raise ValueError(f"estimator: expected 'pairs' or 'maxmin', got {estimator!r}")
    has_pairs = any(j >= 0 for j in complement_of)
    t = to_torch(a, dev)
    npairs = None
    if estimator == "pairs" and has_pairs:
        if sigma is None:
            s0, s1 = nayar2006.noise_from_pairs(a, complement_of)
            sigma = np.sqrt(s0 + s1 * np.clip(a.mean(axis=0), 0, None))
        lp, lm, npairs = pair_extremes(t, complement_of, sigma=sigma)
        alpha_minus = 1.0 - alpha
    else:
        lp, lm = t.amax(dim=0), t.amin(dim=0)
        alpha_minus = 1.0 - alpha if has_pairs else alpha
    direct, glob = _solve(lp, lm, alpha=alpha, b=b, alpha_minus=alpha_minus)
    info = {"l_plus": to_numpy(lp), "l_minus": to_numpy(lm), "alpha_plus": alpha,
            "alpha_minus": alpha_minus, "estimator": estimator if has_pairs else "maxmin"}
    if npairs is not None:
        info["pairs_used"] = to_numpy(npairs)
    return to_numpy(direct), to_numpy(glob), info


def sinusoid(images: np.ndarray, *, b: float = 0.0,
             phases=(0.0, 2 * np.pi / 3, 4 * np.pi / 3), device="torch-cpu"):
    """:func:`nayar2006.sinusoid` through torch on ``device``: offset and
    amplitude of the three-step phase shift, ``L_d = 2A/(1 − b)``,
    ``L_g = 2m/(1 + b) − L_d``."""
    from lumigraph.capture.errors import EstimationError

    torch, _ = torch_modules()
    dev = resolve_device(device)
    a = nayar2006.validate_stack(images, need=3, method="sinusoid")
    if len(a) != len(phases):
        raise EstimationError("<images>", f"method 'sinusoid' takes exactly {len(phases)} images "
                                          f"(one per phase), got {len(a)}")
    if not 0.0 <= b < 1.0:
        raise ValueError(f"b: expected 0 <= b < 1, got {b}")
    t = to_torch(a, dev)
    ph = np.asarray(phases, np.float64)
    cw, sw = np.cos(ph).astype(np.float32), np.sin(ph).astype(np.float32)
    cos = _seq_sum(torch.stack([t[k] * cw[k] for k in range(len(ph))]))
    sin = _seq_sum(torch.stack([t[k] * sw[k] for k in range(len(ph))]))
    amp = np.float32(2.0 / len(ph)) * torch.sqrt(cos * cos + sin * sin)
    mean = _seq_sum(t) / np.float32(len(a))
    direct = amp / (0.5 * (1.0 - b))
    glob = 2.0 * mean / (1.0 + b) - direct
    return (to_numpy(direct), to_numpy(glob),
            {"l_plus": to_numpy(t.amax(dim=0)), "l_minus": to_numpy(t.amin(dim=0)),
             "amplitude": to_numpy(amp), "offset": to_numpy(mean)})


def occluder(images: np.ndarray, *, alpha: float | None = None, b: float = 0.0,
             device="torch-cpu"):
    """:func:`nayar2006.occluder` through torch on ``device``: max/min over
    the sweep; α measured from the extremes (a strided sample, on numpy)
    unless given."""
    dev = resolve_device(device)
    a = nayar2006.validate_stack(images, need=3, method="occluder")
    t = to_torch(a, dev)
    lp, lm = t.amax(dim=0), t.amin(dim=0)
    lpn, lmn = to_numpy(lp), to_numpy(lm)
    source = "given"
    if alpha is None:
        alpha, source = nayar2006.occluder_lit_fraction(a, lpn, lmn), "measured"
    direct, glob = _solve(lp, lm, alpha=alpha, b=b, alpha_minus=alpha)
    return to_numpy(direct), to_numpy(glob), {"l_plus": lpn, "l_minus": lmn, "alpha": float(alpha),
                                              "alpha_source": source}


def _reflect101(n: int, m: int):
    """Indices ``0 .. m − 1`` of a length-``n`` axis extended by numpy's
    ``mode="reflect"`` (the edge not repeated), for any ``m``."""
    if n == 1:
        return np.zeros(m, np.int64)
    i = np.arange(m) % (2 * (n - 1))
    return np.where(i >= n, 2 * (n - 1) - i, i)


def single(images: np.ndarray, *, alpha: float = 0.5, b: float = 0.0, tile: int = 16,
           fraction: float = 0.2, device="torch-cpu"):
    """:func:`nayar2006.single` through torch on ``device``: per tile the
    means of the brightest and darkest ``fraction`` of the pixels (a sort per
    tile), interpolated bilinearly from the tile centres as OpenCV's
    ``resize`` does (centres at ``(i + ½)·tile − ½``, edges clamped), then
    solved with α⁺ = α⁻ = ``alpha``."""
    from lumigraph.capture.errors import EstimationError
    from lumigraph.capture.remap_torch import remap_tensor

    torch, _ = torch_modules()
    dev = resolve_device(device)
    a = nayar2006.validate_stack(images, need=1, method="single")
    if len(a) != 1:
        raise EstimationError("<images>", f"method 'single' takes exactly one image, got {len(a)}")
    if tile < 2:
        raise ValueError(f"tile: expected >= 2 pixels, got {tile}")
    img = to_torch(a[0], dev)
    h, w, c = img.shape
    th, tw = max(1, -(-h // tile)), max(1, -(-w // tile))
    iy = torch.as_tensor(_reflect101(h, th * tile), device=img.device)
    ix = torch.as_tensor(_reflect101(w, tw * tile), device=img.device)
    pad = img.index_select(0, iy).index_select(1, ix)
    blocks = pad.reshape(th, tile, tw, tile, c).permute(0, 2, 4, 1, 3).reshape(th, tw, c, -1)
    srt = torch.sort(blocks, dim=-1).values
    k = max(1, int(round(fraction * srt.shape[-1])))
    lp_t = srt[..., -k:].mean(dim=-1)
    lm_t = srt[..., :k].mean(dim=-1)
    # cv2.resize's source position of output pixel d: (d + ½)/tile − ½, in float32
    mx = torch.as_tensor(((np.arange(w) + 0.5) / tile - 0.5).astype(np.float32), device=img.device)
    my = torch.as_tensor(((np.arange(h) + 0.5) / tile - 0.5).astype(np.float32), device=img.device)
    mx, my = mx[None, :].expand(h, w), my[:, None].expand(h, w)

    def up(t):
        # replicate border = resize's clamping at the edges; never snapped (resize is not remap)
        return remap_tensor(t.permute(2, 0, 1).contiguous(), mx, my, border="replicate",
                            snap=False).permute(1, 2, 0)

    lp, lm = up(lp_t), up(lm_t)
    direct, glob = _solve(lp, lm, alpha=alpha, b=b, alpha_minus=alpha)
    return to_numpy(direct), to_numpy(glob), {"l_plus": to_numpy(lp), "l_minus": to_numpy(lm),
                                              "tile": tile}


METHODS = {"checker": checker, "sinusoid": sinusoid, "occluder": occluder, "single": single}
