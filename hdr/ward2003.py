"""Ward (2003): median threshold bitmap (MTB) alignment of an exposure bracket.

G. Ward, "Fast, Robust Image Registration for Compositing High Dynamic Range
Photographs from Hand-Held Exposures", J. Graphics Tools 8(2), 2003,
doi:10.1080/10867651.2003.10487583.

Each exposure is reduced to a bitmap thresholded at its own median (which
is nearly invariant to exposure), with an exclusion bitmap masking pixels
within a noise band of the median. Integer shifts are found coarse to fine
on an image pyramid: at each level the 9 neighbours of the doubled coarse
shift are tried and the one with the fewest differing (XOR) pixels kept.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> base = rng.integers(0, 255, (64, 80), dtype=np.uint8)
>>> import scipy.ndimage as ndi
>>> base = ndi.gaussian_filter(base.astype(float), 2).astype(np.uint8)
>>> moved = np.roll(base, (3, -5), axis=(0, 1))
>>> mtb_shift(base, moved, levels=4)
(5, -3)
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.errors import InputError

# Pyramid levels of mtb_shift: at least 1 (the full image); 2**levels px is
# the largest shift found, and past ~16 levels the pyramid is stopped by its
# 16 px floor on any image a camera makes.
MIN_LEVELS, MAX_LEVELS = 1, 16


def _gray(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img, dtype=np.float32)
    if a.ndim == 3:
        a = a @ np.array([0.2126, 0.7152, 0.0722], np.float32)[: a.shape[2]] if a.shape[2] == 3 \
            else a.mean(axis=2)
    return a


def _bitmaps(g: np.ndarray, noise: float):
    med = np.median(g)
    return g > med, np.abs(g - med) > noise


def _shrink(g):
    h, w = (g.shape[0] // 2) * 2, (g.shape[1] // 2) * 2
    return g[:h, :w].reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))


def _shifted(b: np.ndarray, dx: int, dy: int) -> np.ndarray:
    out = np.zeros_like(b)
    h, w = b.shape
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[yd, xd] = b[ys, xs]
    return out


def mtb_shift(reference_image: np.ndarray, moving_image: np.ndarray, *, levels: int = 6,
              noise: float | None = None) -> tuple[int, int]:
    """Integer shift ``(dx, dy)`` that moves ``moving_image`` onto ``reference_image``
    (apply with :func:`apply_shift`); x right, y down, pixels.

    Parameters
    ----------
    reference_image, moving_image : ndarray, ``(H, W)`` or ``(H, W, C)``
        Codes or radiance of two exposures (any scale: the median threshold
        removes it).
    levels : int
        Pyramid levels; the largest recoverable shift is about ``2**levels``.
    noise : float, optional
        Exclusion band around the median, in the images' units (default:
        4/255 of each image's range).
    """
    g1, g2 = _gray(reference_image), _gray(moving_image)
    if g1.shape != g2.shape:
        raise ValueError(f"moving_image: expected shape {g1.shape}, got {g2.shape}")
    pyr = [(g1, g2)]
    for _ in range(max(levels - 1, 0)):
        a, b = pyr[-1]
        if min(a.shape) < 16:
            break
        pyr.append((_shrink(a), _shrink(b)))
    dx = dy = 0
    for a, b in reversed(pyr):
        dx, dy = 2 * dx, 2 * dy
        na = noise if noise is not None else 4.0 / 255.0 * float(np.ptp(a) or 1.0)
        nb = noise if noise is not None else 4.0 / 255.0 * float(np.ptp(b) or 1.0)
        ta, ea = _bitmaps(a, na)
        tb, eb = _bitmaps(b, nb)
        best = None
        for ddy in (-1, 0, 1):
            for ddx in (-1, 0, 1):
                sx, sy = dx + ddx, dy + ddy
                diff = (ta ^ _shifted(tb, sx, sy)) & ea & _shifted(eb, sx, sy)
                err = int(np.count_nonzero(diff))
                if best is None or err < best[0]:
                    best = (err, sx, sy)
        _, dx, dy = best
    return int(dx), int(dy)


def apply_shift(image: np.ndarray, shift: tuple[int, int]) -> np.ndarray:
    """Translate by integer ``(dx, dy)``; uncovered borders repeat the edge."""
    dx, dy = shift
    pad = [(abs(dy), abs(dy)), (abs(dx), abs(dx))] + [(0, 0)] * (image.ndim - 2)
    big = np.pad(image, pad, mode="edge")
    h, w = image.shape[:2]
    y0, x0 = abs(dy) - dy, abs(dx) - dx
    return big[y0:y0 + h, x0:x0 + w].copy()


def check_align_options(*, reference: int | None = None, levels: int = 6,
                        count: int | None = None) -> None:
    """:func:`align`'s options: ``levels`` an integer
    :data:`MIN_LEVELS`..:data:`MAX_LEVELS`, ``reference`` an image index
    ``0..count-1`` (``>= 0`` while ``count`` is unknown) or None.

    Raises
    ------
    InputError
        Naming ``levels`` or ``reference``.

    Examples
    --------
    >>> check_align_options(reference=1, levels=6, count=3)
    >>> try:
    ...     check_align_options(reference=3, count=3)
    ... except InputError as e:
    ...     print(e)
    reference: expected an image index 0..2, got 3
    """
    def integer(v):
        return isinstance(v, int | np.integer) and not isinstance(v, bool)

    if not integer(levels) or not MIN_LEVELS <= levels <= MAX_LEVELS:
        raise InputError("levels", f"expected an integer {MIN_LEVELS}..{MAX_LEVELS}, got {levels!r}")
    if reference is not None:
        top = "" if count is None else f"{count - 1}"
        if not integer(reference) or reference < 0 or (count is not None and reference >= count):
            raise InputError("reference", f"expected an image index 0..{top or 'N-1'}, got "
                                          f"{reference!r}")


def align(images, *, reference: int | None = None, levels: int = 6):
    """Align every exposure to a reference (default: the middle one).

    Returns ``(aligned (P, H, W, C) same dtype, shifts list of (dx, dy))``;
    the options are checked by :func:`check_align_options`.
    """
    stack = np.asarray(images)
    p = stack.shape[0]
    check_align_options(reference=reference, levels=levels, count=p)
    ref = p // 2 if reference is None else int(reference)
    shifts = [(0, 0) if j == ref else mtb_shift(stack[ref], stack[j], levels=levels)
              for j in range(p)]
    return np.stack([apply_shift(stack[j], shifts[j]) for j in range(p)]), shifts
