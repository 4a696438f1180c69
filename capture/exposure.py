"""The exposure of a capture: the one check of exposure times, and the one rule
for the effective exposure of an aperture bracket.

Every reader and every HDR function checks exposure times through
:func:`check_exposure_times` (finite, positive, one per image; distinct for a
bracket), so the rule and its messages live here and nowhere else. A stack
bracketed by aperture (``f_numbers`` in ``stack.json``) records light in
proportion to ``Δt / N²``; :func:`effective_exposure_times` turns its times
into the relative exposures ``Δt · (N_ref / N)²`` every HDR verb works with
(merge, response and video alike).

Examples
--------
>>> check_exposure_times([1 / 30, 1 / 8], 2).tolist()
[0.03333333333333333, 0.125]
>>> check_exposure_times([0.01, -1.0], 2)
Traceback (most recent call last):
...
lumigraph.capture.errors.InputError: exposure_times_s: exposure times must be positive and finite, got [0.01, -1.0]
>>> effective_exposure_times([0.01, 0.01, 0.01], [2.0, 4.0, 8.0])
(0.01, 0.0025, 0.000625)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError


def check_exposure_times(exposure_times_s, count: int, *,
                         where: str | os.PathLike = "exposure_times_s",
                         distinct: bool = False) -> np.ndarray:
    """Validate exposure times: present, one per image, finite and positive.

    Parameters
    ----------
    exposure_times_s : sequence of float or None
        Seconds (or relative exposures), one per image.
    count : int
        Images they belong to.
    where : str or path-like
        What the error names: the caller's argument (default
        ``exposure_times_s``) or the file the times came from.
    distinct : bool
        Refuse repeated times (a bracket needs each image at its own
        exposure; a video of alternating exposures repeats them).

    Returns
    -------
    ndarray, ``(count,)`` float64

    Raises
    ------
    InputError
        Naming ``where``: missing, not numbers, not one per image, not
        positive and finite, or (``distinct``) repeated.
    """
    if exposure_times_s is None:
        raise InputError(where, "exposure times are needed (EXIF, stack.json or given)")
    try:
        t = np.asarray(exposure_times_s, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InputError(where, f"expected exposure times in seconds, got "
                                f"{exposure_times_s!r}") from None
    if t.size != count:
        raise InputError(where, f"{t.size} exposure times for {count} images")
    if not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise InputError(where, f"exposure times must be positive and finite, got {t.tolist()}")
    if distinct and np.unique(t).size != t.size:
        dup = sorted({float(x) for x in t if np.sum(t == x) > 1})
        raise InputError(where, f"duplicated exposure times {dup}: each image of a bracket needs "
                                "its own exposure (drop the duplicate frames)")
    return t


def effective_exposure_times(exposure_times_s: Sequence[float],
                             f_numbers: Sequence[float] | None = None, *,
                             f_number_ref: float | None = None,
                             where: str | os.PathLike = "f_numbers") -> tuple[float, ...]:
    """Relative exposure of each image: ``Δt · (N_ref / N)²``.

    Parameters
    ----------
    exposure_times_s : sequence of float, ``(P,)``
        Shutter times, seconds (already checked).
    f_numbers : sequence of float, ``(P,)``, optional
        Aperture of each image; without them the times are the exposures.
    f_number_ref : float, optional
        The aperture the exposures are relative to (default: the widest,
        ``min(f_numbers)``).
    where : str or path-like
        What an error about the f-numbers names.

    Returns
    -------
    tuple of float, ``(P,)``
    """
    times = tuple(float(t) for t in exposure_times_s)
    if f_numbers is None:
        return times
    try:
        fn = np.asarray(f_numbers, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InputError(where, f"expected f-numbers, got {f_numbers!r}") from None
    if fn.size != len(times):
        raise InputError(where, f"{fn.size} f-numbers for {len(times)} images")
    if not np.all(np.isfinite(fn)) or np.any(fn <= 0):
        raise InputError(where, f"f-numbers must be positive and finite, got {fn.tolist()}")
    ref = float(f_number_ref if f_number_ref is not None else fn.min())
    if not (np.isfinite(ref) and ref > 0):
        raise InputError(where, f"f_number_ref must be positive and finite, got {ref}")
    return tuple(float(t * (ref / n) ** 2) for t, n in zip(times, fn, strict=True))


# ------------------------------------------------------------------ bit depth
# Common sensor depths: data without a declared depth are taken as the
# smallest of these that holds their largest code.
SENSOR_DEPTHS = (8, 10, 12, 14, 16)


@dataclass(frozen=True)
class BitDepth:
    """How deep a stack's integer codes are, and how that was decided.

    Attributes
    ----------
    bits : int or None
        Significant bits; ``z_max = 2**bits - 1`` is saturation (``None``:
        float data).
    source : str
        How it was decided (recorded in the meta as ``bit_depth_source``).
    shift : int
        Left-aligned data (the low bits of every code empty): the codes are
        shifted right by this many bits to give ``bits``-bit values.
    """

    bits: int | None
    source: str
    shift: int = 0


def _low_zero_bits(images, container: int) -> int:
    """Bits at the bottom that are zero in every code of every image."""
    ored = 0
    for im in images:
        ored |= int(np.bitwise_or.reduce(np.asarray(im).ravel())) if np.asarray(im).size else 0
    if ored == 0:
        return container
    return (ored & -ored).bit_length() - 1


def code_summary(codes: np.ndarray) -> np.ndarray:
    """What :func:`decide_bit_depth` looks at in one image, in a few values:
    its largest code and each bit set anywhere in its codes (the OR of every
    code, bit by bit), as a 1-D array of the image's dtype. Every decision
    :func:`decide_bit_depth` takes on the summaries is the one it takes on
    the images (each bit of the OR is at most the largest code's top bit), so
    a stack of any length is decided holding one image at a time. Float
    images give one zero of their dtype (float data has no bit depth).

    Examples
    --------
    >>> code_summary(np.array([[0, 17], [4095, 64]], np.uint16)).tolist()
    [4095, 1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048]
    >>> z = np.array([1, 4095], np.uint16) << 4  # 12-bit codes, left-aligned
    >>> decide_bit_depth([code_summary(z)], ["a.png"]) == decide_bit_depth([z], ["a.png"])
    True
    """
    z = np.asarray(codes)
    if z.dtype.kind not in "ui" or not z.size:
        return np.zeros(1, z.dtype)
    top = int(z.max())
    ored = int(np.bitwise_or.reduce(z.ravel()))
    return np.array([top] + [1 << k for k in range(8 * z.dtype.itemsize) if ored >> k & 1],
                    z.dtype)


def decide_bit_depth(images: Sequence[np.ndarray], paths: Sequence[str | os.PathLike], *,
                     given: int | None = None, declared: int | None = None,
                     declared_where: str | os.PathLike = "bit_depth",
                     significant: Sequence[tuple[int, str] | None] | None = None) -> BitDepth:
    """Decide the bit depth of a stack's codes: given, declared, or detected.

    In order: ``given`` (the user's, e.g. ``--bit-depth``) is checked against
    the codes; ``declared`` (``stack.json``'s ``bit_depth``) likewise;
    ``significant`` (per file: a PNG's ``sBIT`` or a RAW's white level, with
    its name) is honoured, its codes right- or left-aligned (the PNG
    specification scales a 12-bit sample up to 16 bits); otherwise an 8-bit
    container is 8-bit, and a 16-bit container is taken as left-aligned when
    the low bits of every code are empty (10-bit data shifted up by 6), else
    as the smallest common sensor depth (:data:`SENSOR_DEPTHS`) holding the
    largest code: a 12-bit camera's clipped pixels sit at 4095, and a bracket
    always has some.

    Parameters
    ----------
    images : sequence of ndarray
        The integer codes of each file (any shape), one dtype.
    paths : sequence of path-like
        The files, for the messages.
    given, declared : int, optional
        Bits (1..16).
    declared_where : str or path-like
        What an error about ``declared`` names (the stack.json).
    significant : sequence of (int, str) or None, optional
        Per file, the bits its header declares and which header.

    Returns
    -------
    BitDepth

    Raises
    ------
    InputError
        Naming the file whose codes exceed the given, declared or
        significant depth (and are not left-aligned to it).

    Examples
    --------
    >>> z = np.array([0, 17, 4095], np.uint16)
    >>> decide_bit_depth([z], ["a.png"]).bits
    12
    >>> b = decide_bit_depth([z << 6], ["a.png"])
    >>> b.bits, b.shift
    (10, 6)
    >>> decide_bit_depth([z], ["a.png"], given=10)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: a.png: codes up to 4095 do not fit in 10 bits (0..1023): the bit depth given is too small for this file (leave it out to detect it)
    """
    imgs = [np.asarray(im) for im in images]
    if not imgs or imgs[0].dtype.kind not in "ui":
        return BitDepth(None, "float data (linear, no code values)")
    container = 8 * imgs[0].dtype.itemsize
    tops = [int(im.max()) if im.size else 0 for im in imgs]
    top = max(tops)

    def fits(bits: int, what: str, problem: str) -> BitDepth:
        """``bits``-bit codes, right-aligned or left-aligned in the container;
        else an error naming the first file that overflows."""
        if top < 2 ** bits:
            return BitDepth(bits, what)
        k = container - bits
        if k > 0 and _low_zero_bits(imgs, container) >= k:
            return BitDepth(bits, f"{what}; codes left-aligned in the {container}-bit container "
                                  f"(the low {k} bits of every code empty): shifted right", k)
        i = next(j for j, t in enumerate(tops) if t >= 2 ** bits)
        raise InputError(paths[i], f"codes up to {tops[i]} do not fit in {bits} bits "
                                   f"(0..{2 ** bits - 1}): {problem}")

    if given is not None:
        if not 1 <= int(given) <= container:
            raise InputError(paths[0], f"{given} bits given, but the file holds {container}-bit "
                                       f"codes ({imgs[0].dtype}); give 1..{container}")
        return fits(int(given), "given", "the bit depth given is too small for this file "
                                         "(leave it out to detect it)")
    if declared is not None:
        if int(declared) > container or top >= 2 ** int(declared):
            raise InputError(declared_where, f"key 'bit_depth': {declared} bits, but the images "
                                             f"are {imgs[0].dtype} with codes up to {top}")
        return BitDepth(int(declared), "stack.json")
    sig = [s for s in (significant or ()) if s is not None]
    if sig:
        for path, im, top_i, s in zip(paths, imgs, tops, significant, strict=True):
            if s is None:
                continue
            b, what = s
            k = container - b
            if b > container or (top_i >= 2 ** b and not (
                    k > 0 and _low_zero_bits([im], container) >= k)):
                raise InputError(path, f"its {what} declares {b} bits but its codes reach "
                                       f"{top_i} in a {container}-bit container (give the bit "
                                       "depth)")
        bits, what = max(sig)
        return fits(bits, what, f"{what} declares {bits} bits (give the bit depth)")
    if container == 8:
        return BitDepth(8, "8-bit container")
    k = _low_zero_bits(imgs, container)
    if 2 <= k <= container - 8:
        bits = container - k
        return BitDepth(bits, f"left-aligned: the low {k} bits of every code are empty "
                              f"({bits}-bit data in a {container}-bit container), shifted right", k)
    bits = next(b for b in SENSOR_DEPTHS if top < 2 ** b or b >= container)
    if top == 2 ** bits - 1:
        return BitDepth(bits, f"largest code {top} = 2^{bits}-1 (the saturation plateau): "
                              f"{bits}-bit data in a {container}-bit container")
    return BitDepth(bits, f"largest code {top}: the smallest common sensor depth holding it "
                          f"({bits} bits; no code at {2 ** bits - 1}, nothing clipped)")


def check_brightness_order(images: np.ndarray, exposure_times_s, paths: Sequence[str], *,
                           force: bool = False, max_pixels: int = 65536) -> list[str]:
    """Check exposure times against the images' brightness order.

    A static bracket's longer exposure is brighter at almost every pixel that
    is clipped (any channel) in neither frame and above the dark floor (each frame's 5th
    percentile, plus a tenth of the code range) in one of them. For each pair of
    images adjacent in time order (equal times skipped), those pixels where the
    two differ are counted:
    the pair is out of order when more of them are darker in the longer
    exposure than brighter, by more than 3 binomial standard deviations
    (``darker − brighter > 3 √(darker + brighter)``). That catches times given
    reversed, shuffled, or with one pair swapped (``--times`` in another order
    than the files).

    Parameters
    ----------
    images : ndarray, ``(P, H, W[, C])`` integer codes
    exposure_times_s : sequence of float, ``(P,)``
    paths : sequence of str, ``(P,)``
        The files, for the message.
    force : bool
        Return the disagreements as warnings instead of raising.
    max_pixels : int
        Pixels compared (an even subsample of larger images).

    Returns
    -------
    list of str
        One line per out-of-order pair (only with ``force``; otherwise empty).

    Raises
    ------
    InputError
        Naming the longer exposure's file and the other one of the first pair
        out of order (and how many pairs are).

    Examples
    --------
    >>> scene = np.linspace(1.0, 60.0, 64).reshape(8, 8)
    >>> z = np.stack([np.clip(scene * k, 0, 255) for k in (1, 2, 4)]).astype(np.uint8)
    >>> check_brightness_order(z, [0.01, 0.03, 0.09], ["a", "b", "c"])
    []
    >>> try:
    ...     check_brightness_order(z, [0.09, 0.03, 0.01], ["a", "b", "c"])
    ... except InputError as e:
    ...     print(e.where)
    b
    """
    z = np.asarray(images)
    t = np.asarray(exposure_times_s, dtype=np.float64).ravel()
    p = z.shape[0]
    if p < 2 or t.size != p or z.dtype.kind not in "ui":
        return []
    if z.ndim == 3:
        z = z[..., None]
    step = max(1, int(np.ceil(np.sqrt(z.shape[1] * z.shape[2] / max_pixels))))
    s = z[:, ::step, ::step].reshape(p, -1, z.shape[-1]).astype(np.int64)
    top = int(s.max())
    lum = s.sum(axis=2)
    hi_clip = (s >= 0.98 * top).any(axis=2)
    # Each frame's dark floor (a black level, a film base, where most pixels of a short
    # exposure sit): its 5th percentile. Only pixels clearly above the floor in one of the
    # two frames say which is brighter; at the floor, grain and a scan's offset decide.
    above = lum - np.percentile(lum, 5, axis=1)[:, None]
    signal = 0.1 * top * s.shape[2]
    order = np.argsort(t, kind="stable")
    bad = []
    for a, b in zip(order[:-1], order[1:], strict=True):
        if t[a] == t[b]:
            continue
        # clipped in either frame: no order to read (and a registration border, pure
        # blue in Memorial, is clipped in one channel of the frames it covers)
        use = (np.maximum(above[a], above[b]) > signal) & ~(hi_clip[a] | hi_clip[b])
        d = lum[b, use] - lum[a, use]
        brighter, darker = int(np.sum(d > 0)), int(np.sum(d < 0))
        if darker - brighter > 3.0 * np.sqrt(max(darker + brighter, 1)):
            share = darker / max(darker + brighter, 1)
            bad.append((int(a), int(b), share))
    if not bad:
        return []
    lines = [f"{paths[b]} is given {t[b]:g} s, longer than {t[a]:g} s of {paths[a]}, but it is "
             f"darker at {100 * s_:.0f} % of the pixels that differ" for a, b, s_ in bad]
    if force:
        return [line + " (used as given: --force)" for line in lines]
    a, b, share = bad[0]
    more = f" ({len(bad)} pairs out of order)" if len(bad) > 1 else ""
    raise InputError(paths[b], f"exposure time {t[b]:g} s is longer than {t[a]:g} s of "
                               f"{paths[a]}, but this image is darker at {100 * share:.0f} % of "
                               f"the pixels that differ{more}: the times are not in the images' "
                               "order (give --times in file order, or --force to use them)")
