"""Bench stage ``lightfield``: refocusing, lenslet decoding, light-slab rendering, depth.

Cases (capture/ scenes with exact ground truth, plus HCI "antinous" with GT
disparity):

- ``array``: a camera-array light field (9x9 views of 512x512x3; quick: 5x5 of
  128x128) with the exact synthetic-aperture refocus images as truth.
  Ours: shift-and-add (knob: interpolation kernel; ``linear`` is the bilinear
  baseline), Fourier slice (slices after the one-time 4-D FFT), the 4-D FFT
  alone. Peers: shift-and-add with ``scipy.ndimage.shift`` (spline order 1
  and 3). Error: RMS against the truth (PSNR, peak 1, in the extras); times
  are per refocus.
- ``lenslet square`` / ``lenslet hex``: plenoptic raws; ours: grid estimation
  + decoding (no peer is installed: PlenoptiCam and the MATLAB LF Toolbox are
  not available here); error: RMS of the views, extras: PSNR, centre errors.
- ``novel view``: light-slab rendering at the centre of four cameras against a
  ground-truth render (knob: the slab's focal-plane slope).
- ``HCI antinous``: disparity of the centre view (whole 512x512) against
  the HCI ground truth, with the HCI metrics (BadPix 0.07 / 0.03 / 0.01, MSE
  x 100, 15 px boundary left out); held out (nothing was tuned on it). One
  row runs ours and the baseline alternately on it (times: min over the
  repeats; the speed target is scaled by the baseline's time measured there).
- ``depth A/B/C/K/S seed N``: rendered 5x5 light fields with exact
  disparity; five scene kinds (A/B/C: textured planes; K: bright planes
  before a dark, low-contrast one, :func:`dark_background_scene`; S: a shaded
  ellipse before a dark wall and a steeply slanted floor, supersampled,
  :func:`slanted_floor_scene`); seeds 0, 3, 4, 5 (K: 0, 3-6; S: 0, 3) were
  the tuning set (seed 0 shown), seeds 1-2 are reported.
  ``depth F seed N``: kind S dimmer, partly texture-less, noisy and 8-bit
  (:func:`dim_floor_scene`: isolated gross floor errors); seeds 0, 3 tuned,
  1-2 reported, outside the issue's 0.5x check (harder than antinous's floor).
  ``depth Aq/Bq/Cq/Kq seed N``: the same views quantised to 8-bit gamma
  codes (as PNG light fields such as HCI antinous are); seed 0 and, for the
  dead zone of :mod:`lightfield.wang2015`, seed 3 were tuned on, seeds 1-2
  are reported (their own check; the issue's 0.5x target is on the float rows).
  Depth rows: ours ``wang2015`` (the default) against the earlier
  ``variance`` method (the baseline), same inputs, same process.
- ``refocus parity``: Fourier slice and shift-and-add against the exact
  synthetic aperture on several rendered scenes x slopes (PSNR of each in the
  extras; the check: the worst difference).
- ``refocus sweep``: 50 slopes, single-threaded, both methods: total time and
  peak traced memory above the call's start (9x9x256x256x3; quick 5x5x96x96x3).
- ``refocus sweep 9x9x512x512x3 (child)``: the issue's size, in a child
  process per repeat (:func:`sweep_child`): both methods' total times and
  each one's resident high-water mark above its start (full bench only).
"""

from __future__ import annotations

import math

import numpy as np

from lumigraph.capture.bench import Case, Check, Method, Results, Stage, missing_shared, shared_data

BIG = {"size": (512, 512), "grid": "9x9"}
SMALL = {"size": (128, 128), "grid": "5x5"}
SLOPES = (0.35, 0.7)
ALTERNATIONS = 6   # side-by-side timings per method (median taken)
#: the issue's depth-speed target on HCI antinous and the baseline's time it
#: measured on its (quiet) machine: on a loaded machine the target is scaled by
#: the baseline's time measured alongside ours
DEPTH_TARGET_S, DEPTH_BASELINE_ISSUE_S = 10.0, 9.2


def _psnr(mse: float) -> float:
    return float(10 * math.log10(1.0 / mse)) if mse > 0 else float("inf")


def _array_case(quick: bool):
    def load():
        from lumigraph.capture.render import render
        from lumigraph.lightfield.field import LightField

        cfg = SMALL if quick else BIG
        s = render("lightfield-array", size=cfg["size"], grid=cfg["grid"], thin_lens=False,
                   focus=SLOPES)
        lf = LightField(s.gt_arrays["views"], spacing=s.gt["spacing"], focal_px=s.gt["focal_px"])
        return {"kind": "refocus", "lf": lf, "slopes": list(SLOPES),
                "truth": s.gt_arrays["synthetic_aperture"]}

    cfg = SMALL if quick else BIG
    return Case("array", load, f"{cfg['grid']} views of {cfg['size'][0]}x{cfg['size'][1]}x3, "
                               f"3 textured planes (disparity 1.0..0.2 px/view), refocus at "
                               f"slopes {SLOPES}; truth: exact synthetic-aperture images")


def _lenslet_case(lattice: str, quick: bool):
    def load():
        from lumigraph.capture.render import render

        name = "lightfield-lenslet" + ("-hex" if lattice == "hex" else "")
        n = 20 if quick else 40
        s = render(name, size=(n, n))
        truth = s.gt_arrays.get("views_rect", s.gt_arrays["views"])
        return {"kind": "lenslet", "raw": s.images[0], "white": s.images[1],
                "views": s.gt["views"][0], "truth": truth, "centers": s.gt_arrays["centers"]}

    return Case(f"lenslet {lattice}", load, f"{lattice} microlens grid, pitch 22.4 px, rotated "
                                            "1.5 deg, 5x5 views, 12-bit noise-free raw")


def _novel_case(quick: bool):
    def load():
        from lumigraph.capture.render import render
        from lumigraph.lightfield.field import LightField

        size = (96, 96) if quick else (256, 256)
        s = render("lightfield-array", size=size, grid="5x5", thin_lens=False,
                   disparity_near=0.6, disparity_far=0.1, focus=(0.35,))
        lf = LightField(s.gt_arrays["views"], spacing=s.gt["spacing"], focal_px=s.gt["focal_px"])
        return {"kind": "novel", "lf": lf, "position": s.gt["novel_position"],
                "truth": s.gt_arrays["novel_view"]}

    return Case("novel view", load, "5x5 array, planes at disparity 0.6..0.1; pinhole at the "
                                    "centre of four cameras (0.5, 0.5, 0) view steps")


def _hci_case():
    def load():
        from lumigraph.capture.io import read_image, read_pfm
        from lumigraph.lightfield.field import from_images

        root = shared_data(*_HCI)
        names = [root / f"input_Cam{9 * r + c:03d}.png" for r in range(2, 7) for c in range(2, 7)]
        lf = from_images([read_image(n) for n in names], grid=(5, 5), spacing=1.0)
        gt = read_pfm(root / "gt_disp_lowres.pfm")
        return {"kind": "depth", "lf": lf, "truth": gt, "slopes": np.linspace(-3.3, 2.9, 63)}

    return Case("HCI antinous", load, "real-data check (held out): HCI antinous 5x5, 512x512, "
                                      "GT disparity", unavailable=missing_shared(*_HCI))


DEPTH_SCENES = {"A": {"planes": 3, "disparity_near": 1.0, "disparity_far": 0.2},
                "B": {"planes": 4, "disparity_near": 2.0, "disparity_far": 0.3, "texel_px": 3.0},
                "C": {"planes": 2, "disparity_near": 1.5, "disparity_far": 0.1, "texel_px": 1.0},
                "K": {"dark_background": True},
                "S": {"slanted_floor": True},
                "F": {"dim_floor": True}}      # 8-bit already: no "Fq" rows
#: the kinds the issue's 0.5x target covers; F (round 6) is harder than
#: antinous's floor (noise and texture-less patches) and is reported on its own
ISSUE_KINDS = ("A", "B", "C", "K", "S")


def dark_background_scene(seed: int, size=(160, 120)):
    """``(LightField, disparity)``: a 5x5 array of bright textured planes at
    1.6 and 0.9 px/view in front of a dark, low-contrast plane at 0.2
    (linear radiance 0.012 .. 0.032, texel 2 px): the failure kind of HCI
    antinous (its background next to a silhouette matches at every
    disparity). Built from ``capture/scenes/lightfield.build_scene``, the
    far plane's texture mapped affinely (its B-spline coefficients map with
    it); noise-free float views, exact disparity of the centre view."""
    import dataclasses

    from lumigraph.capture.scenes.lightfield import build_scene, render_views
    from lumigraph.lightfield.field import LightField

    rng = np.random.default_rng(seed)
    w, h = size
    sc = build_scene(rng, width=w, height=h, f=float(w), spacing=1.0,
                     disparities=np.array([1.6, 0.9, 0.2]), texel_px=2.0, reach=4.0)
    far = sc.planes[-1]
    dark = dataclasses.replace(far, coef=0.012 + 0.02 * (far.coef - 0.08) / 0.9)
    sc = dataclasses.replace(sc, planes=(*sc.planes[:-1], dark))
    xs, ys = np.arange(w, dtype=float), np.arange(h, dtype=float)
    views = render_views(sc, 5, 5, 1.0, xs, ys).astype(np.float32)
    return LightField(views, spacing=1.0), (w / sc.depth_at(xs, ys)).astype(np.float32)


def slanted_floor_scene(seed: int, size=(160, 120), supersample: int = 3):
    """``(LightField, disparity)``: a 5x5 array looking at a shaded, textured
    ellipse (a curved silhouette, disparity 1.6 px/view, dimmed towards its
    rim) in front of a dark, low-contrast wall (0.3) that creases into a
    floor slanting towards the camera (0.3 at the crease, 1.0 at the bottom
    row; disparity linear in the image row, as for any plane): HCI
    antinous's silhouette and floor strip. Each pixel is the mean of
    ``supersample`` x ``supersample`` point samples (so silhouette pixels are
    blends, as in a rendered image); textures are smooth random fields
    (feature size ~2 px), sampled bilinearly on a 4x finer grid. Returns
    noise-free float views and the exact disparity at the centre view's
    pixel centres."""
    from lumigraph.lightfield.field import LightField

    views, gt = _floor_views(np.random.default_rng(seed), size, supersample,
                             crease=(0.55, 0.7), cy=(0.35, 0.5), ay=(0.3, 0.4),
                             back=(0.012, 0.04), flat=0.0, falloff=False)
    return LightField(views, spacing=1.0), gt


def dim_floor_scene(seed: int, size=(160, 120), supersample: int = 3, noise: float = 0.0012):
    """``(LightField, disparity)``: kind S (:func:`slanted_floor_scene`) made
    harder where HCI antinous's floor is: the wall and floor dimmer and
    weaker in texture (linear 0.012 .. 0.045) with a quarter of their area
    texture-less (smooth patches at the texture's mean), lit with a fall-off
    towards the crease (x 0.6 .. 1.4, fixed to the surface), sensor noise
    (Gaussian, ``noise`` at linear 0.05, growing with the square root of the
    signal, independent per view) and 8-bit gamma codes. Its flat cost
    curves leave isolated gross errors on the floor (the round-6 tuning
    kind of docs/decisions/lightfield-depth.md). Random draws from seed
    ``1000 + seed``; the disparity is exact at the centre view's pixels."""
    from lumigraph.lightfield.field import LightField

    rng = np.random.default_rng(1000 + seed)
    views, gt = _floor_views(rng, size, supersample, crease=(0.5, 0.6), cy=(0.3, 0.45),
                             ay=(0.25, 0.35), back=(0.012, 0.045), flat=0.25, falloff=True)
    views = views + rng.normal(0, noise, views.shape).astype(np.float32) * np.sqrt(
        np.maximum(views, 1e-4) / 0.05).clip(0.3, 3)
    return quantise_8bit(LightField(np.clip(views, 0, 1), spacing=1.0)), gt


def _floor_views(rng, size, supersample, *, crease, cy, ay, back, flat, falloff):
    """The 5x5 views and exact centre-view disparity shared by kinds S and F:
    an ellipse (disparity 2.3) before a wall (-0.3) creasing into a floor
    slanting to 2.0 at the bottom row. ``crease``, ``cy``, ``ay``: ranges of
    the crease row, the ellipse's centre row and half-height (fractions of
    the height); ``back``: the wall's texture range, ``flat`` its share of
    texture-less area; ``falloff``: light falling towards the crease.
    Every random draw comes from ``rng``, in a fixed order."""
    from scipy.ndimage import gaussian_filter, map_coordinates

    w, h = size
    d_wall, d_bottom, d_fg = -0.3, 2.0, 2.3
    crease_y = h * rng.uniform(*crease)
    slope = (d_bottom - d_wall) / (h - 1 - crease_y)
    cx, cy_ = w * rng.uniform(0.4, 0.6), h * rng.uniform(*cy)
    ax, ay_ = w * rng.uniform(0.18, 0.26), h * rng.uniform(*ay)
    tilt = rng.uniform(-0.5, 0.5)
    fine, pad = 4, 12      # texture grid: 4 samples per px, 12 px beyond the image

    def texture(lo, hi, flat=0.0):
        t = gaussian_filter(rng.standard_normal(((h + 2 * pad) * fine, (w + 2 * pad) * fine, 3)),
                            (2 * fine, 2 * fine, 0))
        t = (t - t.min()) / (t.max() - t.min())
        if flat > 0:
            m = gaussian_filter(rng.standard_normal(t.shape[:2]), 6 * fine)
            m = gaussian_filter((m > np.quantile(m, 1 - flat)).astype(float), fine)[..., None]
            t = t * (1 - m) + t.mean((0, 1)) * m
        return (lo + (hi - lo) * t).astype(np.float32)

    back_tex, front = texture(*back, flat=flat), texture(0.15, 0.8)

    def sample(tex, x, y):
        c = [(y + pad) * fine, (x + pad) * fine]
        return np.stack([map_coordinates(tex[..., k], c, order=1, mode="nearest")
                         for k in range(3)], -1)

    def inside(x, y):
        xr, yr = x - cx, y - cy_
        xt = xr * np.cos(tilt) + yr * np.sin(tilt)
        yt = -xr * np.sin(tilt) + yr * np.cos(tilt)
        return (xt / ax) ** 2 + (yt / ay_) ** 2

    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    shape = (h, w, supersample, supersample)   # (row, column, sub-row, sub-column)
    ys = np.broadcast_to((np.arange(h)[:, None] + sub)[:, None, :, None], shape)
    xs = np.broadcast_to((np.arange(w)[:, None] + sub)[None, :, None, :], shape)
    views = np.empty((5, 5, h, w, 3), np.float32)
    for i in range(5):
        for j in range(5):
            du, dv = i - 2, j - 2
            # background: the centre-view point (x0, y0) seen at (x, y) solves
            # y0 - d(y0) du = y with d(y0) = d_wall + slope (y0 - crease) below the crease
            y0 = (ys + (d_wall - slope * crease_y) * du) / (1 - slope * du)
            y0 = np.where(y0 >= crease_y, y0, ys + d_wall * du)
            d0 = d_wall + slope * np.maximum(y0 - crease_y, 0)
            img = sample(back_tex, xs + d0 * dv, y0)
            if falloff:
                img = img * (0.6 + 0.8 * np.clip((y0 - crease_y) / (h - crease_y), 0, 1))[..., None]
            xf, yf = xs + d_fg * dv, ys + d_fg * du
            r2 = inside(xf, yf)
            shade = np.clip(1.1 - 0.9 * r2, 0.05, 1)[..., None]
            img = np.where((r2 <= 1)[..., None], shade * sample(front, xf, yf), img)
            views[i, j] = img.mean((2, 3))
    yc, xc = np.mgrid[0:h, 0:w].astype(np.float64)
    gt = np.where(inside(xc, yc) <= 1, d_fg, d_wall + slope * np.maximum(yc - crease_y, 0))
    return views, gt.astype(np.float32)


def quantise_8bit(lf):
    """The light field's views as 8-bit gamma-2.2 codes, decoded back to
    linear radiance (what a PNG light field holds)."""
    from lumigraph.lightfield.field import LightField

    codes = np.round(np.clip(lf.data, 0, 1) ** (1 / 2.2) * 255)
    return LightField(((codes / 255) ** 2.2).astype(np.float32), spacing=lf.spacing)


def _depth_case(kind: str, seed: int, quick: bool):
    size = (96, 72) if quick else (160, 120)
    base, quantised = kind[0], kind.endswith("q")

    def load():
        from lumigraph.capture.render import render
        from lumigraph.lightfield.field import LightField

        if base == "K":
            lf, gt = dark_background_scene(seed, size)
        elif base == "S":
            lf, gt = slanted_floor_scene(seed, size)
        elif base == "F":
            lf, gt = dim_floor_scene(seed, size)
        else:
            s = render("lightfield-array", size=size, grid="5x5", seed=seed, thin_lens=False,
                       **DEPTH_SCENES[base])
            lf, gt = LightField(s.gt_arrays["views"], spacing=1.0), s.gt_arrays["disparity"]
        if quantised:
            lf = quantise_8bit(lf)
        return {"kind": "depth", "lf": lf, "truth": gt, "slopes": np.linspace(-0.5, 2.5, 31)}

    return Case(f"depth {kind} seed {seed}", load,
                f"5x5 views of {size[0]}x{size[1]}, "
                + ("bright planes 1.6, 0.9 before a dark one at 0.2 px/view" if base == "K"
                   else "a shaded ellipse at 1.6 px/view before a dark wall and slanted floor "
                        "(0.3..1.0), 3x3 supersampled" if base == "S"
                   else "kind S dimmer, texture-less patches, light fall-off, sensor noise, "
                        "8-bit" if base == "F"
                   else f"planes {DEPTH_SCENES[base]}")
                + (", 8-bit gamma codes" if quantised else "")
                + (" (tuning set)" if seed == 0 else ""))


_HCI = ("data", "lightfield-real", "hci_antinous_5x5")
HCI_BOUNDARY = 15   # px left out at the border, as the HCI benchmark's evaluation does


# ------------------------------------------- Fourier refocus parity and sweep
# Issue 16: Fourier slice within 0.2 dB of shift-and-add on every rendered
# scene and slope; 50-slope sweep time and peak memory. The scenes are the
# reporting set of docs/decisions/fourier-refocus.md (the filter was chosen
# on other seeds and sizes).
PARITY_SCENES = (
    dict(grid="9x9", size=(192, 144), seed=11),
    dict(grid="7x7", size=(160, 120), seed=12, texel_px=3.0),
    dict(grid="5x5", size=(128, 128), seed=13, planes=4, disparity_near=1.5,
         disparity_far=0.1, focus=(-0.6, 0.15, 0.45, 1.3, 2.5)),
    dict(grid="6x6", size=(128, 96), seed=15, focus=(-0.35, 0.3, 0.75, 1.1)),
    dict(grid="9x9", size=(144, 112), seed=14, texel_px=0.6),
)
SWEEP = {"full": ("9x9", 256), "quick": ("5x5", 96)}
SWEEP_SLOPES = 50
#: the issue's own sweep size (U = V, pixels), measured in a child process so
#: its peak resident memory is the sweep's own (full bench only: a minute or two)
SWEEP_ISSUE = (9, 512)

# The child: random views (time and memory do not depend on the content; the
# accuracy is the parity and sweep cases'), then each method once, in the
# given order (after a warm-up on a crop), each with its own peak: the kernel's high-water mark (VmHWM)
# is reset to the current size before each call (/proc/self/clear_refs "5",
# Linux >= 4.0), so the peak above the call's start is its own, output
# stack included. One JSON line on stdout.
_SWEEP_CHILD = """
import json, sys, time
import numpy as np
from lumigraph.lightfield.bench import _sweep_stack
from lumigraph.lightfield.field import LightField

g, n, k = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
order = sys.argv[4].split(",")

def status(key):
    return [int(ln.split()[1]) * 1024 for ln in open("/proc/self/status") if ln.startswith(key)][0]

rng = np.random.default_rng(0)
lf = LightField(rng.random((g, g, n, n, 3), dtype=np.float32))
data = {"lf": lf, "slopes": np.linspace(-1.0, 1.0, k)}
out = {"lf_bytes": lf.data.nbytes}
small = {"lf": LightField(lf.data[:, :, :16, :16]), "slopes": [-1.0, 0.5]}
for name in order:   # imports and first-call set-up out of the timings
    _sweep_stack(name, small)
for name in order:
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    base = status("VmRSS:")
    t0 = time.perf_counter()
    stack = _sweep_stack(name, data)
    out[name + "_s"] = time.perf_counter() - t0
    out[name + "_peak"] = status("VmHWM:") - base
    del stack
print("SWEEP " + json.dumps(out))
"""


def _parity_case(quick: bool):
    scenes = PARITY_SCENES[2:4] if quick else PARITY_SCENES

    def load():
        from lumigraph.capture.render import render
        from lumigraph.lightfield.field import LightField

        out = []
        for p in scenes:
            s = render("lightfield-array", thin_lens=False, **p)
            out.append({"name": f"{p['grid']} {p['size'][0]}x{p['size'][1]} seed {p['seed']}",
                        "lf": LightField(s.gt_arrays["views"].astype(np.float32)),
                        "slopes": [float(x) for x in s.gt["focus_slopes"]],
                        "truth": s.gt_arrays["synthetic_aperture"]})
        return {"kind": "parity", "scenes": out}

    return Case("refocus parity", load,
                f"{len(scenes)} rendered scenes (grids 5x5..9x9, even and odd, texel 0.6..3 px, "
                "slopes -0.6..2.5 px/view); truth: exact synthetic aperture per slope; "
                "error: worst PSNR over scenes x slopes (extras: each)")


def _sweep_case(quick: bool):
    grid, n = SWEEP["quick" if quick else "full"]

    def load():
        from lumigraph.capture.render import render
        from lumigraph.lightfield.field import LightField

        slopes = np.linspace(-1.0, 1.0, SWEEP_SLOPES)
        s = render("lightfield-array", size=(n, n), grid=grid, thin_lens=False,
                   focus=tuple(float(x) for x in slopes[::10]))
        return {"kind": "sweep", "lf": LightField(s.gt_arrays["views"].astype(np.float32)),
                "slopes": slopes, "truth_idx": list(range(0, SWEEP_SLOPES, 10)),
                "truth": s.gt_arrays["synthetic_aperture"]}

    return Case("refocus sweep", load,
                f"{grid} views of {n}x{n}x3 (the bench's affordable size; the 512x512 figures "
                f"are in docs/decisions/fourier-refocus.md), {SWEEP_SLOPES} slopes -1..1; "
                "single-threaded (FFT workers 1, BLAS 1 thread where it can be set); peak "
                "memory: tracemalloc's peak above the call's start, in an untimed extra run")


def _sweep_issue_case():
    g, n = SWEEP_ISSUE

    def load():
        return {"kind": "sweep child", "grid": g, "size": n, "runs": []}

    return Case(f"refocus sweep {g}x{g}x{n}x{n}x3 (child)", load,
                f"the issue's size: {g}x{g} random views of {n}x{n}x3 float32, "
                f"{SWEEP_SLOPES} slopes -1..1, single-threaded, both methods in one child "
                "process per repeat, alternating which goes first (time: min over the repeats; "
                "peak: the child's resident high-water mark above the call's start, output "
                "stack included, reset before each call); full bench only")


def sweep_child(grid: int, size: int, slopes: int = SWEEP_SLOPES,
                order=("fourier", "shift-add")) -> dict:
    """Run the 50-slope sweep of both methods in a fresh Python process (see
    ``_SWEEP_CHILD``): ``{"lf_bytes", "<method>_s", "<method>_peak"}``."""
    import json
    import os
    import subprocess
    import sys

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    p = subprocess.run([sys.executable, "-c", _SWEEP_CHILD, str(grid), str(size), str(slopes),
                        ",".join(order)], capture_output=True, text=True, env=env, check=False)
    for line in p.stdout.splitlines():
        if line.startswith("SWEEP "):
            return json.loads(line[len("SWEEP "):])
    raise RuntimeError(f"sweep child exited {p.returncode}: {p.stderr.strip()[-300:]}")


def _sweep_child_run(data, _):
    # the first method of a child pays its page faults on fresh memory: alternate
    order = ("fourier", "shift-add") if len(data["runs"]) % 2 == 0 else ("shift-add", "fourier")
    data["runs"].append(sweep_child(data["grid"], data["size"], order=order))
    return {"runs": list(data["runs"])}


def _parity_run(method):
    def run(data, _):
        from lumigraph.lightfield import ng2005
        from lumigraph.lightfield.refocus import shift_and_add_stack

        f = ng2005.refocus_stack if method == "fourier" else shift_and_add_stack
        return {"parity": [f(sc["lf"], sc["slopes"]) for sc in data["scenes"]]}

    return run


def _blas_threads(n: int) -> int | None:
    """Set OpenBLAS's thread count through the library numpy loaded; the
    previous count, or None where no OpenBLAS is found."""
    import ctypes

    try:
        with open("/proc/self/maps") as f:
            libs = {ln.split()[-1] for ln in f if "openblas" in ln.lower() and ".so" in ln}
    except OSError:
        return None
    for path in sorted(libs):
        lib = ctypes.CDLL(path)
        for get, put in (("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
                         ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
                         ("openblas_get_num_threads", "openblas_set_num_threads")):
            if hasattr(lib, get) and hasattr(lib, put):
                old = int(getattr(lib, get)())
                getattr(lib, put)(int(n))
                return old
    return None


def _sweep_stack(method, data):
    from lumigraph.lightfield import ng2005
    from lumigraph.lightfield.refocus import shift_and_add_stack

    workers, ng2005.WORKERS = ng2005.WORKERS, 1
    old = _blas_threads(1)
    try:
        if method == "fourier":
            return ng2005.refocus_stack(data["lf"], data["slopes"])
        return shift_and_add_stack(data["lf"], data["slopes"])
    finally:
        ng2005.WORKERS = workers
        if old is not None:
            _blas_threads(old)


def _sweep_peak(method):
    """Untimed: one sweep under tracemalloc (numpy's allocations are traced,
    the spectrum's too: ng2005 allocates it plainly while tracing); the peak
    above the call's start, output stack included."""
    def prepare(data):
        import tracemalloc

        tracemalloc.start()
        try:
            base = tracemalloc.get_traced_memory()[0]
            _sweep_stack(method, data)
            peak = tracemalloc.get_traced_memory()[1] - base
        finally:
            tracemalloc.stop()
        return {**data, "peak_bytes": peak}

    return prepare


def _sweep_run(method):
    def run(data, _):
        return {"sweep": _sweep_stack(method, data), "peak_bytes": data["peak_bytes"]}

    return run


def _parity_error(data, out):
    if "parity" in out:
        extra, worst = {}, math.inf
        for sc, images in zip(data["scenes"], out["parity"], strict=True):
            for k, s in enumerate(sc["slopes"]):
                p = _psnr(float(np.mean((images[k].astype(np.float64) - sc["truth"][k]) ** 2)))
                extra[f"psnr_db {sc['name']} slope {s:g}"] = p
                worst = min(worst, p)
        return {"error": worst, "psnr_db_worst": worst, **extra}
    if "runs" in out:   # the issue-size sweep in a child process
        runs = out["runs"]
        lf_bytes = runs[0]["lf_bytes"]
        res = {m: {"s": min(r[f"{m}_s"] for r in runs), "peak": max(r[f"{m}_peak"] for r in runs)}
               for m in ("fourier", "shift-add")}
        return {"error": math.nan, "runs": len(runs), "lf_mb": lf_bytes / 2 ** 20,
                "fourier_s": res["fourier"]["s"], "shift_add_s": res["shift-add"]["s"],
                "fourier_peak_mb": res["fourier"]["peak"] / 2 ** 20,
                "shift_add_peak_mb": res["shift-add"]["peak"] / 2 ** 20,
                "fourier_peak_over_lf": res["fourier"]["peak"] / lf_bytes,
                "ratio": res["fourier"]["s"] / res["shift-add"]["s"]}
    images, idx = out["sweep"], data["truth_idx"]
    mse = float(np.mean((images[idx].astype(np.float64) - data["truth"]) ** 2))
    lf_bytes = data["lf"].data.nbytes
    peak = out["peak_bytes"]
    return {"error": math.sqrt(mse), "psnr_db": _psnr(mse), "slopes": len(data["slopes"]),
            "lf_mb": lf_bytes / 2 ** 20,
            "peak_mb": math.nan if peak is None else peak / 2 ** 20,
            "peak_over_lf": math.nan if peak is None else peak / lf_bytes}


def _fourier_checks(res: Results, quick: bool) -> list[Check]:
    out = []
    try:
        fo = res.get("refocus parity", "parity: fourier slice (ours)")
        sa = res.get("refocus parity", "parity: shift-add lanczos3 (ours)")
        keys = [k for k in fo.extra if k.startswith("psnr_db ") and k in sa.extra]
        d = {k[len("psnr_db "):]: fo.extra[k] - sa.extra[k] for k in keys}
        worst = min(d, key=d.get)
        out.append(Check("Fourier slice within 0.2 dB of our shift-and-add on every rendered "
                         "scene and slope (dB, worst)", d[worst], -0.2, d[worst] >= -0.2,
                         f"{len(d)} scene x slope pairs; median {np.median(list(d.values())):+.2f} "
                         f"dB; worst {worst}"))
    except (KeyError, ValueError) as e:
        out.append(Check("refocus parity rows present", math.nan, None, False, str(e)))
    try:
        fo = res.get("refocus sweep", "sweep 50: fourier slice (ours)")
        sa = res.get("refocus sweep", "sweep 50: shift-add lanczos3 (ours)")
        t_fo, t_sa = min(fo.times_s), min(sa.times_s)
        size = "5x5x96x96x3 (quick)" if quick else "9x9x256x256x3"
        out.append(Check(f"{SWEEP_SLOPES} slopes: Fourier total <= 0.3x shift-and-add, {size}, "
                         "single thread", t_fo / t_sa, 0.3, t_fo / t_sa <= 0.3 or quick,
                         f"min of repeats {t_fo:.2f} s vs {t_sa:.2f} s; PSNR at 5 slopes "
                         f"{fo.extra['psnr_db']:.2f} vs {sa.extra['psnr_db']:.2f} dB"
                         + (" (informational in quick mode)" if quick else "")))
        r = fo.extra["peak_over_lf"]
        out.append(Check(f"{SWEEP_SLOPES} slopes: Fourier peak memory <= 2x the light field, "
                         f"{size}", r, 2.0, r <= 2.0 or quick,
                         f"{fo.extra['peak_mb']:.0f} MB above the call's start (output stack "
                         f"included) for a {fo.extra['lf_mb']:.0f} MB light field; shift-add "
                         f"{sa.extra['peak_mb']:.0f} MB"
                         + (" (informational in quick mode: spectra under 64 MB keep all "
                            "channels at once)" if quick else "")))
    except (KeyError, ValueError) as e:
        out.append(Check("refocus sweep rows present", math.nan, None, False, str(e)))
    if quick:
        return out
    g, n = SWEEP_ISSUE
    size = f"{g}x{g}x{n}x{n}x3 (the issue's size)"
    try:
        x = res.get(f"refocus sweep {g}x{g}x{n}x{n}x3 (child)", "sweep 50 in a child: both").extra
        r = x["ratio"]
        out.append(Check(f"{SWEEP_SLOPES} slopes: Fourier total <= 0.3x shift-and-add, {size}, "
                         "single thread, child process", r, 0.3, r <= 0.3,
                         f"min of {x['runs']} children: {x['fourier_s']:.2f} s vs "
                         f"{x['shift_add_s']:.2f} s"))
        r = x["fourier_peak_over_lf"]
        out.append(Check(f"{SWEEP_SLOPES} slopes: Fourier peak memory <= 2x the light field, "
                         f"{size}, child's resident high-water mark", r, 2.0, r <= 2.0,
                         f"{x['fourier_peak_mb']:.0f} MB above the call's start (output stack "
                         f"included; the worst of {x['runs']} children) for a "
                         f"{x['lf_mb']:.0f} MB light field; shift-add "
                         f"{x['shift_add_peak_mb']:.0f} MB"))
    except (KeyError, ValueError) as e:
        out.append(Check("refocus sweep (child) rows present", math.nan, None, False, str(e)))
    return out


# ------------------------------------------------------------------ methods
def _shift_add(data, kernel):
    from lumigraph.lightfield.refocus import shift_and_add

    return {"idx": list(range(len(data["slopes"]))),
            "images": np.stack([shift_and_add(data["lf"], s, kernel=kernel)
                                for s in data["slopes"]])}


def _scipy_shift(data, order):
    """Peer: shift-and-add with scipy.ndimage.shift (spline of the given order),
    per channel (2-D), mirror borders."""
    from scipy.ndimage import shift

    lf = data["lf"]
    u, v = lf.grid
    uc, vc = lf.center
    out = []
    for s in data["slopes"][:1]:   # one refocus: the peer is slow (times are per refocus)
        acc = np.zeros(lf.data.shape[2:], np.float64)
        for i in range(u):
            for j in range(v):
                for c in range(lf.data.shape[4]):
                    acc[..., c] += shift(lf.data[i, j, :, :, c], (s * (i - uc), s * (j - vc)),
                                         order=order, mode="reflect")
        out.append(acc / (u * v))
    return {"idx": [0], "images": np.stack(out).astype(np.float32)}


def _interleaved(data, _):
    """FFT once, then Fourier slice and Lanczos shift-and-add alternately,
    each call timed, ``ALTERNATIONS`` times (cycling over the slopes): on a
    shared machine the load drifts between bench rows, so the speed targets
    use the medians of these side-by-side times, and the ratio's spread over
    the alternations is reported too."""
    import time

    from lumigraph.lightfield import ng2005
    from lumigraph.lightfield.refocus import shift_and_add

    t0 = time.perf_counter()
    spec = ng2005.prepare(data["lf"], max_slope=max(data["slopes"]))
    t_fft = time.perf_counter() - t0
    t_fo, t_sa, images = [], [], {}
    slopes = data["slopes"]
    for n in range(max(ALTERNATIONS, len(slopes))):
        s = slopes[n % len(slopes)]
        t0 = time.perf_counter()
        img = ng2005.refocus(spec, s)
        t_fo.append(time.perf_counter() - t0)
        images.setdefault(n % len(slopes), img)
        t0 = time.perf_counter()
        shift_and_add(data["lf"], s)
        t_sa.append(time.perf_counter() - t0)
    ratios = np.asarray(t_fo) / np.asarray(t_sa)
    return {"idx": list(range(len(slopes))), "images": np.stack([images[i] for i in
                                                                  range(len(slopes))]),
            "timing": {"fft_s": t_fft, "slice_s": float(np.median(t_fo)),
                       "shift_add_s": float(np.median(t_sa)),
                       "ratio_median": float(np.median(ratios)),
                       "ratio_max": float(ratios.max()), "alternations": len(ratios)}}


def _fft(data, _):
    from lumigraph.lightfield import ng2005

    spec = ng2005.prepare(data["lf"], max_slope=max(data["slopes"]))
    data["spec"] = spec
    return {"spec": spec}


def _fourier_prepare(data):
    from lumigraph.lightfield import ng2005

    if "spec" not in data:
        data["spec"] = ng2005.prepare(data["lf"], max_slope=max(data["slopes"]))
    return data


def _fourier(data, _):
    from lumigraph.lightfield import ng2005

    return {"idx": list(range(len(data["slopes"]))),
            "images": np.stack([ng2005.refocus(data["spec"], s) for s in data["slopes"]])}


def _decode(data, _):
    from lumigraph.lightfield.lenslet import decode

    d = decode(data["raw"], data["white"], views=data["views"])
    return {"views": d.lightfield.data, "centers": d.grid.centers()}


def _novel(interp):
    def run(data, slope):
        from lumigraph.lightfield.levoy1996 import render_view

        return render_view(data["lf"], data["position"], focus_slope=slope, interpolation=interp)

    return run


def _depth(name):
    def run(data, _):
        from lumigraph.lightfield.methods import DEPTH_METHODS

        return DEPTH_METHODS[name](data["lf"], data["slopes"])

    return run


def _depth_interleaved_prepare(data):
    return {**data, "times": {"wang2015": [], "variance": []},
            "peaks": {"wang2015": [], "variance": []}}


def _depth_interleaved(data, _):
    """Ours (``wang2015``) and the baseline (``variance``) one after the other
    on the same input, each call timed and its peak of traced allocations
    (tracemalloc: numpy arrays, OpenCV's outputs; not OpenCV's internal
    scratch) recorded; over the bench's repeats the minimum times are
    compared, since the load of a shared machine only ever adds time."""
    import time
    import tracemalloc
    from types import SimpleNamespace

    from lumigraph.lightfield.methods import DEPTH_METHODS

    times, peaks, est = data["times"], data["peaks"], {}
    tracemalloc.start()
    try:
        for name in times:
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            t0 = time.perf_counter()
            est[name] = DEPTH_METHODS[name](data["lf"], data["slopes"]).disparity
            times[name].append(time.perf_counter() - t0)
            peaks[name].append(tracemalloc.get_traced_memory()[1] - base)
    finally:
        tracemalloc.stop()
    base_metrics = {f"baseline_{k}": v for k, v in
                    _depth_metrics(est["variance"], data["truth"]).items()}
    return SimpleNamespace(disparity=est["wang2015"], timing={
        "ours_s": min(times["wang2015"]), "baseline_s": min(times["variance"]),
        "alternations": len(times["wang2015"]),
        "ours_peak_mb": max(peaks["wang2015"]) / 2 ** 20,
        "baseline_peak_mb": max(peaks["variance"]) / 2 ** 20,
        "lf_mb": data["lf"].data.nbytes / 2 ** 20, **base_metrics})


def _depth_metrics(disp, truth) -> dict:
    """The HCI benchmark's metrics over its evaluation region (all but a
    ``HCI_BOUNDARY`` px border): BadPix(t) = % of pixels with |error| > t px,
    MSE x 100 = 100 x mean squared error (px^2)."""
    b = HCI_BOUNDARY
    e = (disp - truth)[b:-b, b:-b].astype(np.float64)
    a = np.abs(e)
    return {"error": float(a.mean()), "badpix_0.07_pct": 100 * float((a > 0.07).mean()),
            "badpix_0.03_pct": 100 * float((a > 0.03).mean()),
            "badpix_0.01_pct": 100 * float((a > 0.01).mean()),
            "mse_x100": 100 * float((e ** 2).mean())}


def _error(data, out):
    kind = data["kind"]
    if kind in ("parity", "sweep", "sweep child"):
        return _parity_error(data, out)
    if kind == "refocus":
        if "spec" in out:   # the FFT alone: error of the slices it enables (untimed)
            out = _fourier(data, None)
        truth = data["truth"][out["idx"]]
        mse = float(np.mean((out["images"].astype(np.float64) - truth) ** 2))
        first = float(np.mean((out["images"][0].astype(np.float64) - truth[0]) ** 2))
        return {"error": math.sqrt(mse), "psnr_db": _psnr(mse), "psnr_db_first": _psnr(first),
                "per_refocus": len(out["idx"]), **out.get("timing", {})}
    if kind == "lenslet":
        v, t = out["views"], data["truth"]
        if v.shape != t.shape:
            raise ValueError(f"decoded {v.shape} but truth is {t.shape}")
        mse = float(np.mean((v.astype(np.float64) - t) ** 2))
        c = out["centers"]
        if c.shape != data["centers"].shape:
            raise ValueError(f"found {c.shape[:2]} lenslets, truth has {data['centers'].shape[:2]}")
        err = np.linalg.norm(c - data["centers"], axis=-1)
        return {"error": math.sqrt(mse), "psnr_db": _psnr(mse),
                "centre_err_max_px": float(err.max()), "centre_err_rms_px":
                    float(np.sqrt((err ** 2).mean()))}
    if kind == "novel":
        m = out.valid
        mse = float(np.mean((out.image[m].astype(np.float64) - data["truth"][m]) ** 2))
        return {"error": math.sqrt(mse), "psnr_db": _psnr(mse), "valid_fraction": float(m.mean())}
    if kind == "depth":
        return {**_depth_metrics(out.disparity, data["truth"]), **getattr(out, "timing", {})}
    raise ValueError(kind)


def _per_refocus(row) -> float:
    return row.time_s / max(1, row.extra.get("per_refocus", 1))


def _checks(res: Results, ctx) -> list[Check]:
    out = []
    quick = ctx.get("quick", False)
    size = "5x5x128x128x3 (quick)" if quick else "9x9x512x512x3"
    try:
        lin = res.get("array", "shift-add (ours)", "linear")
        lz = res.get("array", "shift-add (ours)", "lanczos3")
        fo = res.get("array", "fourier slice (ours)")
        fft = res.get("array", "4-D FFT (ours)")
        p_lin, p_lz, p_fo = lin.extra["psnr_db"], lz.extra["psnr_db"], fo.extra["psnr_db"]
        out.append(Check("shift-and-add PSNR >= bilinear baseline + 2 dB (vs exact "
                         "synthetic aperture)", p_lz - p_lin, 2.0, p_lz - p_lin >= 2.0,
                         f"lanczos3 {p_lz:.2f} dB, bilinear {p_lin:.2f} dB"))
        out.append(Check(f"Fourier slice within 0.2 dB of our shift-and-add, {size}", p_fo - p_lz,
                         -0.2, p_fo - p_lz >= -0.2,
                         f"Fourier {p_fo:.2f} dB, shift-add {p_lz:.2f} dB"
))
        il = res.get("array", "interleaved timing (ours)")
        t_fo, t_lz, t_fft = il.extra["slice_s"], il.extra["shift_add_s"], il.extra["fft_s"]
        ratio = il.extra["ratio_median"]
        out.append(Check(f"each Fourier refocus (after the FFT) <= 0.1x one shift-and-add, "
                         f"{size}", ratio, 0.1, ratio <= 0.1 or quick,
                         f"median of {il.extra['alternations']} side-by-side ratios (max "
                         f"{il.extra['ratio_max']:.3f}); medians {t_fo:.3f} s vs {t_lz:.3f} s "
                         f"per refocus (separate rows: {_per_refocus(fo):.3f} s vs "
                         f"{_per_refocus(lz):.3f} s)"
                         + (" (informational in quick mode)" if quick else "")))
        tot_fo, tot_sa = t_fft + 10 * t_fo, 10 * t_lz
        out.append(Check(f"10 depths: Fourier total (FFT included) < shift-and-add total, {size}",
                         tot_fo / tot_sa, 1.0, tot_fo < tot_sa or quick,
                         f"FFT {t_fft:.2f} s + 10 x {t_fo:.3f} s = {tot_fo:.2f} s vs "
                         f"10 x {t_lz:.3f} s = {tot_sa:.2f} s (FFT row median {fft.time_s:.2f} s)"
                         + (" (informational in quick mode)" if quick else "")))
        try:
            sp1 = res.get("array", "scipy.ndimage.shift", 1)
            sp3 = res.get("array", "scipy.ndimage.shift", 3)
            f_lz = lz.extra["psnr_db_first"]
            out.append(Check(f"peer: shift-and-add PSNR - scipy.ndimage.shift order 3 at slope "
                             f"{SLOPES[0]} (dB)", f_lz - sp3.extra["psnr_db"], 0.0, True,
                             f"scipy order 1 {sp1.extra['psnr_db']:.2f} dB, order 3 "
                             f"{sp3.extra['psnr_db']:.2f} dB ({_per_refocus(sp3):.3f} s/refocus), "
                             "informational"))
        except (KeyError, AttributeError):
            pass
    except KeyError as e:
        out.append(Check("refocus rows present", math.nan, None, False, str(e)))
    out += _fourier_checks(res, quick)
    for lat in ("square", "hex"):
        try:
            r = res.get(f"lenslet {lat}", "decode (ours)")
            out.append(Check(f"lenslet {lat}: microlens centres within 0.1 px of truth",
                             r.extra["centre_err_max_px"], 0.1, r.extra["centre_err_max_px"] <= 0.1,
                             f"max {r.extra['centre_err_max_px']:.4f} px, "
                             f"RMS {r.extra['centre_err_rms_px']:.4f} px"))
            out.append(Check(f"lenslet {lat}: sub-aperture views >= 35 dB PSNR", r.extra["psnr_db"],
                             35.0, r.extra["psnr_db"] >= 35.0, "noise-free raw, estimated grid"))
        except (KeyError, AttributeError) as e:
            out.append(Check(f"lenslet {lat} decoded", math.nan, None, False, str(e)))
    try:
        rows = res.of("novel view", "light slab quadrilinear")
        best = max(rows, key=lambda r: r.extra["psnr_db"])
        out.append(Check("novel view at an in-between position >= 30 dB PSNR",
                         best.extra["psnr_db"], 30.0, best.extra["psnr_db"] >= 30.0,
                         f"quadrilinear, focal slope {best.value}, valid "
                         f"{100 * best.extra['valid_fraction']:.1f}%"))
    except (KeyError, ValueError) as e:
        out.append(Check("novel view rendered", math.nan, None, False, str(e)))
    out.extend(_depth_checks(res))
    return out


def _depth_checks(res: Results) -> list[Check]:
    out = []
    try:
        il = res.get("HCI antinous", "depth wang2015 vs variance, interleaved")
        x = il.extra
        bp, mse = x["badpix_0.07_pct"], x["mse_x100"]
        out.append(Check("HCI antinous (held out): BadPix(0.07) <= 20 %", bp, 20.0, bp <= 20.0,
                         f"BadPix 0.03 / 0.01: {x['badpix_0.03_pct']:.1f} / "
                         f"{x['badpix_0.01_pct']:.1f} %; baseline (variance) "
                         f"{x['baseline_badpix_0.07_pct']:.1f} / "
                         f"{x['baseline_badpix_0.03_pct']:.1f} / "
                         f"{x['baseline_badpix_0.01_pct']:.1f} %"))
        out.append(Check("HCI antinous (held out): MSE x 100 <= 5", mse, 5.0, mse <= 5.0,
                         f"baseline {x['baseline_mse_x100']:.1f}"))
        t_new, t_old = il.extra["ours_s"], il.extra["baseline_s"]
        # the issue's 10 s on its machine, where the baseline took 9.2 s: here,
        # 10 s x (the baseline's time alongside ours / 9.2 s)
        target = DEPTH_TARGET_S * t_old / DEPTH_BASELINE_ISSUE_S
        out.append(Check(f"HCI antinous: depth time <= {DEPTH_TARGET_S:g} s on the issue's machine "
                         f"(target scaled by the baseline's time here)", t_new, target,
                         t_new <= target,
                         f"ours {t_new:.1f} s, baseline {t_old:.1f} s (min of "
                         f"{il.extra['alternations']} interleaved each; issue: baseline "
                         f"{DEPTH_BASELINE_ISSUE_S} s), ratio {t_new / t_old:.2f} <= "
                         f"{DEPTH_TARGET_S / DEPTH_BASELINE_ISSUE_S:.2f}; absolute "
                         f"{'within' if t_new <= DEPTH_TARGET_S else 'above'} "
                         f"{DEPTH_TARGET_S:g} s on this machine"))
        peak = il.extra["ours_peak_mb"] + il.extra["lf_mb"]
        out.append(Check("HCI antinous: depth peak memory <= 1 GB (light field + the call's "
                         "peak allocations)", peak, 1024.0, peak <= 1024.0,
                         f"call {il.extra['ours_peak_mb']:.0f} MB + light field "
                         f"{il.extra['lf_mb']:.0f} MB; baseline's call "
                         f"{il.extra['baseline_peak_mb']:.0f} MB (tracemalloc)"))
    except (KeyError, AttributeError):
        pass   # shared data missing: the case is skipped
    for suffix, bound, what in (("", 0.5, "BadPix(0.07) <= 0.5x the baseline's"),
                                ("q", 1.0, "8-bit quantised views, BadPix(0.07) <= the "
                                           "baseline's (no issue target: tracks a weakness)")):
        ratios = []
        for k in ISSUE_KINDS:
            for s in (1, 2):
                try:
                    n = res.get(f"depth {k}{suffix} seed {s}", "depth wang2015 (ours)")
                    o = res.get(f"depth {k}{suffix} seed {s}", "depth variance (baseline)")
                    ratios.append(n.extra["badpix_0.07_pct"]
                                  / max(o.extra["badpix_0.07_pct"], 1e-9))
                except (KeyError, AttributeError):
                    continue
        if ratios:
            worst = max(ratios)
            out.append(Check(f"rendered depth (seeds 1-2, not tuned on): {what}, worst scene",
                             worst, bound, worst <= bound,
                             f"median ratio {float(np.median(ratios)):.2f} over {len(ratios)} "
                             "scenes"))
    return out


def stage(*, quick: bool = False) -> Stage:
    cases = (_array_case(quick), _lenslet_case("square", quick), _lenslet_case("hex", quick),
             _novel_case(quick), _hci_case(), _parity_case(quick), _sweep_case(quick),
             *(() if quick else (_sweep_issue_case(),)),
             *(_depth_case(k + q, seed, quick) for q in ("", "q") for k in DEPTH_SCENES
               if not (q and k == "F")
               for seed in (0, 1, 2)))
    # HCI antinous: both methods in one row, interleaved (speed target)
    depth_cases = tuple(f"depth {k}{q} seed {s}" for q in ("", "q") for k in DEPTH_SCENES
                        if not (q and k == "F")
                        for s in (0, 1, 2))
    arr = ("array",)
    methods = (
        Method("shift-add (ours)", _shift_add, "kernel", ("linear", "cubic", "lanczos3"),
               cases=arr),
        Method("4-D FFT (ours)", _fft, cases=arr),
        Method("fourier slice (ours)", _fourier, prepare=_fourier_prepare, cases=arr),
        Method("interleaved timing (ours)", _interleaved, cases=arr),
        Method("scipy.ndimage.shift", _scipy_shift, "order", (1, 3), peer="scipy", cases=arr),
        Method("decode (ours)", _decode, cases=("lenslet square", "lenslet hex")),
        Method("light slab quadrilinear", _novel("quadrilinear"), "focus slope", (0.0, 0.35),
               cases=("novel view",)),
        Method("light slab uv-bilinear", _novel("uv-bilinear"), "focus slope", (0.0, 0.35),
               cases=("novel view",)),
        Method("parity: shift-add lanczos3 (ours)", _parity_run("shift-add"),
               cases=("refocus parity",)),
        Method("parity: fourier slice (ours)", _parity_run("fourier"), cases=("refocus parity",)),
        Method("sweep 50: shift-add lanczos3 (ours)", _sweep_run("shift-add"),
               cases=("refocus sweep",), prepare=_sweep_peak("shift-add")),
        Method("sweep 50: fourier slice (ours)", _sweep_run("fourier"), cases=("refocus sweep",),
               prepare=_sweep_peak("fourier")),
        Method("sweep 50 in a child: both", _sweep_child_run,
               cases=(_sweep_issue_case().name,)),
        Method("depth wang2015 (ours)", _depth("wang2015"), cases=depth_cases),
        Method("depth variance (baseline)", _depth("variance"), cases=depth_cases),
        Method("depth wang2015 vs variance, interleaved", _depth_interleaved,
               prepare=_depth_interleaved_prepare, cases=("HCI antinous",)),
    )
    return Stage("lightfield", cases, methods, _error, "RMS error (linear radiance; px for "
                                                        "disparity)", checks=_checks,
                 description="Refocusing against the exact synthetic-aperture truth (times per "
                             "refocus; the 4-D FFT row is the one-time cost), lenslet decoding, "
                             "light-slab novel views, depth from the light field.")
