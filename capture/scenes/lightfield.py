"""Light fields with exact ground truth (scene family 4): camera arrays,
synthetic-aperture and thin-lens refocus truth, plenoptic (lenslet) raws.

The world is a stack of textured fronto-parallel planes (nearest first); every
plane but the farthest is a rectangle, so nearer planes occlude farther ones.
A plane's texture is a continuous function: the cubic B-spline interpolant of a
scikit-image picture (sRGB decoded to linear radiance). A pixel is the box
average of the composited image over its 1x1 footprint (centres at integer
coordinates). Because a fronto-parallel plane maps to the image by a separable
affine map, and the occlusion masks are axis-aligned rectangles, a pixel value
is a sum of separable terms (inclusion-exclusion over the nearer rectangles),
each ``By @ C @ Bx.T`` with ``Bx[x, i]`` the *exact* integral of the B-spline
``beta3(t - i)`` over the part of pixel ``x`` a term covers (closed form: the
B-spline's antiderivative). No resampling, no supersampling error.

Cameras ``(u, v)`` (row, column) of a ``U x V`` array sit at
``((v - vc) * spacing, (u - uc) * spacing, 0)``, all looking down +z with focal
length ``focal_px`` and the principal point at the image centre. A point at
depth ``Z`` has disparity ``d = focal_px * spacing / Z`` px per view step and
appears in view ``(u, v)`` at ``x - d (v - vc), y - d (u - uc)`` (the HCI
light-field convention). Refocusing at slope ``s`` averages the views sampled
at ``x - s (v - vc), y - s (u - uc)`` (shift-and-add, reference eq. 5.9).

Because each term is bilinear in ``By`` and ``Bx``, averaging views over a
product grid of camera positions equals ``mean(By) @ C @ mean(Bx).T``: the
exact synthetic-aperture image (the average of the ``U x V`` views, each
rendered analytically at its subpixel shift) and the thin-lens image (the same
average over the continuous square aperture spanning the array's cells,
integrated by a 256-point midpoint rule per axis) cost little more than one
view.

The lenslet raw models a plenoptic camera (reference §5.4.5, Fig. 5.24): a
square or hexagonal microlens grid, rotated by a small angle, with subpixel
origin; under each microlens an ``N x N`` mosaic of square cells,
``view_step_px`` wide, each cell recording the ray of one sub-aperture view
(the GT views, rendered at the lenslet lattice positions); vignetting inside
each microimage and across the sensor; dark outside the cells. The white image
is the same optics looking at a uniform white field, so raw / white recovers
the views exactly at every cell's pixels.

Examples
--------
>>> s = render_array(size=(32, 24), seed=0, rng=np.random.default_rng(0), grid="3x3",
...                  thin_lens=False)
>>> s.gt_arrays["views"].shape, len(s.images), s.stack["lightfield"]["grid"]
((3, 3, 24, 32, 3), 9, [3, 3])
"""

from __future__ import annotations

import contextlib
import itertools
import math
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import Option, RenderedScene, SceneSpec

TEXTURES = ("astronaut", "coffee", "rocket", "chelsea")
THIN_LENS_SAMPLES = 256  # midpoint rule per aperture axis


def parse_grid(text: str, *, name: str = "grid") -> tuple[int, int]:
    """``"5x7"`` -> ``(5, 7)`` = (U rows, V columns) of a camera grid.

    >>> parse_grid("2x9")
    (2, 9)
    """
    try:
        u, v = (int(t) for t in str(text).lower().split("x"))
    except ValueError:
        raise InputError(name, f"expected ROWSxCOLS such as 5x5, got {text!r}") from None
    if u < 1 or v < 1 or u * v < 2 or u > 64 or v > 64:
        raise InputError(name, f"grid {u}x{v} is impossible: 1..64 per side, at least 2 views")
    return u, v


def _bspline_integral(t: np.ndarray) -> np.ndarray:
    """Antiderivative of the centred cubic B-spline: 0 for t <= -2, 1 for t >= 2."""
    t = np.clip(t, -2.0, 2.0)
    out = np.zeros_like(t)
    for k, c in enumerate((1.0, -4.0, 6.0, -4.0, 1.0)):
        out += c * np.maximum(t + 2.0 - k, 0.0) ** 4
    return out / 24.0


def _srgb_to_linear(img: np.ndarray) -> np.ndarray:
    a = img.astype(np.float64) / 255.0
    return np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4)


@dataclass(frozen=True)
class Plane:
    """A textured fronto-parallel plane at ``depth`` (world units).

    ``coef`` (Ny, Nx, 3) are cubic B-spline coefficients; texel ``(i, j)`` is
    centred at world ``(x0 + j * texel, y0 + i * texel)``. ``rect`` is the
    plane's extent ``(X0, X1, Y0, Y1)`` in world units, or None (infinite).
    """

    depth: float
    coef: np.ndarray
    texel: float
    x0: float
    y0: float
    rect: tuple[float, float, float, float] | None


class OutsideScene(ValueError):
    """A camera (or a refocus shift) the scene's textures do not cover: the
    options asked for a view the generator cannot render exactly."""


def _axis_weights(p, cam, plane_offset, zrel, f, pp, texel, n_tex, lo_clip, hi_clip):
    """Sparse (N, n_tex): mean over cameras of the exact mean of beta3(t - i)
    over each pixel's clipped footprint.

    ``p`` (n, N) pixel centres seen from camera positions ``cam`` (n,); the
    footprint ``[p - 1/2, p + 1/2]`` is clipped to ``[lo_clip, hi_clip]`` (n,)
    (pixel units); t(x) = (cam + zrel (x - pp)/f - x0)/texel.
    """
    from scipy.sparse import csr_matrix

    a = zrel / (f * texel)
    b = ((cam - zrel * pp / f - plane_offset) / texel)[:, None]
    lo = np.maximum(p - 0.5, lo_clip[:, None])
    hi = np.minimum(p + 0.5, hi_clip[:, None])
    ok = hi > lo
    ta, tb = a * lo + b, a * hi + b
    k = int(math.ceil(a)) + 5
    i0 = np.floor(np.where(ok, ta, 0.0) - 2.0).astype(np.int64)
    idx = i0[..., None] + np.arange(k)                      # (n, N, k)
    w = (_bspline_integral(tb[..., None] - idx) - _bspline_integral(ta[..., None] - idx)) / a
    w[~ok] = 0.0
    used = w != 0.0
    if used.any() and (idx[used].min() < 0 or idx[used].max() >= n_tex):
        raise OutsideScene("texture too small for this camera position (render within the slab)")
    idx = np.clip(idx, 0, n_tex - 1)
    n, npx = p.shape
    w = np.moveaxis(w, 0, 1).reshape(npx, n * k) / n
    idx = np.moveaxis(idx, 0, 1).reshape(npx, n * k)
    m = csr_matrix((w.ravel(), idx.ravel(), np.arange(0, npx * n * k + 1, n * k)),
                   shape=(npx, n_tex))
    m.sum_duplicates()
    return m


@dataclass(frozen=True)
class PlaneScene:
    """Planes (nearest first) seen by pinhole cameras with focal ``f`` and
    principal point ``(ppx, ppy)``."""

    planes: tuple[Plane, ...]
    f: float
    ppx: float
    ppy: float

    def render(self, cams_x, xs, cams_y, ys, cam_z: float = 0.0) -> np.ndarray:
        """Average over a product grid of camera positions of the exact pixel values.

        Parameters
        ----------
        cams_x : (n,) float
            Camera x positions (world units).
        xs : (n, W) float
            Pixel x positions sampled from the camera at ``cams_x[i]``.
        cams_y, ys : (m,), (m, H)
            The same along y.
        cam_z : float
            Camera z (world units); planes must stay in front.

        Returns
        -------
        ndarray, (H, W, 3) float64
            ``mean_{i, j}`` of the view from camera ``(cams_x[i], cams_y[j], cam_z)``
            sampled at ``(xs[i], ys[j])``.
        """
        cams_x, cams_y = np.atleast_1d(cams_x), np.atleast_1d(cams_y)
        xs, ys = np.atleast_2d(xs), np.atleast_2d(ys)
        out = np.zeros((ys.shape[1], xs.shape[1], 3))
        for k, plane in enumerate(self.planes):
            zrel = plane.depth - cam_z
            if zrel <= 0:
                raise OutsideScene(f"cam_z: plane at depth {plane.depth} is behind the camera")
            occluders = [j for j in range(k) if self.planes[j].rect is not None]
            for r in range(len(occluders) + 1):
                for subset in itertools.combinations(occluders, r):
                    rects = list(subset) + ([k] if plane.rect is not None else [])
                    bx = self._mean_weights(plane, zrel, cams_x, xs, self.ppx, rects, 0, cam_z)
                    by = self._mean_weights(plane, zrel, cams_y, ys, self.ppy, rects, 2, cam_z)
                    if bx is None or by is None:
                        continue
                    ny, nx, _ = plane.coef.shape
                    tmp = (by @ plane.coef.reshape(ny, nx * 3)).reshape(-1, nx, 3)
                    tmp = np.ascontiguousarray(tmp.transpose(1, 0, 2)).reshape(nx, -1)
                    term = (bx @ tmp).reshape(xs.shape[1], -1, 3).transpose(1, 0, 2)
                    if r % 2 == 0:
                        out += term
                    else:
                        out -= term
        return out

    def _mean_weights(self, plane, zrel, cams, ps, pp, rects, axis, cam_z):
        lo = np.full(len(cams), -np.inf)
        hi = np.full(len(cams), np.inf)
        for j in rects:
            q = self.planes[j]
            zj = q.depth - cam_z
            lo = np.maximum(lo, pp + self.f * (q.rect[axis] - cams) / zj)
            hi = np.minimum(hi, pp + self.f * (q.rect[axis + 1] - cams) / zj)
        if not (hi > lo).any():
            return None
        n_tex = plane.coef.shape[1 - axis // 2]
        offset = plane.x0 if axis == 0 else plane.y0
        return _axis_weights(ps, cams, offset, zrel, self.f, pp, plane.texel, n_tex, lo, hi)

    def depth_at(self, xs, ys, cam=(0.0, 0.0)) -> np.ndarray:
        """Depth of the nearest surface through each pixel centre, (H, W) float64."""
        x, y = np.meshgrid(xs, ys)
        depth = np.full(x.shape, np.inf)
        for plane in reversed(self.planes):
            wx = cam[0] + plane.depth * (x - self.ppx) / self.f
            wy = cam[1] + plane.depth * (y - self.ppy) / self.f
            inside = np.ones(x.shape, bool) if plane.rect is None else (
                (wx >= plane.rect[0]) & (wx < plane.rect[1]) & (wy >= plane.rect[2])
                & (wy < plane.rect[3]))
            depth[inside] = plane.depth
        return depth


def build_scene(rng, *, width, height, f, spacing, disparities, texel_px, reach,
                ppx=None, ppy=None) -> PlaneScene:
    """Planes at the given disparities (px per view step, nearest first).

    ``reach`` bounds the camera offsets the textures must support (world units).
    Rectangles are placed in the centre view's pixel frame: the nearest at the
    left, the next at the right, overlapping, so every pair of depths meets at
    an occlusion edge.
    """
    import skimage.data

    ppx = (width - 1) / 2 if ppx is None else ppx
    ppy = (height - 1) / 2 if ppy is None else ppy
    n = len(disparities)
    boxes = [(0.12, 0.52, 0.18, 0.66), (0.40, 0.88, 0.34, 0.92), (0.05, 0.60, 0.55, 0.95)]
    planes = []
    for k, d in enumerate(disparities):
        z = f * spacing / d
        texel = texel_px * z / f
        margin = reach + 4 * texel
        wx0 = -margin + z * (-3 - ppx) / f
        wx1 = margin + z * (width + 2 - ppx) / f
        wy0 = -margin + z * (-3 - ppy) / f
        wy1 = margin + z * (height + 2 - ppy) / f
        nx = int(math.ceil((wx1 - wx0) / texel)) + 6
        ny = int(math.ceil((wy1 - wy0) / texel)) + 6
        pic = _srgb_to_linear(getattr(skimage.data, TEXTURES[k % len(TEXTURES)])()[..., :3])
        reps = (int(math.ceil(ny / pic.shape[0])) + 1, int(math.ceil(nx / pic.shape[1])) + 1)
        tiled = np.tile(np.concatenate([pic, pic[::-1]], 0), (reps[0], 1, 1))
        tiled = np.tile(np.concatenate([tiled, tiled[:, ::-1]], 1), (1, reps[1], 1))
        oy = int(rng.integers(0, tiled.shape[0] - ny + 1))
        ox = int(rng.integers(0, tiled.shape[1] - nx + 1))
        tex = tiled[oy:oy + ny, ox:ox + nx]
        tex = 0.08 + 0.9 * tex * (0.75 + 0.25 * k / max(n - 1, 1))
        from scipy.ndimage import spline_filter

        coef = np.stack([spline_filter(tex[..., c], order=3, mode="mirror") for c in range(3)], -1)
        rect = None
        if k < n - 1:
            bx = boxes[k % len(boxes)]
            jitter = rng.uniform(-0.03, 0.03, 4)
            fx = np.array([bx[0], bx[1]]) + jitter[:2]
            fy = np.array([bx[2], bx[3]]) + jitter[2:]
            rect = (z * (fx[0] * width - ppx) / f, z * (fx[1] * width - ppx) / f,
                    z * (fy[0] * height - ppy) / f, z * (fy[1] * height - ppy) / f)
        planes.append(Plane(z, coef, texel, wx0, wy0, rect))
    return PlaneScene(tuple(planes), float(f), float(ppx), float(ppy))


def view_offsets(n: int) -> np.ndarray:
    """View-step offsets ``k - (n - 1)/2`` of an n-camera axis."""
    return np.arange(n) - (n - 1) / 2


def render_views(scene: PlaneScene, u: int, v: int, spacing: float, xs, ys) -> np.ndarray:
    """All views (U, V, H, W, 3) float64 of a U x V array at pixel positions xs, ys."""
    out = np.empty((u, v, len(ys), len(xs), 3))
    for i, ou in enumerate(view_offsets(u)):
        for j, ov in enumerate(view_offsets(v)):
            out[i, j] = scene.render(ov * spacing, xs, ou * spacing, ys)
    return out


def synthetic_aperture(scene: PlaneScene, u: int, v: int, spacing: float, slope: float,
                       width: int, height: int) -> np.ndarray:
    """The exact shift-and-add image: mean over the U x V views, view (u, v)
    rendered at ``x - slope (v - vc), y - slope (u - uc)`` (H, W, 3) float64."""
    ov, ou = view_offsets(v), view_offsets(u)
    xs = np.arange(width)[None, :] - slope * ov[:, None]
    ys = np.arange(height)[None, :] - slope * ou[:, None]
    return scene.render(ov * spacing, xs, ou * spacing, ys)


def thin_lens_image(scene: PlaneScene, u: int, v: int, spacing: float, slope: float,
              width: int, height: int, samples: int = THIN_LENS_SAMPLES) -> np.ndarray:
    """A thin lens focused at disparity ``slope`` whose square aperture spans the
    array's cells (``V * spacing`` by ``U * spacing``): the continuous aperture
    integral, by a ``samples``-point midpoint rule per axis (H, W, 3) float64."""
    av = (np.arange(samples) + 0.5) / samples * v - v / 2
    au = (np.arange(samples) + 0.5) / samples * u - u / 2
    xs = np.arange(width)[None, :] - slope * av[:, None]
    ys = np.arange(height)[None, :] - slope * au[:, None]
    return scene.render(av * spacing, xs, au * spacing, ys)


def _codes(radiance: np.ndarray, bits: int, noise: float, rng) -> np.ndarray:
    top = 2 ** bits - 1
    c = radiance * top
    if noise > 0:
        c = c + rng.normal(0.0, noise, c.shape)
    return np.clip(np.round(c), 0, top).astype(np.uint16)


@contextlib.contextmanager
def _refused(option: str, problem: str):
    """An :class:`OutsideScene` inside the block is the options' doing:
    InputError naming ``option``."""
    try:
        yield
    except OutsideScene:
        raise InputError(option, problem) from None


def render_array(*, size, seed, rng, grid="5x5", planes=3, disparity_near=1.0,
                 disparity_far=0.2, spacing=1.0, texel_px=1.5, focus=(), thin_lens=True,
                 novel=(0.5, 0.5, 0.0), noise=0.0, jitter_deg=0.0, jitter_pos=0.0):
    """A U x V camera-array light field of textured planes, with exact truth.

    With ``jitter_deg`` / ``jitter_pos`` the captured images come from a
    non-ideal rig: camera ``k`` is rotated by a random angle up to
    ``jitter_deg`` about a random axis and its centre moved in the array
    plane by up to ``jitter_pos`` grid steps per axis; ``stack.json`` and
    ``gt.json`` then carry ``lightfield.cameras`` (K, dist, image_size,
    ``cam_from_world`` R, t per view, row-major) and ``views`` stays the ideal
    array. A rotated view is exact at its centre (analytic render on a frame
    extended by a margin) resampled by the rotation homography
    ``K R^T K^-1`` with a cubic B-spline (the only approximation).

    Views are 16-bit linear PNGs ``view-UU-VV.png`` (row-major); ``stack.json``
    carries ``lightfield`` (grid, spacing, focal_px). Ground truth: ``views``
    (U, V, H, W, 3) float32 radiance, ``depth`` and ``disparity`` (H, W) of the
    centre view (nearest surface at each pixel centre; the centre view of an
    even grid is the virtual camera at the grid centre), ``synthetic_aperture``
    and (with ``thin_lens``) ``thin_lens`` (n, H, W, 3) at ``focus_slopes``;
    ``novel_view`` (H, W, 3): a pinhole at ``novel`` (view steps, relative to
    the grid centre; same intrinsics).
    """
    u, v = parse_grid(grid)
    w, h = size
    f = float(w)
    disp = np.linspace(disparity_near, disparity_far, planes) if planes > 1 else \
        np.array([disparity_near])
    reach = (max(u, v) / 2 + 1.5) * spacing
    jittered = jitter_deg > 0 or jitter_pos > 0
    margin = int(math.ceil(2 * f * math.tan(math.radians(jitter_deg)) + jitter_pos + 4)) \
        if jittered else 0
    if jittered:
        reach += margin * spacing / float(np.min(disp)) + jitter_pos * spacing
    scene = build_scene(rng, width=w, height=h, f=f, spacing=spacing, disparities=disp,
                        texel_px=texel_px, reach=reach)
    xs, ys = np.arange(w, dtype=float), np.arange(h, dtype=float)
    views = render_views(scene, u, v, spacing, xs, ys)
    slopes = [float(s) for s in focus] if focus else sorted(
        {float(x) for x in np.round(np.concatenate([disp, (disp[:-1] + disp[1:]) / 2]), 6)})
    # a refocus slope far from the planes' disparities shifts the views past
    # the textures (which cover the array's reach): refused, naming the option
    slope_opt = "focus" if focus else "disparity_near"
    with _refused(slope_opt, f"refocus slopes {slopes} shift the views beyond this scene's "
                             "textures; use slopes near the plane disparities, or disparities "
                             "closer together"):
        sa = np.stack([synthetic_aperture(scene, u, v, spacing, s, w, h) for s in slopes])
    depth = scene.depth_at(xs, ys)
    nx_, ny_, nz_ = (float(t) * spacing for t in novel)
    with _refused("novel", f"the novel view at {tuple(novel)} view steps is outside the scene "
                           "(behind a plane or beyond its textures); use a position within a few "
                           "view steps of the grid, in front of the planes"):
        novel_view = scene.render(nx_, xs, ny_, ys, cam_z=nz_)
    gt_arrays = {"novel_view": novel_view.astype(np.float32), "views": views.astype(np.float32),
                 "depth": depth.astype(np.float32),
                 "disparity": (f * spacing / depth).astype(np.float32),
                 "synthetic_aperture": sa.astype(np.float32)}
    if thin_lens:
        with _refused(slope_opt, f"thin-lens refocus at slopes {slopes} reaches beyond this "
                                 "scene's textures; use slopes near the plane disparities, or "
                                 "--thin-lens false"):
            gt_arrays["thin_lens"] = np.stack(
                [thin_lens_image(scene, u, v, spacing, s, w, h) for s in slopes]
            ).astype(np.float32)
    captured = views
    lf_cams = None
    if jittered:
        captured, lf_cams = _jittered_views(scene, u, v, spacing, w, h, f, margin, jitter_deg,
                                            jitter_pos, rng)
    codes = _codes(captured, 16, noise, rng)
    names = [f"view-{i:02d}-{j:02d}.png" for i in range(u) for j in range(v)]
    images = tuple(codes[i, j] for i in range(u) for j in range(v))
    lf = {"grid": [u, v], "spacing": spacing, "focal_px": f, "principal_point": [(w - 1) / 2,
                                                                                 (h - 1) / 2]}
    if lf_cams is not None:
        lf["cameras"] = lf_cams
    return RenderedScene(
        "lightfield-array", {}, images, tuple(names),
        stack={"bit_depth": 16, "linear": True, "exposure_times_s": [1.0] * len(names),
               "lightfield": lf},
        gt={**lf, "code_scale": 65535, "noise_sigma_codes": noise,
            "planes": [{"depth": p.depth, "disparity": f * spacing / p.depth,
                        "rect": list(p.rect) if p.rect else None} for p in scene.planes],
            "focus_slopes": slopes, "novel_position": [nx_, ny_, nz_],
            "thin_lens_aperture": [u * spacing, v * spacing],
            "thin_lens_samples_per_axis": THIN_LENS_SAMPLES,
            "slope_convention": "view (u, v) sees a point of disparity d at "
                                "x - d (v - vc), y - d (u - uc)"},
        gt_arrays=gt_arrays)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _jittered_views(scene, u, v, spacing, w, h, f, margin, jitter_deg, jitter_pos, rng):
    """Views (U, V, H, W, 3) float64 of rotated, displaced cameras and their
    camera.json-style descriptions (see :func:`render_array`)."""
    from scipy.ndimage import map_coordinates

    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    xs_e = np.arange(-margin, w + margin, dtype=float)
    ys_e = np.arange(-margin, h + margin, dtype=float)
    gx, gy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    pix = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    out = np.empty((u, v, h, w, 3))
    cams = []
    for i, ou in enumerate(view_offsets(u)):
        for j, ov in enumerate(view_offsets(v)):
            d = rng.uniform(-jitter_pos, jitter_pos, 2)
            centre = np.array([(ov + d[0]) * spacing, (ou + d[1]) * spacing, 0.0])
            R = _rotation(rng.normal(size=3), math.radians(rng.uniform(0, jitter_deg)))
            ideal = scene.render(centre[0], xs_e, centre[1], ys_e)
            # The rotated camera's pixel x_r sees what the unrotated camera at
            # the same centre sees at K R^T K^-1 x_r (depth-independent).
            q = K @ R.T @ np.linalg.inv(K) @ pix
            qx, qy = q[0] / q[2] + margin, q[1] / q[2] + margin
            for c in range(3):
                out[i, j, ..., c] = map_coordinates(ideal[..., c], [qy, qx], order=3,
                                                    mode="mirror").reshape(h, w)
            cams.append({"K": K.tolist(), "dist": [0.0] * 5, "image_size": [w, h],
                         "cam_from_world": {"R": R.tolist(), "t": (-R @ centre).tolist()}})
    return out, cams


# ----------------------------------------------------------------- lenslet raws
SQRT3_2 = math.sqrt(3.0) / 2.0


def lattice_positions(rows: int, cols: int, lattice: str, odd_shift: float = 0.5):
    """Lattice positions (rows, cols, 2) of microlenses in pitch units, (x, y):
    square ``(j, i)``; hexagonal ``(j + odd_shift (i mod 2), i sqrt(3)/2)``."""
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    if lattice == "hex":
        return np.stack([j + odd_shift * (i % 2), i * SQRT3_2], -1).astype(float)
    return np.stack([j, i], -1).astype(float)


def render_lenslet(*, size, seed, rng, lattice="square", views=5, pitch=22.4, rotation_deg=1.5,
                   view_step_px=3.0, planes=3, disparity_near=0.6, disparity_far=0.1,
                   texel_px=2.5, noise=0.0):
    """A plenoptic raw (12-bit) and its white image, with the exact grid and views.

    ``size`` is the number of microlenses (columns, rows) = the view size. GT:
    ``centers`` (rows, cols, 2) sensor px of the microlens centres (x, y);
    ``views`` (N, N, rows, cols, 3) radiance at the lattice positions; for hex
    also ``views_rect`` (N, N, Hr, cols - 1, 3) on the square grid of unit
    spacing inside every row's samples (``x = j + 1/2``, ``y = k``) that a
    decoder resamples to.
    """
    cols, rows = size
    n = views
    half = n * view_step_px / 2
    if half * math.sqrt(2) > pitch / 2 - 0.5:
        raise InputError("view_step_px", f"{n} views of {view_step_px} px do not fit a "
                                         f"microlens of pitch {pitch} px")
    pos = lattice_positions(rows, cols, lattice)
    theta = math.radians(rotation_deg)
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    rel = pos @ rot.T * pitch
    origin = pitch - rel.reshape(-1, 2).min(0) + rng.uniform(0, 1, 2)
    centers = rel + origin
    sensor_w = int(math.ceil(centers[..., 0].max() + pitch))
    sensor_h = int(math.ceil(centers[..., 1].max() + pitch))

    spacing, f = 1.0, float(cols)
    ppx, ppy = (pos[..., 0].max()) / 2, (pos[..., 1].max()) / 2
    disp = np.linspace(disparity_near, disparity_far, planes)
    scene = build_scene(rng, width=cols + 2, height=int(pos[..., 1].max()) + 3, f=f,
                        spacing=spacing, disparities=disp, texel_px=texel_px,
                        reach=(n / 2 + 1.5) * spacing, ppx=ppx, ppy=ppy)
    xs_even = np.arange(cols, dtype=float)
    ys = pos[:, 0, 1]
    gt_views = render_views(scene, n, n, spacing, xs_even, ys)
    if lattice == "hex":
        odd = render_views(scene, n, n, spacing, xs_even + 0.5, ys)
        gt_views[:, :, 1::2] = odd[:, :, 1::2]
        hr = int(math.floor((rows - 1) * SQRT3_2)) + 1
        views_rect = render_views(scene, n, n, spacing, xs_even[:-1] + 0.5,
                                  np.arange(hr, dtype=float))
    gt_views = np.clip(gt_views, 0.0, None)

    # Which microlens and which cell each sensor pixel sees.
    py, px = np.mgrid[0:sensor_h, 0:sensor_w].astype(float)
    q = np.stack([px - origin[0], py - origin[1]], -1) @ rot / pitch   # lattice frame, pitch units
    i0 = np.round(q[..., 1] / (SQRT3_2 if lattice == "hex" else 1.0)).astype(int)
    value = np.zeros((sensor_h, sensor_w, 3))
    white = np.zeros((sensor_h, sensor_w))
    for di in (-1, 0, 1):
        ii = i0 + di
        shift = 0.5 * (ii % 2) if lattice == "hex" else 0.0
        j0 = np.round(q[..., 0] - shift).astype(int)
        for dj in (-1, 0, 1):
            jj = j0 + dj
            ok = (ii >= 0) & (ii < rows) & (jj >= 0) & (jj < cols)
            ic, jc = np.clip(ii, 0, rows - 1), np.clip(jj, 0, cols - 1)
            delta = (np.stack([px, py], -1) - centers[ic, jc]) @ rot   # rotated into lattice frame
            cell = np.floor((delta + half) / view_step_px).astype(int)
            ok &= (cell >= 0).all(-1) & (cell < n).all(-1)
            r2 = (delta ** 2).sum(-1) / (2 * half * half)
            vig = 1.0 - 0.4 * r2
            cu, cv = np.clip(cell[..., 1], 0, n - 1), np.clip(cell[..., 0], 0, n - 1)
            value[ok] = gt_views[cu[ok], cv[ok], ic[ok], jc[ok]] * vig[ok, None]
            white[ok] = vig[ok]
    rr = ((px - sensor_w / 2) ** 2 + (py - sensor_h / 2) ** 2) / ((sensor_w / 2) ** 2 + (sensor_h / 2) ** 2)
    falloff = 1.0 - 0.25 * rr
    gain = 0.95
    raw = _codes(value * (falloff * gain)[..., None], 12, noise, rng)
    white_codes = _codes(white * falloff * gain, 12, 0.0, rng)
    gt_arrays = {"centers": centers.astype(np.float64), "views": gt_views.astype(np.float32)}
    if lattice == "hex":
        gt_arrays["views_rect"] = np.clip(views_rect, 0, None).astype(np.float32)
    info = {"views": [n, n], "lattice": lattice}
    return RenderedScene(
        "lightfield-lenslet", {}, (raw, np.repeat(white_codes[..., None], 3, -1)),
        ("raw.png", "white.png"),
        stack={"bit_depth": 12, "linear": True, "exposure_times_s": [1.0, 1.0], "lenslet": info},
        gt={"lattice": lattice, "pitch_px": pitch, "rotation_deg": rotation_deg,
            "origin_px": origin.tolist(), "view_step_px": view_step_px, "views": [n, n],
            "hex_odd_shift": 0.5 if lattice == "hex" else 0.0, "rows": rows, "cols": cols,
            "planes": [{"depth": p.depth, "disparity": f * spacing / p.depth} for p in scene.planes],
            "noise_sigma_codes": noise, "code_scale": 4095 * gain},
        gt_arrays=gt_arrays)


def _array_options(**defaults):
    d = {"grid": "5x5", "planes": 3, "disparity_near": 1.0, "disparity_far": 0.2,
         "spacing": 1.0, "texel_px": 1.5, "thin_lens": True, "noise": 0.0, **defaults}
    return (
        Option("grid", str, d["grid"], "camera grid ROWSxCOLS (U x V)"),
        Option("planes", int, d["planes"], "number of textured planes", low=1, high=4),
        Option("disparity_near", float, d["disparity_near"],
               "disparity of the nearest plane, px per view step", low=0.02, high=8.0),
        Option("disparity_far", float, d["disparity_far"],
               "disparity of the farthest plane, px per view step", low=0.02, high=8.0),
        Option("spacing", float, d["spacing"], "camera spacing (world units)", low=1e-3,
               high=1e3),
        Option("texel_px", float, d["texel_px"], "texel size in pixels (texture smoothness)",
               low=0.5, high=20.0),
        Option("focus", tuple, (), "refocus slopes for the GT refocus images (comma list); "
                                   "default: the plane disparities and midpoints",
               low=-16.0, high=16.0),
        Option("thin_lens", bool, d["thin_lens"], "also render thin-lens refocus truth"),
        Option("novel", tuple, (0.5, 0.5, 0.0), "novel-view truth position X,Y,Z (view steps)",
               low=-100.0, high=100.0),
        Option("noise", float, d["noise"], "Gaussian noise in 16-bit code values", low=0.0),
        Option("jitter_deg", float, 0.0, "per-camera rotation jitter (max degrees; poses in "
                                         "stack.json)", low=0.0, high=5.0),
        Option("jitter_pos", float, 0.0, "per-camera in-plane centre jitter (max grid steps)",
               low=0.0, high=0.5),
    )


def _lenslet_options(lattice):
    return (
        Option("lattice", str, lattice, "microlens grid", choices=("square", "hex")),
        Option("views", int, 5, "views per microimage side", low=2, high=15),
        Option("pitch", float, 22.4, "microlens pitch (px)", low=4.0, high=200.0),
        Option("rotation_deg", float, 1.5, "microlens grid rotation (degrees)", low=-10, high=10),
        Option("view_step_px", float, 3.0, "sensor px per view step inside a microimage",
               low=1.0, high=20.0),
        Option("planes", int, 3, "number of textured planes", low=1, high=4),
        Option("disparity_near", float, 0.6, "nearest plane disparity (px/view)", low=0.02,
               high=4.0),
        Option("disparity_far", float, 0.1, "farthest plane disparity (px/view)", low=0.02,
               high=4.0),
        Option("texel_px", float, 2.5, "texel size in view pixels", low=0.5, high=20.0),
        Option("noise", float, 0.0, "Gaussian noise in 12-bit code values", low=0.0),
    )


SPECS = {
    "lightfield-array": SceneSpec(
        "lightfield-array", (96, 96), _array_options(), version=1, min_size=(16, 16)),
    "lightfield-lenslet": SceneSpec(
        "lightfield-lenslet", (40, 40), _lenslet_options("square"), version=1, min_size=(8, 8)),
    "lightfield-lenslet-hex": SceneSpec(
        "lightfield-lenslet-hex", (40, 40), _lenslet_options("hex"), version=2, min_size=(8, 8)),
}
