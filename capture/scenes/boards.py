"""Calibration targets: checkerboard and ChArUco boards in N poses, seen by a
camera (or a stereo rig) with known intrinsics and lens distortion.

Two scenes:

``boards``
    One camera, ``--views`` poses of a ``--board checker`` or ``charuco``
    target. ``--distortion`` picks the lens (``none``, ``normal``: moderate
    radial k1–k3 plus tangential, ``strong``: k1 = −0.3); ``--poses varied``
    (tilts 25–50° about random in-plane axes, positions spread over the
    image) or ``fronto`` (a near-degenerate set: every board within 3° of
    fronto-parallel).
``boards-stereo``
    The same targets seen by two cameras (each with its own K and
    distortion), the right one ``x_right = R x_left + T`` with a horizontal
    baseline of ``--baseline`` board units and a small rotation. ``--rig
    stereo-pair-rectified`` (or ``stereo-pair-unrectified``) renders them
    instead with the cameras and pose of the ``stereo-pair`` scene in that
    layout (:func:`capture.scenes.stereo.pair_rig`), so the calibration chain
    can end in that pair; give ``--baseline`` and ``--square`` in the pair's
    metres.

The camera is deliberately asymmetric (``fx != fy``, principal point off the
image centre in both axes) so a swapped argument or a transposed matrix shows.

Board frame (both kinds, as OpenCV's ``CharucoBoard``): origin at the top-left
OUTER corner of the squared area, x along columns, y along rows, z = 0 on the
board (into the board away from a camera that faces it); square ``(i, j)`` (column,
row) is black when ``i + j`` is even. A ``C × R``-square board has
``(C-1)(R-1)`` inner corners at ``((i+1) s, (j+1) s)``, row-major (x fastest),
the order ``findChessboardCorners((C-1, R-1))`` and ChArUco ids use. A white
margin of one square surrounds the squares.

Rendering is exact resampling through the forward model: for each of the
``ss × ss`` sub-pixel samples of every pixel the distorted pixel is unprojected
with :meth:`capture.camera.Camera.unproject` (shared by all views of a camera),
intersected with the board plane (a homography of the undistorted normalised
coordinates), and the checker is integrated analytically over the sample's
footprint on the board (a box filter: the integral of a square wave is a
triangle wave), so corner positions carry no sampling bias. ChArUco markers come
from ``cv2.aruco``'s board image (bilinear lookup; they never touch a corner).
Then Gaussian blur (optics), Gaussian read noise and 8-bit quantisation.

Ground truth: ``gt.json`` holds the board spec (the ``--board`` string of
``lumigraph calib calibrate``), the camera(s) in the ``camera.json`` layout,
each view's ``cam_from_world`` pose (world = board frame) and the rig;
``gt/corners.npy`` ``(V, N, 2)`` float64 the exact distorted pixel positions
of every inner corner in every view (``corners_left``/``corners_right`` for
the rig), ``gt/object_points.npy`` ``(N, 3)``.

Examples
--------
>>> s = render_boards(size=(160, 120), seed=0, rng=np.random.default_rng(0), views=2)
>>> len(s.images), s.images[0].shape, s.gt_arrays["corners"].shape
(2, (120, 160), (2, 54, 2))
"""

from __future__ import annotations

import numpy as np

from lumigraph.capture.errors import InputError
from lumigraph.capture.render import Option, RenderedScene, SceneSpec

# lenses, as distortion (k1, k2, p1, p2, k3)
_DISTORTION = {
    "none": (0.0, 0.0, 0.0, 0.0, 0.0),
    "normal": (-0.12, 0.045, 6e-4, -4e-4, -0.01),
    "strong": (-0.30, 0.09, 8e-4, -5e-4, -0.012),
}
_BLACK, _WHITE, _BACKGROUND = 0.07, 0.86, 0.35


def camera_for(size: tuple[int, int], distortion: str, *, which: str = "left"):
    """The scene's camera for an image size: fx ≈ 0.9 w (a ~58° lens), fy
    1.5 % shorter, principal point off centre by (+2.7 %, −2.3 %) of the size."""
    from lumigraph.capture.camera import Camera

    w, h = size
    f = 0.9 * w
    if which == "left":
        K = [[f, 0, 0.5 * (w - 1) + 0.027 * w], [0, 0.985 * f, 0.5 * (h - 1) - 0.023 * h], [0, 0, 1]]
        dist = _DISTORTION[distortion]
    else:
        K = [[1.012 * f, 0, 0.5 * (w - 1) - 0.018 * w], [0, 0.999 * f, 0.5 * (h - 1) + 0.015 * h],
             [0, 0, 1]]
        dist = tuple(0.8 * v for v in _DISTORTION[distortion])
    model = "none" if distortion == "none" else "k1k2p1p2k3"
    return Camera(np.array(K, float), np.array(dist, float), (w, h), model)


def board_spec(board: str, cols: int, rows: int, square: float) -> dict:
    """Board description; ``spec`` is the ``--board`` string of ``lumigraph calib``."""
    if board == "checker":
        return {"kind": "checker", "cols": cols, "rows": rows, "square": square,
                "spec": f"checker:{cols}x{rows}:{square:g}"}
    marker = 0.75 * square
    return {"kind": "charuco", "cols": cols, "rows": rows, "square": square, "marker": marker,
            "dictionary": "DICT_4X4_250",
            "spec": f"charuco:{cols}x{rows}:{square:g}:{marker:g}:DICT_4X4_250"}


def inner_corners(cols: int, rows: int, square: float) -> np.ndarray:
    """``((cols-1)(rows-1), 3)`` board-frame inner corners, row-major (x fastest)."""
    j, i = np.mgrid[1:rows, 1:cols]
    return np.column_stack([i.ravel() * square, j.ravel() * square, np.zeros(i.size)]).astype(float)


def _rot(axis, angle):
    import cv2

    a = np.asarray(axis, float)
    return cv2.Rodrigues(a / np.linalg.norm(a) * angle)[0]


def _fov_radius(cam) -> float:
    """Undistorted radius of the nearest image corner: inside it the distortion
    polynomial is monotonic, so projections there are trustworthy."""
    w, h = cam.image_size
    rim = cam.unproject(np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], float))[:, :2]
    return float(np.hypot(rim[:, 0], rim[:, 1]).min())


def _visible(cam, fov, R, t, pts, margin_px) -> bool:
    Xc = pts @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        return False
    xy = Xc[:, :2] / Xc[:, 2:3]
    w, h = cam.image_size
    if np.any(np.hypot(xy[:, 0], xy[:, 1]) > 0.98 * fov):
        return False
    px = cam.project(Xc)
    return bool(np.all((px >= margin_px) & (px <= np.array([w - 1, h - 1]) - margin_px)))


def _sample_poses(rng, cams, spec, views, poses):
    """Board poses ``cam_from_board`` (of the first camera) keeping the whole board
    plus half its margin in every camera's image: stratified target positions,
    tilts and rolls drawn from ``rng`` (rejection sampling)."""
    cols, rows, s = spec["cols"], spec["rows"], spec["square"]
    bw, bh = cols * s, rows * s
    outline = np.array([[-0.5 * s, -0.5 * s, 0], [bw + 0.5 * s, -0.5 * s, 0],
                        [-0.5 * s, bh + 0.5 * s, 0], [bw + 0.5 * s, bh + 0.5 * s, 0],
                        [0.5 * bw, -0.5 * s, 0], [0.5 * bw, bh + 0.5 * s, 0],
                        [-0.5 * s, 0.5 * bh, 0], [bw + 0.5 * s, 0.5 * bh, 0]])
    centre = np.array([0.5 * bw, 0.5 * bh, 0.0])
    cam0 = cams[0][0]
    w, h = cam0.image_size
    fovs = [_fov_radius(c) for c, _, _ in cams]
    cells = rng.permutation(9)
    # tilt-axis directions stratified over the views (one per 360/V deg sector, in random
    # order) so the board normals fan out in every direction, not by the luck of the draw
    sectors = rng.permutation(views)
    out = []
    for k in range(views):
        for attempt in range(400):
            # pull the target towards the centre, and shrink the board, if a cell proves hard to fill
            pull = max(0.0, 1.0 - attempt / 300)
            shrink = 1.0 - 0.4 * max(0.0, attempt - 100) / 300
            cell = cells[k % 9]
            if poses == "varied":
                # The principal point is pinned by perspective foreshortening (Zhang 2000,
                # sec. 3.3: constraints come from the planes' differing orientations) and
                # by the distortion seen toward the image edges and corners, and its standard
                # deviation falls as sigma / sqrt(corners). So: boards filling 80-100 % of
                # the width, centres spread to +-40 % of the frame (views reach the corners
                # and edges), tilts 20-50 deg about axes in every direction. With a 19x14
                # board at 1280x960 and 0.2 px corner noise this gives sigma(cx) ~ 0.21 px,
                # sigma(cy) ~ 0.16 px (from the fit's covariance; calib/bench.py).
                spread, jitter = (0.4, 0.06) if len(cams) == 1 else (0.22, 0.08)
                tilt = np.deg2rad(rng.uniform(20, 50))
                # a rig's board must fit both views (shifted by the baseline): smaller
                frac = rng.uniform(*((0.8, 1.0) if len(cams) == 1 else (0.5, 0.7))) * shrink
                phi = 2 * np.pi * (sectors[k] + rng.uniform()) / views
            else:
                spread, jitter = 0.21, 0.08
                tilt = np.deg2rad(rng.uniform(0.5, 3.0))
                frac = rng.uniform(0.45, 0.6) * shrink
                phi = rng.uniform(0, 2 * np.pi)
            off = np.array([(cell % 3 - 1) * spread + rng.uniform(-jitter, jitter),
                            (cell // 3 - 1) * spread + rng.uniform(-jitter, jitter)])
            target = np.array([w, h]) * (0.5 + pull * off)
            roll = np.deg2rad(rng.uniform(-20, 20))
            R = _rot([np.cos(phi), np.sin(phi), 0.0], tilt) @ _rot([0, 0, 1], roll)
            dist = cam0.K[0, 0] * bw / (frac * w)
            ray = cam0.unproject(target[None])[0]
            t = ray / ray[2] * dist - R @ centre
            if all(_visible(c, fov, Rc @ R, Rc @ t + tc, outline, 2.0)
                   for (c, Rc, tc), fov in zip(cams, fovs, strict=True)):
                out.append((R, t))
                break
        else:
            # the options together leave no pose in view (not our fault: the user's choice)
            raise InputError("size", "could not place the board in view of every camera; use a "
                                     "larger image, fewer squares or a shorter baseline")
    return out


def _box_square_wave(p, half):
    """Mean of the ±1 square wave (period 2, +1 on [0, 1)) over ``[p-half, p+half]``,
    via its integral, the triangle wave ``1 - |(p mod 2) - 1|``."""
    def tri(q):
        return 1.0 - np.abs(np.mod(q, 2.0) - 1.0)

    h = np.maximum(half, 1e-6)
    avg = (tri(p + h) - tri(p - h)) / (2 * h)
    sq = np.where(np.mod(p, 2.0) < 1.0, 1.0, -1.0)
    return np.where(half > 1e-4, avg, sq)


def _box_interval(p, half, lo, hi):
    """Fraction of ``[p-half, p+half]`` inside ``[lo, hi]``."""
    h = np.maximum(half, 1e-9)
    return np.clip((np.minimum(p + h, hi) - np.maximum(p - h, lo)) / (2 * h), 0.0, 1.0)


def _marker_texture(spec):
    import cv2

    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec["dictionary"]))
    board = cv2.aruco.CharucoBoard((spec["cols"], spec["rows"]), spec["square"], spec["marker"], d)
    pps = 48  # texels per square: markers of a 4x4 dictionary get 6 cells of ~7 texels
    img = board.generateImage((spec["cols"] * pps, spec["rows"] * pps), marginSize=0, borderBits=1)
    tex = img.astype(np.float32) / 255.0
    # keep only the markers: black squares become white (the checker is analytic)
    j, i = np.mgrid[0:spec["rows"], 0:spec["cols"]]
    black = np.kron(((i + j) % 2 == 0).astype(np.uint8), np.ones((pps, pps), np.uint8)).astype(bool)
    tex[black] = 1.0
    return tex, pps


def _render_view(nxy, shape, ss, R, t, spec, marker_tex, cam):
    """Radiance in [0, 1] of one view from the undistorted normalised sample
    coordinates ``nxy`` (H*ss, W*ss, 2); only the board's bounding box is traced,
    the rest is the uniform background."""
    import cv2

    h, w = shape
    s = spec["square"]
    cols, rows = spec["cols"], spec["rows"]
    img = np.full((h, w), _BACKGROUND, np.float64)
    edge = np.linspace(0, 1, 41)
    loop = np.concatenate([np.column_stack([edge, 0 * edge]), np.column_stack([1 + 0 * edge, edge]),
                           np.column_stack([edge, 1 + 0 * edge]), np.column_stack([0 * edge, edge])])
    outline = np.column_stack([(loop[:, 0] * (cols + 2) - 1) * s, (loop[:, 1] * (rows + 2) - 1) * s,
                               np.zeros(len(loop))])
    px = cam.project_world(outline, R, t)
    x0, y0 = np.floor(np.nanmin(px, axis=0)).astype(int) - 3
    x1, y1 = np.ceil(np.nanmax(px, axis=0)).astype(int) + 4
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    sub = nxy[y0 * ss:y1 * ss, x0 * ss:x1 * ss].reshape(-1, 2)
    H = np.column_stack([R[:, 0], R[:, 1], t])  # (x, y, 1) ~ H (u, v, 1)
    Hi = np.linalg.inv(H)
    hom = sub @ Hi[:, :2].T + Hi[:, 2]
    shp = ((y1 - y0) * ss, (x1 - x0) * ss)
    with np.errstate(divide="ignore", invalid="ignore"):
        pu = (hom[:, 0] / (hom[:, 2] * s)).reshape(shp)
        pv = (hom[:, 1] / (hom[:, 2] * s)).reshape(shp)
    back = (hom[:, 2] <= 0).reshape(shp)
    pu[back] = -1e6
    pv[back] = -1e6
    # footprint of one sample on the board (sample spacing 1/ss px), per axis, in squares
    gu_y, gu_x = np.gradient(pu)
    gv_y, gv_x = np.gradient(pv)
    hu = np.clip(0.5 * (np.abs(gu_x) + np.abs(gu_y)), 0, 10)
    hv = np.clip(0.5 * (np.abs(gv_x) + np.abs(gv_y)), 0, 10)
    checker = _box_square_wave(pu, hu) * _box_square_wave(pv, hv)  # +1 on black squares
    refl = 0.5 * (_WHITE + _BLACK) - 0.5 * (_WHITE - _BLACK) * checker
    if marker_tex is not None:
        tex, pps = marker_tex
        m = cv2.remap(tex, (pu * pps - 0.5).astype(np.float32), (pv * pps - 0.5).astype(np.float32),
                      cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
        refl = _BLACK + (refl - _BLACK) * m
    in_squares = _box_interval(pu, hu, 0, cols) * _box_interval(pv, hv, 0, rows)
    on_board = _box_interval(pu, hu, -1, cols + 1) * _box_interval(pv, hv, -1, rows + 1)
    board = _WHITE + (refl - _WHITE) * in_squares
    crop = _BACKGROUND + (board - _BACKGROUND) * on_board
    img[y0:y1, x0:x1] = crop.reshape(y1 - y0, ss, x1 - x0, ss).mean(axis=(1, 3))
    return img


def _samples(cam, ss):
    w, h = cam.image_size
    off = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(w)[:, None] + off[None, :]).ravel()
    ys = (np.arange(h)[:, None] + off[None, :]).ravel()
    X, Y = np.meshgrid(xs, ys)
    return cam.unproject(np.column_stack([X.ravel(), Y.ravel()]))[:, :2].reshape(h * ss, w * ss, 2)


def _capture(radiance, rng, blur, noise):
    import cv2

    img = radiance.astype(np.float32)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    codes = img * 255.0
    if noise > 0:
        codes = codes + rng.normal(0.0, noise, codes.shape)
    return np.clip(np.round(codes), 0, 255).astype(np.uint8)


def _pose_dict(R, t):
    return {"R": np.asarray(R).tolist(), "t": np.asarray(t).tolist()}


def _common(size, rng, board, cols, rows, square, views, distortion, poses, ss, stereo, baseline,
            rig_from="boards"):
    from lumigraph.capture.rig import Rig

    spec = board_spec(board, cols, rows, square)
    left = camera_for(size, distortion)
    rig = None
    if stereo and rig_from != "boards":
        from lumigraph.capture.scenes.stereo import pair_rig

        if distortion != "none":
            raise InputError("distortion", f"the {rig_from} rig's cameras have no lens distortion, "
                                           f"got {distortion!r}; render it with distortion none")
        layout = "unrectified" if rig_from.endswith("unrectified") else "rectified"
        rig = pair_rig(size, layout=layout, baseline=baseline)
        left = rig.left
    cams = [(left, np.eye(3), np.zeros(3))]
    if stereo and rig is None:
        right = camera_for(size, distortion, which="right")
        R_rl = _rot([0.3, -1.0, 0.2], np.deg2rad(1.6))
        T_rl = np.array([-baseline, 0.012 * baseline, 0.006 * baseline])
        rig = Rig.from_pose(left, right, R_rl, T_rl)
        cams.append((right, R_rl, T_rl))
    elif stereo:
        cams.append((rig.right, rig.R, rig.T))
    pose_list = _sample_poses(rng, cams, spec, views, poses)
    return spec, cams, rig, pose_list


def _render_all(cams, pose_list, spec, ss, rng, blur, noise):
    marker_tex = _marker_texture(spec) if spec["kind"] == "charuco" else None
    obj = inner_corners(spec["cols"], spec["rows"], spec["square"])
    images, corners = [], []
    for cam, Rc, tc in cams:
        w, h = cam.image_size
        nxy = _samples(cam, ss)
        ims, cs = [], []
        for R, t in pose_list:
            Rv, tv = Rc @ R, Rc @ t + tc
            ims.append(_capture(_render_view(nxy, (h, w), ss, Rv, tv, spec, marker_tex, cam), rng, blur, noise))
            cs.append(cam.project_world(obj, Rv, tv))
        images.append(ims)
        corners.append(np.array(cs))
    return images, corners, obj


def render_boards(*, size, seed, rng, board="checker", views=15, cols=10, rows=7, square=30.0,
                  distortion="normal", poses="varied", noise=1.0, blur=0.6, supersample=2):
    """Single-camera calibration views (see the module docstring)."""
    spec, cams, _, pose_list = _common(size, rng, board, cols, rows, square, views, distortion,
                                       poses, supersample, False, 0.0)
    images, corners, obj = _render_all(cams, pose_list, spec, supersample, rng, blur, noise)
    cam = cams[0][0]
    names = tuple(f"view_{k:02d}.png" for k in range(views))
    gt = {"board": spec, "camera": cam.to_dict(), "distortion": distortion, "poses": poses,
          "cam_from_world": [_pose_dict(R, t) for R, t in pose_list],
          "noise_sigma_codes": noise, "blur_sigma_px": blur,
          "note": "world = board frame (origin at the outer top-left corner of the squares)"}
    return RenderedScene("boards", {}, tuple(images[0]), names,
                         stack={"bit_depth": 8, "linear": False, "board": spec["spec"]},
                         gt=gt, gt_arrays={"corners": corners[0], "object_points": obj})


def render_boards_stereo(*, size, seed, rng, board="checker", views=12, cols=10, rows=7,
                         square=30.0, baseline=120.0, distortion="normal", noise=1.0, blur=0.6,
                         supersample=2, rig="boards"):
    """Stereo-rig calibration views (see the module docstring); ``rig`` names
    whose cameras and pose render them."""
    rig_from = rig
    spec, cams, rig, pose_list = _common(size, rng, board, cols, rows, square, views, distortion,
                                         "varied", supersample, True, baseline, rig_from)
    images, corners, obj = _render_all(cams, pose_list, spec, supersample, rng, blur, noise)
    names = tuple(f"left_{k:02d}.png" for k in range(views)) + \
        tuple(f"right_{k:02d}.png" for k in range(views))
    rig_d = rig.to_dict()
    gt = {"board": spec, "rig": rig_d, "distortion": distortion,
          "cam_from_world": [_pose_dict(R, t) for R, t in pose_list],
          "right_cam_from_world": [_pose_dict(rig.R @ R, rig.R @ t + rig.T) for R, t in pose_list],
          "left_images": list(names[:views]), "right_images": list(names[views:]),
          "noise_sigma_codes": noise, "blur_sigma_px": blur,
          "note": "world = board frame; cam_from_world are the left camera's poses; x_right = R x_left + T"}
    return RenderedScene("boards-stereo", {}, tuple(images[0] + images[1]), names,
                         stack={"bit_depth": 8, "linear": False, "board": spec["spec"]},
                         gt=gt, gt_arrays={"corners_left": corners[0], "corners_right": corners[1],
                                           "object_points": obj})


_COMMON_OPTIONS = (
    Option("board", str, "checker", "target kind", choices=("checker", "charuco")),
    Option("cols", int, 10, "squares across the board", low=3, high=40),
    Option("rows", int, 7, "squares down the board", low=3, high=40),
    Option("square", float, 30.0, "square side, in board units (mm)", low=1e-6, high=1e6),
    Option("noise", float, 1.0, "Gaussian read noise, in 8-bit code values", low=0.0, high=50.0),
    Option("blur", float, 0.6, "Gaussian optical blur sigma, in pixels", low=0.0, high=5.0),
    Option("supersample", int, 2, "samples per pixel side (box-filtered each)", low=1, high=8),
)

SPECS = {
    "boards": SceneSpec(
        "boards", (320, 240),
        _COMMON_OPTIONS + (
            Option("views", int, 15, "number of board poses", low=1, high=60),
            Option("distortion", str, "normal", "lens: none, normal (k1..k3 + tangential) or "
                   "strong (k1 = -0.3)", choices=("none", "normal", "strong")),
            Option("poses", str, "varied", "varied tilts (20-50 deg, every direction) or a near-degenerate "
                   "fronto-parallel set (< 3 deg)", choices=("varied", "fronto"))),
        min_size=(96, 72), version=4),
    "boards-stereo": SceneSpec(
        "boards-stereo", (320, 240),
        _COMMON_OPTIONS + (
            Option("views", int, 12, "number of board poses", low=1, high=60),
            Option("baseline", float, 120.0, "baseline, in board units", low=1e-6, high=1e6),
            Option("distortion", str, "normal", "lens of both cameras",
                   choices=("none", "normal", "strong")),
            Option("rig", str, "boards", "the cameras and their pose: this scene's own (boards), or "
                   "those the stereo-pair scene renders with in its --layout rectified or "
                   "unrectified at the same --size and --baseline (needs --distortion none), so "
                   "the rig calibrated from these boards is that pair's",
                   choices=("boards", "stereo-pair-rectified", "stereo-pair-unrectified"))),
        min_size=(96, 72), version=4),
}
