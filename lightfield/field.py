"""The 4-D light-field container and its folder format (DESIGN §3-4).

A light field is ``data[u, v, y, x, c]``: ``(U, V)`` the camera / sub-aperture
grid (row, column), ``(H, W)`` the views, ``C`` channels, float32 linear
radiance. ``spacing`` is the distance between neighbouring cameras (world
units; depths use the same units) and ``focal_px`` the views' focal
length in pixels.

Refocus parameters (all equivalent):

- **slope** ``s``: the shift in pixels per view step. Refocusing at ``s``
  averages view ``(u, v)`` sampled at ``x - s (v - vc), y - s (u - uc)``;
  a point of disparity ``d`` (it appears at ``x - d (v - vc)`` in view
  ``(u, v)``, the HCI convention) is sharp when ``s = d``.
- **depth** ``Z``: ``s = focal_px * spacing / Z``.
- **Ng's alpha** (reference eq. 5.9, virtual sensor at ``alpha F``):
  ``s = alpha_scale (1 - 1/alpha)`` where ``alpha_scale = du/dx`` is the
  directional sample spacing over the spatial one, both on the sensor. For a
  plenoptic camera whose microimages span the N views (matched f-numbers) this
  is ``N``, our default, ``max(U, V)``. Ng's range of exact refocusing,
  ``|1 - 1/alpha| <= dx/du``, is then ``|s| <= 1``: beyond it the views are
  more than a pixel apart and the refocused image aliases.

Folder format: ``view-UU-VV.exr`` (float32, row-major) and ``lightfield.json``
(grid, spacing, focal_px, alpha_scale, view names), written last so its
presence means the folder is complete.

Examples
--------
>>> import numpy as np
>>> lf = LightField(np.zeros((3, 5, 4, 6, 3), np.float32), spacing=0.1, focal_px=50.0)
>>> lf.grid, lf.size, lf.slope_from_depth(5.0), lf.slope_from_alpha(2.0)
((3, 5), (6, 4), 1.0, 2.5)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError

SCHEMA = "lumigraph.lightfield"


@dataclass(frozen=True)
class LightField:
    """A 4-D light field ``(U, V, H, W, C)`` float32 linear, with its geometry.

    Parameters
    ----------
    data : ndarray, (U, V, H, W, C) or (U, V, H, W)
        Views; converted to float32 (a 4-D array gets C = 1).
    spacing : float
        Camera spacing (world units), > 0.
    focal_px : float, optional
        Focal length of the views in pixels (needed for depth <-> slope).
    alpha_scale : float, optional
        ``du/dx`` for Ng's alpha; default ``max(U, V)``.
    info : dict
        Provenance (source files, decoder figures).
    """

    data: np.ndarray
    spacing: float = 1.0
    focal_px: float | None = None
    alpha_scale: float | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        d = np.asarray(self.data)
        if d.ndim == 4:
            d = d[..., None]
        if d.ndim != 5:
            raise ValueError(f"data: expected (U, V, H, W, C), got shape {np.shape(self.data)}")
        if d.shape[0] * d.shape[1] < 2:
            raise ValueError(f"data: a light field needs at least 2 views, got {d.shape[:2]}")
        if d.dtype != np.float32:
            d = d.astype(np.float32)
        object.__setattr__(self, "data", d)
        _check_geometry(spacing=self.spacing, focal_px=self.focal_px)
        if self.alpha_scale is None:
            object.__setattr__(self, "alpha_scale", float(max(d.shape[:2])))
        elif not self.alpha_scale > 0:
            raise ValueError(f"alpha_scale: expected > 0, got {self.alpha_scale}")

    @property
    def grid(self) -> tuple[int, int]:
        """(U, V): rows and columns of views."""
        return int(self.data.shape[0]), int(self.data.shape[1])

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) of each view."""
        return int(self.data.shape[3]), int(self.data.shape[2])

    @property
    def center(self) -> tuple[float, float]:
        """(uc, vc): the grid centre in view indices."""
        return (self.data.shape[0] - 1) / 2, (self.data.shape[1] - 1) / 2

    def slope_from_depth(self, depth: float) -> float:
        """Slope (px per view step) that focuses at ``depth`` (units of spacing)."""
        if self.focal_px is None:
            raise InputError("depth", "the light field has no focal_px to turn a depth into a "
                                      "slope; import it with its focal length or refocus by slope")
        if not depth > 0:
            raise InputError("depth", f"depth must be positive, got {depth}")
        return float(self.focal_px * self.spacing / depth)

    def slope_from_alpha(self, alpha: float) -> float:
        """Slope of Ng's alpha: ``alpha_scale (1 - 1/alpha)``."""
        if not alpha > 0:
            raise InputError("alpha", f"alpha must be positive, got {alpha}")
        return float(self.alpha_scale * (1.0 - 1.0 / alpha))

    def alpha_from_slope(self, slope: float) -> float:
        """Inverse of :meth:`slope_from_alpha` (inf at ``slope = alpha_scale``)."""
        den = 1.0 - slope / self.alpha_scale
        return float("inf") if den == 0 else float(1.0 / den)

    def alpha_range(self) -> tuple[float, float]:
        """Ng's exact refocusing range of alpha, ``|1 - 1/alpha| <= dx/du``."""
        k = 1.0 / self.alpha_scale
        return 1.0 / (1.0 + k), (float("inf") if k >= 1 else 1.0 / (1.0 - k))

    def to_dict(self) -> dict:
        u, v = self.grid
        return {"schema": SCHEMA, "schema_version": 1, "grid": [u, v], "size": list(self.size),
                "channels": int(self.data.shape[4]), "spacing": float(self.spacing),
                "focal_px": self.focal_px, "alpha_scale": float(self.alpha_scale),
                "views": [view_name(i, j) for i in range(u) for j in range(v)],
                "order": "row-major: view-UU-VV, U = row (y), V = column (x)",
                "info": self.info}

    def save(self, folder: str | os.PathLike, *, meta: dict | None = None) -> Path:
        """Write the views (EXR float32) and ``lightfield.json`` (last)."""
        from lumigraph.capture.artifact import make_meta, write_artifact, write_json
        from lumigraph.capture.io import write_exr

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        u, v = self.grid
        for i in range(u):
            for j in range(v):
                img = self.data[i, j]
                write_exr(folder / view_name(i, j), img[..., 0] if img.shape[2] == 1 else img)
        body = self.to_dict()
        write_artifact(folder / "lightfield.json", lambda p: write_json(p, body),
                       meta=meta or make_meta(SCHEMA, params={"grid": [u, v]}))
        return folder

    @classmethod
    def load(cls, folder: str | os.PathLike) -> LightField:
        """Read a folder written by :meth:`save` (or its ``lightfield.json``).

        Raises
        ------
        InputError
            Naming ``lightfield.json`` and the key at fault (:func:`read_lightfield_json`),
            or a view that is missing, unreadable or of another size.
        """
        from lumigraph.capture.io import read_exr

        folder = Path(folder)
        js = folder / "lightfield.json" if folder.is_dir() else folder
        if not js.exists():
            raise InputError(folder, "not a light-field folder (no lightfield.json); make one "
                                     "with 'lumigraph lightfield import' or 'decode'")
        body = read_lightfield_json(js)
        (u, v), names = body["grid"], body["views"]
        for i, n in enumerate(names):
            if not (js.parent / n).is_file():
                raise InputError(js, f"key 'views[{i}]': {n} is not a file in {js.parent}")
        views = []
        for n in names:
            img = read_exr(js.parent / n)
            views.append(img[..., None] if img.ndim == 2 else img)
            if views[-1].shape != views[0].shape:
                raise InputError(js.parent / n, f"size {views[-1].shape} differs from "
                                                f"{names[0]} {views[0].shape}")
            check_finite_view(views[-1], js.parent / n)
        h, w, c = views[0].shape
        for key, found in (("size", [w, h]), ("channels", c)):
            if key in body and body[key] != found:
                raise InputError(js, f"key '{key}': the file says {body[key]}, but the views are "
                                     f"{w}x{h} with {c} channels")
        data = np.stack(views).reshape(u, v, *views[0].shape)
        return cls(data, spacing=body["spacing"], focal_px=body["focal_px"],
                   alpha_scale=body["alpha_scale"], info=body["info"])


def read_lightfield_json(path: str | os.PathLike) -> dict:
    """Read and check ``lightfield.json``: the one parser of its keys.

    Returns the body with ``grid`` ``[U, V]`` (positive integers, at least 2
    views), ``views`` (``U * V`` file names), ``spacing`` (positive, default
    1), ``focal_px`` and ``alpha_scale`` (positive or None), ``info`` (an
    object) filled in; ``size`` ``[W, H]`` and ``channels``, when present,
    are positive integers.

    Raises
    ------
    InputError
        Naming the file and the key at fault.
    """
    from lumigraph.capture.artifact import load_json_artifact
    from lumigraph.capture.schema import fail, require

    body = load_json_artifact(path, "light-field description", schemas=(SCHEMA,))
    u, v = require(body, "grid", "list", length=2, items="integer", low=1, path=path)
    if u * v < 2:
        raise fail(path, "grid", f"a light field needs at least 2 views, got a {u}x{v} grid")
    names = require(body, "views", "list", items="file name", path=path)
    if len(names) != u * v:
        raise fail(path, "views", f"{len(names)} views listed for a {u}x{v} grid")
    out = dict(body, grid=[u, v], views=names,
               spacing=require(body, "spacing", "number", above=0, default=1.0, path=path),
               focal_px=require(body, "focal_px", "number", above=0, nullable=True,
                                default=None, path=path),
               alpha_scale=require(body, "alpha_scale", "number", above=0, nullable=True,
                                   default=None, path=path),
               info=require(body, "info", "object", default={}, path=path))
    if "size" in body:
        out["size"] = require(body, "size", "list", length=2, items="integer", low=1, path=path)
    if "channels" in body:
        out["channels"] = require(body, "channels", "integer", low=1, path=path)
    return out


def check_finite_view(view: np.ndarray, where) -> None:
    """Refuse a view holding NaN or infinity (``InputError`` naming ``where``,
    its file): one such sample spreads through every refocused pixel and
    every disparity cost it enters.

    >>> check_finite_view(np.array([[0.5, np.nan]]), "view-00-01.exr")
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: view-00-01.exr: 1 of 2 samples are not finite (NaN or inf); a light field's views must hold finite radiance
    """
    if view.dtype.kind == "f":
        bad = int(np.count_nonzero(~np.isfinite(view)))
        if bad:
            raise InputError(where, f"{bad} of {view.size} samples are not finite (NaN or inf); "
                                    "a light field's views must hold finite radiance")


def view_name(u: int, v: int) -> str:
    """File name of view (u, v): ``view-UU-VV.exr``."""
    return f"view-{u:02d}-{v:02d}.exr"


def srgb_to_linear(codes: np.ndarray) -> np.ndarray:
    """Decode sRGB code values (uint8/uint16) to linear float32 in [0, 1] (IEC 61966-2-1).

    >>> srgb_to_linear(np.array([0, 255], np.uint8)).tolist()
    [0.0, 1.0]
    """
    top = 255.0 if codes.dtype == np.uint8 else 65535.0
    a = codes.astype(np.float64) / top
    return np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _check_geometry(*, spacing, focal_px):
    if not (np.isfinite(spacing) and spacing > 0):
        raise InputError("spacing", f"expected a positive number, got {spacing}")
    if focal_px is not None and not (np.isfinite(focal_px) and focal_px > 0):
        raise InputError("focal_px", f"expected a positive number, got {focal_px}")


def check_from_images(n_images: int, *, grid: tuple[int, int], spacing: float,
                      focal_px: float | None = None) -> None:
    """The checks of :func:`from_images` that need no pixels, for a caller
    that has not read the ``n_images`` views yet: ``spacing`` and
    ``focal_px`` finite and positive, one view per grid node.

    Raises
    ------
    InputError
        Naming ``spacing``, ``focal_px`` or ``grid``.

    Examples
    --------
    >>> check_from_images(6, grid=(2, 3), spacing=0.05, focal_px=800)
    >>> check_from_images(5, grid=(2, 3), spacing=0.05)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: grid: a 2x3 grid needs 6 images, got 5
    """
    _check_geometry(spacing=spacing, focal_px=focal_px)
    u, v = grid
    if n_images != u * v:
        raise InputError("grid", f"a {u}x{v} grid needs {u * v} images, got {n_images}")


def from_images(images, *, grid: tuple[int, int], spacing: float, focal_px: float | None = None,
                linear: bool = False, bit_depth: int | None = None, names=None) -> LightField:
    """Build a light field from row-major views (a list of (H, W[, C]) arrays).

    Integer views are sRGB-decoded to linear radiance unless ``linear``, in
    which case codes are divided by ``2**bit_depth - 1``. ``spacing`` and
    ``focal_px`` must be finite and positive. Raises InputError naming the
    argument (:func:`check_from_images`), or the view when sizes differ or
    a float view holds NaN or infinity (:func:`check_finite_view`).
    """
    u, v = grid
    names = list(names) if names is not None else [f"view {k}" for k in range(len(images))]
    check_from_images(len(images), grid=grid, spacing=spacing, focal_px=focal_px)
    out = []
    for img, name in zip(images, names, strict=True):
        img = img[..., None] if img.ndim == 2 else img[..., :3]
        if out and img.shape != out[0].shape:
            raise InputError(name, f"is {img.shape[1]}x{img.shape[0]}x{img.shape[2]}, but "
                                   f"{names[0]} is {out[0].shape[1]}x{out[0].shape[0]}x"
                                   f"{out[0].shape[2]}; all views need one size")
        if img.dtype.kind == "f":
            check_finite_view(img, name)
            lin = img.astype(np.float32)
        elif linear:
            top = 2 ** (bit_depth or 8 * img.dtype.itemsize) - 1
            lin = (img.astype(np.float64) / top).astype(np.float32)
        else:
            lin = srgb_to_linear(img)
        out.append(lin)
    data = np.stack(out).reshape(u, v, *out[0].shape)
    return LightField(data, spacing=spacing, focal_px=focal_px)
