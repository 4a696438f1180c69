"""A facade with relief seen from two far-apart viewpoints, for model-based stereo.

``model-stereo``
    A textured wall (a plane, turned 12° towards the offset side) with
    protruding pillars and recessed window boxes (relief a few per cent of
    the distance deep), seen by a *key* camera and an *offset* camera whose
    viewing directions differ by ``--angle`` degrees (default 30°, a wide
    baseline). The key camera sees the wall 12° off its normal, the offset
    camera ``|angle − 12|``° off it: at 30° the two views foreshorten the
    wall alike (18° vs 12°, widths within 3 %), at 65° very differently
    (53° vs 12°, the offset view 0.62 × as wide), with the relief hiding
    more of the wall the larger the angle.
    The rough model of Debevec, Taylor & Malik (SIGGRAPH 1996,
    doi:10.1145/237170.237191; reference ch. 5, Stage 3, Fig. 5.12) is the
    wall plane without its relief, given as its depth seen from the key camera.

Ground truth (``gt_arrays``): ``depth`` (H, W) float64, the key camera's
``z`` of the visible surface; ``model_depth`` (H, W) float64, the key
camera's ``z`` of the wall plane (the rough model; NaN where the ray misses
the wall); ``relief`` = ``depth − model_depth`` (the offset δ along the key
ray that model-based stereo recovers; negative = nearer, a pillar);
``offset_xy`` (H, W, 2) float64, the offset-image pixel of each key pixel
centre (NaN where the point is hidden from the offset camera or outside
its frame). ``gt``: ``rig`` (the ``rig.json`` layout, left = key, right =
offset, ``x_offset = R x_key + T``, metres), ``cam_from_world`` of both
(world = key camera frame), ``relief_m`` (pillar and window depths),
``suggested_max_offset`` (m) and the noise.

Rendering reuses the exact ray caster of :mod:`capture.scenes.stereo`
(Lambertian surfaces under one fixed light, box-filtered ``ss × ss`` rays per
pixel, 8-bit codes with Gaussian read noise); ground truth is evaluated at
pixel centres with one ray each.

Examples
--------
>>> s = render_facade(size=(48, 36), seed=0, rng=np.random.default_rng(0), supersample=1)
>>> r = s.gt_arrays["relief"]
>>> bool(np.nanmin(r) < -0.1 and np.nanmax(r) > 0.1), s.gt["rig"]["left"]["image_size"]
(True, [48, 36])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lumigraph.capture.render import Option, RenderedScene, SceneSpec
from lumigraph.capture.scenes.stereo import _cast, _depth, _look_at, _Rect, _render_view, _texture

DISTANCE_M = 6.0  # key camera to the facade centre
PILLAR_M = 0.18  # pillars protrude this much towards the cameras
RECESS_M = 0.25  # windows are set back this much
SLANT_DEG = 12.0  # the wall's normal turns this far from the key camera towards the offset camera


@dataclass(frozen=True)
class _HoledRect(_Rect):
    """A ``_Rect`` with rectangular holes ``(s0, s1, r0, r1)`` in its own
    ``(s, r) ∈ [0, 1]²`` coordinates (the window openings of the wall)."""

    holes: tuple = ()

    def hit(self, C, D):
        t, (s, r) = _Rect.hit(self, C, D)
        for s0, s1, r0, r1 in self.holes:
            t = np.where((s > s0) & (s < s1) & (r > r0) & (r < r1), np.inf, t)
        return t, (s, r)


def _wall_texture(aspect):
    """Bricks (scikit-image's ``brick``, tiled so a brick is ~0.4 m wide)
    blended with ``gravel`` for fine detail, about one texel per key-image
    pixel at 320 px width; float32 RGB, ``aspect`` = width / height."""
    import cv2

    brick = _texture("brick", max_side=160)
    h = 427
    w = round(h * aspect)
    tiled = np.tile(brick, (h // 160 + 1, w // 160 + 1, 1))[:h, :w]
    gravel = cv2.resize(_texture("gravel", max_side=512), (w, h), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray((0.65 * tiled + 0.35 * gravel) * np.float32([1.0, 0.82, 0.68]))


def _facade(textureless):
    """Primitives in the key camera frame (X right, Y down, Z forward), metres.

    Wall frame: ``P0`` its centre, ``eu`` along it (horizontal), ``ev`` down,
    ``n`` its normal towards the cameras. Returns the primitives and the wall
    plane ``(P0, n)`` (the rough model).
    """
    a = np.radians(SLANT_DEG)
    P0 = np.array([0.0, 0.0, DISTANCE_M])
    eu = np.array([np.cos(a), 0.0, np.sin(a)])
    ev = np.array([0.0, 1.0, 0.0])
    n = -np.cross(eu, ev)  # (sin a, 0, -cos a): towards the cameras
    half_u, half_v = 6.0, 4.0

    def at(u, v, h=0.0):
        return P0 + u * eu + v * ev + h * n

    windows = [(u, v) for u in (-1.6, 0.0, 1.6) for v in (-1.1, 0.9)]
    ww, wh = 0.8, 1.0
    holes = tuple(((u - ww / 2 + half_u) / (2 * half_u), (u + ww / 2 + half_u) / (2 * half_u),
                   (v - wh / 2 + half_v) / (2 * half_v), (v + wh / 2 + half_v) / (2 * half_v))
                  for u, v in windows)
    prims = [_HoledRect(at(-half_u, -half_v), 2 * half_u * eu, 2 * half_v * ev,
                        _wall_texture(half_u / half_v), holes=holes)]
    for i, (u, v) in enumerate(windows):
        u0, u1, v0, v1 = u - ww / 2, u + ww / 2, v - wh / 2, v + wh / 2
        d = -RECESS_M
        tex = _texture(("astronaut", "coffee", "chelsea", "rocket", "cat", "immunohistochemistry")[i],
                       max_side=128)
        side = _texture("gravel", tint=(0.8, 0.85, 0.9), max_side=96)
        prims += [
            _Rect(at(u0, v0, d), ww * eu, wh * ev, tex),  # the back of the recess
            _Rect(at(u0, v0, d), -d * n, wh * ev, side),  # left reveal
            _Rect(at(u1, v0, d), -d * n, wh * ev, side),  # right reveal
            _Rect(at(u0, v0, d), ww * eu, -d * n, side),  # head
            _Rect(at(u0, v1, d), ww * eu, -d * n, side),  # sill
        ]
    pw = 0.35
    for j, u in enumerate((-2.4, -0.8, 0.8, 2.4)):
        u0, u1 = u - pw / 2, u + pw / 2
        tex = _texture("gravel", tint=(0.95, 0.9, 0.75) if j % 2 else (0.8, 0.8, 0.85), max_side=256)
        prims += [
            _Rect(at(u0, -half_v, PILLAR_M), pw * eu, 2 * half_v * ev, tex),  # front
            _Rect(at(u0, -half_v), PILLAR_M * n, 2 * half_v * ev, tex),  # left side
            _Rect(at(u1, -half_v), PILLAR_M * n, 2 * half_v * ev, tex),  # right side
        ]
    if textureless:
        # a flat grey sign 3 cm proud of the wall between the window rows
        prims.append(_Rect(at(-0.6, -0.5, 0.03), 1.2 * eu, 0.8 * ev, None, (0.6, 0.58, 0.55)))
    return prims, (P0, n, eu, ev, half_u, half_v)


def render_facade(*, size, seed, rng, angle=30.0, noise=1.0, textureless=False, supersample=3):
    """Key and offset views of the facade, exact depth, model depth and relief.

    Geometry: the key camera is at the origin looking along +Z (world = key
    camera frame), ``fx = fy = 0.95 W``; the facade centre is 6 m ahead. The
    offset camera sits on the circle of radius 6 m around the facade centre,
    ``angle`` degrees to the right, looking at the centre, with its own K
    (focal 3 % longer, principal point off-centre). The wall faces 12° to the
    right of the key camera, towards the offset camera, which sees it at
    ``|angle − 12|`` degrees incidence (the key camera at 12°).

    Returns
    -------
    RenderedScene
        ``key.png``, ``offset.png`` (uint8 RGB) and the ground truth listed in
        the module docstring.

    Examples
    --------
    >>> s = render_facade(size=(40, 30), seed=1, rng=np.random.default_rng(1), supersample=1)
    >>> m, z = s.gt_arrays["model_depth"], s.gt_arrays["depth"]
    >>> bool(np.all(np.isfinite(m))), bool(np.nanmax(np.abs(z - m)) < 0.3)
    (True, True)
    """
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.rig import Rig

    w, h = size
    f = 0.95 * w
    K_k = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    K_o = np.array([[1.03 * f, 0, (w - 1) / 2 - 0.02 * w], [0, 1.03 * f, (h - 1) / 2 + 0.015 * h],
                    [0, 0, 1]])
    a = np.radians(angle)
    centre = np.array([0.0, 0.0, DISTANCE_M])
    c_o = centre + DISTANCE_M * np.array([np.sin(a), 0.0, -np.cos(a)])
    R, T = _look_at(c_o, centre)
    prims, (P0, n, eu, ev, half_u, half_v) = _facade(textureless)
    I3, z3 = np.eye(3), np.zeros(3)
    key = _render_view(prims, K_k, I3, z3, size, supersample, rng, noise)
    off = _render_view(prims, K_o, R, T, size, supersample, rng, noise)

    Z = _depth(prims, K_k, I3, z3, size)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([xs, ys, np.ones_like(xs)], axis=-1) @ np.linalg.inv(K_k).T
    finite = np.isfinite(Z)
    P = rays * np.where(finite, Z, np.nan)[..., None]
    # the rough model: the wall plane n·(X − P0) = 0 along each key ray (z = 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        zm = (n @ P0) / (rays @ n)
    X = rays * zm[..., None]
    u, v = (X - P0) @ eu, (X - P0) @ ev
    model = np.where((zm > 0) & (np.abs(u) <= half_u) & (np.abs(v) <= half_v), zm, np.nan)

    # visibility from the offset camera (as capture.scenes.stereo.render_pair)
    Pf = P.reshape(-1, 3)
    ok = np.isfinite(Pf).all(axis=1)
    t_hit, _ = _cast(prims, c_o, Pf[ok] - c_o, shade=False)
    visible = np.zeros(len(Pf), bool)
    visible[np.flatnonzero(ok)] = t_hit >= 1 - 1e-6
    Po = Pf @ R.T + T
    with np.errstate(invalid="ignore", divide="ignore"):
        xo = Po @ K_o.T
        xo = xo[:, :2] / xo[:, 2:3]
    inside = (xo[:, 0] > -0.5) & (xo[:, 0] < w - 0.5) & (xo[:, 1] > -0.5) & (xo[:, 1] < h - 0.5)
    keep = visible & inside & ok
    offset_xy = np.where(keep[:, None], xo, np.nan).reshape(h, w, 2)

    depth = np.where(finite, Z, np.nan)
    rig = Rig.from_pose(Camera(K_k, np.zeros(5), size, "none"), Camera(K_o, np.zeros(5), size, "none"),
                        R, T).to_dict()
    relief = depth - model
    gt = {"rig": rig,
          "cam_from_world": {"key": {"R": I3.tolist(), "t": z3.tolist()},
                             "offset": {"R": R.tolist(), "t": T.tolist()}},
          "angle_deg": angle, "distance_m": DISTANCE_M, "slant_deg": SLANT_DEG,
          "relief_m": {"pillar": -PILLAR_M, "window": RECESS_M,
                       "sign": -0.03 if textureless else None},
          "suggested_max_offset": float(np.ceil(1.4 * max(PILLAR_M, RECESS_M) * 20) / 20),
          "hidden_fraction": float(1 - keep[ok].mean()),
          "noise_sigma_codes": noise, "supersample": supersample,
          "textureless_sign": bool(textureless)}
    return RenderedScene("model-stereo", {}, (key, off), ("key.png", "offset.png"),
                         stack={"bit_depth": 8, "linear": True, "kind": "stereo-pair"},
                         gt=gt, gt_arrays={"depth": depth, "model_depth": model, "relief": relief,
                                           "offset_xy": offset_xy})


SPECS = {
    "model-stereo": SceneSpec(
        "model-stereo", (320, 240),
        (Option("angle", float, 30.0, "angle between the two viewing directions (degrees)",
                low=5.0, high=70.0),
         Option("noise", float, 1.0, "Gaussian read noise (8-bit code values)", low=0.0),
         Option("textureless", bool, False, "add a flat grey sign on the wall (a textureless patch)"),
         Option("supersample", int, 3, "rays per pixel side (anti-aliasing)", low=1, high=6)),
        version=1),
}
