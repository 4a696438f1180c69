"""The artifact kinds ``lumigraph view`` shows, each read by the project's own reader.

One class per kind, built by :func:`load` from a path. Each holds the arrays
it read (the page asks for many pictures of one artifact: the exposure or the
refocus slider moves, the cursor probes) and answers four questions:

- :meth:`Artifact.describe`: kind, shape, units and the controls the page draws;
- :meth:`Artifact.image`: the picture at given control values, RGB ``uint8``;
- :meth:`Artifact.probe`: the value under the cursor, full resolution, with units;
- :meth:`Artifact.geometry`: positions, colours and faces for the 3-D view.

Readers (one parser per artifact kind, ARCHITECTURE.md): radiance maps
through :func:`lumigraph.hdr.formats.read_hdr_image` (EXR, RGBE ``.hdr``,
LogLuv TIFF, three-channel PFM); plain 8/16-bit images through
:func:`lumigraph.capture.io.read_image`; one-channel PFM (disparity, depth)
through :func:`lumigraph.capture.io.read_pfm`; ``.flo`` through
:func:`lumigraph.capture.io.read_flo`; light fields through
:meth:`lumigraph.lightfield.field.LightField.load`; ``response.json`` through
:meth:`lumigraph.hdr.response.ResponseCurve.load`; point clouds through
:func:`lumigraph.capture.io.read_ply`; meshes (a PLY with faces, such as the
Façade solve's ``model.ply``) through ``read_ply(faces=True)``, ``.obj`` through
:func:`lumigraph.stereo.debevec1996.outputs.read_obj` and the Façade model's
``blocks.json`` through :func:`lumigraph.stereo.debevec1996.model.load_blocks`.

Speed (issue 18): a radiance map is shown from a display copy at most
:data:`DISPLAY_MAX_PX` wide (area-averaged once, at load), so an exposure move
is one table and one gather over a log2 index of at most 3 MP (Reinhard's
global curve: the same, with a per-luminance offset); the probe reads the full
resolution array. A light field refocuses by the Fourier slice theorem
(:mod:`lumigraph.lightfield.ng2005`): the 4-D FFT once per light field, then a
2-D slice and one inverse FFT per slider move.
"""

from __future__ import annotations

import json
import math
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lumigraph.capture.errors import InputError

# The display copy of a radiance map or image: at most this many pixels wide
# (the page shows it scaled to the window; wider costs time per slider move
# and shows nothing more on a screen).
DISPLAY_MAX_PX = 2048
# Exposure slider range, stops.
STOPS = 16.0
# Largest |slope| (px per view step) of the refocus slider; the Fourier
# spectrum is padded for it (lightfield.ng2005.prepare's max_slope).
MAX_SLOPE = 3.0
# Points sent to the 3-D view at most (a JSON of 200k points is ~10 MB).
MAX_POINTS = 200_000
# JSON bodies shown as text at most (bytes).
MAX_JSON_BYTES = 1 << 20

RADIANCE_EXTS = (".exr", ".hdr", ".pic")
IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".ppm", ".pgm", ".pnm")
TIFF_EXTS = (".tif", ".tiff")


# ------------------------------------------------------------------ controls
@dataclass(frozen=True)
class Control:
    """One control the page draws: a ``slider`` (min, max, step) or a
    ``select`` (options); ``default`` is its first value."""

    name: str
    kind: str
    default: float | str
    min: float | None = None
    max: float | None = None
    step: float | None = None
    options: tuple[str, ...] = ()
    label: str = ""

    def to_dict(self) -> dict:
        return {"name": self.name, "kind": self.kind, "min": self.min, "max": self.max,
                "step": self.step, "default": self.default, "options": list(self.options),
                "label": self.label or self.name}

    def parse(self, text: str | None):
        """The value of ``text`` (None: the default), checked against the range.

        >>> Control("exposure", "slider", 0.0, -2, 2, 0.1).parse("1.5")
        1.5
        >>> Control("tone", "select", "linear", options=("linear",)).parse("x")
        Traceback (most recent call last):
        ...
        lumigraph.capture.errors.InputError: tone: expected one of linear, got 'x'
        """
        if text is None or text == "":
            return self.default
        if self.kind == "select":
            if text not in self.options:
                raise InputError(self.name, f"expected one of {', '.join(self.options)}, "
                                            f"got {text!r}")
            return text
        try:
            x = float(text)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and self.min <= x <= self.max):
            raise InputError(self.name, f"expected a number in [{self.min:g}, {self.max:g}], "
                                        f"got {text!r}")
        return x


def parse_controls(controls, args) -> dict:
    """``{name: value}`` for every control, from a mapping of query strings."""
    return {c.name: c.parse(args.get(c.name)) for c in controls}


# -------------------------------------------------------------- tone curves
_LUT_SIZE = 65536
_SRGB_LUT: np.ndarray | None = None


def _srgb_lut() -> np.ndarray:
    """sRGB codes (uint8) of linear values ``i / (N - 1)``, ``N = 65536``: rounding the
    index moves a value by at most half a step, which moves the code by at most
    ``255 * 12.92 / (2 * 65535) = 0.025`` (the curve's steepest slope is its linear toe)."""
    global _SRGB_LUT
    if _SRGB_LUT is None:
        from lumigraph.hdr.reinhard2002 import srgb_encode

        x = np.arange(_LUT_SIZE, dtype=np.float64) / (_LUT_SIZE - 1)
        _SRGB_LUT = np.round(255.0 * srgb_encode(x)).astype(np.uint8)
    return _SRGB_LUT


def expose_srgb(radiance: np.ndarray, stops: float) -> np.ndarray:
    """Linear radiance at ``stops`` of exposure, clipped to [0, 1] and sRGB-encoded:
    ``round(255 srgb(clip(2^stops L)))`` within 0.025 of a code (a 65536-entry
    table; IEC 61966-2-1). ``(H, W[, C])`` float -> ``(H, W, 3)`` uint8.

    >>> expose_srgb(np.array([[0.0, 0.25, 1.0]], np.float32), 1.0)[0, :, 0].tolist()
    [0, 188, 255]
    """
    x = np.multiply(radiance, np.float32(2.0 ** stops * (_LUT_SIZE - 1)), dtype=np.float32)
    np.clip(x, 0, _LUT_SIZE - 1, out=x)
    x += np.float32(0.5)
    out = _srgb_lut()[x.astype(np.uint16)]
    return _rgb(out)


def _rgb(img: np.ndarray) -> np.ndarray:
    """``(H, W)``, ``(H, W, 1|3|4)`` -> ``(H, W, 3)`` (grey repeated, alpha dropped)."""
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[2] == 1:
        return np.repeat(img, 3, axis=2)
    return np.ascontiguousarray(img[..., :3])


def display_copy(img: np.ndarray, max_px: int = DISPLAY_MAX_PX) -> tuple[np.ndarray, float]:
    """``(copy, scale)``: ``img`` area-averaged (OpenCV ``INTER_AREA``) to at most
    ``max_px`` wide, and ``scale`` = copy width / image width (1: the image itself).
    NaN/inf become 0 first (unknown shows black)."""
    h, w = img.shape[:2]
    if w <= max_px:
        return img, 1.0
    import cv2

    nh = max(1, round(h * max_px / w))
    src = np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0) if img.dtype.kind == "f" else img
    out = cv2.resize(src, (max_px, nh), interpolation=cv2.INTER_AREA)
    if img.ndim == 3 and out.ndim == 2:
        out = out[..., None]
    return out, max_px / w


def tone_map(radiance: np.ndarray, *, stops: float, tone: str) -> np.ndarray:
    """The display copy drawn with ``tone``: ``linear`` (:func:`expose_srgb`) or the
    project's Reinhard operators (:func:`lumigraph.hdr.reinhard2002.tonemap`) with
    the key ``0.18 2^stops`` (the operator divides out the exposure; its key is
    the exposure control it has). The Reinhard statistics and the local
    operator's scales are those of the display copy."""
    if tone == "linear":
        return expose_srgb(radiance, stops)
    from lumigraph.hdr.reinhard2002 import tonemap

    rgb = radiance[..., :3] if radiance.ndim == 3 and radiance.shape[2] == 4 else radiance
    rgb = np.maximum(np.nan_to_num(rgb, nan=0.0, posinf=0.0), 0.0)
    return _rgb(tonemap(rgb, method=tone, key=0.18 * 2.0 ** stops))


def auto_stops(radiance: np.ndarray) -> float:
    """Exposure (stops, 0.1 steps) that brings the log-average of the largest
    channel to 0.18, middle grey (Reinhard 2002's key: a first look at the
    scene's body, its highlights clipped), from a subsample of at most
    512 x 512 pixels."""
    x = radiance if radiance.ndim == 2 else radiance.max(axis=2)
    x = x[::max(1, x.shape[0] // 512), ::max(1, x.shape[1] // 512)]
    x = x[np.isfinite(x) & (x > 0)]
    if x.size == 0:
        return 0.0
    log_mean = float(np.mean(np.log2(x.astype(np.float64))))
    return float(np.clip(round(math.log2(0.18) - log_mean, 1), -STOPS, STOPS))


def _xy(x, y, w: int, h: int) -> tuple[int, int]:
    """Pixel indices of probe coordinates ``x, y`` (the artifact's own pixels)."""
    try:
        xi, yi = math.floor(float(x)), math.floor(float(y))
    except (TypeError, ValueError):
        raise InputError("x, y", f"expected pixel coordinates, got x={x!r}, y={y!r}") from None
    if not (0 <= xi < w and 0 <= yi < h):
        raise InputError("x, y", f"({x}, {y}) lies outside the {w}x{h} image")
    return xi, yi


def _values(v) -> list:
    """A pixel's values as JSON numbers (NaN -> None: unknown)."""
    a = np.atleast_1d(np.asarray(v, np.float64)).tolist()
    return [None if not math.isfinite(t) else t for t in a]


def read_meta(path: Path) -> dict | None:
    """The ``.meta.json`` sidecar beside ``path`` (None when there is none);
    an unreadable one becomes ``{"error": ...}`` (the artifact still shows)."""
    from lumigraph.capture.artifact import meta_path

    m = meta_path(path)
    if not m.is_file():
        return None
    try:
        body = json.loads(m.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        return {"error": f"{m}: unreadable sidecar ({e})"}
    return body if isinstance(body, dict) else {"error": f"{m}: not a JSON object"}


# --------------------------------------------------------------- the kinds
class Artifact:
    """One artifact read from ``path``; subclasses fill in what their kind shows."""

    kind = "artifact"
    units = ""
    image_format = "png"  # the encoder the page's pictures use by default

    def __init__(self, path: Path):
        self.path = path
        self.lock = threading.Lock()  # one picture at a time (caches, FFT scratch)

    def controls(self) -> list[Control]:
        return []

    def shape(self) -> list[int]:
        return []

    def extra(self) -> dict:
        return {}

    def describe(self) -> dict:
        return {"kind": self.kind, "path": str(self.path), "shape": self.shape(),
                "units": self.units, "controls": [c.to_dict() for c in self.controls()],
                "image_format": self.image_format, "has_image": self.has_image,
                "has_geometry": self.has_geometry, **self.extra()}

    has_image = True
    has_geometry = False

    def image(self, values: dict) -> np.ndarray:
        raise InputError(self.path, f"a {self.kind} has no picture; ask for its geometry")

    def probe(self, x, y, values: dict) -> dict:
        raise InputError(self.path, f"a {self.kind} has no value under a cursor")

    def geometry(self) -> dict:
        raise InputError(self.path, f"a {self.kind} has no 3-D geometry; ask for its image")


# Elements per np.take in gather: the chunk's indices, cast to intp (8 bytes
# each, 2 MB), stay in the cache between the cast and the take.
GATHER_CHUNK = 1 << 18


def gather(table: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``table[index]`` for a uint16 ``index``, by chunks of :data:`GATHER_CHUNK`.

    numpy casts a non-intp index to intp before it gathers; on a whole 3 MP RGB
    index that is a 72 MB intermediate streamed through memory, by chunks it
    stays in the cache (docs/decisions/view-looking.md: the gathers of a slider
    move, interleaved).

    >>> gather(np.array([10, 20, 30], np.uint8), np.array([[2, 0]], np.uint16)).tolist()
    [[30, 10]]
    """
    flat = np.ascontiguousarray(index).reshape(-1)
    out = np.empty(flat.size, table.dtype)
    for s in range(0, flat.size, GATHER_CHUNK):
        np.take(table, flat[s:s + GATHER_CHUNK], out=out[s:s + GATHER_CHUNK])
    return out.reshape(index.shape)


# The display copy of a radiance map is kept as a log2 index: LOG_STEPS codes
# per stop over LOG_STOPS stops below its brightest value (darker: index 0,
# black at any exposure the slider reaches). An exposure move is then one
# 65536-entry table (the sRGB code of each index at that exposure) and one
# gather, instead of a multiply, a clip and a table on floats. Rounding to
# the index moves ln L by at most ln 2 / (2 LOG_STEPS); the code moves by at
# most 112.1 times that (255 x srgb'(x) peaks at 255 * 1.055 / 2.4 at x = 1),
# 0.038 of a code, on top of the table's own rounding to whole codes.
LOG_STEPS = 1024
LOG_STOPS = 63  # LOG_STEPS * LOG_STOPS + 1 indices fit in uint16


def log_index(radiance: np.ndarray) -> tuple[np.ndarray, float]:
    """``(index, top)``: ``index = round(LOG_STEPS (log2 L - log2 top)) + LOG_STEPS
    LOG_STOPS`` as uint16 (0: at or below ``top 2^-LOG_STOPS``, zero, negative or
    unknown), ``top`` the largest finite value (1 when there is none)."""
    x = np.asarray(radiance, np.float32)
    finite = np.isfinite(x)
    top = float(x[finite].max()) if finite.any() else 1.0
    top = top if top > 0 else 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.log2(x / np.float32(top))
    q *= np.float32(LOG_STEPS)
    q += np.float32(LOG_STEPS * LOG_STOPS + 0.5)
    q = np.nan_to_num(q, nan=0.0, neginf=0.0, posinf=0.0)
    np.clip(q, 0, LOG_STEPS * LOG_STOPS, out=q)
    return q.astype(np.uint16), top


def log_exposure_table(top: float, stops: float) -> np.ndarray:
    """The sRGB code (uint8) of each :func:`log_index` value at ``stops``."""
    from lumigraph.hdr.reinhard2002 import srgb_encode

    q = np.arange(LOG_STEPS * LOG_STOPS + 1, dtype=np.float64)
    lin = top * np.exp2(stops + (q - LOG_STEPS * LOG_STOPS) / LOG_STEPS)
    lin[0] = 0.0
    return np.round(255.0 * srgb_encode(lin)).astype(np.uint8)


def _code_table(top: float, top_index: int, start: int = 0) -> np.ndarray:
    """sRGB codes (uint8) of the indices ``start..top_index`` at 0 stops, as
    :func:`log_exposure_table` but running past ``top`` (to white); an index
    at or below 0 is black."""
    from lumigraph.hdr.reinhard2002 import srgb_encode

    q = np.arange(start, top_index + 1, dtype=np.float64)
    lin = top * np.exp2((q - LOG_STEPS * LOG_STOPS) / LOG_STEPS)
    lin[q <= 0] = 0.0
    return np.round(255.0 * srgb_encode(lin)).astype(np.uint8)


# Reinhard's global curve by log indices (Radiance._reinhard_global): a channel's
# index relative to its pixel's luminance index, d = q_c - q_L, kept as uint16
# d + _D_LOW clipped to [0, _D_LOW + _D_HIGH]. Above: a channel is at most
# L / 0.0722 (blue's luminance weight, log2 3.79 stops) and the luminance's top at
# most the channels' top, so d < 3.8 x 1024 < _D_HIGH never clips.
# Below: d < -_D_LOW means the channel is under 2^-20 of its pixel's luminance,
# so under 2^-20 of the display luminance (<= 1) after the operator's ratio: code
# 0, as is the clipped value (a zero or unknown channel, index 0, is set there).
_D_LOW = 24 * LOG_STEPS
_D_HIGH = 4 * LOG_STEPS
# sRGB code 0 below this linear value: 255 x 12.92 x v < 1/2
_BLACK = 0.5 / (255 * 12.92)


class _ReinhardIndex:
    """What a Reinhard global move needs of a display copy, made once per
    artifact: the luminance's log index and statistics, the channels' indices
    relative to it (``d``, uint16), the table's index bias and two scratch
    buffers (one picture at a time: the artifact's lock)."""

    __slots__ = ("q_lum", "top_lum", "stats", "d", "bias", "table", "g3", "j")

    @classmethod
    def of(cls, display: np.ndarray, index: np.ndarray, top: float) -> _ReinhardIndex:
        from lumigraph.hdr.reinhard2002 import _lum, _lum_statistics

        t = cls()
        rgb = display[..., :3] if display.ndim == 3 else display[..., None]
        rgb = np.maximum(np.nan_to_num(rgb, nan=0.0, posinf=0.0), 0.0)
        lum = _lum(rgb, "reinhard")  # tonemap's own (float64)
        t.q_lum, t.top_lum = log_index(lum)
        t.stats = _lum_statistics(lum, local=False)  # tonemap_statistics([rgb]), lum reused
        qc = index[..., :3] if index.ndim == 3 else index
        if qc.ndim == 3 and qc.shape[2] == 1:
            qc = qc[..., 0]
        lum_q = t.q_lum[..., None] if qc.ndim == 3 else t.q_lum
        d = qc.astype(np.int32) - lum_q + _D_LOW
        np.clip(d, 0, _D_LOW + _D_HIGH, out=d)
        d[qc == 0] = 0  # zero, negative or unknown: black whatever the luminance
        t.d = d.astype(np.uint16)
        # the code table's index 0 sits so that indices 0.._D_LOW + _D_HIGH are black
        # (a luminance clipped to index 0 leaves d alone there) and 65535 is white
        # (the saturated add): white is 12.7 stops (13000 indices) above black,
        # 36864 are free
        n = LOG_STEPS * LOG_STOPS
        last_black = math.ceil(n + LOG_STEPS * math.log2(_BLACK / top)) - 1
        t.bias = _D_LOW + _D_HIGH - last_black + 16
        t.table = _code_table(top, 65535 - t.bias, start=-t.bias)
        t.g3 = np.empty_like(t.d)
        t.j = np.empty_like(t.d)
        return t


class Radiance(Artifact):
    """Linear radiance (EXR, RGBE, LogLuv TIFF, three-channel PFM)."""

    kind = "radiance"
    units = "linear radiance (relative)"
    image_format = "jpeg"

    def __init__(self, path: Path, full: np.ndarray):
        super().__init__(path)
        self.full = full
        self.display, self.scale = display_copy(full)
        self.default_stops = auto_stops(self.display)
        self.index, self.top = log_index(self.display)
        self._tone = None  # the Reinhard indices, made on first use

    def controls(self):
        return [Control("exposure", "slider", self.default_stops, -STOPS, STOPS, 0.1,
                        label="exposure (stops)"),
                Control("tone", "select", "linear",
                        options=("linear", "reinhard", "reinhard-local"),
                        label="tone mapping")]

    def shape(self):
        return list(self.full.shape)

    def extra(self):
        h, w = self.display.shape[:2]
        return {"display_size": [w, h], "display_scale": self.scale}

    def image(self, values):
        if values["tone"] == "linear":
            return _rgb(gather(log_exposure_table(self.top, values["exposure"]), self.index))
        if values["tone"] == "reinhard":
            return self._reinhard_global(0.18 * 2.0 ** values["exposure"])
        return tone_map(self.display, stops=values["exposure"], tone=values["tone"])

    def _reinhard_global(self, key: float) -> np.ndarray:
        """Reinhard's global operator (:func:`lumigraph.hdr.reinhard2002.global_operator`,
        with the display copy's statistics) through the log indices.

        The operator scales each pixel's RGB by ``L_d / L``, a function of the
        luminance only, so a channel's picture index is ``q_c + off(q_L)`` (its
        log index plus the ratio's log2 offset at the luminance's index). Written
        ``d_c + G(q_L)`` with ``d_c = q_c - q_L`` (per pixel, kept from the first
        call: :class:`_ReinhardIndex`) and ``G(q) = q + off(q)`` (one 64513-entry
        table per key), a move is one gather of ``G`` over the luminance indices,
        one saturating uint16 add (OpenCV) and one gather of the code table: no
        float work per pixel. Three index roundings (channel, luminance: the
        ratio's slope in ln L is within (-1, 1), offset) move the code by at most
        3 x 0.038 against the exact value, so it is within half a code plus 0.114
        of the project's :func:`tonemap` of the display copy before its rounding
        (tested against its 16-bit output)."""
        import cv2

        from lumigraph.hdr.reinhard2002 import global_operator

        if self._tone is None:
            self._tone = _ReinhardIndex.of(self.display, self.index, self.top)
        t = self._tone
        n = LOG_STEPS * LOG_STOPS
        q = np.arange(n + 1, dtype=np.float64)
        lum_q = t.top_lum * np.exp2((q - n) / LOG_STEPS)
        with np.errstate(divide="ignore"):
            off = LOG_STEPS * np.log2(global_operator(lum_q, key=key, statistics=t.stats) / lum_q)
        g = np.round(q + off - _D_LOW + t.bias)
        g[0] = 0  # zero luminance: black (tonemap's ratio 0), d_c alone stays in the black
        g = np.clip(np.nan_to_num(g, nan=0.0), 0, 65535).astype(np.uint16)
        gl = gather(g, t.q_lum)
        if t.d.ndim == 3:
            cv2.merge([gl] * t.d.shape[2], dst=t.g3)
        else:
            t.g3 = gl
        cv2.add(t.d, t.g3, dst=t.j)  # saturates at 65535: white
        return _rgb(gather(t.table, t.j))

    def probe(self, x, y, values):
        h, w = self.full.shape[:2]
        xi, yi = _xy(x, y, w, h)
        return {"x": xi, "y": yi, "value": _values(self.full[yi, xi]), "units": self.units}


class Image(Artifact):
    """A plain 8/16-bit image (as captured: codes, not radiance)."""

    kind = "image"

    def __init__(self, path: Path, full: np.ndarray):
        super().__init__(path)
        self.full = full
        bits = 16 if full.dtype == np.uint16 else 8
        self.units = f"{bits}-bit code"
        small, self.scale = display_copy(full)
        # 16-bit codes shown as their top 8 bits, rounded (65535 -> 255)
        s = (small.astype(np.float32) / 257.0 + 0.5).astype(np.uint8) if bits == 16 else small
        self.display = _rgb(s.astype(np.uint8, copy=False))

    def shape(self):
        return list(self.full.shape)

    def extra(self):
        h, w = self.display.shape[:2]
        return {"display_size": [w, h], "display_scale": self.scale}

    def image(self, values):
        return self.display

    def probe(self, x, y, values):
        h, w = self.full.shape[:2]
        xi, yi = _xy(x, y, w, h)
        return {"x": xi, "y": yi, "value": _values(self.full[yi, xi]), "units": self.units}


def colour_map(values: np.ndarray, lo: float, hi: float, name: str) -> np.ndarray:
    """A scalar map in colour: OpenCV's ``jet`` (the Middlebury disparity
    pictures' map) or grey, from ``lo`` (blue / black) to ``hi`` (red / white);
    unknown (NaN) is black. ``(H, W)`` -> ``(H, W, 3)`` uint8 RGB."""
    import cv2

    span = hi - lo if hi > lo else 1.0
    t = np.nan_to_num((values - lo) / span, nan=0.0, posinf=1.0, neginf=0.0)
    codes = (np.clip(t, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    out = _rgb(codes) if name == "grey" else cv2.applyColorMap(codes, cv2.COLORMAP_JET)[..., ::-1]
    out = np.ascontiguousarray(out)
    out[~np.isfinite(values)] = 0
    return out


class Scalar(Artifact):
    """A one-channel float map (disparity or depth PFM, one-channel EXR of depth)."""

    kind = "scalar"

    def __init__(self, path: Path, full: np.ndarray, meta: dict | None):
        super().__init__(path)
        self.full = full
        name = path.name.lower()
        units = (meta or {}).get("units") if isinstance((meta or {}).get("units"), str) else None
        self.quantity = "disparity" if "disp" in name else "depth" if "depth" in name else "value"
        self.units = units or {"disparity": "px", "depth": "scene units"}.get(self.quantity, "")
        known = full[np.isfinite(full)]
        lo, hi = (float(known.min()), float(known.max())) if known.size else (0.0, 1.0)
        if hi <= lo:
            hi = lo + 1.0
        self.range = (lo, hi)
        self.known_fraction = float(known.size) / max(full.size, 1)
        self.small, self.scale = display_copy(full)
        # the display copy keeps NaN where the full map is unknown everywhere below it
        if self.scale != 1.0:
            import cv2

            mask = np.isfinite(full).astype(np.float32)
            frac = cv2.resize(mask, self.small.shape[1::-1], interpolation=cv2.INTER_AREA)
            with np.errstate(invalid="ignore", divide="ignore"):
                self.small = np.where(frac > 0, self.small / frac, np.nan).astype(np.float32)

    def controls(self):
        lo, hi = self.range
        step = (hi - lo) / 200
        return [Control("lo", "slider", lo, lo, hi, step, label=f"colour from ({self.units})"),
                Control("hi", "slider", hi, lo, hi, step, label=f"colour to ({self.units})"),
                Control("colours", "select", "jet", options=("jet", "grey"), label="colour map")]

    def shape(self):
        return list(self.full.shape)

    def extra(self):
        h, w = self.small.shape[:2]
        return {"display_size": [w, h], "display_scale": self.scale, "quantity": self.quantity,
                "range": list(self.range), "known_fraction": self.known_fraction}

    def image(self, values):
        return colour_map(self.small, values["lo"], values["hi"], values["colours"])

    def probe(self, x, y, values):
        h, w = self.full.shape[:2]
        xi, yi = _xy(x, y, w, h)
        return {"x": xi, "y": yi, "value": _values(self.full[yi, xi]), "units": self.units,
                "quantity": self.quantity}


class Flow(Artifact):
    """A Middlebury ``.flo`` flow field (dx, dy in pixels; NaN unknown)."""

    kind = "flow"
    units = "px"

    def __init__(self, path: Path, full: np.ndarray):
        super().__init__(path)
        self.full = full
        r = np.hypot(full[..., 0], full[..., 1])
        known = r[np.isfinite(r)]
        self.max_length = float(known.max()) if known.size else 0.0
        step = max(1, math.ceil(full.shape[1] / DISPLAY_MAX_PX))
        self.small = full[::step, ::step]  # nearest: flow vectors are not averaged across edges
        self.scale = 1.0 / step

    def controls(self):
        top = max(self.max_length, 1e-3)
        return [Control("max_flow", "slider", top, top / 100, 2 * top, top / 100,
                        label="length of full colour (px)")]

    def shape(self):
        return list(self.full.shape)

    def extra(self):
        h, w = self.small.shape[:2]
        return {"display_size": [w, h], "display_scale": self.scale,
                "max_length": self.max_length}

    def image(self, values):
        from lumigraph.stereo.flow_colour import flow_to_colour

        return flow_to_colour(self.small, max_flow=values["max_flow"])

    def probe(self, x, y, values):
        h, w = self.full.shape[:2]
        xi, yi = _xy(x, y, w, h)
        dx, dy = _values(self.full[yi, xi])
        length = None if dx is None else math.hypot(dx, dy)
        return {"x": xi, "y": yi, "value": [dx, dy], "length": length, "units": self.units}


class LightFieldView(Artifact):
    """A light field: refocused (slope, or depth where ``focal_px`` is known) or one view."""

    kind = "lightfield"
    units = "linear radiance (relative)"
    image_format = "jpeg"

    def __init__(self, path: Path, lf):
        super().__init__(path)
        self.lf = lf
        self._spectrum = None
        self._last: tuple[float, np.ndarray] | None = None  # (slope, refocused full res)
        self.default_stops = auto_stops(lf.data[lf.grid[0] // 2, lf.grid[1] // 2])

    def controls(self):
        u, v = self.lf.grid
        c = [Control("mode", "select", "refocus", options=("refocus", "view"), label="show"),
             Control("slope", "slider", 0.0, -MAX_SLOPE, MAX_SLOPE, 0.01,
                     label="refocus slope (px per view step)")]
        if self.lf.focal_px is not None:
            near = self.lf.focal_px * self.lf.spacing / MAX_SLOPE
            c.append(Control("depth", "slider", "", near, 100 * near, near / 10,
                             label="refocus depth (units of spacing; overrides the slope)"))
        c += [Control("u", "slider", float((u - 1) // 2), 0, u - 1, 1, label="view row u"),
              Control("v", "slider", float((v - 1) // 2), 0, v - 1, 1, label="view column v"),
              Control("exposure", "slider", self.default_stops, -STOPS, STOPS, 0.1,
                      label="exposure (stops)")]
        return c

    def shape(self):
        return list(self.lf.data.shape)

    def extra(self):
        w, h = self.lf.size
        return {"display_size": [w, h], "display_scale": 1.0, "grid": list(self.lf.grid),
                "spacing": self.lf.spacing, "focal_px": self.lf.focal_px,
                "max_slope": MAX_SLOPE}

    def slope(self, values) -> float:
        """The slope the controls ask for: ``depth`` when given, else ``slope``."""
        depth = values.get("depth")
        if depth not in (None, ""):
            s = self.lf.slope_from_depth(float(depth))
            return float(min(s, MAX_SLOPE))
        return float(values["slope"])

    def refocused(self, slope: float) -> np.ndarray:
        """The light field refocused at ``slope``, ``(H, W, C)`` float32 (Ng 2005's
        Fourier slice; the 4-D FFT is made on the first call and kept)."""
        if self._last is not None and self._last[0] == slope:
            return self._last[1]
        from lumigraph.lightfield import ng2005

        if self._spectrum is None:
            self._spectrum = ng2005.prepare(self.lf, max_slope=MAX_SLOPE)
        img = ng2005.refocus(self._spectrum, slope)
        self._last = (slope, img)
        return img

    def _linear(self, values) -> np.ndarray:
        if values["mode"] == "view":
            u, v = self.lf.grid
            i = min(int(values["u"]), u - 1)
            j = min(int(values["v"]), v - 1)
            return self.lf.data[i, j]
        return self.refocused(self.slope(values))

    def image(self, values):
        return expose_srgb(self._linear(values), values["exposure"])

    def probe(self, x, y, values):
        w, h = self.lf.size
        xi, yi = _xy(x, y, w, h)
        out = {"x": xi, "y": yi, "value": _values(self._linear(values)[yi, xi]),
               "units": self.units}
        if values["mode"] == "refocus":
            out["slope"] = self.slope(values)
        return out


class Response(Artifact):
    """A ``response.json``: the inverse response ``g(z) = ln f^-1(z)`` per channel."""

    kind = "response"
    units = "ln relative exposure"

    def __init__(self, path: Path, curve):
        super().__init__(path)
        self.curve = curve

    def shape(self):
        return list(self.curve.g.shape)

    def extra(self):
        g = self.curve.g
        return {"method": self.curve.method, "bit_depth": int(self.curve.bit_depth),
                "exposure_times_s": self.curve.exposure_times_s,
                "warnings": list(self.curve.warnings),
                "curves": [_values(ch) for ch in g]}  # look.js may draw them itself

    def image(self, values):
        """The curves drawn by matplotlib (Agg): code against ``g``, one line per channel."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        g = self.curve.g
        fig = Figure(figsize=(6.4, 4.0), dpi=100)
        ax = fig.add_subplot()
        colours = ("tab:red", "tab:green", "tab:blue") if len(g) == 3 else ("k",) * len(g)
        for ch, col in zip(g, colours, strict=False):
            ax.plot(np.arange(len(ch)), ch, color=col, lw=1.2)
        ax.set_xlabel(f"code ({self.curve.bit_depth}-bit)")
        ax.set_ylabel("g(z) = ln relative exposure")
        ax.set_title(f"{self.path.name}: {self.curve.method}")
        ax.grid(alpha=0.3)
        fig.tight_layout()
        canvas = FigureCanvasAgg(fig)  # Agg on this figure only: no global backend switch
        canvas.draw()
        return np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])

    def probe(self, x, y, values):
        """``x`` is a code: ``g`` of every channel there."""
        n = self.curve.g.shape[1]
        z, _ = _xy(x, 0, n, 1)
        return {"x": z, "value": _values(self.curve.g[:, z]), "units": self.units}


class Geometry(Artifact):
    """A point cloud (PLY) or a mesh (the Façade model): shown in 3-D."""

    has_image = False
    has_geometry = True
    units = "scene units"

    def __init__(self, path: Path, kind: str, points: np.ndarray, colors=None, faces=None):
        super().__init__(path)
        self.kind = kind
        self.points, self.colors, self.faces = points, colors, faces

    def shape(self):
        return list(self.points.shape)

    def extra(self):
        lo = self.points.min(axis=0) if len(self.points) else np.zeros(3)
        hi = self.points.max(axis=0) if len(self.points) else np.zeros(3)
        return {"bounds": [_values(lo), _values(hi)],
                "faces": 0 if self.faces is None else int(len(self.faces))}

    def geometry(self):
        pts, cols = self.points, self.colors
        step = 1
        if self.faces is None and len(pts) > MAX_POINTS:  # a mesh is never thinned
            step = math.ceil(len(pts) / MAX_POINTS)
            pts = pts[::step]
            cols = cols[::step] if cols is not None else None
        # decimals to 1e-7 of the model's extent: compact JSON, far below a pixel
        extent = float(np.abs(pts).max()) if len(pts) else 1.0
        decimals = max(0, 7 - math.ceil(math.log10(extent))) if extent > 0 else 7
        return {"kind": self.kind, "positions": np.round(pts, decimals).ravel().tolist(),
                "decimals": decimals,
                "colors": None if cols is None else cols.ravel().tolist(),
                "faces": None if self.faces is None else self.faces.ravel().tolist(),
                "every": step, "count": int(len(self.points))}


class JsonText(Artifact):
    """Any other JSON artifact (model.json, camera.json, …): shown as text."""

    kind = "json"
    has_image = False

    def __init__(self, path: Path, text: str):
        super().__init__(path)
        self.text = text

    def extra(self):
        return {"text": self.text}


# ---------------------------------------------------------- finding, loading
def _tiff_is_logluv(p: Path) -> bool:
    """True when the TIFF's first page says LogLuv (Photometric 32845)."""
    from lumigraph.capture.headers import tiff_pages
    from lumigraph.hdr.formats import TAG_PHOTOMETRIC_LOGLUV

    try:
        with open(p, "rb") as f:
            head = f.read(1 << 20)
        tags = tiff_pages(head, p)[0]
    except (OSError, InputError, IndexError):
        return False  # read_image says what is wrong with it
    return tags.get(262, [None])[0] == TAG_PHOTOMETRIC_LOGLUV


def _ply_has_faces(p: Path) -> bool:
    """True when the PLY's header declares a face element with records (a mesh,
    the Façade solve's ``model.ply``); read_ply says what is wrong with a bad one."""
    try:
        with open(p, "rb") as f:
            head = f.read(1 << 16)
    except OSError:
        return False
    end = head.find(b"end_header")
    for line in head[:end if end >= 0 else len(head)].splitlines():
        parts = line.split()
        if parts[:2] == [b"element", b"face"] and len(parts) == 3 and parts[2].isdigit():
            return int(parts[2]) > 0
    return False


def _pfm_channels(p: Path) -> int:
    with open(p, "rb") as f:
        return 3 if f.read(2) == b"PF" else 1


def kind_of(path) -> str | None:
    """The artifact kind of ``path`` by its name (None: not one the page shows);
    a TIFF and a PFM are told apart by their first bytes (radiance or not).

    >>> kind_of("notes.txt") is None, kind_of("x/response.json"), kind_of("a.flo")
    (True, 'response', 'flow')
    """
    p = Path(path)
    name = p.name.lower()
    if p.is_dir():
        return "lightfield" if (p / "lightfield.json").is_file() else None
    if name.endswith(".meta.json"):
        return None  # shown beside its artifact
    if name == "lightfield.json":
        return "lightfield"
    if name == "response.json":
        return "response"
    if name == "blocks.json":
        return "mesh"
    if name.endswith(".json"):
        return "json"
    if name.endswith(RADIANCE_EXTS):
        return "radiance"
    if name.endswith(".pfm"):
        try:
            return "radiance" if _pfm_channels(p) == 3 else "scalar"
        except OSError:
            return "scalar"
    if name.endswith(TIFF_EXTS):
        return "radiance" if p.is_file() and _tiff_is_logluv(p) else "image"
    if name.endswith(IMAGE_EXTS):
        return "image"
    if name.endswith(".flo"):
        return "flow"
    if name.endswith(".ply"):
        return "mesh" if p.is_file() and _ply_has_faces(p) else "pointcloud"
    if name.endswith(".obj"):
        return "mesh"
    return None


def expand(paths, *, max_files: int = 2000) -> list[Path]:
    """The artifacts of ``paths``: a file is itself (whatever its kind: an unknown
    one shows its error); a folder holding ``lightfield.json`` is one light field;
    another folder is every artifact under it (sorted, light-field folders kept
    whole, hidden names skipped), at most ``max_files``."""
    out: list[Path] = []

    def walk(folder: Path):
        if (folder / "lightfield.json").is_file():
            out.append(folder / "lightfield.json")
            return
        try:
            entries = sorted(folder.iterdir())
        except OSError:
            return
        for e in entries:
            if len(out) >= max_files or e.name.startswith("."):
                continue
            if e.is_dir():
                walk(e)
            elif kind_of(e) is not None:
                out.append(e)

    for p in map(Path, paths):
        if p.is_dir():
            walk(p)
        else:
            out.append(p)
    return out


def load(path) -> Artifact:
    """Read ``path`` by its kind's reader.

    Raises
    ------
    InputError
        The file is missing, of a kind the page does not show, or its reader
        refuses it (the reader's message, naming the file).
    """
    p = Path(path)
    kind = kind_of(p)
    if kind == "lightfield" and p.is_dir():
        p = p / "lightfield.json"
    if not p.exists():
        raise InputError(p, "file not found")
    if kind is None:
        raise InputError(p, "not an artifact lumigraph view shows (radiance maps, images, "
                            "PFM, .flo, light fields, response.json, PLY, the Façade model, "
                            "JSON)")
    if kind == "radiance":
        from lumigraph.hdr.formats import read_hdr_image

        img = read_hdr_image(p)
        if img.ndim == 3 and img.shape[2] not in (1, 3, 4):
            raise InputError(p, f"{img.shape[2]} channels: expected grey, RGB or RGBA radiance")
        return Radiance(p, img)
    if kind == "image":
        from lumigraph.capture.io import read_image

        img = read_image(p)
        if img.dtype.kind == "f":
            return Radiance(p, img)
        return Image(p, img)
    if kind == "scalar":
        from lumigraph.capture.io import read_pfm

        return Scalar(p, read_pfm(p), read_meta(p))
    if kind == "flow":
        from lumigraph.capture.io import read_flo

        return Flow(p, read_flo(p))
    if kind == "lightfield":
        from lumigraph.lightfield.field import LightField

        return LightFieldView(p, LightField.load(p.parent))
    if kind == "response":
        from lumigraph.hdr.response import ResponseCurve

        return Response(p, ResponseCurve.load(p))
    if kind == "pointcloud":
        from lumigraph.capture.io import read_ply

        pts, cols = read_ply(p)
        return Geometry(p, "pointcloud", pts, cols)
    if kind == "mesh":
        if p.suffix.lower() == ".ply":
            from lumigraph.capture.io import read_ply

            vertices, _, faces = read_ply(p, faces=True)
        elif p.suffix.lower() == ".obj":
            from lumigraph.stereo.debevec1996.outputs import read_obj

            vertices, faces = read_obj(p)
        else:  # blocks.json: the Façade model's own mesh
            from lumigraph.stereo.debevec1996.model import load_blocks

            mesh = load_blocks(p).mesh()
            vertices, faces = mesh.vertices, mesh.faces
        return Geometry(p, "mesh", np.asarray(vertices, np.float64),
                        faces=np.asarray(faces, np.int64))
    # json
    size = p.stat().st_size
    with open(p, "rb") as f:
        raw = f.read(MAX_JSON_BYTES)
    try:
        text = raw.decode("utf-8")
        if size <= MAX_JSON_BYTES:
            text = json.dumps(json.loads(text), indent=2)
    except (UnicodeDecodeError, ValueError) as e:
        raise InputError(p, f"not a JSON file ({e})") from None
    if size > MAX_JSON_BYTES:
        text += f"\n… ({size - MAX_JSON_BYTES} more bytes not shown)"
    return JsonText(p, text)


def encode(img: np.ndarray, fmt: str) -> bytes:
    """RGB ``uint8`` -> PNG (zlib level 1: a fast encoder, lossless) or JPEG
    (quality 90, for the slider pictures: a 3 MP frame in a few tens of ms).

    JPEG keeps the colour at full resolution (4:4:4): 4:2:0 saves 10-20 ms on
    a 3 MP frame but smears per-pixel colour (59 codes RMS against 8 on colour
    noise, docs/decisions/view-looking.md), and these pictures are data."""
    import cv2

    # cvtColor: the channel swap without numpy's strided copy (30 ms on 3 MP)
    bgr = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR)
    if fmt == "png":
        ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    elif fmt == "jpeg":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90,
                                             cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                             cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444])
    else:
        raise InputError("format", f"expected png or jpeg, got {fmt!r}")
    if not ok:
        raise RuntimeError(f"OpenCV could not encode a {img.shape} picture as {fmt}")
    return buf.tobytes()
