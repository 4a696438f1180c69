"""Calibration targets: the board description and corner detection.

Boards are given as the ``--board`` strings of ``lumigraph calib``:

* ``checker:COLSxROWS:SQUARE`` — a checkerboard of COLS × ROWS **squares**
  (so (COLS−1) × (ROWS−1) inner corners: OpenCV's 9×6 pattern is
  ``checker:10x7:…``), squares of side SQUARE (any length unit, e.g. mm;
  it becomes the unit of every translation);
* ``charuco:COLSxROWS:SQUARE:MARKER:DICT`` — a ChArUco board (``cv2.aruco``)
  with markers of side MARKER from dictionary DICT (``DICT_4X4_250`` or
  ``4X4_250``).

Board frame (both kinds, OpenCV's ``CharucoBoard`` convention): origin at the
top-left outer corner of the squares, x along columns, y along rows, z = 0 on
the board; square ``(0, 0)`` is black; inner corner ``k = j (COLS−1) + i`` sits
at ``((i+1) s, (j+1) s, 0)``.

Detection uses OpenCV (``findChessboardCorners`` then ``cornerSubPix`` for
checkerboards, ``aruco.CharucoDetector`` for ChArUco). ChArUco corners are
refined with the checkerboard's ``cornerSubPix`` with the markers painted
white, then by fitting a blurred X-junction model to each corner's pixels
(:mod:`lumigraph.calib.rohr1992`), the pixels near any marker left out, so no
blurred marker edge pulls a corner and no interpolation leans it
(docs/decisions/charuco-marker-removal.md; ``FIT_MODEL = False`` gives the
earlier second ``cornerSubPix`` on the image with each marker rendered and
subtracted). For large images the
checkerboard search runs on a 2× reduced copy and only the sub-pixel refinement
on the full image; checkerboards whose 180° rotation differs in colour (COLS +
ROWS odd) are put in the board's own orientation (square (0, 0) black), so the
corner order of a left and a right view agree. A found grid whose checker
pattern continues beyond its outer squares (OpenCV matched a smaller pattern
inside a larger board: the ``--board`` counts too few squares) is rejected, so
a wrong spec never yields silently wrong object points.

Examples
--------
>>> b = BoardSpec.parse("checker:10x7:25")
>>> b.pattern_size, b.n_corners, b.object_points[1].tolist()
((9, 6), 54, [50.0, 25.0, 0.0])
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from lumigraph.capture.errors import InputError

_CHECKER = re.compile(r"^checker:(\d+)x(\d+):([0-9.eE+-]+)$")
_CHARUCO = re.compile(r"^charuco:(\d+)x(\d+):([0-9.eE+-]+):([0-9.eE+-]+):(?:DICT_)?([A-Za-z0-9_]+)$")


@dataclass(frozen=True)
class BoardSpec:
    """A planar calibration target.

    Attributes
    ----------
    kind : {"checker", "charuco"}
    cols, rows : int
        Squares across and down (>= 3 each).
    square : float
        Square side, in the user's length unit.
    marker : float
        ChArUco marker side (0 for checkerboards).
    dictionary : str
        ``cv2.aruco`` dictionary name, e.g. ``"DICT_4X4_250"`` (ChArUco only).
    """

    kind: str
    cols: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = ""

    def __post_init__(self):
        if self.kind not in ("checker", "charuco"):
            raise ValueError(f"kind: expected 'checker' or 'charuco', got {self.kind!r}")
        if self.cols < 3 or self.rows < 3:
            raise ValueError(f"cols, rows: expected at least 3 squares each, got {self.cols}x{self.rows}")
        if not self.square > 0 or not np.isfinite(self.square):
            raise ValueError(f"square: expected a positive size, got {self.square}")
        if self.kind == "charuco":
            if not 0 < self.marker < self.square:
                raise ValueError(f"marker: expected 0 < marker < square ({self.square}), got {self.marker}")
            import cv2

            if not hasattr(cv2.aruco, self.dictionary):
                raise ValueError(f"dictionary: unknown cv2.aruco dictionary {self.dictionary!r}")

    @classmethod
    def parse(cls, text: str, *, where: str = "board") -> BoardSpec:
        """Parse a ``--board`` string (see the module docstring); InputError if it does not."""
        t = text.strip()
        m = _CHECKER.match(t)
        try:
            if m:
                return cls("checker", int(m[1]), int(m[2]), float(m[3]))
            m = _CHARUCO.match(t)
            if m:
                return cls("charuco", int(m[1]), int(m[2]), float(m[3]), float(m[4]), "DICT_" + m[5].upper())
        except ValueError as e:
            raise InputError(where, f"{text!r}: {e}") from None
        raise InputError(where, f"cannot parse {text!r}; expected checker:COLSxROWS:SQUARE or "
                                "charuco:COLSxROWS:SQUARE:MARKER:DICT (COLS, ROWS count squares), "
                                "e.g. checker:10x7:25")

    @property
    def spec(self) -> str:
        if self.kind == "checker":
            return f"checker:{self.cols}x{self.rows}:{self.square:g}"
        return f"charuco:{self.cols}x{self.rows}:{self.square:g}:{self.marker:g}:{self.dictionary}"

    @property
    def pattern_size(self) -> tuple[int, int]:
        """Inner corners ``(per row, per column)``, OpenCV's ``patternSize``."""
        return self.cols - 1, self.rows - 1

    @property
    def n_corners(self) -> int:
        return (self.cols - 1) * (self.rows - 1)

    @property
    def object_points(self) -> np.ndarray:
        """``(n_corners, 3)`` float64 inner corners in the board frame, row-major."""
        j, i = np.mgrid[1:self.rows, 1:self.cols]
        return np.column_stack([i.ravel() * self.square, j.ravel() * self.square,
                                np.zeros(i.size)]).astype(np.float64)

    def to_dict(self) -> dict:
        d = {"kind": self.kind, "cols": self.cols, "rows": self.rows, "square": self.square,
             "spec": self.spec}
        if self.kind == "charuco":
            d.update(marker=self.marker, dictionary=self.dictionary)
        return d

    def _charuco(self):
        import cv2

        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker, d)


@dataclass(frozen=True)
class Detection:
    """Board corners found in one image.

    Attributes
    ----------
    ids : ndarray, (N,) int64
        Inner-corner indices into ``BoardSpec.object_points``.
    image_points : ndarray, (N, 2) float64
        Sub-pixel corner positions ``(x, y)``, distorted pixels.
    object_points : ndarray, (N, 3) float64
        The same corners in the board frame.
    image_size : (int, int)
        ``(w, h)`` of the image they were found in.
    fallbacks : int
        Corners whose X-junction model fit failed (ChArUco: ``FIT_MODEL``), which
        keep ``cornerSubPix``'s position.
    """

    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray
    image_size: tuple[int, int]
    fallbacks: int = 0

    def __post_init__(self):
        n = len(self.ids)
        if np.asarray(self.image_points).shape != (n, 2) or np.asarray(self.object_points).shape != (n, 3):
            raise ValueError(f"image_points, object_points: expected (N, 2) and (N, 3) with N = {n}")

    def __len__(self) -> int:
        return len(self.ids)


def to_gray8(image: np.ndarray) -> np.ndarray:
    """An ``(H, W)`` uint8 view of an 8/16-bit gray or RGB image (for detection only)."""
    a = np.asarray(image)
    if a.ndim == 3:
        a = a[..., :3].mean(axis=2) if a.shape[2] >= 3 else a[..., 0]
    if a.ndim != 2:
        raise ValueError(f"image: expected (H, W) or (H, W, C), got shape {np.asarray(image).shape}")
    if a.dtype == np.uint8:
        return a
    a = a.astype(np.float64)
    top = 65535.0 if np.asarray(image).dtype == np.uint16 else max(float(a.max()), 1e-12)
    return np.clip(np.round(a * 255.0 / top), 0, 255).astype(np.uint8)


_SUBPIX_CRITERIA = (3, 40, 1e-3)  # cv2.TERM_CRITERIA_EPS | COUNT, 40 iterations, 1e-3 px


def subpix_window(points: np.ndarray, pattern_size: tuple[int, int]) -> int:
    """Half-width of the ``cornerSubPix`` window: 40 % of the smallest corner
    spacing (so the window never reaches a neighbouring corner), 2..10 px."""
    g = points.reshape(pattern_size[1], pattern_size[0], 2)
    dx = np.linalg.norm(np.diff(g, axis=1), axis=2).min()
    dy = np.linalg.norm(np.diff(g, axis=0), axis=2).min()
    return int(np.clip(np.floor(0.4 * min(dx, dy)), 2, 10))


def _orient(gray: np.ndarray, pts: np.ndarray, board: BoardSpec) -> np.ndarray:
    """Reverse the corner order when OpenCV returned the board rotated by 180°
    (square (0, 0) must be the dark one); only defined when COLS + ROWS is odd."""
    if (board.cols + board.rows) % 2 == 0:
        return pts
    import cv2

    nc = board.cols - 1
    c0, ec, er = pts[0], pts[1] - pts[0], pts[nc] - pts[0]
    probe = np.array([c0 - 0.5 * (ec + er), c0 + 0.5 * (ec - er)], np.float32)
    vals = cv2.remap(gray, probe[:, 0:1], probe[:, 1:2], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE).ravel()
    return pts[::-1].copy() if vals[0] > vals[1] else pts


def _pattern_continues(gray: np.ndarray, pts: np.ndarray, board: BoardSpec) -> bool:
    """Whether the checker pattern goes on beyond the found grid, i.e. OpenCV
    matched a smaller pattern inside a larger board (a ``--board`` with too few
    squares). The ring of square centres 1.5 squares outside the outermost
    inner corners lies on the board's plain margin for the right board, but
    on alternating squares for a larger one: compare the parity contrast
    there with that of the outer squares (0.5 squares outside), which a
    checkerboard always has."""
    import cv2

    nc, nr = board.pattern_size
    grid = np.mgrid[0:nr, 0:nc][::-1].reshape(2, -1).T.astype(np.float64)  # (col, row)
    H, _ = cv2.findHomography(grid, pts)
    if H is None:
        return False
    g32 = gray if gray.dtype == np.float32 else gray.astype(np.float32)  # once, not per side
    h, w = gray.shape

    def sides(d):
        c = np.arange(-d, nc - 1 + d + 1e-9)
        r = np.arange(-d, nr - 1 + d + 1e-9)
        return [np.column_stack([c, np.full(c.size, -d)]), np.column_stack([c, np.full(c.size, nr - 1 + d)]),
                np.column_stack([np.full(r.size, -d), r]), np.column_stack([np.full(r.size, nc - 1 + d), r])]

    # the square centres 0.5 and 1.5 squares outside each side, mapped and
    # sampled in one call each (this runs once per detected view)
    groups = sides(0.5) + sides(1.5)
    cells = np.concatenate(groups)
    xy = cv2.perspectiveTransform(cells[None], H)[0]
    vals = cv2.remap(g32, xy[:, 0:1].astype(np.float32), xy[:, 1:2].astype(np.float32),
                     cv2.INTER_LINEAR).ravel()
    inside_all = np.all((xy >= 1) & (xy <= np.array([w - 2, h - 2])), axis=1)
    parity_all = np.where((np.floor(cells[:, 0]) + np.floor(cells[:, 1])) % 2 == 0, 1.0, -1.0)
    contrast = []
    start = 0
    for g in groups:
        sl = slice(start, start + len(g))
        start += len(g)
        inside = inside_all[sl]
        if inside.sum() < 3:
            contrast.append(np.nan)
            continue
        v, parity = vals[sl][inside], parity_all[sl][inside]
        # a continuing checker alternates at every sample (a cluttered background
        # beyond a narrow margin correlates with the parity only by chance)
        signed = (v - np.median(v)) * parity
        agree = max(np.mean(signed > 0), np.mean(signed < 0))
        contrast.append(abs(float(np.mean(signed))) if agree >= 0.85 else 0.0)
    outer, beyond = np.array(contrast[:4]), np.array(contrast[4:])
    with np.errstate(invalid="ignore"):
        return bool(np.any(beyond > 0.5 * outer))


# how far past the marker's edge the paint reaches, as a share of the gap to the
# square's edge (docs/decisions/calibration-model-choice.md): 0.8 clipped the
# square's blurred edges, 0.1-0.2 left the marker's at blur 1.2 px; 0.35 and 0.5
# were best on the tuning sets, 0.35 at blur 1.2
PAINT_GROW = 0.35


def _p95(v: np.ndarray):
    """``np.percentile(v, 95)`` of a 1-D array by a partial sort (the same
    linear interpolation, in the same arithmetic: numpy's ``_lerp`` with a
    Python-float weight), without ``percentile``'s ~0.1 ms of bookkeeping a
    call, which was half the painting's time.

    >>> v = np.array([0, 10, 20, 30, 40, 250], np.uint8)
    >>> float(_p95(v)) == float(np.percentile(v, 95))
    True
    """
    n = v.size
    vi = (n - 1) * 0.95
    lo = int(vi)
    hi = min(lo + 1, n - 1)
    if v.dtype == np.uint8:  # the order statistics from the histogram: no copy, no sort
        a, b = np.searchsorted(np.bincount(v, minlength=256).cumsum(), (lo, hi), side="right").astype(np.uint8)
    else:
        part = np.partition(v, (lo, hi))
        a, b = part[lo], part[hi]
    t = vi - lo
    d = b - a
    return a + d * t if t < 0.5 else b - d * (1 - t)


def _paint_out_markers(gray: np.ndarray, marker_corners, square_over_marker: float) -> np.ndarray:
    """A copy of ``gray`` with each ArUco marker covered by its white square's
    level (95th percentile inside the square), out to ``PAINT_GROW`` of the
    way from the marker's edge to the square's, so the marker's edges
    (blurred) vanish and the square's own edges, which locate the corner, keep
    their blurred profile (corner RMS on the 640x480 ChArUco renders: 0.034 px,
    a checkerboard's 0.037; the detector's own 0.13)."""
    import cv2

    out = gray.copy()
    if marker_corners is None or len(marker_corners) == 0:
        return out
    h, w = gray.shape
    grow = 1 + PAINT_GROW * (square_over_marker - 1)
    # the geometry of every marker at once; only the two fills stay per marker
    q = np.asarray(marker_corners, np.float64).reshape(-1, 4, 2)
    c = q.mean(axis=1, keepdims=True)
    sq = c + (q - c) * square_over_marker
    lo = np.maximum(np.floor(sq.min(axis=1)).astype(int), 0)
    hi = np.minimum(np.ceil(sq.max(axis=1)).astype(int) + 1, (w, h))
    sq16 = np.round((sq - lo[:, None]) * 16).astype(np.int32)
    fill16 = np.round((c + (q - c) * grow) * 16).astype(np.int32)
    for k in np.flatnonzero(np.all(hi > lo, axis=1)):
        (x0, y0), (x1, y1) = lo[k], hi[k]
        # the square's own box only: a whole-image mask per marker costs 10x the detection
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(mask, sq16[k], 1, lineType=cv2.LINE_8, shift=4)
        inside = gray[y0:y1, x0:x1][mask.view(bool)]
        if inside.size == 0:
            continue
        cv2.fillConvexPoly(out, fill16[k], int(_p95(inside)), lineType=cv2.LINE_AA, shift=4)
    return out


# Marker removal by a forward model (docs/decisions/charuco-marker-removal.md).
# Painting a marker out leaves its blurred edge beyond the paint: at 320 px a
# marker sits 1.8-3 px from its square's edges, and the dark fringe that the
# paint cannot reach lies at different pixel distances from a corner on the
# near and the far side of a tilted board, so the refined corners leaned
# towards the near side (-0.005 px, focal 0.17 % on one 320 px set). Instead
# each marker is rendered (its bits through the homography of its square's
# refined corners, integrated over the pixel, blurred by the image's blur, which
# is fitted on the markers themselves) and its fitted contrast added back.
MARKER_BLURS = (0.3, 0.5, 0.75, 1.1, 1.6, 2.5)  # px, candidate Gaussian sigmas (then a parabola)
# samples per pixel side when rendering a marker's coverage: no farther apart than one texel
# (whose bilinear ramp then makes the sum a pixel's box integral), 2..4
_MARKER_SS = (2, 4)
_TEXELS_PER_BIT = 8
# a corner moved by more than this by the second refinement keeps its first one
# (the model then misses something: a marker the detector confused, an occlusion)
MAX_MARKER_MOVE_PX = 0.5


@lru_cache(maxsize=8)
def _marker_layout(board: BoardSpec):
    """Each marker's board corners ``(M, 4, 2)``, its square ``(i, j)`` and its
    darkness texture (1 on black bits and the border, 0 on white bits), as
    ``cv2.aruco`` draws it: corner 0 top-left, rows along the board's y."""
    import cv2

    cb = board._charuco()
    obj = np.asarray(cb.getObjPoints(), np.float64)[:, :, :2]
    d = cb.getDictionary()
    side = (d.markerSize + 2) * _TEXELS_PER_BIT
    texs = tuple(1.0 - cv2.aruco.generateImageMarker(d, int(i), side, borderBits=1).astype(np.float32) / 255.0
                 for i in np.asarray(cb.getIds()).ravel())
    squares = np.floor(obj.mean(axis=1) / board.square).astype(int)
    return obj, squares, texs, side


@lru_cache(maxsize=8)
def _marker_blocks(board: BoardSpec):
    """Per marker, the board's fixed part of the homography choice: its
    square's four inner corners ``(M, 4)`` (top-left, top-right, bottom-left,
    bottom-right; -1 where the square is on the board's edge), the inner
    corners within 1.5 squares of its centre ``(M, C)`` (-1 padded), and the
    marker id -> square map."""
    obj, squares, _, _ = _marker_layout(board)
    nc, nr = board.pattern_size
    ob = board.object_points[:, :2]
    own = np.full((len(obj), 4), -1, np.int64)
    blocks = []
    for k, (i, j) in enumerate(squares):
        ids = [(jj - 1) * nc + (ii - 1) for jj in (j, j + 1) for ii in (i, i + 1)
               if 1 <= ii <= nc and 1 <= jj <= nr]
        if len(ids) == 4:
            own[k] = ids
        blocks.append(np.flatnonzero(np.all(np.abs(ob - obj[k].mean(axis=0)) <= 1.5 * board.square + 1e-9,
                                            axis=1)))
    block = np.full((len(obj), max(len(b) for b in blocks)), -1, np.int64)
    for k, b in enumerate(blocks):
        block[k, :len(b)] = b
    by_id = {int(k): (int(sq[0]), int(sq[1]))
             for k, sq in zip(np.asarray(board._charuco().getIds()).ravel(), squares, strict=True)}
    return own, block, by_id


def _homographies_4(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """``(K, 3, 3)`` homographies from four point pairs each (``(K, 4, 2)``,
    float32 values), OpenCV ``getPerspectiveTransform``'s 8x8 system solved
    for all at once. Its products of coordinates are float32 ones (``Point2f``
    times ``Point2f``), which maps the points back only to ~1e-6 px: they are
    formed the same way here, so the two agree to double rounding.

    >>> sq = np.array([[[0.0, 0], [1, 0], [0, 1], [1, 1]]])
    >>> (_homographies_4(sq, 2 * sq + 5)[0].round(6) + 0.0).tolist()
    [[2.0, 0.0, 5.0], [0.0, 2.0, 5.0], [0.0, 0.0, 1.0]]
    """
    K = len(src)
    x, y, u, v = (np.asarray(a, np.float32) for a in (src[..., 0], src[..., 1], dst[..., 0], dst[..., 1]))
    A = np.zeros((K, 8, 8))
    A[:, :4, 0], A[:, :4, 1], A[:, :4, 2] = x, y, 1.0
    A[:, 4:, 3], A[:, 4:, 4], A[:, 4:, 5] = x, y, 1.0
    A[:, :4, 6], A[:, :4, 7] = -(x * u), -(y * u)
    A[:, 4:, 6], A[:, 4:, 7] = -(x * v), -(y * v)
    h = np.linalg.solve(A, np.concatenate([u, v], axis=1).astype(np.float64)[..., None])[..., 0]
    return np.concatenate([h, np.ones((K, 1))], axis=1).reshape(K, 3, 3)


def _remove_markers(gray: np.ndarray, ids: np.ndarray, pts: np.ndarray, board: BoardSpec):
    """``gray`` (H, W) uint8 with the markers next to the refined corners
    ``pts`` (N, 2) px (board ids ``ids``) taken out: ``(float32 image, set of
    modelled squares (i, j))``, or None when no marker could be modelled.

    A marker is modelled when its square's four corners were found (their
    homography), else from the found corners within 1.5 squares of it (at
    least 6, not collinear: partial boards). The image near each marker is
    ``a_m + A_m * (G_sigma * C_m)`` with ``C_m`` the marker's darkness
    integrated over each pixel; sigma is the one of ``MARKER_BLURS`` (refined
    by a parabola through its neighbours) with the least residual over all
    markers' insides, ``a_m, A_m`` are fitted per marker (uneven light), and
    ``A_m G_sigma * C_m`` is subtracted.

    The homographies (but for ``findHomography``'s), boxes and warps'
    matrices of all markers are computed at once, the per-marker sums of the
    blur's fit as segment sums; per marker remain the warp of its texture,
    the pixel-box average and the fill of its inside (one OpenCV call each).
    The result is bit-identical to the one-marker-at-a-time loop it replaced
    (tests/calib/test_charuco_removal_batched.py)."""
    import cv2

    h, w = gray.shape
    s, m = board.square, board.marker
    obj, squares, texs, side = _marker_layout(board)
    own, block, _ = _marker_blocks(board)
    ob = board.object_points[:, :2]
    found = np.zeros(board.n_corners + 1, bool)  # the last entry: the -1 pads, never found
    found[ids] = True
    pos = np.zeros((board.n_corners, 2))
    # getPerspectiveTransform took the corners as float32
    pos[ids] = np.asarray(pts, np.float32)
    nM = len(obj)
    H = np.zeros((nM, 3, 3))
    use = np.zeros(nM, bool)
    four = np.all(own >= 0, axis=1) & np.all(found[own], axis=1)
    if four.any():
        H[four] = _homographies_4(ob[own[four]], pos[own[four]])
        use[four] = True
    # the others: the found corners of the 1.5-square block, at least 6, not collinear
    wt = (found[block] & ~four[:, None]).astype(np.float64)
    n = wt.sum(axis=1)
    cand = np.flatnonzero(~four & (n >= 6))
    if cand.size:
        src, dst, wc = ob[block[cand]], np.zeros((cand.size, block.shape[1], 2)), wt[cand]
        pos64 = np.zeros((board.n_corners, 2))
        pos64[ids] = pts  # findHomography took them as float64
        dst[:] = pos64[block[cand]]
        nc_ = n[cand]
        cen = (src * wc[..., None]).sum(1) / nc_[:, None]
        d = (src - cen[:, None]) * wc[..., None]
        a, b, c = (d[..., 0] ** 2).sum(1), (d[..., 0] * d[..., 1]).sum(1), (d[..., 1] ** 2).sum(1)
        smallest = np.sqrt(np.maximum(0.5 * (a + c) - np.sqrt(0.25 * (a - c) ** 2 + b * b), 0))
        spread = smallest >= 0.15 * s * np.sqrt(nc_)
        # findHomography's least squares (a DLT, then Levenberg-Marquardt that
        # stops within ~1e-5 px of the minimum, once 0.02 px short of it): one call
        # per marker, as a batched Gauss-Newton would move these markers by that much
        for k, sp, sr, dr, wr in zip(cand, spread, src, dst, wc, strict=True):
            if sp:
                Hb, _ = cv2.findHomography(sr[wr > 0], dr[wr > 0], 0)
                if Hb is not None:
                    H[k], use[k] = Hb, True
    if not use.any():
        return None
    ks = np.flatnonzero(use)
    Hk = H[ks]
    q = obj[ks]  # (K, 4, 2) board
    qh = np.einsum("kij,kpj->kpi", Hk, np.concatenate([q, np.ones(q.shape[:2] + (1,))], axis=2))
    qi = qh[..., :2] / qh[..., 2:]
    pad = int(np.ceil(3 * MARKER_BLURS[-1])) + 2
    lo = np.maximum(np.floor(qi.min(axis=1)).astype(int) - pad, 0)
    hi = np.minimum(np.ceil(qi.max(axis=1)).astype(int) + pad + 1, (w, h))
    keep = np.all(hi - lo >= 2, axis=1)
    if not keep.any():
        return None
    ks, Hk, q, qi, lo, hi = ks[keep], Hk[keep], q[keep], qi[keep], lo[keep], hi[keep]
    K = len(ks)
    px = np.linalg.norm(qi - np.roll(qi, 1, axis=1), axis=2).mean(axis=1)  # marker side, px
    ss = np.clip(np.ceil(side / np.maximum(px, 1e-9)), *_MARKER_SS).astype(int)
    step = m / side
    # texel centres -> board -> image pixel centres -> the ss-times finer grid of the box
    B = np.zeros((K, 3, 3))
    B[:, 0, 0] = B[:, 1, 1] = step
    B[:, 0, 2], B[:, 1, 2] = q[:, 0, 0] + 0.5 * step, q[:, 0, 1] + 0.5 * step
    B[:, 2, 2] = 1
    up = np.zeros((K, 3, 3))
    up[:, 0, 0] = up[:, 1, 1] = ss
    up[:, 0, 2] = up[:, 1, 2] = 0.5 * (ss - 1)
    up[:, 2, 2] = 1
    shift = np.tile(np.eye(3), (K, 1, 1))
    shift[:, 0, 2], shift[:, 1, 2] = -ss * lo[:, 0], -ss * lo[:, 1]
    Mw = ((shift @ up) @ Hk) @ B
    X0, Y0 = lo.min(axis=0)
    X1, Y1 = hi.max(axis=0)
    # one region of interest holds every patch: the blurs run there only
    cov = np.zeros((Y1 - Y0, X1 - X0), np.float32)
    # 16 bits (a dictionary holds at most 1024 markers): the grouping below is then a radix sort
    label = np.zeros(cov.shape, np.uint16)
    poly = np.round((qi - (X0, Y0)) * 16).astype(np.int32)
    patches = []
    for n_, (k, (x0, y0), (x1, y1), f) in enumerate(zip(ks.tolist(), lo.tolist(), hi.tolist(), ss.tolist(),
                                                      strict=True)):
        # the padded box, not only the marker's: the warp's float32 coordinates
        # depend on the box's origin, and the smaller box was no faster
        fine = cv2.warpPerspective(texs[k], Mw[n_], ((x1 - x0) * f, (y1 - y0) * f), flags=cv2.INTER_LINEAR,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        c = cv2.resize(fine, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)  # the pixel's box
        cov[y0 - Y0:y1 - Y0, x0 - X0:x1 - X0] += c
        patches.append((x0 - X0, y0 - Y0, x1 - X0, y1 - Y0, c))
        cv2.fillConvexPoly(label, poly[n_], n_ + 1, lineType=cv2.LINE_8, shift=4)
    done = {(int(squares[k][0]), int(squares[k][1])) for k in ks}
    g = gray[Y0:Y1, X0:X1].astype(np.float32)
    # the inside pixels grouped by marker (row-major within each): per-marker
    # sums are then segment sums, 10x cheaper than weighted bincounts
    sel = np.flatnonzero(label.ravel())
    sel = sel[np.argsort(label.ravel()[sel], kind="stable")]
    lab = label.ravel()[sel]
    starts = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]])
    present = lab[starts]
    L = K + 1

    def persum(x):
        out = np.zeros(L)
        out[present] = np.add.reduceat(x, starts)
        return out

    val = g.ravel()[sel].astype(np.float64)
    cnt = np.maximum(np.bincount(lab, minlength=L), 1).astype(np.float64)
    si = persum(val)
    vi = persum(val * val) - si * si / cnt

    def fit(sigma):
        mb = cv2.GaussianBlur(cov, (0, 0), sigma).ravel()[sel].astype(np.float64)
        sm = persum(mb)
        vm = persum(mb * mb) - sm * sm / cnt
        cim = persum(val * mb) - si * sm / cnt
        ok = vm > 1e-9
        amp = np.where(ok, cim / np.where(ok, vm, 1.0), 0.0)  # the marker's (negative) contrast
        return float(np.sum((vi - amp * cim)[1:])), amp

    res = [fit(sg)[0] for sg in MARKER_BLURS]
    b = int(np.argmin(res))
    sigma = MARKER_BLURS[b]
    if 0 < b < len(MARKER_BLURS) - 1:
        # the parabola through the minimum and its neighbours (in sigma)
        xs, ys = np.array(MARKER_BLURS[b - 1:b + 2]), np.array(res[b - 1:b + 2])
        a2, a1, _ = np.polyfit(xs, ys, 2)
        if a2 > 0:
            sigma = float(np.clip(-a1 / (2 * a2), xs[0], xs[2]))
    _, amp = fit(sigma)
    dark = np.zeros(cov.shape, np.float32)
    for n_, (x0, y0, x1, y1, c) in enumerate(patches):
        dark[y0:y1, x0:x1] += np.float32(amp[n_ + 1]) * c
    out = gray.astype(np.float32)
    out[Y0:Y1, X0:X1] -= cv2.GaussianBlur(dark, (0, 0), sigma)
    return out, done


def _empty(size) -> Detection:
    return Detection(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3)), size)


# the painted refinement alone: False reproduces the corners before the markers were modelled
REMOVE_MARKERS = True


def _refine_without_markers(gray, ids, pts, mcorners, mids, board, win):
    """The corners ``pts`` (refined on the painted image) refined again on
    ``gray`` with the markers rendered and subtracted (:func:`_remove_markers`).
    A corner keeps its first refinement when one of its two white squares'
    markers could not be modelled (the paint would then be in its window, and
    a mix of the two is biased either way) or when it moved by more than
    ``MAX_MARKER_MOVE_PX``. Detected markers that were not modelled are painted
    out as before."""
    import cv2

    removed = _remove_markers(gray, ids, pts, board)
    if removed is None:
        return pts
    clean, done = removed
    by_id = _marker_blocks(board)[2]
    if mcorners is not None and mids is not None and len(mcorners):
        left = [c for c, k in zip(mcorners, np.asarray(mids).ravel(), strict=True)
                if by_id.get(int(k)) not in done]
        if left:
            clean = _paint_out_markers(clean, left, board.square / board.marker)
    new = cv2.cornerSubPix(clean, pts.astype(np.float32).reshape(-1, 1, 2), (win, win), (-1, -1),
                           _SUBPIX_CRITERIA).reshape(-1, 2).astype(np.float64)
    nc = board.cols - 1
    ii, jj = ids % nc + 1, ids // nc + 1  # the corner is the top-left of square (ii, jj)
    # its window holds squares (ii-1..ii, jj-1..jj); the white ones ((i + j) odd) carry markers
    grid = np.zeros((board.cols, board.rows), bool)
    grid[tuple(np.array(sorted(done)).T)] = True
    sx, sy = np.stack([ii - 1, ii, ii - 1, ii]), np.stack([jj - 1, jj - 1, jj, jj])
    ok = np.all(grid[sx, sy] | ((sx + sy) % 2 == 0), axis=0)
    ok &= np.linalg.norm(new - pts, axis=1) < MAX_MARKER_MOVE_PX
    out = pts.copy()
    out[ok] = new[ok]
    return out


# The last step of ChArUco detection (docs/decisions/charuco-marker-removal.md, "The
# model fit"): the blurred X-junction model (calib/rohr1992.py) fitted to each corner's
# pixels, the pixels near a marker left out. The model describes the image itself, so
# nothing is subtracted: fitted on the image with the markers removed it gave the same
# corners. False: cornerSubPix on the image with the markers subtracted (REMOVE_MARKERS).
FIT_MODEL = True
# The model's window: cornerSubPix's half-window (40 % of the corner spacing), at most
# this, px (the junction's edges are straight over it even on a strongly tilted board).
FIT_RADIUS_MAX = 4
# Pixels nearer a marker than this many of the image's blur sigmas, plus half a pixel
# (the pixel's own half-width), stay out of the fit: the marker's blurred edge there is
# below Phi(-2) = 2.3 % of its contrast.
FIT_MARKER_CLEARANCE = 2.0
# The blur assumed for the first fit's mask (generous: that pass only measures the blur),
# on at most this many corners, with at most this many steps (a blur to ~0.05 px, where
# the clearance moves by 0.1 px).
_FIT_FIRST_BLUR = 1.2
_FIT_BLUR_CORNERS = 12
_FIT_BLUR_ITERATIONS = 6


def _marker_quads(ids: np.ndarray, pts: np.ndarray, board: BoardSpec, mcorners) -> np.ndarray:
    """``(K, 4, 2)`` image corners of the markers next to the found corners
    ``pts`` (board ids ``ids``): each marker whose square's four inner corners
    were found, through that square's homography (so a marker the ArUco
    detector missed is there too), and every detected one (``mcorners``;
    the squares on the board's edge have no four corners)."""
    obj, _, _, _ = _marker_layout(board)
    own, _, _ = _marker_blocks(board)
    found = np.zeros(board.n_corners + 1, bool)  # the last entry: the -1 pads, never found
    found[ids] = True
    pos = np.zeros((board.n_corners, 2))
    pos[ids] = pts
    four = np.all(own >= 0, axis=1) & np.all(found[own], axis=1)
    quads = []
    if four.any():
        H = _homographies_4(board.object_points[:, :2][own[four]], pos[own[four]])
        q = obj[four]
        qh = np.einsum("kij,kpj->kpi", H, np.concatenate([q, np.ones(q.shape[:2] + (1,))], axis=2))
        quads.append(qh[..., :2] / qh[..., 2:])
    if mcorners is not None and len(mcorners):
        quads.append(np.asarray(mcorners, np.float64).reshape(-1, 4, 2))
    return np.concatenate(quads) if quads else np.zeros((0, 4, 2))


def _away_from_markers(shape, quads, pts, radius, clear) -> np.ndarray:
    """``(H, W)`` bool: True where a pixel lies farther than ``clear`` px from
    every marker ``quads``. Computed only on the region that holds the windows
    (``radius``) of the corners ``pts`` and every marker pixel within ``clear``
    of them: a distance transform of a whole 960x720 image costs ~4 ms."""
    import cv2

    reach = radius + int(np.ceil(clear)) + 2
    x0, y0 = np.maximum(np.floor(pts.min(axis=0)).astype(int) - reach, 0)
    x1, y1 = np.minimum(np.ceil(pts.max(axis=0)).astype(int) + reach + 1, shape[::-1])
    near = np.zeros((y1 - y0, x1 - x0), np.uint8)
    for q in np.round((quads - (x0, y0)) * 16).astype(np.int32):
        cv2.fillConvexPoly(near, q, 1, lineType=cv2.LINE_8, shift=4)
    valid = np.zeros(shape, bool)
    valid[y0:y1, x0:x1] = cv2.distanceTransform(1 - near, cv2.DIST_L2, 3) > clear
    return valid


def _fit_charuco(gray, ids, pts, mcorners, board, win):
    """``(corners, fallbacks)``: the corners ``pts`` (refined on the painted
    image) fitted by the X-junction model on ``gray`` with the pixels within
    ``FIT_MARKER_CLEARANCE`` blurs of a marker left out. The blur is the
    corners' own: a first fit of a dozen corners with a generous mask
    (``_FIT_FIRST_BLUR``) measures it (median fitted ``s``, less the pixel
    box's 1/12 px^2), the fit of all corners uses it. A corner whose fit fails
    keeps ``pts``."""
    from lumigraph.calib.rohr1992 import fit_corners

    quads = _marker_quads(ids, pts, board, mcorners)
    radius = int(min(win, FIT_RADIUS_MAX))
    # the blur is one number per image: a dozen corners spread over the board measure it
    few = pts[np.unique(np.linspace(0, len(pts) - 1, min(len(pts), _FIT_BLUR_CORNERS)).astype(int))]
    f = fit_corners(gray, few, radius=radius, iterations=_FIT_BLUR_ITERATIONS,
                    valid=_away_from_markers(gray.shape, quads, few, radius,
                                             FIT_MARKER_CLEARANCE * _FIT_FIRST_BLUR + 0.5))
    s = float(np.median(f.blur[f.ok])) if f.ok.any() else np.sqrt(_FIT_FIRST_BLUR ** 2 + 1 / 12)
    blur = float(np.sqrt(max(s * s - 1 / 12, 0.04)))
    f = fit_corners(gray, pts, radius=radius, blur=s,
                    valid=_away_from_markers(gray.shape, quads, pts, radius, FIT_MARKER_CLEARANCE * blur + 0.5))
    return f.points, int((~f.ok).sum())


def detect(image: np.ndarray, board: BoardSpec) -> Detection:
    """Find the board's inner corners in one image.

    Parameters
    ----------
    image : ndarray, (H, W) or (H, W, C), uint8/uint16
    board : BoardSpec

    Returns
    -------
    Detection
        Empty (``len(d) == 0``) when the board is not in the image: an image
        without a board is an expected case that callers skip and name.
    """
    import cv2

    gray = to_gray8(image)
    h, w = gray.shape
    if board.kind == "charuco":
        det = cv2.aruco.CharucoDetector(board._charuco())
        corners, ids, mcorners, mids = det.detectBoard(gray)
        if ids is None or len(ids) < 6:
            return _empty((w, h))
        ids = ids.ravel().astype(np.int64)
        pts = corners.reshape(-1, 2).astype(np.float32)
        # The detector's refinement errs by ~0.1-0.2 px (3-5x a checkerboard's):
        # cornerSubPix either sees the markers' edges (which pull the corner) or,
        # kept inside the marker-free margin, too few pixels. The markers are
        # found, so paint them out with their square's white and refine as on a
        # plain checkerboard, with the checkerboard's window.
        painted = _paint_out_markers(gray, mcorners, board.square / board.marker)
        dist = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        np.fill_diagonal(dist, np.inf)
        win = int(np.clip(np.floor(0.4 * np.median(dist.min(axis=1))), 2, 10))
        pts = cv2.cornerSubPix(painted, pts.reshape(-1, 1, 2), (win, win), (-1, -1),
                               _SUBPIX_CRITERIA).reshape(-1, 2).astype(np.float64)
        fallbacks = 0
        if FIT_MODEL:
            pts, fallbacks = _fit_charuco(gray, ids, pts, mcorners, board, win)
        elif REMOVE_MARKERS:
            pts = _refine_without_markers(gray, ids, pts, mcorners, mids, board, win)
        return Detection(ids, pts, board.object_points[ids], (w, h), fallbacks)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, pts = False, None
    if max(w, h) > 1000:  # search on a 2x-reduced copy; refine on the full image
        small = cv2.resize(gray, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        found, pts = cv2.findChessboardCorners(small, board.pattern_size, flags=flags)
        if found:
            pts = pts.reshape(-1, 2) * 2.0 + 0.5
    if not found:
        found, pts = cv2.findChessboardCorners(gray, board.pattern_size, flags=flags)
        if not found:
            return _empty((w, h))
    pts = pts.reshape(-1, 2).astype(np.float32)
    win = subpix_window(pts, board.pattern_size)
    pts = cv2.cornerSubPix(gray, pts.reshape(-1, 1, 2), (win, win), (-1, -1),
                           _SUBPIX_CRITERIA).reshape(-1, 2)
    pts = _orient(gray, pts.astype(np.float64), board)
    if _pattern_continues(gray, pts, board):
        return _empty((w, h))
    ids = np.arange(board.n_corners, dtype=np.int64)
    return Detection(ids, pts, board.object_points, (w, h))
