"""Grey images and their noise: the one luma conversion and the two noise
estimates that stereo and flow share, each named for what it computes.

Luma (one computation, two units):

- :func:`luma_codes`: Rec. 601 luma ``0.299 R + 0.587 G + 0.114 B`` in the
  image's own code values (an 8-bit image gives 0..255). Block matching and
  model-based stereo compare and threshold in code values.
- :func:`luma_normalised`: the same luma divided by the integer dtype's
  largest value (uint8 255, uint16 65535), so any integer image lands in
  [0, 1]; float images are taken as they are. Flow works in [0, 1].

Noise (two estimators of one σ, for two purposes): both filter with
Immerkær's 3×3 difference-of-Laplacians mask, which cancels smooth image
content and passes white noise with gain 6 (J. Immerkær, "Fast noise variance
estimation", CVIU 64(2), 1996, doi:10.1006/cviu.1996.0060). They differ in
where they average its response:

- :func:`noise_sigma_immerkaer`: over the whole image (the paper's eq. 2).
  Fast; texture and edges leak into the estimate, which errs high on
  textured images. Flow uses it for its texture confidence.
- :func:`noise_sigma_smooth_blocks`: over the smoothest 10 % of 8×8 blocks,
  leaving out blocks near black or white (clipped, so quieter than the
  sensor). Robust to texture: what block matching and model-based stereo
  use to set their texture thresholds.

Examples
--------
>>> img = np.full((2, 2, 3), 255, np.uint8)
>>> float(luma_codes(img).max()), float(luma_normalised(img).max())
(255.0, 1.0)
"""

from __future__ import annotations

import math

import numpy as np


def luma_codes(image: np.ndarray) -> np.ndarray:
    """Rec. 601 luma in the image's own code values.

    Parameters
    ----------
    image : ndarray, ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)``
        Any numeric dtype; RGB(A) order (alpha ignored).

    Returns
    -------
    ndarray, ``(H, W)`` float32
        ``0.299 R + 0.587 G + 0.114 B`` (OpenCV's RGB→grey weights), in the
        input's code values; a grey input is only converted to float32.

    Examples
    --------
    >>> [round(float(v), 3) for v in luma_codes(np.array([[[100, 100, 100], [255, 0, 0]]], np.uint8))[0]]
    [100.0, 76.245]
    """
    import cv2

    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = cv2.cvtColor(np.ascontiguousarray(a[..., :3], dtype=np.float32), cv2.COLOR_RGB2GRAY)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    elif a.ndim != 2:
        raise ValueError(f"image: expected (H, W) or (H, W, 1|3|4), got shape {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def luma_normalised(image: np.ndarray) -> np.ndarray:
    """Rec. 601 luma scaled to [0, 1] by the integer dtype's largest value.

    :func:`luma_codes` times ``1 / iinfo(dtype).max`` for integer images
    (uint8: 1/255, uint16: 1/65535); float images are returned in their own
    values (taken as already in [0, 1]).

    Returns
    -------
    ndarray, ``(H, W)`` float32

    Examples
    --------
    >>> luma_normalised(np.full((2, 2, 3), 255, np.uint8)).max()
    np.float32(1.0)
    >>> float(luma_normalised(np.full((1, 1), 65535, np.uint16))[0, 0])
    1.0
    """
    a = np.asarray(image)
    f = luma_codes(a)
    if a.dtype.kind in "ui":
        f = f * np.float32(1.0 / float(np.iinfo(a.dtype).max))
    return np.ascontiguousarray(f, np.float32)


def _immerkaer_response(gray: np.ndarray) -> np.ndarray:
    """``|gray ⊛ [[1,-2,1],[-2,4,-2],[1,-2,1]]|`` without the one-pixel border
    (float32, ``(H-2, W-2)``): white noise of σ gives a mean of ``6 σ sqrt(2/π)``."""
    import cv2

    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    return np.abs(cv2.filter2D(gray, cv2.CV_32F, k)[1:-1, 1:-1])


def noise_sigma_immerkaer(gray: np.ndarray) -> float:
    """Standard deviation of white noise in an image, from the mean absolute
    Immerkær mask response over the whole image (Immerkær 1996, eq. 2).

    Fast, but texture and edges count as noise: on a textured image the
    estimate errs high (see :func:`noise_sigma_smooth_blocks`).

    Parameters
    ----------
    gray : ndarray, ``(H, W)``, H, W >= 3
        One grey image, any unit (σ comes in the same unit).

    Examples
    --------
    >>> g = np.full((64, 64), 0.5) + np.random.default_rng(1).normal(0, 0.01, (64, 64))
    >>> round(noise_sigma_immerkaer(g), 3)
    0.01
    """
    r = _immerkaer_response(np.asarray(gray, np.float32))
    h, w = gray.shape[:2]
    return float(math.sqrt(math.pi / 2) / (6 * (w - 2) * (h - 2)) * r.sum())


def noise_sigma_smooth_blocks(gray: np.ndarray) -> float:
    """Robust estimate of the sensor noise σ of one image, from its smoothest
    parts.

    The mean absolute Immerkær mask response is taken over 8×8 blocks and the
    10th percentile of the blocks kept: the smoothest parts of a scene show
    the noise alone, where a global average (:func:`noise_sigma_immerkaer`)
    would count texture and edges as noise. Blocks whose mean level lies
    within 4 % of the image's range from its darkest or brightest value are
    left out (clipped, quieter than the sensor) when at least 10 others
    remain. An image under 10×10 pixels falls back to the global mean.

    Parameters
    ----------
    gray : ndarray, ``(H, W)`` float32
        One grey image, any unit (σ comes in the same unit).

    Examples
    --------
    >>> g = np.full((64, 64), 100.0) + np.random.default_rng(1).normal(0, 2, (64, 64))
    >>> round(noise_sigma_smooth_blocks(g.astype(np.float32)), 1)
    2.0
    """
    import cv2

    r = _immerkaer_response(gray)
    h, w = (r.shape[0] // 8) * 8, (r.shape[1] // 8) * 8
    if h == 0 or w == 0:
        return float(np.sqrt(np.pi / 2) * r.mean() / 6.0)
    # 8x8 block means (area resampling by exactly 1/8 is the block mean)
    blocks = cv2.resize(r[:h, :w], (w // 8, h // 8), interpolation=cv2.INTER_AREA)
    # blocks near black or white are clipped (less noise than the sensor's):
    # leave them out
    level = cv2.resize(np.ascontiguousarray(gray[1:h + 1, 1:w + 1]), (w // 8, h // 8),
                       interpolation=cv2.INTER_AREA)
    lo, hi = float(gray.min()), float(gray.max())
    ok = (level > lo + 0.04 * (hi - lo)) & (level < hi - 0.04 * (hi - lo))
    if ok.sum() >= 10:
        blocks = blocks[ok]
    # mean |N(0, s)| = s·sqrt(2/π); the 10th percentile of 8×8 block means of
    # pure noise sits at 0.785 of their mean (measured; the mask's responses
    # are correlated), hence 1/0.785
    return float(np.sqrt(np.pi / 2) * np.percentile(blocks, 10) / 6.0 / 0.785)
