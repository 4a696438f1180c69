"""Image pyramids and the shared machinery of coarse-to-fine correspondence.

The pyramid of reference §5.1.3 (Fig. 5.5): each level halves the resolution,
every pixel the average of a 2x2 block of the level below ("much like the
construction of a mip map"). A flow field found at level l is carried to level
l-1 by doubling its vectors and resampling it (pixel centres follow OpenCV's
half-pixel rule, which is what 2x2 averaging implies), then refined there.

Also here: warping an image by a flow, the forward-backward consistency test
and the choice of pyramid depth from the largest expected motion
(``levels="auto"``). Grey conversion and noise estimates are in
:mod:`lumigraph.stereo.luma`.

Examples
--------
>>> import numpy as np
>>> img = np.random.default_rng(0).random((48, 64)).astype(np.float32)
>>> [p.shape for p in build_pyramid(img, 3)]
[(48, 64), (24, 32), (12, 16)]
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError

MIN_LEVEL_SIDE = 12  # no pyramid level is made smaller than this (pixels)
MAX_LEVELS = 12  # the deepest pyramid a caller may ask for (4096x smaller)


def check_levels(levels) -> int | str:
    """The pyramid depth a coarse-to-fine method is given: ``"auto"`` or an
    integer ``1..MAX_LEVELS``, returned as ``"auto"`` or an ``int``.

    Raises
    ------
    InputError
        Naming ``levels``: not ``"auto"``, not an integer, or out of range.

    Examples
    --------
    >>> check_levels("auto"), check_levels(np.int64(3))
    ('auto', 3)
    >>> check_levels(13)
    Traceback (most recent call last):
    ...
    lumigraph.capture.errors.InputError: levels: expected 1..12 levels, got 13
    """
    if isinstance(levels, str) and levels == "auto":
        return "auto"
    if not isinstance(levels, int | np.integer) or isinstance(levels, bool):
        raise InputError("levels", f"expected 'auto' or an integer >= 1, got {levels!r}")
    if not 1 <= levels <= MAX_LEVELS:
        raise InputError("levels", f"expected 1..{MAX_LEVELS} levels, got {levels}")
    return int(levels)


def build_pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """Levels 0 (full size) .. levels-1, each the 2x2 block average of the one below.

    Parameters
    ----------
    image : ndarray, float32, ``(H, W)`` or ``(H, W, C)``
    levels : int
        Number of levels, >= 1. Odd sizes round up (area averaging).

    Returns
    -------
    list of ndarray
        Level l has shape ``ceil(H / 2**l), ceil(W / 2**l)``.
    """
    import cv2

    if levels < 1:
        raise ValueError(f"levels: expected >= 1, got {levels}")
    out = [np.ascontiguousarray(image, np.float32)]
    for _ in range(levels - 1):
        h, w = out[-1].shape[:2]
        out.append(cv2.resize(out[-1], ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA))
    return out


def upsample_flow(flow: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Carry a flow field one level down: resample to ``shape`` (H, W) and
    scale the vectors by the size ratio (2 for a pyramid step)."""
    import cv2

    h, w = shape
    sy, sx = h / flow.shape[0], w / flow.shape[1]
    up = cv2.resize(flow, (w, h), interpolation=cv2.INTER_LINEAR)
    up[..., 0] *= sx
    up[..., 1] *= sy
    return up


@functools.lru_cache(maxsize=16)
def _grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    X, Y = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    X.flags.writeable = False
    Y.flags.writeable = False
    return X, Y


@functools.lru_cache(maxsize=16)
def _grid_xy(h: int, w: int) -> np.ndarray:
    g = np.stack(_grid(h, w), axis=-1)
    g.flags.writeable = False
    return g


def grid_xy(shape: tuple[int, int]) -> np.ndarray:
    """Pixel-centre coordinates as one ``(H, W, 2)`` float32 array of (x, y)
    (read-only, cached): ``flow + grid_xy`` is a cv2.remap map."""
    return _grid_xy(int(shape[0]), int(shape[1]))


def grid(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates ``(X, Y)``, float32 (read-only, cached), for
    an ``(H, W)`` image."""
    return _grid(int(shape[0]), int(shape[1]))


def warp(image: np.ndarray, flow: np.ndarray, *, border: str = "replicate",
         cubic: bool = True, device="cpu") -> np.ndarray:
    """Sample ``image`` at ``x + flow(x)`` (bicubic, or bilinear with
    ``cubic=False``): with forward flow 0 -> 1,
    ``warp(moving, flow)`` is the moving image pulled back onto the reference.
    ``device`` other than ``"cpu"`` runs :func:`lumigraph.stereo.warp_torch.warp`
    (the same result within float32 rounding)."""
    import cv2

    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.stereo import warp_torch

            return warp_torch.warp(image, flow, border=border, cubic=cubic, device=dev)

    mode = {"replicate": cv2.BORDER_REPLICATE, "constant": cv2.BORDER_CONSTANT}[border]
    # Bicubic: bilinear interpolation smooths by a sub-pixel-phase dependent
    # amount, which biases the matching minimum toward whole pixels.
    interp = cv2.INTER_CUBIC if cubic else cv2.INTER_LINEAR
    # One (H, W, 2) float32 map: a single add, no per-axis copies.
    m = cv2.add(np.asarray(flow, np.float32), grid_xy(flow.shape[:2]))
    return cv2.remap(np.ascontiguousarray(image, np.float32), m, None, interp, borderMode=mode,
                     borderValue=np.nan)


def forward_backward(forward: np.ndarray, backward: np.ndarray, *,
                     device="cpu") -> tuple[np.ndarray, np.ndarray]:
    """Forward-backward consistency: the round trip ``x -> x + f(x) -> + b(.)``
    should come back to ``x``.

    Flagged inconsistent (occluded or wrong) where the round-trip error
    exceeds ``0.01 (|f|^2 + |b|^2) + 0.5`` px^2 (Sundaram, Brox, Keutzer 2010,
    doi:10.1007/978-3-642-15549-9_32), or the target leaves the frame.

    Returns
    -------
    inconsistent : ndarray, bool, ``(H, W)``
    round_trip_px : ndarray, float32, ``(H, W)``

    ``device`` other than ``"cpu"`` runs
    :func:`lumigraph.stereo.warp_torch.forward_backward`.
    """
    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.stereo import warp_torch

            return warp_torch.forward_backward(forward, backward, device=dev)
    h, w = forward.shape[:2]
    bw = warp(backward, forward, border="constant", cubic=False)
    X, Y = grid((h, w))
    tx, ty = X + forward[..., 0], Y + forward[..., 1]
    outside = (tx < -0.5) | (tx > w - 0.5) | (ty < -0.5) | (ty > h - 0.5)
    s = forward + bw
    err2 = s[..., 0] ** 2 + s[..., 1] ** 2
    bound = 0.01 * ((forward ** 2).sum(-1) + (bw ** 2).sum(-1)) + 0.5
    bad = outside | ~np.isfinite(err2) | (err2 > bound)
    return bad, np.sqrt(np.where(np.isfinite(err2), err2, np.inf)).astype(np.float32)


@dataclass(frozen=True)
class LevelChoice:
    """The pyramid depth chosen, and why (every candidate with its score).

    ``score`` of a candidate depth L is the largest motion left at its top
    level, ``max_motion / 2**(L-1)``, divided by what one level can resolve
    (``reach_px``); the choice is the fewest levels with score <= 1.
    """

    levels: int
    max_motion_px: float
    source: str
    reach_px: float
    candidates: tuple = field(default_factory=tuple)

    def to_dict(self) -> dict:
        return {"levels": self.levels, "max_motion_px": self.max_motion_px, "source": self.source,
                "reach_px": self.reach_px, "candidates": [dict(c) for c in self.candidates]}


def estimate_max_motion(reference: np.ndarray, moving: np.ndarray) -> tuple[float, list[dict]]:
    """Largest motion between two grey ``(H, W)`` images, reference to moving, px, from phase correlation of
    the whole frame and of 3x3 overlapping half-size tiles (each reaches a
    quarter of the frame). Peaks with a weak response are ignored.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> import cv2
    >>> a = cv2.GaussianBlur(rng.random((96, 128)).astype(np.float32), (0, 0), 1.5)
    >>> b = np.roll(a, (5, -12), axis=(0, 1))
    >>> bool(abs(estimate_max_motion(a, b)[0] - 13.0) < 1.0)      # |(-12, 5)| = 13
    True
    """
    import cv2

    h, w = reference.shape
    f = 1
    while max(h, w) / f > 160:  # half resolution and below keep this cheap
        f *= 2
    a = cv2.resize(reference, (w // f, h // f), interpolation=cv2.INTER_AREA) if f > 1 else reference
    b = cv2.resize(moving, (w // f, h // f), interpolation=cv2.INTER_AREA) if f > 1 else moving
    hh, ww = a.shape
    tiles = [(0, 0, hh, ww)]
    th, tw = hh // 2, ww // 2
    for iy in range(3):
        for ix in range(3):
            tiles.append((iy * th // 2, ix * tw // 2, th, tw))
    found = []
    best = 0.0
    for y0, x0, th_, tw_ in tiles:
        pa = np.ascontiguousarray(a[y0:y0 + th_, x0:x0 + tw_], np.float64)
        pb = np.ascontiguousarray(b[y0:y0 + th_, x0:x0 + tw_], np.float64)
        if min(pa.shape) < 8:
            continue
        win = cv2.createHanningWindow((pa.shape[1], pa.shape[0]), cv2.CV_64F)
        (dx, dy), resp = cv2.phaseCorrelate(pa, pb, win)
        mag = float(math.hypot(dx, dy) * f)
        found.append({"tile": [x0 * f, y0 * f, tw_ * f, th_ * f], "shift_px": [dx * f, dy * f],
                      "response": float(resp)})
        if resp > 0.1:  # a clear peak; noise-only correlation stays near 0.01-0.05
            best = max(best, mag)
    return best, found


def choose_levels(shape: tuple[int, int], *, max_motion_px: float, reach_px: float,
                  source: str = "given", limit: int = 10) -> LevelChoice:
    """Fewest levels whose top level leaves at most ``reach_px`` of motion,
    bounded so the top level keeps sides >= ``MIN_LEVEL_SIDE``.

    Examples
    --------
    >>> choose_levels((240, 320), max_motion_px=45.0, reach_px=3.0).levels
    5
    """
    h, w = shape
    most = 1
    while most < limit and min(h, w) / 2 ** most >= MIN_LEVEL_SIDE:
        most += 1
    cands, chosen = [], None
    for L in range(1, most + 1):
        score = max_motion_px / 2 ** (L - 1) / reach_px
        cands.append({"levels": L, "top_size": [math.ceil(w / 2 ** (L - 1)),
                                                math.ceil(h / 2 ** (L - 1))],
                      "top_motion_px": max_motion_px / 2 ** (L - 1), "score": score})
        if chosen is None and score <= 1.0:
            chosen = L
    return LevelChoice(chosen or most, float(max_motion_px), source, float(reach_px), tuple(cands))
