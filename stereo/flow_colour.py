"""Middlebury colour coding of flow fields (Baker et al. 2011, IJCV 92(1),
doi:10.1007/s11263-010-0390-2): hue is the direction, saturation the length
relative to the largest known vector; unknown (NaN) is black.

The colour wheel is the Middlebury one (55 hues through red, yellow, green,
cyan, blue, magenta, interpolated linearly), so our pictures read like every
flow paper's.

Examples
--------
>>> f = np.zeros((2, 3, 2), np.float32); f[0, 0] = (1, 0); f[1, 2] = np.nan
>>> img = flow_to_colour(f)
>>> img.shape, img.dtype.name, img[1, 2].tolist(), img[0, 1].tolist()
((2, 3, 3), 'uint8', [0, 0, 0], [255, 255, 255])
"""

from __future__ import annotations

import numpy as np


def colour_wheel() -> np.ndarray:
    """The Middlebury wheel: ``(55, 3)`` float RGB in [0, 255]."""
    segments = ((15, (255, 0, 0), (255, 255, 0)), (6, (255, 255, 0), (0, 255, 0)),
                (4, (0, 255, 0), (0, 255, 255)), (11, (0, 255, 255), (0, 0, 255)),
                (13, (0, 0, 255), (255, 0, 255)), (6, (255, 0, 255), (255, 0, 0)))
    rows = []
    for n, a, b in segments:
        t = np.arange(n)[:, None] / n
        rows.append((1 - t) * np.array(a, float) + t * np.array(b, float))
    return np.concatenate(rows)


def flow_to_colour(flow: np.ndarray, *, max_flow: float | None = None) -> np.ndarray:
    """Colour-code a flow field.

    Parameters
    ----------
    flow : ndarray, ``(H, W, 2)``
        (dx, dy) in pixels; NaN where unknown.
    max_flow : float, optional
        Length shown fully saturated; default the largest known length.

    Returns
    -------
    ndarray, uint8, ``(H, W, 3)`` RGB
    """
    f = np.asarray(flow, np.float64)
    if f.ndim != 3 or f.shape[2] != 2:
        raise ValueError(f"flow: expected (H, W, 2), got {f.shape}")
    known = np.isfinite(f).all(axis=2)
    u = np.where(known, f[..., 0], 0.0)
    v = np.where(known, f[..., 1], 0.0)
    rad = np.hypot(u, v)
    top = max_flow if max_flow is not None else (rad[known].max() if known.any() else 0.0)
    if top > 0:
        u, v, rad = u / top, v / top, rad / top
    wheel = colour_wheel()
    n = len(wheel)
    a = np.arctan2(-v, -u) / np.pi
    fk = (a + 1) / 2 * (n - 1)
    k0 = np.floor(fk).astype(int) % n
    k1 = (k0 + 1) % n
    t = (fk - np.floor(fk))[..., None]
    col = ((1 - t) * wheel[k0] + t * wheel[k1]) / 255.0
    r = np.clip(rad, 0, 1)[..., None]
    col = 1 - r * (1 - col)  # saturation grows with length, white at rest
    col = np.where((rad > 1)[..., None], col * 0.75, col)  # beyond max_flow: darker
    out = np.round(255 * col).astype(np.uint8)
    out[~known] = 0
    return out
