"""Fast separation of direct and global light with high-frequency illumination.

Nayar, Krishnan, Grossberg and Raskar, "Fast Separation of Direct and Global
Components of a Scene using High Frequency Illumination", ACM SIGGRAPH 2006,
doi:10.1145/1141911.1141977 (reference ch. 8, §8.3.3–8.3.4, Fig. 8.43,
eqs. 8.12–8.14).

Model. A projector pattern lights a fraction α of its pixels; off pixels leak a
fraction ``b`` (the black level) of the on level. A scene point that is lit
directly sees its direct light ``L_d`` (``b·L_d`` when unlit), and, because
global transport averages a high-frequency pattern (eq. 8.12), a global part
``a·L_g`` with ``a = b + (1 − b)·α`` for an image whose lit fraction is α.
With ``L⁺`` taken from an image in which the pixel is lit (lit fraction α⁺) and
``L⁻`` from one where it is not (lit fraction α⁻):

    L⁺ = L_d + a⁺·L_g,      a⁺ = b + (1 − b)·α⁺
    L⁻ = b·L_d + a⁻·L_g,    a⁻ = b + (1 − b)·α⁻

whose solution (the **b-corrected pair**) is

    L_d = (a⁻·L⁺ − a⁺·L⁻) / (a⁻ − b·a⁺),      L_g = (L⁻ − b·L⁺) / (a⁻ − b·a⁺).

For a pattern and its complement (α⁻ = 1 − α⁺ = 1 − α) and ``b = 0`` this is
eqs. 8.13–8.14 (``L_g = L⁻/(1 − α)``, ``L_d = L⁺ − α·L_g``); for α = ½ it is the
book's pair ``L_d = (L⁺ − L⁻)/(1 − b)``, ``L_g = 2(L⁻ − b·L⁺)/(1 − b²)``.
When both extremes come from shifts of one pattern (α⁺ = α⁻ = α) it reduces to
``L_d = (L⁺ − L⁻)/(1 − b)``, ``L_g = (L⁻ − b·L⁺)/((1 − b)·a)``.

Methods (all take linear images ``(N, H, W, C)`` float32):

- :func:`checker` — shifted checkerboards and complements; ``estimator="maxmin"``
  is the textbook ``L⁺ = max``, ``L⁻ = min`` over the set (Fig. 8.43);
  ``estimator="pairs"`` (default) classifies each pixel lit/unlit in every
  complementary pair and averages the decisive pairs, which removes the
  noise bias of max/min (the max of many noisy images is biased up, the min
  down) and divides the noise by √(pairs);
- :func:`sinusoid` — three phase-shifted sinusoids, solved exactly per pixel
  (offset and amplitude of a three-step phase shift);
- :func:`single` — one stripe image, ``L±`` per tile, interpolated back;
- :func:`occluder` — a shadow sweep (a pole or a mesh moved over the scene):
  ``L⁺`` the maximum, ``L⁻`` the minimum over the frames, α measured from them.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> d, g = rng.uniform(0.2, 1, (4, 5, 1)), rng.uniform(0.1, 0.5, (4, 5, 1))
>>> lp, lm = d + 0.5 * g, 0.5 * g                    # alpha = 0.5, b = 0
>>> sd, sg = solve(lp, lm, alpha=0.5, b=0.0)
>>> bool(np.allclose(sd, d) and np.allclose(sg, g))
True
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.errors import EstimationError

MASK_NEVER_LIT, MASK_SATURATED, MASK_LOW_CONTRAST = 1, 2, 4
DEBIAS = 1.0


def _coefficients(alpha_plus: float, alpha_minus: float, b: float) -> tuple[float, float, float]:
    if not 0.0 < alpha_plus < 1.0 or not 0.0 < alpha_minus < 1.0:
        raise ValueError(f"alpha: expected lit fractions in (0, 1), got {alpha_plus}, {alpha_minus}")
    if not 0.0 <= b < 1.0:
        raise ValueError(f"b: expected 0 <= b < 1, got {b}")
    ap = b + (1.0 - b) * alpha_plus
    am = b + (1.0 - b) * alpha_minus
    det = am - b * ap
    return ap, am, det


def solve(l_plus: np.ndarray, l_minus: np.ndarray, *, alpha: float = 0.5, b: float = 0.0,
          alpha_minus: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Direct and global light from ``L⁺``/``L⁻`` (eqs. 8.13–8.14, b-corrected).

    Parameters
    ----------
    l_plus, l_minus : ndarray, float, same shape
        Linear radiance with the pixel lit / unlit.
    alpha : float in (0, 1)
        Lit fraction α⁺ of the image giving ``L⁺``.
    b : float in [0, 1)
        Projector black level.
    alpha_minus : float, optional
        Lit fraction α⁻ of the image giving ``L⁻``; default ``1 − alpha`` (the
        complement, as in eq. 8.14).

    Returns
    -------
    direct, global : ndarray, float32
        ``L_d = (a⁻L⁺ − a⁺L⁻)/(a⁻ − b a⁺)``, ``L_g = (L⁻ − b L⁺)/(a⁻ − b a⁺)``
        with ``a± = b + (1 − b) α±`` (see the module docstring).

    Examples
    --------
    >>> d, g, b = np.array([1.0]), np.array([0.4]), 0.15
    >>> lp, lm = d + (1 + b) / 2 * g, b * d + (1 + b) / 2 * g   # the book's pair
    >>> [round(float(v[0]), 6) for v in solve(lp, lm, b=b)]
    [1.0, 0.4]
    """
    am_frac = 1.0 - alpha if alpha_minus is None else alpha_minus
    ap, am, det = _coefficients(alpha, am_frac, b)
    lp = np.asarray(l_plus, np.float32)
    lm = np.asarray(l_minus, np.float32)
    direct = (am * lp - ap * lm) / det
    glob = (lm - b * lp) / det
    return direct.astype(np.float32), glob.astype(np.float32)


def extremes(images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The textbook ``L⁺ = max``, ``L⁻ = min`` over a shifted set (Fig. 8.43).

    Examples
    --------
    >>> lp, lm = extremes(np.array([[1.0, 5.0], [3.0, 2.0]]))
    >>> lp.tolist(), lm.tolist()
    ([3.0, 5.0], [1.0, 2.0])
    """
    a = np.asarray(images)
    return a.max(axis=0).astype(np.float32), a.min(axis=0).astype(np.float32)


def pair_extremes(images: np.ndarray, complement_of, *, keep: float = 0.75, sigma=None):
    """``L±`` from complementary pairs: every pair votes lit/unlit, decisive pairs average.

    In each pair (a pattern and its complement) the pixel is lit in one image
    and unlit in the other, so the pair's difference ``t = I_P − I_P̄`` is
    ``±(L⁺ − L⁻)`` plus noise and its sum ``I_P + I_P̄ = L⁺ + L⁻`` plus noise.
    Pairs whose contrast ``|t|`` reaches ``keep`` times the mean contrast of the
    better half of the pairs are decisive (pairs where the pixel straddles a
    square edge are not); when even the best contrast is within 3 noise
    standard deviations every pair is used (the pixel may simply be unlit).
    Then, the sum over all pairs and the contrast over the decisive ones,

        L⁺ + L⁻ = mean(I_P + I_P̄),     L⁺ − L⁻ = sqrt(max(mean(t²) − σ_t², 0)),

    with ``σ_t² = 2σ²`` the noise variance of ``t``: both are unbiased under
    noise (max/min over all images is biased, the max up and the min down), and
    their noise falls as 1/√(decisive pairs).

    Parameters
    ----------
    images : ndarray, ``(N, ...)``
        Linear images.
    complement_of : sequence of int
        Index of each image's complement (``-1`` for none).
    sigma : ndarray or float, optional
        Noise standard deviation of one capture (``images.shape[1:]`` or
        scalar); 0 when omitted.

    Returns
    -------
    l_plus, l_minus : ndarray, float32, ``images.shape[1:]``
    pairs_used : ndarray, int16, ``images.shape[1:]``

    Examples
    --------
    >>> im = np.array([[4.0], [1.0], [1.1], [4.1]])   # two pairs: (0,1), (2,3)
    >>> lp, lm, n = pair_extremes(im, [1, 0, 3, 2])
    >>> round(float(lp[0]), 3), round(float(lm[0]), 3), int(n[0])
    (4.05, 1.05, 2)
    """
    a = np.asarray(images, np.float32)
    pairs = sorted({(min(i, j), max(i, j)) for i, j in enumerate(complement_of) if j >= 0 and j != i})
    if not pairs:
        raise ValueError("complement_of: no complementary pairs in the set")
    i0 = [p[0] for p in pairs]
    i1 = [p[1] for p in pairs]
    t = a[i0] - a[i1]
    ssum = a[i0] + a[i1]
    c = np.abs(t)
    var_t = 2.0 * np.square(np.asarray(0.0 if sigma is None else sigma, np.float32))
    top = np.sort(c, axis=0)[len(pairs) // 2:].mean(axis=0)
    use = (c >= keep * top) | (top <= 3.0 * np.sqrt(var_t))
    n = use.sum(axis=0)
    n_safe = np.maximum(n, 1)
    mean_sum = (ssum * use).sum(axis=0) / n_safe
    ms = (t * t * use).sum(axis=0) / n_safe
    contrast = np.sqrt(np.maximum(ms - DEBIAS * var_t, 0.0))
    lp = 0.5 * (mean_sum + contrast)
    lm = 0.5 * (mean_sum - contrast)
    return lp.astype(np.float32), lm.astype(np.float32), n.astype(np.int16)


def noise_from_pairs(images: np.ndarray, complement_of) -> tuple[float, float]:
    """Fit ``σ²(I) = s0 + s1·I`` to the spread of pattern+complement sums.

    Every pair sums to the same all-on image (``(1 + b)·white``), so the
    per-pixel variance of the pair sums across pairs is ``2σ²`` of one capture;
    a straight line in the mean level captures read and shot noise.

    Returns
    -------
    s0, s1 : float
        Variance at zero and its slope in the linear units of ``images``.
    """
    a = np.asarray(images, np.float32)
    pairs = sorted({(min(i, j), max(i, j)) for i, j in enumerate(complement_of) if j >= 0 and j != i})
    if len(pairs) < 2:
        return 0.0, 0.0
    step = noise_step(a[0].size)
    sums = np.stack([(a[i] + a[j]).ravel()[::step] for i, j in pairs])
    return noise_fit(sums)


def noise_step(size: int) -> int:
    """Stride of the flat pixels :func:`noise_from_pairs` fits (about 20000 of them)."""
    return max(1, size // 20000)


def noise_fit(sums: np.ndarray) -> tuple[float, float]:
    """:func:`noise_from_pairs`'s line through pair sums ``(P, M)`` already
    sampled (every :func:`noise_step`-th flat value): the variance and mean are
    per value, so a sample gathered band by band gives the same numbers."""
    if len(sums) < 2:
        return 0.0, 0.0
    var = sums.var(axis=0, ddof=1) / 2.0
    level = sums.mean(axis=0) / 2.0
    x, y = level.astype(np.float64), var.astype(np.float64)
    A = np.stack([np.ones_like(x), x], axis=1)
    s0, s1 = np.linalg.lstsq(A, y, rcond=None)[0]
    return max(float(s0), 0.0), max(float(s1), 0.0)


def validate_stack(images: np.ndarray, *, need: int, method: str) -> np.ndarray:
    """Check a linear stack ``(N, H, W, C)`` for a method; return float32."""
    a = np.asarray(images)
    if a.ndim == 3:
        a = a[..., None]
    if a.ndim != 4:
        raise ValueError(f"images: expected (N, H, W, C) linear images, got shape {np.shape(images)}")
    if len(a) < need:
        raise EstimationError("<images>", f"method {method!r} needs at least {need} images, got {len(a)}")
    if a.dtype.kind != "f":
        raise TypeError(f"images: expected float linear values, got {a.dtype}")
    return a.astype(np.float32, copy=False)


def checker(images: np.ndarray, *, alpha: float = 0.5, b: float = 0.0, complement_of=None,
            estimator: str = "pairs", sigma=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Separate a shifted-checkerboard (or shifted binary pattern) stack.

    Parameters
    ----------
    images : ndarray, ``(N, H, W, C)`` float32, linear
        Shifted patterns and their complements, in any order, or shifts of
        one pattern without complements.
    alpha : float in (0, 1)
        Lit fraction of the patterns.
    b : float in [0, 1)
        Projector black level.
    complement_of : sequence of int, optional
        Complement index per image; default: found from the images
        (:func:`separation.pairing.find_pairs`, which raises
        :class:`InputError` for a missing complement); ``maxmin`` needs none.
    estimator : {"pairs", "maxmin"}
        ``pairs``: :func:`pair_extremes` (noise-robust); ``maxmin``: the
        textbook max/min over all images (Fig. 8.43).
    sigma : ndarray or float, optional
        Noise standard deviation of one capture, for the ``pairs`` estimator's
        debiasing (default: estimated from the pattern+complement sums).

    Returns
    -------
    direct, global : ndarray, ``(H, W, C)`` float32
    info : dict
        ``l_plus``, ``l_minus`` arrays and the lit fractions used.

    Examples
    --------
    >>> from lumigraph.capture.patterns import checker_set
    >>> ps = checker_set((8, 8), square=2, shifts=2)
    >>> d = np.full((8, 8), 0.6); g = np.full((8, 8), 0.2)
    >>> stack = np.stack([d * p + 0.5 * g for p in ps.images])[..., None]
    >>> sd, sg, _ = checker(stack, complement_of=ps.complement_of)
    >>> bool(np.allclose(sd, 0.6, atol=1e-6) and np.allclose(sg, 0.2, atol=1e-6))
    True
    """
    a = validate_stack(images, need=2, method="checker")
    n = len(a)
    if complement_of is None:
        # from the captures, whatever their order (a board plus its complement is all-lit)
        from lumigraph.separation.pairing import find_pairs

        complement_of = find_pairs(a).complement_of if estimator == "pairs" else [-1] * n
    complement_of = list(complement_of)
    if len(complement_of) != n:
        raise ValueError(f"complement_of: expected {n} entries, got {len(complement_of)}")
    has_pairs = any(j >= 0 for j in complement_of)
    if estimator == "pairs" and has_pairs:
        if sigma is None:
            s0, s1 = noise_from_pairs(a, complement_of)
            sigma = np.sqrt(s0 + s1 * np.clip(a.mean(axis=0), 0, None))
        lp, lm, npairs = pair_extremes(a, complement_of, sigma=sigma)
        alpha_minus = 1.0 - alpha
    elif estimator in ("pairs", "maxmin"):
        lp, lm = extremes(a)
        npairs = None
        # max/min over shifts of one pattern: both extremes from images of lit fraction α;
        # over a set with complements (α = ½ in practice) the minimum comes from a complement.
        alpha_minus = 1.0 - alpha if has_pairs else alpha
    else:
        raise ValueError(f"estimator: expected 'pairs' or 'maxmin', got {estimator!r}")
    direct, glob = solve(lp, lm, alpha=alpha, b=b, alpha_minus=alpha_minus)
    info = {"l_plus": lp, "l_minus": lm, "alpha_plus": alpha, "alpha_minus": alpha_minus,
            "estimator": estimator if has_pairs else "maxmin"}
    if npairs is not None:
        info["pairs_used"] = npairs
    return direct, glob, info


def sinusoid(images: np.ndarray, *, b: float = 0.0,
             phases=(0.0, 2 * np.pi / 3, 4 * np.pi / 3)) -> tuple[np.ndarray, np.ndarray, dict]:
    """Separate three phase-shifted sinusoids ``0.5 + 0.5 cos(θ + φ_k)`` (§8.3.4).

    A lit point sees ``I_k = L_d·(b + (1 − b)(½ + ½cos(θ + φ_k))) + L_g·(1 + b)/2``
    (the global part sees the pattern's mean). The three-step phase shift gives
    the offset ``m = mean_k I_k`` and amplitude ``A = (2/3)|Σ_k I_k e^{iφ_k}|``
    exactly, so ``L_d = 2A/(1 − b)`` and ``L_g = 2m/(1 + b) − L_d`` — no max/min.

    Examples
    --------
    >>> th = np.linspace(0, 6, 7)[:, None]
    >>> ims = np.stack([0.8 * (0.5 + 0.5 * np.cos(th + p)) + 0.3 * 0.5
    ...                 for p in (0, 2 * np.pi / 3, 4 * np.pi / 3)])
    >>> d, g, _ = sinusoid(ims[..., None])
    >>> bool(np.allclose(d, 0.8, atol=1e-5) and np.allclose(g, 0.3, atol=1e-5))
    True
    """
    a = validate_stack(images, need=3, method="sinusoid")
    if len(a) != len(phases):
        raise EstimationError("<images>", f"method 'sinusoid' takes exactly {len(phases)} images "
                                          f"(one per phase), got {len(a)}")
    if not 0.0 <= b < 1.0:
        raise ValueError(f"b: expected 0 <= b < 1, got {b}")
    ph = np.asarray(phases, np.float64)
    # Weighted sums image by image, in order: elementwise float32 arithmetic gives every
    # pixel the same bits whatever the array's size. A BLAS product (tensordot, numpy
    # 2.4's OpenBLAS) rounds by the blocking, so a band of rows differed from the whole
    # image in the last bit (issue 19's bands are bit-identical to the untiled run).
    cw, sw = np.cos(ph).astype(np.float32), np.sin(ph).astype(np.float32)
    cos, sin = cw[0] * a[0], sw[0] * a[0]
    for k in range(1, len(ph)):
        cos = cos + cw[k] * a[k]
        sin = sin + sw[k] * a[k]
    amp = (2.0 / len(ph)) * np.sqrt(cos * cos + sin * sin)
    mean = a.mean(axis=0)
    direct = amp / (0.5 * (1.0 - b))
    glob = 2.0 * mean / (1.0 + b) - direct
    lp, lm = extremes(a)
    return (direct.astype(np.float32), glob.astype(np.float32),
            {"l_plus": lp, "l_minus": lm, "amplitude": amp, "offset": mean})


def single(images: np.ndarray, *, alpha: float = 0.5, b: float = 0.0, tile: int = 16,
           fraction: float = 0.2) -> tuple[np.ndarray, np.ndarray, dict]:
    """Separate one image under a high-frequency stripe pattern (§8.3.4, Fig. 8.47).

    The image is cut into ``tile×tile`` tiles, each spanning at least one stripe
    period; in each tile ``L⁺`` is the mean of the brightest ``fraction`` of the
    pixels and ``L⁻`` the mean of the darkest (robust max/min), then both are
    interpolated bilinearly from the tile centres back to every pixel and
    solved with α⁺ = α⁻ = ``alpha`` (both extremes see the same image). Assumes
    the scene varies slowly within a tile: detail finer than a tile is lost.

    Examples
    --------
    >>> x = np.arange(32)
    >>> stripe = (x % 4 < 2).astype(float)
    >>> img = np.broadcast_to(0.6 * stripe + 0.5 * 0.2, (32, 32))[None, ..., None]
    >>> d, g, _ = single(img, tile=8)
    >>> round(float(d.mean()), 4), round(float(g.mean()), 4)
    (0.6, 0.2)
    """
    a = validate_stack(images, need=1, method="single")
    if len(a) != 1:
        raise EstimationError("<images>", f"method 'single' takes exactly one image, got {len(a)}")
    if tile < 2:
        raise ValueError(f"tile: expected >= 2 pixels, got {tile}")
    import cv2

    img = a[0]
    h, w, c = img.shape
    th, tw = max(1, -(-h // tile)), max(1, -(-w // tile))
    pad = np.pad(img, ((0, th * tile - h), (0, tw * tile - w), (0, 0)), mode="reflect")
    blocks = pad.reshape(th, tile, tw, tile, c).transpose(0, 2, 4, 1, 3).reshape(th, tw, c, -1)
    srt = np.sort(blocks, axis=-1)
    k = max(1, int(round(fraction * srt.shape[-1])))
    lp_t = srt[..., -k:].mean(axis=-1)
    lm_t = srt[..., :k].mean(axis=-1)

    def up(t):
        # tile centres sit at (i + 0.5)·tile − 0.5; resize of the padded grid maps them there
        big = cv2.resize(t.astype(np.float32), (tw * tile, th * tile), interpolation=cv2.INTER_LINEAR)
        return big[:h, :w].reshape(h, w, c)

    lp, lm = up(lp_t), up(lm_t)
    direct, glob = solve(lp, lm, alpha=alpha, b=b, alpha_minus=alpha)
    return direct, glob, {"l_plus": lp, "l_minus": lm, "tile": tile}


def occluder_lit_fraction(images: np.ndarray, l_plus: np.ndarray, l_minus: np.ndarray,
                          *, step: int = 2) -> float:
    """The lit fraction α of a shadow sweep, measured from its frames.

    α is the fraction of the source's light that reaches a point in a typical
    frame (``1 − shadow width / sweep`` for a pole, the open area of a mesh).
    Among pixels whose shadow contrast ``L⁺ − L⁻`` is at least half the 90th
    percentile (pixels the sweep visibly covers), α is the fraction of
    (frame, pixel) samples nearer ``L⁺`` than ``L⁻``; every ``step``-th row and
    column is enough. The result is clipped to ``[1/N, 1 − 1/N]``.

    Raises
    ------
    EstimationError
        No pixel changes across the frames (no moving shadow).

    Examples
    --------
    >>> frames = np.ones((4, 2, 8, 1)); frames[np.arange(4), :, np.arange(4) * 2] = 0.2
    >>> occluder_lit_fraction(frames, frames.max(axis=0), frames.min(axis=0), step=1)
    0.75
    """
    from lumigraph.separation.residue import strided_percentile

    a = np.asarray(images)[:, ::step, ::step]
    lp = np.asarray(l_plus, np.float32)[::step, ::step]
    lm = np.asarray(l_minus, np.float32)[::step, ::step]
    # the exact order statistics (bands of rows find the same: separation.tiled)
    top = strided_percentile(lp - lm, OCCLUDER_PERCENTILE, stride=1, absolute=False)
    return occluder_alpha(*occluder_lit_counts(a, lp, lm, top=top), frames=len(a))


OCCLUDER_PERCENTILE = 90.0  # of L+ - L-: pixels at half of it or more are swept


def occluder_lit_counts(a, lp, lm, *, top: float) -> tuple[int, int]:
    """:func:`occluder_lit_fraction`'s (frame, pixel) samples nearer ``L⁺`` than
    ``L⁻`` among the swept pixels, and all swept samples: integers (a band's
    counts add up), from the strided frames ``a`` and extremes ``lp``, ``lm``."""
    if not top > 0:
        raise EstimationError("<images>", "no pixel changes across the frames (no moving shadow): "
                                          "the occluder method needs a shadow swept over the scene")
    sel = (lp - lm) >= 0.5 * top
    lit = a[:, sel] > 0.5 * (lp + lm)[sel]
    return int(lit.sum()), int(lit.size)


def occluder_alpha(lit: int, total: int, *, frames: int) -> float:
    """α from :func:`occluder_lit_counts`, clipped to ``[1/N, 1 − 1/N]``."""
    return float(np.clip(lit / max(total, 1), 1.0 / frames, 1.0 - 1.0 / frames))


def occluder(images: np.ndarray, *, alpha: float | None = None,
             b: float = 0.0) -> tuple[np.ndarray, np.ndarray, dict]:
    """Separate a shadow sweep: a thin occluder or a mesh moved across the scene
    (Nayar et al. 2006, §5; reference ch. 8, §8.3.4, Fig. 8.46).

    A pixel is lit in some frames and in the umbra in others, so, as the paper
    and the book take them, ``L⁺`` is the per-pixel maximum over the frames
    and ``L⁻`` the minimum. Every frame has the same lit fraction α (the
    occluder blocks the same share of the source wherever it is), so both
    extremes see ``α·L_g``: ``L_d = (L⁺ − L⁻)/(1 − b)``, ``L_g = L⁻/α`` for
    ``b = 0``. α is measured from the frames (:func:`occluder_lit_fraction`)
    unless given: a pole leaves α near 1, a mesh its open fraction.

    The maximum and minimum of noisy frames are biased (up and down by about
    the noise times the expected extreme of N draws); a pixel the sweep never
    lit fully (too few frames, a penumbra wider than the step) keeps too low
    an ``L⁺`` and too much of its direct light in the global image.

    Examples
    --------
    >>> frames = np.full((4, 3, 1), 0.7 + 0.75 * 0.2)   # lit: d + (3/4) g
    >>> frames[1] = 0.75 * 0.2                           # pixel in shadow
    >>> d, g, info = occluder(frames[:, :, None, :])
    >>> round(float(d.mean()), 5), round(float(g.mean()), 5), info["alpha"], info["alpha_source"]
    (0.7, 0.2, 0.75, 'measured')
    """
    a = validate_stack(images, need=3, method="occluder")
    lp, lm = extremes(a)
    source = "given"
    if alpha is None:
        alpha, source = occluder_lit_fraction(a, lp, lm), "measured"
    direct, glob = solve(lp, lm, alpha=alpha, b=b, alpha_minus=alpha)
    return direct, glob, {"l_plus": lp, "l_minus": lm, "alpha": float(alpha),
                          "alpha_source": source}


def black_level(black: np.ndarray, white: np.ndarray, *, floor: float) -> float:
    """Projector black level ``b`` from all-black and all-white frames.

    Every light path scales with the projector's output, so ``black = b·white``
    pixel by pixel; ``b`` is the median ratio over pixels whose white value is
    well above ``floor`` (the noise) and above 5 % of the white frame's 99th
    percentile. :func:`black_level_rows` on the whole frame (both are float32
    values; the order statistics are exact, so bands give the same number).

    Examples
    --------
    >>> w = np.linspace(0.2, 1.0, 50)
    >>> round(black_level(0.15 * w, w, floor=0.01), 6)
    0.15
    """
    bl, wh = np.asarray(black), np.asarray(white)
    return black_level_rows(lambda y0, y1: (bl[y0:y1], wh[y0:y1]), [(0, len(wh))], floor=floor)


def black_level_rows(read, ranges, *, floor: float) -> float:
    """:func:`black_level` of frames read in bands of rows: ``read(y0, y1)`` →
    ``(black, white)`` rows, for each ``(y0, y1)`` of ``ranges`` (covering the
    frames). Six passes: the white frame's 99th percentile (exact order
    statistics, two), then the median of the float64 ratios over the pixels
    kept (a radix select on their bits, four); memory: a few 2^16-bin
    histograms beside a band.

    Raises
    ------
    EstimationError
        Fewer than 16 pixels of the white frame are bright enough.
    """
    from lumigraph.separation.residue import RadixSelect, float_keys, key_float

    if len(ranges) == 1:  # whole: the same order statistics, by np.partition (faster)
        return _black_level_whole(*read(*ranges[0]), floor=floor)
    top = RadixSelect(32)
    while True:
        for y0, y1 in ranges:
            top.add(float_keys(np.asarray(read(y0, y1)[1], np.float32)))
        if top.refine(lambda n: _ranks(BLACK_PERCENTILE, n)):
            break
    lo, hi = (key_float(k, np.float32) for k in top.values())
    p99 = _lerp(lo, hi, BLACK_PERCENTILE, top.total)
    thr = max(10.0 * floor, 0.05 * p99)
    med = RadixSelect(64)
    while True:
        for y0, y1 in ranges:
            bl, wh = read(y0, y1)
            wh = np.asarray(wh, np.float32).astype(np.float64)
            ok = wh > thr
            med.add(float_keys(np.asarray(bl, np.float32).astype(np.float64)[ok] / wh[ok]))
        if med.total < 16:
            raise EstimationError("white", "the all-white frame is too dark to measure the black "
                                           "level")
        if med.refine(lambda n: ((n - 1) // 2, n // 2)):
            break
    a, b = (key_float(k, np.float64) for k in med.values())
    return float((a + b) / 2.0)


BLACK_PERCENTILE = 99.0  # of the white frame: pixels above 5 % of it measure b


def _black_level_whole(black, white, *, floor: float) -> float:
    # black_level_rows' steps on one band: the k-th smallest sortable key is the same
    # key whether a radix select or a partition finds it
    from lumigraph.separation.residue import float_keys, key_float

    def select(keys, ranks, dtype):
        part = np.partition(keys, sorted(set(ranks)))
        return [key_float(int(part[r]), dtype) for r in ranks]

    wh32 = np.asarray(white, np.float32)
    keys = float_keys(wh32)
    lo, hi = select(keys, _ranks(BLACK_PERCENTILE, keys.size), np.float32)
    thr = max(10.0 * floor, 0.05 * _lerp(lo, hi, BLACK_PERCENTILE, keys.size))
    wh = wh32.astype(np.float64)
    ok = wh > thr
    if ok.sum() < 16:
        raise EstimationError("white", "the all-white frame is too dark to measure the black level")
    ratios = float_keys(np.asarray(black, np.float32).astype(np.float64)[ok] / wh[ok])
    n = ratios.size
    a, b = select(ratios, ((n - 1) // 2, n // 2), np.float64)
    return float((a + b) / 2.0)


def _ranks(q: float, n: int) -> tuple[int, int]:
    pos = q / 100.0 * (n - 1)
    k0 = int(np.floor(pos))
    return k0, min(k0 + 1, n - 1)


def _lerp(lo: float, hi: float, q: float, n: int) -> float:
    pos = q / 100.0 * (n - 1)
    return float(lo + (hi - lo) * (pos - np.floor(pos)))
