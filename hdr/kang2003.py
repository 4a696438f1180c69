"""Kang, Uyttendaele, Winder & Szeliski (2003): HDR video from alternating exposures.

S. B. Kang, M. Uyttendaele, S. Winder and R. Szeliski, "High Dynamic Range
Video", SIGGRAPH 2003, doi:10.1145/882262.882270 (reference ch. 6, §6.3.2).

The camera alternates short and long exposures; every output frame is the
radiance of the *current* frame, completed from its registered neighbours:

1. **Exposure equalisation** ("boosting", §6.3.2 step 2). A pair of frames is
   compared at the longer of their two exposures: each frame's relative
   exposure ``f⁻¹(z)`` (eq. 6.4: ``X = f⁻¹(Z)/Δt``) is rescaled to that
   exposure, clipped to the range both frames can record (the shorter frame's
   boosted black level up to saturation) and re-encoded through the response,
   so optical flow sees equal brightness.
2. **Registration.** For an inner frame the two neighbours share an exposure,
   so the flow between them (previous → next) sees texture exactly where the
   current frame is clipped; under constant velocity the current frame sits
   half-way, ``v(x) = ½ F(x − v(x))`` (Kang's *bidirectional* estimate,
   without his global/projective refinement). The first and last frame use the
   flow current → neighbour on the equalised pair (*unidirectional*). Flow is
   :func:`stereo.pyramid_flow.pyramid_flow`; the neighbours' radiance is
   pulled onto the current frame by ``cv2.remap``.
3. **HDR recovery** (§6.3.2 step 3). Where the current frame's code values are
   reliable (non-zero variance weight of :func:`hdr.merge.variance_weight_table`)
   its own radiance is kept. Elsewhere a warped neighbour is used only if it
   is consistent: flow forward-backward consistent, every pixel it is
   interpolated from reliable, within the bound the clipped current pixel
   implies (saturated: radiance ≥ ``f⁻¹(z_hi)/Δt``; black: ≤ ``f⁻¹(z_lo)/Δt``)
   to ``k`` noise σ, agreeing with the current frame on the well-exposed
   pixels around it, and (inner frames) with the other neighbour. Accepted
   neighbours are averaged with inverse-variance weights; a pixel with none
   keeps the current frame's bound and is flagged :data:`FALLBACK` (and
   :data:`CLIPPED` / :data:`BLACK` as in :func:`hdr.merge.merge`), never a
   ghost.
4. **Tone mapping** (step 4): :func:`tonemap_video` is Reinhard et al.'s global
   operator (eq. 1-4 of doi:10.1145/566570.566575, :mod:`hdr.reinhard2002`)
   with the log-average luminance and the white point smoothed over a window
   of frames, so the exposure of the display does not flicker.

Examples
--------
>>> from lumigraph.capture.scenes.brackets import render_bracket_video
>>> from lumigraph.hdr.response import ResponseCurve
>>> s = render_bracket_video(size=(48, 36), seed=0, rng=np.random.default_rng(0), frames=3)
>>> v = hdr_video(np.stack(s.images), s.stack["exposure_times_s"], ResponseCurve("gt", 8, s.gt_arrays["g"]))
>>> v.radiance.shape, v.radiance.dtype.name, sorted(v.frames[1]["sources"])
((3, 36, 48, 3), 'float32', ['both', 'current', 'fallback', 'next', 'previous'])
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.hdr.merge import BLACK, CLIPPED, GHOST, variance_weight_table
from lumigraph.hdr.response import ResponseCurve
from lumigraph.hdr.samples import check_stack

# consistency_sigma's default (6): docs/decisions/hdr-video-consistency-sigma.md

WARPED = 8  # the value comes from registered neighbours
FALLBACK = 16  # unreliable in the current frame and no consistent neighbour: its bound


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class HDRVideo:
    """Per-frame radiance of an alternating-exposure video.

    Attributes
    ----------
    radiance : ndarray, ``(N, H, W, C)`` float32
        Relative linear radiance per frame (``f⁻¹(z)/Δt`` units, as
        :func:`hdr.merge.merge`).
    flags : ndarray, ``(N, H, W, C)`` uint8
        :data:`WARPED`, :data:`FALLBACK`, :data:`GHOST` (a neighbour was
        rejected), :data:`hdr.merge.CLIPPED` / :data:`hdr.merge.BLACK` (the
        value is a bound).
    exposure_times_s : tuple of float
    frames : tuple of dict
        Per frame: ``sources`` (share of pixel-channels from ``current``,
        ``previous``, ``next``, ``both``, ``fallback``), ``rejected`` (share of
        the current frame's unreliable pixel-channels each test refused, per
        neighbour), ``flow`` (mode, levels, occluded share, mean |v| px).
    params : dict
    warnings : tuple of str
    """

    radiance: np.ndarray
    flags: np.ndarray
    exposure_times_s: tuple[float, ...]
    frames: tuple[dict, ...]
    params: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def __post_init__(self):
        if self.radiance.dtype != np.float32 or self.radiance.ndim != 4:
            raise TypeError(f"radiance: expected (N, H, W, C) float32, got "
                            f"{self.radiance.shape} {self.radiance.dtype}")
        if self.flags.shape != self.radiance.shape or self.flags.dtype != np.uint8:
            raise ValueError(f"flags: expected {self.radiance.shape} uint8, got "
                             f"{self.flags.shape} {self.flags.dtype}")
        if len(self.frames) != self.radiance.shape[0]:
            raise ValueError(f"frames: expected {self.radiance.shape[0]} diagnostics, got "
                             f"{len(self.frames)}")


@dataclass(frozen=True)
class TonemappedVideo:
    """Display frames of :func:`tonemap_video`.

    Attributes
    ----------
    images : ndarray, ``(N, H, W, 3)`` uint8 or uint16, sRGB-encoded
    log_average : ndarray, ``(N,)`` float64
        Each frame's own log-average luminance ``L̄_w`` (Reinhard eq. 1).
    log_average_used : ndarray, ``(N,)`` float64
        The temporally smoothed ``L̄_w`` the frames were scaled by.
    flicker : float
        Mean ``|Δ ln L̄|`` between consecutive frames of the log-average the
        frames were scaled by: how much the display of a pixel whose radiance
        did not change jumps from frame to frame (0: none).
    """

    images: np.ndarray
    log_average: np.ndarray
    log_average_used: np.ndarray
    flicker: float
    params: dict = field(default_factory=dict)


# ------------------------------------------------------------- validation
def _check(frames, exposure_times_s, response):
    if not isinstance(response, ResponseCurve):
        raise TypeError(f"response: expected a ResponseCurve, got {type(response).__name__}")
    z, t, _ = check_stack(frames, exposure_times_s, bit_depth=response.bit_depth, where="frames",
                          distinct_times=False)
    if z.shape[0] < 2:
        raise InputError("frames", f"HDR video needs at least 2 frames, got {z.shape[0]}")
    if response.channels not in (1, z.shape[-1]):
        raise InputError("response", f"curve has {response.channels} channels, frames have "
                                     f"{z.shape[-1]}")
    if float(t.max() / t.min()) < 1.0 + 1e-3:
        raise InputError("exposure_times_s",
                         f"every frame has the same exposure ({t[0]:g} s): HDR video needs "
                         "alternating exposures (neighbours would clip where the current frame "
                         "does); use a plain merge or tone map")
    return z, t


# ------------------------------------------------------------ the pieces
class Radiometry:
    """Per-code lookup tables of a response and noise model, shared by every frame.

    Parameters
    ----------
    response : ResponseCurve
    c : int
        Channels of the frames (a single-channel curve is repeated).
    full_well_e, read_noise_e, clip_margin : float
        As :func:`hdr.merge.merge`.

    Attributes
    ----------
    x : ndarray, ``(C, Z)`` float
        ``f⁻¹(z)``, relative exposure per code (eq. 6.4 before ``/Δt``).
    reliable : ndarray, ``(C, Z)`` bool
        Codes with a non-zero variance weight.
    var : ndarray, ``(C, Z)`` float
        Variance of ``f⁻¹(z)`` (0 at unreliable codes).
    lo, hi : int
        The lowest and highest code reliable in every channel: below ``lo`` a
        pixel is black, above ``hi`` saturated.

    Examples
    --------
    >>> rad = Radiometry(ResponseCurve.linear(8, 1), 3, full_well_e=1e4, read_noise_e=5.0,
    ...                  clip_margin=0.02)
    >>> rad.lo, rad.hi, rad.lookup(rad.reliable, np.array([[[0, 128, 255]]], np.uint8)).tolist()
    (6, 249, [[[False, True, False]]])
    """

    def __init__(self, response, c, *, full_well_e, read_noise_e, clip_margin):
        x = response.exposure_table()
        if response.channels == 1:
            x = np.repeat(x, c, axis=0)
        self.x = x  # f^-1(z), (C, Z)
        w = variance_weight_table(x, full_well_e=full_well_e, read_noise_e=read_noise_e,
                                  clip_margin=clip_margin)
        self.reliable = w > 0  # (C, Z)
        # Variance of f^-1(z) (before / Δt²); at unreliable codes that of the
        # nearest reliable code, used only for the bound tests.
        var = np.where(w > 0, 1.0 / np.maximum(w, 1e-300), np.nan)
        self.zmax = response.code_max
        self.lo = int(math.ceil(clip_margin * self.zmax))
        self.hi = int(math.floor((1 - clip_margin) * self.zmax))
        ok = np.nonzero(self.reliable.all(axis=0))[0]
        if ok.size == 0:
            raise InputError("response", "no code value is reliable at this clip margin")
        self.lo, self.hi = int(ok[0]), int(ok[-1])
        self.var = np.where(np.isfinite(var), var, 0.0)
        self.var_lo = var[:, self.lo]
        self.var_hi = var[:, self.hi]
        # Monotone copy of f^-1 for re-encoding exposures as codes.
        self.x_mono = np.maximum.accumulate(x, axis=1)

    def lookup(self, table, z):
        """``table[ch][z[..., ch]]`` per channel: a ``(C, Z)`` table at codes ``z``
        (float32; bool for a bool table)."""
        out = np.empty(z.shape, bool if np.asarray(table).dtype == bool else np.float32)
        for ch in range(z.shape[-1]):
            out[..., ch] = table[ch][z[..., ch]]
        return out

    def encode(self, e):
        """Exposure (``f⁻¹`` units) → normalised code in [0, 1], per channel."""
        out = np.empty(e.shape, np.float32)
        codes = np.arange(self.zmax + 1, dtype=np.float64) / self.zmax
        for ch in range(e.shape[-1]):
            out[..., ch] = np.interp(e[..., ch], self.x_mono[ch], codes)
        return out


def equalise(x_a, t_a, x_b, t_b, rad: Radiometry):
    """Both frames' radiance re-exposed at ``max(t_a, t_b)``, clipped to the range
    both can record and re-encoded through the response (Kang's "boost")."""
    t = max(t_a, t_b)
    lo = rad.x[:, rad.lo] * t / min(t_a, t_b)
    hi = rad.x[:, rad.hi]
    lo = np.minimum(lo, hi)
    return (rad.encode(np.clip(x_a * t, lo, hi)), rad.encode(np.clip(x_b * t, lo, hi)))


def _flow(a, b, *, window, method, max_motion_px):
    """Flow ``a → b`` with its forward-backward round trip: ``(flow, inconsistent,
    round_trip_px, levels)``, as ``pyramid_flow(consistency=True)`` but keeping
    the round-trip error, which bounds how far off a disowned vector may be."""
    from lumigraph.stereo.pyramid import forward_backward
    from lumigraph.stereo.pyramid_flow import pyramid_flow

    opts = dict(method=method, window=window, consistency=False)
    fwd = pyramid_flow(a, b, levels="auto", max_motion_px=max_motion_px, **opts)
    # Same pyramid depth and top-level search radius backwards.
    bwd = pyramid_flow(b, a, levels="auto",
                       max_motion_px=fwd.info["level_choice"]["max_motion_px"], **opts)
    bad, rt = forward_backward(fwd.flow, bwd.flow)
    return fwd.flow, bad, rt, fwd.levels


def _register(i, x_all, t, rad, grid, flow_opts, *, bidirectional):
    """Sampling maps of frame ``i``'s neighbours: ``{j: (H, W, 2) map}``, their
    forward-backward inconsistency ``{j: (H, W) bool}``, the position
    uncertainty of each sample ``{j: (H, W) px}`` and diagnostics."""
    n = len(x_all)
    nbrs = [j for j in (i - 1, i + 1) if 0 <= j < n]
    maps, occ, unc = {}, {}, {}
    if bidirectional and len(nbrs) == 2:
        p, q = nbrs
        f, bad, rt, levels = _flow(*equalise(x_all[p], t[p], x_all[q], t[q], rad), **flow_opts)
        # Constant velocity: v(x) = F(x - v(x)) / 2 by fixed-point iteration.
        v = 0.5 * f
        for _ in range(3):
            v = 0.5 * _remap(f, grid - v, border_value=0.0)
        at = grid - v
        bad_c = _remap(bad.astype(np.float32), at, linear=False, border_value=1.0) > 0
        # Each neighbour is displaced by half the flow, so by half its error.
        unc_c = 0.5 * _remap(rt, at, linear=False, border_value=np.inf)
        maps = {p: grid - v, q: grid + v}
        occ = {p: bad_c, q: bad_c}
        unc = {p: unc_c, q: unc_c}
        fdiag = {"mode": "bidirectional", "levels": levels, "occluded": float(bad.mean()),
                 "mean_motion_px": float(np.hypot(v[..., 0], v[..., 1]).mean())}
        return maps, occ, unc, fdiag
    fdiag = {"mode": "unidirectional"}
    for j in nbrs:
        key = f"{j - i:+d}"
        f, bad, rt, levels = _flow(*equalise(x_all[i], t[i], x_all[j], t[j], rad), **flow_opts)
        maps[j], occ[j], unc[j] = grid + f, bad, rt
        fdiag[f"levels_{key}"] = levels
        fdiag[f"occluded_{key}"] = float(bad.mean())
        fdiag[f"mean_motion_px_{key}"] = float(np.hypot(f[..., 0], f[..., 1]).mean())
        b = 2 * j - i
        if not (bidirectional and len(nbrs) == 1 and 0 <= b < n):
            continue
        # End frame: the frame two away has the current exposure, so their
        # flow needs no boost (no amplified noise, no clipping to the common
        # range); under constant velocity the neighbour sits half-way. Where
        # that flow's round trip fails, the one-way flow's may still close.
        f2, bad2, rt2, levels2 = _flow(*equalise(x_all[i], t[i], x_all[b], t[b], rad),
                                       **flow_opts)
        # Per pixel the registration whose round trip closes; if both or
        # neither, the one with the smaller position uncertainty.
        use2 = (~bad2 & bad) | ((bad2 == bad) & (0.5 * rt2 <= rt))
        maps[j] = np.where(use2[..., None], grid + 0.5 * f2, maps[j])
        occ[j] = bad2 & bad
        unc[j] = np.where(use2, 0.5 * rt2, rt)
        fdiag["mode"] = "halved same-exposure pair, else unidirectional"
        fdiag["pair"] = [i, b]
        fdiag[f"levels_{b - i:+d}"] = levels2
        fdiag["occluded_same_exposure"] = float(bad2.mean())
        fdiag[f"used_same_exposure_{key}"] = float(use2.mean())
    return maps, occ, unc, fdiag


def _remap(img, m, *, linear=True, border_value=0.0):
    import cv2

    interp = cv2.INTER_LINEAR if linear else cv2.INTER_NEAREST
    return _keep_axis(img, cv2.remap(np.ascontiguousarray(img, np.float32), m, None, interp,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=border_value))


def _grid(h, w):
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return np.stack([xs, ys], axis=-1)


def _keep_axis(a, out):
    """OpenCV drops a single channel's axis: give (H, W, 1) back for (H, W, 1)."""
    return out[..., None] if np.ndim(a) == 3 and out.ndim == 2 else out


def _dilate(a, k):
    import cv2

    return _keep_axis(a, cv2.dilate(a, np.ones((k, k), np.uint8), borderType=cv2.BORDER_REPLICATE))


def _erode(a, k):
    import cv2

    return _keep_axis(a, cv2.erode(a, np.ones((k, k), np.uint8), borderType=cv2.BORDER_REPLICATE))


def _flat_within(xw, radius, tol2):
    """Where the warped neighbour ``xw`` (NaN: unreliable) varies by at most
    ``sqrt(tol2)`` over a square of half-width >= ``radius`` px (at least 2) around
    each pixel: there the sample's value does not depend on where exactly it
    was taken. Beyond 16 px nothing counts as flat."""
    lo_img = np.where(np.isnan(xw), np.inf, xw)
    hi_img = np.where(np.isnan(xw), 0.0, xw)
    flat = np.zeros(xw.shape, bool)
    todo = np.ones(radius.shape, bool)
    for half in (2, 4, 8, 16):
        here = todo & (radius <= half)
        if here.any():
            k = 2 * half + 1
            ok = (_dilate(hi_img, k) - _erode(lo_img, k)) ** 2 <= tol2
            flat |= here[..., None] & ok
        todo &= ~here
    return flat


def _box_mean(a, k):
    import cv2

    return _keep_axis(a, cv2.blur(np.ascontiguousarray(a, np.float32), (k, k),
                                  borderType=cv2.BORDER_REFLECT))


# --------------------------------------------------------------- the method
def hdr_video(frames: np.ndarray, exposure_times_s, response: ResponseCurve, *, window: int = 9,
              flow_method: str = "dense", consistency_sigma: float = 6.0,
              neighbourhood: int = 7, outlier_share: float = 0.25,
              bidirectional: bool = True, max_motion_px: float | None = None,
              full_well_e: float = 10000.0, read_noise_e: float = 5.0,
              clip_margin: float = 0.02, progress=None, device="cpu",
              only: Sequence[int] | None = None) -> HDRVideo:
    """Radiance of every frame of an alternating-exposure video.

    Parameters
    ----------
    frames : ndarray, ``(N, H, W, C)`` uint8/uint16 codes, ``N >= 2``
        In time order; consecutive frames should differ in exposure.
    exposure_times_s : sequence of float, ``(N,)``
        Exposure time of each frame, seconds (not all equal).
    response : ResponseCurve
        The camera's curve (bit depth of the codes).
    window : int
        Flow window (odd, px) of :func:`stereo.pyramid_flow.pyramid_flow`.
    flow_method : {"dense", "local"}
        ``"dense"`` fills textureless (clipped) areas from their surroundings.
    consistency_sigma : float
        ``k``: a warped neighbour further than ``k`` noise σ from what the
        current frame says (its bound, or the other neighbour) is rejected.
        6 was chosen on held-out renders subject to the large-motion hard
        case (``docs/decisions/hdr-video-consistency-sigma.md``).
    neighbourhood : int
        Side (px) of the window of well-exposed current pixels a warped
        neighbour must agree with.
    outlier_share : float
        Reject a neighbour pixel when more than this share of those current
        pixels differ by more than ``k`` σ (misregistration nearby).
    bidirectional : bool
        Inner frames register through the previous → next flow (True) or
        each neighbour on its own equalised pair (False).
    max_motion_px : float, optional
        Largest expected motion between consecutive frames (px) for the
        flow's pyramid depth; default estimated by the flow.
    full_well_e, read_noise_e, clip_margin : float
        Noise model and clipping of :func:`hdr.merge.merge`.
    progress : callable, optional
        Wraps the frame loop (``progress(range(N))``), e.g.
        :func:`capture.commandline.progress`.
    only : sequence of int, optional
        Complete only these frames (indices into ``frames``): the result is
        the video of those frames, in that order (their diagnostics keep the
        indices into ``frames``). Frame ``i`` reads the frames
        :func:`frames_used` names only, so ``hdr_video(frames[r.start:r.stop],
        ..., only=[i - r.start])`` with ``r = frames_used(i, N)`` gives frame
        ``i``'s radiance to the bit (what a batch item of ``hdr video``
        computes).
    device : {"cpu", "cuda", "torch-cpu", "auto"}
        Where the neighbours are warped onto each frame
        (:mod:`lumigraph.capture.device`; a torch device:
        :func:`hdr.video_torch.warp_neighbour_torch`); the flow and the
        tests run on the CPU.

    Returns
    -------
    HDRVideo

    Raises
    ------
    InputError
        Fewer than 2 frames, times not one per frame / not positive, all
        frames at one exposure, codes beyond the curve's bit depth.

    Notes
    -----
    The steps, each a function below: check the inputs (:func:`_check`,
    :func:`_check_options`); every frame through the response
    (:func:`_linearise`); then per frame: the frame to complete and its
    clipping bounds (:func:`_current_frame`), register its neighbours
    (:func:`_register`, boosting each pair with :func:`equalise`), warp them
    (:func:`_warp_neighbour`), test each against the frame
    (:func:`_consistency`), accept by the pair's agreement (:func:`_accept`),
    fill and flag (:func:`_fill`), and account for the sources
    (:func:`_sources`).
    """
    z, t = _check(frames, exposure_times_s, response)
    _check_options(flow_method, consistency_sigma, neighbourhood, outlier_share, window)
    warp = _warp_neighbour
    if device != "cpu":
        from lumigraph.capture.device import resolve_device

        dev = resolve_device(device)
        if dev.uses_torch:
            from lumigraph.hdr.video_torch import warp_neighbour_torch

            def warp(video, j, m):
                return warp_neighbour_torch(video, j, m, dev)
    n, h, w, c = z.shape
    rad = Radiometry(response, c, full_well_e=full_well_e, read_noise_e=read_noise_e,
                      clip_margin=clip_margin)
    tests = _Tests(k2=float(consistency_sigma) ** 2, neighbourhood=neighbourhood,
                   outlier_share=outlier_share)
    flow_opts = dict(window=window, method=flow_method, max_motion_px=max_motion_px)
    grid = _grid(h, w)
    video = _linearise(z, t, rad)

    out = np.empty((n, h, w, c), np.float32)
    flags = np.zeros((n, h, w, c), np.uint8)
    diags = []
    todo = range(n) if only is None else [int(i) for i in only]
    if any(not 0 <= i < n for i in todo):
        raise InputError("only", f"frame indices must be within 0..{n - 1}")
    steps = todo if progress is None else progress(todo)
    for i in steps:
        t0 = time.perf_counter()
        cur = _current_frame(i, z, t, video, rad)
        maps, occ, unc, fdiag = _register(i, video.x, t, rad, grid, flow_opts,
                                          bidirectional=bidirectional)
        warped = {j: warp(video, j, maps[j]) for j in cur.neighbours}
        checked = {j: _consistency(cur, warped[j], occ[j], unc[j], tests)
                   for j in cur.neighbours}
        accepted, rejected = _accept(cur, warped, checked, tests)
        out[i], flags[i], used, fallback = _fill(cur, warped, accepted)
        diags.append({"frame": i, "exposure_s": float(t[i]),
                      "sources": _sources(cur, used, fallback),
                      "rejected": rejected, "flow": fdiag,
                      "time_s": time.perf_counter() - t0})
    params = {"window": window, "flow_method": flow_method,
              "consistency_sigma": float(consistency_sigma), "neighbourhood": neighbourhood,
              "outlier_share": float(outlier_share), "bidirectional": bool(bidirectional),
              "max_motion_px": max_motion_px, "full_well_e": full_well_e,
              "read_noise_e": read_noise_e, "clip_margin": clip_margin}
    if only is not None:  # the video of the frames asked for, in their order
        out, flags, t = out[todo], flags[todo], [t[i] for i in todo]
    return HDRVideo(out, flags, tuple(float(x) for x in t), tuple(diags), params,
                    tuple(_fallback_warnings(diags)))


def frames_used(i: int, n: int, *, bidirectional: bool = True) -> range:
    """The frames :func:`hdr_video` reads to complete frame ``i`` of ``n``: its
    neighbours ``i-1..i+1``; an end frame also the frame two away (same
    exposure, :func:`_register`).

    >>> frames_used(0, 10), frames_used(5, 10), frames_used(9, 10), frames_used(1, 2)
    (range(0, 3), range(4, 7), range(7, 10), range(0, 2))
    """
    lo, hi = max(0, i - 1), min(n, i + 2)
    if bidirectional and hi - lo == 2:  # an end frame (of a video of 3 frames or more)
        lo, hi = max(0, min(lo, i - 2)), min(n, max(hi, i + 3))
    return range(lo, hi)


# ------------------------------------------------------- the method's steps
MIN_WINDOW = 3  # the flow's own least window (stereo.pyramid_flow.check_options)


def check_video_options(*, window: int = 9, consistency_sigma: float = 6.0) -> None:
    """:func:`hdr_video`'s ``window`` (odd, >= :data:`MIN_WINDOW` px: the
    flow's, :func:`stereo.pyramid_flow.check_options`) and
    ``consistency_sigma`` (a finite number > 0), checked before any frame is
    read.

    Raises
    ------
    InputError
        Naming ``window`` or ``consistency_sigma``.

    Examples
    --------
    >>> check_video_options(window=9, consistency_sigma=6.0)
    >>> try:
    ...     check_video_options(window=0)
    ... except InputError as e:
    ...     print(e)
    window: expected an odd size >= 3, got 0
    """
    from lumigraph.stereo.pyramid_flow import check_options

    if isinstance(window, bool) or not isinstance(window, int | np.integer):
        raise InputError("window", f"expected an odd integer >= {MIN_WINDOW}, got {window!r}")
    check_options(window=int(window))
    try:
        ok = math.isfinite(consistency_sigma) and consistency_sigma > 0
    except TypeError:
        ok = False
    if not ok:
        raise InputError("consistency_sigma", f"expected a finite number > 0, got "
                                              f"{consistency_sigma!r}")


def _check_options(flow_method, consistency_sigma, neighbourhood, outlier_share, window=9):
    """Step 0: the options (the frames, times and curve are :func:`_check`'s)."""
    check_video_options(window=window, consistency_sigma=consistency_sigma)
    if flow_method not in ("dense", "local"):
        raise ValueError(f"flow_method: expected 'dense' or 'local', got {flow_method!r}")
    if neighbourhood < 1 or neighbourhood % 2 == 0:
        raise ValueError(f"neighbourhood: expected an odd size >= 1, got {neighbourhood}")
    if not 0 < outlier_share <= 1:
        raise ValueError(f"outlier_share: expected in (0, 1], got {outlier_share}")


@dataclass(frozen=True)
class _Tests:
    """The consistency tests' settings: ``k²`` (``consistency_sigma²``), the side of
    the well-exposed window and the outlier share that rejects a neighbour there."""

    k2: float
    neighbourhood: int
    outlier_share: float


@dataclass(frozen=True)
class _Linear:
    """Every frame through the response (eq. 6.4): radiance ``x = f⁻¹(z)/Δt``, its
    variance and whether its code is reliable, ``(H, W, C)`` per frame."""

    x: list
    reliable: list
    var: list


def _linearise(z, t, rad: Radiometry) -> _Linear:
    """Step 1: radiance, reliability and variance of every frame."""
    n = len(z)
    return _Linear(x=[rad.lookup(rad.x, z[i]) / np.float32(t[i]) for i in range(n)],
                   reliable=[rad.lookup(rad.reliable.astype(np.float32), z[i]) > 0
                             for i in range(n)],
                   var=[rad.lookup(rad.var, z[i]) / np.float32(t[i] ** 2) for i in range(n)])


@dataclass(frozen=True)
class _Current:
    """Frame ``i`` as the one to complete: its own values, where it is unreliable
    (saturated or black), and the bounds its clipped pixels put on the truth."""

    index: int
    neighbours: tuple[int, ...]
    x: np.ndarray
    reliable: np.ndarray
    var: np.ndarray
    unreliable: np.ndarray
    saturated: np.ndarray
    bound_hi: np.ndarray  # (C,): saturated => radiance >= f^-1(z_hi)/Δt
    bound_lo: np.ndarray  # (C,): black => radiance <= f^-1(z_lo)/Δt
    var_bound_hi: np.ndarray
    var_bound_lo: np.ndarray

    @property
    def unreliable_count(self) -> int:
        """Unreliable pixel-channels (at least 1: the shares' denominator)."""
        return max(int(self.unreliable.sum()), 1)


def _current_frame(i, z, t, video: _Linear, rad: Radiometry) -> _Current:
    """Step 2: frame ``i``, its neighbours and its clipping bounds."""
    unrel = ~video.reliable[i]
    return _Current(index=i, neighbours=tuple(j for j in (i - 1, i + 1) if 0 <= j < len(z)),
                    x=video.x[i], reliable=video.reliable[i], var=video.var[i],
                    unreliable=unrel, saturated=unrel & (z[i] > rad.hi),
                    bound_hi=(rad.x[:, rad.hi] / t[i]).astype(np.float32),
                    bound_lo=(rad.x[:, rad.lo] / t[i]).astype(np.float32),
                    var_bound_hi=(rad.var_hi / t[i] ** 2).astype(np.float32),
                    var_bound_lo=(rad.var_lo / t[i] ** 2).astype(np.float32))


@dataclass(frozen=True)
class _Warped:
    """A neighbour pulled onto the current frame: radiance, variance, and where
    its interpolation footprint was mostly reliable."""

    x: np.ndarray
    var: np.ndarray
    reliable: np.ndarray


def _warp_neighbour(video: _Linear, j, sampling_map) -> _Warped:
    """Step 4 (after registration, step 3 :func:`_register`): neighbour ``j``
    resampled at ``sampling_map``.

    Normalised interpolation: only the neighbour's reliable pixels contribute,
    so one clipped pixel in a footprint does not void it."""
    rw = _remap(video.reliable[j].astype(np.float32), sampling_map, border_value=0.0)
    rws = np.maximum(rw, 1e-6)
    return _Warped(x=_remap(np.where(video.reliable[j], video.x[j], 0.0), sampling_map) / rws,
                   var=_remap(np.where(video.reliable[j], video.var[j], 0.0), sampling_map) / rws,
                   reliable=rw > 0.5)


@dataclass(frozen=True)
class _Checked:
    """The single-neighbour tests' outcome: ``passed`` (reliable, within the current
    frame's bound, no misregistration nearby), ``occluded`` (the flow's round trip
    disowns the sample and the neighbour is not flat there) and the shares of the
    current frame's unreliable pixel-channels each test refused."""

    passed: np.ndarray
    occluded: np.ndarray
    rejected: dict


def _consistency(cur: _Current, nb: _Warped, occ, unc, tests: _Tests) -> _Checked:
    """Step 5: test a warped neighbour against the current frame."""
    k2, c = tests.k2, cur.x.shape[-1]
    xw, vw, relw = nb.x, nb.var, nb.reliable
    unrel, sat, nu = cur.unreliable, cur.saturated, cur.unreliable_count
    # A flow the round trip disowns only matters where the neighbour has
    # structure within the flow's uncertainty; flat there, the value is the
    # same wherever it was sampled. The uncertainty is the round-trip error
    # (a 90 px pan the pyramid cannot follow leaves errors of tens of px,
    # where a fixed 5 px window let flat-but-wrong dark areas through).
    flat = _flat_within(np.where(relw, xw, np.nan), unc, k2 * vw)
    occl = np.repeat(occ[..., None], c, axis=2) & ~flat
    # Clipped current pixel: the truth is above (saturated) / below (black) its bound.
    low = sat & ((cur.bound_hi - xw) ** 2 > k2 * (vw + cur.var_bound_hi)) & (xw < cur.bound_hi)
    high = ((unrel & ~sat) & ((xw - cur.bound_lo) ** 2 > k2 * (vw + cur.var_bound_lo))
            & (xw > cur.bound_lo))
    # Misregistration shows where both frames are well exposed nearby.
    n = tests.neighbourhood
    both = cur.reliable & relw
    r2 = np.where(both, (xw - cur.x) ** 2 / np.maximum(vw + cur.var, 1e-30), 0.0)
    cnt = _box_mean(both.astype(np.float32), n)
    bad = _box_mean((both & (r2 > k2)).astype(np.float32), n)
    ghost_near = (cnt * n ** 2 >= 3) & (bad > tests.outlier_share * cnt)
    return _Checked(passed=relw & ~low & ~high & ~ghost_near, occluded=occl,
                    rejected={"neighbour_unreliable": float((unrel & ~relw).sum() / nu),
                              "bound": float((unrel & (low | high)).sum() / nu),
                              "neighbourhood": float((unrel & ghost_near).sum() / nu)})


def _accept(cur: _Current, warped, checked, tests: _Tests):
    """Step 6: the pixel-channels each neighbour may fill, and the rejection shares.

    With two neighbours, both warped independently and agreeing within noise
    outvote a flow round trip that did not close; disagreeing, neither is used."""
    i, nbrs, unrel, nu = cur.index, cur.neighbours, cur.unreliable, cur.unreliable_count
    rejected = {f"{j - i:+d}": dict(checked[j].rejected) for j in nbrs}
    accepted = {}
    if len(nbrs) == 2:
        p, q = nbrs
        a, b = warped[p], warped[q]
        pair = checked[p].passed & checked[q].passed
        agree = pair & ((a.x - b.x) ** 2 <= tests.k2 * (a.var + b.var))
        disagree = pair & ~agree
        for j in nbrs:
            accepted[j] = checked[j].passed & ~disagree & (~checked[j].occluded | agree)
        rejected["disagree"] = float((unrel & disagree).sum() / nu)
    else:
        for j in nbrs:
            accepted[j] = checked[j].passed & ~checked[j].occluded
    for j in nbrs:
        rejected[f"{j - i:+d}"]["occluded"] = float(
            (unrel & checked[j].passed & checked[j].occluded & ~accepted[j]).sum() / nu)
    return accepted, rejected


def _fill(cur: _Current, warped, accepted):
    """Step 7 (§6.3.2 step 3): the frame's radiance and flags.

    Reliable pixel-channels keep the current frame's value; unreliable ones the
    inverse-variance mean of the accepted neighbours (:data:`WARPED`), or with
    none the frame's own clipping bound as :func:`hdr.merge.merge` gives it
    (:data:`FALLBACK` with :data:`CLIPPED` / :data:`BLACK`). :data:`GHOST`
    marks a neighbour that was rejected there."""
    h, w, c = cur.x.shape
    unrel, sat = cur.unreliable, cur.saturated
    num = np.zeros((h, w, c), np.float32)
    den = np.zeros((h, w, c), np.float32)
    used = {}
    for j in cur.neighbours:
        xw, vw = warped[j].x, warped[j].var
        ok = accepted[j] & unrel
        used[j] = ok
        wgt = np.where(ok, 1.0 / np.maximum(vw, 1e-30), 0.0).astype(np.float32)
        num += wgt * np.where(ok, xw, 0.0)
        den += wgt
    filled = unrel & (den > 0)
    fallback = unrel & ~filled
    res = cur.x.copy()
    res[filled] = num[filled] / den[filled]
    res[fallback & sat] = np.broadcast_to(cur.bound_hi, res.shape)[fallback & sat]
    fb_dark = fallback & ~sat
    res[fb_dark] = np.broadcast_to(cur.bound_lo, res.shape)[fb_dark]
    f = np.zeros((h, w, c), np.uint8)
    f[filled] |= WARPED
    f[fallback] |= FALLBACK
    f[fallback & sat] |= CLIPPED
    f[fb_dark] |= BLACK
    any_rej = np.zeros((h, w, c), bool)
    for j in cur.neighbours:
        any_rej |= unrel & warped[j].reliable & ~accepted[j]  # inconsistent neighbour
    f[any_rej] |= GHOST
    return res, f, used, fallback


def _sources(cur: _Current, used, fallback) -> dict:
    """Step 8: the share of pixel-channels each source gave."""
    i, rc = cur.index, cur.reliable
    total = float(rc.size)
    prev_u = used.get(i - 1, np.zeros_like(cur.unreliable))
    next_u = used.get(i + 1, np.zeros_like(cur.unreliable))
    return {"current": float(rc.sum() / total),
            "previous": float((prev_u & ~next_u).sum() / total),
            "next": float((next_u & ~prev_u).sum() / total),
            "both": float((prev_u & next_u).sum() / total),
            "fallback": float(fallback.sum() / total)}


def _fallback_warnings(diags) -> list[str]:
    """What the caller must hear: much of the video kept its clipping bounds."""
    fb = [d["sources"]["fallback"] for d in diags]
    if max(fb) <= 0.05:
        return []
    return [f"{100 * float(np.mean(fb)):.1f} % of pixel-channels (up to "
            f"{100 * max(fb):.1f} % in frame {int(np.argmax(fb))}) are unreliable in "
            "their frame with no consistent neighbour: kept the frame's clipping "
            "bound, flagged (the exposures are too close for this scene's range, or "
            "the motion too large)"]


def unaligned_merge(frames: np.ndarray, exposure_times_s, response: ResponseCurve, index: int, *,
                    full_well_e: float = 10000.0, read_noise_e: float = 5.0,
                    clip_margin: float = 0.02) -> np.ndarray:
    """The naive baseline: frame ``index`` and its neighbours merged without registration.

    Inverse-variance weights of :func:`hdr.merge.merge` over frames
    ``index-1 .. index+1`` (those that exist; repeated exposure times are fine
    here, unlike a bracket); where none is reliable, the current frame's
    clipping bound as in :func:`hdr_video`.

    Returns
    -------
    ndarray, ``(H, W, C)`` float32, relative radiance.

    Examples
    --------
    >>> r = ResponseCurve.linear(8, 1)
    >>> z = np.stack([np.full((2, 2, 1), v, np.uint8) for v in (100, 200, 100)])
    >>> round(float(unaligned_merge(z, [1.0, 2.0, 1.0], r, 1)[0, 0, 0]), 4)  # 100/255 per second
    0.3922
    """
    z, t = _check(frames, exposure_times_s, response)
    if not 0 <= index < z.shape[0]:
        raise ValueError(f"index: expected 0..{z.shape[0] - 1}, got {index}")
    rad = Radiometry(response, z.shape[-1], full_well_e=full_well_e, read_noise_e=read_noise_e,
                      clip_margin=clip_margin)
    num = np.zeros(z.shape[1:], np.float32)
    den = np.zeros(z.shape[1:], np.float32)
    for j in range(max(0, index - 1), min(z.shape[0], index + 2)):
        var = rad.lookup(rad.var, z[j]) / np.float32(t[j] ** 2)
        ok = rad.lookup(rad.reliable.astype(np.float32), z[j]) > 0
        wgt = np.where(ok, 1.0 / np.maximum(var, 1e-30), 0.0).astype(np.float32)
        num += wgt * rad.lookup(rad.x, z[j]) / np.float32(t[j])
        den += wgt
    out = np.where(den > 0, num / np.maximum(den, 1e-30), 0.0).astype(np.float32)
    zi = z[index]
    sat = (den <= 0) & (zi > rad.hi)
    dark = (den <= 0) & ~sat
    out[sat] = np.broadcast_to((rad.x[:, rad.hi] / t[index]).astype(np.float32), out.shape)[sat]
    out[dark] = np.broadcast_to((rad.x[:, rad.lo] / t[index]).astype(np.float32), out.shape)[dark]
    return out


# ------------------------------------------------------------ tone mapping
def check_temporal(temporal: int) -> int:
    """:func:`tonemap_video`'s ``temporal``: an odd number of frames >= 1.

    Raises
    ------
    InputError
        Naming ``temporal``.

    Examples
    --------
    >>> check_temporal(5)
    5
    >>> try:
    ...     check_temporal(4)
    ... except InputError as e:
    ...     print(e)
    temporal: expected an odd number of frames >= 1, got 4
    """
    if not isinstance(temporal, int | np.integer) or temporal < 1 or temporal % 2 == 0:
        raise InputError("temporal", f"expected an odd number of frames >= 1, got {temporal!r}")
    return temporal


@dataclass(frozen=True)
class VideoExposure:
    """What :func:`tonemap_video` carries from frame to frame: per frame
    ``ln L̄_w`` (Reinhard eq. 1) and ``ln L_max``, and their centred moving
    averages over ``temporal`` frames (:func:`video_exposure`). Everything
    else is per frame, so a video of any length is tone-mapped one frame in
    memory at a time (:func:`tonemap_frame`).

    Attributes
    ----------
    log_avg, log_max : ndarray, ``(N,)`` float64
        Each frame's own ``ln L̄_w`` and ``ln L_max`` (:func:`frame_log_stats`).
    smoothed_log_avg, smoothed_log_max : ndarray, ``(N,)`` float64
        Their centred means over ``temporal`` frames, shrinking at the ends.
    key : float
    temporal : int
    bit_depth : {8, 16}
    delta : float
        Reinhard's ``δ`` (eq. 1), the floor of the luminance's log.
    """

    log_avg: np.ndarray
    log_max: np.ndarray
    smoothed_log_avg: np.ndarray
    smoothed_log_max: np.ndarray
    key: float
    temporal: int
    bit_depth: int = 8
    delta: float = 1e-6

    @property
    def log_average(self) -> np.ndarray:
        """Each frame's own ``L̄_w``."""
        return np.exp(self.log_avg)

    @property
    def log_average_used(self) -> np.ndarray:
        """The smoothed ``L̄_w`` each frame is scaled by."""
        return np.exp(self.smoothed_log_avg)

    @property
    def flicker(self) -> float:
        """:attr:`TonemappedVideo.flicker`."""
        n = len(self.smoothed_log_avg)
        return float(np.mean(np.abs(np.diff(self.smoothed_log_avg)))) if n > 1 else 0.0

    @property
    def params(self) -> dict:
        return {"key": self.key, "temporal": int(self.temporal), "bit_depth": self.bit_depth}


def frame_log_stats(radiance: np.ndarray, *, delta: float = 1e-6) -> tuple[float, float]:
    """One frame's ``ln L̄_w`` (Reinhard et al. 2002 eq. 1: the mean of
    ``ln(δ + L_w)``) and ``ln max(L_max, δ)``, luminance ``L_w`` of the
    radiance clipped at 0 (:data:`hdr.reinhard2002.LUMA`).

    Parameters
    ----------
    radiance : ndarray, ``(H, W, 3)`` float, linear, finite
    delta : float

    Returns
    -------
    (float, float)

    Examples
    --------
    >>> a, m = frame_log_stats(np.full((2, 2, 3), 0.5, np.float32))
    >>> round(math.exp(a), 4), round(math.exp(m), 4)
    (0.5, 0.5)
    """
    v, lum = _frame_luminance(radiance)
    return float(np.mean(np.log(delta + lum))), float(np.log(max(float(lum.max()), delta)))


def _frame_luminance(radiance) -> tuple[np.ndarray, np.ndarray]:
    """A frame's radiance as float64 clipped at 0, and its luminance: the
    arithmetic :func:`tonemap_video` always did, one frame at a time (a
    frame's rows are the same float64 operations whether or not the other
    frames are stacked beside it)."""
    from lumigraph.hdr.reinhard2002 import LUMA

    v = np.asarray(radiance, dtype=np.float64)
    if v.ndim != 3 or v.shape[-1] != 3:
        raise ValueError(f"radiance: expected (H, W, 3), got {np.shape(radiance)}")
    if not np.isfinite(v).all():
        raise ValueError("radiance: expected finite values, got NaN/inf")
    v = np.maximum(v, 0.0)
    return v, v @ LUMA


def video_exposure(log_stats, *, key: float = 0.18, temporal: int = 5, bit_depth: int = 8,
                   delta: float = 1e-6) -> VideoExposure:
    """The temporal part of :func:`tonemap_video`: from each frame's
    :func:`frame_log_stats` (in frame order), the centred moving average of
    ``ln L̄_w`` and ``ln L_max`` over ``temporal`` frames.

    Parameters
    ----------
    log_stats : sequence of (float, float), one per frame
    key, temporal, bit_depth, delta
        As :func:`tonemap_video`.

    Returns
    -------
    VideoExposure

    Raises
    ------
    InputError
        ``temporal`` not odd >= 1, ``bit_depth`` not 8 or 16, ``key`` out of range.

    Examples
    --------
    >>> e = video_exposure([(0.0, 1.0), (1.0, 2.0), (2.0, 3.0)], temporal=3)
    >>> e.smoothed_log_avg.tolist(), e.flicker
    ([0.5, 1.0, 1.5], 0.5)
    """
    from lumigraph.hdr.reinhard2002 import check_key

    check_temporal(temporal)
    if bit_depth not in (8, 16):
        raise InputError("bit_depth", f"expected 8 or 16, got {bit_depth}")
    key = check_key(key)
    stats = [(float(a), float(m)) for a, m in log_stats]
    n = len(stats)
    log_avg = np.array([a for a, _ in stats], np.float64)
    log_max = np.array([m for _, m in stats], np.float64)
    half = temporal // 2
    # Centred moving average of ln L̄_w (and ln L_max), shrinking at the ends.
    sm_avg = np.array([log_avg[max(0, i - half):i + half + 1].mean() for i in range(n)])
    sm_max = np.array([log_max[max(0, i - half):i + half + 1].mean() for i in range(n)])
    return VideoExposure(log_avg, log_max, sm_avg, sm_max, key, int(temporal), bit_depth, delta)


def tonemap_frame(radiance: np.ndarray, exposure: VideoExposure, index: int) -> np.ndarray:
    """Frame ``index`` of :func:`tonemap_video`, alone: Reinhard's global
    operator (eq. 2-4) scaled by the smoothed log-average of ``exposure``
    (:func:`video_exposure`), sRGB-encoded.

    Parameters
    ----------
    radiance : ndarray, ``(H, W, 3)`` float, linear, finite
        The frame ``exposure`` was computed with at ``index``.
    exposure : VideoExposure
    index : int

    Returns
    -------
    ndarray, ``(H, W, 3)`` uint8 or uint16 (``exposure.bit_depth``)

    Examples
    --------
    >>> v = np.exp(np.random.default_rng(1).normal(0, 1, (4, 6, 6, 3))).astype(np.float32)
    >>> e = video_exposure([frame_log_stats(f) for f in v], temporal=3)
    >>> bool((tonemap_frame(v[2], e, 2) == tonemap_video(v, temporal=3).images[2]).all())
    True
    """
    from lumigraph.hdr.reinhard2002 import global_operator, srgb_encode

    v, lum = _frame_luminance(radiance)
    e, i = exposure, int(index)
    top = 2 ** e.bit_depth - 1
    # global_operator scales by the frame's own L̄_w; a key rescaled by
    # L̄_w / L̄_smoothed makes it scale by the smoothed one instead.
    k_i = e.key * math.exp(e.log_avg[i] - e.smoothed_log_avg[i])
    white = e.key * math.exp(e.smoothed_log_max[i] - e.smoothed_log_avg[i])
    ld = global_operator(lum, key=k_i, white=white, delta=e.delta)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(lum > 0, ld / lum, 0.0)
    out = np.empty(v.shape, np.uint8 if e.bit_depth == 8 else np.uint16)
    out[...] = np.round(srgb_encode(v * ratio[..., None]) * top)
    return out


def tonemap_video(radiances: np.ndarray, *, key: float = 0.18, temporal: int = 5,
                  bit_depth: int = 8, delta: float = 1e-6) -> TonemappedVideo:
    """Temporally coherent Reinhard global tone mapping of a radiance video.

    Each frame is Reinhard et al. 2002's global operator (eq. 1-4,
    :func:`hdr.reinhard2002.global_operator`), but the log-average luminance
    ``L̄_w`` (eq. 1) and the white point are the geometric mean over a centred
    window of ``temporal`` frames, so a frame whose clipped areas differ from
    its neighbours' does not change the exposure of the whole picture.

    Only ``L̄_w`` and ``L_max`` cross frames: :func:`frame_log_stats`,
    :func:`video_exposure` and :func:`tonemap_frame` are this function one
    frame in memory at a time, to the bit (``hdr video`` on a cluster uses
    them on videos of any length).

    Parameters
    ----------
    radiances : ndarray, ``(N, H, W, 3)`` float, linear, finite, ≥ 0
    key : float
        Reinhard's key ``a``, > 0.
    temporal : int
        Odd window length in frames, >= 1 (:func:`check_temporal`); 1 is
        per-frame tone mapping.
    bit_depth : {8, 16}

    Returns
    -------
    TonemappedVideo

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> v = np.repeat(np.exp(rng.normal(0, 1, (1, 8, 8, 3))), 6, axis=0).astype(np.float32)
    >>> v[1::2, :2] *= 50.0  # a clipped area's bound alternates, the rest is still
    >>> a, b = tonemap_video(v, temporal=1), tonemap_video(v, temporal=5)
    >>> bool(b.flicker < a.flicker), a.images.shape
    (True, (6, 8, 8, 3))
    """
    v = np.asarray(radiances)
    if v.ndim != 4 or v.shape[-1] != 3:
        raise ValueError(f"radiances: expected (N, H, W, 3), got {np.shape(radiances)}")
    if not np.isfinite(v).all():
        raise ValueError("radiances: expected finite values, got NaN/inf")
    check_temporal(temporal)
    if bit_depth not in (8, 16):
        raise InputError("bit_depth", f"expected 8 or 16, got {bit_depth}")
    e = video_exposure([frame_log_stats(f, delta=delta) for f in v], key=key, temporal=temporal,
                       bit_depth=bit_depth, delta=delta)
    images = np.empty(v.shape, np.uint8 if bit_depth == 8 else np.uint16)
    for i in range(v.shape[0]):
        images[i] = tonemap_frame(v[i], e, i)
    return TonemappedVideo(images, e.log_average, e.log_average_used, e.flicker, e.params)
