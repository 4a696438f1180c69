"""High-frequency residue: does the projected pattern survive into the global image?

Nayar's separation assumes global transport blurs the pattern away (eq. 8.12).
A mirror-like surface reflects the pattern sharply onto other surfaces, and a
pattern too coarse for the scene's transport is not averaged either; then the
"global" light still carries the pattern and the split is wrong (reference
§8.3.3, Fig. 8.45). Two checks, both relative to the noise:

- :func:`pair_residue` (checker stacks): every complementary pair gives its own
  global estimate; if the assumption holds they agree, if the pattern survives
  in the global light they differ by the pattern's contribution.
- :func:`spatial_residue` (any method): the global image's local contrast at
  pattern scale, compared with that of the pattern-free mean image (object
  edges show in both, a surviving pattern only in the global image).

Examples
--------
>>> import numpy as np
>>> g = np.ones((32, 32, 1), np.float32)
>>> frac, _ = spatial_residue(g, g, window=5)
>>> frac
0.0
"""

from __future__ import annotations

import numpy as np


def pair_residue(images, complement_of, *, b: float, alpha: float, sigma: np.ndarray,
                 valid: np.ndarray, keep: float = 0.75, rel: float = 0.5) -> tuple[float, np.ndarray]:
    """Fraction of valid pixels whose per-pair global estimates disagree.

    Parameters
    ----------
    images : ndarray, ``(N, H, W, C)`` float32
    complement_of : sequence of int
    b, alpha : float
        Black level and lit fraction (for the per-pair solve).
    sigma : ndarray, ``(H, W, C)``
        Noise standard deviation of one capture.
    valid : ndarray, ``(H, W)`` bool
    rel : float
        A pixel is flagged when the spread of the per-pair global estimates
        exceeds ``rel`` of the global estimate and 6 noise standard deviations.

    Returns
    -------
    fraction : float
    flagged : ndarray, ``(H, W)`` bool
    """
    from lumigraph.separation.nayar2006 import _coefficients

    a = np.asarray(images, np.float32)
    pairs = sorted({(min(i, j), max(i, j)) for i, j in enumerate(complement_of) if j >= 0 and j != i})
    if len(pairs) < 2:
        return 0.0, np.zeros(a.shape[1:3], bool)
    hi = np.maximum(a[[p[0] for p in pairs]], a[[p[1] for p in pairs]])
    lo = np.minimum(a[[p[0] for p in pairs]], a[[p[1] for p in pairs]])
    c = hi - lo
    top = np.sort(c, axis=0)[len(pairs) // 2:].mean(axis=0)
    use = c >= keep * top
    _, _, det = _coefficients(alpha, 1.0 - alpha, b)
    g = (lo - b * hi) / det
    gmax = np.where(use, g, -np.inf).max(axis=0)
    gmin = np.where(use, g, np.inf).min(axis=0)
    spread = np.where(use.sum(axis=0) >= 2, gmax - gmin, 0.0)
    gmean = (g * use).sum(axis=0) / np.maximum(use.sum(axis=0), 1)
    sig_g = np.sqrt(2.0) * sigma * (1.0 + b) / det
    flag = (spread > rel * np.abs(gmean)) & (spread > 6.0 * sig_g)
    flagged = flag.any(axis=-1) & valid
    n = max(int(valid.sum()), 1)
    return float(flagged.sum() / n), flagged


def spatial_residue(global_, mean_image, *, window: int = 9, rel: float = 0.3,
                    valid: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """Fraction of pixels where the global image has pattern-scale contrast that
    the pattern-free mean image lacks.

    ``r(x) = |x − box(x)| / box(x)`` over a ``window``-pixel box (about one
    pattern period); a pixel is flagged when ``r(global) > rel`` and
    ``r(global) > 3·r(mean)``.
    """
    import cv2

    def contrast(x):
        x = np.asarray(x, np.float32)
        sm = cv2.blur(x, (window, window), borderType=cv2.BORDER_REFLECT)
        sm = sm.reshape(x.shape)
        ref = 0.02 * float(np.percentile(np.abs(sm[::4, ::4]), 99))  # subsampled: cheap at 1 MP
        return np.abs(x - sm) / np.maximum(np.abs(sm), 1e-6 + ref)

    rg = contrast(global_)
    rm = contrast(mean_image)
    flag = ((rg > rel) & (rg > 3.0 * rm)).any(axis=-1)
    if valid is not None:
        flag &= valid
        n = max(int(valid.sum()), 1)
    else:
        n = flag.size
    return float(flag.sum() / n), flag
