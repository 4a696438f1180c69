"""Bench stage ``hdr``: response recovery and merging beside OpenCV, colour-hdri
and pfstools, on ``bracket`` renders with exact ground truth, in one run.

Cases
-----
- ``8-bit``: the default film-response bracket (7 exposures, 1.5 stops,
  shot + read noise); ``12-bit`` and ``16-bit``: the same scene deeper;
- ``8-bit``, ``12-bit``, ``16-bit`` also run our Robertson et al. 2003
  (converged; beside OpenCV CalibrateRobertson and pfstools' Robertson at 8 bits);
- ``8-bit, times ±10 %``: the stack carries nominal times off by up to 10 %
  (Mitsunaga–Nayar refines them, also with the shortest and longest exposures
  known exactly; Debevec gets the exact times as the yardstick; MN's error is
  also given up to the common power rough times leave free, beside the
  information bound of the draw);
- ``merge``: radiance from each method's own curve;
- ``merge 12 MP``: 9 exposures tiled up to 4000×3000 (quick: 1 MP), wall
  time and tracemalloc peak of the merge alone;
- ``video``: ``bracket_video`` (6 frames alternating 3 stops apart, 1.5 px/frame
  pan, a moving light): Kang et al. 2003 HDR video against the unaligned merge
  of each frame with its neighbours, the single frame, and OpenCV MergeDebevec
  on the same unaligned three frames; error = log-radiance RMS over the pixels
  the current frame clips but a neighbour's exposure records (``all``: every
  pixel, 6 px borders excluded).

- ``family <kind> <b>-bit (tuned|reported)``: capture.scenes.brackets' family
  (room, walls, outdoor, night, studio; each its own response and noise;
  seeds 0-2; 8/12/16 bits): Debevec against CalibrateDebevec over codes
  10/255..95 % (median over seeds, worst in the JSON); 12 and 16 bits against
  our 8 bits as the paired per-scene ratio over ``PAIRED_SEEDS`` (0-23: our
  Debevec only; mean ± s.e., median, worst; quick: no deep case), our Robertson against
  CalibrateRobertson (8 bits, full runs), merge against MergeDebevec,
  Mitsunaga-Nayar monotone; ``tuned`` kinds may have set our
  defaults, ``reported`` ones are held out;
- real sets: ``memorial`` (against Debevec's memorial.hdr), ``canon 5D Mk II``
  (the chart's neutral patches' ratios across channels), ``iphone`` (against
  OpenCV's merge; no reference).

Error: ln-response RMS over the well-exposed codes (5–95 % of the range)
after removing each channel's free offset; for merges, relative RMS radiance
error over pixels well exposed in at least one image after one global
scale.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import tempfile
import tracemalloc
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.bench import Case, Check, Method, Results, Stage

SIZE = (320, 240)


# ------------------------------------------------------------------- metrics
def ln_response_rms(g: np.ndarray, g_true: np.ndarray, bit_depth: int) -> float:
    """RMS of ``g − g_true`` over codes 5–95 % of the range, each channel's
    mean difference removed (``g`` is defined up to a constant per channel).

    Examples
    --------
    >>> g = np.log(np.arange(1, 257, dtype=float))[None].repeat(3, 0)
    >>> round(ln_response_rms(g + [[1.0], [2.0], [3.0]], g, 8), 12)
    0.0
    """
    zmax = 2 ** bit_depth - 1
    m = slice(int(math.ceil(0.05 * zmax)), int(0.95 * zmax) + 1)
    d = np.asarray(g, np.float64)[:, m] - np.asarray(g_true, np.float64)[:, m]
    d = d - d.mean(axis=1, keepdims=True)
    return float(np.sqrt(np.mean(d ** 2)))


def radiance_rel_rms(est: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """Relative RMS error over ``mask`` after the least-squares global scale."""
    e = est[mask].astype(np.float64)
    t = truth[mask].astype(np.float64)
    ok = np.isfinite(e)
    e, t = e[ok], t[ok]
    s = float(np.sum(e * t / t ** 2) / np.sum(e * e / t ** 2))
    return float(np.sqrt(np.mean(((s * e - t) / t) ** 2)))


# --------------------------------------------------------------------- cases
def _bracket(bit_depth=8, size=SIZE, **opts):
    from lumigraph.capture.render import render

    s = render("bracket", size=size, bit_depth=bit_depth, seed=3, **opts)
    z = np.stack(s.images)
    if z.ndim == 3:
        z = z[..., None]
    return {"z": z, "times": np.array(s.stack["exposure_times_s"]),
            "exact": np.array(s.gt["exposure_times_exact_s"]), "g_true": s.gt_arrays["g"],
            "bit_depth": bit_depth,
            "radiance": s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]}


def _big(quick):
    from lumigraph.capture.render import render

    s = render("bracket", size=(400, 300), exposures=9, stops=1.0, seed=4)
    reps = (1, 1) if quick else (10, 10)  # 0.12 MP or 12 MP
    z = np.stack([np.tile(im, reps + (1,)) for im in s.images])
    return {"z": z, "times": np.array(s.stack["exposure_times_s"])}


# ------------------------------------------------------------------ methods
def _ours_debevec(d, samples):
    from lumigraph.hdr.debevec1997 import response_debevec1997

    t = d["exact"] if "exact_only" in d else d["times"]
    return response_debevec1997(d["z"], t, bit_depth=d["bit_depth"], samples=samples).g


def _ours_debevec_exact(d, samples):
    from lumigraph.hdr.debevec1997 import response_debevec1997

    return response_debevec1997(d["z"], d["exact"], bit_depth=d["bit_depth"], samples=samples).g


def _ours_mn(d, order):
    from lumigraph.hdr.mitsunaga1999 import response_mitsunaga1999

    r = response_mitsunaga1999(d["z"], d["times"], bit_depth=d["bit_depth"], order=order)
    return r.g, np.array(r.exposure_times_s)


def _ours_mn_two_references(d, order):
    """Mitsunaga–Nayar with the rough times and the shortest and longest
    exposures known exactly (``--reference-time`` twice): the power fixed."""
    from lumigraph.hdr.mitsunaga1999 import response_mitsunaga1999

    lo, hi = int(np.argmin(d["exact"])), int(np.argmax(d["exact"]))
    r = response_mitsunaga1999(d["z"], d["times"], bit_depth=d["bit_depth"], order=order,
                               reference_times={lo: float(d["exact"][lo]),
                                                hi: float(d["exact"][hi])})
    return r.g, np.array(r.exposure_times_s)


def _ours_robertson(d, samples):
    from lumigraph.hdr.robertson2003 import response_robertson2003

    return response_robertson2003(d["z"], d["times"], bit_depth=d["bit_depth"], samples=samples).g


def _bgr(d):
    return [np.ascontiguousarray(im[..., ::-1]) for im in d["z"]]


def _cv_debevec(d, samples):
    import cv2

    cal = cv2.createCalibrateDebevec(samples=samples)
    crv = cal.process(_bgr(d), d["times"].astype(np.float32))
    return np.log(np.maximum(crv[:, 0, ::-1].T.astype(np.float64), 1e-12))


def _cv_robertson(d, _k):
    import cv2

    crv = cv2.createCalibrateRobertson().process(_bgr(d), d["times"].astype(np.float32))
    return np.log(np.maximum(crv[:, 0, ::-1].T.astype(np.float64), 1e-12))


def _colour_debevec(d, samples):
    import colour_hdri

    stack = colour_hdri.ImageStack()
    top = 2 ** d["bit_depth"] - 1
    for im, t in zip(d["z"], d["times"], strict=True):
        stack.append(colour_hdri.Image(data=im.astype(np.float64) / top,
                                       metadata=colour_hdri.Metadata(8.0, float(t), 100.0)))
    crf = colour_hdri.camera_response_functions_Debevec1997(
        stack, sampling_function_kwargs={"samples": samples}, n=top + 1)
    return np.log(np.maximum(np.asarray(crf, np.float64).T, 1e-12))


def _pfs_unavailable():
    return None if shutil.which("pfshdrcalibrate") and shutil.which("pfsinhdrgen") else \
        "pfstools not installed (Debian package pfstools)"


def _pfs(method):
    def run(d, _k):
        from lumigraph.capture.io import write_image

        with tempfile.TemporaryDirectory() as tmp:
            lines = []
            for j, (im, t) in enumerate(zip(d["z"], d["times"], strict=True)):
                p = os.path.join(tmp, f"e{j}.png")
                write_image(p, im)
                lines.append(f"{p} {1.0 / float(t)!r} 8 100 0")
            script = os.path.join(tmp, "s.hdrgen")
            with open(script, "w") as f:
                f.write("\n".join(lines) + "\n")
            resp = os.path.join(tmp, "r.m")
            with subprocess.Popen(["pfsinhdrgen", script], stdout=subprocess.PIPE) as gen:
                subprocess.run(["pfshdrcalibrate", "-c", method, "-s", resp, "-b",
                                str(d["bit_depth"])], stdin=gen.stdout, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, check=True)
            return _read_pfs_response(resp)

    return run


def _read_pfs_response(path) -> np.ndarray:
    chans, cur = [], None
    with open(path) as f:
        lines = f.readlines()
    for line in lines:
        if line.startswith("# name:"):
            cur = []
            chans.append(cur)
        elif not line.startswith("#") and len(line.split()) == 3 and cur is not None:
            cur.append(float(line.split()[2]))
    resp = np.array(chans[:3], np.float64)
    return np.log(np.maximum(resp, resp[resp > 0].min() if (resp > 0).any() else 1e-12))


# ------------------------------------------------------------------ merges
def _merge_prepare(d):
    import cv2

    from lumigraph.hdr.debevec1997 import response_debevec1997

    out = dict(d)
    out["curve"] = response_debevec1997(d["z"], d["times"], bit_depth=d["bit_depth"])
    out["cv_curve"] = cv2.createCalibrateDebevec().process(_bgr(d), d["times"].astype(np.float32))
    out["bgr"] = _bgr(d)
    return out


def _merge_ours(d, _k):
    from lumigraph.hdr.merge import merge

    return merge(d["z"], d["times"], d["curve"]).radiance


def _merge_cv(d, _k):
    import cv2

    return cv2.createMergeDebevec().process(d["bgr"], d["times"].astype(np.float32),
                                            d["cv_curve"])[..., ::-1]


def _big_prepare_ours(d):
    from lumigraph.capture.render import render
    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.response import ResponseCurve

    s = render("bracket", size=(400, 300), exposures=9, stops=1.0, seed=4)
    curve = ResponseCurve("gt", 8, s.gt_arrays["g"])
    # Peak memory is measured once, untimed: tracing every allocation slows numpy.
    # A first call on a crop loads the modules merge imports lazily (1.4 MB of
    # bytecode, counted by tracemalloc as if the merge had allocated it).
    merge(d["z"][:, :8, :8], d["times"], curve, workers=1)
    tracemalloc.start()
    try:
        m = merge(d["z"], d["times"], curve)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return {**d, "curve": curve, "peak": peak, "out_bytes": m.radiance.nbytes}


def _big_ours(d, _k):
    from lumigraph.hdr.merge import merge

    m = merge(d["z"], d["times"], d["curve"], workers=1)  # single thread, as OpenCV's
    return {"peak": d["peak"], "out_bytes": m.radiance.nbytes, "shape": m.radiance.shape}


def _big_prepare_cv(d):
    import cv2

    from lumigraph.capture.render import render

    cv2.setNumThreads(1)  # speed is compared single thread each
    s = render("bracket", size=(400, 300), exposures=9, stops=1.0, seed=4)
    crv = np.exp(s.gt_arrays["g"]).T[:, None, ::-1].astype(np.float32).copy()
    return {**d, "bgr": _bgr(d), "cv_curve": crv, "cv2": cv2}


def _big_cv(d, _k):
    m = d["cv2"].createMergeDebevec().process(d["bgr"], d["times"].astype(np.float32),
                                              d["cv_curve"])
    return {"peak": math.nan, "out_bytes": m.nbytes, "shape": m.shape}


# -------------------------------------------------------------------- video
VIDEO_NOISE = {"full_well_e": 20000.0, "read_noise_e": 4.0}  # the scene's sensor


def _video_case():
    from lumigraph.capture.render import render
    from lumigraph.hdr.kang2003 import Radiometry
    from lumigraph.hdr.response import ResponseCurve

    s = render("bracket_video", size=(160, 120), frames=6, seed=1)
    z = np.stack(s.images)
    t = np.array(s.stack["exposure_times_s"])
    truth = s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]
    curve = ResponseCurve("gt", 8, s.gt_arrays["g"])
    rad = Radiometry(curve, 3, clip_margin=0.02, **VIDEO_NOISE)
    rec = np.stack([recoverable(z, t, truth, rad, i) for i in range(len(t))])
    border = np.ones(z.shape, bool)
    border[:, :, :VIDEO_BORDER] = border[:, :, -VIDEO_BORDER:] = False
    return {"video": True, "z": z, "times": t, "truth": truth, "curve": curve,
            "recoverable": rec, "all": border}


VIDEO_BORDER = 6  # px at the left and right edges the pan brings in from outside the neighbours


def recoverable(z, t, truth, rad, i):
    """Pixel-channels clipped in frame ``i`` of the codes ``z`` (N, H, W, C)
    whose true radiance ``truth`` a neighbour's exposure records well (a
    factor 2 / 1.5 inside its reliable range of ``rad``, a
    :class:`hdr.kang2003.Radiometry`, so noise cannot clip it there), away from
    the ``VIDEO_BORDER`` columns: the pixels HDR video can and should fill.
    Shared by the bench's video case and the tests of hdr.kang2003."""
    lo, hi = rad.x[:, rad.lo], rad.x[:, rad.hi]
    clip = (z[i] < rad.lo) | (z[i] > rad.hi)
    rec = np.zeros_like(clip)
    for j in (i - 1, i + 1):
        if 0 <= j < len(t):
            e = truth[i] * t[j]
            rec |= (e > 2 * lo) & (e < hi / 1.5)
    m = clip & rec
    m[:, :VIDEO_BORDER] = m[:, -VIDEO_BORDER:] = False
    return m


def _video_ours(d, sigma):
    from lumigraph.hdr.kang2003 import hdr_video

    return hdr_video(d["z"], d["times"], d["curve"], consistency_sigma=sigma,
                     **VIDEO_NOISE).radiance


def _video_naive(d, _k):
    from lumigraph.hdr.kang2003 import unaligned_merge

    return np.stack([unaligned_merge(d["z"], d["times"], d["curve"], i, **VIDEO_NOISE)
                     for i in range(len(d["times"]))])


def _video_single(d, _k):
    from lumigraph.hdr.merge import merge

    return np.stack([merge(d["z"][i:i + 1], d["times"][i:i + 1], d["curve"]).radiance
                     for i in range(len(d["times"]))])


def _video_cv(d, _k):
    import cv2

    crv = np.exp(d["curve"].g).T[:, None, ::-1].astype(np.float32).copy()
    bgr = _bgr(d)
    n = len(d["times"])
    out = []
    for i in range(n):
        js = list(range(max(0, i - 1), min(n, i + 2)))
        m = cv2.createMergeDebevec().process([bgr[j] for j in js],
                                             d["times"][js].astype(np.float32), crv)
        out.append(m[..., ::-1])
    return np.stack(out)


def _video_error(d, out):
    def rms(m):
        e = np.log(np.maximum(np.asarray(out, np.float64)[m], 1e-12)) - np.log(d["truth"][m])
        return float(np.sqrt(np.mean(e ** 2)))

    return {"error": rms(d["recoverable"]), "all": rms(d["all"])}


# ------------------------------------------------------------ the family
# Rendered brackets we did not make the defaults on: capture.scenes.brackets'
# family (kinds x seeds x bit depths), each kind with its own response and
# noise. A case is one kind at one bit depth; its methods fit every seed once
# (in ``prepare``, untimed: the family measures accuracy, Memorial measures
# speed), and the error is the median over the seeds (``worst`` beside it).
FAMILY_SIZE = (160, 120)
FAMILY_SIZE_QUICK = (96, 72)
LOW_CODES = (10, 30)  # at 8 bits: where noise and clipping at 0 bias the mean code (issue 13)


# The "12- and 16-bit <= the 8-bit figure" check, as a paired ratio over enough
# scene seeds that its own noise cannot flip it. One scene's deep / 8-bit error
# ratio scatters by 0.06-0.10 (sd over scene seeds 0-15, docs/decisions/
# hdr-debevec-noise.md, seventh pass) while the pooled ratio is 0.81-0.91 on
# the tuned kinds, so a median of 3 seeds (s.e. ~0.05) flips from one code
# change to the next. n is chosen on the TUNED kinds only: their largest
# per-scene sd (studio 12-bit, 0.097) and a standard error of at most 0.02 on
# the mean ratio, i.e. the tuned kinds' worst pooled ratio (room 12-bit 0.904)
# sits >= 4.5 s.e. below 1.
PAIRED_SE_TARGET = 0.02
TUNED_RATIO_SD = 0.097


def seeds_for_se(sd: float, se: float) -> int:
    """Scene seeds ``n`` for which the mean of ``n`` paired ratios with
    per-scene standard deviation ``sd`` has standard error ``sd/√n <= se``.

    >>> seeds_for_se(TUNED_RATIO_SD, PAIRED_SE_TARGET)
    24
    """
    return int(math.ceil((sd / se) ** 2 - 1e-9))


PAIRED_SEEDS = tuple(range(seeds_for_se(TUNED_RATIO_SD, PAIRED_SE_TARGET)))
PAIRED_NOTE = (f"n = {len(PAIRED_SEEDS)} = (sd {TUNED_RATIO_SD} of the tuned kinds' per-scene "
               f"ratio / s.e. {PAIRED_SE_TARGET})^2; passes at the point estimate, mean <= 1")


@dataclass(frozen=True)
class PairedRatio:
    """Per-scene ratios ``deep_i / base_i`` over the scene seeds both were
    measured on: ``mean`` ± ``se`` (sample sd / √n), ``median``, ``worst`` (the
    largest) and its ``worst_seed``; ``figures`` = median deep / median base
    (the issue's "figure" is the median over seeds)."""

    n: int
    mean: float
    se: float
    median: float
    worst: float
    worst_seed: int
    figures: float


def paired_ratio(deep: dict, base: dict) -> PairedRatio:
    """The paired deep / base error ratio over the seeds (keys) present in both
    ``deep`` and ``base`` (``{seed: error}``); ``se`` is NaN for one seed.

    >>> r = paired_ratio({0: 0.8, 1: 0.9, 2: 1.0, 3: 1.1}, {0: 1.0, 1: 1.0, 2: 1.0, 3: 1.0, 4: 2})
    >>> r.n, round(r.mean, 6), round(r.se, 6), r.worst, r.worst_seed
    (4, 0.95, 0.06455, 1.1, 3)
    """
    seeds = sorted(set(deep) & set(base))
    if not seeds:
        raise ValueError("paired_ratio: no seed measured on both sides")
    r = np.array([deep[k] / base[k] for k in seeds], np.float64)
    w = int(np.argmax(r))
    se = float(np.std(r, ddof=1) / math.sqrt(len(r))) if len(r) > 1 else math.nan
    return PairedRatio(len(r), float(r.mean()), se, float(np.median(r)), float(r[w]), seeds[w],
                       float(np.median([deep[k] for k in seeds])
                             / np.median([base[k] for k in seeds])))


def ln_response_rms_up_to_power(g, g_true, bit_depth: int) -> float:
    """:func:`ln_response_rms` after the best common power: ``g`` against
    ``γ·g_true`` with one ``γ`` for all channels (least squares over the same
    codes, each channel's offset removed), in ``g_true``'s units.

    With rough times a response is fixed only up to that power (Mitsunaga &
    Nayar 1999, §4; the ratios take the same power): this is the part of the
    error the bracket's codes decide.

    Examples
    --------
    >>> g = np.log(np.arange(1, 257, dtype=float))[None].repeat(3, 0)
    >>> round(ln_response_rms_up_to_power(0.9 * g + 1.0, g, 8), 12)
    0.0
    """
    zmax = 2 ** bit_depth - 1
    m = slice(int(math.ceil(0.05 * zmax)), int(0.95 * zmax) + 1)
    a = np.asarray(g, np.float64)[:, m]
    b = np.asarray(g_true, np.float64)[:, m]
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    gam = float(np.sum(a * b) / np.sum(b * b))
    return float(np.sqrt(np.mean((a / gam - b) ** 2)))


def _power_bound_error(d) -> float:
    """The ln-response RMS of an estimator that knows the data-determined
    curve exactly and sets the free power from the stack's rough times (least
    squares in log, as :func:`hdr.bench_mn.oracle_ratio_error`): on average no
    estimator with these times does better."""
    x = np.log(np.sort(d["exact"]))
    y = np.log(np.sort(d["times"]))
    x, y = x - x.mean(), y - y.mean()
    gam = float(np.dot(x, y) / np.dot(x, x))
    return ln_response_rms(gam * np.asarray(d["g_true"], np.float64), d["g_true"], d["bit_depth"])


def ln_response_rms_range(g, g_true, bit_depth, lo: float, hi: float) -> float:
    """:func:`ln_response_rms` over the codes ``lo..hi`` given as fractions of
    the code range (``10/255`` … ``0.95``), each channel's offset removed."""
    zmax = 2 ** bit_depth - 1
    m = slice(int(math.ceil(lo * zmax)), int(hi * zmax) + 1)
    d = np.asarray(g, np.float64)[:, m] - np.asarray(g_true, np.float64)[:, m]
    d = d - d.mean(axis=1, keepdims=True)
    return float(np.sqrt(np.mean(d ** 2)))


def _family_name(kind, bit_depth):
    from lumigraph.capture.scenes.brackets import TUNED_KINDS

    return f"family {kind} {bit_depth}-bit ({'tuned' if kind in TUNED_KINDS else 'reported'})"


def _family_case(kind, bit_depth, seeds, size, paired_seeds=()):
    from lumigraph.capture.scenes.brackets import bracket_family

    def one(c):
        s = c.render(size)
        return {"z": np.stack(s.images), "times": np.array(s.stack["exposure_times_s"]),
                "g_true": s.gt_arrays["g"], "bit_depth": bit_depth, "seed": c.seed,
                "radiance": s.gt_arrays["radiance"].astype(np.float64) * s.gt["exposure_scale"]}

    def load():
        cs = bracket_family(kinds=(kind,), seeds=seeds, bit_depths=(bit_depth,))
        # the deep-vs-8-bit check's extra scene seeds: our Debevec only (_once's paired)
        extra = [s for s in paired_seeds if s not in seeds]
        more = bracket_family(kinds=(kind,), seeds=extra, bit_depths=(bit_depth,)) if extra else ()
        return {"family": True, "kind": kind, "split": cs[0].split,
                "seeds": [one(c) for c in cs], "paired": [one(c) for c in more]}

    paired = (f"; our Debevec also on scene seeds {paired_seeds[0]}-{paired_seeds[-1]} for the "
              f"paired {bit_depth}-bit / 8-bit ratio ({PAIRED_NOTE})" if paired_seeds else "")
    return Case(_family_name(kind, bit_depth), load,
                f"{kind}: {', '.join(f'{k}={v}' for k, v in _family_camera(kind).items())}; "
                f"seeds {list(seeds)}, {size[0]}x{size[1]}; error = median over seeds of the "
                f"ln-response RMS over codes {LOW_CODES[0]}/255..95 % (worst and codes "
                f"{LOW_CODES[0]}-{LOW_CODES[1]} in the JSON); time column: not a timing (each "
                f"fit runs once, untimed){paired}")


def _family_camera(kind):
    from lumigraph.capture.scenes.brackets import FAMILY

    return FAMILY[kind]


def _once(fit, paired=False):
    """A family method: ``fit(seed_data)`` for every seed, once, in ``prepare``
    (``paired``: also on the deep-vs-8-bit check's extra seeds, after them)."""
    def prepare(d):
        return {"out": [fit(s) for s in d["seeds"] + (d.get("paired", []) if paired else [])]}

    return prepare, (lambda state, _k: state["out"])


def _fam_debevec(s):
    from lumigraph.hdr.debevec1997 import response_debevec1997

    return response_debevec1997(s["z"], s["times"], bit_depth=s["bit_depth"]).g


def _fam_cv_debevec(s):
    return _cv_debevec(s, 70)


def _fam_mn(s):
    from lumigraph.hdr.mitsunaga1999 import response_mitsunaga1999

    r = response_mitsunaga1999(s["z"], s["times"], bit_depth=s["bit_depth"])
    return r.g, np.array(r.exposure_times_s)


def _fam_robertson(s):
    from lumigraph.hdr.robertson2003 import response_robertson2003

    return response_robertson2003(s["z"], s["times"], bit_depth=s["bit_depth"]).g


def _fam_cv_robertson(s):
    return _cv_robertson(s, None)


def _fam_merge_ours(s):
    from lumigraph.hdr.debevec1997 import response_debevec1997
    from lumigraph.hdr.merge import merge

    curve = response_debevec1997(s["z"], s["times"], bit_depth=s["bit_depth"])
    return merge(s["z"], s["times"], curve).radiance


def _fam_merge_cv(s):
    import cv2

    bgr = _bgr(s)
    crv = cv2.createCalibrateDebevec().process(bgr, s["times"].astype(np.float32))
    return cv2.createMergeDebevec().process(bgr, s["times"].astype(np.float32), crv)[..., ::-1]


def _family_error(d, outs):
    errs, extra = [], {}
    low, mono = [], []
    n = len(d["seeds"])
    data = d["seeds"] + d.get("paired", [])[:len(outs) - n]
    for s, out in zip(data, outs, strict=True):
        zmax = 2 ** s["bit_depth"] - 1
        if isinstance(out, tuple):  # Mitsunaga-Nayar: (g, refined times)
            g = out[0]
            z = s["z"]
            seen = [np.unique(z[..., c]) for c in range(g.shape[0])]
            mono.append(all(bool(np.all(np.diff(g[c][u[(u > 0) & (u < zmax)]]) > 0))
                            for c, u in enumerate(seen)))
            out = g
        if out.ndim == 3:  # a radiance map
            well = ((s["z"] > 0.05 * zmax) & (s["z"] < 0.95 * zmax)).any(axis=0)
            errs.append(radiance_rel_rms(out, s["radiance"], well))
            continue
        errs.append(ln_response_rms_range(out, s["g_true"], s["bit_depth"], LOW_CODES[0] / 255,
                                          0.95))
        low.append(ln_response_rms_range(out, s["g_true"], s["bit_depth"], LOW_CODES[0] / 255,
                                         LOW_CODES[1] / 255))
    # The row's figure is over the family's seeds, as every peer's; a method fitted
    # on the paired seeds too lists every scene seed's error for the paired check.
    extra = {"worst": float(np.max(errs[:n])), "per_seed": [float(e) for e in errs[:n]],
             "split": d["split"]}
    if len(errs) > n:
        extra["paired_seeds"] = [int(s["seed"]) for s in data]
        extra["paired_errors"] = [float(e) for e in errs]
    if low:
        extra["low_codes_median"] = float(np.median(low[:n]))
    if mono:
        extra["monotone_all_seeds"] = bool(all(mono))
    return {"error": float(np.median(errs[:n])), **extra}


# ------------------------------------------------------------- real sets
MEMORIAL = ("data", "hdr-real", "memorial")
IPHONE = ("data", "hdr-real", "iphone_xr_night")
CANON = ("data", "hdr-frobisher-canon5d2")
# The ColorChecker's neutral row in the Canon frames (640x426; x, y of each
# patch's centre, white to black; the patches are ~5 px, a 3x3 median each).
CANON_NEUTRALS = ((406, 232), (412, 232), (418, 232), (424, 232), (431, 232), (437, 232))


def _memorial():
    from fractions import Fraction

    from lumigraph.capture.bench import shared_data
    from lumigraph.capture.io import read_stack
    from lumigraph.hdr.formats import read_hdr_image

    root = shared_data(*MEMORIAL)
    times = [float(Fraction(t.strip())) for t in (root / "shutter_times.txt").read_text().split()]
    files = sorted(root.glob("memorial00*.png"))
    st = read_stack(files, times=times)
    z = st.images
    # Debevec's README: pure-blue pixels mark the registration borders.
    blue = ((z[..., 0] == 0) & (z[..., 1] == 0) & (z[..., 2] == 255)).any(axis=0)
    ref = read_hdr_image(root / "memorial.hdr").astype(np.float64)[..., :3]
    return {"real": "memorial", "z": z, "times": np.array(times), "bit_depth": 8,
            "ref": ref, "valid": ~blue & np.all(ref > 0, axis=-1)}


def _canon():
    from lumigraph.capture.bench import shared_data
    from lumigraph.capture.io import read_stack

    files = sorted(shared_data(*CANON).glob("IMG_26*.jpg"))
    st = read_stack(files, need_times=True)
    return {"real": "canon", "z": st.images, "times": np.array(st.exposure_times_s),
            "bit_depth": 8}


def _iphone(quick):
    import cv2

    from lumigraph.capture.bench import shared_data
    from lumigraph.capture.io import read_stack

    files = sorted(shared_data(*IPHONE).glob("IMG_*.jpeg"))
    st = read_stack(files, need_times=True)
    f = 8 if quick else 4  # 12 MP -> 0.19 / 0.75 MP: the bench compares, the memory case is hdrmn's
    z = np.stack([cv2.resize(im, None, fx=1 / f, fy=1 / f, interpolation=cv2.INTER_AREA)
                  for im in st.images])
    return {"real": "iphone", "z": z, "times": np.array(st.exposure_times_s), "bit_depth": 8}


def _real_ours(d, _k):
    from lumigraph.hdr.debevec1997 import response_debevec1997
    from lumigraph.hdr.merge import merge

    curve = response_debevec1997(d["z"], d["times"], bit_depth=8)
    return merge(d["z"], d["times"], curve).radiance


def _real_ours_robertson(d, _k):
    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.robertson2003 import response_robertson2003

    curve = response_robertson2003(d["z"], d["times"], bit_depth=8)
    return merge(d["z"], d["times"], curve).radiance


def _real_cv(d, _k):
    return _fam_merge_cv(d)


def _median_abs_dln(est, ref, valid):
    """Median |Δ ln| over ``valid`` after fitting one scale per channel (the
    median log ratio: robust to the few pixels either side clips)."""
    out = []
    for c in range(3):
        e, r = est[..., c][valid], ref[..., c][valid]
        ok = np.isfinite(e) & (e > 0) & (r > 0)
        dl = np.log(e[ok]) - np.log(r[ok])
        out.append(np.abs(dl - np.median(dl)))
    return float(np.median(np.concatenate(out)))


def _neutral_spread(rad):
    """RMS over the chart's neutral patches of the channels' disagreement in
    ln radiance after one scale per channel: 0 when every patch-to-patch
    ratio is the same in R, G and B, as a neutral grey's must be."""
    L = np.array([[np.median(rad[y - 1:y + 2, x - 1:x + 2, c]) for c in range(3)]
                  for x, y in CANON_NEUTRALS], np.float64)
    lnl = np.log(np.maximum(L, 1e-30))
    lnl = lnl - lnl.mean(axis=0, keepdims=True)   # the per-channel scale
    dev = lnl - lnl.mean(axis=1, keepdims=True)   # channels against their mean
    return float(np.sqrt(np.mean(dev ** 2)))


def _real_error(d, out):
    out = np.asarray(out, np.float64)
    if d["real"] == "memorial":
        return {"error": _median_abs_dln(out, d["ref"], d["valid"])}
    if d["real"] == "canon":
        return {"error": _neutral_spread(out)}
    # iPhone: no reference; the fraction of finite, positive radiance and the
    # black-everywhere share are reported, the error is the agreement with OpenCV.
    return {"error": math.nan if "cv" not in d else
            _median_abs_dln(out, d["cv"], np.ones(out.shape[:2], bool)),
            "finite": float(np.isfinite(out).all(axis=-1).mean())}


# ------------------------------------------------------------------- errors
def _error(d, out):
    if isinstance(d, dict) and d.get("family"):
        return _family_error(d, out)
    if isinstance(d, dict) and d.get("real"):
        return _real_error(d, out)
    if isinstance(d, dict) and d.get("video"):
        return _video_error(d, out)
    if isinstance(out, dict):  # the 12 MP timing case
        return {"error": out["peak"] / out["out_bytes"] if math.isfinite(out["peak"]) else math.nan,
                "peak_bytes": out["peak"], "out_bytes": out["out_bytes"]}
    if isinstance(out, tuple):  # Mitsunaga-Nayar: (g, refined times)
        g, times = out
        tr = np.exp(np.diff(np.log(np.sort(d["exact"]))))
        rr = np.exp(np.diff(np.log(np.sort(times))))
        return {"error": ln_response_rms(g, d["g_true"], d["bit_depth"]),
                "ratio_error_max": float(np.max(np.abs(rr / tr - 1))),
                "error_up_to_power": ln_response_rms_up_to_power(g, d["g_true"], d["bit_depth"]),
                "bound_error": _power_bound_error(d)}
    if out.ndim == 3:  # a radiance map
        well = ((d["z"] > 0.05 * 255) & (d["z"] < 0.95 * 255)).any(axis=0)
        return radiance_rel_rms(out, d["radiance"], well)
    return ln_response_rms(out, d["g_true"], d["bit_depth"])


def _row(res, case, method):
    try:
        r = res.get(case, method)
    except KeyError:
        return None
    return r if r.status == "ok" else None


def _seed_errors(row) -> dict:
    """``{scene seed: error}`` of a family row fitted on the paired seeds."""
    return dict(zip(row.extra["paired_seeds"], row.extra["paired_errors"], strict=True))


def _family_checks(res: Results) -> list[Check]:
    """The issue's targets on every kind of the family (median over seeds),
    each labelled with its split."""
    from lumigraph.capture.scenes.brackets import KINDS, TUNED_KINDS

    out = []
    for kind in KINDS:
        lab = "tuned" if kind in TUNED_KINDS else "reported"
        c8 = _family_name(kind, 8)
        o, cv = _row(res, c8, "debevec (ours)"), _row(res, c8, "CalibrateDebevec (OpenCV)")
        if o and cv:
            r = o.error / cv.error
            out.append(Check(f"[{lab}] {kind} 8-bit: Debevec ln-response RMS / OpenCV "
                             "CalibrateDebevec <= 0.5 (median over seeds)", r, 0.5, r <= 0.5,
                             f"ours {o.error:.4g} (worst {o.extra['worst']:.4g}, codes 10-30 "
                             f"{o.extra.get('low_codes_median', math.nan):.4g}); OpenCV "
                             f"{cv.error:.4g} (worst {cv.extra['worst']:.4g}, codes 10-30 "
                             f"{cv.extra.get('low_codes_median', math.nan):.4g})"))
        for bd in (12, 16):
            d = _row(res, _family_name(kind, bd), "debevec (ours)")
            if not (o and d):
                continue
            if "paired_errors" in d.extra and "paired_errors" in o.extra:
                p = paired_ratio(_seed_errors(d), _seed_errors(o))
                out.append(Check(
                    f"[{lab}] {kind} {bd}-bit: Debevec ln-response RMS <= ours at 8 bits "
                    f"(paired ratio, mean over {p.n} scene seeds <= 1)", p.mean, 1.0,
                    p.mean <= 1.0,
                    f"mean {p.mean:.3f} ± {p.se:.3f} s.e. (mean + 2 s.e. "
                    f"{p.mean + 2 * p.se:.3f}), median {p.median:.3f}, worst {p.worst:.3f} "
                    f"(seed {p.worst_seed}); median figures over the {p.n} seeds {bd}-bit / "
                    f"8-bit {p.figures:.3f}, over seeds 0-2 {d.error:.4g} / {o.error:.4g}; "
                    f"{PAIRED_NOTE}; OpenCV cannot run on > 8-bit input"))
            else:  # quick runs or a single seed: the median figures, as the issue words it
                out.append(Check(f"[{lab}] {kind} {bd}-bit: Debevec ln-response RMS <= ours at "
                                 "8 bits (median over seeds; no paired seeds)", d.error, o.error,
                                 d.error <= o.error,
                                 f"{bd}-bit {d.error:.4g} (worst {d.extra['worst']:.4g}), 8-bit "
                                 f"{o.error:.4g}; OpenCV cannot run on > 8-bit input"))
        ro, rc = _row(res, c8, "robertson (ours)"), _row(res, c8, "CalibrateRobertson (OpenCV)")
        if ro and rc:
            # The accuracy half of "Robertson <= 1.0x OpenCV's time at equal or better
            # error" (the time half is the Memorial speed check).
            r = ro.error / rc.error
            out.append(Check(f"[{lab}] {kind} 8-bit: Robertson ln-response RMS / OpenCV "
                             "CalibrateRobertson <= 1.0 (median over seeds)", r, 1.0, r <= 1.0,
                             f"ours {ro.error:.4g} (worst {ro.extra['worst']:.4g}), OpenCV "
                             f"{rc.error:.4g} (worst {rc.extra['worst']:.4g})"))
        mo = _row(res, c8, "merge (ours, own curve)")
        mc = _row(res, c8, "MergeDebevec (OpenCV, own curve)")
        if mo and mc:
            r = mo.error / mc.error
            out.append(Check(f"[{lab}] {kind} 8-bit: merged radiance rel. RMS / OpenCV "
                             "MergeDebevec <= 0.8 (median over seeds)", r, 0.8, r <= 0.8,
                             f"ours {mo.error:.4g} (worst {mo.extra['worst']:.4g}), OpenCV "
                             f"{mc.error:.4g} (worst {mc.extra['worst']:.4g})"))
        mn = _row(res, c8, "mitsunaga-nayar (ours)")
        if mn and o:
            # Mitsunaga-Nayar's own targets (order stability, ratios) are in its
            # rows of the other cases; here: monotone on every seed, error vs Debevec.
            r = mn.error / o.error
            out.append(Check(f"[{lab}] {kind} 8-bit: Mitsunaga-Nayar monotone on every seed "
                             "and error <= 1.5x our Debevec", r, 1.5,
                             bool(mn.extra.get("monotone_all_seeds")) and r <= 1.5,
                             f"MN {mn.error:.4g}, monotone on all seeds: "
                             f"{mn.extra.get('monotone_all_seeds')}; Debevec {o.error:.4g}"))
    return out


def _real_checks(res: Results) -> list[Check]:
    out = []
    for case, what in (("memorial", "Memorial vs Debevec's memorial.hdr: median |Δ ln| after "
                                    "one scale per channel"),
                       ("canon 5D Mk II", "Canon 5D Mk II ColorChecker neutral row: channels' "
                                          "disagreement of patch ratios, ln RMS")):
        o, c = _row(res, case, "merge (ours)"), _row(res, case, "MergeDebevec (OpenCV)")
        rb = _row(res, case, "merge (ours, Robertson curve)")
        if o and c:
            r = o.error / c.error
            out.append(Check(f"[reported] {what}, ours / OpenCV (informational)", r, 1.0,
                             r <= 1.0, f"ours {o.error:.4g} ({o.time_s:.3g} s), OpenCV "
                                       f"{c.error:.4g} ({c.time_s:.3g} s)"
                                       + (f"; ours with our Robertson curve {rb.error:.4g}"
                                          if rb else "")))
    o = _row(res, "iphone", "merge (ours)")
    if o:
        out.append(Check("[reported] iPhone XR night (downscaled): median |Δ ln| ours vs OpenCV's "
                         "merge (informational, no reference)", o.error, None,
                         bool(np.isfinite(o.error)),
                         f"finite radiance share {o.extra.get('finite', math.nan):.4g}"))
    return out


def _checks(res: Results, ctx) -> list[Check]:
    out = _family_checks(res) + _real_checks(res)

    def best(case, m):
        try:
            return res.best(case, m)
        except KeyError:
            return None

    ours, cv = best("8-bit", "debevec (ours)"), best("8-bit", "CalibrateDebevec (OpenCV)")
    cv_default = None
    try:
        cv_default = res.get("8-bit", "CalibrateDebevec (OpenCV)", 70)
    except KeyError:
        pass
    ours_default = None
    try:
        ours_default = res.get("8-bit", "debevec (ours)", 600)
    except KeyError:
        pass
    if ours_default and cv_default:
        r = ours_default.error / cv_default.error
        out.append(Check("8-bit ln-response RMS / OpenCV CalibrateDebevec (defaults) <= 0.5",
                         r, 0.5, r <= 0.5, f"ours {ours_default.error:.4g}, OpenCV "
                                           f"{cv_default.error:.4g}"))
    if ours and cv:
        r = ours.error / cv.error
        out.append(Check("8-bit ln-response RMS, best of each sweep / OpenCV <= 0.5", r, 0.5,
                         r <= 0.5, f"ours {ours.error:.4g}, OpenCV {cv.error:.4g}"))
    for bd in ("12-bit", "16-bit"):
        try:
            o = res.get(bd, "debevec (ours)", 600)
        except KeyError:
            o = None
        if o and o.status == "ok":
            # Correct: deeper data carry less quantisation noise, so no worse than our
            # 8-bit error plus the fit's sampling scatter (shot noise 1.6 % per
            # observation at mid exposure over ~90 observations per effective degree of
            # freedom: 0.0017 ln, x1.5 for two independent fits = 0.0025).
            ref = (ours_default.error if ours_default else math.nan) + 0.0025
            out.append(Check(f"{bd} ln-response RMS correct (<= ours at 8 bit + 0.0025)",
                             o.error, ref, o.error <= ref, "OpenCV cannot run on > 8-bit input"))
    try:
        ro, rc = res.get("8-bit", "robertson (ours)"), res.get("8-bit", "CalibrateRobertson (OpenCV)")
        if ro.status == "ok" and rc.status == "ok":
            r = ro.error / rc.error
            try:
                pf = res.get("8-bit", "Robertson (pfstools)")
                pf_txt = f", pfstools {pf.error:.4g}" if pf.status == "ok" else ""
            except KeyError:
                pf_txt = ""
            deep = []
            for bd in ("12-bit", "16-bit"):
                try:
                    deep.append(f"{bd} {res.get(bd, 'robertson (ours)').error:.4g}")
                except KeyError:
                    pass
            # Informational here: the target ("at equal or better error") is checked per
            # kind of the family (_family_checks), its time half on Memorial (_extra).
            out.append(Check("8-bit Robertson ln-response RMS, ours / OpenCV "
                             "CalibrateRobertson default (informational; targets per family "
                             "kind)", r, None,
                             bool(np.isfinite(r)),
                             f"ours {ro.error:.4g}, OpenCV {rc.error:.4g}{pf_txt}"
                             + (f"; ours {', '.join(deep)}" if deep else "")))
    except KeyError:
        pass
    try:
        mo, mc = res.get("merge", "merge (ours, own curve)"), \
            res.get("merge", "MergeDebevec (OpenCV, own curve)")
        out.append(Check("merged radiance rel. RMS <= OpenCV MergeDebevec with its curve",
                         mo.error / mc.error, 1.0, mo.error <= mc.error,
                         f"ours {mo.error:.4g}, OpenCV {mc.error:.4g}"))
    except KeyError:
        pass
    de = best("8-bit, times ±10 %", "debevec (ours, exact times)")
    pm = best("8-bit, times ±10 %", "Mitsunaga-Nayar (pfstools)")
    try:
        mn_auto = res.get("8-bit, times ±10 %", "mitsunaga-nayar (ours)", "auto")
    except KeyError:
        mn_auto = None
    if mn_auto is not None and mn_auto.status == "ok":
        rerr = mn_auto.extra.get("ratio_error_max", math.nan)
        out.append(Check("MN refined ratios within 1 % of the truth", rerr, 0.01, rerr <= 0.01,
                         "times given off by up to ±10 %"))
        if de:
            # With times off by ±10 % the data fix the curve only up to a common power
            # (issue 13 restates the ratio target for this reason): the raw error is the
            # power the rough times set, near the information bound whatever the method.
            # The 1.5x is checked where the data decide it: up to that power, and with two
            # exposures known exactly (which fix the power).
            up = mn_auto.extra.get("error_up_to_power", math.nan)
            bound = mn_auto.extra.get("bound_error", math.nan)
            r = up / de.error
            out.append(Check("MN response error up to the common power the rough times leave "
                             "free / Debevec with exact times <= 1.5", r, 1.5, r <= 1.5,
                             f"MN {up:.4g} (raw {mn_auto.error:.4g}, the information bound "
                             f"for this time draw {bound:.4g}), Debevec {de.error:.4g}"))
            try:
                m2 = res.get("8-bit, times ±10 %", "mitsunaga-nayar (ours, 2 reference times)",
                             "auto")
                r2 = m2.error / de.error
                out.append(Check("MN response error with the shortest and longest exposures "
                                 "known exactly / Debevec with exact times <= 1.5", r2, 1.5,
                                 r2 <= 1.5, f"MN {m2.error:.4g}, Debevec {de.error:.4g}"))
            except KeyError:
                pass
        if pm:
            out.append(Check("MN response error <= pfstools MN", mn_auto.error / pm.error, 1.0,
                             mn_auto.error <= pm.error, f"pfstools {pm.error:.4g}"))
    try:
        bo = res.get("merge 12 MP", "merge (ours)")
        bc = res.get("merge 12 MP", "MergeDebevec (OpenCV)")
        r = bo.time_s / bc.time_s
        out.append(Check("merge 9 exposures wall time / OpenCV MergeDebevec <= 1.0", r, 1.0,
                         r <= 1.0, f"ours {bo.time_s:.3g} s, OpenCV {bc.time_s:.3g} s"))
        peak = bo.extra.get("peak_bytes", math.nan) / bo.extra.get("out_bytes", math.nan)
        out.append(Check("merge peak memory beyond inputs / one float32 output <= 3", peak, 3.0,
                         peak <= 3.0, "tracemalloc peak during merge"))
    except KeyError:
        pass
    try:
        vo = res.get("video", "hdr video (ours)", 6.0)
        vn = res.get("video", "unaligned merge")
        r = vo.error / vn.error
        out.append(Check("HDR video log-radiance RMS on clipped, recoverable pixels / unaligned "
                         "merge (informational)", r, 1.0, r < 1.0,
                         f"ours {vo.error:.4g}, unaligned {vn.error:.4g}; all pixels: ours "
                         f"{vo.extra.get('all', math.nan):.4g}, unaligned "
                         f"{vn.extra.get('all', math.nan):.4g}"))
    except KeyError:
        pass
    return out


REAL_CASES = ("memorial", "canon 5D Mk II", "iphone")


def _family_and_real_cases(quick: bool) -> list[Case]:
    """The family (quick: seed 0, 8 bits, small; full: seeds 0-2, and our
    Debevec on :data:`PAIRED_SEEDS` too) and the real sets (quick: the Canon
    bracket only)."""
    from lumigraph.capture.bench import missing_shared
    from lumigraph.capture.scenes.brackets import FAMILY_BIT_DEPTHS, FAMILY_SEEDS, KINDS

    seeds = (0,) if quick else FAMILY_SEEDS
    depths = (8,) if quick else FAMILY_BIT_DEPTHS
    size = FAMILY_SIZE_QUICK if quick else FAMILY_SIZE
    # full runs: our Debevec also on PAIRED_SEEDS for the deep-vs-8-bit check (quick has
    # no deep case, so no paired seeds)
    paired = () if quick else PAIRED_SEEDS
    out = [_family_case(k, b, seeds, size, paired) for b in depths for k in KINDS]
    out.append(Case("canon 5D Mk II", _canon, "3 JPEGs 3 stops apart, EXIF times; error = the "
                    "channels' disagreement (ln RMS) of the ColorChecker neutral patches' "
                    "ratios after one scale per channel", unavailable=missing_shared(*CANON)))
    if not quick:
        out.append(Case("memorial", _memorial, "16 scans 1 stop apart (shutter_times.txt); "
                        "error = median |Δ ln| against Debevec's memorial.hdr after one scale "
                        "per channel, pure-blue border pixels excluded",
                        unavailable=missing_shared(*MEMORIAL)))
        out.append(Case("iphone", lambda: _iphone_with_cv(quick), "5 JPEGs (EXIF times), "
                        "downscaled 4x; no reference: error = median |Δ ln| against OpenCV's "
                        "merge (OpenCV's own row is 0 by construction)",
                        unavailable=missing_shared(*IPHONE)))
    return out


def _iphone_with_cv(quick):
    d = _iphone(quick)
    d["cv"] = np.asarray(_fam_merge_cv(d), np.float64)
    return d


def stage(*, quick: bool = False) -> Stage:
    samples = (600,) if quick else (300, 600, 1500)
    cv_samples = (70,) if quick else (70, 200)
    orders = ("auto",) if quick else ("auto", 3)
    size = (160, 120) if quick else SIZE
    cases = [Case("8-bit", lambda: _bracket(8, size), "film response, 7 exposures 1.5 stops apart")]
    if not quick:
        cases += [Case("12-bit", lambda: _bracket(12)), Case("16-bit", lambda: _bracket(16))]
    cases += [Case("8-bit, times ±10 %",
                   lambda: _bracket(8, size, time_error=0.10, stack_times="nominal"),
                   "stack times are nominal, off by up to ±10 %"),
              Case("merge", lambda: _bracket(8, size), "each method with its own curve"),
              Case("merge 12 MP", lambda: _big(quick),
                   "9 exposures tiled to 12 MP (quick: 0.12 MP); error column = tracemalloc "
                   "peak / output bytes"),
              Case("video", _video_case, "bracket_video 160x120, 6 frames, 3 stops, 1.5 px/frame "
                                         "pan; log RMS on clipped pixels a neighbour records")]
    cases += _family_and_real_cases(quick)
    fam8 = tuple(c.name for c in cases if c.name.startswith("family") and " 8-bit" in c.name)
    fam_all = tuple(c.name for c in cases if c.name.startswith("family"))
    reals = tuple(c.name for c in cases if c.name in REAL_CASES)
    resp_cases = ("8-bit", "12-bit", "16-bit")
    methods = (
        Method("debevec (ours)", _ours_debevec, "samples", samples, cases=resp_cases),
        Method("mitsunaga-nayar (ours)", _ours_mn, "order", orders,
               cases=("8-bit, times ±10 %",) if quick else ("8-bit", "8-bit, times ±10 %")),
        Method("mitsunaga-nayar (ours, 2 reference times)", _ours_mn_two_references, "order",
               ("auto",), cases=("8-bit, times ±10 %",)),
        Method("debevec (ours, exact times)", _ours_debevec_exact, "samples", (600,),
               cases=("8-bit, times ±10 %",)),
        Method("CalibrateDebevec (OpenCV)", _cv_debevec, "samples", cv_samples, peer="opencv",
               cases=("8-bit",)),
        Method("CalibrateRobertson (OpenCV)", _cv_robertson, peer="opencv",
               cases=() if quick else ("8-bit",)),
        Method("Debevec1997 (colour-hdri)", _colour_debevec, "samples",
               (100,), peer="colour-hdri", cases=("8-bit",),
               unavailable=(lambda: "skipped in quick mode (about 13 s a run)") if quick else None),
        Method("robertson (ours)", _ours_robertson, "samples", (5000,),
               cases=() if quick else resp_cases),
        Method("Robertson (pfstools)", _pfs("robertson"), peer="pfstools",
               unavailable=_pfs_unavailable, cases=() if quick else ("8-bit",)),
        Method("Mitsunaga-Nayar (pfstools)", _pfs("mitsunaga"), peer="pfstools",
               unavailable=_pfs_unavailable,
               cases=("8-bit, times ±10 %",) if quick else ("8-bit", "8-bit, times ±10 %")),
        Method("merge (ours, own curve)", _merge_ours, prepare=_merge_prepare, cases=("merge",)),
        Method("MergeDebevec (OpenCV, own curve)", _merge_cv, peer="opencv",
               prepare=_merge_prepare, cases=("merge",)),
        Method("merge (ours)", _big_ours, prepare=_big_prepare_ours, cases=("merge 12 MP",)),
        Method("MergeDebevec (OpenCV)", _big_cv, peer="opencv", prepare=_big_prepare_cv,
               cases=("merge 12 MP",)),
        Method("hdr video (ours)", _video_ours, "consistency_sigma",
               (6.0,) if quick else (2.0, 4.0, 6.0, 8.0), cases=("video",)),
        Method("unaligned merge", _video_naive, cases=("video",)),
        Method("single frame", _video_single, cases=("video",)),
        Method("MergeDebevec (OpenCV, unaligned)", _video_cv, peer="opencv", cases=("video",)),
        # the family: each fit once per seed (prepare), error = median over seeds
        Method("debevec (ours)", _once(_fam_debevec, True)[1],
               prepare=_once(_fam_debevec, True)[0],
               cases=fam_all),
        Method("CalibrateDebevec (OpenCV)", _once(_fam_cv_debevec)[1],
               prepare=_once(_fam_cv_debevec)[0], peer="opencv", cases=fam8),
        Method("mitsunaga-nayar (ours)", _once(_fam_mn)[1], prepare=_once(_fam_mn)[0],
               cases=() if quick else fam8),
        Method("robertson (ours)", _once(_fam_robertson)[1], prepare=_once(_fam_robertson)[0],
               cases=() if quick else fam8),
        Method("CalibrateRobertson (OpenCV)", _once(_fam_cv_robertson)[1],
               prepare=_once(_fam_cv_robertson)[0], peer="opencv", cases=() if quick else fam8),
        Method("merge (ours, own curve)", _once(_fam_merge_ours)[1],
               prepare=_once(_fam_merge_ours)[0], cases=fam8),
        Method("MergeDebevec (OpenCV, own curve)", _once(_fam_merge_cv)[1],
               prepare=_once(_fam_merge_cv)[0], peer="opencv", cases=fam8),
        # real sets: timed (curve + merge), error against the set's own reference
        Method("merge (ours)", _real_ours, cases=reals),
        Method("merge (ours, Robertson curve)", _real_ours_robertson,
               cases=tuple(c for c in reals if c != "iphone")),
        Method("MergeDebevec (OpenCV)", _real_cv, peer="opencv", cases=reals),
    )
    return Stage("hdr", tuple(cases), methods, _error, "ln-response RMS / radiance rel. RMS",
                 checks=_checks, description=__doc__.split("\n\n")[0], repeats=3,
                 extra=lambda: _extra(quick))


def _extra(quick: bool):
    """Mitsunaga-Nayar's seed sweeps and ratio bound (``bench_mn``) and, in full
    runs, the response fits' wall time on Memorial against OpenCV's, interleaved
    (``bench_response.memorial_speed``)."""
    import math

    from lumigraph.capture.bench import Row, missing_shared, shared_data
    from lumigraph.hdr.bench_mn import mn_rows
    from lumigraph.hdr.bench_response import memorial_speed

    rows, checks = mn_rows(quick=quick)
    if quick or missing_shared(*MEMORIAL)():
        return rows, checks
    r = memorial_speed(shared_data(*MEMORIAL), repeats=5)
    case = "memorial speed (16 x 512x768)"
    for method, peer, key in (("debevec (ours, automatic lambda)", None, "ours_debevec"),
                              ("CalibrateDebevec (OpenCV, 70 samples)", "opencv", "cv_debevec"),
                              ("CalibrateDebevec (OpenCV, 600 samples)", "opencv",
                               "cv_debevec_600"),
                              ("robertson (ours)", None, "ours_robertson"),
                              ("CalibrateRobertson (OpenCV)", "opencv", "cv_robertson")):
        rows.append(Row("hdr", case, method, peer, "", None, r[key], (r[key],), math.nan, "ok"))
    for what, ours, cv in (("Debevec with automatic lambda", "ours_debevec", "cv_debevec"),
                           ("Robertson", "ours_robertson", "cv_robertson")):
        ratio = r[ours] / r[cv]
        checks.append(Check(f"Memorial: {what} wall time <= 1.0x OpenCV's (single thread, "
                            "interleaved, min of 5)", ratio, 1.0, ratio <= 1.0,
                            f"ours {r[ours]:.3f} s, OpenCV {r[cv]:.3f} s"))
    return rows, checks
