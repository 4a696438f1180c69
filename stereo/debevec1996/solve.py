"""Photogrammetric modelling (Façade stage 1): block parameters and camera
poses from marked image edges.

P. E. Debevec, C. J. Taylor and J. Malik, "Modeling and Rendering
Architecture from Photographs", SIGGRAPH 1996, doi:10.1145/237170.237191;
C. J. Taylor and D. J. Kriegman, "Structure and motion from line segments in
multiple images", PAMI 17(11), 1995. Reference ch. 5, §5.3.2, eqs. 5.3–5.5.

**Objective (eq. 5.3).** A model edge (world endpoints ``X0, X1``, linear in
the block parameters ``θ``) projects through camera ``j`` (``x_cam = R_j X +
t_j``, intrinsics ``K_j``) to the image line ``l = K(R X0 + t) × K(R X1 +
t)``. A marked segment with endpoints ``p1, p2`` (length ``L`` px) is at
signed distances ``h1, h2`` from it; the distance varies linearly along the
segment, so the error integrated along it is in closed form

    Err = ∫₀ᴸ h(s)² ds = L/3 · (h1² + h1 h2 + h2²),

written as two residuals ``√(L/3) · (h1 + h2/2, √3/2 · h2)`` whose squares
add to ``Err``. A mark that carries its own noise (``spread_px``, the
scatter of the image's step along it, measured where the mark was snapped
onto the photograph) above ``noise_px`` has its residuals divided by
``rel = spread_px / noise_px``: weighted least squares, each mark's ends
counted by the inverse of their variance. The unknowns are the free block
parameters, a rotation (``R_j = exp([ω_j]×) R_j⁰``) and translation per
photograph and, optionally,
one focal-length scale shared by every photograph. The Jacobian is analytic
(the edge endpoints are linear in ``θ``, :meth:`BlockModel.edge_matrices`);
it is block-sparse (a mark touches its own photograph's six pose columns and
its block's parameters). ``scipy.optimize.least_squares`` gets it as a
``scipy.sparse`` matrix (trust region, LSMR steps) when it has more than 600
columns; below that it is assembled dense and the final solve is MINPACK's
Levenberg–Marquardt (QR steps: a ten-block, eight-photograph, 1200-segment
solve takes 0.6 s instead of 1.4 s with SVD trust-region steps).

**Initialisation (eqs. 5.4, 5.5).** Rotations first: a marked edge whose
model direction ``v`` is known (axis-aligned block edges) and its image
line's interpretation-plane normal ``n = Kᵀ l`` (camera frame) satisfy
``nᵀ R v = 0`` (eq. 5.4). With a rough rotation given, ``Σ (nᵀ R v)²`` is
minimised from it (Gauss–Newton); without one, the vanishing directions of
two axes (the null vectors of their stacked normals) give ``R`` up to signs,
the up axis pointing up in the image and the other sign chosen by the fit of
the next step. With the rotations fixed, each endpoint's constraint ``nᵀ (R
X(θ) + t) = 0`` is *linear* in ``θ`` and every ``t`` (eq. 5.5): one
least-squares solve gives all translations and parameters (rows rescaled by
the endpoint depths of a first solve, so they measure pixels).

**Robustness.** A first solve uses the ``soft_l1`` loss on the per-segment
RMS distance (scale ``3 · noise_px``); a mark whose RMS distance to its
projected edge exceeds ``5 ·`` the endpoint noise (``noise_px`` or the
marks' own robust spread, the larger) is reported as mis-marked and left out
of the final plain least-squares solve (eq. 5.3 as written).

**Uncertainty.** First order: with ``J`` the Jacobian of the weighted
residuals ``r = A h`` at the solution and the endpoint distances ``h``
independent with variance ``σ² rel²`` (``σ`` estimated from the residual
distances, ``σ̂² = Σ (h / rel)² / (2n − p)``), ``cov = σ̂² (JᵀJ)⁻¹ Jᵀ (rel A)
(rel A)ᵀ J (JᵀJ)⁻¹``. Where the marks mix hand marks and automatic marking's
proposals (``proposed``; at least ``VARIANCE_COMPONENTS_MIN_MARKS`` of each,
``separate_noise``), the two kinds' noise is estimated separately (Helmert's
variance components, :func:`group_variances`): each kind's
``rel`` is scaled by its noise relative to the hand marks' and the solve
repeated until the ratio settles (at most four times). ``σ̂`` is then the
hand marks' noise, ``sigma_px_by_kind`` holds both.

**Gauge.** The world frame is the model's (the root block stands centred on
the origin, axis-aligned); the scale comes from the fixed parameter(s): at
least one length must be fixed. Unconstrained unknowns (no mark constrains a
parameter, a photograph with too few marks) are found by a rank test of the
column-scaled Jacobian at the start and named in an :class:`EstimationError`
(:class:`Unconstrained`, which also carries the names). A rough solve
(``hold_unconstrained``) holds them instead: only the null directions, in
the parameters' own units (the unknowns become ``z`` with ``θ_free =
θ_start + B z``, ``B`` an orthonormal basis of the rest), so the
combination the marks do fix is solved; or, with ``"parameters"``, every
parameter such a direction moves.
A photograph with fewer than three marks (six constraints on its six pose
unknowns) is left out with a warning.

Examples
--------
>>> from lumigraph.stereo.debevec1996.edges import EdgeMarks
>>> from lumigraph.capture.scenes.facade_edges import ring_cameras, project_edges
>>> m = BlockModel.from_dict(FIXTURE)
>>> cams = ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700)
>>> marks = EdgeMarks.from_dict({"photographs": project_edges(m, cams)}, model=m,
...                             photographs=list(cams))
>>> start = m.with_values(m.values[~m.fixed] * 1.2)   # every free parameter 20 % off
>>> sol = solve_facade(start, marks, {p: c["K"] for p, c in cams.items()})
>>> err = max(abs(sol.params[n] - v) / v for n, v in m.named_values().items())
>>> bool(err < 1e-8), sol.outliers
(True, [])
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.stereo.debevec1996.model import BlockModel

_A0 = np.array([[1.0, 0.5], [0.0, np.sqrt(3.0) / 2.0]])  # h -> residuals: rᵀr = h1² + h1h2 + h2²
MIN_MARKS = 3
DENSE_MAX_COLUMNS = 600  # above: a sparse Jacobian and LSMR trust-region steps

FIXTURE = {"blocks": [
    {"name": "house", "kind": "box",
     "params": {"width": {"value": 10.0, "fixed": True}, "depth": 6.0, "height": 6.0}},
    {"name": "roof", "kind": "wedge", "parent": "house",
     "params": {"width": {"same_as": "house/width"}, "depth": {"same_as": "house/depth"},
                "height": 2.5}},
    {"name": "tower", "kind": "box", "parent": "house", "on": "base", "x": "offset", "y": "front",
     "params": {"width": 3.0, "depth": {"same_as": "tower/width"}, "height": 9.0,
                "offset_x": 6.5}}]}


class Unconstrained(EstimationError):
    """The solver's refusal when no combination of the marks constrains some
    unknowns (the rank test of the column-scaled Jacobian at the start, and
    again at the solution):
    an :class:`EstimationError` (exit 2 on the command line) that also
    carries the unknowns' names, ``unknowns`` (parameter names as the
    model's slots, ``"<photo>:position"`` / ``"<photo>:rotation"`` for a
    pose, ``"focal_scale"``), so a caller can say what would constrain each
    (:func:`lumigraph.stereo.debevec1996.automark.unconstrained_spots`; the
    command line puts that list in ``details``).

    >>> str(Unconstrained("edges.json", ("tower/height",))).split(":")[:2]
    ['edges.json', ' the marks do not constrain tower/height']
    """

    def __init__(self, where, unknowns, *, details=(), at_solution=False):
        self.unknowns = tuple(unknowns)
        self.at_solution = bool(at_solution)
        super().__init__(where, "the marks do not constrain " + ", ".join(self.unknowns)
                         + (" at the solution the solve reached (the start's test passed)"
                            if at_solution else "")
                         + ": mark more edges of those blocks / photographs, share or fix "
                           "those parameters", details=details)


class CannotSeeMarks(EstimationError):
    """The solver's refusal when a solved camera sits on the line of one of
    its marked edges: the edge projects to a point there, eq. 5.3's
    projected line is undefined, and a solve can end on it with small
    residuals (a camera 20 m off on the corner where two of its marked
    edges meet, seed 226 of the marking eval). ``photos`` names them,
    ``edges`` maps each to ``(edge, why)``.

    >>> CannotSeeMarks("edges.json", {"photo_03.png": ("house/top-front", "x")}).photos
    ('photo_03.png',)
    """

    def __init__(self, where, edges):
        self.edges = dict(edges)
        self.photos = tuple(self.edges)
        super().__init__(where, "; ".join(
            f"the solved camera of {p!r} cannot see its mark of {e!r} ({why})"
            for p, (e, why) in self.edges.items())
            + ": a wrong pose that fits the marks; mark edges in other directions on that "
              "photograph, or give a rough pose")


class NoRotationStart(EstimationError):
    """The solver's refusal when a photograph's marks cannot start its
    rotation (eq. 5.4 needs two edges along each of two of the model's axes)
    and no rough rotation was given for it: an :class:`EstimationError`
    that also names the photograph, ``photo``, so a caller holding a rough
    pose for it (a previous solve) can give it and solve again.

    >>> NoRotationStart("edges.json", "photo_01.png").photo
    'photo_01.png'
    """

    def __init__(self, where, photo):
        self.photo = photo
        super().__init__(where, f"photograph {photo!r}: cannot initialise its rotation (mark at "
                                "least two edges along each of two of the model's axes, or give "
                                "a rough pose)")


@dataclass(frozen=True)
class FacadeSolution:
    """The fitted model and cameras.

    model : BlockModel with the fitted values; params / std : every
    parameter name -> value / first-order standard deviation (0 for a fixed
    one); poses : photo -> (R (3, 3), t (3,)) with ``x_cam = R x + t``;
    pose_std : photo -> {"rotation_rad" (3,), "t" (3,), "centre" (3,)};
    focal_scale, focal_scale_std : the shared focal-length factor (1, 0
    when not fitted); K : photo -> the (fitted) intrinsics; outliers : the
    marks left out as mis-marked, ``(photo, edge, rms distance px)``;
    dropped : photographs left out; mark_rms_px : one RMS distance per kept
    mark, ``(photo, edge, px)``; sigma_px : the estimated endpoint noise (of
    the hand marks, where each kind's is estimated); sigma_px_by_kind :
    ``{"hand": px, "proposed": px}`` where each kind's noise was estimated
    (``separate_noise``), else empty;
    rms_px : RMS distance over the kept marks; covariance / unknowns : of
    the final solve; warnings; seconds; noise_px : the solve's endpoint
    noise (a mark's ``spread_px`` above it weighs the mark down)."""

    model: BlockModel
    params: dict
    std: dict
    poses: dict
    pose_std: dict
    focal_scale: float
    focal_scale_std: float
    K: dict
    outliers: list
    dropped: list
    mark_rms_px: list
    sigma_px: float
    rms_px: float
    covariance: np.ndarray = field(repr=False)
    unknowns: tuple = field(repr=False)
    warnings: list = field(default_factory=list)
    seconds: float = 0.0
    nfev: int = 0
    held: tuple = ()
    noise_px: float = 1.0
    sigma_px_by_kind: dict = field(default_factory=dict)

    @property
    def centres(self) -> dict:
        """photo -> camera centre ``-Rᵀ t`` (world)."""
        return {p: -R.T @ t for p, (R, t) in self.poses.items()}


def _skew(v):
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def _right_jacobian(w):
    """The right Jacobian of SO(3) at rotation vectors ``w`` (C, 3)."""
    th = np.linalg.norm(w, axis=-1)[:, None, None]
    W = _skew(w)
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5, (1 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0, (ths - np.sin(ths)) / ths**3)
    return np.eye(3)[None] - a * W + b * (W @ W)


class _Problem:
    """The marks of the kept photographs as arrays, and the residual /
    Jacobian of eq. 5.3 over ``x = [θ_free, (ω, t) per photo, focal scale]``."""

    def __init__(self, model, marks, photos, K, R0, *, free_focal, noise_px=None,
                 separate_noise=False, hold_along=None):
        self.model, self.photos, self.free_focal = model, list(photos), free_focal
        pi = {p: i for i, p in enumerate(self.photos)}
        self.marks = marks
        self.cam = np.array([pi[m.photo] for m in marks], int)
        self.seg = np.array([m.segment for m in marks], float).reshape(-1, 4)
        self.C0, self.C1 = model.edge_matrices([m.edge for m in marks])
        self.free = ~model.fixed
        self.Cf = (self.C0[:, :, self.free], self.C1[:, :, self.free])
        self.base = model.values
        self.Px = int(self.free.sum())
        # directions of the free parameters held at the model's values
        # (``hold_along``, slot-space rows): the unknowns are then ``z`` with
        # θ_free = base_free + B z, B an orthonormal basis of the rest
        self.B, self.hold_along = None, hold_along
        if hold_along is not None and len(hold_along):
            A = np.asarray(hold_along, float)[:, self.free]
            _, s, Vt = np.linalg.svd(A, full_matrices=True)
            r = int((s > 1e-9 * max(float(s[0]), 1e-300)).sum()) if s.size else 0
            if r:
                self.B = Vt[r:].T
        self.P = self.Px if self.B is None else self.B.shape[1]
        # θ = off + E z over every slot: the fixed slots (and, where
        # directions are held, the free ones' base) plus the unknowns' span
        self.E = np.zeros((len(self.base), self.P))
        self.E[self.free] = np.eye(self.P) if self.B is None else self.B
        self.off = np.where(self.free, 0.0, self.base) if self.B is None else self.base.copy()
        self.nc = len(self.photos)
        self.K0 = np.array([K[p] for p in self.photos], float)
        self.R0 = np.array(R0, float)
        self.n = len(marks)
        self.ncol = self.P + 6 * self.nc + (1 if free_focal else 0)
        self.ncol_x = self.Px + 6 * self.nc + (1 if free_focal else 0)
        self.length = np.hypot(self.seg[:, 2] - self.seg[:, 0], self.seg[:, 3] - self.seg[:, 1])
        # each mark's endpoint noise relative to noise_px: the larger of it and
        # the image's own scatter along the mark (Mark.spread_px), where measured
        self.rel = np.ones(self.n)
        self.noise_px = noise_px
        self.separate_noise = separate_noise
        self.proposed = np.array([bool(getattr(m, "proposed", False)) for m in marks], bool)
        if noise_px is not None:
            self.rel = np.array([max(1.0, (getattr(m, "spread_px", None) or 0.0) / noise_px)
                                 for m in marks], float).reshape(self.n)

    def theta(self, z):
        """All slot values from the parameter unknowns ``z`` (P,)."""
        th = self.base.copy()
        th[self.free] = z if self.B is None else self.base[self.free] + self.B @ z
        return th

    def unknowns_of(self, th):
        """The parameter unknowns ``z`` of slot values ``th`` (projected onto
        the held directions' complement where directions are held)."""
        return th[self.free] if self.B is None else self.B.T @ (th[self.free] - self.base[self.free])

    def embedding(self) -> np.ndarray:
        """``T`` (ncol_x, ncol): d(every unknown, parameters as named) / dz."""
        if self.B is None:
            return np.eye(self.ncol)
        T = np.zeros((self.ncol_x, self.ncol))
        T[: self.Px, : self.P] = self.B
        T[self.Px:, self.P:] = np.eye(self.ncol - self.P)
        return T

    def ties(self):
        """The held directions as rows over the unknowns as named (``ncol_x``
        columns, zero on the poses), or None."""
        if self.B is None:
            return None
        hold = np.asarray(self.hold_along, float)
        T = np.zeros((len(hold), self.ncol_x))
        T[:, : self.Px] = hold[:, self.free]
        return T

    def split(self, x):
        th = self.theta(x[: self.P])
        cams = x[self.P: self.P + 6 * self.nc].reshape(self.nc, 6)
        s = x[-1] if self.free_focal else 1.0
        return th, cams[:, :3], cams[:, 3:], s

    def rotations(self, w):
        return Rotation.from_rotvec(w).as_matrix() @ self.R0

    def pack(self, th, w, t, s=1.0):
        x = [self.unknowns_of(th), np.concatenate([w, t], 1).ravel()]
        if self.free_focal:
            x.append([s])
        return np.concatenate(x)

    def distances(self, x, *, jac=False, full=False):
        """Signed endpoint distances ``h`` (n, 2) and, with ``jac``, their
        Jacobian as (rows, cols, values) of a (2n, ncol) sparse matrix
        (``full``: (2n, ncol_x), by the parameters as named, not ``z``)."""
        th, w, t, s = self.split(x)
        E = Rotation.from_rotvec(w).as_matrix()
        R = E @ self.R0
        K = self.K0.copy()
        K[:, 0, :2] *= s
        K[:, 1, 1] *= s
        c = self.cam
        X = [self.C0 @ th, self.C1 @ th]
        Y = [np.einsum("nij,nj->ni", R[c], Xk) + t[c] for Xk in X]
        u = [np.einsum("nij,nj->ni", K[c], Yk) for Yk in Y]
        lvec = np.cross(u[0], u[1])
        n12 = np.hypot(lvec[:, 0], lvec[:, 1])
        n12 = np.where(n12 > 0, n12, 1e-300)
        p = [np.c_[self.seg[:, 0:2], np.ones(self.n)], np.c_[self.seg[:, 2:4], np.ones(self.n)]]
        h = np.stack([(lvec * pi).sum(1) / n12 for pi in p], 1)
        if not jac:
            return h
        cols, vals = [], []
        l12 = np.c_[lvec[:, :2], np.zeros(self.n)]
        Jr = _right_jacobian(w)
        Kn = K[c]
        P = self.Px if (full or self.B is None) else self.P
        fo = np.arange(P)
        for i in range(2):
            g = p[i] / n12[:, None] - ((lvec * p[i]).sum(1) / n12**3)[:, None] * l12
            b = [np.cross(u[1], g), np.cross(g, u[0])]              # dh/du0, dh/du1
            a = [np.einsum("nji,nj->ni", Kn, bk) for bk in b]         # dh/dY_k
            dth = sum(np.einsum("ni,nis->ns", np.einsum("nj,nji->ni", a[k], R[c]), self.Cf[k])
                      for k in range(2))
            if P != self.Px:
                dth = dth @ self.B
            dt = a[0] + a[1]
            dw = np.zeros((self.n, 3))
            for k in range(2):
                v = np.einsum("nij,nj->ni", self.R0[c], X[k])
                q = np.einsum("nji,nj->ni", E[c], a[k])
                dw += np.einsum("nji,nj->ni", Jr[c], np.cross(v, q))
            blocks = [dth, dw, dt]
            ccols = [np.broadcast_to(fo, (self.n, P)),
                     P + 6 * c[:, None] + np.arange(3)[None],
                     P + 6 * c[:, None] + 3 + np.arange(3)[None]]
            if self.free_focal:
                K1 = self.K0[c]
                ds = sum((bk * np.c_[np.einsum("nj,nj->n", K1[:, 0, :2], Y[k][:, :2]),
                                     K1[:, 1, 1] * Y[k][:, 1], np.zeros(self.n)]).sum(1)
                         for k, bk in enumerate(b))
                blocks.append(ds[:, None])
                ccols.append(np.full((self.n, 1), (self.ncol_x if full else self.ncol) - 1))
            cols.append(np.concatenate(ccols, 1))
            vals.append(np.concatenate(blocks, 1))
        return h, cols, vals

    def weights(self, weighted):
        """Per-mark 2x2 maps h -> residuals (the eq. 5.3 weighting √(L/3) or
        the per-length mean, 1/√3), each divided by the mark's relative
        endpoint noise (``rel``; 1 unless its ``spread_px`` is above the
        solve's ``noise_px``)."""
        s = np.sqrt(self.length / 3.0) if weighted else np.full(self.n, 1 / np.sqrt(3.0))
        return (s / self.rel)[:, None, None] * _A0[None]

    def residuals(self, x, A):
        return np.einsum("nij,nj->ni", A, self.distances(x)).ravel()

    def jacobian(self, x, A, *, dense, full=False):
        from scipy.sparse import csr_matrix

        _, cols, vals = self.distances(x, jac=True, full=full)
        ncol = self.ncol_x if full else self.ncol
        if dense:  # each row's columns are distinct: plain fancy assignment
            rows = np.arange(self.n)[:, None]
            Jh = []
            for j in range(2):
                M = np.zeros((self.n, ncol))
                M[rows, cols[j]] = vals[j]
                Jh.append(M)
            J = np.empty((self.n, 2, ncol))
            for i in range(2):
                J[:, i] = A[:, i, 0, None] * Jh[0] + A[:, i, 1, None] * Jh[1]
            return J.reshape(2 * self.n, ncol)
        # rows of r = A h: r_i = Σ_j A_ij h_j, so each residual row mixes both endpoints' rows
        rows, cc, vv = [], [], []
        for i in range(2):
            for j in range(2):
                coef = A[:, i, j]
                if not np.any(coef):
                    continue
                rows.append(np.broadcast_to((2 * np.arange(self.n) + i)[:, None], cols[j].shape))
                cc.append(cols[j])
                vv.append(coef[:, None] * vals[j])
        M = csr_matrix((np.concatenate([v.ravel() for v in vv]),
                        (np.concatenate([r.ravel() for r in rows]),
                         np.concatenate([c.ravel() for c in cc]))), shape=(2 * self.n, ncol))
        return M.toarray() if dense else M

    def column_names(self):
        names = [n for n, f in zip(self.model.slot_names, self.free, strict=True) if f]
        for p in self.photos:
            names += [f"{p}:rotation"] * 3 + [f"{p}:position"] * 3
        if self.free_focal:
            names.append("focal_scale")
        return names


def _plane_normals(seg, K):
    """Unit interpretation-plane normals (camera frame) of segments (n, 4)."""
    p0 = np.c_[seg[:, :2], np.ones(len(seg))]
    p1 = np.c_[seg[:, 2:], np.ones(len(seg))]
    n = np.einsum("nji,nj->ni", K, np.cross(p0, p1))
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _known_axis(model, edges):
    """For each edge name: 0/1/2 when its direction is a world axis for any
    parameter values (one non-zero row of C1 − C0), else −1."""
    C0, C1 = model.edge_matrices(edges)
    nz = np.abs(C1 - C0).sum(2) > 0
    return np.where(nz.sum(1) == 1, nz.argmax(1), -1)


def _rotation_refine(R, normals, dirs, iterations=10):
    """Gauss–Newton on Σ (nᵀ R v)² (eq. 5.4) from ``R``; directions it does
    not constrain keep their start (minimum-norm steps)."""
    for _ in range(iterations):
        Rv = dirs @ R.T
        r = (normals * Rv).sum(1)
        J = np.cross(Rv, normals)       # d(nᵀ exp(ω) R v)/dω at ω = 0
        step = np.linalg.lstsq(J, -r, rcond=1e-10)[0]
        R = Rotation.from_rotvec(step).as_matrix() @ R
        if np.linalg.norm(step) < 1e-15:
            break
    return R


def _rotation_from_vanishing(normals, axes):
    """Candidate rotations from the vanishing directions of two or three
    world axes (eq. 5.4 without a start); None when fewer than two axes have
    two marks.

    The axis whose marks' interpretation planes differ most (the largest
    second singular value of their normals) gives its vanishing direction
    alone; the next is fitted perpendicular to it (the smallest singular
    vector of its normals projected on the plane normal to the first).
    Two marks of one axis that nearly coincide in the image (two vertical
    edges of a tower seen along its side, seed 226 of the marking eval)
    make their own intersection meaningless; fitted perpendicular to a
    well-seen axis the direction is one angle, not two, and each mark
    fixes it. (Before 2026-12-03 each axis's direction was its own and the
    two were made orthogonal afterwards: that start was 86° off there.)

    >>> R = Rotation.from_euler("xyz", [100, 5, 30], degrees=True).as_matrix()
    >>> pts = {0: [(0, 1, 5), (0, -1, 5), (0, 2, 7)], 2: [(1, 0, 5), (-1, 0, 6)]}
    >>> N, ax = [], []
    >>> for a, offs in pts.items():
    ...     for o in offs:
    ...         n = np.cross(R @ np.array(o, float), R[:, a])
    ...         N.append(n / np.linalg.norm(n)); ax.append(a)
    >>> cands = _rotation_from_vanishing(np.array(N), np.array(ax))
    >>> bool(min(np.abs(c - R).max() for c in cands) < 1e-12)
    True
    """
    v, spread = {}, {}
    for a in range(3):
        N = normals[axes == a]
        if len(N) >= 2:
            _, sv, Vt = np.linalg.svd(N)
            v[a], spread[a] = Vt[-1], sv[1]    # (2 or more marks: sv[1] exists)
    if len(v) < 2:
        return None
    first, second = sorted(v, key=lambda a: -spread[a])[:2]
    # the second: min Σ (nᵀ v)² over unit v in the plane normal to the first,
    # v = B c with B an orthonormal basis of that plane
    B = np.linalg.svd(v[first][None])[2][1:].T
    c = np.linalg.svd(normals[axes == second] @ B)[2][-1]
    v = {first: v[first], second: B @ c}
    out = []
    for signs in np.ndindex(2, 2, 2):
        cols = {a: (1.0 - 2.0 * signs[a]) * v[a] for a in v}
        a, b = sorted(cols)
        c = 3 - a - b
        cols[c] = np.cross(cols[(c + 1) % 3], cols[(c + 2) % 3])
        if signs[c]:
            continue                  # the completed axis carries no sign of its own
        M = np.stack([cols[0], cols[1], cols[2]], 1)
        U, _, Vt = np.linalg.svd(M)
        R = U @ Vt
        if np.linalg.det(M) <= 0 or R[1, 2] > 0:
            continue                      # a reflection, or world up looking down (y is down)
        out.append(R)
    return out


# a marked edge projected this much shorter than its mark: the camera sits on
# (next to) the edge's line. A mark can be longer than its edge's projection
# (snapped along a collinear neighbour: 76 px on an 18 px edge, seed 239 of
# the marking eval, a quarter flagged it), not twenty times longer; on the
# line the projection is a point (0 px under 138 px marks, seed 226)
COLLAPSED = 0.05


def _unseen_edge(edges, uv, z, lengths):
    """The first of ``edges`` (one photograph's marked edges) that its
    camera cannot see, as ``(edge, why)``: projected ``COLLAPSED`` times
    shorter than its mark (``uv`` its endpoints' pixels (k, 2, 2), ``z``
    their depths (k, 2), ``lengths`` its marks' lengths (k,)): the camera
    sits on the edge's line. None when none is."""
    for i, e in enumerate(edges):
        if np.all(z[i] > 0):
            proj = float(np.linalg.norm(uv[i, 1] - uv[i, 0]))
            if proj < COLLAPSED * lengths[i]:
                return e, (f"the camera is on the edge's line: it projects to {proj:.1f} px, "
                           f"its mark is {lengths[i]:.0f} px")
    return None


def _camera_fit(R, N, X0, X1, K, seg) -> float:
    """The squared pixel distances of one photograph's marks with rotation
    ``R`` and its eq. 5.5 translation for fixed model points (inf when a
    point falls behind the camera)."""
    A = np.concatenate([N, N])
    b = -np.concatenate([(N * (X0 @ R.T)).sum(1), (N * (X1 @ R.T)).sum(1)])
    t = np.linalg.lstsq(A, b, rcond=None)[0]
    Y = np.concatenate([X0, X1]) @ R.T + t
    if np.any(Y[:, 2] <= 0):
        return np.inf
    u = Y @ K.T
    u = u[:, :2] / u[:, 2:]
    n = len(seg)
    d0 = seg[:, 2:] - seg[:, :2]
    # distance of each model endpoint's image to its marked line (cheap proxy)
    nrm = np.c_[-d0[:, 1], d0[:, 0]] / np.linalg.norm(d0, axis=1, keepdims=True)
    e = np.concatenate([((u[:n] - seg[:, :2]) * nrm).sum(1), ((u[n:] - seg[:, :2]) * nrm).sum(1)])
    return float((e**2).sum())


def _linear_translations(prob: _Problem, R, th_start, cams_only=None):
    """Eq. 5.5: the free parameters and every translation from the rotations
    ``R`` (C, 3, 3), one linear least-squares solve; rows rescaled by the
    endpoint depths of a first solve so they measure pixels."""
    n = prob.n
    N = _plane_normals(prob.seg, prob.K0[prob.cam])
    E, fixed_th = prob.E, prob.off
    scale = np.ones((n, 2))
    sol = None
    for _ in range(2):
        A = np.zeros((2 * n, prob.P + 3 * prob.nc))
        b = np.zeros(2 * n)
        for k, Ck in enumerate((prob.C0, prob.C1)):
            nR = np.einsum("ni,nij->nj", N, R[prob.cam])            # nᵀ R
            rows = 2 * np.arange(n) + k
            A[rows, : prob.P] = np.einsum("nj,njs->ns", nR, Ck @ E) * scale[:, k:k + 1]
            A[rows[:, None], prob.P + 3 * prob.cam[:, None] + np.arange(3)] = N * scale[:, k:k + 1]
            b[rows] = -np.einsum("nj,njs,s->n", nR, Ck, fixed_th) * scale[:, k]
        # columns scaled to unit norm and a faint pull (1e-7) towards the
        # starting values: a parameter no mark constrains keeps its start
        # instead of the minimum-norm 0 (a flat block), the others move by
        # ~1e-14 relative (the nonlinear solve removes even that)
        cn = np.linalg.norm(A, axis=0)
        cn = np.where(cn > 0, cn, 1.0)
        x_start = np.r_[prob.unknowns_of(th_start), np.zeros(3 * prob.nc)] * cn
        lam = 1e-7
        y = np.linalg.lstsq(np.vstack([A / cn, lam * np.eye(A.shape[1])]),
                            np.r_[b, lam * x_start], rcond=None)[0]
        sol = y / cn
        th = prob.theta(sol[: prob.P])
        t = sol[prob.P:].reshape(prob.nc, 3)
        z = np.stack([np.einsum("nij,nj->ni", R[prob.cam], Ck @ th)[:, 2] + t[prob.cam, 2]
                      for Ck in (prob.C0, prob.C1)], 1)
        z = np.where(z > 1e-9, z, np.median(np.abs(z)) + 1e-9)
        scale = 1.0 / z
    return th, t


# the rank test: a singular value of the column-scaled Jacobian below this
# times the largest is a null direction, and an unknown with more than
# NULL_WEIGHT of it in a null direction is unconstrained
RANK_RCOND = 1e-9
NULL_WEIGHT = 0.1


# a parameter's Jacobian column this many times the median parameter column's: a marked edge
# projects through (next to) a camera's centre at that start, not a real sensitivity
DEGENERATE_COLUMN = 1e6


def _degenerate_start(J, names) -> bool:
    """Whether the Jacobian ``J`` at a start is unusable: not finite, or a
    parameter's column ``DEGENERATE_COLUMN`` times the median parameter
    column (an edge projected through, or next to, a camera's centre; the
    rank test's round-off floor, scaled to the largest column, would then
    call every other parameter unconstrained)."""
    J = np.asarray(J)
    if not np.all(np.isfinite(J)):
        return True
    norms = np.linalg.norm(J, axis=0)[[":" not in n for n in names]]
    norms = norms[norms > 0]
    return bool(norms.size and norms.max() > DEGENERATE_COLUMN * np.median(norms))


def _null_space(J, names, *, rcond=RANK_RCOND, ties=None):
    """The column-scaled Jacobian's null space: ``(zero, keep, norms,
    null)``, the round-off columns, the rest, every column's norm and the
    null directions (rows over ``keep``, scaled). ``ties`` (k, columns):
    directions held (rows in the unknowns' own units), appended as unit rows
    of the scaled system."""
    J = np.asarray(J)
    norms = np.linalg.norm(J, axis=0)
    # a column is zero when it is round-off next to the largest of its kind (a
    # parameter that only slides an edge along its own line: a box's height
    # seen through its vertical edges alone)
    kind = np.array([n.split(":")[-1] if ":" in n else "param" for n in names])
    zero = np.zeros(len(names), bool)
    for k in set(kind):
        sel = kind == k
        zero[sel] = norms[sel] <= 1e-9 * norms[sel].max()
    keep = np.flatnonzero(~zero)
    Js = J[:, keep] / norms[keep]
    if ties is not None and len(ties):
        Ts = np.asarray(ties, float)[:, keep] / norms[keep]
        tn = np.linalg.norm(Ts, axis=1)
        Js = np.vstack([Js, Ts[tn > 0] / tn[tn > 0, None]])
    _, s, Vt = np.linalg.svd(Js, full_matrices=False)
    null = Vt[s < rcond * s[0]] if s.size else Vt[:0]
    return zero, keep, norms, null


def _rank_deficient(J, names, *, rcond=RANK_RCOND, ties=None):
    """The unknowns no combination of marks constrains: names with weight in
    the null space of the column-scaled Jacobian (``ties``: directions held,
    :func:`_null_space`)."""
    zero, keep, _, null = _null_space(J, names, rcond=rcond, ties=ties)
    bad = {names[i] for i in np.flatnonzero(zero)}
    for v in null:
        for i in np.flatnonzero(np.abs(v) > NULL_WEIGHT):
            bad.add(names[keep[i]])
    return sorted(bad, key=names.index)


def _free_parameter_directions(names, keep, norms, null) -> np.ndarray:
    """The null directions' parameter parts (:func:`_null_space`'s
    ``keep, norms, null``), in the parameters' own units (rows over the
    ``names`` columns, zero on poses and the focal scale, orthonormal): a
    direction with no more than ``NULL_WEIGHT`` of its scaled weight on
    parameters (a photograph's pose) is left out."""
    par = np.array([":" not in names[i] and names[i] != "focal_scale" for i in keep])
    rows = []
    for v in null:
        if np.linalg.norm(v[par]) > NULL_WEIGHT:
            u = np.zeros(len(names))
            u[keep[par]] = v[par] / norms[keep[par]]
            rows.append(u / np.linalg.norm(u))
    if not rows:
        return np.zeros((0, len(names)))
    _, s, Vt = np.linalg.svd(np.array(rows), full_matrices=False)
    return Vt[s > 1e-6 * s[0]]


def check_solve_options(*, noise_px: float, max_iterations: int,
                        hold_unconstrained: bool | str = False) -> None:
    if not (np.isfinite(noise_px) and noise_px > 0):
        raise InputError("noise_px", f"expected a positive endpoint noise in pixels, got {noise_px}")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise InputError("max_iterations", f"expected a positive integer, got {max_iterations}")
    if not (isinstance(hold_unconstrained, bool) or hold_unconstrained in HOLD_MODES):
        raise InputError("hold_unconstrained", "expected False, True, \"directions\" or "
                         f"\"parameters\", got {hold_unconstrained!r}")


# the mis-mark test against each mark's own noise (its spread_px) when True;
# False, the default: against the solve's noise_px for every mark
OUTLIER_OWN_NOISE = False


def solve_facade(model: BlockModel, marks, K: dict, *, rough_rotations: dict | None = None,
                 free_focal: bool = False, noise_px: float = 1.0, robust: bool = True,
                 max_iterations: int = 200, hold_unconstrained: bool | str = False,
                 separate_noise: bool = True, where: str = "edges.json",
                 hold_along=None) -> FacadeSolution:
    """Fit the free block parameters and every photograph's pose to the
    marked edges (module docstring).

    Parameters
    ----------
    model : BlockModel
        The model; its values are the starting parameters (eq. 5.5 replaces
        them from the rotations, they matter only where marks are few).
    marks : EdgeMarks
        The marked segments (pixels).
    K : dict
        photo -> (3, 3) intrinsics in pixels (undistorted photographs).
    rough_rotations : dict, optional
        photo -> (3, 3) rough ``R`` (``x_cam = R x + t``) to start eq. 5.4
        from; without one, a photograph's rotation comes from its vanishing
        directions (two world axes marked twice each).
    free_focal : bool
        Fit one focal-length scale shared by every photograph.
    noise_px : float
        The marks' endpoint noise (px): the scale of the robust loss and of
        the mis-marked test.
    robust : bool
        Find and leave out mis-marked edges first.
    hold_unconstrained : bool or {"directions", "parameters"}
        Instead of refusing, hold what the marks do not constrain at its
        starting value and leave out the photographs whose pose they do not
        constrain (a rough solve). ``True`` or ``"directions"``: where a free
        direction mixes parameters (a wing's width and offset when only one
        of its side edges is marked), only that direction is held, and the
        combination the marks fix is solved; ``"parameters"``: every
        parameter a free direction moves is held (automatic marking's own
        rough solves, whose searches then scan those parameters). Either
        way ``held`` names the parameters a held direction moves.
    hold_along : array_like, optional
        ``(k, S)`` directions over the model's slots held at the model's
        values (what ``hold_unconstrained`` passes on to its re-solve).
    separate_noise : bool
        When the marks mix hand marks and automatic marking's proposals (at
        least ``VARIANCE_COMPONENTS_MIN_MARKS`` of each), estimate each
        kind's endpoint noise (Helmert's variance components) and weight the
        marks by it (module docstring); False: one noise for all.

    Returns
    -------
    FacadeSolution

    Raises
    ------
    EstimationError
        No parameter fixed (the scale is free); unknowns no mark
        constrains (named); a photograph whose rotation cannot be
        initialised; fewer than two photographs left.
    """
    rough = dict(rough_rotations or {})
    retried: list[str] = []
    while True:
        alternatives: dict = {}
        try:
            sol = _solve_facade(model, marks, K, rough_rotations=rough or None,
                                free_focal=free_focal, noise_px=noise_px, robust=robust,
                                max_iterations=max_iterations,
                                hold_unconstrained=hold_unconstrained,
                                separate_noise=separate_noise, where=where,
                                alternatives=alternatives, hold_along=hold_along)
            break
        except (Unconstrained, CannotSeeMarks) as e:
            # a pose free at the solution, or one that cannot see its marks,
            # started from its vanishing directions' best-fitting sign: the
            # mirror image of the pose through its marks can fit them as well
            # (seed 226 of the marking eval: every mark of the photograph on the
            # front wall but one). Its next candidate, once.
            if isinstance(e, CannotSeeMarks):
                named = set(e.photos)
            else:
                named = {u.split(":")[0] for u in e.unknowns if ":" in u}
                if not (e.at_solution and all(":" in u for u in e.unknowns)):
                    raise
            if not (named and named <= alternatives.keys() and alternatives
                    and all(alternatives[p] for p in named)):
                raise
            for p in sorted(named):
                rough[p] = alternatives[p][0]
                retried.append(p)
    if retried:
        sol = replace(sol, warnings=[
            f"photograph {p!r}: its pose was free where the solve from its vanishing directions "
            "ended; solved again from their next candidate rotation" for p in retried]
            + sol.warnings)
    return sol


def _solve_facade(model: BlockModel, marks, K: dict, *, rough_rotations: dict | None = None,
                  free_focal: bool = False, noise_px: float = 1.0, robust: bool = True,
                  max_iterations: int = 200, hold_unconstrained: bool | str = False,
                  separate_noise: bool = True, where: str = "edges.json",
                  alternatives: dict | None = None, hold_along=None) -> FacadeSolution:
    """:func:`solve_facade` from one start; ``alternatives``, when given, is
    filled with ``photo -> [the other candidate rotations, best first]`` of
    the photographs whose rotation came from vanishing directions."""
    check_solve_options(noise_px=noise_px, max_iterations=max_iterations,
                        hold_unconstrained=hold_unconstrained)
    t0 = time.perf_counter()
    warnings: list[str] = []
    if not model.fixed.any():
        raise EstimationError(model.where, "no parameter is fixed, so the scale is free: fix one "
                              "length, e.g. {\"value\": 10, \"fixed\": true}")
    marks_by = {}
    for m in marks.marks:
        marks_by.setdefault(m.photo, []).append(m)
    photos, dropped = [], []
    for p in marks.photographs:
        k = len(marks_by.get(p, []))
        if k >= MIN_MARKS:
            photos.append(p)
        else:
            dropped.append(p)
            warnings.append(f"photograph {p!r} has {k} marked edge(s) ({2 * k} constraints on its "
                            f"6 pose unknowns): left out; mark at least {MIN_MARKS}")
    missing = [p for p in photos if p not in K]
    if missing:
        raise InputError("K", f"no intrinsics for photograph(s) {', '.join(missing)}")
    if not photos:
        raise EstimationError(where, f"no photograph has {MIN_MARKS} or more marked edges")
    kept = [m for p in photos for m in marks_by[p]]

    # eq. 5.4: rotations
    axes_all = _known_axis(model, [m.edge for m in kept])
    R0 = []
    prob0 = _Problem(model, kept, photos, K, np.repeat(np.eye(3)[None], len(photos), 0),
                     free_focal=False)
    normals = _plane_normals(prob0.seg, prob0.K0[prob0.cam])
    candidates = []
    for j, p in enumerate(photos):
        sel = prob0.cam == j
        ax = axes_all[sel]
        dirs = np.eye(3)[np.clip(ax, 0, 2)][ax >= 0]
        nj = normals[sel][ax >= 0]
        if rough_rotations is not None and p in rough_rotations:
            cand = [np.asarray(rough_rotations[p], float)]
        else:
            cand = _rotation_from_vanishing(nj, ax[ax >= 0])
            if not cand:
                raise NoRotationStart(where, p)
        candidates.append([_rotation_refine(R, nj, dirs) for R in cand])
    # choose among sign candidates photograph by photograph: the eq. 5.5 fit of
    # its translation alone (starting parameters), points in front
    R0 = np.array([c[0] for c in candidates])
    th0 = model.values
    for j, cand in enumerate(candidates):
        if len(cand) > 1:
            sel = prob0.cam == j
            fit = [_camera_fit(R, normals[sel], prob0.C0[sel] @ th0, prob0.C1[sel] @ th0,
                               prob0.K0[j], prob0.seg[sel]) for R in cand]
            order = np.argsort(fit, kind="stable")
            candidates[j] = [cand[i] for i in order]
            R0[j] = candidates[j][0]
            if alternatives is not None:
                alternatives[photos[j]] = candidates[j][1:]
    prob = _Problem(model, kept, photos, K, R0, free_focal=free_focal, noise_px=noise_px,
                    separate_noise=separate_noise, hold_along=hold_along)
    th, t = _linear_translations(prob, R0, model.values)        # eq. 5.5
    # a size the linear solve makes non-positive (mis-marked edges pull it) starts
    # from the model's value instead: the robust pass then finds the bad marks
    size = np.array([n.rsplit("/", 1)[-1] in ("width", "depth", "height")
                     for n in model.slot_names])
    th = np.where(size & (th <= 0), model.values, th)
    x0 = prob.pack(th, np.zeros((len(photos), 3)), t)

    names = prob.column_names()
    Aw = prob.weights(True)
    with np.errstate(invalid="ignore", divide="ignore"):
        J0 = prob.jacobian(x0, Aw, dense=True, full=True)
    if _degenerate_start(J0, names) and not np.array_equal(th, model.values):
        # the linear solve from few marks can put a marked edge through a
        # camera's centre (a weak direction, seed 44 of the marking eval), or
        # next to it (a Jacobian column 10^10 times the others': seed 152, where
        # the rank test then found every other parameter "zero" beside it): the
        # parameters' starting values, with the linear translations, instead
        x0 = prob.pack(model.values, np.zeros((len(photos), 3)), t)
        with np.errstate(invalid="ignore", divide="ignore"):
            J0 = prob.jacobian(x0, Aw, dense=True, full=True)
        warnings.append("the linear initialisation put a marked edge through (or next to) a "
                        "camera's centre: started from the starting values instead")
    if not np.all(np.isfinite(J0)):
        raise EstimationError(where, "the starting model projects a marked edge to a point "
                              "(a block of zero size?): check the starting values in blocks.json")
    # a rough solve (hold_unconstrained) also holds what the marks barely
    # constrain: with four noisy marks a weak direction wanders far
    rcond = 1e-3 if hold_unconstrained else RANK_RCOND
    ties = prob.ties()
    bad = _rank_deficient(J0, names, rcond=rcond, ties=ties)
    if bad and hold_unconstrained:
        # hold the model's unconstrained parameters first; only a photograph
        # still unconstrained with them held is left out
        held = [b for b in bad if ":" not in b and b != "focal_scale"]
        lost = [] if held else sorted({b.split(":")[0] for b in bad if ":" in b})
        fixed, along = (_hold(prob, J0, names, held, rcond=rcond, ties=ties, hold_along=hold_along,
                              mode=hold_unconstrained) if held else ([], hold_along))
        if held:
            warnings.append(_held_said(held, fixed, "no mark constrains them"))
        if lost:
            warnings.append("left out (their marks do not fix their pose): " + ", ".join(lost))
        sol = solve_facade(model.with_fixed(fixed), _without(marks, lost) if lost else marks, K,
                           rough_rotations=rough_rotations,
                           free_focal=free_focal and "focal_scale" not in bad, noise_px=noise_px,
                           robust=robust, max_iterations=max_iterations, where=where,
                           hold_unconstrained=hold_unconstrained,
                           separate_noise=separate_noise, hold_along=along)
        return replace(sol, warnings=warnings + sol.warnings, dropped=dropped + lost + sol.dropped,
                       held=tuple(dict.fromkeys(tuple(held) + sol.held)))
    if bad:
        raise Unconstrained(where, tuple(dict.fromkeys(bad)))
    dense = prob.ncol <= DENSE_MAX_COLUMNS
    kw = dict(method="trf", x_scale="jac", ftol=1e-14, xtol=1e-14, gtol=1e-14,
              max_nfev=max_iterations, tr_solver="exact" if dense else "lsmr")
    nfev = 0
    outliers: list = []
    if robust:
        Am = prob.weights(False)
        r = least_squares(lambda x: prob.residuals(x, Am), x0,
                          jac=lambda x: prob.jacobian(x, Am, dense=dense),
                          loss="soft_l1", f_scale=3.0 * noise_px,
                          # only a start and the mis-mark test: loose tolerances, and the
                          # iterative trust-region solver (an SVD per step costs more)
                          **{**kw, "ftol": 1e-8, "xtol": 1e-8, "gtol": 1e-8, "tr_solver": "lsmr"})
        nfev += r.nfev
        ran_off = bool(np.any(size & (prob.split(r.x)[0] <= 0)))
        # the mis-mark test in pixels for every mark: a mark's spread_px says how
        # well the image shows its edge, not how far off a mark may be placed
        # (tried per mark: a mark 2-3 px off a corner the image barely shows
        # was excused by its scatter and kept; docs/decisions/view-marking.md)
        h = prob.distances(r.x) / (prob.rel[:, None] if OUTLIER_OWN_NOISE else 1.0)
        d = np.sqrt((h[:, 0] ** 2 + h[:, 0] * h[:, 1] + h[:, 1] ** 2) / 3.0)
        spread = 1.4826 * np.median(np.abs(h))
        limit = 5.0 * max(noise_px, spread)
        out = d > limit
        if ran_off:
            # the robust pass ran off along a direction the marks barely hold
            # (a size went non-positive: no model there; the soft loss lets it
            # drift): its distances test nothing, so no mark is left out, and
            # the plain solve starts from the linear initialisation instead
            pass
        elif out.any():
            scale = prob.rel if OUTLIER_OWN_NOISE else np.ones(prob.n)
            outliers = [(m.photo, m.edge, float(di * ri))
                        for m, di, ri, o in zip(kept, d, scale, out, strict=True) if o]
            for o, ri in zip(outliers, scale[out], strict=True):
                warnings.append(f"mark of {o[1]!r} on {o[0]!r} is {o[2]:.1f} px from its projected "
                                f"edge (limit {limit * ri:.1f} px): mis-marked? left out")
            # the final solve without them, from the robust solution's rotations
            # (a photograph left with too few marks is dropped, the rank test reruns)
            th, w, _, _ = prob.split(r.x)
            R = prob.rotations(w)
            gone = {id(m) for m, o in zip(kept, out, strict=True) if o}
            rest = replace(marks, marks=tuple(m for m in marks.marks if id(m) not in gone))
            sol = solve_facade(model, rest, K, rough_rotations={p: R[j] for j, p in
                                                                enumerate(photos)},
                               free_focal=free_focal, noise_px=noise_px, robust=False,
                               max_iterations=max_iterations,
                               hold_unconstrained=hold_unconstrained,
                               separate_noise=separate_noise, where=where, hold_along=hold_along)
            return replace(sol, outliers=outliers, warnings=warnings + sol.warnings,
                           dropped=dropped + sol.dropped, nfev=nfev + sol.nfev,
                           seconds=time.perf_counter() - t0)
        if not ran_off:
            x0 = r.x
    try:
        return _final(prob, x0, kw, model, dropped, outliers, warnings, t0, nfev, where)
    except (Unconstrained, CannotSeeMarks) as e:
        # a camera that cannot see its marks, with candidate rotations left, goes
        # back to solve_facade to start again from the next of them
        retry = (isinstance(e, CannotSeeMarks) and bool(alternatives)
                 and all(alternatives.get(p) for p in e.photos))
        if not hold_unconstrained or retry:
            raise
        # a rough solve treats what the solution's rank test finds free as the
        # start's test does: the parameters held, else the photographs left out
        # (a rough pose that ends with a marked edge through its centre, seed 226);
        # a camera that cannot see its marks is left out too
        if isinstance(e, CannotSeeMarks):
            held, lost = [], sorted(e.photos)
        else:
            held = [b for b in e.unknowns if ":" not in b and b != "focal_scale"]
            lost = [] if held else sorted({b.split(":")[0] for b in e.unknowns if ":" in b})
        if not (held or lost):
            raise
        fixed, along = [], hold_along
        if held:
            fixed, along = _hold(prob, e.jacobian, e.unknowns_all, held, rcond=RANK_RCOND,
                                 ties=prob.ties(), hold_along=hold_along, mode=hold_unconstrained)
        sol = solve_facade(model.with_fixed(fixed or []), _without(marks, lost) if lost else marks,
                           K, rough_rotations=rough_rotations, free_focal=free_focal,
                           noise_px=noise_px, robust=robust, max_iterations=max_iterations,
                           where=where, hold_unconstrained=hold_unconstrained,
                           separate_noise=separate_noise, hold_along=along)
        # (the solve reruns from the marks: its warnings and dropped photographs are the new ones)
        said = (_held_said(held, fixed, "free at the solution")
                if held else "left out (their marks do not fix their pose at the solution, or "
                "the solved camera cannot see them): " + ", ".join(lost))
        return replace(sol, warnings=[said] + sol.warnings, dropped=lost + sol.dropped,
                       held=tuple(dict.fromkeys(tuple(held) + sol.held)))


HOLD_MODES = ("directions", "parameters")


def _hold(prob, J, names, held, *, rcond, ties, hold_along, mode):
    """What a rough solve holds of the parameters ``held`` (those the rank
    test of ``J``, columns ``names``, found free): ``(fixed, hold_along)``,
    the parameters to fix (a zero column; all of ``held`` in the mode
    ``"parameters"``, or where the directions found add nothing to those
    already held) and the slot-space directions to hold."""
    if mode == "parameters":
        return list(held), hold_along
    zero, keep, norms, null = _null_space(J, names, rcond=rcond, ties=ties)
    fixed = [n for n, z in zip(names, zero, strict=True) if z and n in held]
    D = _free_parameter_directions(names, keep, norms, null)
    rows = np.zeros((len(D), len(prob.base)))
    rows[:, np.flatnonzero(prob.free)] = D[:, : prob.Px]
    old = np.zeros((0, len(prob.base))) if hold_along is None else np.asarray(hold_along, float)
    new = np.vstack([old, rows])
    if _rank(new) == _rank(old):
        if fixed:
            return fixed, hold_along
        return list(held), hold_along
    return fixed, new


def _rank(M) -> int:
    return int(np.linalg.matrix_rank(M)) if len(M) else 0


def _held_said(held, fixed, why):
    if set(held) <= set(fixed or ()):
        return f"held at their starting values ({why}): " + ", ".join(held)
    return (f"held at their starting values along the direction(s) the marks leave free ({why}; "
            "the combination the marks fix is solved): " + ", ".join(held))


def _without(marks, photos):
    """``marks`` without the photographs ``photos``."""
    return replace(marks, marks=tuple(m for m in marks.marks if m.photo not in photos),
                   photographs=tuple(p for p in marks.photographs if p not in photos))


def sandwich_covariance(J: np.ndarray, D: np.ndarray, sigma: float) -> np.ndarray | None:
    """The first-order covariance of a least-squares fit with Jacobian ``J``
    (``m × p``, the weighted residuals') whose residuals are ``D`` (``m ×
    p``, the same rows before a weighting the noise does not follow) times
    noise of standard deviation ``sigma``: ``σ² N⁻¹ DᵀD N⁻¹``, ``N = JᵀJ``;
    None when ``J`` is singular.

    ``N⁻¹`` comes from the SVD of the column-scaled ``J``, not from
    inverting ``JᵀJ``: that squares the condition number, and a Façade solve
    with a nearly free direction (a scaled condition of 1e9, which the rank
    test lets through) gave negative variances of 1e27 (the marking eval,
    seed 81). Here the result is ``B Bᵀ``, positive semi-definite by
    construction.

    >>> J = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    >>> np.allclose(sandwich_covariance(J, J, 0.5), 0.25 * np.linalg.inv(J.T @ J))
    True
    """
    J, D = np.asarray(J, float), np.asarray(D, float)
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    try:
        _, sv, Vt = np.linalg.svd(J / norms, full_matrices=False)
    except np.linalg.LinAlgError:
        return None
    if not (sv.size and sv[-1] > 0 and np.all(np.isfinite(sv))):
        return None
    Ninv = (Vt.T / sv**2) @ Vt / norms[:, None] / norms[None, :]
    B = Ninv @ D.T
    return sigma**2 * (B @ B.T)


# Hand marks and automatic marking's proposals are not equally accurate (on
# the rendered scenes the proposals sit ~0.2 px from the solved edges, the
# hand marks at the 0.5 px they were drawn with); one pooled σ̂ then states
# too small a σ for what the hand marks fix, and weighs the proposals too
# little (docs/decisions/facade.md). With at least this many marks of each
# kind, each kind's noise is estimated and the marks are weighted by it.
VARIANCE_COMPONENTS_MIN_MARKS = 8
_OWN_RESIDUALS_BOUND = True


def group_variances(J: np.ndarray, W: np.ndarray, e: np.ndarray, groups: np.ndarray):
    """Helmert's variance components: each group's noise variance from the
    residuals of one weighted least-squares fit.

    The fit minimises ``‖W e‖²`` over the unknowns (``W`` block-diagonal,
    one ``(2, 2)`` block per mark, ``(n, 2, 2)``); ``e`` ``(n, 2)`` are the
    residual endpoint distances at the solution and ``J`` ``(2n, p)`` the
    Jacobian of ``W e``. With ``M = W⁻¹ J (JᵀJ)⁻¹ Jᵀ W`` the residuals are
    ``(I − M) ε``, so ``E[RSS_g] = Σ_k σ_k² ‖P_g (I − M) P_k‖²_F``: one
    linear equation per group, solved for the ``σ_k²``. ``groups`` ``(n,)``
    integers ``0 … G−1``. Returns the ``(G,)`` variances, or None when a
    solution is not positive (too few marks of a kind to tell); a group
    whose component comes out at or below zero (far more precise than the
    rest, whose noise leaking into its residuals explains them) gets the
    upper bound ``RSS_g / ‖P_g (I − M) P_g‖²_F`` (its residuals as its own
    noise alone).

    The Frobenius norms come from ``A = W⁻¹ Q`` and ``B = Wᵀ Q`` (``Q`` an
    orthonormal basis of ``J``'s columns), ``‖P_g (I − A Bᵀ) P_k‖²_F =
    [g = k] (|g| − 2 Σ_{i∈g} a_i·b_i) + tr(A_gᵀ A_g B_kᵀ B_k)``: O(n p²).

    >>> rng = np.random.default_rng(1)
    >>> n = 400
    >>> groups = (np.arange(n) >= 100).astype(int)      # 100 marks at 0.6, 300 at 0.2
    >>> X = rng.normal(size=(2 * n, 3))                  # a linear model, unit weights
    >>> noise = rng.normal(size=(n, 2)) * np.where(groups, 0.2, 0.6)[:, None]
    >>> beta = np.linalg.lstsq(X, noise.ravel(), rcond=None)[0]
    >>> e = (noise.ravel() - X @ beta).reshape(n, 2)
    >>> W = np.repeat(np.eye(2)[None], n, 0)
    >>> np.sqrt(group_variances(X, W, e, groups)).round(2).tolist()  # ± 0.03 and ± 0.006
    [0.56, 0.19]
    """
    n = len(groups)
    Q, _ = np.linalg.qr(np.asarray(J, float))
    Qm = Q.reshape(n, 2, -1)
    A = np.einsum("nij,njc->nic", np.linalg.inv(W), Qm).reshape(2 * n, -1)
    B = np.einsum("nji,njc->nic", W, Qm).reshape(2 * n, -1)
    rows = np.repeat(np.asarray(groups, int), 2)
    G = int(rows.max()) + 1
    AA = [A[rows == g].T @ A[rows == g] for g in range(G)]
    BB = [B[rows == g].T @ B[rows == g] for g in range(G)]
    T = np.array([[float(np.sum(AA[g] * BB[k].T)) for k in range(G)] for g in range(G)])
    for g in range(G):
        T[g, g] += float((rows == g).sum() - 2 * np.einsum("ic,ic->", A[rows == g], B[rows == g]))
    rss = np.array([float(np.sum(np.asarray(e, float).ravel()[rows == g] ** 2)) for g in range(G)])
    try:
        s2 = np.linalg.solve(T, rss)
    except np.linalg.LinAlgError:
        return None
    if _OWN_RESIDUALS_BOUND:
        # a group far more precise than the rest: the others' noise leaking
        # into its residuals explains them all and its component comes out
        # at or below zero. Its residuals taken as its own noise alone bound
        # its variance from above (precise proposals among hand marks:
        # pooling them with the hand marks weighed them down 25-fold)
        own = rss / np.maximum(np.diag(T), 1e-300)
        s2 = np.where(s2 > 0, s2, own)
    return s2 if np.all(s2 > 0) else None


def _final(prob, x0, kw, model, dropped, outliers, warnings, t0, nfev, where):
    Aw = prob.weights(True)
    dense = kw["tr_solver"] == "exact"
    if dense:  # MINPACK's Levenberg-Marquardt (QR steps): the quickest on small problems
        kw = dict(method="lm", ftol=1e-15, xtol=1e-15, gtol=1e-15, x_scale="jac",
                  max_nfev=kw["max_nfev"])
    r = least_squares(lambda x: prob.residuals(x, Aw), x0,
                      jac=lambda x: prob.jacobian(x, Aw, dense=dense), **kw)
    nfev += r.nfev
    x = r.x
    kind_ratio = None
    groups = prob.proposed.astype(int)
    if prob.separate_noise and min(int(groups.sum()), int(len(groups) - groups.sum())) \
            >= VARIANCE_COMPONENTS_MIN_MARKS:
        # each kind's noise relative to the hand marks' (rel scales a mark's
        # noise): estimate, re-weight, re-solve, until the ratio settles
        kind_ratio = np.ones(2)
        for _ in range(4):
            Wb = Aw * prob.rel[:, None, None]
            s2 = group_variances(prob.jacobian(x, Aw, dense=True), Wb,
                                 prob.distances(x) / prob.rel[:, None], groups)
            if s2 is None:
                break
            ratio = np.sqrt(s2 / s2[0])
            if np.all(np.abs(ratio - 1) < 0.02):
                break
            kind_ratio *= ratio
            prob.rel = prob.rel * ratio[groups]
            Aw = prob.weights(True)
            r = least_squares(lambda x, A=Aw: prob.residuals(x, A), x,
                              jac=lambda x, A=Aw: prob.jacobian(x, A, dense=dense), **kw)
            nfev += r.nfev
            x = r.x
    th, w, t, s = prob.split(x)
    R = prob.rotations(w)
    h = prob.distances(x)
    n, p = prob.n, prob.ncol
    dof = max(2 * n - p, 1)
    sigma = float(np.sqrt(((h / prob.rel[:, None]) ** 2).sum() / dof))
    by_kind = ({} if kind_ratio is None else
               {"hand": sigma, "proposed": sigma * float(kind_ratio[1])})
    J = np.asarray(prob.jacobian(x, Aw, dense=True))
    # the rank test again, where the answer is: the start's test sees the
    # Jacobian at the linear initialisation, and a solve can end where a
    # direction the start held is free (a marking-eval run, seed 205, ended
    # 8e3 off with σ of that size; a fresh solve of its marks refused)
    Jx = J if prob.B is None else np.asarray(prob.jacobian(x, Aw, dense=True, full=True))
    names = prob.column_names()
    bad = (_rank_deficient(Jx, names, ties=prob.ties()) if np.all(np.isfinite(Jx)) else [])
    if bad:
        e = Unconstrained(where, tuple(dict.fromkeys(bad)), at_solution=True)
        e.jacobian, e.unknowns_all = Jx, names
        raise e
    # sandwich: r = A h with cov(h) = σ² rel² I -> cov(r) = σ² (rel A)(rel A)ᵀ
    D = np.einsum("nji,njc->nic", Aw * prob.rel[:, None, None],
                  J.reshape(n, 2, p)).reshape(2 * n, p)   # (rel A)ᵀ J
    cov = sandwich_covariance(J, D, sigma)
    if cov is None:
        raise EstimationError(where, "the normal equations are singular at the solution")
    if prob.B is not None:   # by the unknowns as named (a held direction's variance is 0)
        T = prob.embedding()
        cov = T @ cov @ T.T
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    fitted = model.with_values(th[prob.free])
    std_slot = np.zeros(len(model.slot_names))
    std_slot[prob.free] = sd[: prob.Px]
    params = fitted.named_values()
    std = {nm: float(std_slot[model.slot_of(nm)]) for nm in params}
    # each solved camera must be able to see what it marked: not from a point on
    # a marked edge's line (eq. 5.3's projected line is undefined there, and a
    # solve can end on it: seed 226 of the marking eval, a camera 20 m off on
    # the corner where two of its marked edges meet, the parameters right)
    edge_names = [m.edge for m in prob.marks]
    unseen = {}
    P0, P1 = prob.C0 @ th, prob.C1 @ th
    Y = [np.einsum("nij,nj->ni", R[prob.cam], P) + t[prob.cam] for P in (P0, P1)]
    u = [np.einsum("nij,nj->ni", prob.K0[prob.cam], y) for y in Y]
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = np.stack([x[:, :2] / x[:, 2:] for x in u], 1)
    z = np.stack([y[:, 2] for y in Y], 1)
    for j, ph in enumerate(prob.photos):
        sel = np.flatnonzero(prob.cam == j)
        e = _unseen_edge([edge_names[i] for i in sel], uv[sel], z[sel], prob.length[sel])
        if e is not None:
            unseen[ph] = e
    if unseen:
        raise CannotSeeMarks(where, unseen)
    poses, pose_std, Ks = {}, {}, {}
    for j, ph in enumerate(prob.photos):
        poses[ph] = (R[j], t[j].copy())
        c = prob.Px + 6 * j
        Cj = cov[c:c + 6, c:c + 6]
        # centre = -Rᵀ t: d/dω = -R⁰ᵀ... evaluated at the solution through the full R
        Gw = R[j].T @ _skew(t[j])
        Gt = -R[j].T
        G = np.concatenate([Gw, Gt], 1)
        cc = G @ Cj @ G.T
        pose_std[ph] = {"rotation_rad": np.sqrt(np.clip(np.diag(Cj)[:3], 0, None)),
                        "t": np.sqrt(np.clip(np.diag(Cj)[3:], 0, None)),
                        "centre": np.sqrt(np.clip(np.diag(cc), 0, None))}
        Kj = prob.K0[j].copy()
        Kj[0, :2] *= s
        Kj[1, 1] *= s
        Ks[ph] = Kj
    d = np.sqrt((h[:, 0] ** 2 + h[:, 0] * h[:, 1] + h[:, 1] ** 2) / 3.0)
    mark_rms = [(m.photo, m.edge, float(v)) for m, v in zip(prob.marks, d, strict=True)]
    if not r.success:
        warnings.append(f"the solver stopped before converging ({r.message})")
    if prob.noise_px is not None:
        warnings += _noisier_than_given(sigma, by_kind, float(prob.noise_px), groups, p)
    warnings += _weak_unknowns(params, std, pose_std)
    return FacadeSolution(
        model=fitted, params=params, std=std, poses=poses, pose_std=pose_std,
        focal_scale=float(s), focal_scale_std=float(sd[-1]) if prob.free_focal else 0.0,
        K=Ks, outliers=outliers, dropped=dropped, mark_rms_px=mark_rms, sigma_px=sigma,
        rms_px=float(np.sqrt(np.mean(h**2))), covariance=cov, unknowns=tuple(prob.column_names()),
        warnings=warnings, seconds=time.perf_counter() - t0, nfev=nfev,
        noise_px=float(prob.noise_px) if prob.noise_px is not None else 1.0,
        sigma_px_by_kind=by_kind)


def _noisier_than_given(sigma: float, by_kind: dict, noise_px: float, groups, p: int) -> list:
    """A warning when the marks fit worse than the endpoint noise the caller
    gave can explain. With marks off their edges by that noise alone, σ̂²
    dof / σ² is χ²(dof) (dof = 2 × marks − unknowns, per kind its share);
    past its 0.1 % tail some marks are off by more: the σ, scaled by σ̂,
    still assume every kept mark is on its edge."""
    from scipy.stats import chi2

    kinds = by_kind or {"": sigma}
    n = len(groups)
    out = []
    for kind, s in kinds.items():
        k = int(np.sum(groups == (1 if kind == "proposed" else 0))) if by_kind else n
        dof = 2 * k - p * k / max(n, 1)
        if dof < 10:
            continue
        limit = noise_px * math.sqrt(chi2.ppf(0.999, dof) / dof)
        if s > limit:
            out.append(f"{kind + ' ' if kind else ''}marks fit at σ̂ = {s:.2f} px, beyond the "
                       f"{noise_px:g} px endpoint noise given (χ² 0.1 % limit {limit:.2f} px): "
                       "some marks are off their edges, which the σ do not cover; look at the "
                       "largest residuals")
    return out


# A size whose 3σ interval reaches zero is not determined (not even its
# sign); a rotation σ above 1° (3σ: 3°, about 50 px at f = 1000 px) is not
# a usable camera for texture mapping or stereo. Both are said, never hidden
# in the σ columns alone.
WEAK_REL_STD = 1 / 3
WEAK_ROTATION_RAD = math.radians(1.0)


def _weak_unknowns(params: dict, std: dict, pose_std: dict) -> list[str]:
    """Warnings naming the parameters and poses the marks determine poorly
    (first-order σ): parameters with σ > |value| / 3, photographs whose
    rotation σ exceeds 1°."""
    out = []
    weak = [f"{n} ({std[n] / abs(v):.0%})" for n, v in params.items()
            if std.get(n, 0) > WEAK_REL_STD * abs(v) > 0]
    if weak:
        out.append("poorly determined parameters (σ over a third of the value): "
                   + ", ".join(weak) + "; mark more edges of their blocks")
    rot = [f"{p} ({math.degrees(float(np.max(d['rotation_rad']))):.1f}°)"
           for p, d in pose_std.items() if np.max(d["rotation_rad"]) > WEAK_ROTATION_RAD]
    if rot:
        out.append("poorly determined camera rotations (σ over 1°): " + ", ".join(rot)
                   + "; mark edges in more directions on these photographs")
    return out


def project_model_edges(model: BlockModel, K, R, t, *, params=None) -> dict:
    """Every model edge projected by one camera: ``name -> (uv0, uv1)`` in
    pixels (NaN for an endpoint behind the camera)."""
    out = {}
    K, R, t = np.asarray(K, float), np.asarray(R, float), np.asarray(t, float).ravel()
    for nm, (p0, p1) in model.edges(params).items():
        uv = []
        for P in (p0, p1):
            y = K @ (R @ P + t)
            uv.append(y[:2] / y[2] if y[2] > 1e-9 else np.full(2, np.nan))
        out[nm] = (uv[0], uv[1])
    return out
