"""The separation result: direct and global images plus where to trust them.

Examples
--------
>>> import numpy as np, tempfile
>>> s = Separation(np.ones((2, 3, 1), np.float32), np.zeros((2, 3, 1), np.float32),
...                np.zeros((2, 3), np.uint8), "checker")
>>> d = tempfile.mkdtemp()
>>> _ = s.save(d, meta={"schema": "demo"})
>>> Separation.load(d).direct.shape
(2, 3, 1)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lumigraph.separation.nayar2006 import MASK_LOW_CONTRAST, MASK_NEVER_LIT, MASK_SATURATED

SCHEMA = "lumigraph.separation"
MASK_BITS = {"never_lit": MASK_NEVER_LIT, "saturated": MASK_SATURATED,
             "low_contrast": MASK_LOW_CONTRAST}
# what Separation.save writes into its folder (each with its .meta.json), mask last
FILES = ("direct.exr", "global.exr", "mask.png")


@dataclass(frozen=True)
class Separation:
    """Direct and global light of one view.

    Attributes
    ----------
    direct, global_ : ndarray, ``(H, W, C)`` float32
        Linear radiance, in the units of the input images.
    mask : ndarray, ``(H, W)`` uint8
        0 where the separation is trusted; otherwise the OR of
        ``1`` never lit (the brightest capture is within the noise of black),
        ``2`` saturated in some capture, ``4`` ``L⁺ − L⁻`` within the noise.
    method : str
        The ``--method`` used.
    params : dict
        α, b (and whether b was given or measured), estimator, …
    quality : dict
        Mask counts, noise model, residue-check figures.
    warnings : tuple of str
    """

    direct: np.ndarray
    global_: np.ndarray
    mask: np.ndarray
    method: str
    params: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def __post_init__(self):
        if self.direct.ndim != 3 or self.direct.shape != self.global_.shape:
            raise ValueError(f"direct, global_: expected equal (H, W, C) shapes, got "
                             f"{self.direct.shape} and {self.global_.shape}")
        if self.mask.shape != self.direct.shape[:2] or self.mask.dtype != np.uint8:
            raise ValueError(f"mask: expected (H, W) uint8, got {self.mask.shape} {self.mask.dtype}")
        if self.direct.dtype != np.float32 or self.global_.dtype != np.float32:
            raise TypeError("direct, global_: expected float32")

    @property
    def valid(self) -> np.ndarray:
        """``(H, W)`` bool: pixels with no mask bit set."""
        return self.mask == 0

    def save(self, folder: str | os.PathLike, *, meta: dict) -> Path:
        """Write ``direct.exr``, ``global.exr`` and ``mask.png`` (each with its
        ``.meta.json``) into ``folder``; ``mask.png`` is written last."""
        from lumigraph.capture import io
        from lumigraph.capture.artifact import write_artifact

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        base = {**meta, "params": {**meta.get("params", {}), **self.params},
                "quality": {**meta.get("quality", {}), **self.quality},
                "warnings": list(meta.get("warnings", [])) + list(self.warnings),
                "method": self.method, "mask_bits": MASK_BITS}
        for name, arr in (("direct", self.direct), ("global", self.global_)):
            write_artifact(folder / f"{name}.exr", lambda p, a=arr: io.write_exr(p, a),
                           meta={**base, "component": name})
        write_artifact(folder / "mask.png", lambda p: io.write_image(p, self.mask),
                       meta={**base, "component": "mask"})
        return folder

    @classmethod
    def load(cls, folder: str | os.PathLike) -> Separation:
        """Read a folder written by :meth:`save`."""
        import json

        from lumigraph.capture import io
        from lumigraph.capture.errors import InputError

        folder = Path(folder)
        need = [folder / n for n in ("direct.exr", "global.exr", "mask.png")]
        for p in need:
            if not p.exists():
                raise InputError(p, "missing; not a separation folder")
        d = io.read_exr(need[0])
        g = io.read_exr(need[1])
        if d.ndim == 2:
            d, g = d[..., None], g[..., None]
        meta = {}
        mp = folder / "mask.png.meta.json"
        if mp.exists():
            meta = json.loads(mp.read_text())
        return cls(d, g, io.read_image(need[2]).astype(np.uint8), meta.get("method", "unknown"),
                   meta.get("params", {}), meta.get("quality", {}), tuple(meta.get("warnings", [])))
