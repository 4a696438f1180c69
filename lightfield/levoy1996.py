"""Light-slab rendering of a novel pinhole view (Levoy & Hanrahan 1996), reference §5.4.3.

M. Levoy, P. Hanrahan, "Light Field Rendering", ACM SIGGRAPH 1996,
doi:10.1145/237170.237199.

The slab is the pair of planes: the camera plane ``(u, v)`` at z = 0 (cameras
at ``((v - vc) spacing, (u - uc) spacing, 0)``) and the focal plane ``(s, t)``
at the disparity ``focus_slope`` (depth ``focal_px spacing / focus_slope``;
slope 0 is the plane at infinity). A novel pinhole at ``(X, Y, Z)`` (world
units, same intrinsics as the views, looking down +z) sends the ray of pixel
``(x, y)`` through the camera plane at fractional view ``(u*, v*)`` and the
focal plane at a point which camera ``(u, v)`` sees at pixel

    x_k = ppx + (s_f / spacing)(X - (v - vc) spacing) + (1 - Z s_f / (f spacing))(x - ppx)

(and likewise for y). ``quadrilinear`` interpolates bilinearly in ``(u, v)``
between the four nearest cameras and bilinearly in ``(s, t)`` within each;
``uv-bilinear`` (the fast option the paper notes is sometimes sufficient) takes
the nearest ``(s, t)`` sample. Rays that leave the slab (outside the camera
grid or a view) are invalid: value 0, ``valid`` False.

Examples
--------
>>> import numpy as np
>>> from lumigraph.lightfield.field import LightField
>>> lf = LightField(np.random.default_rng(0).random((3, 3, 8, 10, 1)), focal_px=10.0)
>>> out = render_view(lf, (0.0, 0.0, 0.0))     # the centre camera itself
>>> bool(np.allclose(out.image, lf.data[1, 1])), bool(out.valid.all())
(True, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.lightfield.field import LightField

INTERPOLATIONS = ("quadrilinear", "uv-bilinear")


@dataclass(frozen=True)
class NovelView:
    """A rendered view: ``image`` (H, W, C) float32 linear (0 where invalid),
    ``valid`` (H, W) bool, and the pinhole ``position`` (X, Y, Z)."""

    image: np.ndarray
    valid: np.ndarray
    position: tuple[float, float, float]

    def __post_init__(self):
        if self.image.shape[:2] != self.valid.shape:
            raise ValueError("valid: must be (H, W) of the image")


def render_view(lf: LightField, position, *, focus_slope: float = 0.0,
                interpolation: str = "quadrilinear") -> NovelView:
    """Render the view of a pinhole at ``position`` from the light slab.

    Parameters
    ----------
    lf : LightField
        Needs ``focal_px`` when ``position`` has Z != 0.
    position : (X, Y, Z)
        Pinhole centre in world units (X right, Y down, Z forward), relative to
        the grid centre; ``Z != 0`` needs ``lf.focal_px``.
    focus_slope : float
        Disparity (px per view step) of the slab's (s, t) plane; put it at the
        scene's mean depth to keep ghosting least.
    interpolation : {"quadrilinear", "uv-bilinear"}

    Returns
    -------
    NovelView

    Raises
    ------
    InputError
        ``position`` with ``Z != 0`` for a light field without ``focal_px``,
        or not finite; ``focus_slope`` not finite.
    ValueError
        An unknown ``interpolation``.
    """
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
                         f"got {interpolation!r}")
    px_, py_, pz = (float(c) for c in position)
    if not np.all(np.isfinite([px_, py_, pz])):
        raise InputError("position", f"expected a finite (X, Y, Z), got {tuple(position)}")
    if not np.isfinite(focus_slope):
        raise InputError("focus_slope", f"expected a finite slope, got {focus_slope}")
    u, v = lf.grid
    _, _, h, w, c = lf.data.shape
    uc, vc = lf.center
    f = lf.focal_px
    if f is None:
        if pz != 0.0:
            raise InputError("position", "Z != 0 needs the light field's focal_px (give it when "
                                         "the light field is imported)")
        f = float(w)
    ppx, ppy = (w - 1) / 2, (h - 1) / 2
    sp = lf.spacing
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    vf = (px_ - pz * (x - ppx) / f) / sp + vc          # fractional camera column
    uf = (py_ - pz * (y - ppy) / f) / sp + uc          # fractional camera row
    valid = (vf >= -1e-9) & (vf <= v - 1 + 1e-9) & (uf >= -1e-9) & (uf <= u - 1 + 1e-9)
    v0 = np.clip(np.floor(vf), 0, max(v - 2, 0)).astype(np.int64)
    u0 = np.clip(np.floor(uf), 0, max(u - 2, 0)).astype(np.int64)
    scale = 1.0 - pz * focus_slope / (f * sp)
    flat = lf.data.reshape(-1, c)
    out = np.zeros((h, w, c), np.float64)
    for du in (0, 1):
        for dv in (0, 1):
            ui, vi = np.minimum(u0 + du, u - 1), np.minimum(v0 + dv, v - 1)
            wu = np.clip(1.0 - np.abs(uf - ui), 0.0, 1.0) if u > 1 else np.ones_like(uf)
            wv = np.clip(1.0 - np.abs(vf - vi), 0.0, 1.0) if v > 1 else np.ones_like(vf)
            if u == 1 and du == 1 or v == 1 and dv == 1:
                continue
            wc = wu * wv
            xk = ppx + focus_slope / sp * (px_ - (vi - vc) * sp) + scale * (x - ppx)
            yk = ppy + focus_slope / sp * (py_ - (ui - uc) * sp) + scale * (y - ppy)
            inside = (xk >= -1e-6) & (xk <= w - 1 + 1e-6) & (yk >= -1e-6) & (yk <= h - 1 + 1e-6)
            valid &= inside | (wc == 0)
            base = (ui * v + vi) * (h * w)
            if interpolation == "uv-bilinear":
                xi = np.clip(np.round(xk), 0, w - 1).astype(np.int64)
                yi = np.clip(np.round(yk), 0, h - 1).astype(np.int64)
                out += wc[..., None] * flat[base + yi * w + xi]
                continue
            x0 = np.clip(np.floor(xk), 0, w - 2).astype(np.int64)
            y0 = np.clip(np.floor(yk), 0, h - 2).astype(np.int64)
            fx, fy = np.clip(xk - x0, 0, 1), np.clip(yk - y0, 0, 1)
            for dy, wy in ((0, 1 - fy), (1, fy)):
                for dx, wx in ((0, 1 - fx), (1, fx)):
                    out += (wc * wy * wx)[..., None] * flat[base + (y0 + dy) * w + x0 + dx]
    out[~valid] = 0.0
    return NovelView(out.astype(np.float32), valid, (px_, py_, pz))
