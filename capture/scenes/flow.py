"""Image sequences with exact forward optical flow (scene family 3, flow half).

A textured background plane moves under a known homography per frame (camera
motion), an independently moving textured ellipse moves under its own affine
map, and optionally a third object appears in (``change="added"``) or vanishes
from (``change="removed"``) the last frame, as in Sand–Teller's video matching
(reference §5.1.4). Every frame is the box filter over each pixel of a
continuous image (bilinearly interpolated scikit-image textures), computed by
``supersample``² samples per pixel, so the flow evaluated at the pixel centre
(OpenCV convention: centres at integer coordinates) is exact for the surface
seen there.

Ground truth (``gt/*.npy``), frame 0 -> frame 1 and, for N frames, every
consecutive pair:

==============  ==============  ================================================
array           shape, dtype    meaning
==============  ==============  ================================================
``flow``        (H, W, 2) f32   forward flow (dx, dy) px, 0 -> 1; NaN where the
                                surface has no counterpart (a removed object)
``occluded``    (H, W) bool     target hidden by a nearer surface, outside the
                                frame, or without a counterpart
``boundary``    (H, W) bool     pixel (or its target) mixes two surfaces
``textureless`` (H, W) bool     centre lies in the flat texture region
``flows``       (N-1, H, W, 2)  all consecutive flows (``flows[0] == flow``)
``occlusions``  (N-1, H, W)     their occlusion masks
==============  ==============  ================================================

Scenes: ``flow`` (default), ``flow-large`` (> 40 px), ``flow-textureless``,
``flow-brightness`` (gain, offset and an illumination gradient in frame 1),
``flow-video`` (Sand–Teller: lighting change, an added object, a small camera
shift) and ``flow-sequence`` (5 frames).

Examples
--------
>>> s = render_flow(size=(64, 48), seed=0, rng=np.random.default_rng(0), supersample=2)
>>> s.images[0].shape, s.gt_arrays["flow"].shape, s.gt_arrays["occluded"].dtype.name
((48, 64, 3), (48, 64, 2), 'bool')
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.capture.render import Option, RenderedScene, SceneSpec

BACKGROUND_TEXTURE = "astronaut"
OBJECT_TEXTURE = "chelsea"
ADDED_TEXTURE = "coffee"
TEXEL_PX = 1.25  # one texel spans 1.25 pixels: textures are magnified, never aliased
LAYERS = ("background", "object", "added")


def _texture(name: str, width: int, height: int) -> np.ndarray:
    """A scikit-image picture as float32 RGB in [0, 1], resized to cover
    ``width x height`` texels (area averaging when shrinking)."""
    import cv2
    import skimage.data

    img = getattr(skimage.data, name)()
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3].astype(np.float32) / 255.0
    h, w = img.shape[:2]
    scale = max(width / w, height / h)
    size = (max(2, math.ceil(w * scale)), max(2, math.ceil(h * scale)))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_CUBIC
    return np.clip(cv2.resize(img, size, interpolation=interp), 0.0, 1.0)


def _apply(H: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map points through a 3x3 homography (float64)."""
    d = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    return (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / d, (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / d


def _sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear texture lookup at texel coordinates, mirrored beyond the edge
    (the mirrored texture is still one continuous function)."""
    import cv2

    return cv2.remap(tex, u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REFLECT_101)


def _similarity(cx: float, cy: float, *, tx: float, ty: float, angle: float, scale: float,
                px: float = 0.0, py: float = 0.0) -> np.ndarray:
    """Rotation/scale about (cx, cy), then translation, with an optional
    perspective row: a homography in pixel coordinates."""
    c, s = math.cos(angle) * scale, math.sin(angle) * scale
    C = np.array([[1, 0, cx], [0, 1, cy], [0, 0, 1]], float)
    M = np.array([[c, -s, tx], [s, c, ty], [px, py, 1]], float)
    return C @ M @ np.linalg.inv(C)


class _Layout:
    """Every random choice of one sequence (drawn once, so frames agree)."""

    def __init__(self, w, h, rng, *, frames, motion, object_motion, textureless, change,
                 moving_object):
        self.w, self.h, self.frames = w, h, frames
        phi = rng.uniform(0, 2 * math.pi)
        # Background: translation of `motion` px per frame plus a small
        # rotation, zoom and perspective (camera motion past a plane).
        step = dict(tx=motion * math.cos(phi), ty=motion * math.sin(phi),
                    angle=math.radians(rng.uniform(-0.6, 0.6)), scale=1 + rng.uniform(-0.008, 0.008),
                    px=rng.uniform(-3e-5, 3e-5) * 320 / w, py=rng.uniform(-3e-5, 3e-5) * 240 / h)
        self.bg = [np.linalg.matrix_power(_similarity(w / 2, h / 2, **step), k) for k in range(frames)]
        # Texture placement: frame-0 pixel -> texel, centred in the texture.
        self.tex_w, self.tex_h = math.ceil(w / TEXEL_PX) + 8, math.ceil(h / TEXEL_PX) + 8
        # Independently moving ellipse: its own rotation and translation,
        # in a direction at least 60 degrees away from the background's.
        self.moving = moving_object
        self.ob_center = np.array([w * rng.uniform(0.35, 0.65), h * rng.uniform(0.35, 0.65)])
        self.ob_radii = np.array([w * rng.uniform(0.14, 0.2), h * rng.uniform(0.16, 0.24)])
        psi = phi + rng.choice([-1, 1]) * rng.uniform(math.pi / 3, math.pi)
        ostep = _similarity(*self.ob_center, tx=object_motion * math.cos(psi),
                            ty=object_motion * math.sin(psi),
                            angle=math.radians(rng.uniform(-3, 3)), scale=1.0)
        self.ob = [np.linalg.matrix_power(ostep, k) for k in range(frames)]
        # A flat region of the background texture (moves with the background).
        tw, th = self.tex_w, self.tex_h
        self.flat = None
        if textureless:
            fx, fy = rng.uniform(0.05, 0.15) * tw, rng.uniform(0.1, 0.2) * th
            self.flat = (fx, fy, fx + 0.34 * tw, fy + 0.45 * th)
            self.flat_colour = np.array([0.55, 0.5, 0.45], np.float32)
        # A box that appears in (or vanishes from) the last frame.
        self.change = change
        ax, ay = w * rng.uniform(0.62, 0.72), h * rng.uniform(0.08, 0.25)
        self.added_box = (ax, ay, ax + 0.22 * w, ay + 0.3 * h)

    def added_in(self, k: int) -> bool:
        last = k == self.frames - 1
        return (self.change == "added" and last) or (self.change == "removed" and not last)


def _labels(lay: _Layout, k: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Visible layer (0 background, 1 moving object, 2 added box) at points of frame k."""
    lab = np.zeros(x.shape, np.uint8)
    if lay.moving:
        ox, oy = _apply(np.linalg.inv(lay.ob[k]), x, y)
        inside = (((ox - lay.ob_center[0]) / lay.ob_radii[0]) ** 2
                  + ((oy - lay.ob_center[1]) / lay.ob_radii[1]) ** 2) <= 1.0
        lab[inside] = 1
    if lay.added_in(k):
        # The box is attached to the background: it moves with the camera.
        bx, by = _apply(np.linalg.inv(lay.bg[k]), x, y)
        x0, y0, x1, y1 = lay.added_box
        lab[(bx >= x0) & (bx <= x1) & (by >= y0) & (by <= y1)] = 2
    return lab


def _frame(lay: _Layout, k: int, tex: dict, s: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame k as float32 RGB radiance in [0, 1], box-filtered over s x s
    samples per pixel; the layer label of each pixel centre; and whether the
    pixel's footprint mixes layers."""
    w, h = lay.w, lay.h
    offs = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(w)[:, None] + offs[None, :]).ravel()
    ys = (np.arange(h)[:, None] + offs[None, :]).ravel()
    X, Y = np.meshgrid(xs, ys)
    lab = _labels(lay, k, X, Y)
    bx, by = _apply(np.linalg.inv(lay.bg[k]), X, Y)
    u, v = bx / TEXEL_PX + 4, by / TEXEL_PX + 4
    img = _sample(tex["background"], u, v)
    if lay.flat is not None:
        x0, y0, x1, y1 = lay.flat
        img[(u >= x0) & (u <= x1) & (v >= y0) & (v <= y1)] = lay.flat_colour
    if lay.moving:
        ox, oy = _apply(np.linalg.inv(lay.ob[k]), X, Y)
        m = lab == 1
        img[m] = _sample(tex["object"], ox / TEXEL_PX, oy / TEXEL_PX)[m]
    m = lab == 2
    if m.any():
        img[m] = _sample(tex["added"], bx / TEXEL_PX, by / TEXEL_PX)[m]
    img = img.reshape(h, s, w, s, 3).mean(axis=(1, 3))
    mixed = lab.reshape(h, s, w, s)
    mixed = mixed.min(axis=(1, 3)) != mixed.max(axis=(1, 3))
    cx, cy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return img.astype(np.float32), _labels(lay, k, cx, cy), mixed


def _flow(lay: _Layout, k: int, labels: tuple, mixed: tuple):
    """Exact flow k -> k+1 at pixel centres, and its occlusion/boundary masks."""
    import cv2

    w, h = lay.w, lay.h
    cx, cy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    lab0 = labels[k]
    tx, ty = _apply(lay.bg[k + 1] @ np.linalg.inv(lay.bg[k]), cx, cy)
    if lay.moving:
        ox, oy = _apply(lay.ob[k + 1] @ np.linalg.inv(lay.ob[k]), cx, cy)
        tx, ty = np.where(lab0 == 1, ox, tx), np.where(lab0 == 1, oy, ty)
    flow = np.stack([tx - cx, ty - cy], axis=-1)
    gone = (lab0 == 2) & (not lay.added_in(k + 1))
    flow[gone] = np.nan
    outside = (tx < -0.5) | (tx > w - 0.5) | (ty < -0.5) | (ty > h - 0.5)
    seen = _labels(lay, k + 1, tx, ty)
    occluded = outside | gone | (seen != lab0)
    # Mixed pixels: the centre's surface is not the only one in the pixel's
    # footprint, here or at the target (1 px margin for the target's rounding).
    ix = np.clip(np.rint(tx), 0, w - 1).astype(int)
    iy = np.clip(np.rint(ty), 0, h - 1).astype(int)
    mixed1 = cv2.dilate(mixed[k + 1].astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    boundary = mixed[k] | mixed1[iy, ix]
    return flow.astype(np.float32), occluded, boundary


def render_flow(*, size, seed, rng, frames=2, motion=6.0, object_motion=9.0, moving_object=True,
                textureless=False, gain=1.0, offset=0.0, illumination=0.0, change="none",
                noise=1.0, supersample=3):
    """Render an N-frame sequence with exact forward flow.

    Frame k's radiance is ``box_s(T(A_k^{-1} x))`` composited over layers
    (background homography ``A_k``, object affine map, added box), then in
    frames k >= 1 multiplied by ``gain**(k/(N-1)) * (1 + illumination * r(x))``
    (``r`` a horizontal ramp in [-1, 1]) plus ``offset * k/(N-1)``, then
    ``round(255 * value + N(0, noise))`` clipped to uint8.

    Examples
    --------
    >>> s = render_flow(size=(48, 32), seed=1, rng=np.random.default_rng(1), frames=3,
    ...                 supersample=2)
    >>> len(s.images), s.gt_arrays["flows"].shape
    (3, (2, 32, 48, 2))
    """
    w, h = size
    lay = _Layout(w, h, rng, frames=frames, motion=motion, object_motion=object_motion,
                  textureless=textureless, change=change, moving_object=moving_object)
    tw, th = lay.tex_w, lay.tex_h
    tex = {"background": _texture(BACKGROUND_TEXTURE, tw, th),
           "object": _texture(OBJECT_TEXTURE, tw, th),
           "added": _texture(ADDED_TEXTURE, tw, th)}
    rendered = [_frame(lay, k, tex, supersample) for k in range(frames)]
    labels = tuple(r[1] for r in rendered)
    mixed = tuple(r[2] for r in rendered)
    images = []
    ramp = np.linspace(-1.0, 1.0, w, dtype=np.float32)[None, :, None]
    for k, (img, _, _) in enumerate(rendered):
        t = k / max(frames - 1, 1)
        lit = img * (gain ** t) * (1 + illumination * t * ramp) + offset * t
        codes = 255.0 * lit + (rng.normal(0.0, noise, lit.shape) if noise > 0 else 0.0)
        images.append(np.clip(np.rint(codes), 0, 255).astype(np.uint8))
    flows, occs, bounds = zip(*(_flow(lay, k, labels, mixed) for k in range(frames - 1)),
                              strict=True)
    cx, cy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    if lay.flat is not None:
        bx, by = _apply(np.linalg.inv(lay.bg[0]), cx, cy)
        u, v = bx / TEXEL_PX + 4, by / TEXEL_PX + 4
        x0, y0, x1, y1 = lay.flat
        # At least 2 texels inside: the bilinear texture is exactly flat there.
        flat = (u >= x0 + 2) & (u <= x1 - 2) & (v >= y0 + 2) & (v <= y1 - 2) & (labels[0] == 0)
    else:
        flat = np.zeros((h, w), bool)
    mag = np.hypot(flows[0][..., 0], flows[0][..., 1])
    known = ~occs[0] & np.isfinite(mag)
    gt = {
        "flow_convention": "forward: frame_k(x, y) <-> frame_k+1(x + dx, y + dy); pixel centres "
                           "at integer coordinates; NaN where no counterpart exists",
        "background_from_frame0": [H.tolist() for H in lay.bg],
        "object_from_frame0": [M.tolist() for M in lay.ob] if lay.moving else None,
        "object_ellipse": {"center_px": lay.ob_center.tolist(), "radii_px": lay.ob_radii.tolist()},
        "max_motion_px": float(np.nanmax(mag[known])) if known.any() else 0.0,
        "noise_sigma_codes": noise,
        "photometric": {"gain": gain, "offset": offset, "illumination": illumination},
        "supersample": supersample,
        "layers": list(LAYERS),
    }
    arrays = {"flow": flows[0], "occluded": occs[0], "boundary": bounds[0], "textureless": flat,
              "flows": np.stack(flows), "occlusions": np.stack(occs)}
    names = tuple(f"frame{k:02d}.png" for k in range(frames))
    return RenderedScene("flow", {}, tuple(images), names,
                         stack={"bit_depth": 8, "linear": False, "kind": "sequence"},
                         gt=gt, gt_arrays=arrays)


def _options(**defaults) -> tuple[Option, ...]:
    d = dict(frames=2, motion=6.0, object_motion=9.0, moving_object=True, textureless=False,
             gain=1.0, offset=0.0, illumination=0.0, change="none", noise=1.0, supersample=3)
    d.update(defaults)
    return (
        Option("frames", int, d["frames"], "number of frames", low=2, high=64),
        Option("motion", float, d["motion"], "background translation per frame, px", low=0.0,
               high=200.0),
        Option("object_motion", float, d["object_motion"], "moving object's translation per "
               "frame, px", low=0.0, high=200.0),
        Option("moving_object", bool, d["moving_object"], "include the independently moving ellipse"),
        Option("textureless", bool, d["textureless"], "a flat region in the background texture"),
        Option("gain", float, d["gain"], "brightness gain reached in the last frame", low=0.0,
               high=4.0, open_low=True),
        Option("offset", float, d["offset"], "brightness offset (fraction of full scale) reached "
               "in the last frame", low=-0.5, high=0.5),
        Option("illumination", float, d["illumination"], "strength of a left-right illumination "
               "gradient reached in the last frame", low=0.0, high=0.9),
        Option("change", str, d["change"], "an object added to / removed from the last frame",
               choices=("none", "added", "removed")),
        Option("noise", float, d["noise"], "Gaussian noise sigma, 8-bit code values", low=0.0,
               high=255.0),
        Option("supersample", int, d["supersample"], "samples per pixel side (anti-aliasing)",
               low=1, high=8),
    )


def _spec(name, **defaults) -> SceneSpec:
    """Every flow scene is render_flow with its own option defaults."""
    return SceneSpec(name, (320, 240), _options(**defaults), version=2, min_size=(32, 24))


SPECS = {
    "flow": _spec("flow"),
    "flow-large": _spec("flow-large", motion=44.0, object_motion=52.0),
    "flow-textureless": _spec("flow-textureless", textureless=True),
    "flow-brightness": _spec("flow-brightness", gain=0.6, offset=0.06, illumination=0.35),
    "flow-video": _spec("flow-video", motion=3.0, moving_object=False, gain=0.7, offset=0.05,
                        illumination=0.3, change="added"),
    "flow-sequence": _spec("flow-sequence", frames=5, motion=4.0, object_motion=6.0),
}
