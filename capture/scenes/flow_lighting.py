"""Lighting-change pairs with exact flow: the test family of video matching
(Sand & Teller 2004, reference §5.1.4).

Two takes of one scene: the second has a small camera shift (every layer
moves under its own affine map, nearer layers more), different lighting
(gain, offset, gamma, a left-right illumination gradient) and optionally an
object added to or removed from it. Several scene *kinds*, so a method tuned
on some can be judged on the others:

=============  ================================================================
kind           content
=============  ================================================================
``layers``     textured layered scene: a photo background and three textured
               rectangles at different depths (different motions, occlusions)
``natural``    one photo plane under a small homography (rotation, zoom)
``noise``      multi-scale value-noise texture with two textured discs
``cartoon``    flat colour regions: large textureless areas, edges carry
               the motion
``materials``  gravel background, a grass rectangle and a brick disc, each
               moving on its own (held out: never run while tuning)
=============  ================================================================

The frames are box filters of the continuous scene over each pixel
(``supersample``² samples), so the flow at the pixel centre (integer
coordinates, OpenCV's convention) is exact for the surface seen there.
Radiance ``r`` in [0, 1] becomes, in the second take,
``clip((gain * r**gamma) * (1 + illumination * ramp(x)) + offset)``, then
8-bit codes with ``noise`` code values of Gaussian noise.

Returns a :class:`LightingPair`: the two uint8 RGB frames, the exact flow
``(H, W, 2)`` (NaN where the surface has no counterpart), ``occluded``
(hidden, outside the frame or no counterpart), ``changed`` (the added or
removed object, in the reference frame's pixels) and ``textureless`` (the
reference's flat pixels, from the continuous scene).

Examples
--------
>>> p = render_lighting("layers", size=(64, 48), seed=0)
>>> p.frames[0].shape, p.flow.shape, p.frames[1].dtype.name
((48, 64, 3), (48, 64, 2), 'uint8')
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

KINDS = ("layers", "natural", "noise", "cartoon", "materials")
CHANGES = ("none", "added", "removed")

# Named lighting/scene variants of the family: each is a set of options of
# render_lighting. "mixed" combines all of them.
VARIANTS = {
    "gain": dict(gain=0.55, offset=0.08),
    "contrast": dict(gain=1.6, offset=-0.25),
    "gamma": dict(gamma=0.55, gain=0.9),
    "mixed": dict(gain=0.7, offset=0.06, gamma=1.4, illumination=0.3, change="added"),
    "removed": dict(gain=1.25, offset=-0.05, gamma=0.8, change="removed"),
}


@dataclass(frozen=True)
class LightingPair:
    frames: tuple[np.ndarray, np.ndarray]
    flow: np.ndarray
    occluded: np.ndarray
    changed: np.ndarray
    textureless: np.ndarray
    options: dict = field(default_factory=dict)

    @property
    def valid(self) -> np.ndarray:
        """Pixels with an observable, finite flow."""
        return ~self.occluded & np.isfinite(self.flow).all(axis=2)


def _photo(name: str, w: int, h: int) -> np.ndarray:
    import cv2
    import skimage.data

    img = getattr(skimage.data, name)()
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3].astype(np.float32) / 255.0
    s = max(w / img.shape[1], h / img.shape[0])
    size = (max(2, math.ceil(img.shape[1] * s)), max(2, math.ceil(img.shape[0] * s)))
    return np.clip(cv2.resize(img, size, interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_CUBIC),
                   0, 1)


def _value_noise(w: int, h: int, rng) -> np.ndarray:
    """Sum of bicubically upsampled random grids (octaves 4..64 px), RGB."""
    import cv2

    out = np.zeros((h, w, 3), np.float32)
    for cell, amp in ((64, 1.0), (32, 0.7), (16, 0.5), (8, 0.35), (4, 0.25)):
        g = rng.random((h // cell + 3, w // cell + 3, 3)).astype(np.float32)
        up = cv2.resize(g, ((w // cell + 3) * cell, (h // cell + 3) * cell),
                        interpolation=cv2.INTER_CUBIC)
        out += amp * up[:h, :w]
    out -= out.min()
    return out / out.max()


def _cartoon(w: int, h: int, rng) -> np.ndarray:
    """Flat colour polygons and discs; a faint fine texture on a few of them."""
    import cv2

    img = np.empty((h, w, 3), np.float32)
    img[:] = rng.uniform(0.2, 0.8, 3)
    for _ in range(14):
        col = tuple(float(c) for c in rng.uniform(0.05, 0.95, 3))
        if rng.random() < 0.5:
            c = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
            cv2.circle(img, c, int(rng.uniform(0.05, 0.18) * w), col, -1, cv2.LINE_AA)
        else:
            pts = np.stack([rng.uniform(0, w, 4), rng.uniform(0, h, 4)], -1).astype(np.int32)
            cv2.fillPoly(img, [cv2.convexHull(pts)], col, cv2.LINE_AA)
    return img


def _texture(kind_or_name: str, w: int, h: int, rng) -> np.ndarray:
    if kind_or_name == "noise":
        return _value_noise(w, h, rng)
    if kind_or_name == "cartoon":
        return _cartoon(w, h, rng)
    return _photo(kind_or_name, w, h)


def _affine(cx, cy, tx, ty, angle_deg=0.0, scale=1.0) -> np.ndarray:
    a = math.radians(angle_deg)
    c, s = math.cos(a) * scale, math.sin(a) * scale
    C = np.array([[1, 0, cx], [0, 1, cy], [0, 0, 1]], float)
    M = np.array([[c, -s, tx], [s, c, ty], [0, 0, 1]], float)
    return C @ M @ np.linalg.inv(C)


class _Layer:
    """A texture on a support (rectangle, disc or everything) in frame-0
    pixels, moving by ``motion`` (3x3, frame 0 -> frame 1)."""

    def __init__(self, tex, motion, shape=None, box=None, frames=(0, 1)):
        self.tex, self.motion, self.shape, self.box, self.frames = tex, motion, shape, box, frames

    def to_frame0(self, k, x, y):
        if k == 0:
            return x, y
        M = np.linalg.inv(self.motion)
        d = M[2, 0] * x + M[2, 1] * y + M[2, 2]
        return ((M[0, 0] * x + M[0, 1] * y + M[0, 2]) / d, (M[1, 0] * x + M[1, 1] * y + M[1, 2]) / d)

    def covers(self, k, x, y):
        if k not in self.frames:
            return np.zeros(x.shape, bool)
        u, v = self.to_frame0(k, x, y)
        if self.shape is None:
            return np.ones(x.shape, bool)
        x0, y0, x1, y1 = self.box
        if self.shape == "rect":
            return (u >= x0) & (u <= x1) & (v >= y0) & (v <= y1)
        cx, cy, rx, ry = (x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2, (y1 - y0) / 2
        return ((u - cx) / rx) ** 2 + ((v - cy) / ry) ** 2 <= 1

    def sample(self, k, x, y):
        import cv2

        u, v = self.to_frame0(k, x, y)
        m = 8  # textures are padded by 8 px around the frame
        return cv2.remap(self.tex, (u + m).astype(np.float32), (v + m).astype(np.float32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)


def _layers(kind, w, h, rng, shift, change):
    """Back-to-front layers of one scene kind."""
    W, H = w + 16, h + 16
    phi = rng.uniform(0, 2 * math.pi)
    dx, dy = shift * math.cos(phi), shift * math.sin(phi)
    cam = _affine(w / 2, h / 2, dx, dy, rng.uniform(-0.5, 0.5), 1 + rng.uniform(-0.01, 0.01))
    photos = ("coffee", "astronaut", "chelsea", "rocket", "immunohistochemistry")
    out = []
    if kind == "layers":
        names = list(rng.permutation(photos))
        out.append(_Layer(_texture(names[0], W, H, rng), cam))
        for i in range(3):
            bw, bh = w * rng.uniform(0.2, 0.32), h * rng.uniform(0.25, 0.4)
            x0, y0 = rng.uniform(0.05, 0.95) * (w - bw), rng.uniform(0.05, 0.95) * (h - bh)
            depth = 1.0 + 0.6 * (i + 1)  # nearer layers move more (parallax)
            mot = _affine(x0 + bw / 2, y0 + bh / 2, dx * depth, dy * depth, rng.uniform(-1, 1))
            out.append(_Layer(_texture(names[i + 1], W, H, rng), mot, "rect", (x0, y0, x0 + bw, y0 + bh)))
    elif kind == "natural":
        name = photos[int(rng.integers(len(photos)))]
        H3 = cam.copy()
        H3[2, :2] = rng.uniform(-2e-5, 2e-5, 2) * 320 / w  # a little perspective
        out.append(_Layer(_texture(name, W, H, rng), H3))
    elif kind == "noise":
        out.append(_Layer(_value_noise(W, H, rng), cam))
        for _ in range(2):
            r = w * rng.uniform(0.1, 0.16)
            cx, cy = rng.uniform(r, w - r), rng.uniform(r, h - r)
            psi = rng.uniform(0, 2 * math.pi)
            mot = _affine(cx, cy, dx + 2.5 * math.cos(psi), dy + 2.5 * math.sin(psi), rng.uniform(-2, 2))
            out.append(_Layer(_value_noise(W, H, rng), mot, "disc", (cx - r, cy - r, cx + r, cy + r)))
    elif kind == "cartoon":
        out.append(_Layer(_cartoon(W, H, rng), cam))
        r = w * 0.14
        cx, cy = rng.uniform(r, w - r), rng.uniform(r, h - r)
        mot = _affine(cx, cy, dx * 1.8, dy * 1.8)
        out.append(_Layer(_cartoon(W, H, rng), mot, "disc", (cx - r, cy - r, cx + r, cy + r)))
    elif kind == "materials":
        out.append(_Layer(_texture("gravel", W, H, rng), cam))
        for shape, name in (("rect", "grass"), ("disc", "brick")):
            bw, bh = w * rng.uniform(0.25, 0.35), h * rng.uniform(0.3, 0.45)
            x0, y0 = rng.uniform(0.05, 0.95) * (w - bw), rng.uniform(0.05, 0.95) * (h - bh)
            psi = rng.uniform(0, 2 * math.pi)
            m = rng.uniform(1.5, 4.0)
            mot = _affine(x0 + bw / 2, y0 + bh / 2, dx + m * math.cos(psi), dy + m * math.sin(psi),
                          rng.uniform(-1.5, 1.5))
            out.append(_Layer(_texture(name, W, H, rng), mot, shape, (x0, y0, x0 + bw, y0 + bh)))
    else:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    if change != "none":
        bw, bh = 0.2 * w, 0.28 * h
        x0, y0 = rng.uniform(0.1, 0.7) * w, rng.uniform(0.1, 0.6) * h
        frames = (1,) if change == "added" else (0,)
        # Attached to the background (moves with the camera), like a teapot on a table.
        out.append(_Layer(_texture("brick", W, H, rng) * 0.8 + 0.1, cam, "rect",
                          (x0, y0, x0 + bw, y0 + bh), frames=frames))
    return out


def _top(layers, k, x, y):
    lab = np.full(x.shape, -1, np.int16)
    for i, L in enumerate(layers):
        lab[L.covers(k, x, y)] = i
    return lab


def _frame(layers, k, w, h, s):
    offs = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(w)[:, None] + offs[None, :]).ravel()
    ys = (np.arange(h)[:, None] + offs[None, :]).ravel()
    X, Y = np.meshgrid(xs, ys)
    lab = _top(layers, k, X, Y)
    img = np.zeros(X.shape + (3,), np.float32)
    for i, L in enumerate(layers):
        m = lab == i
        if m.any():
            img[m] = L.sample(k, X, Y)[m]
    return img.reshape(h, s, w, s, 3).mean(axis=(1, 3))


def render_lighting(kind: str, *, size=(320, 240), seed: int = 0, shift: float = 3.0,
                    gain: float = 1.0, offset: float = 0.0, gamma: float = 1.0,
                    illumination: float = 0.0, change: str = "none", noise: float = 1.0,
                    supersample: int = 2) -> LightingPair:
    """Render one pair of the lighting-change family (module docstring).

    Parameters
    ----------
    kind : one of :data:`KINDS`
    size : (width, height) px
    shift : float
        Camera translation between the takes, px (nearer layers move up to 2.8x).
    gain, offset, gamma, illumination : float
        Photometric change of the second take (radiance in [0, 1]).
    change : one of :data:`CHANGES`
        An object added to the second take or removed from it.
    noise : float
        Gaussian noise sigma, 8-bit codes.

    Examples
    --------
    >>> p = render_lighting("cartoon", size=(48, 32), seed=1, change="added")
    >>> bool(p.changed.any()), bool(np.isfinite(p.flow).all())    # added: all flows exist
    (True, True)
    """
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    if change not in CHANGES:
        raise ValueError(f"change: expected one of {CHANGES}, got {change!r}")
    w, h = size
    rng = np.random.default_rng([seed, KINDS.index(kind)])
    layers = _layers(kind, w, h, rng, shift, change)
    rad = [_frame(layers, k, w, h, supersample) for k in (0, 1)]
    ramp = np.linspace(-1, 1, w, dtype=np.float32)[None, :, None]
    lit1 = gain * np.power(np.clip(rad[1], 0, 1), gamma) * (1 + illumination * ramp) + offset
    frames = []
    for img in (rad[0], lit1):
        codes = 255.0 * img + (rng.normal(0, noise, img.shape) if noise > 0 else 0)
        frames.append(np.clip(np.rint(codes), 0, 255).astype(np.uint8))
    cx, cy = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    lab0 = _top(layers, 0, cx, cy)
    flow = np.zeros((h, w, 2), np.float64)
    for i, L in enumerate(layers):
        m = lab0 == i
        M = L.motion
        tx = M[0, 0] * cx + M[0, 1] * cy + M[0, 2]
        ty = M[1, 0] * cx + M[1, 1] * cy + M[1, 2]
        d = M[2, 0] * cx + M[2, 1] * cy + M[2, 2]
        flow[m, 0] = (tx / d - cx)[m]
        flow[m, 1] = (ty / d - cy)[m]
    tx, ty = cx + flow[..., 0], cy + flow[..., 1]
    changed = np.zeros((h, w), bool)
    if change == "removed":
        changed = lab0 == len(layers) - 1
        flow[changed] = np.nan
    lab1 = _top(layers, 1, tx, ty)
    outside = (tx < -0.5) | (tx > w - 0.5) | (ty < -0.5) | (ty > h - 0.5)
    occluded = outside | changed | (lab1 != lab0)
    if change == "added":
        # Pixels of frame 0 whose target is covered by the added object.
        changed = lab1 == len(layers) - 1
    # Flat: the reference's radiance has no gradient over a 5x5 window.
    import cv2

    g = cv2.cvtColor(rad[0].astype(np.float32), cv2.COLOR_RGB2GRAY)
    gx, gy = cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1)
    energy = cv2.boxFilter(gx * gx + gy * gy, -1, (5, 5))
    textureless = energy < 1e-6
    opts = dict(kind=kind, size=size, seed=seed, shift=shift, gain=gain, offset=offset,
                gamma=gamma, illumination=illumination, change=change, noise=noise)
    return LightingPair((frames[0], frames[1]), flow.astype(np.float32), occluded, changed,
                        textureless, opts)

