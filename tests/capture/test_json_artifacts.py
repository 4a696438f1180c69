"""Every JSON artifact is checked once, at load time, by its one parser: a file
with wrong bytes or wrong content is refused with InputError naming the file
and the key, never a KeyError/TypeError/IndexError or numpy's ValueError (which
the command line would report as an internal fault, exit 1).

Each artifact starts valid, written by the project's own writer (the committed
fixtures, or a writer run on them), then gets one fault at a time (the table)
or random structural mutations (hypothesis, fixed seed): the load either
succeeds or raises InputError.
"""

from __future__ import annotations

import copy
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, assert_clean_error, lumigraph
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lumigraph.capture.errors import InputError

FIXTURES = ROOT / "fixtures"
DROP = object()  # a table value: delete the key


@dataclass
class Artifact:
    """A valid artifact: its file, its parsed body and the one parser that loads it."""

    path: Path
    body: dict
    load: object

    def write(self, body) -> None:
        self.path.write_text(json.dumps(body))  # NaN/Infinity literals where the body has them


def _tracks_body(rig) -> dict:
    left, right = rig.to_dict()["left"], rig.to_dict()["right"]
    X = np.array([[0.1, -0.05, 2.0], [-0.2, 0.1, 3.0], [0.0, 0.0, 2.5]])
    px = [rig.left.project(X), rig.right.project(X @ rig.R.T + rig.T)]
    return {"views": [{"camera": left},
                      {"camera": right, "cam_from_world": {"R": rig.R.tolist(),
                                                           "t": rig.T.tolist()}}],
            "tracks": [[px[0][j].tolist(), px[1][j].tolist()] for j in range(len(X))],
            "pixel_sigma": 0.5}


@pytest.fixture(scope="module")
def artifacts(tmp_path_factory) -> dict[str, Artifact]:
    from lumigraph.calib.rectify import Rectification, rectify
    from lumigraph.capture.artifact import write_json
    from lumigraph.capture.camera import Camera
    from lumigraph.capture.io import read_stack, read_stack_json, write_stack_json
    from lumigraph.capture.rig import CameraArray, Rig
    from lumigraph.hdr import response_debevec1997
    from lumigraph.hdr.response import ResponseCurve
    from lumigraph.lightfield.field import LightField
    from lumigraph.stereo.triangulate import read_tracks

    tmp = tmp_path_factory.mktemp("artifacts")
    out = {}
    shutil.copytree(FIXTURES / "bracket-8bit", tmp / "bracket")
    out["stack"] = (tmp / "bracket" / "stack.json", lambda p: read_stack([p.parent]))
    (tmp / "projector").mkdir()
    shutil.copy(FIXTURES / "projector" / "stack.json", tmp / "projector")
    out["stack-projector"] = (tmp / "projector" / "stack.json", read_stack_json)
    lf_gt = json.loads((FIXTURES / "lightfield" / "gt.json").read_text())
    write_stack_json(tmp / "lf-stack", [f"view-{i:02d}.png" for i in range(9)], bit_depth=16,
                     lightfield={k: lf_gt[k] for k in ("grid", "spacing", "focal_px")},
                     lenslet={"views": [5, 5], "lattice": "hex"})
    out["stack-lightfield"] = (tmp / "lf-stack" / "stack.json", read_stack_json)
    for name in ("camera", "rig"):
        shutil.copy(FIXTURES / f"{name}.json", tmp)
    out["camera"] = (tmp / "camera.json", Camera.load)
    out["rig"] = (tmp / "rig.json", Rig.load)
    (tmp / "pair").mkdir()
    shutil.copy(FIXTURES / "stereo-pair" / "gt.json", tmp / "pair")
    out["gt-rig"] = (tmp / "pair" / "gt.json", Rig.load)
    rig = Rig.load(FIXTURES / "rig.json")
    out["camera-array"] = (CameraArray.load(FIXTURES / "rig.json").save(tmp / "cameras.json"),
                           CameraArray.load)
    stack = read_stack([FIXTURES / "bracket-8bit"])
    curve = response_debevec1997(stack.images, stack.exposure_times_s, smoothness=20.0)
    out["response"] = (curve.save(tmp / "response.json"), ResponseCurve.load)
    out["rectification"] = (rectify(rig).save(tmp / "rectification.json"), Rectification.load)
    shutil.copytree(FIXTURES / "lightfield", tmp / "lf", ignore=shutil.ignore_patterns("gt*"))
    out["lightfield"] = (tmp / "lf" / "lightfield.json", lambda p: LightField.load(p.parent))
    write_json(tmp / "tracks.json", _tracks_body(rig))
    out["tracks"] = (tmp / "tracks.json", read_tracks)
    arts = {}
    for kind, (path, load) in out.items():
        load(path)  # valid as written
        arts[kind] = Artifact(Path(path), json.loads(Path(path).read_text()), load)
    return arts


def _set(body, path: tuple, value):
    body = copy.deepcopy(body)
    node = body
    for k in path[:-1]:
        node = node[k]
    if value is DROP:
        del node[path[-1]]
    else:
        node[path[-1]] = value(node[path[-1]]) if callable(value) else value
    return body


def _key(path: tuple) -> str:
    text = ""
    for k in path:
        text += f"[{k}]" if isinstance(k, int) else (f".{k}" if text else k)
    return text


NAN, INF = float("nan"), float("inf")
FLIP_Z = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]
# (kind, path in the body, new value (DROP deletes it; a function maps the old
# value), the key the error must name (default: the path))
FAULTS = [
    ("stack", ("images", 4), 42, None),
    ("stack", ("images",), {}, None),
    ("stack", ("images",), [], None),
    ("stack", ("images",), DROP, None),
    ("stack", ("images", 1), "exposure_09.png", None),
    ("stack", ("exposure_times_s", 1), -0.004, None),
    ("stack", ("exposure_times_s", 1), NAN, None),
    ("stack", ("exposure_times_s",), lambda t: t[:3], None),
    ("stack", ("bit_depth",), "8", None),
    ("stack", ("bit_depth",), 0, None),
    ("stack", ("bit_depth",), 4, None),  # the codes go up to 255
    ("stack", ("bit_depth",), 16, None),  # the PNGs are 8-bit
    ("stack", ("linear",), "yes", None),
    ("stack", ("f_numbers",), [2.8, 4.0], None),
    ("stack", ("schema",), "lumigraph.camera", None),
    ("stack", ("schema_version",), 2, None),
    ("stack-projector", ("sets", "checker", 2), None, None),
    ("stack-projector", ("sets", "flat"), ["black.png"], None),
    ("stack-projector", ("patterns", "checker"), [], None),
    ("stack-projector", ("patterns", "checker", "complement_of", 0), 99, None),
    ("stack-projector", ("patterns", "checker", "complement_of"), [1, 0], None),
    ("stack-projector", ("patterns", "checker", "lit_fraction", 0), 1.5, None),
    ("stack-lightfield", ("lightfield", "spacing"), "wide", None),
    ("stack-lightfield", ("lightfield", "grid"), [3, 0], "lightfield.grid[1]"),
    ("stack-lightfield", ("lightfield", "focal_px"), -48, None),
    ("stack-lightfield", ("lenslet", "views"), [10 ** 6], "lenslet.views[0]"),
    ("camera", ("K",), DROP, None),
    ("camera", ("K",), "oops", None),
    ("camera", ("K",), lambda K: K[:2], None),
    ("camera", ("K", 0, 0), 0.0, None),
    ("camera", ("K", 1, 1), -700.0, None),
    ("camera", ("K", 0, 2), NAN, None),
    ("camera", ("K", 0, 2), INF, None),
    ("camera", ("K", 2), [0, 0, 2], None),
    ("camera", ("K", 1, 0), 5.0, None),
    ("camera", ("dist",), [0.1, 0.0, 0.0], None),
    ("camera", ("dist", 0), "x", None),
    ("camera", ("image_size",), [640], None),
    ("camera", ("image_size", 0), -640, None),
    ("camera", ("image_size", 1), 480.5, None),
    ("camera", ("image_size", 1), 10 ** 400, None),
    ("camera", ("model",), 5, None),
    ("camera", ("schema",), "lumigraph.rig", None),
    ("rig", ("T",), DROP, None),
    ("rig", ("T",), [0, 0, 0], None),
    ("rig", ("T",), [1, 2], None),
    ("rig", ("R",), FLIP_Z, None),
    ("rig", ("R", 0, 0), NAN, None),
    ("rig", ("E",), "x", None),
    ("rig", ("right",), [], None),
    ("rig", ("left", "K", 1, 1), -1.0, None),
    ("rig", ("left", "dist"), None, None),
    ("rig", ("schema_version",), "1", None),
    ("gt-rig", ("rig", "T"), "far", None),
    ("gt-rig", ("rig",), 5, None),
    ("gt-rig", ("rig", "left"), DROP, "rig"),
    ("gt-rig", ("rig", "right", "image_size"), [0, 0], "rig.right.image_size[0]"),
    ("camera-array", ("cameras",), [], None),
    ("camera-array", ("cameras", 1, "cam_from_world", "t"), [0, 0], None),
    ("camera-array", ("cameras", 1, "cam_from_world", "R"), FLIP_Z, None),
    ("camera-array", ("cameras", 0, "cam_from_world"), DROP, None),
    ("camera-array", ("cameras", 1, "K"), None, None),
    ("response", ("g",), DROP, None),
    ("response", ("bit_depth",), 9, "g[0]"),
    ("response", ("bit_depth",), 17, None),
    ("response", ("bit_depth",), "8", None),
    ("response", ("g", 1, 10), "x", None),
    ("response", ("g", 1, 10), NAN, None),
    ("response", ("g", 2), lambda row: row[:100], None),
    ("response", ("g",), lambda g: g[:2], "channels"),
    ("response", ("exposure_times", 0), -1.0, None),
    ("response", ("method",), "", None),
    ("response", ("selection",), [], None),
    ("response", ("warnings",), [1], "warnings[0]"),
    ("response", ("schema",), "lumigraph.stack", None),
    ("response", ("schema_version",), 7, None),
    ("rectification", ("rig",), DROP, None),
    ("rectification", ("R1", 0, 0), 5.0, "R1"),
    ("rectification", ("P1", 0, 0), 0.0, None),
    ("rectification", ("P2", 0, 3), 5.0, None),
    ("rectification", ("Q",), lambda Q: Q[:3], None),
    ("rectification", ("image_size",), "640x480", None),
    ("rectification", ("rig", "left", "dist"), [0, 0, 0], None),
    ("lightfield", ("spacing",), "wide", None),
    ("lightfield", ("spacing",), -1.0, None),
    ("lightfield", ("spacing",), NAN, None),
    ("lightfield", ("views", 3), 42, None),
    ("lightfield", ("views",), lambda v: v[:8], None),
    ("lightfield", ("views", 0), "view-09-09.exr", None),
    ("lightfield", ("grid",), [3], None),
    ("lightfield", ("grid",), [1, 1], None),
    ("lightfield", ("focal_px",), 0, None),
    ("lightfield", ("info",), [], None),
    ("lightfield", ("size",), [1, 1], None),
    ("lightfield", ("channels",), "3", None),
    ("lightfield", ("schema",), "lumigraph.stack", None),
    ("tracks", ("views", 0, "camera", "K", 0, 0), 0.0, None),
    ("tracks", ("views",), lambda v: v[:1], None),
    ("tracks", ("views", 1, "cam_from_world", "R"), [[2, 0, 0], [0, 2, 0], [0, 0, 2]], None),
    ("tracks", ("tracks", 0, 1), [1.0], None),
    ("tracks", ("tracks", 0), lambda t: t[:1], None),
    ("tracks", ("tracks", 1, 0, 1), "y", None),
    ("tracks", ("pixel_sigma",), "half", None),
]


def _expect(art: Artifact, body_or_bytes, *fragments: str) -> InputError:
    """Write the faulty file, load it: one InputError naming the file and ``fragments``."""
    if isinstance(body_or_bytes, bytes):
        art.path.write_bytes(body_or_bytes)
    else:
        art.write(body_or_bytes)
    try:
        with pytest.raises(InputError) as info:
            art.load(art.path)
    finally:
        art.write(art.body)  # the next test starts from the valid file
    err = info.value
    assert err.where == str(art.path), (err.where, str(err))
    for f in fragments:
        assert f in err.problem, (f, str(err))
    return err


@pytest.mark.parametrize("kind, path, value, key", FAULTS,
                         ids=[f"{k}-{_key(p)}-{i}" for i, (k, p, _, _) in enumerate(FAULTS)])
def test_a_wrong_key_is_named(artifacts, kind, path, value, key):
    art = artifacts[kind]
    key = key or _key(path)
    err = _expect(art, _set(art.body, path, value), f"key '{key}'")
    assert not err.problem.startswith("key '': ")


KINDS = ["stack", "stack-projector", "stack-lightfield", "camera", "rig", "gt-rig",
         "camera-array", "response", "rectification", "lightfield", "tracks"]
SCHEMA_CHECKED = [k for k in KINDS if k != "tracks"]


@pytest.mark.parametrize("kind", KINDS)
def test_bytes_that_are_not_json_name_the_file(artifacts, kind):
    art = artifacts[kind]
    text = art.path.read_bytes()
    at = text.index(b'"') + 1
    err = _expect(art, text[:at] + "é".encode("latin-1") + text[at:], "not UTF-8",
                  f"offset {at}")
    assert "0xe9" in err.problem
    _expect(art, text[: len(text) // 2], "invalid JSON", "line")
    _expect(art, b"[" + text + b"]", "expected a JSON object", "a list of 1")
    _expect(art, b"", "invalid JSON")
    _expect(art, b"[" * 100_000, "invalid JSON")
    _expect(art, b'{"x": ' + b"9" * 5000 + b"}", "invalid JSON")
    _expect(art, b'{"x": 1e999}', "key 'x'", "NaN or infinity")


@pytest.mark.parametrize("kind", SCHEMA_CHECKED)
def test_another_kind_or_version_is_refused(artifacts, kind):
    art = artifacts[kind]
    _expect(art, {**art.body, "schema": "lumigraph.other"}, "key 'schema'", "lumigraph.other")
    _expect(art, {**art.body, "schema_version": 99}, "key 'schema_version'", "99")


def test_a_byte_order_mark_and_no_schema_are_accepted(artifacts):
    """A hand-written stack.json (no schema keys) saved by a Windows editor."""
    art = artifacts["stack"]
    body = {k: v for k, v in art.body.items() if not k.startswith("schema")}
    art.path.write_bytes(b"\xef\xbb\xbf" + json.dumps(body).encode())
    try:
        assert art.load(art.path).exposure_times_s == tuple(art.body["exposure_times_s"])
    finally:
        art.write(art.body)


# ------------------------------------------------------------------ fuzzing
ODD_VALUES = [None, NAN, INF, -INF, -1, 0, -1e-9, 1e308, 10 ** 400, 2 ** 63, 0.5, True, "",
              "wide", [], {}, [1, 2], [[1.0]], [None], {"a": 1}]


@st.composite
def _mutated(draw, body: dict):
    """``body`` after 1-3 structural edits: drop a key or an element, or
    replace any value (at any depth) with an odd one."""
    body = copy.deepcopy(body)
    for _ in range(draw(st.integers(1, 3))):
        parent, key, node = None, None, body
        while isinstance(node, dict | list) and node:
            if parent is not None and not draw(st.booleans()):
                break  # stop at this level (deeper with probability 1/2 each step)
            keys = list(node) if isinstance(node, dict) else list(range(len(node)))
            parent, key = node, draw(st.sampled_from(keys))
            node = parent[key]
        if parent is None:
            continue
        if draw(st.booleans()):
            del parent[key]
        else:
            parent[key] = copy.deepcopy(draw(st.sampled_from(ODD_VALUES)))
    return body


def _fuzz(art: Artifact, data) -> None:
    body = data.draw(_mutated(art.body))
    text = json.dumps(body).encode()
    if data.draw(st.integers(0, 9)) == 5:  # now and then (1 in 10), a truncated file
        text = text[: data.draw(st.integers(0, len(text)))]
    art.path.write_bytes(text)
    try:
        art.load(art.path)
    except InputError as e:
        assert e.where == str(art.path), str(e)
    finally:
        art.write(art.body)


FUZZ = settings(max_examples=200, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                       HealthCheck.data_too_large])


@pytest.mark.parametrize("kind", KINDS)
@FUZZ
@given(data=st.data())
def test_mutated_artifacts_load_or_raise_input_error(artifacts, kind, data):
    _fuzz(artifacts[kind], data)


# ------------------------------------------------------------ the command line
def test_the_command_line_reports_a_bad_stack_json_as_bad_input(tmp_path):
    """The issue's cases: exit 2 naming the file and the key, not exit 1."""
    folder = tmp_path / "bracket"
    shutil.copytree(FIXTURES / "bracket-8bit", folder)
    body = json.loads((folder / "stack.json").read_text())
    body["images"][3] = 42
    (folder / "stack.json").write_text(json.dumps(body))
    r = lumigraph("hdr", "response", folder, "--out", tmp_path / "response.json")
    assert_clean_error(r, "stack.json", "key 'images[3]'")
    (folder / "stack.json").write_bytes("{\"images\": [\"é.png\"]}".encode("latin-1"))
    r = lumigraph("hdr", "response", folder, "--out", tmp_path / "response.json")
    assert_clean_error(r, "stack.json", "not UTF-8")
    lf = tmp_path / "lf"
    shutil.copytree(FIXTURES / "lightfield", lf)
    body = json.loads((lf / "lightfield.json").read_text())
    body["spacing"] = "wide"
    (lf / "lightfield.json").write_text(json.dumps(body))
    r = lumigraph("lightfield", "refocus", lf, "--slope", "0", "--out", tmp_path / "r.exr")
    assert_clean_error(r, "lightfield.json", "key 'spacing'", "got 'wide'")
