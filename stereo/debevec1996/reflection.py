"""A reflection layer at infinity for view-dependent texture mapping: the
view-dependent part of a glossy plane's appearance, estimated from the
photographs and re-rendered for the new view.

VDTM (:mod:`~lumigraph.stereo.debevec1996.vdtm`) blends what the
photographs saw at a surface point. Where a glossy surface reflects a
distant environment, the colour it shows changes with the viewing direction
and no blend of the photographs' colours at that point is the new view's:
at the ends of an arc of photographs it cannot even beat the nearest
photograph (``docs/decisions/facade-vdtm.md``, the oracle bound). Layered
image-based rendering separates what a surface shows into a part that stays
on the surface and a reflected part that moves with the view (S. N. Sinha,
J. Kopf, M. Goesele, D. Scharstein and R. Szeliski, "Image-Based Rendering
for Scenes with Reflections", SIGGRAPH 2012, doi:10.1145/2185520.2185596,
there with the reflection at a finite virtual depth). Here the reflection
is at infinity, the case of a sky or a far environment, and of a highlight
under a distant light:

    I_i(X) = D(X) + S_g(r(d_i(X), n_g))

``I_i(X)`` the colour photograph ``i`` shows at the surface point ``X``;
``D(X)`` the view-independent part; ``d_i(X)`` the unit viewing direction
from photograph ``i``'s centre to ``X``; ``r(d, n) = d − 2 (d·n) n`` its
mirror direction about the plane's normal ``n``; ``S_g`` one function of
direction per *orientation group* ``g`` (the planes of the model with one
normal share it: a distant environment and a distant light look the same
from every parallel plane). ``S_g`` is tabulated on a ``grid × grid``
bilinear grid over the mirror direction's two in-plane components
``(r·u, r·w) ∈ [−1, 1]²``.

Fit (:func:`fit_reflection_layer`): ``D`` is eliminated per texel (texels
of one photograph pixel's footprint over each plane, seen by two or more
photographs), so ``S_g`` comes from the differences between the photographs
at each texel: a sparse least-squares problem with a second-difference
(Laplacian) penalty ``λ`` on the grid, solved with robust reweighting
(Cauchy weights on each texel's residual: texture edges resampled
differently by each photograph, and relief the model lacks, are not
reflections). Only differences are observed, so ``S_g`` is known up to a
constant, which cancels in the correction below.

Model only what a scene needs: per group, ``λ`` and whether to use the
layer at all are chosen by leaving each photograph out in turn and
predicting its colours from the others (the blend's weights seen from its
centre), with and without the layer's correction; the layer is used only
where it predicts held-out photographs better, and every candidate's score
is kept (``ReflectionLayer.groups[k].scores``). A matte plane, or one that
only two photographs see from far apart (where the differences do not
determine ``S_g``), keeps the plain blend.

Where on a plane the layer applies (the gate ``γ(X)``): one ``S_g`` is
wrong for a second material on the plane (a window's glass reflects four
times what the brick around it does, and its highlight is narrower), and
moving its samples by the brick's layer is worse than not moving them. So
per texel, summed over its ``(2 r + 1)²`` neighbourhood on the plane
(:data:`GATE_RADIUS`), the layer's residual sum of squares is compared with
the sum of squares of the photographs' differences without it: ``γ = 1``
where the layer leaves less, ``0`` where it leaves more, ``1`` where no
texel near was seen twice. The held-out test scores the gated layer (each
fold's gate from that fold's fit).

Render (``render_vdtm(..., reflection=layer)``): each photograph's sample
is moved to the new view before the blend,

    c_i(X) + γ(X) [S_g(r(d, n_g)) − S_g(r(d_i(X), n_g))]

with ``d`` the new view's direction at ``X``.

Limits: one layer per orientation (a second material keeps the plain blend
where the gate finds it, rather than a layer of its own); planar surfaces;
the reflected world at infinity (a nearby reflected object has parallax
this model lacks); a highlight that falls between the directions the
photographs saw is smoothed over, not recovered.

Examples
--------
A matte plane (a texture and nothing that moves with the view): the
held-out test keeps the plain blend, and says so.

>>> import numpy as np
>>> from lumigraph.stereo.debevec1996.vdtm import Photograph
>>> from lumigraph.stereo.debevec1996.reflection import fit_reflection_layer
>>> K = np.array([[40.0, 0, 23.5], [0, 40.0, 17.5], [0, 0, 1]])
>>> quad = (np.array([[-2.0, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]),
...         np.array([[0, 1, 2], [0, 2, 3]]))
>>> def camera(x):  # at (x, 0, 6) looking down at the plane z = 0
...     R = np.diag([1.0, -1, -1]); return R, -R @ np.array([x, 0, 6.0])
>>> yy, xx = np.mgrid[0:36, 0:48]
>>> def photo(x):  # the texture 100 + 40 sin(X) cos(Y) seen from x
...     R, t = camera(x); X = (np.stack([xx - 23.5, yy - 17.5], -1) / 40) * 6
...     Xw = X * [1, -1] + [x, 0]
...     return Photograph((100 + 40 * np.sin(Xw[..., 0]) * np.cos(Xw[..., 1]))[..., None], K, R, t)
>>> layer = fit_reflection_layer(quad, [photo(x) for x in (-1.0, 0.0, 1.0)], grid=8)
>>> [(g.used, g.held_out > 0, bool(np.allclose(g.normal, [0, 0, 1]))) for g in layer.groups]
[(False, True, True)]
>>> sorted(layer.groups[0].scores)[:2]
['fading lambda=1', 'fading lambda=10']
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lumigraph.capture.errors import InputError

DEFAULT_LAMBDAS = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0)
# the smoothness prior's behaviour beyond the directions seen (:func:`_laplacian`)
BORDERS = ("fading", "linear")
# a candidate replaces a simpler one (none; the fading prior) only when its held-out
# squared errors are lower by more than this many standard errors of the difference
SIGNIFICANCE = 3.0
DEFAULT_GRID = 48
ROBUST_ITERATIONS = 3
# texels per orientation group at most (a finer footprint is coarsened to this)
MAX_TEXELS = 250_000
# texel size in photograph pixels at the model: the layer is smooth, and texels
# finer than the photographs' samples add cost, not information
TEXEL_PIXELS = 1.5
# the gate (:func:`_gate`): the layer applies only where, over a (2 r + 1)² texel
# neighbourhood, it explains the photographs' differences better than none
GATE = True
GATE_RADIUS = 2


@dataclass(frozen=True)
class ReflectionGroup:
    """One orientation group's layer.

    ``normal``, ``u``, ``w`` (3,) the plane's unit normal and in-plane axes
    (world); ``planes`` the model planes (``vdtm._face_planes`` indices) in
    the group; ``layer`` (grid², C) ``S_g`` on the grid (code values of the
    photographs, up to a constant); ``used`` whether the held-out test chose
    it; ``lam`` the chosen Laplacian weight and ``border`` its behaviour
    beyond the directions seen (:func:`_laplacian`); ``scores`` the held-out
    mean squared error per channel of every candidate (``"none"``,
    ``"fading lambda=…"``, ``"linear lambda=…"``)
    over ``held_out`` samples; ``texels`` how many texels the fit saw,
    ``multi_view`` how many two or more photographs saw; ``gate`` per plane
    ``(k, s_first, q_first, γ)``, the gate (:func:`_gate`) on the plane's
    texel grid (``()``: the layer applies everywhere), ``texel`` that
    grid's spacing (world units), ``gated_off`` the share of the texels
    where the gate is 0.
    """

    normal: np.ndarray
    u: np.ndarray
    w: np.ndarray
    planes: tuple
    layer: np.ndarray
    used: bool
    lam: float
    border: str
    scores: dict
    held_out: int
    texels: int
    multi_view: int
    gate: tuple = ()
    texel: float = 0.0
    gated_off: float = 0.0


@dataclass(frozen=True)
class ReflectionLayer:
    """The reflection layer of a model seen by its photographs
    (:func:`fit_reflection_layer`): ``groups``, ``plane_group`` (P,) the
    group of each model plane, ``face_plane`` (M,) the plane of each
    triangle, ``grid``, ``texel`` (the texel size, world units)."""

    groups: tuple
    plane_group: np.ndarray
    face_plane: np.ndarray
    grid: int
    texel: float

    def summary(self) -> list[dict]:
        """One JSON-ready dict per group: normal, used, λ, scores."""
        return [{"normal": [round(float(x), 6) for x in g.normal], "used": bool(g.used),
                 "lambda": float(g.lam), "border": g.border, "held_out_samples": int(g.held_out),
                 "gated_off_fraction": round(float(g.gated_off), 4), "chosen": _key(g),
                 "texels": int(g.texels), "multi_view_texels": int(g.multi_view),
                 "held_out_mse": {k: round(float(v), 4) for k, v in g.scores.items()}}
                for g in self.groups]


def _key(g):
    """The score key of the group's chosen candidate (``"none"`` when unused)."""
    return f"{g.border} lambda={g.lam:g}" if g.used else "none"


def _frame(n):
    ref = np.array([0, 0, 1.0]) if abs(n[2]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(ref, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def _mirror_coords(d, n, u, w):
    """The mirror direction of the unit directions ``d (N, 3)`` about the
    plane ``n``, as its components along ``u`` and ``w`` (N, 2) in [−1, 1]."""
    r = d - 2 * (d @ n)[:, None] * n
    return np.stack([r @ u, r @ w], 1)


def _design(c, grid):
    """Sparse (N, grid²) bilinear weights of the coordinates ``c (N, 2)``."""
    import scipy.sparse as sp

    x = np.clip((c[:, 0] + 1) / 2 * (grid - 1), 0, grid - 1 - 1e-9)
    y = np.clip((c[:, 1] + 1) / 2 * (grid - 1), 0, grid - 1 - 1e-9)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    idx = np.stack([y0 * grid + x0, y0 * grid + x0 + 1, (y0 + 1) * grid + x0,
                    (y0 + 1) * grid + x0 + 1], 1)
    wt = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
    return sp.csr_matrix((wt.ravel(), (np.repeat(np.arange(len(c)), 4), idx.ravel())),
                         shape=(len(c), grid * grid))


def _laplacian(grid, border):
    """Second differences on the grid's rows and columns. ``border="linear"``:
    the interior nodes only, zero on every linear function, so the layer
    extends linearly beyond the directions the photographs saw;
    ``"fading"``: also at the border nodes against a zero outside the grid,
    so beyond what was seen the layer levels off towards a constant."""
    import scipy.sparse as sp

    eye = sp.identity(grid)
    if border == "linear":
        d2 = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(grid - 2, grid))
    else:
        d2 = sp.diags([1.0, -2.0, 1.0], [-1, 0, 1], shape=(grid, grid))
    return sp.vstack([sp.kron(eye, d2), sp.kron(d2, eye)]).tocsr()


class _Centred:
    """The fit's data with each texel's mean removed (texels seen twice or
    more): the centred bilinear design ``Bm − M[tm]`` (rows, G), kept as
    ``Bm`` (the rows' bilinear design) and ``M`` (T, G) (each texel's mean
    row) with their transposes (CSR); ``rhs`` (rows, C) the centred
    colours, ``tm`` (rows,) each row's texel, ``cnt`` (T,) each texel's samples, ``res_none`` (T,)
    each texel's sum of squares without a layer (Σ |ΔI|²). Built once for
    a set of rows and shared by every candidate's solve on them."""

    def __init__(self, B, obs, tex, n_tex):
        import scipy.sparse as sp

        self.cnt = np.bincount(tex, minlength=n_tex)
        self.n_tex, self.G, self.C = n_tex, B.shape[1], obs.shape[1]
        rows = np.flatnonzero(self.cnt[tex] >= 2)
        self.tm = tex[rows]
        inv = 1.0 / np.maximum(self.cnt, 1)
        mean = sp.csr_matrix((inv[self.tm], (self.tm, np.arange(len(rows)))),
                             shape=(n_tex, len(rows)))
        # the centred design Ac = Bm − M[tm] is never formed: a row of it has
        # the bilinear taps of every sample of its texel (4 × count), so its
        # normal matrix costs count² times that of the plain design; with one
        # weight per texel, Acᵀ W Ac = Bmᵀ W Bm − Mᵀ diag(w · count) M
        self.Bm = B[rows].tocsr()
        self.BmT = self.Bm.T.tocsr()
        self.M = (mean @ self.Bm).tocsr()
        self.MT = self.M.T.tocsr()
        self.rhs = obs[rows] - (mean @ obs[rows])[self.tm]
        self.res_none = np.bincount(self.tm, (self.rhs ** 2).sum(1), minlength=n_tex)


def _solve(cen, lap2, lam, weight):
    """``S`` (G, C) minimising Σ weight_t |ΔI − ΔS|² + λ (rows/G) |L S|²
    over the centred data ``cen`` (:class:`_Centred`); also per texel the
    residual sum of squares, the count of samples and the sum of squares
    without the layer."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl

    G = cen.G
    if not len(cen.tm):
        return np.zeros((G, cen.C)), np.zeros(cen.n_tex), cen.cnt, cen.res_none
    wr = weight[cen.tm]
    AtWA = (cen.BmT.multiply(wr[None, :]).tocsr() @ cen.Bm
            - cen.MT.multiply((weight * cen.cnt)[None, :]).tocsr() @ cen.M)
    A = (AtWA + lam * (float(wr.sum()) / G) * lap2 + 1e-6 * sp.identity(G)).tocsc()
    # A is symmetric positive definite: a symmetric ordering, no pivoting;
    # Acᵀ W rhs = Bmᵀ W rhs, as each texel's centred colours sum to zero
    S = spl.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                 options={"SymmetricMode": True}).solve(np.asarray(cen.BmT @ (wr[:, None] * cen.rhs)))
    r = cen.rhs - (cen.Bm @ S - (cen.M @ S)[cen.tm])
    return S, np.bincount(cen.tm, (r ** 2).sum(1), minlength=cen.n_tex), cen.cnt, cen.res_none


def _robust_solve(cen, lap2, lam, iterations):
    """:func:`_solve` reweighted ``iterations`` times: Cauchy weights on each
    texel's RMS residual, scale 2.385 × the MAD-based σ of the residuals.
    Returns ``(S, weight, res, res_none)``: the weights of the last solve,
    and its residual sums of squares per texel with and without the layer."""
    weight = np.ones(cen.n_tex)
    for it in range(iterations + 1):
        S, res, cnt, res_none = _solve(cen, lap2, lam, weight)
        if it == iterations:
            break
        ok = cnt >= 2
        if not ok.any():
            break
        rt = np.sqrt(res / np.maximum(cnt - 1, 1) / cen.C)
        c = max(2.385 * 1.4826 * float(np.median(rt[ok])), 1e-9)
        weight = 1.0 / (1.0 + (rt / c) ** 2)
    return S, weight, res, res_none


def _texels(v, f, face_plane, planes, members, n, u, w, size):
    """Texel centres (T, 3) on the polygons of the planes ``members``, and
    their layout: per plane ``(k, s_first, q_first, index)``, ``index``
    (rows along ``w``, columns along ``u``) the texel of each cell of the
    plane's texel grid (−1 off its polygons)."""
    out, layout, base = [], [], 0
    for k in members:
        tri = v[f[face_plane == k]]
        s, q = tri @ u, tri @ w
        ss = np.arange(s.min() + size / 2, s.max(), size)
        qq = np.arange(q.min() + size / 2, q.max(), size)
        S_, Q_ = np.meshgrid(ss, qq)
        px, py = S_.ravel(), Q_.ravel()
        inside = np.zeros(len(px), bool)
        for a, b, c in np.stack([s, q], 2):  # each triangle's three corners (s, q)
            e = [(p1[0] - p0[0]) * (py - p0[1]) - (p1[1] - p0[1]) * (px - p0[0])
                 for p0, p1 in ((a, b), (b, c), (c, a))]
            inside |= (((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0))
                       | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0)))
        index = np.full(len(px), -1, np.int64)
        index[inside] = base + np.arange(int(inside.sum()))
        base += int(inside.sum())
        if len(ss) and len(qq):
            layout.append((int(k), float(ss[0]), float(qq[0]), index.reshape(S_.shape)))
        out.append(planes[k, 3] * n + px[inside, None] * u + py[inside, None] * w)
    return (np.concatenate(out) if out else np.zeros((0, 3))), layout


def _gate(res, res_none, layout, radius):
    """Where the layer applies, per texel (T,) and per plane's texel grid:
    1 where, summed over the texel's ``(2 radius + 1)²`` neighbourhood on its
    plane, the layer leaves less of the photographs' differences than no
    layer does (``res < res_none``), 0 where it leaves more (a material that
    reflects differently from the one the layer fits: glass in a brick
    wall), 1 where no texel near was seen twice (nothing to tell)."""
    from scipy.ndimage import uniform_filter

    g = np.ones(len(res))
    grids = []
    for k, s0, q0, index in layout:
        inside = index >= 0
        a = np.zeros(index.shape)
        b = np.zeros(index.shape)
        a[inside] = res[index[inside]]
        b[inside] = res_none[index[inside]]
        size = 2 * radius + 1
        # which neighbourhoods hold a texel seen twice, counted, not read off
        # the sums: a running-sum filter leaves round-off (~1e-16 of the sums
        # nearby) where every term is 0, and a test on that residue is noise
        near = uniform_filter((b > 0).astype(np.float64), size, mode="constant") * size**2 > 0.5
        a = uniform_filter(a, size, mode="constant")
        b = uniform_filter(b, size, mode="constant")
        gk = np.where(near, (a < b).astype(np.float64), 1.0)
        g[index[inside]] = gk[inside]
        grids.append((k, s0, q0, gk.astype(np.float32)))
    return g, tuple(grids)


def _gate_at(group, X, plane):
    """The group's gate at the points ``X (N, 3)`` on the planes ``plane (N,)``
    (the nearest cell of the plane's texel grid; 1 without a gate)."""
    out = np.ones(len(X))
    for k, s0, q0, gk in group.gate:
        at = np.flatnonzero(plane == k)
        if not len(at):
            continue
        i = np.clip(np.rint((X[at] @ group.u - s0) / group.texel).astype(np.int64), 0, gk.shape[1] - 1)
        j = np.clip(np.rint((X[at] @ group.w - q0) / group.texel).astype(np.int64), 0, gk.shape[0] - 1)
        out[at] = gk[j, i]
    return out


def _held_out(k, tex, crd, obs, cam, X, photos, S, grid, power, neighbours, gate=None):
    """Photograph ``k``'s samples predicted from the others' (the blend's
    weights seen from its centre), without and with the layer: the squared
    errors of the samples the others see, summed over the channels."""
    from lumigraph.stereo.debevec1996.vdtm import _angle_to, _unit, _weights

    mine = cam == k
    tk = tex[mine]
    if not len(tk):
        return np.zeros(0), np.zeros(0)
    others = [j for j in np.unique(cam) if j != k]
    if not others:
        return np.zeros(0), np.zeros(0)
    ray = _unit(X[tk] - photos[k].centre)
    theta = np.full((len(others), len(tk)), np.inf)
    C = obs.shape[1]
    samp = np.zeros((len(others), len(tk), C))
    cj = np.zeros((len(others), len(tk), 2))
    lut = np.full(len(X), -1)
    for a, j in enumerate(others):
        sel = np.flatnonzero(cam == j)
        lut[:] = -1
        lut[tex[sel]] = sel
        r = lut[tk]
        ok = r >= 0
        samp[a, ok] = obs[r[ok]]
        cj[a, ok] = crd[r[ok]]
        theta[a, ok] = _angle_to(ray[ok], X[tk[ok]], photos[j].centre)
    W = _weights(theta, power, neighbours)
    ws = W.sum(0)
    good = ws > 0
    if not good.any():
        return np.zeros(0), np.zeros(0)
    none = (W[..., None] * samp).sum(0)[good] / ws[good, None]
    Sk = _design(crd[mine], grid) @ S
    corr = np.stack([Sk - _design(cj[a], grid) @ S for a in range(len(others))])
    if gate is not None:
        corr *= gate[tk][None, :, None]
    lay = none + (W[..., None] * corr).sum(0)[good] / ws[good, None]
    truth = obs[mine][good]
    return ((none - truth) ** 2).sum(1), ((lay - truth) ** 2).sum(1)


def _clearly_better(a, b):
    """Whether the squared errors ``a`` (n,) are below ``b``'s (the same
    samples) by more than :data:`SIGNIFICANCE` standard errors of the mean
    difference."""
    if len(a) < 2:
        return False
    d = b - a
    return bool(d.mean() > SIGNIFICANCE * d.std() / math.sqrt(len(d)))


def _texel_size(photos, v):
    """:data:`TEXEL_PIXELS` photograph pixels' footprint at the model: the
    median over the photographs of their median model depth over their
    focal length, times that."""
    sizes = []
    for p in photos:
        d = p.depth[np.isfinite(p.depth)]
        if len(d):
            sizes.append(float(np.median(d)) / float(np.sqrt(abs(np.linalg.det(
                np.asarray(p.K, np.float64)[:2, :2])))) * TEXEL_PIXELS)
    if not sizes:
        return float(np.ptp(v, axis=0).max()) / 256
    return float(np.median(sizes))


def fit_reflection_layer(mesh, photographs, *, tolerance: float = 0.01,
                         lambdas=DEFAULT_LAMBDAS, grid: int = DEFAULT_GRID,
                         texel: float | None = None,
                         robust_iterations: int = ROBUST_ITERATIONS,
                         power: float | None = None,
                         neighbours: int | None = None, progress=None) -> ReflectionLayer:
    """Fit the reflection layer of ``mesh`` from its posed ``photographs``
    (module docstring).

    Parameters
    ----------
    mesh : ``(vertices, faces)`` or an object with ``vertices``/``faces``
        World coordinates.
    photographs : sequence of Photograph
        As :func:`~lumigraph.stereo.debevec1996.vdtm.prepare_photographs`
        returns them (prepared here when they have no depth maps).
    tolerance : float
        Visibility, as :func:`~lumigraph.stereo.debevec1996.vdtm.render_vdtm`'s.
    lambdas : sequence of float
        Candidate Laplacian weights (relative to the data's weight per grid
        cell); each group takes the one that best predicts held-out
        photographs.
    grid : int
        The layer's grid is ``grid × grid`` over the mirror direction.
    texel : float, optional
        Texel size (world units); default :data:`TEXEL_PIXELS` photograph
        pixels' footprint at the model (:func:`_texel_size`).
    robust_iterations : int
        Reweighting rounds of the robust fit (0: plain least squares).
    power, neighbours : optional
        The blend's weights in the held-out test (default the blend's).
    progress : callable, optional
        Wraps the loop over the orientation groups (``progress(iterable)``,
        one step a group: the fit takes seconds to a minute), e.g.
        :func:`~lumigraph.capture.commandline.progress`.

    Returns
    -------
    ReflectionLayer
    """
    from lumigraph.stereo.debevec1996.vdtm import (
        DEFAULT_NEIGHBOURS,
        DEFAULT_POWER,
        _face_planes,
        _mesh_and_photographs,
        _sample,
        _unit,
    )

    lambdas = tuple(float(x) for x in lambdas)
    if not lambdas or not all(math.isfinite(x) and x > 0 for x in lambdas):
        raise InputError("lambdas", f"expected positive weights, got {lambdas!r}")
    if isinstance(grid, bool) or not isinstance(grid, (int, np.integer)) or not 4 <= grid <= 512:
        raise InputError("grid", f"expected a whole number in [4, 512], got {grid!r}")
    if texel is not None and not (math.isfinite(texel) and texel > 0):
        raise InputError("texel", f"expected a positive size, got {texel!r}")
    power = DEFAULT_POWER if power is None else float(power)
    neighbours = DEFAULT_NEIGHBOURS if neighbours is None else int(neighbours)
    v, f, photos, C = _mesh_and_photographs(mesh, photographs, tolerance)
    face_plane, planes = _face_planes(v, f)
    # orientation groups: the planes with one normal
    normals: list = []
    plane_group = np.full(len(planes), -1, np.int64)
    for k, pl in enumerate(planes):
        for gi, n in enumerate(normals):
            if n @ pl[:3] > 1 - 1e-6:
                plane_group[k] = gi
                break
        else:
            plane_group[k] = len(normals)
            normals.append(pl[:3].copy())
    size = _texel_size(photos, v) if texel is None else float(texel)
    laps = {b: (lambda L: (L.T @ L).tocsr())(_laplacian(grid, b)) for b in BORDERS}
    cands = [(b, lam) for b in BORDERS for lam in lambdas]
    groups = []
    steps = list(enumerate(normals))
    for gi, n in (steps if progress is None else progress(steps)):
        u, w = _frame(n)
        members = tuple(int(k) for k in np.flatnonzero(plane_group == gi))
        gsize = size
        X, layout = _texels(v, f, face_plane, planes, members, n, u, w, gsize)
        while len(X) > MAX_TEXELS:
            gsize *= math.sqrt(len(X) / MAX_TEXELS) * 1.01
            X, layout = _texels(v, f, face_plane, planes, members, n, u, w, gsize)
        tex, crd, obs, cam = [], [], [], []
        for j, p in enumerate(photos):
            if not len(X):
                break
            s, ok = _sample(p, X, tolerance)
            d = _unit(X[ok] - p.centre)
            front = d @ n < 0  # a photograph behind the plane does not see it
            t_ = np.flatnonzero(ok)[front]
            tex.append(t_)
            crd.append(_mirror_coords(d[front], n, u, w))
            obs.append(s[ok][front].astype(np.float64))
            cam.append(np.full(len(t_), j))
        if tex:
            tex, crd = np.concatenate(tex), np.concatenate(crd)
            obs, cam = np.concatenate(obs).reshape(-1, C), np.concatenate(cam)
        else:
            tex, crd = np.zeros(0, np.int64), np.zeros((0, 2))
            obs, cam = np.zeros((0, C)), np.zeros(0, np.int64)
        T = len(X)
        cnt = np.bincount(tex, minlength=T)
        B = _design(crd, grid)
        # the robust weights of the whole fit for each λ, kept for its held-out
        # folds (a texel's weight says whether it is a reflection, not which
        # photograph is out): one solve a fold
        whole = _Centred(B, obs, tex, T)
        fits = [_robust_solve(whole, laps[b], lam, robust_iterations) for b, lam in cands]
        e_none, e_cand = [], [[] for _ in cands]
        for k in np.unique(cam):
            keep = cam != k
            fold = _Centred(B[keep], obs[keep], tex[keep], T)
            for ci, (b, lam) in enumerate(cands):
                Sk, rk, _, nk = _solve(fold, laps[b], lam, fits[ci][1])
                gk = _gate(rk, nk, layout, GATE_RADIUS)[0] if GATE else None
                e0, e1 = _held_out(k, tex, crd, obs, cam, X, photos, Sk, grid, power, neighbours,
                                   gk)
                e_cand[ci].append(e1)
            e_none.append(e0)
        e_none = np.concatenate(e_none) if e_none else np.zeros(0)
        e_cand = [np.concatenate(e) if e else np.zeros(0) for e in e_cand]
        held = len(e_none)
        denom = max(held, 1) * C
        scores = {"none": float(e_none.sum()) / denom}
        scores.update({f"{b} lambda={lam:g}": float(e.sum()) / denom
                       for (b, lam), e in zip(cands, e_cand, strict=True)})

        # the simpler prior (BORDERS[0]) unless the other predicts clearly better;
        # the layer only where it predicts clearly better than none (a matte
        # plane's layer fits the sampling's noise and gains by chance)
        by = {b: min((ci for ci, c in enumerate(cands) if c[0] == b),
                     key=lambda ci: e_cand[ci].sum()) for b in BORDERS}
        best = by[BORDERS[0]]
        for b in BORDERS[1:]:
            if _clearly_better(e_cand[by[b]], e_cand[best]):
                best = by[b]
        used = _clearly_better(e_cand[best], e_none)
        border, lam = cands[best]
        S = fits[best][0] if used else np.zeros((grid * grid, C))
        gate, off = (), 0.0
        if used and GATE:
            per_texel, gate = _gate(fits[best][2], fits[best][3], layout, GATE_RADIUS)
            off = float((per_texel == 0).mean()) if len(per_texel) else 0.0
        groups.append(ReflectionGroup(n, u, w, members, S, used, lam, border, scores, held, T,
                                      int((cnt >= 2).sum()), gate, gsize, off))
    return ReflectionLayer(tuple(groups), plane_group, face_plane, int(grid), float(size))


def corrections(layer: ReflectionLayer, X, faces, C, photos, *, which=None):
    """``(N, C)`` per photograph: the layer's move of each photograph's
    sample at the points ``X (N, 3)`` (on the triangles ``faces (N,)``) to
    the view from ``C``: ``S_g(r(d)) − S_g(r(d_i))``; a list over ``photos``
    (None where no point of a used group is seen; ``which[i]`` (N,) bool
    restricts photograph ``i`` to the points it sees)."""
    from lumigraph.stereo.debevec1996.vdtm import _unit

    out = [None] * len(photos)
    g_of = layer.plane_group[layer.face_plane[faces]]
    ray = None
    for gi, g in enumerate(layer.groups):
        if not g.used:
            continue
        sel = np.flatnonzero(g_of == gi)
        if not len(sel):
            continue
        if ray is None:
            ray = _unit(X - C)
        new = _design(_mirror_coords(ray[sel], g.normal, g.u, g.w), layer.grid) @ g.layer
        gate = _gate_at(g, X[sel], layer.face_plane[faces[sel]])
        for i, p in enumerate(photos):
            at = sel if which is None else sel[which[i][sel]]
            if not len(at):
                continue
            m = np.searchsorted(sel, at)
            d = _unit(X[at] - p.centre)
            own = _design(_mirror_coords(d, g.normal, g.u, g.w), layer.grid) @ g.layer
            if out[i] is None:
                out[i] = np.zeros((len(X), g.layer.shape[1]))
            out[i][at] = (new[m] - own) * gate[m, None]
    return out
