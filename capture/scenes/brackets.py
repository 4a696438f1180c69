"""``bracket`` and ``bracket_video``: exposure brackets of a high-dynamic-range scene.

The scene is analytic, so its linear radiance is exact ground truth: a room
textured with scikit-image's ``coffee`` photograph (sRGB-decoded to linear
albedo) under a smooth light gradient, a deep shadow on the left, a window on
the upper right showing ``rocket`` in daylight, Gaussian specular highlights
and three small emitters. In-frame dynamic range is about 10⁷ : 1.
``--kind`` picks another scene of the family (:data:`KINDS`): ``walls`` (a
box of large uniform walls under a lamp), ``outdoor`` (sky, sun and a doorway
in deep shadow), ``night`` (a street at night, mostly dark, with lamps),
``studio`` (a low-texture backdrop and two matte spheres). :data:`FAMILY`
gives each kind its own camera (response, noise, bracket) and
:func:`bracket_family` lists the bench's cases, kinds × seeds × bit depths,
labelled ``tuned`` or ``reported`` (held out).

Camera model (reference ch. 6, eq. 6.1-6.2): relative exposure
``X = k · L · e`` with ``e = Δt · (N_ref / N)²`` (time, and f-number ``N`` for
aperture brackets) and ``k`` per second (``gt.json``: ``exposure_scale``);
``X = 1`` fills the well. Noise is added in electrons before the response:
shot noise (Gaussian with variance equal to the count, the Poisson limit) and
read noise, ``X_noisy = (n_e + N(0, sqrt(n_e + σ_read²))) / full_well``;
then the response ``f`` maps ``clip(X_noisy, 0, 1)`` to codes
``round(f(·) · (2**bit_depth − 1))``.

Responses (``--response``): ``film`` — a per-channel Naka–Rushton S-curve
``f(X) = X^γ/(X^γ + s^γ) · (1 + s^γ)`` with different ``γ, s`` per channel
(an H&D-like sigmoid in log exposure with a toe and a shoulder); ``scurve``
— the same form, steeper; ``toe`` — the sRGB OETF (a linear toe); ``log`` —
``ln(1 + aX)/ln(1 + a)`` per channel; ``gamma`` — ``X^(1/2.2)``; ``linear`` — ``X``. ``gt/g.npy`` is the exact
``ln f⁻¹(z / z_max)`` table (``(3, 2**bit_depth)``; code 0 evaluated at half
a code); ``gt/radiance.npy`` the radiance ``(H, W, 3)`` float32.

Exposure times: nominal ``Δt_j = t_min · 2^(stops·j)`` (a camera's dial); the
exact ones differ from them by up to ``--time-error`` (uniform, seeded) as a
real shutter does. ``gt.json`` holds both; ``stack.json`` carries
``--stack-times exact|nominal``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import Option, RenderedScene, SceneSpec

# Per-channel film curve parameters (gamma, s): the channels differ, as dye
# layers of a colour film do.
FILM = ((1.35, 0.16), (1.15, 0.20), (0.95, 0.26))
# A steeper S-curve (a contrasty slide film / camera "vivid" look): toe and
# shoulder both pronounced, channels differ.
SCURVE = ((1.9, 0.34), (1.7, 0.30), (1.8, 0.40))
GAMMA = 2.2
# ``log``: a camera log encoding ``f(X) = ln(1 + a X) / ln(1 + a)``, ``a`` per channel.
LOG_A = (40.0, 60.0, 90.0)
RESPONSES = ("film", "scurve", "toe", "log", "gamma", "linear")


def response_params(kind: str):
    """The JSON-able parameters of response ``kind`` (``gt.json``: ``response_params``)."""
    return {"film": [list(p) for p in FILM], "scurve": [list(p) for p in SCURVE],
            "gamma": GAMMA, "log": list(LOG_A), "toe": "sRGB OETF (IEC 61966-2-1)",
            "linear": None}[kind]


# ---------------------------------------------------------------- responses
def response_forward(x: np.ndarray, kind: str, channel: int) -> np.ndarray:
    """``f(X)`` in [0, 1] for exposure ``X >= 0`` (clipped at 1 above saturation).

    ``film``/``scurve``: Naka–Rushton ``X^γ/(X^γ + s^γ) · (1 + s^γ)`` per
    channel; ``toe``: the sRGB OETF (a linear toe, then ``1.055 X^(1/2.4) −
    0.055``); ``log``: ``ln(1 + aX)/ln(1 + a)``; ``gamma``: ``X^(1/2.2)``;
    ``linear``: ``X``.

    Examples
    --------
    >>> [round(float(response_forward(np.array(1.0), k, 0)), 12) for k in ("film", "toe", "log")]
    [1.0, 1.0, 1.0]
    """
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    if kind == "linear":
        return x
    if kind == "gamma":
        return x ** (1.0 / GAMMA)
    if kind in ("film", "scurve"):
        gam, s = (FILM if kind == "film" else SCURVE)[channel]
        xg = x ** gam
        return np.minimum(xg / (xg + s ** gam) * (1.0 + s ** gam), 1.0)
    if kind == "toe":
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    if kind == "log":
        a = LOG_A[channel]
        return np.log1p(a * x) / np.log1p(a)
    raise ValueError(f"kind: expected one of {', '.join(RESPONSES)}, got {kind!r}")


def response_inverse(y: np.ndarray, kind: str, channel: int) -> np.ndarray:
    """``f⁻¹(y)`` for normalised code ``y`` in [0, 1] (exact inverse of
    :func:`response_forward`).

    Examples
    --------
    >>> y = response_forward(np.array([0.01, 0.3]), "film", 2)
    >>> np.allclose(response_inverse(y, "film", 2), [0.01, 0.3])
    True
    """
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0)
    if kind == "linear":
        return y
    if kind == "gamma":
        return y ** GAMMA
    if kind in ("film", "scurve"):
        gam, s = (FILM if kind == "film" else SCURVE)[channel]
        u = y / (1.0 + s ** gam)
        with np.errstate(divide="ignore"):
            return s * (u / (1.0 - u)) ** (1.0 / gam)
    if kind == "toe":
        return np.where(y <= 12.92 * 0.0031308, y / 12.92, ((y + 0.055) / 1.055) ** 2.4)
    if kind == "log":
        a = LOG_A[channel]
        return np.expm1(y * np.log1p(a)) / a
    raise ValueError(f"kind: expected one of {', '.join(RESPONSES)}, got {kind!r}")


def gt_log_inverse(kind: str, bit_depth: int) -> np.ndarray:
    """The exact table ``g[c, z] = ln f⁻¹(z / z_max)``, ``(3, 2**bit_depth)`` float64
    (code 0 evaluated at half a code so the table is finite)."""
    zmax = 2 ** bit_depth - 1
    z = np.arange(zmax + 1, dtype=np.float64)
    z[0] = 0.5
    return np.stack([np.log(response_inverse(z / zmax, kind, c)) for c in range(3)])


# -------------------------------------------------------------------- scene
def _srgb_to_linear(img: np.ndarray) -> np.ndarray:
    v = img.astype(np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _texture(name: str, w: int, h: int, shift=(0.0, 0.0), pad: int = 0) -> np.ndarray:
    import cv2
    import skimage.data

    img = _srgb_to_linear(getattr(skimage.data, name)())
    th, tw = img.shape[:2]
    scale = max((w + 2 * pad) / tw, (h + 2 * pad) / th)
    # Affine: output pixel (x, y) samples the texture at ((x + pad - dx)/scale, …).
    m = np.array([[scale, 0, shift[0] - pad * 0], [0, scale, shift[1]]], np.float64)
    out = cv2.warpAffine(img.astype(np.float32), m, (w, h), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REFLECT)
    return out.astype(np.float64)


def scene_radiance(w: int, h: int, *, shift=(0.0, 0.0), emitter_shift=(0.0, 0.0)) -> np.ndarray:
    """The exact linear radiance ``(H, W, 3)`` float64 of the HDR room.

    ``shift`` translates the whole scene (camera pan, pixels), ``emitter_shift``
    moves the brightest emitter further (an independently moving light).

    Examples
    --------
    >>> r = scene_radiance(64, 48)
    >>> r.shape, bool(r.max() / r.min() > 1e4)
    ((48, 64, 3), True)
    """
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    xs = (xs - shift[0]) / max(w - 1, 1)
    ys = (ys - shift[1]) / max(h - 1, 1)
    albedo = 0.03 + 0.9 * _texture("coffee", w, h, shift=shift)
    light = 0.35 * np.exp(1.2 * (1.0 - ys))[..., None] * np.ones(3)
    with np.errstate(over="ignore"):  # far left of a long pan: exp -> inf, the shadow -> 0
        shadow = 1.0 / (1.0 + np.exp(-(xs - 0.28) / 0.02))  # 0 in the left shadow, 1 outside
    light = light * (0.008 + 0.992 * shadow)[..., None]
    rad = albedo * light
    window = (xs > 0.62) & (xs < 0.95) & (ys > 0.08) & (ys < 0.5)
    outdoor = 0.05 + _texture("rocket", w, h, shift=shift)
    rad = np.where(window[..., None], 60.0 * outdoor * np.array([0.95, 1.0, 1.08]), rad)
    # Specular highlights: peaked, smooth (so every code level between the
    # surface and the peak is visited).
    for cx, cy, sig, peak in ((0.35, 0.7, 0.025, 40.0), (0.5, 0.82, 0.015, 120.0)):
        d2 = (xs - cx) ** 2 + ((ys - cy) * h / w) ** 2
        rad = rad + peak * np.exp(-d2 / (2 * sig ** 2))[..., None] * np.array([1.0, 0.97, 0.9])
    emitters = ((0.15, 0.2, 0.022, 3000.0, (1.0, 0.85, 0.6)),
                (0.52, 0.3, 0.03, 400.0, (0.8, 0.9, 1.0)),
                (0.8, 0.75, 0.02, 150.0, (1.0, 0.6, 0.5)))
    for i, (cx, cy, r, val, col) in enumerate(emitters):
        ex = cx + (emitter_shift[0] / max(w - 1, 1) if i == 0 else 0.0)
        ey = cy + (emitter_shift[1] / max(h - 1, 1) if i == 0 else 0.0)
        d = np.sqrt((xs - ex) ** 2 + ((ys - ey) * h / w) ** 2)
        disk = np.clip((r - d) * w + 0.5, 0.0, 1.0)  # anti-aliased edge, one pixel wide
        rad = rad * (1 - disk[..., None]) + disk[..., None] * val * np.array(col)
    return rad


# ------------------------------------------------------- the bracket family
# Scene kinds besides the HDR room: brackets we did not tune on (issue 13).
# Every radiance is analytic (smooth shading, anti-aliased edges, Gaussian
# glows), so each code between a surface and a light is visited and the
# radiance is exact at every pixel.
KINDS = ("room", "walls", "outdoor", "night", "studio")


def _value_noise(w: int, h: int, key: int, cells: int, octaves: int = 3) -> np.ndarray:
    """Smooth value noise in [0, 1], ``(H, W)``; ``key`` fixes the pattern
    (the scene, not the render seed: the radiance of a kind is one scene)."""
    import cv2

    rng = np.random.default_rng(key)
    out = np.zeros((h, w))
    amp, total = 1.0, 0.0
    for o in range(octaves):
        n = cells * 2 ** o
        grid = rng.random((max(2, n * h // max(w, 1)), n)).astype(np.float32)
        out += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
        amp *= 0.5
    out /= total
    return np.clip((out - out.min()) / max(np.ptp(out), 1e-12), 0.0, 1.0)


def _disk(xs, ys, cx, cy, r, w, h):
    """Anti-aliased disk (one pixel wide edge) in normalised coordinates."""
    d = np.sqrt((xs - cx) ** 2 + ((ys - cy) * h / w) ** 2)
    return np.clip((r - d) * w + 0.5, 0.0, 1.0)


def _box(xs, ys, x0, x1, y0, y1, w, h):
    """Anti-aliased axis-aligned rectangle."""
    fx = np.clip(np.minimum(xs - x0, x1 - xs) * w + 0.5, 0.0, 1.0)
    fy = np.clip(np.minimum(ys - y0, y1 - ys) * h + 0.5, 0.0, 1.0)
    return fx * fy


def _grid(w, h):
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return xs / max(w - 1, 1), ys / max(h - 1, 1)


def _walls(w, h):
    """A box seen from inside: five large uniform walls under one ceiling lamp
    (smooth inverse-square falloff), a bright window in the right wall."""
    xs, ys = _grid(w, h)
    # One-point perspective: the back wall is the central rectangle; the
    # side walls, floor and ceiling are the four trapezoids around it.
    u, v = (xs - 0.5) / 0.22, (ys - 0.5) / 0.2
    back = (np.abs(u) <= 1) & (np.abs(v) <= 1)
    side = np.abs(u) >= np.abs(v)
    albedo = np.where(back[..., None], [0.72, 0.70, 0.64],
                      np.where(side[..., None],
                               np.where((u < 0)[..., None], [0.62, 0.30, 0.22], [0.25, 0.38, 0.62]),
                               np.where((v > 0)[..., None], [0.38, 0.30, 0.22], [0.85, 0.85, 0.82])))
    # Lamp below the ceiling, centre top; irradiance ~ 1/(1 + d^2).
    d2 = (xs - 0.5) ** 2 + ((ys - 0.18) * h / w) ** 2
    light = 0.02 + 0.6 / (1.0 + d2 / 0.02)
    rad = albedo * light[..., None]
    win = _box(xs, ys, 0.80, 0.93, 0.30, 0.62, w, h)
    rad = rad * (1 - win[..., None]) + win[..., None] * 25.0 * np.array([0.9, 1.0, 1.1])
    lamp = _disk(xs, ys, 0.5, 0.1, 0.035, w, h)
    glow = 8.0 * np.exp(-d2 / (2 * 0.05 ** 2))[..., None] * np.array([1.0, 0.9, 0.75])
    rad = rad + glow
    return rad * (1 - lamp[..., None]) + lamp[..., None] * 400.0 * np.array([1.0, 0.9, 0.75])


def _outdoor(w, h):
    """Sky with a sun and its glow over a textured sunlit ground; a building on
    the left whose doorway is in deep shadow."""
    xs, ys = _grid(w, h)
    horizon = 0.45
    sky = (4.0 + 6.0 * np.clip(ys / horizon, 0, 1) ** 2)[..., None] * np.array([0.55, 0.75, 1.15])
    d2 = (xs - 0.72) ** 2 + ((ys - 0.12) * h / w) ** 2
    sky = sky + 400.0 * np.exp(-d2 / (2 * 0.04 ** 2))[..., None] * np.array([1.0, 0.95, 0.85])
    tex = _value_noise(w, h, 101, 6)
    ground = (0.08 + 0.3 * tex)[..., None] * np.array([0.55, 0.7, 0.35]) * 6.0
    is_sky = np.clip((horizon - ys) * h + 0.5, 0, 1)[..., None]
    rad = is_sky * sky + (1 - is_sky) * ground
    bld = _box(xs, ys, -0.1, 0.38, 0.15, 1.1, w, h)[..., None]
    facade = (0.25 + 0.35 * _value_noise(w, h, 102, 10))[..., None] * np.array([0.7, 0.6, 0.5])
    facade = facade * (0.15 + 0.25 * xs)[..., None]  # in its own shade, lit by the sky
    rad = rad * (1 - bld) + bld * facade
    door = _box(xs, ys, 0.1, 0.24, 0.55, 0.98, w, h)[..., None]
    deep = (0.2 + 0.5 * tex)[..., None] * np.array([0.5, 0.5, 0.55]) * 0.004 * (1.2 - ys)[..., None]
    rad = rad * (1 - door) + door * deep
    sun = _disk(xs, ys, 0.72, 0.12, 0.018, w, h)[..., None]
    return rad * (1 - sun) + sun * 8000.0 * np.array([1.0, 0.97, 0.9])


def _night(w, h):
    """A night street: dark sky and houses, most pixels near black; street lamps
    (point lights with glows and pools of light on the road), lit windows."""
    xs, ys = _grid(w, h)
    tex = _value_noise(w, h, 201, 8)
    rad = (0.002 + 0.002 * (1 - ys))[..., None] * np.array([0.3, 0.4, 0.8]) * np.ones((h, w, 3))
    road = ys > 0.7
    road_alb = (0.05 + 0.2 * tex)[..., None] * np.array([0.5, 0.5, 0.5])
    houses = _box(xs, ys, 0.0, 1.0, 0.3, 0.7, w, h)[..., None]
    rad = rad * (1 - houses) + houses * (0.001 + 0.004 * tex)[..., None] * np.array([0.6, 0.5, 0.45])
    for i, x0 in enumerate((0.08, 0.3, 0.55, 0.78)):
        win = _box(xs, ys, x0, x0 + 0.07, 0.42, 0.52, w, h)[..., None]
        rad = rad * (1 - win) + win * (0.6 + 0.3 * i) * np.array([1.0, 0.75, 0.4])
    pool = np.zeros((h, w))
    for cx in (0.2, 0.5, 0.85):
        d2 = (xs - cx) ** 2 + ((ys - 0.2) * h / w) ** 2
        rad = rad + 30.0 * np.exp(-d2 / (2 * 0.03 ** 2))[..., None] * np.array([1.0, 0.8, 0.5])
        rad = rad + 0.1 * np.exp(-d2 / (2 * 0.08 ** 2))[..., None] * np.array([1.0, 0.8, 0.5])
        pool += 1.5 * np.exp(-((xs - cx) ** 2 + ((ys - 0.85) * 2.5) ** 2) / (2 * 0.07 ** 2))
    rad = np.where(road[..., None], road_alb * (0.01 + pool)[..., None] * np.array([1.0, 0.8, 0.5])
                   + rad * 0.0, rad)
    for cx in (0.2, 0.5, 0.85):
        lamp = _disk(xs, ys, cx, 0.2, 0.012, w, h)[..., None]
        rad = rad * (1 - lamp) + lamp * 3000.0 * np.array([1.0, 0.8, 0.5])
    return rad


def _studio(w, h):
    """A low-texture studio shot: a seamless grey backdrop lit from the upper
    left, two matte spheres with soft shading and a small highlight."""
    xs, ys = _grid(w, h)
    light = 0.35 + 0.65 * np.exp(-((xs - 0.2) ** 2 + (ys - 0.1) ** 2) / 0.5)
    back = (0.5 + 0.02 * _value_noise(w, h, 301, 4))[..., None] * np.array([0.6, 0.6, 0.62])
    rad = back * light[..., None]
    ldir = np.array([-0.5, -0.6, 0.62])
    ldir = ldir / np.linalg.norm(ldir)
    for cx, cy, r, col in ((0.35, 0.6, 0.16, (0.75, 0.3, 0.2)), (0.7, 0.55, 0.12, (0.2, 0.5, 0.3))):
        dx, dy = (xs - cx) / r, (ys - cy) * h / w / r
        rr = dx ** 2 + dy ** 2
        nz = np.sqrt(np.clip(1 - rr, 0, 1))
        shade = np.clip(dx * ldir[0] + dy * ldir[1] + nz * ldir[2], 0, 1)
        spec = 12.0 * np.clip(dx * 0.0 + shade, 0, 1) ** 60
        sphere = (0.04 + 0.96 * shade)[..., None] * np.array(col) + spec[..., None]
        m = _disk(xs, ys, cx, cy, r, w, h)[..., None]
        rad = rad * (1 - m) + m * sphere
    return rad


def kind_radiance(kind: str, w: int, h: int) -> np.ndarray:
    """The exact linear radiance ``(H, W, 3)`` float64 of scene ``kind``
    (:data:`KINDS`; ``room`` is :func:`scene_radiance`).

    Examples
    --------
    >>> [kind_radiance(k, 32, 24).shape for k in ("walls", "night")]
    [(24, 32, 3), (24, 32, 3)]
    """
    if kind == "room":
        return scene_radiance(w, h)
    fn = {"walls": _walls, "outdoor": _outdoor, "night": _night, "studio": _studio}.get(kind)
    if fn is None:
        raise InputError("kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
    return np.maximum(fn(w, h), 1e-6)  # radiance is positive: ln L is finite everywhere


def expose(radiance: np.ndarray, e: float, *, response: str, bit_depth: int, rng,
           noise: float, full_well: float, read_noise: float,
           exposure_scale: float) -> np.ndarray:
    """Codes a camera delivers for ``radiance`` at relative exposure ``e``
    (seconds · (N_ref/N)²); see the module docstring for the model."""
    x = exposure_scale * radiance * e
    if noise > 0:
        electrons = np.minimum(x, 4.0) * full_well
        sigma = noise * np.sqrt(electrons + read_noise ** 2)
        x = (electrons + rng.normal(0.0, 1.0, x.shape) * sigma) / full_well
    zmax = 2 ** bit_depth - 1
    y = np.stack([response_forward(x[..., c], response, c) for c in range(3)], axis=-1)
    codes = np.clip(np.round(y * zmax), 0, zmax)
    return codes.astype(np.uint8 if bit_depth <= 8 else np.uint16)


def _common(bit_depth, exposures, stops, min_time, response, noise, full_well, read_noise,
            time_error, stack_times, rng):
    nominal = min_time * 2.0 ** (stops * np.arange(exposures))
    exact = nominal * (1.0 + rng.uniform(-time_error, time_error, exposures))
    gt = {"response": response, "film_params": [list(p) for p in FILM] if response == "film" else None,
          "gamma": GAMMA if response == "gamma" else None,
          **({} if response in ("film", "gamma", "linear") else
             {"response_params": response_params(response)}),
          "exposure_times_exact_s": exact.tolist(), "exposure_times_nominal_s": nominal.tolist(),
          "full_well_e": full_well, "read_noise_e": read_noise, "noise_scale": noise,
          "stack_times": stack_times, "model": "X = exposure_scale * L * t * (N_ref/N)^2; "
                                              "codes = round(f(clip(X_noisy,0,1)) * (2^b-1))"}
    return nominal, exact, gt


def render_bracket(*, size, seed, rng, bit_depth=8, exposures=7, stops=1.5, min_time=1 / 1000,
                   response="film", noise=1.0, full_well=20000.0, read_noise=4.0,
                   time_error=0.03, stack_times="exact", vary="time", exposure_scale=10.0,
                   kind="room"):
    """A static exposure bracket with exact radiance, response and times.

    Examples
    --------
    >>> s = render_bracket(size=(32, 24), seed=0, rng=np.random.default_rng(0), exposures=3)
    >>> len(s.images), s.images[0].dtype.name, s.gt_arrays["g"].shape
    (3, 'uint8', (3, 256))
    """
    w, h = size
    nominal, exact, gt = _common(bit_depth, exposures, stops, min_time, response, noise,
                                 full_well, read_noise, time_error, stack_times, rng)
    rad = kind_radiance(kind, w, h)
    stack = {"bit_depth": bit_depth, "linear": response == "linear"}
    if vary == "aperture":
        # Fixed shutter; the f-number closes by stops/2 per frame from f/22 down.
        n_ref = 2.0
        f_exact = n_ref / np.sqrt(exact / exact[-1]) * 1.0
        f_nominal = n_ref / np.sqrt(nominal / nominal[-1])
        t_fixed = float(nominal[-1])
        e_exact = t_fixed * (n_ref / f_exact) ** 2
        gt.update({"f_numbers_exact": f_exact.tolist(), "f_numbers_nominal": f_nominal.tolist(),
                   "shutter_s": t_fixed, "f_number_ref": n_ref,
                   "relative_exposure_exact": e_exact.tolist()})
        stack["f_numbers"] = (f_exact if stack_times == "exact" else f_nominal).tolist()
        stack["f_number_ref"] = n_ref
        stack["exposure_times_s"] = [t_fixed] * exposures
        es = e_exact
    else:
        stack["exposure_times_s"] = (exact if stack_times == "exact" else nominal).tolist()
        es = exact
    images = tuple(expose(rad, float(e), response=response, bit_depth=bit_depth, rng=rng,
                          noise=noise, full_well=full_well, read_noise=read_noise,
                          exposure_scale=exposure_scale) for e in es)
    gt["exposure_scale"] = exposure_scale
    gt["vary"] = vary
    gt["kind"] = kind
    gt["dynamic_range"] = float(rad.max() / rad.min())
    names = tuple(f"exposure_{j:02d}.png" for j in range(exposures))
    return RenderedScene("bracket", {}, images, names, stack=stack, gt=gt,
                         gt_arrays={"radiance": rad.astype(np.float32),
                                    "g": gt_log_inverse(response, bit_depth)})


def render_bracket_video(*, size, seed, rng, bit_depth=8, frames=8, stops=3.0, min_time=1 / 500,
                         response="film", noise=1.0, full_well=20000.0, read_noise=4.0,
                         pan=1.5, light_speed=2.0, exposure_scale=10.0):
    """HDR video: frames alternate short and long exposures (``stops`` apart)
    while the camera pans ``pan`` px/frame to the right and the brightest
    light moves another ``light_speed`` px/frame down. Ground truth: radiance
    per frame ``(F, H, W, 3)`` and the per-frame scene shift.

    Examples
    --------
    >>> s = render_bracket_video(size=(32, 24), seed=0, rng=np.random.default_rng(0), frames=2)
    >>> s.gt_arrays["radiance"].shape, s.stack["exposure_times_s"][1] / s.stack["exposure_times_s"][0]
    ((2, 24, 32, 3), 8.0)
    """
    w, h = size
    times = np.array([min_time * (2.0 ** stops if f % 2 else 1.0) for f in range(frames)])
    rads, shifts, images = [], [], []
    for f in range(frames):
        shift = (pan * f, 0.0)
        rad = scene_radiance(w, h, shift=shift, emitter_shift=(0.0, light_speed * f))
        rads.append(rad.astype(np.float32))
        shifts.append(list(shift))
        images.append(expose(rad, float(times[f]), response=response, bit_depth=bit_depth,
                             rng=rng, noise=noise, full_well=full_well, read_noise=read_noise,
                             exposure_scale=exposure_scale))
    gt = {"response": response, "exposure_times_exact_s": times.tolist(),
          "scene_shift_px": shifts, "light_speed_px": light_speed, "pan_px": pan,
          "full_well_e": full_well, "read_noise_e": read_noise, "noise_scale": noise,
          "exposure_scale": exposure_scale,
          "flow_note": "background flow from frame f to f+1 is (+pan, 0) px; the brightest "
                       "emitter moves (pan, light_speed) px"}
    names = tuple(f"frame_{f:03d}.png" for f in range(frames))
    return RenderedScene("bracket_video", {}, tuple(images), names,
                         stack={"bit_depth": bit_depth, "exposure_times_s": times.tolist(),
                                "video": True, "linear": response == "linear"},
                         gt=gt, gt_arrays={"radiance": np.stack(rads),
                                           "g": gt_log_inverse(response, bit_depth)})


def _positive_finite(name, v):
    if not math.isfinite(v) or v <= 0:
        raise InputError(name, f"expected a positive exposure, got {v}")


_CAMERA_OPTIONS = (
    Option("bit_depth", int, 8, "sensor bit depth (8..16; 10/12/16 are written as 16-bit PNG "
                                "with sBIT)", low=8, high=16),
    Option("response", str, "film", "camera response (film, scurve: per-channel S-curves; toe: "
                                    "sRGB; log: camera log; gamma 2.2; linear)", choices=RESPONSES),
    # The upper bounds keep every product of the sensor model finite (beyond
    # them a render overflows: inf electrons, NaN codes, null exposure times).
    Option("noise", float, 1.0, "noise scale (0 = noise-free, 1 = shot + read noise)", low=0.0,
           high=100.0),
    Option("full_well", float, 20000.0, "electrons at saturation (shot noise)", low=1.0,
           high=1e9),
    Option("read_noise", float, 4.0, "read noise, electrons RMS", low=0.0, high=1e6),
    Option("exposure_scale", float, 10.0, "X = scale * radiance * time (X = 1 saturates)",
           low=0.0, open_low=True, high=1e9),
)

SPECS = {
    "bracket": SceneSpec(
        "bracket", (160, 120),
        _CAMERA_OPTIONS + (
            Option("exposures", int, 7, "number of exposures P", low=1, high=32),
            Option("stops", float, 1.5, "spacing between exposures, in stops", low=0.0,
                   open_low=True, high=8.0),
            Option("min_time", float, 1 / 1000, "shortest nominal exposure, seconds", low=0.0,
                   open_low=True, high=1e4),
            Option("time_error", float, 0.03, "exact times differ from nominal by up to this "
                                              "fraction", low=0.0, high=0.5),
            Option("stack_times", str, "exact", "times written to stack.json",
                   choices=("exact", "nominal")),
            Option("vary", str, "time", "bracket by shutter time or by aperture",
                   choices=("time", "aperture")),
            Option("kind", str, "room", "scene: room (HDR room), walls (large uniform walls), "
                                        "outdoor (sky, sun, deep shadow), night (street lamps, "
                                        "mostly dark), studio (low texture); FAMILY holds each "
                                        "kind's camera", choices=KINDS),
        ), version=2),
    "bracket_video": SceneSpec(
        "bracket_video", (160, 120),
        _CAMERA_OPTIONS + (
            Option("frames", int, 8, "number of frames", low=2, high=240),
            Option("stops", float, 3.0, "long/short exposure ratio, in stops", low=0.0,
                   open_low=True, high=8.0),
            Option("min_time", float, 1 / 500, "short exposure, seconds", low=0.0, open_low=True,
                   high=1e4),
            # (a texture lookup shifted by more than a few thousand px never returns)
            Option("pan", float, 1.5, "camera pan, pixels per frame (right)", low=-1000.0,
                   high=1000.0),
            Option("light_speed", float, 2.0, "extra motion of the brightest light, px/frame",
                   low=-1000.0, high=1000.0),
        ), version=1),
}


# ------------------------------------------------- the family's cases (bench)
# Each kind's camera: its own response shape, sensor noise and bracket. The
# exposure scale puts the kind's darkest few per cent of pixels around X ~ 0.1
# in the longest exposure; what the shortest cannot hold (suns, lamps) clips
# in every exposure, as in a real bracket.
FAMILY = {
    "room": {"response": "film", "full_well": 20000.0, "read_noise": 4.0, "exposures": 7,
             "stops": 1.5, "exposure_scale": 10.0},
    "walls": {"response": "toe", "full_well": 10000.0, "read_noise": 5.0, "exposures": 9,
              "stops": 1.0, "exposure_scale": 50.0},
    "outdoor": {"response": "log", "full_well": 30000.0, "read_noise": 3.0, "exposures": 7,
                "stops": 2.0, "exposure_scale": 60.0},
    "night": {"response": "gamma", "full_well": 5000.0, "read_noise": 10.0, "exposures": 6,
              "stops": 2.0, "exposure_scale": 100.0},
    "studio": {"response": "scurve", "full_well": 40000.0, "read_noise": 2.0, "exposures": 5,
               "stops": 1.0, "exposure_scale": 200.0},
}
# Defaults may be tuned on these kinds (every seed, every depth); the others
# are held out: the bench reports its targets on them.
TUNED_KINDS = ("room", "studio")
FAMILY_SEEDS = (0, 1, 2)
FAMILY_BIT_DEPTHS = (8, 12, 16)


@dataclass(frozen=True)
class FamilyCase:
    """One rendered bracket of the family: a scene kind, a seed, a bit depth.

    ``split`` is ``"tuned"`` (defaults may be chosen on it) or ``"reported"``
    (held out); :meth:`options` are the ``bracket`` scene's options,
    :meth:`render` renders it (cached) with exact ``g`` and radiance.
    """

    kind: str
    seed: int
    bit_depth: int
    split: str

    @property
    def name(self) -> str:
        return f"{self.kind} seed {self.seed} {self.bit_depth}-bit"

    def options(self) -> dict:
        return {"kind": self.kind, "bit_depth": self.bit_depth, **FAMILY[self.kind]}

    def render(self, size: tuple[int, int] = (160, 120), *, cache: bool = True):
        """The :class:`~lumigraph.capture.render.RenderedScene` of this case."""
        from lumigraph.capture.render import render

        return render("bracket", size=size, seed=self.seed, cache=cache, **self.options())


def bracket_family(*, kinds=KINDS, seeds=FAMILY_SEEDS, bit_depths=FAMILY_BIT_DEPTHS,
                   split: str | None = None) -> tuple[FamilyCase, ...]:
    """The family's cases, kinds × seeds × bit depths, each labelled
    ``tuned`` (kind in :data:`TUNED_KINDS`) or ``reported``; ``split`` keeps
    only one of the two.

    Examples
    --------
    >>> cases = bracket_family(bit_depths=(8,))
    >>> len(cases), sorted({c.split for c in cases})
    (15, ['reported', 'tuned'])
    >>> [c.kind for c in bracket_family(seeds=(0,), bit_depths=(8,), split="reported")]
    ['walls', 'outdoor', 'night']
    """
    if split not in (None, "tuned", "reported"):
        raise InputError("split", f"expected tuned, reported or None, got {split!r}")
    for k in kinds:
        if k not in FAMILY:
            raise InputError("kinds", f"expected kinds among {', '.join(KINDS)}, got {k!r}")
    out = []
    for k in kinds:
        lab = "tuned" if k in TUNED_KINDS else "reported"
        if split is not None and lab != split:
            continue
        out += [FamilyCase(k, int(s), int(b), lab) for s in seeds for b in bit_depths]
    return tuple(out)
