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
        ``.meta.json``) into ``folder``; ``mask.png`` is written last. Through
        :class:`SeparationWriter` in one band, so a run by bands of rows writes
        the same bytes."""
        h, w, c = self.direct.shape
        with SeparationWriter(folder, width=w, height=h, channels=c) as out:
            out.write(self.direct, self.global_, self.mask)
            out.finish(meta=meta, method=self.method, params=self.params, quality=self.quality,
                       warnings=self.warnings)
        return Path(folder)

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


def artifact_meta(meta: dict, *, method: str, params: dict, quality: dict, warnings) -> dict:
    """The sidecar of each file of a separation (``component`` added per file):
    ``meta`` (the command's) with the result's params, quality and warnings."""
    return {**meta, "params": {**meta.get("params", {}), **params},
            "quality": {**meta.get("quality", {}), **quality},
            "warnings": list(meta.get("warnings", [])) + list(warnings),
            "method": method, "mask_bits": MASK_BITS}


class SeparationWriter:
    """``direct.exr``, ``global.exr`` and ``mask.png`` written band by band,
    top to bottom, so a separation by bands never holds its outputs whole.

    Scanline OpenEXR (:class:`capture.tiles.ExrRowWriter`: the bytes
    :func:`capture.io.write_exr` writes for the whole image) and PNG
    (:class:`capture.tiles.PngRowWriter`; :meth:`Separation.save` writes
    through this class too, so whole and banded runs give the same bytes).
    Each file goes to a temporary beside it (:func:`capture.artifact.atomic_path`)
    and replaces it on :meth:`finish`, ``mask.png`` last; a ``with`` block left
    by an exception, or without :meth:`finish`, leaves the folder as it was.

    Examples
    --------
    >>> import numpy as np, tempfile
    >>> d = tempfile.mkdtemp()
    >>> with SeparationWriter(d, width=3, height=4, channels=1) as out:
    ...     for y0 in (0, 3):
    ...         n = min(3, 4 - y0)
    ...         out.write(np.ones((n, 3, 1), np.float32), np.zeros((n, 3, 1), np.float32),
    ...                   np.zeros((n, 3), np.uint8))
    ...     out.finish(meta={}, method="checker", params={}, quality={}, warnings=())
    >>> Separation.load(d).direct.shape
    (4, 3, 1)
    """

    def __init__(self, folder: str | os.PathLike, *, width: int, height: int, channels: int):
        from contextlib import ExitStack

        from lumigraph.capture.artifact import atomic_path
        from lumigraph.capture.tiles import ExrRowWriter, PngRowWriter

        self.folder = Path(folder)
        self.height = height
        self.rows_done = 0
        self._finished = False
        self._stack = ExitStack()
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            # entered mask first: an ExitStack leaves in reverse, so mask.png replaces last
            self._tmp = {}
            for name in reversed(FILES):
                self._tmp[name] = self._stack.enter_context(atomic_path(self.folder / name))
            self._direct = ExrRowWriter(self._tmp["direct.exr"], width, height, channels)
            self._stack.callback(self._direct.close)
            self._global = ExrRowWriter(self._tmp["global.exr"], width, height, channels)
            self._stack.callback(self._global.close)
            self._mask = PngRowWriter(self._tmp["mask.png"], width, height, 1, np.uint8)
            self._stack.callback(self._mask.close)
        except BaseException:
            self._stack.close()
            raise

    def __enter__(self) -> SeparationWriter:
        return self

    def write(self, direct: np.ndarray, global_: np.ndarray, mask: np.ndarray) -> None:
        """The next band: ``(n, W, C)`` float32 direct and global, ``(n, W)`` uint8 mask."""
        self._direct.write(direct)
        self._global.write(global_)
        self._mask.write(mask)
        self.rows_done += len(mask)

    def finish(self, *, meta: dict, method: str, params: dict, quality: dict, warnings) -> None:
        """Close the files (every row written) and write their sidecars."""
        from lumigraph.capture.tiles import finish_artifact

        if self.rows_done != self.height:
            raise RuntimeError(f"{self.folder}: {self.rows_done} of {self.height} rows written")
        for wr in (self._direct, self._global, self._mask):
            wr.close()
        base = artifact_meta(meta, method=method, params=params, quality=quality,
                             warnings=warnings)
        for name in FILES:
            finish_artifact(self.folder / name, self._tmp[name],
                            {**base, "component": name.split(".")[0]})
        self._finished = True

    def __exit__(self, kind, exc, tb):
        if kind is None and not self._finished:
            kind, exc = RuntimeError, RuntimeError(f"{self.folder}: finish() was not called")
            try:
                self._stack.__exit__(kind, exc, None)
            finally:
                raise exc
        return self._stack.__exit__(kind, exc, tb)
