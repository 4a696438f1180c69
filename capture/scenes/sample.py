"""``sample``: a smooth linear radiance ramp seen by an ideal 12-bit linear sensor.

The smallest scene with exact ground truth: it exercises rendering, caching,
``stack.json``/``gt.json`` and 16-bit PNG with ``sBIT``; the demo starts here.
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.render import Option, RenderedScene, SceneSpec


def render_sample(*, size, seed, rng, bit_depth=12, noise=0.0):
    """Radiance ``r(x, y) = 0.05 + 0.9 x/(W-1)`` (R), ``… y/(H-1)`` (G), constant
    0.5 (B); codes ``round(r · (2**bit_depth - 1) + N(0, noise))``, clipped.

    Examples
    --------
    >>> s = render_sample(size=(4, 2), seed=0, rng=np.random.default_rng(0))
    >>> int(s.images[0][0, 0, 2]) == round(0.5 * 4095)
    True
    """
    w, h = size
    x = np.linspace(0.0, 1.0, w)[None, :] * np.ones((h, 1))
    y = np.linspace(0.0, 1.0, h)[:, None] * np.ones((1, w))
    radiance = np.stack([0.05 + 0.9 * x, 0.05 + 0.9 * y, np.full_like(x, 0.5)], axis=-1)
    top = 2 ** bit_depth - 1
    codes = radiance * top + (rng.normal(0.0, noise, radiance.shape) if noise > 0 else 0.0)
    codes = np.clip(np.round(codes), 0, top).astype(np.uint16)
    return RenderedScene("sample", {}, (codes,), ("ramp.png",),
                         stack={"bit_depth": bit_depth, "linear": True, "exposure_times_s": [1.0]},
                         gt={"code_scale": top, "noise_sigma_codes": noise},
                         gt_arrays={"radiance": radiance.astype(np.float32)})


SPECS = {
    "sample": SceneSpec(
        "sample", (64, 48),
        (Option("bit_depth", int, 12, "sensor bit depth", low=8, high=16),
         Option("noise", float, 0.0, "Gaussian read noise, in code values", low=0.0))),
}
