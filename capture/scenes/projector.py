"""``projector`` scenes: a projector-lit corner with real global illumination (Mitsuba 3).

The scene: a V-groove corner of two diffuse walls (diffuse interreflection), a
diffuse floor, a cube of dense scattering medium (subsurface-like volume
scattering, index-matched ``null`` boundary) and a diffuse sphere, lit by a
pinhole projector placed beside the camera (so there are cast shadows the
projector never reaches). ``--mirror`` turns the right wall into a
near mirror (``roughconductor``, GGX α = 0.05) that throws the pattern onto the
left wall: the case where separation fails (reference §8.3.3, Fig. 8.45).

Ground truth (Mitsuba ``volpath``; ``max_depth`` counts path *vertices after the
camera*: 1 = emitters seen directly, **2 = one scattering event, i.e. direct
illumination only** (a surface reflection or a single medium-scattering event
lit straight from the projector), −1 = unlimited):

- ``direct`` = render with ``max_depth=2``; ``full`` = render with
  ``max_depth=-1``; ``global = full − direct`` — each under an all-white
  projector, in linear units where 1.0 is the camera's full-scale code.

Speed comes from the **linearity of light transport**. The projector image is
cut into cells; every pattern used here is constant per cell and periodic with
``n = 4`` cells, so it is ``Σ_c w_c·1_c`` over the 16 residue classes ``c`` of
the cell lattice, and its image is ``Σ_c (b + (1 − b) w_c)·I_c`` where ``I_c``
is the render with only class ``c`` lit. The scene is grey, so three classes
share one RGB render (one per channel, identical paths). Direct light (sharp,
cheap: one NEE per path) is rendered at full resolution; global light (smooth
in the image, expensive) at 1/4 resolution with 16× the samples and upsampled
bilinearly (a linear map, so composition stays exact). Each class's global is
``full − direct`` of two renders **with the same seed** (identical first
vertices), so it is never negative. Every pattern image and the ground truth
are built from the same 16 class renders: the stack is exactly consistent
with the ground truth, and ``gt.json`` states the Monte Carlo noise
(``mc_noise``: measured from two independent half-sample renders) that the
renders themselves carry relative to the converged solution.

Captured images are 16-bit (``--bit-depth``) linear codes of a monochrome
camera, with optional shot noise (``--full-well``) and read noise
(``--read-noise``); ``stack.json`` lists every image and, under ``sets``, which
images each separation method takes.
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.render import Option, RenderedScene, SceneSpec

N_CLASS = 4          # pattern period in projector cells (checker squares of 2 cells)
GLOBAL_FACTOR = 4    # global light is rendered at 1/4 of the image resolution
VERSION = 3
# Dense, forward-scattering, weakly absorbing: light diffuses over several pattern
# periods (transport length ~0.3 scene units) like marble or milk.
MIRROR_ALPHA = 0.05
MEDIUM = {"sigma_t": 10.0, "albedo": 0.98, "g": 0.5}


def _mi():
    import mitsuba as mi

    mi.set_variant("scalar_rgb")  # the only variant that works on this machine
    mi.set_log_level(mi.LogLevel.Error)  # sampler notices would break one-line CLI errors
    return mi


def _scene_dict(size, tex, *, depth, spp, mirror, seed_sampler="multijitter"):
    mi = _mi()
    T = mi.ScalarTransform4f
    w, h = size
    grey = lambda v: {"type": "diffuse", "reflectance": {"type": "rgb", "value": float(v)}}  # noqa: E731
    d = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": int(depth)},
        "sensor": {"type": "perspective", "fov": 40.0,
                   "to_world": T().look_at(origin=[0.0, 0.3, 4.5], target=[0.0, -0.15, 0.0],
                                           up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": int(w), "height": int(h),
                            "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                   "sampler": {"type": seed_sampler, "sample_count": int(spp)}},
        "projector": {"type": "projector", "fov": 44.0,
                      "to_world": T().look_at(origin=[0.55, 0.75, 4.4], target=[0.0, -0.15, 0.0],
                                              up=[0, 1, 0]),
                      "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex),
                                     "filter_type": "nearest", "raw": True},
                      "scale": 25.0},
        "wall_left": {"type": "rectangle", "bsdf": grey(0.75),
                      "to_world": T().translate([-0.92, 0.25, -0.92]).rotate([0, 1, 0], 45)
                      .scale([1.3, 1.3, 1.0])},
        "wall_right": {"type": "rectangle", "bsdf": grey(0.75),
                       "to_world": T().translate([0.92, 0.25, -0.92]).rotate([0, 1, 0], -45)
                       .scale([1.3, 1.3, 1.0])},
        "floor": {"type": "rectangle", "bsdf": grey(0.55),
                  "to_world": T().translate([0, -1.0, 0]).rotate([1, 0, 0], -90).scale([2.6, 2.6, 1])},
        "medium_cube": {"type": "cube", "bsdf": {"type": "null"},
                        "to_world": T().translate([0.35, -0.62, 0.55]).rotate([0, 1, 0], 30).scale(0.38),
                        "interior": {"type": "homogeneous", "sigma_t": MEDIUM["sigma_t"],
                                     "albedo": {"type": "rgb", "value": MEDIUM["albedo"]},
                                     "phase": {"type": "hg", "g": MEDIUM["g"]}}},
        "sphere": {"type": "sphere", "radius": 0.33, "center": [-0.55, -0.67, 0.35],
                   "bsdf": grey(0.6)},
    }
    if mirror:
        # the right wall becomes a near mirror: it throws the pattern onto the left wall
        d["wall_right"]["bsdf"] = {"type": "roughconductor", "alpha": MIRROR_ALPHA, "material": "Al"}
    return d


def _render(size, tex, *, depth, spp, mirror, seed):
    mi = _mi()
    scene = mi.load_dict(_scene_dict(size, tex, depth=depth, spp=spp, mirror=mirror))
    return np.array(mi.render(scene, seed=int(seed)), dtype=np.float64)


def white_render(size, *, depth=-1, spp=32, seed=7, mirror=False):
    """An independent render under the all-white projector (first channel,
    unit emission, same units as :func:`class_renders` before ``gain``), for
    checking the class composition against Mitsuba directly."""
    cx, cy = projector_cells(size)
    tex = np.ones((cy, cx, 3), np.float32)
    return _render(size, tex, depth=depth, spp=spp, mirror=mirror, seed=seed)[..., 0]


def projector_cells(size) -> tuple[int, int]:
    """Projector resolution in cells for a camera of ``size``: about 4 camera
    pixels per cell at the walls, a whole number of ``N_CLASS``-cell periods."""
    w, h = size
    cx = max(N_CLASS, N_CLASS * int(round(w / (3.6 * N_CLASS))))
    cy = max(N_CLASS, N_CLASS * int(round(cx * 0.75 / N_CLASS)))
    return cx, cy


_BASIS: dict = {}


def class_renders(size, *, mirror=False, spp_direct=8, spp_global=256, seed=0):
    """One image per residue class of the projector cell lattice (memoised).

    Variants that differ only in b, α or camera noise reuse the same renders:
    in memory, and on disk beside the scene cache (``basis-<key>.npz``).

    Returns
    -------
    direct, glob : ndarray, ``(16, H, W)`` float64
        Direct (``max_depth=2``) and global (``full − direct``, same seed,
        rendered at 1/4 resolution and upsampled bilinearly) light of each class
        lit alone at unit emission; class ``c = j·4 + i`` lights cells
        ``(x mod 4, y mod 4) = (i, j)``.
    """
    import hashlib

    from lumigraph.capture.render import cache_dir

    key = hashlib.sha256(repr((VERSION, MEDIUM, tuple(size), bool(mirror), spp_direct, spp_global,
                               seed)).encode()).hexdigest()[:20]
    if key in _BASIS:
        return _BASIS[key]
    path = cache_dir() / f"projector-basis-{key}.npz"
    if path.exists():
        try:
            with np.load(path) as z:
                _BASIS[key] = (z["direct"], z["glob"])
                return _BASIS[key]
        except Exception:  # a damaged cache file is re-rendered, never trusted
            pass
    out = _class_renders(size, mirror=mirror, spp_direct=spp_direct, spp_global=spp_global, seed=seed)
    _BASIS[key] = out
    try:
        from lumigraph.capture.artifact import atomic_path

        with atomic_path(path, immediate=True) as tmp:  # same folder, umask's mode, replaced at the end
            np.savez(tmp, direct=out[0], glob=out[1])
    except OSError:
        pass  # a read-only cache only costs speed
    return out


def _class_renders(size, *, mirror, spp_direct, spp_global, seed):
    import cv2

    w, h = size
    lw, lh = max(4, w // GLOBAL_FACTOR), max(3, h // GLOBAL_FACTOR)
    cx, cy = projector_cells(size)
    xi, yi = np.meshgrid(np.arange(cx), np.arange(cy))
    classes = (yi % N_CLASS) * N_CLASS + (xi % N_CLASS)
    n = N_CLASS * N_CLASS
    direct = np.zeros((n, h, w))
    glob = np.zeros((n, h, w))
    for g0 in range(0, n, 3):
        tex = np.zeros((cy, cx, 3), np.float32)
        members = list(range(g0, min(g0 + 3, n)))
        for ch, c in enumerate(members):
            tex[..., ch] = classes == c
        d_hi = _render(size, tex, depth=2, spp=spp_direct, mirror=mirror, seed=seed + 1)
        f_lo = _render((lw, lh), tex, depth=-1, spp=spp_global, mirror=mirror, seed=seed + 2)
        d_lo = _render((lw, lh), tex, depth=2, spp=spp_global, mirror=mirror, seed=seed + 2)
        g_lo = np.maximum(f_lo - d_lo, 0.0)  # same seed: the difference is >= 0 up to rounding
        g_hi = cv2.resize(g_lo, (w, h), interpolation=cv2.INTER_LINEAR)
        for ch, c in enumerate(members):
            direct[c] = d_hi[..., ch]
            glob[c] = g_hi[..., ch]
    return direct, glob


def pattern_sets(cells, *, alpha: float):
    """The pattern sets the scene captures, at projector-cell resolution."""
    from lumigraph.capture import patterns as pt

    sets = {}
    if abs(alpha - 0.5) < 1e-9:
        sets["checker"] = pt.checker_set(cells, square=N_CLASS // 2, shifts=N_CLASS // 2)
    else:
        sets["checker"] = pt.block_set(cells, alpha=alpha, tile=N_CLASS)
    sets["sinusoid"] = pt.sinusoid_set(cells, period=N_CLASS)
    sets["single"] = pt.stripe_set(cells, period=N_CLASS)
    sets["occluder"] = pt.occluder_set(cells, period=N_CLASS, width=1)
    sets["flat"] = pt.flat_set(cells)
    return sets


def compose(direct, glob, pattern, *, b):
    """Image of ``pattern`` (projector cells) from the class renders, black level ``b``."""
    from lumigraph.capture.patterns import cell_weights, emitted

    wts = cell_weights(emitted(pattern, b=b), cell=1, period_cells=N_CLASS).ravel()
    return np.tensordot(wts, direct + glob, axes=1)


def render_projector(*, size, seed, rng, alpha=0.5, b=0.0, mirror=False, bit_depth=16,
                     full_well=0.0, read_noise=0.0, spp=128, repeats=1):
    """Render every pattern stack of the projector scene plus exact direct/global truth.

    Parameters
    ----------
    size : (width, height)
        Camera image size.
    alpha : float in (0, 1)
        Lit fraction of the checker-method patterns (0.5: checkerboards and
        complements; otherwise shifted compact blocks).
    b : float in [0, 1)
        Projector black level: off pixels emit ``b`` times the on level.
    mirror : bool
        Add the near-mirror floor panel.
    bit_depth : int
        Camera bit depth (codes ``round(value·(2**bit_depth − 1))``, clipped).
    full_well : float
        Electrons at full scale for Poisson shot noise (0 = none).
    read_noise : float
        Gaussian read noise, standard deviation in codes (0 = none).
    spp : int
        Samples per pixel of the (low-resolution) global renders.
    repeats : int
        Frames captured per checker pattern (independent camera noise), as a
        video camera delivers; the checker set is repeated in its own order.
    """
    w, h = size
    direct_c, glob_c = class_renders(size, mirror=mirror, spp_global=spp, seed=seed)
    gt_direct = direct_c.sum(axis=0)
    gt_global = glob_c.sum(axis=0)
    gt_full = gt_direct + gt_global
    # Exposure: the 99.5th percentile of the all-white image at 80 % of full scale.
    gain = 0.8 / max(float(np.percentile(gt_full, 99.5)), 1e-12)
    cells = projector_cells(size)
    sets = pattern_sets(cells, alpha=alpha)
    top = 2 ** bit_depth - 1
    images, names, set_names = [], [], {}
    described = {m: ps.describe() for m, ps in sets.items()}
    if repeats > 1:
        ck = described["checker"]
        n_ck = len(ck["names"])
        ck["complement_of"] = [r * n_ck + j if j >= 0 else -1
                               for r in range(repeats) for j in ck["complement_of"]]
        ck["lit_fraction"] = ck["lit_fraction"] * repeats
        ck["names"] = [f"{nm}_r{r}" for r in range(repeats) for nm in ck["names"]]
        ck["repeats"] = repeats
    for method, ps in sets.items():
        set_names[method] = []
        reps = repeats if method == "checker" else 1
        frames = [(nm if reps == 1 else f"{nm}_r{r}", im)
                  for r in range(reps) for nm, im in zip(ps.names, ps.images, strict=True)]
        for name, pat in frames:
            value = gain * compose(direct_c, glob_c, pat, b=b)
            codes = value * top
            if full_well > 0:
                electrons = rng.poisson(np.clip(value, 0, None) * full_well)
                codes = electrons * (top / full_well)
            if read_noise > 0:
                codes = codes + rng.normal(0.0, read_noise, codes.shape)
            images.append(np.clip(np.round(codes), 0, top).astype(np.uint16 if bit_depth > 8 else np.uint8))
            names.append(f"{name}.png")
            set_names[method].append(f"{name}.png")
    mc = _mc_noise(size, mirror=mirror, seed=seed, spp=spp, glob=gt_global)
    sigma_codes = float(read_noise)
    gt = {
        "units": "linear, 1.0 = full-scale code (code = value * (2**bit_depth - 1))",
        "gain": gain,
        "alpha": sets["checker"].info.get("alpha", 0.5),
        "b": b,
        "mirror": mirror,
        "projector_cells": list(cells),
        "cell_period": N_CLASS,
        "max_depth_semantics": "Mitsuba volpath: max_depth counts scattering vertices after the "
                               "camera; 2 = direct only (one surface or medium scattering event "
                               "lit straight from the projector), -1 = unlimited",
        "direct": "render with max_depth=2 under the all-white projector",
        "global": "full (max_depth=-1) minus direct, same seed, under the all-white projector",
        "mc_noise": mc,
        "camera_noise": {"full_well_e": full_well, "read_noise_codes": sigma_codes,
                         "quantisation_codes": 1.0 / np.sqrt(12.0)},
        "patterns": described,
    }
    stack = {"bit_depth": bit_depth, "linear": True, "exposure_times_s": [1.0] * len(images),
             "sets": set_names, "black_level_b": b, "alpha": gt["alpha"],
             "projector_cells": list(cells),
             "patterns": described}
    arrays = {"direct": (gain * gt_direct).astype(np.float32),
              "global": (gain * gt_global).astype(np.float32),
              "full": (gain * gt_full).astype(np.float32)}
    return RenderedScene("projector", {}, tuple(images), tuple(names), stack, gt, arrays)


def _mc_noise(size, *, mirror, seed, spp, glob):
    """Monte Carlo noise of the global renders, measured.

    The per-pixel standard deviation of a global estimate at ``spp`` samples is
    estimated from two independent renders at ``spp/2`` each under the white
    projector (low resolution): ``σ ≈ |a − b| / 2`` (their mean has variance
    ``σ²_{spp/2}/2 = σ²_spp``). Reported relative to the mean global light.
    """
    w, h = size
    lw, lh = max(4, w // GLOBAL_FACTOR), max(3, h // GLOBAL_FACTOR)
    cx, cy = projector_cells(size)
    tex = np.ones((cy, cx, 3), np.float32)
    half = max(1, spp // 8)  # a cheaper probe; scaled to spp below (σ ∝ 1/sqrt(spp))
    gs = []
    for s in (seed + 101, seed + 202):
        f = _render((lw, lh), tex, depth=-1, spp=half, mirror=mirror, seed=s)[..., 0]
        d = _render((lw, lh), tex, depth=2, spp=half, mirror=mirror, seed=s)[..., 0]
        gs.append(f - d)
    sigma_half = np.abs(gs[0] - gs[1]) / np.sqrt(2.0)
    sigma = sigma_half * np.sqrt(half / spp)
    mean_g = float(np.mean(gs[0] + gs[1]) / 2.0)
    return {"global_spp": spp, "direct_spp": 8, "global_resolution": [lw, lh],
            "probe_spp": half,
            "relative_sigma_global": float(np.sqrt(np.mean(sigma ** 2)) / max(mean_g, 1e-12)),
            "note": "per-pixel Monte Carlo standard deviation of the global renders relative to "
                    "the mean global light; the pattern images and the ground truth share the "
                    "same renders, so this is the noise of the truth itself, not a mismatch "
                    "between stack and truth"}


SPECS = {
    "projector": SceneSpec(
        "projector", (128, 96),
        (Option("alpha", float, 0.5, "lit fraction of the checker-method patterns",
                low=0.0, high=1.0, open_low=True, open_high=True),
         Option("b", float, 0.0, "projector black level (off/on light ratio)",
                low=0.0, high=1.0, open_high=True),
         Option("mirror", bool, False, "add a near-mirror panel that throws the pattern onto a wall"),
         Option("bit_depth", int, 16, "camera bit depth", low=8, high=16),
         # (numpy's Poisson sampler refuses means past ~1e19 electrons)
         Option("full_well", float, 0.0, "electrons at full scale for shot noise (0 = off)", low=0.0,
                high=1e9),
         Option("read_noise", float, 0.0, "Gaussian read noise in codes", low=0.0, high=1e6),
         Option("spp", int, 128, "samples per pixel of the global renders", low=4, high=4096),
         Option("repeats", int, 1, "frames per checker pattern (independent noise)", low=1, high=16)),
        version=VERSION, min_size=(32, 24)),
}
