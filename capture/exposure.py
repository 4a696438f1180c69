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
