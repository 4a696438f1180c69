"""Synthetic scenes with exact ground truth: the registry, the result type, the cache.

A scene is a function ``render_fn(*, size, seed, rng, **options) -> RenderedScene``
in a module of ``lumigraph.capture.scenes``. :data:`SCENES` is the one list of
scenes: a :class:`~lumigraph.capture.registry.Registry` mapping the name
``lumigraph render NAME`` takes to its renderer and a one-line summary, the
same shape as every stage's ``--method`` registry. The scene's data (default
size, the table of its options, cache version) is a :class:`SceneSpec` in its
module's ``SPECS``, beside the renderer. :func:`render` validates the options
against the spec, seeds the generator, and caches results by (scene, options,
size, seed, scene version), in memory and on disk (``$LUMIGRAPH_CACHE``,
default ``~/.cache/lumigraph``), so tests can build their inputs on the fly.

A rendered folder holds the captured images exactly as a camera would deliver
them (integer code values), a ``stack.json`` that every stage command accepts
as input, ``gt.json`` describing the ground truth, and ``gt/<name>.npy`` arrays
(float64/float32, exact; ``.npy`` because it loses nothing).

Examples
--------
>>> s = render("sample", size=(32, 16), seed=1, cache=False)
>>> s.images[0].shape, s.images[0].dtype.name, sorted(s.gt_arrays)
((16, 32, 3), 'uint16', ['radiance'])
"""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lumigraph.capture.artifact import atomic_path, dumps_json, unstaged, write_json
from lumigraph.capture.errors import InputError
from lumigraph.capture.registry import Method, Registry

_S = "lumigraph.capture.scenes."

# Every scene, by its command-line name: the renderer it runs (imported on
# first use) and the summary `lumigraph render --list` prints. A new scene is a
# line here and its SceneSpec (size, options, version) in its module's SPECS.
SCENES = Registry("scene", [
    Method("sample", _S + "sample:render_sample",
           "linear radiance ramp on an ideal linear sensor (plumbing smoke test)"),
    Method("boards", _S + "boards:render_boards",
           "checkerboard/ChArUco calibration views, known K and distortion (fx != fy, "
           "off-centre principal point)"),
    Method("boards-stereo", _S + "boards:render_boards_stereo",
           "a stereo rig (two cameras, known R, T) viewing calibration boards"),
    Method("bracket", _S + "brackets:render_bracket",
           "HDR room (>= 1e4:1) bracketed through a known response, exact radiance"),
    Method("bracket_video", _S + "brackets:render_bracket_video",
           "HDR video: alternating short/long exposures, camera pan and a moving light; "
           "radiance per frame"),
    Method("flow", _S + "flow:render_flow",
           "2-frame sequence: textured plane under camera motion (homography) plus an "
           "independently moving ellipse; exact forward flow, occlusion mask"),
    Method("flow-large", _S + "flow:render_flow",
           "as flow with large displacement (background 44 px, object 52 px per frame)"),
    Method("flow-textureless", _S + "flow:render_flow",
           "as flow with a flat (textureless) region in the background"),
    Method("flow-brightness", _S + "flow:render_flow",
           "as flow with a brightness/contrast change: gain 0.6, offset +0.06 and an "
           "illumination gradient in frame 1"),
    Method("flow-video", _S + "flow:render_flow",
           "Sand-Teller video matching: a second take with a small camera shift, different "
           "lighting and an added object"),
    Method("flow-sequence", _S + "flow:render_flow",
           "5-frame sequence of the flow scene (consecutive forward flows)"),
    Method("stereo-pair", _S + "stereo:render_pair",
           "left/right pair (rectified or not) of textured planes and a sphere: exact depth, "
           "disparity, occlusion mask and rig"),
    Method("stereo-views", _S + "stereo:render_views",
           "N views on an arc around textured boxes and a sphere (known poses) for structure "
           "from motion"),
    Method("lightfield-array", _S + "lightfield:render_array",
           "U x V camera-array light field of textured planes at several depths (occlusions); "
           "GT views, depth, exact synthetic-aperture and thin-lens refocus images"),
    Method("lightfield-lenslet", _S + "lightfield:render_lenslet",
           "plenoptic raw + white image, square microlens grid rotated 1.5 deg; size = "
           "microlens count; GT centres, grid, sub-aperture views"),
    Method("lightfield-lenslet-hex", _S + "lightfield:render_lenslet",
           "plenoptic raw + white image, hexagonal microlens grid rotated 1.5 deg; GT centres, "
           "views at lattice positions and on the rectangular grid"),
    Method("projector", _S + "projector:render_projector",
           "projector-lit corner with interreflection and a scattering volume (Mitsuba); "
           "checker/sinusoid/stripe/occluder stacks; direct/global truth"),
    Method("model-stereo", _S + "model_stereo:render_facade",
           "wide-baseline key/offset views of a facade with pillars and recessed windows, with "
           "its rough model (the wall plane) for model-based stereo"),
    Method("facade", _S + "facade:render_facade",
           "a building of blocks (house, gable roof, tower, spire, wing) photographed from around "
           "it, glossy walls and windows: Facade's blocks.json, edges.json, true parameters and "
           "cameras, depth per view, novel views for view-dependent texture mapping"),
])
GT_SCHEMA = "lumigraph.gt"


@dataclass(frozen=True)
class Option:
    """One scene option: ``--name VALUE`` on the command line.

    ``kind`` is ``int``, ``float``, ``str``, ``bool`` or ``tuple`` (of floats,
    ``"1,2,3"``); ``choices`` restricts values; ``low``/``high`` bound numbers,
    each number of a tuple (``open_low``/``open_high`` make a bound exclusive,
    e.g. α ∈ (0, 1)). NaN and infinities are refused whatever the bounds.
    """

    name: str
    kind: type
    default: Any
    help: str
    choices: tuple | None = None
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False

    def parse(self, value: Any) -> Any:
        """``value`` (text or a value) as this option's kind, checked against its
        choices and bounds; :class:`InputError` naming the option otherwise
        (the command line reports its flag)."""
        try:
            if self.kind is bool and isinstance(value, str):
                if value.lower() not in ("1", "0", "true", "false", "yes", "no"):
                    raise ValueError
                v = value.lower() in ("1", "true", "yes")
            elif self.kind is tuple:
                v = tuple(float(x) for x in value.split(",")) if isinstance(value, str) else tuple(value)
            else:
                v = self.kind(value)
        except (TypeError, ValueError):
            raise InputError(self.name, f"expected {self.kind.__name__}, got {value!r}") from None
        # NaN passes every comparison with a bound, and inf breaks the scene's
        # arithmetic (black images, null exposure times): refused whatever the bounds
        nums = v if self.kind is tuple else (v,) if self.kind in (int, float) else ()
        if any(not math.isfinite(x) for x in nums):
            raise InputError(self.name, f"expected a finite number, got {value!r}")
        if self.choices is not None and v not in self.choices:
            raise InputError(self.name, f"{v!r} is not one of {', '.join(map(str, self.choices))}")
        for x in nums:  # a tuple's bounds hold for each of its numbers
            if self.low is not None and (x < self.low or (self.open_low and x == self.low)):
                raise InputError(self.name, f"{x} is out of range: {self._range()}")
            if self.high is not None and (x > self.high or (self.open_high and x == self.high)):
                raise InputError(self.name, f"{x} is out of range: {self._range()}")
        return v

    def _range(self) -> str:
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        return f"{'(' if self.open_low else '['}{lo}, {hi}{')' if self.open_high else ']'}"

    def describe(self) -> str:
        extra = ""
        if self.choices:
            extra = f" one of {{{', '.join(map(str, self.choices))}}}"
        elif self.low is not None or self.high is not None:
            extra = f" in {self._range()}"
        return f"--{self.name.replace('_', '-')} ({self.kind.__name__}{extra}, default {self.default!r}): {self.help}"


@dataclass(frozen=True)
class SceneSpec:
    """A scene's data: default size, options and cache version. Its renderer and
    summary are its entry in :data:`SCENES`; the spec lives in ``SPECS`` of the
    renderer's module."""

    name: str
    default_size: tuple[int, int]
    options: tuple[Option, ...] = ()
    version: int = 1  # bump when the renderer's output changes (invalidates caches)
    min_size: tuple[int, int] = (16, 16)

    @property
    def summary(self) -> str:
        """The one-line description (the scene's help in :data:`SCENES`)."""
        return SCENES[self.name].help

    @property
    def render_fn(self) -> Callable[..., RenderedScene]:
        """The renderer (imported on first use)."""
        return SCENES[self.name].load()

    def check_size(self, size: tuple[int, int] | None) -> tuple[int, int]:
        """``size`` ``(width, height)``, or the default size for ``None``; each
        side from ``min_size`` to 20000 pixels, else :class:`InputError` naming
        ``size``."""
        w, h = size if size is not None else self.default_size
        if w < self.min_size[0] or h < self.min_size[1] or w > 20000 or h > 20000:
            raise InputError("size", f"impossible size {w}x{h} for scene {self.name!r} "
                                     f"(at least {self.min_size[0]}x{self.min_size[1]})")
        return w, h

    def parse_options(self, given: dict[str, Any]) -> dict[str, Any]:
        known = {o.name: o for o in self.options}
        out = {o.name: o.default for o in self.options}
        for k, v in given.items():
            key = k.replace("-", "_")
            if key not in known:
                names = ", ".join(known) or "none"
                raise InputError(key, f"scene {self.name!r} has no such option (its options: "
                                      f"{names})")
            out[key] = known[key].parse(v)
        return out


@dataclass(frozen=True)
class RenderedScene:
    """Captured images plus exact ground truth.

    Attributes
    ----------
    scene : str
        Registered scene name.
    params : dict
        Options, size and seed it was rendered with.
    images : tuple of ndarray
        Captured images, ``(H, W)`` or ``(H, W, C)``, integer code values as a
        camera delivers them (uint8/uint16), RGB.
    image_names : tuple of str
        File names for ``images`` (``.png``; 16-bit PNG for bit depths > 8).
    stack : dict
        Stack-wide facts written to ``stack.json`` (``bit_depth``,
        ``exposure_times_s``, …).
    gt : dict
        JSON-able ground truth (K, poses, response, times, …) -> ``gt.json``.
    gt_arrays : dict of str -> ndarray
        Dense ground truth (radiance, disparity, flow, depth, …) -> ``gt/*.npy``.
    files : dict of str -> dict
        Further JSON documents by relative path (a scene's model file, marks,
        one ``camera.json`` per view), written beside the images.
    """

    scene: str
    params: dict
    images: tuple[np.ndarray, ...]
    image_names: tuple[str, ...]
    stack: dict = field(default_factory=dict)
    gt: dict = field(default_factory=dict)
    gt_arrays: dict = field(default_factory=dict)
    files: dict = field(default_factory=dict)

    def __post_init__(self):
        if len(self.images) != len(self.image_names):
            raise ValueError("image_names: one name per image expected")
        for im in self.images:
            if im.dtype not in (np.uint8, np.uint16):
                raise TypeError(f"images: captured images must be uint8/uint16, got {im.dtype}")

    @property
    def bit_depth(self) -> int:
        return int(self.stack.get("bit_depth", 8 * self.images[0].dtype.itemsize))

    def save(self, folder: str | os.PathLike) -> Path:
        """Write images, ``stack.json``, ``gt.json`` and ``gt/*.npy`` into ``folder``.

        ``stack.json`` is written last: its presence means the folder is complete.
        """
        from lumigraph.capture.io import write_image, write_stack_json

        folder = Path(folder)
        (folder / "gt").mkdir(parents=True, exist_ok=True)
        for im, name in zip(self.images, self.image_names, strict=True):
            bd = self.bit_depth if im.dtype == np.uint16 else None
            write_image(folder / name, im, bit_depth=bd)
        for name, arr in self.gt_arrays.items():
            with atomic_path(folder / "gt" / f"{name}.npy") as tmp:
                np.save(tmp, np.asarray(arr), allow_pickle=False)
        for name, doc in self.files.items():
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            write_json(folder / name, doc)
        files = {"files": sorted(self.files)} if self.files else {}
        write_json(folder / "gt.json", {"schema": GT_SCHEMA, "schema_version": 1,
                                        "scene": self.scene, "params": self.params,
                                        "arrays": sorted(self.gt_arrays), **files, **self.gt})
        write_stack_json(folder, list(self.image_names), scene=self.scene, **self.stack)
        return folder

    @classmethod
    def load(cls, folder: str | os.PathLike) -> RenderedScene:
        """Load a folder written by :meth:`save` (images exactly as saved)."""
        from lumigraph.capture.io import read_image

        folder = Path(folder)
        if not (folder / "stack.json").exists():
            raise InputError(folder, "not a rendered scene folder (no stack.json)")
        stack = json.loads((folder / "stack.json").read_text())
        gt = json.loads((folder / "gt.json").read_text())
        names = tuple(stack.pop("images"))
        scene = gt.pop("scene")
        params = gt.pop("params")
        arrays = {n: np.load(folder / "gt" / f"{n}.npy") for n in gt.pop("arrays")}
        files = {n: json.loads((folder / n).read_text()) for n in gt.pop("files", [])}
        for k in ("schema", "schema_version"):
            stack.pop(k, None)
            gt.pop(k, None)
        stack.pop("scene", None)
        images = tuple(read_image(folder / n) for n in names)
        return cls(scene, params, images, names, stack, gt, arrays, files)


def _spec(method: Method) -> SceneSpec:
    module = importlib.import_module(method.target.split(":")[0])
    spec = module.SPECS[method.name]
    if spec.name != method.name:
        raise ValueError(f"SPECS[{method.name!r}] in {module.__name__} is named {spec.name!r}")
    return spec


def scenes() -> dict[str, SceneSpec]:
    """All registered scenes' specs, by name (imports every scene module)."""
    return {name: _spec(method) for name, method in SCENES.items()}


def get_scene(name: str) -> SceneSpec:
    """The spec of scene ``name`` (imports its module only); InputError listing
    the scenes when there is none of that name."""
    if name not in SCENES:
        raise InputError(name, f"unknown scene; choose from {', '.join(sorted(SCENES))} "
                               "(see 'lumigraph render --list')")
    return _spec(SCENES[name])


def cache_dir() -> Path:
    return Path(os.environ.get("LUMIGRAPH_CACHE", Path.home() / ".cache" / "lumigraph")) / "scenes"


_MEMORY: dict[str, RenderedScene] = {}


def _key(spec: SceneSpec, opts: dict, size: tuple[int, int], seed: int) -> str:
    text = dumps_json({"scene": spec.name, "v": spec.version, "opts": opts,
                       "size": list(size), "seed": seed})
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def render(name: str, *, size: tuple[int, int] | None = None, seed: int = 0,
           cache: bool = True, **options) -> RenderedScene:
    """Render (or fetch from the cache) a registered scene.

    Parameters
    ----------
    name : str
        Scene name (``lumigraph render --list``).
    size : (width, height), optional
        Image size; the scene's default test size when omitted.
    seed : int
        Seeds every random choice (noise, textures, poses): same seed, same bytes.
    cache : bool
        Reuse an earlier render with identical arguments (memory, then disk).
    **options
        Scene options, validated against its spec.
    """
    spec = get_scene(name)
    opts = spec.parse_options(options)
    w, h = spec.check_size(size)
    if not isinstance(seed, int) or seed < 0:
        raise InputError("seed", f"expected a non-negative integer, got {seed!r}")
    key = _key(spec, opts, (w, h), seed)
    if cache and key in _MEMORY:
        return _MEMORY[key]
    disk = cache_dir() / f"{name}-{key}"
    if cache and (disk / "stack.json").exists():
        try:
            result = RenderedScene.load(disk)
            _MEMORY[key] = result
            return result
        except Exception:  # a damaged cache entry is re-rendered, never trusted
            pass
    rng = np.random.default_rng(seed)
    result = SCENES[name](size=(w, h), seed=seed, rng=rng, **opts)
    # the JSON parts as the disk cache (and ``lumigraph render --out``) gives
    # them back: keys sorted. Same seed, same result, fresh or cached: a
    # block model's parameters come in its file's order, and automatic
    # marking's rounds can land elsewhere for another order
    # (docs/decisions/facade.md, 2026-12-05)
    canon = lambda doc: json.loads(dumps_json(doc))  # noqa: E731
    result = RenderedScene(result.scene, {"size": [w, h], "seed": seed, **opts}, result.images,
                           result.image_names, canon(result.stack), canon(result.gt),
                           result.gt_arrays, {n: canon(result.files[n]) for n in sorted(result.files)})
    if cache:
        _MEMORY[key] = result
        try:
            with unstaged():  # the cache is not part of a command's result set
                result.save(disk)
        except OSError:
            pass  # a read-only cache only costs speed
    return result
