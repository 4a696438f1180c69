"""The ChArUco marker removal as first written (calib/detect.py before the
batched rewrite of issue 14's follow-up): one marker at a time, padded
boxes, ``np.percentile``. Kept verbatim as the reference the batched code
must reproduce (tests/calib/test_charuco_removal_batched.py); not used by
the library."""

import numpy as np

from lumigraph.calib.detect import (
    _MARKER_SS,
    _SUBPIX_CRITERIA,
    MARKER_BLURS,
    MAX_MARKER_MOVE_PX,
    PAINT_GROW,
    BoardSpec,
    _marker_layout,
)


def _paint_out_markers(gray: np.ndarray, marker_corners, square_over_marker: float) -> np.ndarray:
    """A copy of ``gray`` with each ArUco marker covered by its white square's
    level (95th percentile inside the square), out to ``PAINT_GROW`` of the
    way from the marker's edge to the square's, so the marker's edges
    (blurred) vanish and the square's own edges, which locate the corner, keep
    their blurred profile (corner RMS on the 640x480 ChArUco renders: 0.034 px,
    a checkerboard's 0.037; the detector's own 0.13)."""
    import cv2

    out = gray.copy()
    h, w = gray.shape
    grow = 1 + PAINT_GROW * (square_over_marker - 1)
    for q in marker_corners or ():
        q = np.asarray(q, np.float64).reshape(4, 2)
        c = q.mean(axis=0)
        sq = c + (q - c) * square_over_marker
        x0, y0 = np.maximum(np.floor(sq.min(axis=0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(sq.max(axis=0)).astype(int) + 1, (w, h))
        if x1 <= x0 or y1 <= y0:
            continue
        # the square's own box only: a whole-image mask per marker costs 10x the detection
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(mask, np.round((sq - (x0, y0)) * 16).astype(np.int32), 1,
                           lineType=cv2.LINE_8, shift=4)
        inside = gray[y0:y1, x0:x1][mask > 0]
        if inside.size == 0:
            continue
        white = int(np.percentile(inside, 95))
        fill = np.round((c + (q - c) * grow) * 16).astype(np.int32)
        cv2.fillConvexPoly(out, fill, white, lineType=cv2.LINE_AA, shift=4)
    return out


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
    ``A_m G_sigma * C_m`` is subtracted."""
    import cv2

    h, w = gray.shape
    s, m = board.square, board.marker
    nc, nr = board.pattern_size
    obj, squares, texs, side = _marker_layout(board)
    ob = board.object_points[:, :2]
    found = np.zeros(board.n_corners, bool)
    found[ids] = True
    pos = np.zeros((board.n_corners, 2))
    pos[ids] = pts
    pad = int(np.ceil(3 * MARKER_BLURS[-1])) + 2
    step = m / side
    patches, done = [], []
    for k in range(len(obj)):
        i, j = squares[k]
        own = [(jj - 1) * nc + (ii - 1) for jj in (j, j + 1) for ii in (i, i + 1)
               if 1 <= ii <= nc and 1 <= jj <= nr]
        if len(own) == 4 and found[own].all():
            H = cv2.getPerspectiveTransform(ob[own].astype(np.float32), pos[own].astype(np.float32))
        else:
            c = obj[k].mean(axis=0)
            blk = np.flatnonzero(found & np.all(np.abs(ob - c) <= 1.5 * s + 1e-9, axis=1))
            if blk.size < 6:
                continue
            src, dst = ob[blk], pos[blk]
            if np.linalg.svd(src - src.mean(axis=0), compute_uv=False)[-1] < 0.15 * s * np.sqrt(blk.size):
                continue
            H, _ = cv2.findHomography(src, dst, 0)
            if H is None:
                continue
        q = obj[k]
        qi = cv2.perspectiveTransform(q[None], H)[0]
        x0, y0 = np.maximum(np.floor(qi.min(axis=0)).astype(int) - pad, 0)
        x1, y1 = np.minimum(np.ceil(qi.max(axis=0)).astype(int) + pad + 1, (w, h))
        if x1 - x0 < 2 or y1 - y0 < 2:
            continue
        px = np.mean(np.linalg.norm(qi - np.roll(qi, 1, axis=0), axis=1))  # marker side, px
        ss = int(np.clip(np.ceil(side / max(px, 1e-9)), *_MARKER_SS))
        up = np.array([[ss, 0, 0.5 * (ss - 1)], [0, ss, 0.5 * (ss - 1)], [0, 0, 1]])
        # texel centres -> board -> image pixel centres -> the ss-times finer grid of this box
        B = np.array([[step, 0, q[0, 0] + 0.5 * step], [0, step, q[0, 1] + 0.5 * step], [0, 0, 1]])
        shift = np.array([[1, 0, -ss * x0], [0, 1, -ss * y0], [0, 0, 1.0]])
        fine = cv2.warpPerspective(texs[k], shift @ up @ H @ B, ((x1 - x0) * ss, (y1 - y0) * ss),
                                   flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        cov = cv2.resize(fine, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)  # the pixel's box
        inside = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(inside, np.round((qi - (x0, y0)) * 16).astype(np.int32), 1,
                           lineType=cv2.LINE_8, shift=4)
        patches.append((x0, y0, x1, y1, cov, inside > 0))
        done.append((int(i), int(j)))
    if not patches:
        return None
    # one region of interest holds every patch: the blurs run there only
    X0, Y0 = min(p[0] for p in patches), min(p[1] for p in patches)
    X1, Y1 = max(p[2] for p in patches), max(p[3] for p in patches)
    cov = np.zeros((Y1 - Y0, X1 - X0), np.float32)
    label = np.zeros(cov.shape, np.int32)
    for n, (x0, y0, x1, y1, c, ins) in enumerate(patches):
        cov[y0 - Y0:y1 - Y0, x0 - X0:x1 - X0] += c
        label[y0 - Y0:y1 - Y0, x0 - X0:x1 - X0][ins] = n + 1
    g = gray[Y0:Y1, X0:X1].astype(np.float32)
    sel = label.ravel() > 0
    lab = label.ravel()[sel]
    val = g.ravel()[sel].astype(np.float64)
    L = len(patches) + 1
    cnt = np.maximum(np.bincount(lab, minlength=L), 1).astype(np.float64)
    si = np.bincount(lab, val, L)
    vi = np.bincount(lab, val * val, L) - si * si / cnt

    def fit(sigma):
        mb = cv2.GaussianBlur(cov, (0, 0), sigma).ravel()[sel].astype(np.float64)
        sm = np.bincount(lab, mb, L)
        vm = np.bincount(lab, mb * mb, L) - sm * sm / cnt
        cim = np.bincount(lab, val * mb, L) - si * sm / cnt
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
    for n, (x0, y0, x1, y1, c, _ins) in enumerate(patches):
        dark[y0 - Y0:y1 - Y0, x0 - X0:x1 - X0] += np.float32(amp[n + 1]) * c
    out = gray.astype(np.float32)
    out[Y0:Y1, X0:X1] -= cv2.GaussianBlur(dark, (0, 0), sigma)
    return out, set(done)


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
    _, squares, _, _ = _marker_layout(board)
    if mcorners is not None and mids is not None and len(mcorners):
        by_id = {int(k): tuple(sq) for k, sq in zip(np.asarray(board._charuco().getIds()).ravel(), squares,
                                                        strict=True)}
        left = [c for c, k in zip(mcorners, np.asarray(mids).ravel(), strict=True)
                if by_id.get(int(k)) not in done]
        if left:
            clean = _paint_out_markers(clean, left, board.square / board.marker)
    new = cv2.cornerSubPix(clean, pts.astype(np.float32).reshape(-1, 1, 2), (win, win), (-1, -1),
                           _SUBPIX_CRITERIA).reshape(-1, 2).astype(np.float64)
    nc = board.cols - 1
    ii, jj = ids % nc + 1, ids // nc + 1  # the corner is the top-left of square (ii, jj)
    # its window holds squares (ii-1..ii, jj-1..jj); the white ones ((i + j) odd) carry markers
    ok = np.array([all((x, y) in done for x in (a - 1, a) for y in (b - 1, b) if (x + y) % 2 == 1)
                   for a, b in zip(ii.tolist(), jj.tolist(), strict=True)], bool)
    ok &= np.linalg.norm(new - pts, axis=1) < MAX_MARKER_MOVE_PX
    out = pts.copy()
    out[ok] = new[ok]
    return out
