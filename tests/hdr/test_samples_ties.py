"""The sampler's noise-level ties (hdr/samples.py, ``tie_noise``)."""

import numpy as np

from lumigraph.hdr.samples import sample_pixels


def _ranges(img, idx):
    """3×3 range of each picked pixel (single channel, interior pixels)."""
    h, w = img.shape
    y, x = np.divmod(idx, w)
    win = np.stack([img[np.clip(y + dy, 0, h - 1), np.clip(x + dx, 0, w - 1)]
                    for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    return (win.max(axis=0) - win.min(axis=0)).astype(np.float64)


def test_flat_deep_wall_is_not_ranked_by_its_own_noise():
    # A flat wall at 16 bits: every 3×3 range is noise only. Exact ranking
    # picks the pixels whose noise happened to be small; ties at a multiple
    # of the noise floor wide enough to cover every range make the pick
    # within a stratum random, so its ranges are those of random pixels:
    # larger than the exact pick's by more than 3 standard errors of the
    # difference of the two means.
    rng = np.random.default_rng(1)
    h, w, n = 60, 80, 300
    ref = np.clip(np.rint(20000 + 40.0 * rng.standard_normal((h, w))), 0, 65535)
    stack = np.stack([ref, np.rint(ref * 0.5)]).astype(np.uint16)[..., None]
    exact = _ranges(ref, sample_pixels(stack, n=n, bit_depth=16, rng=np.random.default_rng(0),
                                       tie_noise=0.0))
    tied = _ranges(ref, sample_pixels(stack, n=n, bit_depth=16, rng=np.random.default_rng(0),
                                      tie_noise=100.0))
    se = np.hypot(exact.std(), tied.std()) / np.sqrt(n)
    assert tied.mean() > exact.mean() + 3 * se

