"""One call from linear captures to a :class:`Separation`: method, black level, mask, residue.

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.patterns import checker_set
>>> ps = checker_set((16, 16), square=4, shifts=2)
>>> d = np.full((16, 16), 0.5); g = np.full((16, 16), 0.2)
>>> ims = np.stack([d * p + 0.5 * g for p in ps.images])[..., None].astype(np.float32)
>>> s = separate(ims, method="checker", complement_of=ps.complement_of)
>>> round(float(s.direct.mean()), 4), round(float(s.global_.mean()), 4), int(s.mask.max())
(0.5, 0.2, 0)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.capture.patterns import check_lit_fraction
from lumigraph.separation import nayar2006
from lumigraph.separation.methods import EXACT_IMAGES, METHODS, MIN_IMAGES
from lumigraph.separation.result import Separation

__all__ = ["EXACT_IMAGES", "METHODS", "MIN_IMAGES", "check_options", "separate"]
RESIDUE_WARN_FRACTION = 0.10


MIN_TILE = 2  # pixels: the least tile of 'single' and of the residue check


def check_options(*, alpha: float | None = None, b: float | None = None, tile: int = 16,
                  noise_sigma: float = 0.0, saturation: float | None = None) -> None:
    """Check :func:`separate`'s scalar options (ranges in its Parameters),
    so a caller can do it before any capture is read.

    Raises
    ------
    InputError
        Naming ``alpha`` (not in (0, 1),
        :func:`capture.patterns.check_lit_fraction`), ``b`` (not in [0, 1)),
        ``tile`` (not an integer >= 2), ``noise_sigma`` (not a finite number
        >= 0) or ``saturation`` (not a finite number > 0).

    Examples
    --------
    >>> check_options(alpha=0.5, b=0.1, tile=8)
    >>> try:
    ...     check_options(tile=1)
    ... except InputError as e:
    ...     print(e)
    tile: expected at least 2 pixels, got 1
    """
    if alpha is not None:
        check_lit_fraction(alpha)
    if b is not None and not 0.0 <= b < 1.0:
        raise InputError("b", f"black level must lie in [0, 1), got {b}")
    if isinstance(tile, bool) or not isinstance(tile, int | np.integer) or tile < MIN_TILE:
        raise InputError("tile", f"expected at least {MIN_TILE} pixels, got {tile}")
    if not (isinstance(noise_sigma, int | float | np.number) and np.isfinite(noise_sigma)
            and noise_sigma >= 0):
        raise InputError("noise_sigma", f"expected a finite standard deviation >= 0, got "
                                        f"{noise_sigma!r}")
    if saturation is not None and not (isinstance(saturation, int | float | np.number)
                                       and np.isfinite(saturation) and saturation > 0):
        raise InputError("saturation", f"expected a finite clip level > 0, got {saturation!r}")


def separate(images: np.ndarray, *, method: str = "checker", alpha: float | None = None,
             b: float | None = None, black: np.ndarray | None = None,
             white: np.ndarray | None = None, complement_of=None, estimator: str = "pairs",
             noise_sigma: float = 0.0, quant_step: float = 0.0, saturation: float | None = None,
             tile: int = 16, names=None, device="cpu") -> Separation:
    """Separate linear captures into direct and global light.

    Parameters
    ----------
    images : ndarray, ``(N, H, W, C)`` float32
        Linear captures under the method's patterns, in any order: checker
        complements are found from the captures and the sinusoid phases
        checked (:mod:`separation.pairing`), and the stack is put in an order
        fixed by its content, so every permutation gives the same result.
    method : {"checker", "sinusoid", "single", "occluder"}
        A name of :data:`separation.methods.METHODS`.
    alpha : float in (0, 1), optional
        Lit fraction of the patterns (default ½; occluder: measured from the frames).
    b : float in [0, 1), optional
        Projector black level; measured from ``black``/``white`` when those are
        given and ``b`` is not, else 0.
    black, white : ndarray, ``(H, W, C)``, optional
        Captures under all-black and all-white projector frames.
    complement_of : sequence of int, optional
        Complement index per checker image (a pattern layout, e.g. from
        ``stack.json``), checked against the captures; default: found from
        them (:func:`separation.pairing.find_pairs`).
    estimator : {"pairs", "maxmin"}
        Checker estimator (noise-robust pairs, or the textbook max/min).
    noise_sigma : float
        Known per-capture noise standard deviation (linear units), added to the
        quantisation noise ``quant_step/√12`` and, for checker pairs, to the
        noise measured from pattern+complement sums.
    saturation : float, optional
        Linear value at and above which a capture is clipped.
    tile : int
        Tile size in pixels, at least 2: the tiles of ``single``, and the
        scale of the spatial residue check of methods without complement
        pairs.
    names : sequence of str, optional
        Image names for error messages.
    device : {"cpu", "cuda", "torch-cpu", "auto"}
        Where the per-pixel estimator runs (:mod:`lumigraph.capture.device`):
        ``"cpu"`` numpy; the others :mod:`lumigraph.separation.nayar2006_torch`
        (every method), equal to numpy's result within float32 rounding.
        Pairing, the noise model and the masks run on numpy either way.

    Raises
    ------
    InputError
        An option out of range (:func:`check_options`, naming it), an
        all-dark capture, a checker capture without a complement among the
        others, a layout the captures contradict, or two sinusoid captures of
        the same phase (each naming the capture).
    EstimationError
        Too few or too many images for the method, or a measured black
        level outside [0, 1).
    """
    from lumigraph.capture.device import resolve_device

    dev = resolve_device(device)
    fn = METHODS.resolve(method)
    a = nayar2006.validate_stack(images, need=MIN_IMAGES[method], method=method)
    if method in EXACT_IMAGES and len(a) != EXACT_IMAGES[method]:
        raise EstimationError("<images>", f"method {method!r} takes exactly {EXACT_IMAGES[method]} "
                                          f"image(s), got {len(a)}")
    names = list(names) if names is not None else [f"image {i}" for i in range(len(a))]
    check_options(alpha=alpha, b=b, tile=tile, noise_sigma=noise_sigma, saturation=saturation)
    quant = quant_step / np.sqrt(12.0)
    floor = 3.0 * np.hypot(noise_sigma, quant) + 1e-7
    # a strided look first (cheap); the full image only when that one looks dark
    peak = a[:, ::4, ::4].reshape(len(a), -1).max(axis=1)
    for i, p in enumerate(peak):
        if p <= floor:
            p = float(a[i].max())
        if p <= floor:
            raise InputError(names[i], f"all-dark frame (brightest value {p:.3g} is within the "
                                       "noise); check the projector and the exposure")
    params: dict = {"method": method}
    if method != "single":
        # the captures in an order fixed by their content (and, for checker, their
        # complements found from the data): any file order gives the same result
        a, names, complement_of, order_info = _arrange(
            a, names, method=method, complement_of=complement_of, estimator=estimator,
            noise=float(np.hypot(noise_sigma, quant)))
        params.update(order_info)
    b = black_level_of(b, black=black, white=white, floor=floor, info=params)
    # Noise model: quantisation + given + (checker pairs) measured from pair sums.
    var0, var1 = quant ** 2 + noise_sigma ** 2, 0.0
    comp = None
    if method == "checker":
        alpha = 0.5 if alpha is None else alpha
        n = len(a)
        comp = list(complement_of) if complement_of is not None else [-1] * n
        s0, s1 = nayar2006.noise_from_pairs(a, comp)
        var0, var1 = var0 + s0, s1
    if dev.uses_torch:
        from functools import partial

        from lumigraph.separation import nayar2006_torch

        fn = partial(nayar2006_torch.METHODS[method], device=dev)
        params["device"] = dev.name
    ev = evaluate(a, fn=fn, method=method, alpha=alpha, b=b, comp=comp, estimator=estimator,
                  var0=var0, var1=var1, saturation=saturation, tile=tile)
    params.update(ev.params)
    direct, glob, mask = ev.direct, ev.global_, ev.mask
    warnings = []
    quality = {"noise_model": {"variance_at_zero": float(var0), "variance_slope": float(var1)},
               "mask_counts": ev.counts}
    if ev.residue_flagged is not None:
        frac = float(ev.residue_flagged / max(ev.counts["valid"], 1))
        quality["residue"] = {"check": "per-pair global disagreement", "fraction": frac}
    else:
        from lumigraph.separation.residue import spatial_residue

        frac, _ = spatial_residue(glob, ev.mean_image, window=residue_window(tile),
                                  valid=mask == 0)
        quality["residue"] = {"check": "spatial pattern-scale contrast", "fraction": frac}
    quality["residue"]["warn_above"] = RESIDUE_WARN_FRACTION
    if frac > RESIDUE_WARN_FRACTION:
        warnings.append(f"high-frequency residue: the pattern survives into the global image in "
                        f"{100 * frac:.1f}% of the trusted pixels (a mirror-like surface, or a "
                        "pattern too coarse for the scene); the split is unreliable there")
    return Separation(direct, glob, mask, method, params, quality, tuple(warnings))


@dataclass(frozen=True)
class Evaluation:
    """The per-pixel step of :func:`separate` on a stack (whole, or a band of rows)."""

    direct: np.ndarray  # (H, W, C) float32
    global_: np.ndarray  # (H, W, C) float32
    mask: np.ndarray  # (H, W) uint8
    mean_image: np.ndarray  # (H, W, C) float32
    counts: dict  # mask counts: integers, summed over bands
    residue_flagged: int | None  # pixels the per-pair residue check flags (None: no pairs)
    params: dict


def evaluate(a, *, fn, method, alpha, b, comp, estimator, var0, var1, saturation,
             tile) -> Evaluation:
    """Everything :func:`separate` does per pixel once the whole-image analysis
    (order, complements, ``b``, the noise line ``var0 + var1·I``) is fixed: the
    estimator, the masks and the per-pair residue flags. Every output pixel
    depends on that pixel of ``a`` ``(N, H, W, C)`` only (``single``: on its
    ``tile``), so bands of rows give the whole image's values."""
    params: dict = {}
    mean_image = a.mean(axis=0)
    sigma_mean = np.sqrt(var0 + var1 * np.clip(mean_image, 0, None)).astype(np.float32)
    if method == "checker":
        direct, glob, info = fn(a, alpha=alpha, b=b, complement_of=comp, estimator=estimator,
                                sigma=sigma_mean)
        params.update(estimator=info["estimator"], alpha=alpha, alpha_minus=info["alpha_minus"])
    elif method == "sinusoid":
        direct, glob, info = fn(a, b=b)
    elif method == "single":
        alpha = 0.5 if alpha is None else alpha
        direct, glob, info = fn(a, alpha=alpha, b=b, tile=tile)
        params.update(alpha=alpha, tile=tile)
    else:
        direct, glob, info = fn(a, alpha=alpha, b=b)
        params.update(alpha=info["alpha"], alpha_source=info["alpha_source"])
    lp, lm = info["l_plus"], info["l_minus"]

    sigma = np.sqrt(var0 + var1 * np.clip(lp, 0, None)).astype(np.float32)
    n_obs = info.get("pairs_used")
    n_obs = np.maximum(n_obs, 1)[..., None] if n_obs is not None and n_obs.ndim == 2 else (
        np.maximum(n_obs, 1) if n_obs is not None else 1)
    sigma_c = np.sqrt(2.0) * sigma / np.sqrt(n_obs)

    mask = np.zeros(a.shape[1:3], np.uint8)
    never = (lp <= 3.0 * sigma).all(axis=-1)
    mask[never] |= nayar2006.MASK_NEVER_LIT
    if saturation is not None:
        mask[(a >= saturation).any(axis=0).any(axis=-1)] |= nayar2006.MASK_SATURATED
    low = ((lp - lm) <= 3.0 * sigma_c).all(axis=-1) & ~never
    mask[low] |= nayar2006.MASK_LOW_CONTRAST
    valid = mask == 0
    counts = mask_counts(mask)
    flagged = None
    if comp is not None and any(j >= 0 for j in comp):
        _, flags = _residue_pairs(a, comp, b=b, alpha=alpha, sigma=sigma, valid=valid)
        flagged = int(flags.sum())
    return Evaluation(direct.astype(np.float32), glob.astype(np.float32), mask, mean_image,
                      counts, flagged, params)


def mask_counts(mask: np.ndarray) -> dict:
    """The quality's ``mask_counts`` of a mask ``(H, W)`` (or a band of it:
    integers, summed over bands)."""
    return {"never_lit": int(((mask & nayar2006.MASK_NEVER_LIT) > 0).sum()),
            "saturated": int(((mask & nayar2006.MASK_SATURATED) > 0).sum()),
            "low_contrast": int(((mask & nayar2006.MASK_LOW_CONTRAST) > 0).sum()),
            "valid": int((mask == 0).sum()), "total": int(mask.size)}


def residue_window(tile: int) -> int:
    """The box of the spatial residue check: about one pattern period (``tile``), odd, >= 5."""
    return max(5, tile // 2 * 2 + 1)


def black_level_of(b, *, black, white, floor, info, measure=None):
    """The projector's black level ``b``: as given, else measured from the
    all-black and all-white frames (:func:`separation.nayar2006.black_level`,
    or ``measure()``: the banded run's, on frames read by rows), else 0;
    ``info`` (the meta) gets ``b`` and ``b_source``. The whole-image and the
    banded runs share it."""
    if b is None and (measure is not None or black is not None and white is not None):
        b = measure() if measure is not None else nayar2006.black_level(black, white, floor=floor)
        info["b_source"] = "measured from the all-black/all-white frames"
        if not 0.0 <= b < 1.0:
            raise EstimationError("black", f"measured black level {b:.3f} is not in [0, 1)")
    elif b is None:
        b = 0.0
        info["b_source"] = "assumed 0 (no --b and no black/white frames)"
    else:
        info["b_source"] = "given"
    info["b"] = float(b)
    return b


def checker_pairs(a, *, names, noise, order, complement_of, estimator, info):
    """The complement of each checker capture (index, -1 for none) or None:
    the given ``complement_of`` checked against the pairs found in ``a``
    (N, ...) (:func:`separation.pairing.find_pairs`, searched in ``order``),
    else the found pairs; ``info`` (the meta) gets ``pairs_source`` and
    ``pair_score_median``. The whole-image and the banded runs share it, so
    they decide the pairs alike (``a`` is the images or the banded run's
    sample of them)."""
    from lumigraph.separation import pairing

    try:
        found = pairing.find_pairs(a, names=names, noise=noise, order=order)
    except InputError:
        if estimator == "pairs":
            raise
        found = None  # max/min needs no pairs; the residue check then uses none
    comp = None
    if complement_of is not None:
        if found is not None:
            pairing.check_pairs(found, complement_of, names=names)
        comp = list(complement_of)
        info["pairs_source"] = "given (pattern layout), checked against the captures"
    elif found is not None:
        comp = list(found.complement_of)
        info["pairs_source"] = ("found from the captures" if found.decisive else
                                "found from the captures (contrast within the noise)")
    if found is not None:
        info["pair_score_median"] = float(np.nanmedian(found.score)) if any(
            j >= 0 for j in found.complement_of) else None
    return comp


def _arrange(a, names, *, method, complement_of, estimator, noise):
    """``a`` and ``names`` in canonical order (:func:`separation.pairing.canonical_order`),
    the complements in that order, and what was found (for the meta)."""
    from lumigraph.separation import pairing

    info: dict = {}
    comp = None
    if complement_of is not None and len(complement_of) != len(a):
        raise InputError("complement_of", f"expected {len(a)} entries, got {len(complement_of)}")
    # the search considers the images sorted by content, so that it (ties, the
    # first name in an error) does not depend on the file order either
    keys = pairing.content_keys(a)
    pre, _ = pairing.canonical_order(a, keys=keys)
    if method == "checker":
        comp = checker_pairs(a, names=names, noise=noise, order=pre,
                             complement_of=complement_of, estimator=estimator, info=info)
    elif method == "sinusoid":
        sp = pairing.phase_spacing(a[pre], names=[names[k] for k in pre], noise=noise)
        iu = np.triu_indices(len(a), 1)
        if np.isfinite(sp[iu]).all():
            info["phase_spacing_deg"] = [round(float(v), 1) for v in sp[iu]]
    order, comp = pairing.canonical_order(a, comp, keys=keys)
    if order != list(range(len(a))):
        a = a[order]
        names = [names[k] for k in order]
    return a, names, comp, info


def _residue_pairs(a, comp, **kw):
    from lumigraph.separation.residue import pair_residue

    return pair_residue(a, comp, **kw)
