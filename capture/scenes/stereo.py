"""Stereo pairs and multi-view sets rendered by exact ray casting, with closed-form geometry.

Two scenes:

``stereo-pair``
    A left/right pair of a textured background plane, a slanted textured card
    and a textured sphere (occlusion borders), optionally a flat grey card
    (``--textureless``) and thin posts in front (``--occluders``). Rectified
    (``--layout rectified``: identical K, ``x_right = x_left − B``) or not
    (``--layout unrectified``: the right camera is rotated by a few degrees,
    raised, and has its own K). Ground truth: left-camera depth ``Z``, disparity
    ``d = fx·B/Z`` (rectified only; ``x_right = x_left − d``), the right-image
    position of every left pixel, NaN where the point is hidden from the right
    camera or falls outside it; the rig (``gt.json["rig"]``, the ``rig.json``
    layout, so ``lumigraph stereo match --rig gt.json`` works).

``stereo-views``
    N views (default 10) on an arc around two textured boxes and a sphere
    standing on a textured floor before a textured wall, for structure from
    motion. Ground truth: every view's ``cam_from_world`` pose, the shared
    camera (``gt.json["camera"]``, the ``camera.json`` layout) and depth maps.

Rendering: each pixel is the mean of ``ss × ss`` rays (box-filter
anti-aliasing, as a sensor integrates over its pixel); surfaces are Lambertian
(a fixed light, so brightness is the same from every viewpoint) with textures
from the images that ship with scikit-image; 8-bit codes with Gaussian read
noise. Ground truth is evaluated at pixel centres (one ray each), exactly.

Examples
--------
>>> s = render_pair(size=(48, 32), seed=0, rng=np.random.default_rng(0), supersample=1)
>>> d = s.gt_arrays["disparity"]
>>> d.shape, bool(np.nanmin(d) > 0)
((32, 48), True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lumigraph.capture.render import Option, RenderedScene, SceneSpec

_LIGHT = np.array([-0.35, -0.6, -0.72]) / np.linalg.norm([-0.35, -0.6, -0.72])


# ------------------------------------------------------------------- textures
def _texture(name: str, *, tint=(1.0, 1.0, 1.0), max_side: int = 256) -> np.ndarray:
    """A scikit-image picture as float32 RGB in [0, 1], shrunk (area filter) so
    that its detail is near the sensor's sampling rate and does not alias."""
    import cv2
    import skimage.data

    img = getattr(skimage.data, name)()
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3].astype(np.float32) / 255.0
    s = max_side / max(img.shape[:2])
    if s < 1:
        img = cv2.resize(img, (round(img.shape[1] * s), round(img.shape[0] * s)),
                         interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(img * np.asarray(tint, np.float32))


def _bilinear(tex: np.ndarray, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
    """Sample ``tex (h, w, 3)`` at float texel coordinates (clamped) -> ``(N, 3)``."""
    h, w = tex.shape[:2]
    tx = np.clip(tx, 0, w - 1.0)
    ty = np.clip(ty, 0, h - 1.0)
    x0 = np.minimum(tx.astype(np.intp), w - 2)
    y0 = np.minimum(ty.astype(np.intp), h - 2)
    fx = (tx - x0)[:, None].astype(np.float32)
    fy = (ty - y0)[:, None].astype(np.float32)
    a, b = tex[y0, x0], tex[y0, x0 + 1]
    c, d = tex[y0 + 1, x0], tex[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


# ----------------------------------------------------------------- primitives
@dataclass(frozen=True)
class _Rect:
    """A textured parallelogram ``origin + s·u + r·v``, ``s, r ∈ [0, 1]``; ``u ⟂ v``.
    ``texture`` None means a flat ``colour`` (a textureless surface)."""

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    texture: np.ndarray | None
    colour: tuple = (0.5, 0.5, 0.5)

    def hit(self, C, D):
        n = np.cross(self.u, self.v)
        denom = D @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((self.origin - C) @ n) / denom
        P = C + t[:, None] * D
        rel = P - self.origin
        s = rel @ self.u / (self.u @ self.u)
        r = rel @ self.v / (self.v @ self.v)
        ok = (t > 1e-9) & (s >= 0) & (s <= 1) & (r >= 0) & (r <= 1) & np.isfinite(t)
        return np.where(ok, t, np.inf), (s, r)

    def shade(self, P, uv, idx):
        s, r = uv[0][idx], uv[1][idx]
        n = np.cross(self.u, self.v)
        n = n / np.linalg.norm(n)
        lam = 0.45 + 0.55 * abs(float(n @ _LIGHT))
        if self.texture is None:
            return np.tile(np.asarray(self.colour, np.float32) * lam, (len(s), 1))
        h, w = self.texture.shape[:2]
        return _bilinear(self.texture, s * (w - 1), r * (h - 1)) * np.float32(lam)


@dataclass(frozen=True)
class _Sphere:
    center: np.ndarray
    radius: float
    texture: np.ndarray

    def hit(self, C, D):
        oc = C - self.center
        b = D @ oc
        c = oc @ oc - self.radius ** 2
        a = np.einsum("ij,ij->i", D, D)
        disc = b * b - a * c
        with np.errstate(invalid="ignore"):
            t = (-b - np.sqrt(disc)) / a
        ok = (disc >= 0) & (t > 1e-9)
        return np.where(ok, t, np.inf), None

    def shade(self, P, uv, idx):
        n = (P - self.center) / self.radius
        lam = 0.3 + 0.7 * np.clip(n @ -_LIGHT, 0, 1)
        h, w = self.texture.shape[:2]
        lon = np.arctan2(n[:, 0], -n[:, 2])
        lat = np.arcsin(np.clip(n[:, 1], -1, 1))
        col = _bilinear(self.texture, (lon / (2 * np.pi) + 0.5) * (w - 1),
                        (lat / np.pi + 0.5) * (h - 1))
        return col * lam[:, None].astype(np.float32)


def _corners(p):
    if isinstance(p, _Rect):
        return np.array([p.origin, p.origin + p.u, p.origin + p.v, p.origin + p.u + p.v])
    o = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    return p.center + p.radius * o


def _cast(prims, C, D, cull=None, *, shade=True):
    """Nearest hit of rays ``C + t·D`` (``D (N, 3)``): ``(t, colour (N, 3))``; a miss
    gives ``t = inf`` and black. ``shade=False`` skips the colours (depth passes)
    and returns ``(t, None)``.

    ``cull = (K, R, t, pix (N, 2))`` restricts each primitive's test to the
    rays inside the image rectangle bounding its projected corners (exact: a
    convex primitive in front of the camera projects inside that rectangle).
    """
    n = len(D)
    T = np.full((len(prims), n), np.inf)
    hits = []
    for k, p in enumerate(prims):
        sel = None
        if cull is not None:
            K, R, t, pix = cull
            cam = _corners(p) @ R.T + t
            if np.all(cam[:, 2] > 1e-6):
                uv = cam[:, :2] / cam[:, 2:3] * [K[0, 0], K[1, 1]] + K[:2, 2]
                lo, hi = uv.min(axis=0) - 1, uv.max(axis=0) + 1
                sel = np.flatnonzero((pix[:, 0] >= lo[0]) & (pix[:, 0] <= hi[0])
                                     & (pix[:, 1] >= lo[1]) & (pix[:, 1] <= hi[1]))
        if sel is None:
            th, uv = p.hit(C, D)
            T[k] = th
            hits.append((None, uv))
        else:
            th, uv = p.hit(C, D[sel])
            T[k, sel] = th
            hits.append((sel, uv))
    which = np.argmin(T, axis=0)
    t = T[which, np.arange(n)]
    if not shade:
        return t, None
    colour = np.zeros((n, 3), np.float32)
    P = C + np.where(np.isfinite(t), t, 0)[:, None] * D
    for k, p in enumerate(prims):
        idx = np.flatnonzero((which == k) & np.isfinite(t))
        if not idx.size:
            continue
        sel, uv = hits[k]
        if sel is None:
            local = idx
        else:
            local = np.searchsorted(sel, idx)
        colour[idx] = p.shade(P[idx], uv, local)
    return t, colour


# ------------------------------------------------------------------- cameras
def _rays(K, R, t, size, ss):
    """World-frame rays of a camera ``x_cam = R x_world + t`` through ``ss × ss``
    sub-pixel samples per pixel: centre ``C (3,)``, directions ``(H·W·ss², 3)``
    scaled so that their camera-frame ``z`` is 1 (so ray ``t`` is depth), and
    the sample positions ``(H·W·ss², 2)`` in pixels."""
    w, h = size
    off = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(w)[:, None] + off[None, :]).ravel()
    ys = (np.arange(h)[:, None] + off[None, :]).ravel()
    # order (y, sy, x, sx) so a reshape to (h, ss, w, ss) averages sub-samples
    X, Y = np.meshgrid(xs, ys)
    pix = np.stack([X.ravel(), Y.ravel()], axis=1)
    yn = (pix[:, 1] - K[1, 2]) / K[1, 1]
    xn = (pix[:, 0] - K[0, 2] - K[0, 1] * yn) / K[0, 0]
    d_cam = np.stack([xn, yn, np.ones_like(xn)], axis=1)
    C = -R.T @ t
    return C, d_cam @ R, pix


def _render_view(prims, K, R, t, size, ss, rng, noise):
    """8-bit codes of one view (mean of ss² rays per pixel, then read noise)."""
    w, h = size
    C, D, pix = _rays(K, R, t, size, ss)
    _, col = _cast(prims, C, D, (K, R, t, pix))
    img = col.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))
    codes = img * 255.0
    if noise > 0:
        codes = codes + rng.normal(0.0, noise, codes.shape)
    return np.clip(np.round(codes), 0, 255).astype(np.uint8)


def _depth(prims, K, R, t, size):
    """Camera-frame depth ``Z (H, W)`` at pixel centres (inf where nothing is hit)."""
    w, h = size
    C, D, pix = _rays(K, R, t, size, 1)
    T, _ = _cast(prims, C, D, (K, R, t, pix), shade=False)
    return T.reshape(h, w)


def _rot(yaw_deg, pitch_deg, roll_deg):
    """``R = Rz(roll) Rx(pitch) Ry(yaw)``."""
    a, b, c = np.radians([yaw_deg, pitch_deg, roll_deg])
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return Rz @ Rx @ Ry


def _look_at(centre, target):
    """``cam_from_world`` ``(R, t)`` of a camera at ``centre`` looking at
    ``target`` with its image ``y`` along world ``+Y`` (world Y points down)."""
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ centre


def _camera_dict(K, size):
    return {"K": K.tolist(), "dist": [0.0] * 5, "image_size": list(size), "model": "none"}


# --------------------------------------------------------------- stereo pair
def _pair_scene(size, rng, textureless, occluders):
    """Primitives in the left camera frame (X right, Y down, Z forward), metres."""
    w, h = size
    aspect = h / w
    prims = [
        # background: a large, slightly slanted textured wall
        _Rect(np.array([-4.0, -3.2, 5.6]), np.array([8.0, 0.0, -1.2]), np.array([0.0, 6.4, 0.0]),
              _texture("astronaut", max_side=384)),
        # slanted card (depth varies across it)
        _Rect(np.array([-1.55, -0.95 * aspect - 0.1, 3.0]), np.array([1.3, 0.0, 0.55]),
              np.array([0.0, 1.5, 0.0]), _texture("coffee")),
        # sphere in front (strong occlusion borders)
        _Sphere(np.array([0.55, 0.12, 2.2]), 0.42, _texture("chelsea")),
    ]
    if textureless:
        # a flat grey card: no texture at all, only read noise
        prims.append(_Rect(np.array([-0.25, -0.78 * aspect - 0.25, 2.6]), np.array([0.75, 0.0, 0.0]),
                           np.array([0.0, 0.55, 0.0]), None, (0.55, 0.55, 0.55)))
    for i in range(occluders):
        x0 = -1.1 + 0.9 * i + rng.uniform(-0.1, 0.1)
        prims.append(_Rect(np.array([x0, -1.5, 1.75 + 0.15 * i]), np.array([0.08, 0.0, 0.0]),
                           np.array([0.0, 3.0, 0.0]), _texture("rocket", max_side=128)))
    return prims


def _pair_geometry(size, layout, baseline):
    """``f``, ``K_l``, ``K_r``, ``R`` (right from left) and the right camera's
    centre ``c_r`` (left frame) of the stereo-pair scene (see :func:`render_pair`)."""
    w, h = size
    f = float(w)
    K_l = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    if layout == "rectified":
        K_r = K_l.copy()
        R = np.eye(3)
        c_r = np.array([baseline, 0.0, 0.0])
    else:
        K_r = np.array([[1.02 * f, 0, (w - 1) / 2 + 0.03 * w], [0, 1.02 * f, (h - 1) / 2 - 0.02 * h],
                        [0, 0, 1]])
        R = _rot(-2.5, 1.2, 1.5)
        c_r = np.array([baseline, 0.02 * baseline, 0.05 * baseline])
    return f, K_l, K_r, R, c_r


def pair_rig(size, *, layout: str = "rectified", baseline: float = 0.18):
    """The rig the ``stereo-pair`` scene renders with at ``size`` (w, h):
    distortion-free cameras, ``x_right = R x_left + T`` with ``T = -R c_right``.

    The ``boards-stereo`` scene can render its calibration boards with this
    very rig (``--rig stereo-pair-rectified`` or ``stereo-pair-unrectified``),
    so a rig calibrated from those boards applies to the pair.

    >>> rig = pair_rig((320, 240), layout="unrectified", baseline=0.18)
    >>> rig.left.focal_px, (-rig.R.T @ rig.T).round(4).tolist()   # the right camera's centre
    ((320.0, 320.0), [0.18, 0.0036, 0.009])
    """
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.rig import Rig

    _, K_l, K_r, R, c_r = _pair_geometry(size, layout, baseline)
    return Rig.from_pose(Camera(K_l, np.zeros(5), size, "none"), Camera(K_r, np.zeros(5), size, "none"),
                         R, -R @ c_r)


def render_pair(*, size, seed, rng, layout="rectified", textureless=False, occluders=0,
                baseline=0.18, noise=1.0, supersample=3):
    """Left/right views with exact depth, disparity and right-image positions.

    Geometry: left camera at the origin (world = left camera frame), ``fx = fy
    = W`` (a 53° field of view), principal point at the image centre. The right
    centre is ``(B, 0, 0)`` (rectified) or ``(B, 0.02·B, 0.05·B)`` with a
    rotation of (yaw 2.5°, pitch 1.2°, roll 1.5°) and its own K (unrectified);
    ``x_right = R x_left + T`` with ``T = −R c_right`` (capture.rig's convention).

    Returns
    -------
    RenderedScene
        ``left.png``, ``right.png`` (uint8 RGB); ``gt_arrays``: ``depth`` (H, W)
        float64 left-camera Z (m), ``disparity`` (H, W) float32 px (rectified:
        ``fx·B/Z``; NaN where hidden from the right camera or outside it;
        unrectified: all NaN), ``right_xy`` (H, W, 2) float64 right-image
        pixel of each left pixel centre (NaN where hidden), ``points`` (H, W, 3)
        float64 left-frame 3-D points; ``gt``: ``rig``, ``cam_from_world`` of
        both, ``disparity_range``.

    Examples
    --------
    >>> s = render_pair(size=(40, 30), seed=1, rng=np.random.default_rng(1), layout="unrectified",
    ...                 supersample=1)
    >>> bool(np.all(np.isnan(s.gt_arrays["disparity"])))
    True
    """
    w, h = size
    f, K_l, K_r, R, c_r = _pair_geometry(size, layout, baseline)
    T = -R @ c_r
    prims = _pair_scene(size, rng, textureless, occluders)
    left = _render_view(prims, K_l, np.eye(3), np.zeros(3), size, supersample, rng, noise)
    right = _render_view(prims, K_r, R, T, size, supersample, rng, noise)

    Z = _depth(prims, K_l, np.eye(3), np.zeros(3), size)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ np.linalg.inv(K_l).T
    finite = np.isfinite(Z)
    P = rays * np.where(finite, Z, np.nan)[..., None]
    # Visibility from the right camera: cast from its centre towards each point;
    # anything nearer than the point itself (relative 1e-6) hides it.
    Pf = P.reshape(-1, 3)
    ok = np.isfinite(Pf).all(axis=1)
    dirs = Pf[ok] - c_r
    t_hit, _ = _cast(prims, c_r, dirs, shade=False)
    visible = np.zeros(len(Pf), bool)
    visible[np.flatnonzero(ok)] = t_hit >= 1 - 1e-6
    Pr = Pf @ R.T + T
    with np.errstate(invalid="ignore", divide="ignore"):
        xr = (Pr @ K_r.T)
        xr = xr[:, :2] / xr[:, 2:3]
    inside = (xr[:, 0] > -0.5) & (xr[:, 0] < w - 0.5) & (xr[:, 1] > -0.5) & (xr[:, 1] < h - 0.5)
    keep = visible & inside & ok
    right_xy = np.where(keep[:, None], xr, np.nan).reshape(h, w, 2)
    if layout == "rectified":
        with np.errstate(divide="ignore"):
            disparity = np.where(keep.reshape(h, w), f * baseline / Z, np.nan).astype(np.float32)
    else:
        disparity = np.full((h, w), np.nan, np.float32)

    rig = pair_rig(size, layout=layout, baseline=baseline).to_dict()
    d_lo = f * baseline / np.nanmax(np.where(finite, Z, np.nan))
    d_hi = f * baseline / np.nanmin(np.where(finite, Z, np.nan))
    gt = {"rig": rig, "layout": layout, "focal_px": f, "baseline_m": baseline,
          "cam_from_world": {"left": {"R": np.eye(3).tolist(), "t": [0.0, 0.0, 0.0]},
                             "right": {"R": R.tolist(), "t": T.tolist()}},
          "disparity_range": [float(d_lo), float(d_hi)],
          "suggested_max_disp": int(16 * np.ceil(1.15 * d_hi / 16)),
          "occluded_fraction": float(1 - keep[ok].mean()),
          "noise_sigma_codes": noise, "supersample": supersample,
          "textureless_card": bool(textureless)}
    return RenderedScene("stereo-pair", {}, (left, right), ("left.png", "right.png"),
                         stack={"bit_depth": 8, "linear": True, "kind": "stereo-pair"},
                         gt=gt, gt_arrays={"depth": np.where(finite, Z, np.nan),
                                           "disparity": disparity, "right_xy": right_xy,
                                           "points": P})


# --------------------------------------------------------------- multi-view
def _views_scene():
    """World frame: X right, Y down (floor at Y = 1), Z away from the cameras; metres."""
    return [
        _Rect(np.array([-12.0, 1.0, -4.0]), np.array([24.0, 0.0, 0.0]), np.array([0.0, 0.0, 8.0]),
              _texture("gravel", tint=(0.9, 0.8, 0.65), max_side=512)),
        _Rect(np.array([-12.0, -6.0, 4.0]), np.array([24.0, 0.0, 0.0]), np.array([0.0, 7.0, 0.0]),
              _texture("hubble_deep_field", tint=(1.6, 1.6, 1.6), max_side=512)),
        # box A (three visible faces, each its own picture)
        _Rect(np.array([-1.2, 0.0, -0.6]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
              _texture("astronaut")),
        _Rect(np.array([-1.2, 0.0, 0.4]), np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]),
              _texture("coffee")),
        _Rect(np.array([-0.2, 0.0, -0.6]), np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]),
              _texture("rocket")),
        _Rect(np.array([-1.2, 0.0, 0.4]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0]),
              _texture("immunohistochemistry")),
        # box B, rotated 30° about Y, taller
        *_box(np.array([1.0, 1.0, 0.9]), 0.7, 1.5, np.radians(30), ("chelsea", "colorwheel", "retina",
                                                                    "cat")),
        _Sphere(np.array([0.2, 0.65, -1.2]), 0.35, _texture("coins", tint=(1.2, 1.3, 1.4))),
    ]


def _box(base_centre, side, height, yaw, textures):
    """Four vertical faces and a top of a box standing on ``base_centre``."""
    c, s = np.cos(yaw), np.sin(yaw)
    ex = np.array([c, 0, -s]) * side
    ez = np.array([s, 0, c]) * side
    up = np.array([0.0, -height, 0.0])
    o = base_centre - ex / 2 - ez / 2
    faces = [
        _Rect(o + up, ex, -up, _texture(textures[0])),
        _Rect(o + ex + up, ez, -up, _texture(textures[1])),
        _Rect(o + ez + up, -ez, -up, _texture(textures[2])),
        _Rect(o + ex + ez + up, -ex, -up, _texture(textures[1], tint=(0.7, 0.8, 1.0))),
        _Rect(o + up, ex, ez, _texture(textures[3])),
    ]
    return faces


def render_views(*, size, seed, rng, views=10, arc_deg=70.0, noise=1.0, supersample=2):
    """``views`` images from an arc of radius 4.5 m, 1.6 m above the floor,
    spanning ``arc_deg`` and looking at the scene centre, with ±0.15 m of
    random jitter in position (so no three centres are exactly collinear).

    Returns
    -------
    RenderedScene
        ``view00.png`` … (uint8 RGB); ``gt``: ``camera`` (camera.json layout),
        ``cam_from_world`` (list of ``{"R", "t"}``), ``centres`` (N, 3) m,
        ``scene_size_m`` (the diameter of the camera centres, the yardstick of
        the SfM target); ``gt_arrays``: ``depth`` (N, H, W) float32.

    Examples
    --------
    >>> s = render_views(size=(32, 24), seed=0, rng=np.random.default_rng(0), views=2,
    ...                  supersample=1)
    >>> len(s.images), len(s.gt["cam_from_world"])
    (2, 2)
    """
    w, h = size
    f = 0.85 * w
    K = np.array([[f, 0, (w - 1) / 2 + 0.013 * w], [0, f, (h - 1) / 2 - 0.011 * h], [0, 0, 1]])
    prims = _views_scene()
    target = np.array([0.0, 0.3, 0.0])
    az = np.radians(np.linspace(-arc_deg / 2, arc_deg / 2, views))
    images, names, poses, centres, depths = [], [], [], [], []
    for i, a in enumerate(az):
        centre = np.array([4.5 * np.sin(a), -0.6, -4.5 * np.cos(a)]) + rng.uniform(-0.15, 0.15, 3)
        R, t = _look_at(centre, target)
        images.append(_render_view(prims, K, R, t, size, supersample, rng, noise))
        names.append(f"view{i:02d}.png")
        poses.append({"R": R.tolist(), "t": t.tolist()})
        centres.append(centre)
        depths.append(_depth(prims, K, R, t, size).astype(np.float32))
    centres = np.array(centres)
    diam = float(np.max(np.linalg.norm(centres[:, None] - centres[None], axis=-1)))
    cam = {"schema": "lumigraph.camera", "schema_version": 1, **_camera_dict(K, size)}
    gt = {"camera": cam, "cam_from_world": poses, "centres": centres.tolist(),
          "scene_size_m": diam, "noise_sigma_codes": noise, "supersample": supersample}
    return RenderedScene("stereo-views", {}, tuple(images), tuple(names),
                         stack={"bit_depth": 8, "linear": True, "kind": "multi-view"},
                         gt=gt, gt_arrays={"depth": np.stack(depths)})


SPECS = {
    "stereo-pair": SceneSpec(
        "stereo-pair", (320, 240),
        (Option("layout", str, "rectified", "rectified (same K, pure x baseline) or unrectified "
                "(rotated right camera with its own K)", choices=("rectified", "unrectified")),
         Option("textureless", bool, False, "add a flat grey card (a textureless region)"),
         Option("occluders", int, 0, "thin posts in front of the scene (more occlusion borders)",
                low=0, high=3),
         Option("baseline", float, 0.18, "distance between the camera centres (m)", low=0.0,
                high=2.0, open_low=True),
         Option("noise", float, 1.0, "Gaussian read noise (8-bit code values)", low=0.0),
         Option("supersample", int, 3, "rays per pixel side (anti-aliasing)", low=1, high=6)),
        version=1),
    "stereo-views": SceneSpec(
        "stereo-views", (320, 240),
        (Option("views", int, 10, "number of views", low=2, high=40),
         Option("arc_deg", float, 70.0, "angle spanned by the camera arc (degrees)", low=1.0,
                high=180.0),
         Option("noise", float, 1.0, "Gaussian read noise (8-bit code values)", low=0.0),
         Option("supersample", int, 2, "rays per pixel side (anti-aliasing)", low=1, high=6)),
        version=1),
}
