"""Decoding plenoptic (lenslet) raws into sub-aperture views (reference §5.4.5, Fig. 5.24).

A plenoptic camera puts a microlens array in front of the sensor: each
microlens images the main-lens aperture onto the pixels behind it, so the
pixel at offset ``delta`` from a microlens centre records the ray through the
sub-aperture at ``delta``. Collecting, for one offset, the pixel under every
microlens gives one sub-aperture image (Ng et al. 2005, "Light Field
Photography with a Hand-held Plenoptic Camera", Stanford CTSR 2005-02).

Decoding (the white image is the camera looking at a uniform white field):

1. :func:`estimate_grid`: microimage centroids of the white image; nearest
   neighbours give the pitch, whether the grid is square (4 neighbours) or
   hexagonal (6), and the rotation (circular mean of the neighbour directions
   mod 90 or 60 degrees); every centroid gets integer lattice indices and the
   lattice (origin and 2x2 basis) is fitted to all of them by least squares,
   so each centre is known far better than any one centroid.
2. :func:`devignette`: raw / white, per pixel.
3. :func:`slice_views`: for view ``(u, v)`` sample, under each microlens, the
   point ``centre + R ((v - vc) q, (u - uc) q)`` (``q`` = microimage width /
   number of views, ``R`` the grid rotation) by bilinear interpolation.
4. :func:`hex_to_rect`: hexagonal grids give rows offset by half a lenslet and
   spaced sqrt(3)/2 apart; resample onto a square grid of unit spacing (cubic
   spline along rows, then along columns).

Examples
--------
>>> import numpy as np
>>> from lumigraph.capture.render import render
>>> s = render("lightfield-lenslet", size=(12, 10), cache=False)
>>> g = estimate_grid(s.images[1])
>>> g.lattice, round(g.pitch_px, 1), (g.rows, g.cols)
('square', 22.4, (10, 12))
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.lightfield.field import LightField

MIN_VIEWS = 2  # views per microimage side: a light field has at least 2

SQRT3_2 = math.sqrt(3.0) / 2.0


@dataclass(frozen=True)
class LensletGrid:
    """A microlens grid on the sensor.

    Centre of lenslet (row i, column j):
    ``origin + basis @ (j + odd_shift * (i mod 2), i)`` in sensor px (x, y).
    Square: ``basis = pitch R``; hexagonal: ``pitch R diag(1, sqrt(3)/2)``.

    Attributes
    ----------
    origin : (2,) float64; basis : (2, 2) float64 (columns: column step, row step)
    lattice : "square" or "hex"; odd_shift : 0 or +-0.5 (hex rows)
    rows, cols : int (complete microimages); extent_px : width of the lit
    square under each microlens; residual_px : RMS centroid-to-lattice distance.
    """

    origin: np.ndarray
    basis: np.ndarray
    lattice: str
    odd_shift: float
    rows: int
    cols: int
    extent_px: float
    residual_px: float

    def __post_init__(self):
        if self.lattice not in ("square", "hex"):
            raise ValueError(f"lattice: expected 'square' or 'hex', got {self.lattice!r}")
        if np.shape(self.basis) != (2, 2) or np.shape(self.origin) != (2,):
            raise ValueError("basis: expected (2, 2) and origin (2,)")

    @property
    def pitch_px(self) -> float:
        return float(np.linalg.norm(self.basis[:, 0]))

    @property
    def rotation_deg(self) -> float:
        return float(math.degrees(math.atan2(self.basis[1, 0], self.basis[0, 0])))

    def centers(self) -> np.ndarray:
        """(rows, cols, 2) sensor px (x, y) of every microlens centre."""
        i, j = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        a = np.stack([j + self.odd_shift * (i % 2), i], -1).astype(float)
        return a @ self.basis.T + self.origin

    def to_dict(self) -> dict:
        return {"origin_px": self.origin.tolist(), "basis_px": self.basis.tolist(),
                "lattice": self.lattice, "odd_shift": self.odd_shift, "rows": self.rows,
                "cols": self.cols, "pitch_px": self.pitch_px, "rotation_deg": self.rotation_deg,
                "extent_px": self.extent_px, "residual_px": self.residual_px}


def _gray(img: np.ndarray) -> np.ndarray:
    a = img.astype(np.float64)
    return a.mean(-1) if a.ndim == 3 else a


def estimate_grid(white: np.ndarray, *, lattice: str = "auto") -> LensletGrid:
    """Fit the microlens grid to a white image.

    Parameters
    ----------
    white : ndarray (H, W[, C])
        White image (any dtype; linear).
    lattice : {"auto", "square", "hex"}

    Returns
    -------
    LensletGrid

    Raises
    ------
    EstimationError
        Too few microimages, or neighbour distances without a lattice.
    """
    from scipy import ndimage
    from scipy.spatial import cKDTree

    if lattice not in ("auto", "square", "hex"):
        raise ValueError(f"lattice: expected auto, square or hex, got {lattice!r}")
    g = _gray(white)
    if g.max() <= 0:
        raise EstimationError("white", "the white image is black")
    g = g / g.max()
    lit = g > 0.25
    labels, n = ndimage.label(lit)
    if n < 9:
        raise EstimationError("white", f"found {n} microimages; need at least 9")
    idx = np.arange(1, n + 1)
    area = ndimage.sum(lit, labels, idx)
    cen = np.array(ndimage.center_of_mass(g, labels, idx))[:, ::-1]   # (x, y)
    sl = ndimage.find_objects(labels)
    h, w = g.shape
    med = np.median(area)
    keep = (area > 0.7 * med) & (area < 1.3 * med)
    keep &= np.array([s[0].start > 0 and s[1].start > 0 and s[0].stop < h and s[1].stop < w
                      for s in sl])
    cen = cen[keep]
    if len(cen) < 9:
        raise EstimationError("white", f"only {len(cen)} complete microimages; need at least 9")
    extent = math.sqrt(float(np.median(area[keep])))
    tree = cKDTree(cen)
    d, nb = tree.query(cen, k=min(7, len(cen)))
    pitch0 = float(np.median(d[:, 1]))
    close = (d[:, 1:] < 1.2 * pitch0) & (d[:, 1:] > 0.8 * pitch0)
    count = np.median(close.sum(1))
    pitch0 = float(np.median(d[:, 1:][close]))     # all neighbours: the nearest is biased low
    if lattice == "auto":
        lattice = "hex" if count >= 5 else "square"
    sym = 6 if lattice == "hex" else 4
    vec = cen[nb[:, 1:]] - cen[:, None, :]
    ang = np.arctan2(vec[..., 1], vec[..., 0])[close]
    theta = float(np.angle(np.exp(1j * sym * ang).mean()) / sym)
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    ref = cen[np.argmin(((cen - [w / 2, h / 2]) ** 2).sum(1))]
    q = (cen - ref) @ rot / pitch0                  # lattice frame, pitch units
    ry = SQRT3_2 if lattice == "hex" else 1.0
    i = np.round(q[:, 1] / ry).astype(int)
    i -= i.min()
    odd_shift = 0.0
    even = i % 2 == 0
    xe = q[even, 0].min()
    if lattice == "hex":
        # Rows are half a pitch apart in x; the convention (+1/2 or -1/2 for
        # odd rows) is whichever keeps every column index >= 0.
        odd_shift = 0.5 if q[~even, 0].min() - xe > 0 else -0.5
    j = np.round(q[:, 0] - xe - odd_shift * (i % 2)).astype(int)
    j -= j.min()
    for _ in range(3):   # refit, re-index from the fit (pitch errors add up across the sensor)
        a = np.stack([j + odd_shift * (i % 2), i, np.ones_like(i)], -1).astype(float)
        sol, *_ = np.linalg.lstsq(a, cen, rcond=None)
        basis, origin = sol[:2].T, sol[2]
        fi = np.linalg.solve(basis, (cen - origin).T).T      # (column-ish, row)
        i = np.round(fi[:, 1]).astype(int)
        if lattice == "hex" and i.min() % 2:   # top row must be row 0: swap the parity
            fi[:, 0] -= odd_shift
            odd_shift = -odd_shift
        i -= i.min()
        j = np.round(fi[:, 0] - odd_shift * (i % 2)).astype(int)
        j -= j.min()
    a = np.stack([j + odd_shift * (i % 2), i, np.ones_like(i)], -1).astype(float)
    sol, *_ = np.linalg.lstsq(a, cen, rcond=None)
    basis, origin = sol[:2].T, sol[2]
    resid = float(np.sqrt(((a @ sol - cen) ** 2).sum(1).mean()))
    if resid > 0.25 * pitch0:
        raise EstimationError("white", f"centroids do not form a {lattice} lattice "
                                       f"(RMS residual {resid:.2f} px)")
    rows, cols = int(i.max()) + 1, int(j.max()) + 1
    return LensletGrid(origin, basis, lattice, odd_shift, rows, cols, extent, resid)


def devignette(raw: np.ndarray, white: np.ndarray, *, floor: float = 0.05) -> np.ndarray:
    """raw / white (per pixel; 0 where white < ``floor`` of its max), float32 (H, W, C)."""
    r = raw.astype(np.float64)
    wt = _gray(white)
    wt = wt / wt.max()
    if r.ndim == 2:
        r = r[..., None]
    scale = float(np.iinfo(white.dtype).max if white.dtype.kind in "ui" else 1.0)
    wmax = float(_gray(white).max()) / scale
    out = np.where(wt[..., None] > floor, r / np.maximum(wt[..., None], floor), 0.0)
    if raw.dtype.kind in "ui":
        out = out / (wmax * float(np.iinfo(raw.dtype).max))
    return out.astype(np.float32)


def slice_views(image: np.ndarray, grid: LensletGrid, views: int) -> np.ndarray:
    """Sub-aperture views (N, N, rows, cols, C) float32 of a devignetted raw."""
    from scipy.ndimage import map_coordinates

    q = grid.extent_px / views
    c = grid.centers()
    rot = grid.basis[:, 0] / np.linalg.norm(grid.basis[:, 0])
    rmat = np.array([[rot[0], -rot[1]], [rot[1], rot[0]]])
    off = (np.arange(views) - (views - 1) / 2) * q
    dv, du = np.meshgrid(off, off)                         # (u, v)
    d = np.stack([dv, du], -1) @ rmat.T                    # (N, N, 2) sensor offsets
    pts = c[None, None] + d[:, :, None, None, :]           # (N, N, rows, cols, 2)
    out = np.stack([map_coordinates(image[..., k], [pts[..., 1], pts[..., 0]], order=1,
                                    mode="constant") for k in range(image.shape[2])], -1)
    return out.astype(np.float32)


def hex_to_rect(views: np.ndarray, grid: LensletGrid) -> np.ndarray:
    """Resample hexagonally sampled views onto a square grid of unit spacing.

    Row i of a hex view holds samples at ``x = j + odd_shift (i mod 2)``,
    ``y = i sqrt(3)/2``. The output holds ``x = j + max(odd_shift, 0)`` for
    ``j < cols - 1`` and ``y = k`` for ``k <= (rows - 1) sqrt(3)/2``: inside
    the samples of every row, so nothing is extrapolated. Cubic B-spline
    interpolation along rows (half-lenslet shift), then along columns.
    (N, N, Hr, cols - 1, C) float32.
    """
    from scipy.ndimage import spline_filter1d

    n1, n2, rows, cols, c = views.shape
    hr = int(math.floor((rows - 1) * SQRT3_2)) + 1
    x_out = np.arange(cols - 1) + max(grid.odd_shift, 0.0)
    v = spline_filter1d(views.astype(np.float64), 3, axis=3, mode="reflect")
    aligned = np.empty((n1, n2, rows, cols - 1, c))
    for i in range(rows):
        pos = x_out - grid.odd_shift * (i % 2)          # sample index within row i
        aligned[:, :, i] = _spline_rows(v[:, :, i], pos)
    a = spline_filter1d(aligned, 3, axis=2, mode="reflect")
    out = _spline_rows(a, np.arange(hr) / SQRT3_2)
    return out.astype(np.float32)


def _spline_rows(coef: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Evaluate cubic B-spline coefficients along axis 2 of (N, N, L, ...) at
    ``pos`` (mirror-extended coefficients); returns (N, N, len(pos), ...)."""
    n = coef.shape[2]
    base = np.floor(pos).astype(int)
    t = pos - base
    out = 0.0
    for k in range(-1, 3):
        d = np.abs(k - t)
        w = np.where(d < 1, 2 / 3 - d ** 2 + d ** 3 / 2, np.where(d < 2, (2 - d) ** 3 / 6, 0.0))
        idx = base + k
        idx = np.where(idx < 0, -idx - 1, np.where(idx >= n, 2 * n - idx - 1, idx))
        out = out + coef[:, :, idx] * w.reshape((1, 1, -1) + (1,) * (coef.ndim - 3))
    return out


@dataclass(frozen=True)
class LensletDecode:
    """A decoded lenslet raw: the light field and the grid it was sliced with."""

    lightfield: LightField
    grid: LensletGrid


def decode(raw: np.ndarray, white: np.ndarray, *, views: int | None = None,
           lattice: str = "auto", grid: LensletGrid | None = None) -> LensletDecode:
    """Decode a lenslet raw into a light field of sub-aperture views.

    Parameters
    ----------
    raw, white : ndarray (H, W[, C])
        Raw and white images, same size, linear codes or floats.
    views : int, optional
        Views per microimage side, ``MIN_VIEWS`` up to one per pixel of the
        lit square (the default); more is refused (``InputError`` naming
        ``views``) before any view is sliced.
    lattice : {"auto", "square", "hex"}
    grid : LensletGrid, optional
        Use this grid instead of estimating it (e.g. the ground truth).

    Returns
    -------
    LensletDecode
        ``lightfield`` (N, N, H, W, C) float32 with spacing 1 (view steps);
        hexagonal grids are resampled onto a square grid.
    """
    if raw.shape[:2] != white.shape[:2]:
        raise ValueError(f"white: size {white.shape[:2]} differs from raw {raw.shape[:2]}")
    if views is not None and (isinstance(views, bool) or not isinstance(views, int | np.integer)
                              or views < MIN_VIEWS):
        raise InputError("views", f"expected an integer >= {MIN_VIEWS} views per microimage side, "
                                  f"got {views!r}")
    g = grid if grid is not None else estimate_grid(white, lattice=lattice)
    most = max(MIN_VIEWS, int(math.floor(g.extent_px)))
    if views is not None and views > most:
        # more views than pixels under a lenslet resample nothing new (and a
        # thousand would allocate N² views of the sensor: refused before that)
        raise InputError("views", f"{views} views per side, but the white image's microimages "
                                  f"are {g.extent_px:.1f} px wide (lenslet pitch {g.pitch_px:.1f} "
                                  f"px): at most {most}")
    n = int(views) if views is not None else most
    lin = devignette(raw, white)
    v = slice_views(lin, g, n)
    if g.lattice == "hex":
        v = hex_to_rect(v, g)
    return LensletDecode(LightField(v, spacing=1.0, info={"lenslet_grid": g.to_dict()}), g)
