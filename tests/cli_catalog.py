"""One valid, fast invocation of every command and verb of ``lumigraph``.

A plain helper module (not a test file): tests import it to run the whole
command line on small inputs. ``tests/test_rerun_stable.py`` runs every entry
twice and compares the artifacts byte for byte; a bad-input corpus can mutate
each entry's inputs, options or outputs and expect a clean exit 2.

Structure
---------
:data:`ENTRIES` is a list of :class:`Entry`, one per command or verb (in the
order of ``lumigraph --help`` and each stage's verbs), plus a few extra entries
for code paths worth running on their own (named ``"<command> (<what>)"``).

An entry's ``argv``, ``inputs`` and ``outputs`` are templates with two fields:
``{in}``, the folder its ``prepare`` filled with inputs, and ``{out}``, a folder
the command writes into (absent until it runs). :func:`materialise` fills them::

    m = materialise(entry, tmp_path)            # inputs in tmp_path/in
    rc, out, err = run_cli(m.argv)              # in-process, output captured
    assert rc == 0 and all(p.exists() for p in m.outputs)
    m2 = materialise(entry, tmp_path, out=tmp_path / "again", prepared=m.names)
                                                # same inputs, another output folder

Inputs are copies (the committed ``fixtures/`` are never touched) or small
renders; a scene is rendered once per machine (the render cache,
``$LUMIGRAPH_CACHE``), saved once per session and copied from there, so once
the cache is warm preparing every entry costs about a second.

``outputs`` lists every primary artifact the command writes, exactly (the
rerun test checks that nothing else appears): sidecars (``*.meta.json``: time,
command line, paths) are excluded by design. ``unstable`` names the outputs
that legitimately differ from run to run, with the reason (only the bench's
wall-time reports). ``fresh_process`` marks the commands whose results once
depended on threads or process history (OpenCV threads in calibration, COLMAP's
threads, OpenCV's global generator in the weighted median): the rerun test also
runs those in two separate processes.

Images are at most 96x72 where the method works at that size; calibration
boards (128x96; the stereo pair's 160x120) and SfM views (160x120) need a
little more for the board or the features to be found.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import hashlib
import io
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "fixtures"


@dataclass(frozen=True)
class Entry:
    """One invocation of one command.

    Attributes
    ----------
    name : str
        ``"calib calibrate"``: the words after ``lumigraph`` that pick the
        command (an extra entry adds ``" (<what>)"``).
    argv : tuple of str
        The arguments after ``lumigraph``, with ``{in}``/``{out}`` fields.
    prepare : callable (folder: Path) -> None
        Lays out the inputs in ``folder`` (the ``{in}`` of the templates).
    inputs : tuple of str
        The paths the command reads, as its command line names them (a file,
        or a folder with stack.json / lightfield.json), templates.
    outputs : tuple of str
        Every primary artifact it writes (files, sidecars excluded), templates.
    unstable : dict of str -> str
        Outputs (templates, a subset of ``outputs``) that cannot be
        byte-identical between runs, and why.
    fresh_process : bool
        Also rerun in two separate processes (results once depended on
        threads or on what ran before in the process).
    """

    name: str
    argv: tuple[str, ...]
    prepare: Callable[[Path], None]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    unstable: dict = field(default_factory=dict)
    fresh_process: bool = False

    def __post_init__(self):
        if not set(self.unstable) <= set(self.outputs):
            raise ValueError(f"{self.name}: unstable outputs must be among the outputs")
        if any(o.endswith(".meta.json") for o in self.outputs):
            raise ValueError(f"{self.name}: sidecars are not primary outputs")

    @property
    def stable_outputs(self) -> tuple[str, ...]:
        """The outputs that must be byte-identical on a rerun (templates)."""
        return tuple(o for o in self.outputs if o not in self.unstable)


class Materialised(NamedTuple):
    """An entry made concrete: unpacks as ``argv, inputs, outputs``."""

    argv: list[str]
    inputs: list[Path]
    outputs: list[Path]
    names: dict  # the template fields: {"in": Path, "out": Path}
    stable_outputs: list[Path]


def materialise(entry: Entry, tmp_path: Path, *, out: Path | None = None,
                prepared: dict | None = None) -> Materialised:
    """Prepare ``entry``'s inputs in ``tmp_path/in`` and fill its templates.

    ``out`` is the output folder (default ``tmp_path/out``; not created).
    ``prepared``: the ``names`` of an earlier materialisation whose inputs to
    reuse instead of preparing them again (a rerun on the same input paths).
    """
    tmp_path = Path(tmp_path)
    if prepared is None:
        folder = tmp_path / "in"
        folder.mkdir(parents=True, exist_ok=True)
        entry.prepare(folder)
        names = {"in": folder}
    else:
        names = {"in": Path(prepared["in"])}
    names["out"] = Path(out) if out is not None else tmp_path / "out"

    def fill(t: str) -> str:
        return t.format(**{k: str(v) for k, v in names.items()})

    return Materialised([fill(a) for a in entry.argv], [Path(fill(p)) for p in entry.inputs],
                        [Path(fill(p)) for p in entry.outputs], names,
                        [Path(fill(p)) for p in entry.stable_outputs])


def run_cli(argv: Sequence[str]) -> tuple[int, str, str]:
    """Run ``lumigraph *argv`` in this process: ``(exit status, stdout, stderr)``."""
    from lumigraph.command import main

    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        rc = main([str(a) for a in argv])
    return rc, o.getvalue(), e.getvalue()


def run_cli_process(argv: Sequence[str], *, timeout: float = 600) -> tuple[int, str, str]:
    """Run ``lumigraph *argv`` as a user would, in a fresh process
    (``python -m lumigraph``): ``(exit status, stdout, stderr)``."""
    r = subprocess.run([sys.executable, "-m", "lumigraph", *map(str, argv)], capture_output=True,
                       text=True, timeout=timeout)
    return r.returncode, r.stdout, r.stderr


# --------------------------------------------------------------------------
# inputs

@functools.cache
def _session_dir() -> Path:
    d = Path(tempfile.mkdtemp(prefix="lumigraph-catalog-"))
    atexit.register(shutil.rmtree, d, ignore_errors=True)
    return d


@functools.cache
def _scene(name: str, size: tuple[int, int], seed: int, options: tuple) -> tuple[Path, object]:
    """A rendered scene saved once per session: ``(folder, RenderedScene)``."""
    from lumigraph.capture.render import render

    s = render(name, size=size, seed=seed, **dict(options))
    key = hashlib.sha256(repr((name, size, seed, options)).encode()).hexdigest()[:12]
    folder = _session_dir() / f"{name}-{key}"
    if not (folder / "stack.json").exists():
        s.save(folder)
    return folder, s


def scene(name: str, dest: Path, *, size: tuple[int, int], seed: int = 0, **options):
    """Copy the rendered scene into ``dest``; returns the RenderedScene."""
    folder, s = _scene(name, tuple(size), seed, tuple(sorted(options.items())))
    shutil.copytree(folder, dest, dirs_exist_ok=True)
    return s


def fixture(name: str, dest: Path) -> Path:
    """Copy ``fixtures/<name>`` (a file or a folder) to ``dest``."""
    src = FIXTURES / name
    if src.is_dir():
        shutil.copytree(src, dest, dirs_exist_ok=True)
    else:
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dest)
    return dest


def _bracket(d: Path) -> None:
    fixture("bracket-8bit", d / "bracket")


def _bracket_and_response(d: Path) -> None:
    from lumigraph.hdr.response import ResponseCurve

    _bracket(d)
    ResponseCurve("gt", 8, np.load(d / "bracket" / "gt" / "g.npy")).save(d / "response.json")


def _radiance(d: Path) -> None:
    from lumigraph.capture.io import write_exr

    rad = np.load(FIXTURES / "bracket-8bit" / "gt" / "radiance.npy").astype(np.float32)
    write_exr(d / "radiance.exr", rad)


BOARD = dict(cols=5, rows=4)  # 12 inner corners: found at 128x96


def _boards(d: Path) -> None:
    scene("boards", d / "boards", size=(128, 96), seed=7, views=5, **BOARD)


def _undistort(d: Path) -> None:
    fixture("camera.json", d / "camera.json")  # a 96x72 camera
    fixture("flow/frame00.png", d / "frame00.png")  # any 96x72 image


STEREO_BOARD_VIEWS = 5


def _boards_stereo(d: Path) -> None:
    # the pair at 60 mm with 60 mm squares: found in both views at 160x120
    scene("boards-stereo", d / "boards", size=(160, 120), seed=6, views=STEREO_BOARD_VIEWS,
          square=60.0, baseline=60.0, **BOARD)


def _pair(d: Path) -> None:
    fixture("stereo-pair", d / "pair")  # 64x48, unrectified
    fixture("rig.json", d / "rig.json")


def _pairs(d: Path) -> None:
    """Two pairs as a left and a right folder (a batch match)."""
    _pair(d)
    for side in ("left", "right"):
        for k in (0, 1):
            (d / side).mkdir(exist_ok=True)
            shutil.copy(d / "pair" / f"{side}.png", d / side / f"p{k}.png")


def _pair_and_disparity(d: Path) -> None:
    from lumigraph.capture.io import write_pfm

    _pair(d)
    write_pfm(d / "disparity.pfm", np.full((48, 64), 6.0, np.float32))


def _matches(d: Path) -> None:
    """A two-view matches file: points seen by the fixture rig (left frame)."""
    from lumigraph.capture.rig import Rig

    fixture("rig.json", d / "rig.json")
    rig = Rig.load(d / "rig.json")
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-0.5, 0.5, (12, 2)), rng.uniform(2.0, 4.0, 12)])
    xl = rig.left.project(pts)
    xr = rig.right.project(pts @ rig.R.T + rig.T)
    lines = ["# x_left y_left x_right y_right"]
    lines += [" ".join(f"{v:.4f}" for v in (*a, *b)) for a, b in zip(xl, xr, strict=True)]
    (d / "matches.txt").write_text("\n".join(lines) + "\n")


def _model_stereo(d: Path) -> None:
    scene("model-stereo", d / "facade", size=(96, 72), seed=0)


def _facade(d: Path) -> None:
    scene("facade", d / "facade", size=(96, 72), seed=0, photos=6, novel=1, supersample=1)


SFM_VIEWS = 4


def _views(d: Path) -> None:
    # 4 views over 20 degrees at 160x120: the smallest set COLMAP registers whole
    scene("stereo-views", d / "views", size=(160, 120), seed=0, views=SFM_VIEWS, arc_deg=20.0)


def _flow(d: Path) -> None:
    fixture("flow", d / "flow")  # 96x72


def _video(d: Path) -> None:
    from lumigraph.hdr.response import ResponseCurve

    s = scene("bracket_video", d / "video", size=(48, 36), seed=2, frames=3)
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(d / "response.json")


def _array(d: Path) -> None:
    scene("lightfield-array", d / "array", size=(48, 40), seed=5, grid="3x3", thin_lens=False)


def _lenslet(d: Path) -> None:
    scene("lightfield-lenslet-hex", d / "raw", size=(12, 12), seed=0)


def _lightfield(d: Path) -> None:
    fixture("lightfield", d / "lf")  # 3x3 views of 48x40


def _projector(d: Path) -> None:
    fixture("projector", d / "projector")  # 48x36


def _brackets_and_response(d: Path) -> None:
    """Two brackets in one folder (a batch merge) and their response."""
    _bracket_and_response(d)
    for b in ("b0", "b1"):
        shutil.copytree(d / "bracket", d / "shots" / b)


def _nothing(d: Path) -> None:
    pass


def _names(prefix: str, names: Sequence[str]) -> tuple[str, ...]:
    return tuple(f"{prefix}/{n}" for n in names)


def _facade_folder(d: Path) -> None:
    # a hand-written block model, 4 painted 96x72 photographs, exact marks
    from lumigraph.capture.scenes.facade_edges import ring_cameras, write_facade_folder
    from lumigraph.stereo.debevec1996.model import load_blocks

    m = load_blocks(FIXTURES / "facade" / "blocks.json")
    cams = ring_cameras(4, target=[1.5, 0, 4], radius=30, height=4, focal_px=100,
                        image_size=(96, 72), arc_deg=(-130.0, -50.0))
    write_facade_folder(d / "facade", m, cams, start=m.with_values(m.values[~m.fixed] * 1.05))


_FACADE_PHOTOS = tuple(f"photo_{k:02d}" for k in range(4))
_FACADE_INPUTS = ("{in}/facade",)
_FACADE_OUTPUTS = (*_names("{out}/facade", ("model.json", "blocks.json", "model.obj", "model.ply",
                                            "cameras.txt", "images.txt", "points3D.txt")),
                   *(f"{{out}}/facade/cameras/{p}.json" for p in _FACADE_PHOTOS),
                   *(f"{{out}}/facade/overlay/{p}.png" for p in _FACADE_PHOTOS))


_LF_VIEWS = tuple(f"view-{u:02d}-{v:02d}.exr" for u in range(3) for v in range(3))
_BOARD_IMAGES = [f"{{in}}/boards/{side}_{k:02d}.png" for side in ("left", "right")
                 for k in range(STEREO_BOARD_VIEWS)]
_BENCH_REASON = "the bench reports hold measured wall times (the point of a bench)"

ENTRIES: list[Entry] = [
    # render -----------------------------------------------------------------
    Entry("render", ("render", "sample", "--size", "16x16", "--seed", "1", "--no-cache", "-q",
                     "--out", "{out}/sample"),
          _nothing, (),
          _names("{out}/sample", ("ramp.png", "stack.json", "gt.json", "gt/radiance.npy"))),
    Entry("render (flow scene)", ("render", "flow", "--size", "48x36", "--seed", "2", "--frames", "2",
                                  "--no-cache", "-q", "--out", "{out}/flow"),
          _nothing, (),
          _names("{out}/flow", ("frame00.png", "frame01.png", "stack.json", "gt.json",
                                *(f"gt/{a}.npy" for a in ("boundary", "flow", "flows", "occluded",
                                                          "occlusions", "textureless"))))),
    # calib ------------------------------------------------------------------
    Entry("calib calibrate", ("calib", "calibrate", "{in}/boards", "--out", "{out}/camera.json",
                              "--yaml", "{out}/camera.yml", "--colmap", "{out}/cameras.txt", "-q"),
          _boards, ("{in}/boards",),
          ("{out}/camera.json", "{out}/camera.yml", "{out}/cameras.txt"), fresh_process=True),
    Entry("calib undistort", ("calib", "undistort", "--camera", "{in}/camera.json", "{in}/frame00.png",
                              "--out", "{out}/undistorted", "-q"),
          _undistort, ("{in}/camera.json", "{in}/frame00.png"),
          _names("{out}/undistorted", ("frame00.png", "camera.json", "undistorted.json"))),
    Entry("calib undistort (by rows)", ("calib", "undistort", "--camera", "{in}/camera.json",
                                        "{in}/frame00.png", "--out", "{out}/undistorted",
                                        "--tile", "8", "-q"),
          _undistort, ("{in}/camera.json", "{in}/frame00.png"),
          _names("{out}/undistorted", ("frame00.png", "camera.json", "undistorted.json"))),
    Entry("calib stereo", ("calib", "stereo", "--left", *_BOARD_IMAGES[:STEREO_BOARD_VIEWS],
                           "--right", *_BOARD_IMAGES[STEREO_BOARD_VIEWS:], "--board", "checker:5x4:60",
                           "--out", "{out}/rig.json", "--yaml", "{out}/rig.yml",
                           "--colmap", "{out}/cameras.txt", "-q"),
          _boards_stereo, tuple(_BOARD_IMAGES),
          ("{out}/rig.json", "{out}/rig.yml", "{out}/cameras.txt"), fresh_process=True),
    Entry("calib rectify", ("calib", "rectify", "--rig", "{in}/rig.json", "{in}/pair/left.png",
                            "{in}/pair/right.png", "--out", "{out}/rectified", "-q"),
          _pair, ("{in}/rig.json", "{in}/pair/left.png", "{in}/pair/right.png"),
          _names("{out}/rectified", ("left.png", "right.png", "maps_left.npy", "maps_right.npy",
                                     "rectification.json"))),
    # hdr --------------------------------------------------------------------
    Entry("hdr response", ("hdr", "response", "{in}/bracket", "--samples", "200", "--seed", "3",
                           "--out", "{out}/response.json", "--plot", "{out}/curve.png", "-q"),
          _bracket, ("{in}/bracket",), ("{out}/response.json", "{out}/curve.png")),
    Entry("hdr merge", ("hdr", "merge", "{in}/bracket", "--response", "{in}/response.json",
                        "--out", "{out}/radiance.exr", "-q"),
          _bracket_and_response, ("{in}/bracket", "{in}/response.json"),
          ("{out}/radiance.exr", "{out}/radiance.mask.png")),
    Entry("hdr merge (by rows)", ("hdr", "merge", "{in}/bracket", "--response",
                                  "{in}/response.json", "--out", "{out}/radiance.exr",
                                  "--tile", "16", "-q"),
          _bracket_and_response, ("{in}/bracket", "{in}/response.json"),
          ("{out}/radiance.exr", "{out}/radiance.mask.png")),
    Entry("hdr merge (batch)", ("hdr", "merge", "{in}/shots", "--response", "{in}/response.json",
                                "--out", "{out}/radiance", "-q"),
          _brackets_and_response, ("{in}/shots", "{in}/response.json"),
          _names("{out}/radiance", ("b0.exr", "b0.mask.png", "b1.exr", "b1.mask.png", "index.json"))),
    Entry("hdr align", ("hdr", "align", *(f"{{in}}/bracket/exposure_{k:02d}.png" for k in range(5)),
                        "--out", "{out}/aligned", "-q"),
          _bracket, tuple(f"{{in}}/bracket/exposure_{k:02d}.png" for k in range(5)),
          _names("{out}/aligned", (*(f"exposure_{k:02d}.png" for k in range(5)), "stack.json"))),
    Entry("hdr tonemap", ("hdr", "tonemap", "{in}/radiance.exr", "--method", "reinhard-local",
                          "--out", "{out}/tonemapped.png", "-q"),
          _radiance, ("{in}/radiance.exr",), ("{out}/tonemapped.png",)),
    Entry("hdr tonemap (by rows)", ("hdr", "tonemap", "{in}/radiance.exr", "--method",
                                    "reinhard-local", "--out", "{out}/tonemapped.png",
                                    "--tile", "16", "--memory", "1GB", "-q"),
          _radiance, ("{in}/radiance.exr",), ("{out}/tonemapped.png",)),
    Entry("hdr video", ("hdr", "video", "{in}/video", "--response", "{in}/response.json",
                        "--out", "{out}/video", "--tonemap", "-q"),
          _video, ("{in}/video", "{in}/response.json"),
          _names("{out}/video", (*(f"frame_{k:03d}.exr" for k in range(3)),
                                 *(f"frame_{k:03d}.png" for k in range(3))))),
    Entry("hdr convert", ("hdr", "convert", "{in}/radiance.exr", "{out}/radiance.hdr", "-q"),
          _radiance, ("{in}/radiance.exr",), ("{out}/radiance.hdr",)),
    # flow -------------------------------------------------------------------
    # the colour-guided weighted median: the path that drew from OpenCV's generator
    Entry("flow", ("flow", "{in}/flow/frame00.png", "{in}/flow/frame01.png", "--method", "pyramid",
                   "--median-radius", "3", "--out", "{out}/flow.flo", "--viz", "{out}/flow.png", "-q"),
          _flow, ("{in}/flow/frame00.png", "{in}/flow/frame01.png"),
          ("{out}/flow.flo", "{out}/flow.prob.exr", "{out}/flow.png"), fresh_process=True),
    # the default method; accurate: its weighted median draws from OpenCV's generator too
    Entry("flow (dis accurate)", ("flow", "{in}/flow/frame00.png", "{in}/flow/frame01.png",
                                  "--preset", "accurate", "--out", "{out}/dis.flo", "-q"),
          _flow, ("{in}/flow/frame00.png", "{in}/flow/frame01.png"),
          ("{out}/dis.flo", "{out}/dis.prob.exr"), fresh_process=True),
    Entry("flow (video-matching)", ("flow", "{in}/flow/frame00.png", "{in}/flow/frame01.png",
                                    "--method", "video-matching", "--out", "{out}/match.flo", "-q"),
          _flow, ("{in}/flow/frame00.png", "{in}/flow/frame01.png"),
          ("{out}/match.flo", "{out}/match.prob.exr")),
    # stereo -----------------------------------------------------------------
    Entry("stereo match", ("stereo", "match", "{in}/pair/left.png", "{in}/pair/right.png",
                           "--rig", "{in}/rig.json", "--max-disp", "16",
                           "--out", "{out}/disparity.pfm", "-q"),
          _pair, ("{in}/pair/left.png", "{in}/pair/right.png", "{in}/rig.json"),
          ("{out}/disparity.pfm",)),
    Entry("stereo match (batch)", ("stereo", "match", "{in}/left", "{in}/right", "--rig",
                                   "{in}/rig.json", "--max-disp", "16", "--out", "{out}/disp", "-q"),
          _pairs, ("{in}/left", "{in}/right", "{in}/rig.json"),
          _names("{out}/disp", ("p0.pfm", "p1.pfm", "index.json"))),
    Entry("stereo depth", ("stereo", "depth", "{in}/disparity.pfm", "--rig", "{in}/rig.json",
                           "--image", "{in}/pair/left.png", "--out", "{out}/points.ply", "-q"),
          _pair_and_disparity, ("{in}/disparity.pfm", "{in}/rig.json", "{in}/pair/left.png"),
          ("{out}/points.ply",)),
    Entry("stereo depth (no rig)", ("stereo", "depth", "{in}/disparity.pfm", "--focal-px", "80",
                                    "--baseline", "0.1", "--cx", "31.5", "--cy", "23.5", "--doffs", "2",
                                    "--out", "{out}/points.ply", "-q"),
          _pair_and_disparity, ("{in}/disparity.pfm",), ("{out}/points.ply",)),
    Entry("stereo model-based", ("stereo", "model-based", "{in}/facade/key.png", "{in}/facade/offset.png",
                                 "--rig", "{in}/facade/gt.json", "--model",
                                 "{in}/facade/gt/model_depth.npy", "--max-offset", "0.35",
                                 "--warped", "{out}/warped.png", "--out", "{out}/depth.pfm", "-q"),
          _model_stereo, ("{in}/facade/key.png", "{in}/facade/offset.png", "{in}/facade/gt.json",
                          "{in}/facade/gt/model_depth.npy"),
          ("{out}/depth.pfm", "{out}/warped.png")),
    Entry("stereo facade depth", ("stereo", "facade", "depth", "--model", "{in}/facade/blocks.json",
                                  "--camera", "{in}/facade/cameras/photo_02.json",
                                  "--out", "{out}/model.pfm", "-q"),
          _facade, ("{in}/facade/blocks.json", "{in}/facade/cameras/photo_02.json"),
          ("{out}/model.pfm",)),
    Entry("stereo facade pair", ("stereo", "facade", "pair", "--key", "{in}/facade/cameras/photo_02.json",
                                 "--offset", "{in}/facade/cameras/photo_03.json",
                                 "--out", "{out}/rig.json", "-q"),
          _facade, ("{in}/facade/cameras/photo_02.json", "{in}/facade/cameras/photo_03.json"),
          ("{out}/rig.json",)),
    Entry("stereo facade render", ("stereo", "facade", "render", "--model", "{in}/facade/blocks.json",
                                   "--photos", "{in}/facade", "--view", "{in}/facade/novel/view_0.json",
                                   "--out", "{out}/view.png", "-q"),
          _facade, ("{in}/facade/blocks.json", "{in}/facade", "{in}/facade/novel/view_0.json"),
          ("{out}/view.png",)),
    Entry("stereo facade render (view map)", ("stereo", "facade", "render", "--model",
                                              "{in}/facade/blocks.json", "--photos", "{in}/facade",
                                              "--view", "{in}/facade/novel/view_0.json",
                                              "--method", "view-map", "--out", "{out}/view.exr", "-q"),
          _facade, ("{in}/facade/blocks.json", "{in}/facade", "{in}/facade/novel/view_0.json"),
          ("{out}/view.exr",)),
    Entry("stereo triangulate", ("stereo", "triangulate", "{in}/matches.txt", "--rig", "{in}/rig.json",
                                 "--out", "{out}/points.json", "-q"),
          _matches, ("{in}/matches.txt", "{in}/rig.json"), ("{out}/points.json",)),
    Entry("stereo sfm", ("stereo", "sfm", *(f"{{in}}/views/view{k:02d}.png" for k in range(SFM_VIEWS)),
                         "--camera", "{in}/views/gt.json", "--seed", "0", "--out", "{out}/sfm", "-q"),
          _views, (*(f"{{in}}/views/view{k:02d}.png" for k in range(SFM_VIEWS)), "{in}/views/gt.json"),
          ("{out}/sfm/cameras.json", "{out}/sfm/points.ply", "{out}/sfm/cameras.txt",
           "{out}/sfm/images.txt", "{out}/sfm/points3D.txt"), fresh_process=True),
    Entry("stereo facade solve", ("stereo", "facade", "solve", "{in}/facade", "--noise-px", "0.5",
                                  "--out", "{out}/facade", "-q"),
          _facade_folder, _FACADE_INPUTS, _FACADE_OUTPUTS),
    Entry("stereo facade automark", ("stereo", "facade", "automark", "{in}/facade",
                                     "--out", "{out}/edges.json", "-q"),
          _facade_folder, _FACADE_INPUTS, ("{out}/edges.json",)),
    # lightfield -------------------------------------------------------------
    Entry("lightfield import", ("lightfield", "import", "{in}/array", "--out", "{out}/lf", "-q"),
          _array, ("{in}/array",), (*_names("{out}/lf", _LF_VIEWS), "{out}/lf/lightfield.json")),
    Entry("lightfield decode", ("lightfield", "decode", "{in}/raw/raw.png", "--white", "{in}/raw/white.png",
                                "--out", "{out}/decoded", "-q"),
          _lenslet, ("{in}/raw/raw.png", "{in}/raw/white.png"),
          (*_names("{out}/decoded", tuple(f"view-{u:02d}-{v:02d}.exr" for u in range(5)
                                          for v in range(5))), "{out}/decoded/lightfield.json")),
    Entry("lightfield refocus", ("lightfield", "refocus", "{in}/lf", "--slope", "0.5",
                                 "--out", "{out}/focus.exr", "-q"),
          _lightfield, ("{in}/lf",), ("{out}/focus.exr",)),
    Entry("lightfield render", ("lightfield", "render", "{in}/lf", "--position", "0.01", "0.01", "0",
                                "--focus-slope", "0.4", "--out", "{out}/view.exr", "-q"),
          _lightfield, ("{in}/lf",), ("{out}/view.exr",)),
    Entry("lightfield depth", ("lightfield", "depth", "{in}/lf", "--slopes=-1,1,9",
                               "--all-in-focus", "{out}/all_in_focus.exr", "--out", "{out}/disparity.pfm",
                               "-q"),
          _lightfield, ("{in}/lf",), ("{out}/disparity.pfm", "{out}/all_in_focus.exr")),
    # separate ---------------------------------------------------------------
    Entry("separate", ("separate", "{in}/projector", "--method", "checker", "--out", "{out}/separation",
                       "-q"),
          _projector, ("{in}/projector",),
          _names("{out}/separation", ("direct.exr", "global.exr", "mask.png"))),
    Entry("separate (by rows)", ("separate", "{in}/projector", "--method", "checker", "--out",
                                 "{out}/separation", "--tile-rows", "13", "--memory", "1GB", "-q"),
          _projector, ("{in}/projector",),
          _names("{out}/separation", ("direct.exr", "global.exr", "mask.png"))),
    Entry("separate patterns", ("separate", "patterns", "--kind", "checker", "--size", "64x48",
                                "--square", "8", "--shifts", "2", "--out", "{out}/patterns", "-q"),
          _nothing, (),
          _names("{out}/patterns", (*(f"checker_{k:02d}.png" for k in range(8)), "stack.json"))),
    # bench ------------------------------------------------------------------
    Entry("bench", ("bench", "io", "--quick", "--repeats", "3", "--out", "{out}/bench", "-q"),
          _nothing, (),
          ("{out}/bench/report.md", "{out}/bench/report.json", "{out}/bench/io.png"),
          unstable={"{out}/bench/report.md": _BENCH_REASON, "{out}/bench/report.json": _BENCH_REASON,
                    "{out}/bench/io.png": _BENCH_REASON + " (plotted against time)"}),
    # inspect ----------------------------------------------------------------
    Entry("inspect", ("inspect", "{in}/bracket", "--out", "{out}/summary.json", "-q"),
          _bracket, ("{in}/bracket",), ("{out}/summary.json",)),
    # view (the local web page; --check opens the inputs as the page would and
    # exits instead of serving; the marks file is only written by edits)
    Entry("view", ("view", "--facade", "{in}/facade", "--edges", "{out}/edges.json", "--check",
                   "-q"),
          _facade_folder, _FACADE_INPUTS, ()),
]

BY_NAME: dict[str, Entry] = {e.name: e for e in ENTRIES}
if len(BY_NAME) != len(ENTRIES):
    raise ValueError("cli_catalog: two entries share a name")


def command_words() -> set[str]:
    """Every command and verb of ``lumigraph`` (``"calib calibrate"``,
    ``"flow"``, …), read from the stages' own parsers (the verbs each one
    registers while answering ``--help``), for a test that the catalog covers
    them all."""
    import argparse
    from unittest import mock

    from lumigraph.command import STAGES

    words = set()
    original = argparse._SubParsersAction.add_parser
    for stage in STAGES:
        verbs = []

        def add_parser(self, name, *args, _verbs=verbs, **kw):
            # a verb group's verbs (stereo facade solve) carry the group's words
            _verbs.append(" ".join([*self._prog_prefix.split()[2:], name]))
            return original(self, name, *args, **kw)

        with mock.patch.object(argparse._SubParsersAction, "add_parser", add_parser):
            rc, _, err = run_cli([stage, "--help"])
        if rc != 0:
            raise RuntimeError(f"lumigraph {stage} --help: exit {rc}: {err}")
        groups = {v for v in verbs if any(w.startswith(v + " ") for w in verbs)}
        words |= {f"{stage} {v}" for v in verbs if v not in groups} or {stage}
    # `separate patterns` is picked before the separation parser runs (its
    # options differ from the method's); its help names it
    rc, out, _ = run_cli(["separate", "patterns", "--help"])
    if rc == 0 and "projector patterns" in out:
        words.add("separate patterns")
    return words


__all__ = ["Entry", "ENTRIES", "BY_NAME", "Materialised", "materialise", "run_cli",
           "run_cli_process", "command_words"]
