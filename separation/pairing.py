"""Which capture complements which, found from the captures: file order never matters.

The pairs estimator of :func:`separation.nayar2006.checker` needs each board's
complement. Light transport is linear and a board plus its complement is the
all-lit projector frame, so every complementary pair of captures sums to the
same image, ``(1 + b)·W`` (``W`` the capture under an all-white frame, ``b``
the black level), whatever the scene; two boards that are not complements
(a board and a shifted board) do not: where both are lit the sum is
``2L⁺``, where both are dark ``2L⁻`` (Nayar et al. 2006, eqs. 8.12–8.14).
Without a white frame the common sum is ``max + min`` over a set whose
shifts visit every phase (``L⁺ + L⁻``).

:func:`find_pairs` scores every pair ``(i, j)`` by the mean deviation of
``I_i + I_j`` from that sum, relative to the set's contrast
``mean(max − min)``: about 0 (noise) for complements, the fraction of pixels
where the two boards agree for anything else (at least ``step/square``,
¼ for four shifts, before camera blur). Pairs are taken greedily, best
first; an image left without a partner while others found one is a missing
complement and is refused (:class:`InputError` naming it), and so is a pair
whose score is far from the complements' (a capture of another pattern).

:func:`canonical_order` then puts the captures in an order that depends on
their content only (pairs by their members' pixel sums, then the first
members, then the second: the ``capture.patterns.checker_set`` layout), so
the floating-point reductions of the estimators run in the same order and
any permutation of the files gives bit-identical results.

Examples
--------
>>> from lumigraph.capture.patterns import checker_set
>>> ps = checker_set((16, 16), square=4, shifts=2)
>>> ims = np.stack([0.6 * p + 0.1 for p in ps.images])[..., None]
>>> perm = [3, 0, 7, 4, 1, 5, 2, 6]            # any order: board next to complement, ...
>>> comp = find_pairs(ims[perm], names=[f"c{k}" for k in perm]).complement_of
>>> sorted((perm[i], perm[j]) for i, j in enumerate(comp) if i < j)
[(0, 4), (1, 5), (2, 6), (3, 7)]
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from lumigraph.capture.errors import InputError

# A complementary pair's score is its noise (~0); boards that are not complements
# score the fraction of pixels where they agree times the contrast seen there: at
# least 1/4 for four shifts per axis in the projector, less after camera blur.
# 0.12 sits between, with room for noise of a few per cent of the contrast.
MAX_PAIR_SCORE = 0.12
MAX_NOISY_SCORE = 0.25
FLAT_FRACTION = 0.9  # a board is the brightest capture at about half the pixels
SAMPLES = 65536  # pixels scored per pair: a fixed random subset (no aliasing with the board)


@dataclass(frozen=True)
class Pairing:
    """Result of :func:`find_pairs` (indices into the images as given).

    ``complement_of[i]`` is ``i``'s partner or ``-1``; ``score[i]`` its pair's
    score (``nan`` when unpaired); ``contrast`` the set's ``mean(max − min)``;
    ``decisive`` False when that contrast is within the noise (any pairing is
    then as good as any other, and the given one is kept); ``scores`` the
    :func:`pair_scores` matrix and ``limit`` the largest score taken as a
    complement.
    """

    complement_of: tuple[int, ...]
    score: tuple[float, ...]
    contrast: float
    decisive: bool
    scores: np.ndarray | None = None
    limit: float = MAX_PAIR_SCORE


@lru_cache(maxsize=8)
def _sample_index(size: int) -> np.ndarray:
    return np.sort(np.random.default_rng(0).choice(size, SAMPLES, replace=False))


def _sample(images: np.ndarray) -> np.ndarray:
    n = len(images)
    flat = images.reshape(n, -1)
    if flat.shape[1] <= SAMPLES:
        return flat.astype(np.float64)
    return flat[:, _sample_index(flat.shape[1])].astype(np.float64)


def pair_scores(images: np.ndarray | None, reference: np.ndarray | None = None, *,
                sample: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Score matrix ``(N, N)``: ``mean|I_i + I_j − R| / mean(max − min)``.

    ``R`` is ``reference`` (a flattened sample, see :func:`find_pairs`) or
    ``max + min`` over the set. Returns the matrix (diagonal ``inf``) and the
    contrast ``mean(max − min)`` (linear units), both over a fixed subset of at
    most :data:`SAMPLES` values (or ``sample``, ``(N, M)``, already drawn).

    Examples
    --------
    >>> s, c = pair_scores(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]))
    >>> float(s[0, 1]), float(s[0, 2]), c
    (0.0, 0.5, 1.0)
    """
    x = _sample(np.asarray(images)) if sample is None else sample
    ref = x.max(axis=0) + x.min(axis=0) if reference is None else reference
    contrast = float((x.max(axis=0) - x.min(axis=0)).mean())
    n = len(x)
    s = np.full((n, n), np.inf)
    scale = contrast if contrast > 0 else 1.0
    for i in range(n):
        s[i, i + 1:] = np.abs(x[i] + x[i + 1:] - ref).mean(axis=1) / scale
        s[i + 1:, i] = s[i, i + 1:]
    return s, contrast


def _greedy(s: np.ndarray, limit: float) -> list[int]:
    # best first; ties broken by index (callers pass a canonical order)
    n = len(s)
    comp = [-1] * n
    iu = np.triu_indices(n, 1)
    for k in np.lexsort((iu[1], iu[0], s[iu])):
        i, j = int(iu[0][k]), int(iu[1][k])
        if comp[i] < 0 and comp[j] < 0 and s[i, j] <= limit:
            comp[i], comp[j] = j, i
    return comp


def find_pairs(images: np.ndarray, *, names=None, noise: float = 0.0,
               max_score: float = MAX_PAIR_SCORE, order=None) -> Pairing:
    """Complementary pairs among ``images`` ``(N, ...)`` (linear), whatever their order.

    Parameters
    ----------
    images : ndarray, ``(N, ...)``
    names : sequence of str, optional
        Names for the error messages (default ``image k``).
    noise : float
        Noise standard deviation of one capture (linear units): below
        ``6·noise`` the contrast is not decisive and nothing is refused.
    max_score : float
        Largest score of a complementary pair (:data:`MAX_PAIR_SCORE`).
    order : sequence of int, optional
        The order in which to consider the images (ties go to the earlier;
        :func:`canonical_order` makes the search independent of the file
        order); results are indexed as ``images`` all the same.

    Returns
    -------
    Pairing
        No pair at all (``complement_of`` all ``-1``) is a set of shifts
        without complements.

    Raises
    ------
    InputError
        Naming an image left without a complement while others have one
        (a missing complement), or one whose best pairing is not a
        complement (a capture of another pattern among the boards).
    """
    a = np.asarray(images)
    n = len(a)
    names = list(names) if names is not None else [f"image {k}" for k in range(n)]
    order = list(range(n)) if order is None else list(order)
    x = _sample(a)[order]
    s, contrast = pair_scores(None, sample=x)
    decisive = contrast > 6.0 * noise and contrast > 0
    comp = _greedy(s, np.inf)
    pairs = [(i, j) for i, j in enumerate(comp) if 0 <= i < j]
    if len(pairs) >= 3:
        # second pass: the common sum is the median of the pairs' sums (max + min is
        # biased by noise, the max up and the min down), which halves a pair's score
        s, _ = pair_scores(None, np.median(np.stack([x[i] + x[j] for i, j in pairs]), axis=0),
                           sample=x)
    best = np.sort(s, axis=1)[:, 0] if n > 1 else np.zeros(n)
    # noise raises every score alike: a complement scores near the typical best
    # (0.08-0.14 in the bench's noisy scenes), but never as much as boards that
    # are not complements (0.25 for four shifts, 0.5 for two, before blur)
    limit = max(max_score, min(2.0 * float(np.median(best)), MAX_NOISY_SCORE))
    comp = _greedy(s, limit)
    lone = [k for k in range(n) if comp[k] < 0]
    if decisive and lone and len(lone) < n:
        k = lone[0]
        sc = [s[i, j] for i, j in enumerate(comp) if j >= 0]
        raise InputError(names[order[k]], f"no complement among the captures (its best match misses "
                                          f"{100 * best[k]:.0f}% of the contrast, the complements "
                                          f"found {100 * float(np.median(sc)):.0f}%); give each "
                                          "board's complement, or leave this one out")
    if decisive and n > 2:
        # an all-white (all-black) frame is a complement too, of the all-black (white)
        # one, but it is the brightest (darkest) capture at almost every pixel, where a
        # board is so at about half of them: refused, it would be taken for a board
        for side, pick in (("white", x.argmax(axis=0)), ("black", x.argmin(axis=0))):
            frac = np.bincount(pick, minlength=n) / x.shape[1]
            if frac.max() > FLAT_FRACTION:
                k = int(np.argmax(frac))
                raise InputError(names[order[k]], f"looks like an all-{side} frame (the "
                                                  f"{'brightest' if side == 'white' else 'darkest'}"
                                                  f" capture at {100 * frac[k]:.0f}% of the "
                                                  f"pixels), not a pattern; give it as --{side}")
    # back to the caller's indices
    inv = np.empty(n, int)
    inv[order] = np.arange(n)
    comp_out = tuple(order[comp[inv[i]]] if comp[inv[i]] >= 0 else -1 for i in range(n))
    score = tuple(float(s[inv[i], comp[inv[i]]]) if comp[inv[i]] >= 0 else float("nan")
                  for i in range(n))
    scores = s[np.ix_(inv, inv)]
    return Pairing(comp_out, score, contrast, bool(decisive), scores, limit)


FIXED_SCALE = 2 ** 24  # units per linear unit: rounding <= 2^-25 per value, only exact ties move
_FIXED_CHUNK = 1 << 16  # values per int64 partial sum: no overflow below 2^23 linear units


def fixed_sum(x: np.ndarray) -> int:
    """Sum of ``x`` in fixed point (``FIXED_SCALE`` units), as a Python int.

    Integer sums do not depend on their order, so summing bands of rows gives
    the whole image's number to the bit (a float64 ``sum`` is pairwise: its
    rounding depends on where the array starts and ends).

    >>> v = np.array([0.5, 0.25, 1e-3], np.float32)
    >>> fixed_sum(v) == fixed_sum(v[:1]) + fixed_sum(v[1:])
    True
    """
    flat = np.asarray(x).reshape(-1)
    total = 0
    for k in range(0, flat.size, _FIXED_CHUNK):
        q = np.rint(flat[k:k + _FIXED_CHUNK].astype(np.float64) * FIXED_SCALE).astype(np.int64)
        total += int(q.sum())
    return total


def content_keys(images: np.ndarray) -> list[tuple]:
    """A sort key per image that depends on its pixels only.

    ``(sum,)`` in fixed point (:func:`fixed_sum`: order-free, so a sum over
    bands of rows is the same number); images whose sums tie also get a digest
    of their bytes (hashing every image would cost more than the separation).
    """
    a = np.asarray(images)
    sums = [fixed_sum(im) for im in a]
    seen: dict[float, int] = {}
    for v in sums:
        seen[v] = seen.get(v, 0) + 1
    return [(v, hashlib.blake2b(np.ascontiguousarray(im).tobytes(), digest_size=16).digest()
             if seen[v] > 1 else b"") for v, im in zip(sums, a, strict=True)]


def canonical_order(images: np.ndarray, complement_of=None, *,
                    keys=None) -> tuple[list[int], list[int] | None]:
    """A permutation of ``images`` fixed by their content, and the complements in it.

    Without complements (or all ``-1``) the images are sorted by
    :func:`content_keys`. With complements, each pair is ordered by its
    members' keys, the pairs by their first member's key, and the result is
    the first members then the second members (the ``checker_set`` layout);
    unpaired images (if any) follow, sorted. ``keys``: :func:`content_keys`
    of the images, when already computed.

    Returns
    -------
    order : list of int
        ``images[order]`` is the canonical stack.
    complement_of : list of int or None
        The complements in the canonical order.

    Examples
    --------
    >>> ims = np.array([[3.0], [1.0], [2.0], [4.0]])
    >>> canonical_order(ims, [2, 3, 0, 1])
    ([1, 2, 3, 0], [2, 3, 0, 1])
    """
    keys = content_keys(images) if keys is None else keys
    n = len(keys)
    if complement_of is None or all(j < 0 for j in complement_of):
        return sorted(range(n), key=keys.__getitem__), None
    pairs = sorted({tuple(sorted((i, j), key=keys.__getitem__))
                    for i, j in enumerate(complement_of) if 0 <= j != i},
                   key=lambda p: keys[p[0]])
    rest = sorted((k for k in range(n) if not 0 <= complement_of[k] != k), key=keys.__getitem__)
    m = len(pairs)
    order = [p[0] for p in pairs] + [p[1] for p in pairs] + rest
    comp = [*range(m, 2 * m), *range(m), *([-1] * len(rest))]
    return order, comp


def check_pairs(pairing: Pairing, complement_of, *, names) -> None:
    """Check a given layout (``stack.json``'s ``complement_of``) against the captures.

    Raises
    ------
    InputError
        Naming the first image whose stated complement does not sum with it
        to the all-lit image (when the contrast is decisive).
    """
    if not pairing.decisive or pairing.scores is None:
        return
    for i, j in enumerate(complement_of):
        if 0 <= j != i and pairing.scores[i, j] > pairing.limit:
            raise InputError(names[i], f"the pattern layout says its complement is {names[j]}, but "
                                       f"their sum misses {100 * pairing.scores[i, j]:.0f}% of the "
                                       "contrast (a complement misses ~0%); the files do not match "
                                       "the layout")


def phase_spacing(images: np.ndarray, *, names=None, noise: float = 0.0) -> np.ndarray:
    """Phase differences (degrees) between phase-shifted sinusoid captures, from the data.

    With ``d_k = I_k − mean_k I`` (the global light and the offset cancel),
    ``d_k = A·cos(θ + φ_k)`` at every pixel, so over many pattern periods the
    correlation of ``d_j`` and ``d_k`` is ``cos(φ_j − φ_k)``: −½ (120°) for
    each pair of a three-step set in any order. A three-step estimate uses
    ``|Σ_k I_k e^{iφ_k}|``, and a permutation of three equally spaced phases
    only rotates or mirrors that phasor, so the order does not matter, but a
    repeated phase (the same capture twice, or another pattern) does.

    Returns
    -------
    ndarray, ``(N, N)``
        ``arccos`` of the correlations, degrees (``nan`` where the
        modulation is within the noise).

    Raises
    ------
    InputError
        Naming the later of two captures that show the same phase (under 60°
        apart, where a three-step set has 120°).

    Examples
    --------
    >>> x = np.linspace(0, 20 * np.pi, 400)
    >>> ims = np.stack([0.3 + 0.2 * np.cos(x + p) for p in (0, 4 * np.pi / 3, 2 * np.pi / 3)])
    >>> np.round(phase_spacing(ims)[0, 1:]).tolist()
    [120.0, 120.0]
    """
    x = _sample(np.asarray(images))
    n = len(x)
    names = list(names) if names is not None else [f"image {k}" for k in range(n)]
    d = x - x.mean(axis=0)
    e = np.sqrt((d * d).mean(axis=1))
    out = np.full((n, n), np.nan)
    ok = e > 3.0 * noise + 1e-12
    for j in range(n):
        for k in range(j + 1, n):
            if ok[j] and ok[k]:
                rho = float((d[j] * d[k]).mean() / (e[j] * e[k]))
                out[j, k] = out[k, j] = np.degrees(np.arccos(np.clip(rho, -1, 1)))
                if out[j, k] < 60.0:
                    raise InputError(names[k], f"shows the same sinusoid phase as {names[j]} "
                                               f"({out[j, k]:.0f} deg apart, a three-step set has "
                                               "120 deg); give one capture per phase")
    return out
