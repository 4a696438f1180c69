"""Looking mode of ``lumigraph view``: every artifact kind through Flask's test client.

The artifacts are written in ``tmp_path`` by the project's own writers; each
kind is described, drawn (the picture decodes, at the display size) and
probed (the value under the cursor is the file's value at that pixel, read
back by the project's reader: exact). Speed is measured by ``lumigraph bench
view``, not here.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from flask import Flask

from lumigraph.capture.io import read_image, write_flo, write_image, write_pfm, write_ply
from lumigraph.hdr.formats import read_hdr_image, write_hdr_image
from lumigraph.hdr.reinhard2002 import srgb_encode, tonemap
from lumigraph.hdr.response import ResponseCurve
from lumigraph.stereo.flow_colour import flow_to_colour
from lumigraph.view import artifacts as A
from lumigraph.view.looking import blueprint

ROOT = Path(__file__).resolve().parents[2]

# The linear exposure picture is a table over a log2 index of the display copy
# (artifacts.LOG_STEPS per stop): its codes are within half a code (rounding)
# plus 112.1 ln2 / (2 LOG_STEPS) (the index's rounding through the sRGB curve's
# steepest slope in ln L, 255 x 1.055 / 2.4) of the exact tone curve.
HALF_CODE = 0.5 + 255 * 1.055 / 2.4 * math.log(2) / (2 * A.LOG_STEPS)


def client(paths):
    app = Flask(__name__)
    app.register_blueprint(blueprint)
    app.config["LUMI_ARTIFACTS"] = [str(p) for p in paths]
    return app.test_client()


def decode(resp) -> np.ndarray:
    assert resp.status_code == 200, resp.get_data(as_text=True)
    img = cv2.imdecode(np.frombuffer(resp.data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert img is not None
    return img[..., ::-1] if img.ndim == 3 else img


def ident(c, path) -> str:
    (row,) = [r for r in c.get("/api/look/list").get_json() if Path(r["path"]) == Path(path)]
    return row["id"]


@pytest.fixture
def rng():
    return np.random.default_rng(18)


# ------------------------------------------------------------------ radiance
@pytest.mark.parametrize("ext", ["exr", "hdr", "tif", "pfm"])
def test_radiance_each_format_describes_draws_and_probes_exactly(tmp_path, rng, ext):
    rad = (rng.random((24, 36, 3)) * 8).astype(np.float32)
    p = tmp_path / f"radiance.{ext}"
    write_hdr_image(p, rad)
    on_disk = read_hdr_image(p)  # what the format keeps (RGBE and LogLuv quantise)
    c = client([p])
    d = c.get("/api/look/0").get_json()
    assert d["error"] is None and d["kind"] == "radiance"
    assert d["shape"] == [24, 36, 3] and d["display_size"] == [36, 24]
    assert [x["name"] for x in d["controls"]] == ["exposure", "tone"]
    img = decode(c.get("/api/look/0/image?exposure=-2&tone=linear&format=png"))
    assert img.shape == (24, 36, 3) and img.dtype == np.uint8
    exact = 255 * srgb_encode(np.clip(2.0 ** -2 * on_disk.astype(np.float64), 0, 1))
    assert np.abs(img - exact).max() <= HALF_CODE
    jpeg = c.get("/api/look/0/image?exposure=-2")  # the default encoder of a radiance map
    assert jpeg.mimetype == "image/jpeg" and decode(jpeg).shape == (24, 36, 3)
    for x, y in [(0, 0), (35, 23), (17, 5)]:
        pr = c.get(f"/api/look/0/probe?x={x + 0.6}&y={y + 0.2}").get_json()
        assert (pr["x"], pr["y"]) == (x, y)
        assert pr["value"] == on_disk[y, x].tolist() and "radiance" in pr["units"]


def test_radiance_display_copy_is_the_area_mean_and_probe_reads_full_resolution(tmp_path, rng):
    w = 2 * A.DISPLAY_MAX_PX  # halved exactly: the copy is the 2x2 block mean
    rad = np.exp(rng.normal(0, 2, (6, w, 3))).astype(np.float32)
    p = tmp_path / "big.exr"
    write_hdr_image(p, rad)
    c = client([p])
    d = c.get("/api/look/0").get_json()
    assert d["display_size"] == [A.DISPLAY_MAX_PX, 3] and d["display_scale"] == 0.5
    mean = rad.astype(np.float64).reshape(3, 2, A.DISPLAY_MAX_PX, 2, 3).mean(axis=(1, 3))
    art = A.load(p)
    # float32 sums of four: within 4 float32 roundings of the mean
    assert np.allclose(art.display, mean, rtol=4 * np.finfo(np.float32).eps, atol=0)
    for stops in (-3.0, 0.0, 2.5):
        img = decode(c.get(f"/api/look/0/image?exposure={stops}&format=png"))
        exact = 255 * srgb_encode(np.clip(2.0 ** stops * mean, 0, 1))
        assert img.shape == (3, A.DISPLAY_MAX_PX, 3)
        assert np.abs(img - exact).max() <= HALF_CODE + 255 * 12.92 * 4 * np.finfo(np.float32).eps
    pr = c.get("/api/look/0/probe?x=4001&y=5").get_json()  # a full-resolution pixel
    assert pr["value"] == rad[5, 4001].tolist()


def test_radiance_reinhard_local_is_the_projects_operator_at_the_key_of_the_exposure(tmp_path,
                                                                                     rng):
    rad = np.exp(rng.normal(0, 1.5, (20, 30, 3))).astype(np.float32)
    p = tmp_path / "r.exr"
    write_hdr_image(p, rad)
    img = decode(client([p]).get("/api/look/0/image?exposure=1&tone=reinhard-local&format=png"))
    assert np.array_equal(img, tonemap(rad, method="reinhard-local", key=0.18 * 2.0))


# Reinhard's global curve through the log indices (artifacts.Radiance._reinhard_global):
# three index roundings of 0.038 code each (channel, luminance, the ratio's offset)
# on top of the half code of rounding to 8 bits.
REINHARD_CODE = 0.5 + 3 * 255 * 1.055 / 2.4 * math.log(2) / (2 * A.LOG_STEPS)


@pytest.mark.parametrize("width, channels", [(30, 3), (30, 0), (30, 4),
                                             (2 * A.DISPLAY_MAX_PX, 3)])
def test_radiance_reinhard_global_within_half_a_code_of_the_projects_operator(
        tmp_path, rng, width, channels):
    # 2^+-9 around the mean: the picture spans black to white at every exposure
    shape = (8, width) + ((channels,) if channels else ())
    rad = np.exp(rng.normal(0, 3, shape)).astype(np.float32)
    rad[0, 0] = 0.0  # black stays black
    if channels:
        rad[0, 1, 1] = 0.0  # one channel zero: that channel stays at code 0
    p = tmp_path / "r.exr"
    if channels == 4:
        art = A.Radiance(p, rad)  # RGBA: alpha is not radiance, only RGB is drawn
    else:
        write_hdr_image(p, rad)
        art = A.load(p)
    rgb = art.display[..., :3] if art.display.ndim == 3 else art.display
    for stops in (-6.0, -2.0, 0.0, 3.0, 8.0):
        if channels == 4:
            img = art.image({"exposure": stops, "tone": "reinhard"})
        else:
            img = decode(client([p]).get(f"/api/look/0/image?exposure={stops}&tone=reinhard"
                                         "&format=png"))
        key = 0.18 * 2.0 ** stops
        # the project's operator before its rounding: its 16-bit output, within
        # half a 16-bit step of the exact value
        exact = tonemap(rgb, method="reinhard", key=key, bit_depth=16).astype(float) * 255 / 65535
        assert np.abs(img - exact).max() <= REINHARD_CODE + 0.5 * 255 / 65535
        ref = tonemap(rgb, method="reinhard", key=key)
        assert np.abs(img.astype(int) - ref).max() <= 1
    if width <= A.DISPLAY_MAX_PX:  # shown as it is: the black pixel stays black
        assert img[0, 0].tolist() == [0, 0, 0]
        if channels:
            assert img[0, 1, 1] == 0


# -------------------------------------------------------------------- images
@pytest.mark.parametrize("bits", [8, 16])
def test_plain_image_probe_is_the_code_and_16_bit_shows_its_top_byte(tmp_path, rng, bits):
    dt = np.uint8 if bits == 8 else np.uint16
    codes = rng.integers(0, 2 ** bits, (14, 22, 3), dtype=dt)
    p = tmp_path / "photo.png"
    write_image(p, codes)
    codes = read_image(p)
    c = client([p])
    d = c.get("/api/look/0").get_json()
    assert d["kind"] == "image" and d["units"] == f"{bits}-bit code"
    img = decode(c.get("/api/look/0/image"))
    expect = codes if bits == 8 else np.floor(codes / 257.0 + 0.5).astype(np.uint8)
    assert np.array_equal(img, expect)
    pr = c.get("/api/look/0/probe?x=21&y=13").get_json()
    assert pr["value"] == codes[13, 21].astype(float).tolist()


def test_grey_image_is_drawn_grey(tmp_path, rng):
    codes = rng.integers(0, 256, (5, 7), dtype=np.uint8)
    p = tmp_path / "grey.png"
    write_image(p, codes)
    img = decode(client([p]).get("/api/look/0/image"))
    assert img.shape == (5, 7, 3) and all(np.array_equal(img[..., k], codes) for k in range(3))


# ------------------------------------------------------- disparity, flow
def test_disparity_pfm_colour_map_and_unknown_pixels(tmp_path, rng):
    disp = (rng.random((12, 16)) * 30 + 2).astype(np.float32)
    disp[3, 4] = np.nan
    p = tmp_path / "disparity.pfm"
    write_pfm(p, disp)
    c = client([p])
    d = c.get("/api/look/0").get_json()
    assert d["kind"] == "scalar" and d["units"] == "px" and d["quantity"] == "disparity"
    assert d["range"] == [float(np.nanmin(disp)), float(np.nanmax(disp))]
    img = decode(c.get("/api/look/0/image?colours=grey"))
    lo, hi = d["range"]
    grey = np.floor((disp - lo) / (hi - lo) * 255 + 0.5)
    known = np.isfinite(disp)
    assert np.array_equal(img[..., 0][known], grey[known]) and img[3, 4].tolist() == [0, 0, 0]
    jet = decode(c.get(f"/api/look/0/image?colours=jet&lo={lo}&hi={hi}"))
    iy, ix = np.unravel_index(np.nanargmin(disp), disp.shape)
    assert jet[iy, ix].tolist() == cv2.applyColorMap(np.uint8([[0]]), cv2.COLORMAP_JET)[0, 0, ::-1].tolist()
    assert c.get("/api/look/0/probe?x=4&y=3").get_json()["value"] == [None]  # unknown
    assert c.get("/api/look/0/probe?x=5&y=3").get_json()["value"] == [float(disp[3, 5])]


def test_flow_is_the_middlebury_wheel_and_probe_is_the_vector(tmp_path, rng):
    flow = rng.normal(0, 3, (10, 13, 2)).astype(np.float32)
    flow[2, 2] = np.nan
    p = tmp_path / "flow.flo"
    write_flo(p, flow)
    c = client([p])
    d = c.get("/api/look/0").get_json()
    assert d["kind"] == "flow" and d["controls"][0]["name"] == "max_flow"
    img = decode(c.get("/api/look/0/image?max_flow=4"))
    assert np.array_equal(img, flow_to_colour(flow, max_flow=4.0))
    pr = c.get("/api/look/0/probe?x=7&y=9").get_json()
    assert pr["value"] == flow[9, 7].tolist() and pr["units"] == "px"
    assert pr["length"] == pytest.approx(float(np.hypot(*flow[9, 7].astype(np.float64))))
    assert c.get("/api/look/0/probe?x=2&y=2").get_json()["value"] == [None, None]


# --------------------------------------------------------------- light field
def test_lightfield_refocus_view_and_depth(tmp_path):
    from lumigraph.lightfield import ng2005
    from lumigraph.lightfield.field import LightField

    folder = tmp_path / "lf"
    shutil.copytree(ROOT / "fixtures" / "lightfield", folder)
    lf = LightField.load(folder)
    c = client([tmp_path])  # a folder: the light field is one artifact
    i = ident(c, folder / "lightfield.json")
    d = c.get(f"/api/look/{i}").get_json()
    assert d["kind"] == "lightfield" and d["grid"] == [3, 3]
    names = [x["name"] for x in d["controls"]]
    assert names == ["mode", "slope", "depth", "u", "v", "exposure"]  # focal_px is known
    refocused = ng2005.refocus(ng2005.prepare(lf, max_slope=A.MAX_SLOPE), 0.4)
    img = decode(c.get(f"/api/look/{i}/image?slope=0.4&exposure=1&format=png"))
    assert np.array_equal(img, A.expose_srgb(refocused, 1.0))
    pr = c.get(f"/api/look/{i}/probe?x=10&y=7&slope=0.4").get_json()
    assert pr["value"] == refocused[7, 10].tolist() and pr["slope"] == 0.4
    depth = lf.focal_px * lf.spacing / 0.4  # the same focus, asked by depth
    by_depth = decode(c.get(f"/api/look/{i}/image?depth={depth}&slope=-1&exposure=1&format=png"))
    assert np.array_equal(by_depth, img)
    view = decode(c.get(f"/api/look/{i}/image?mode=view&u=2&v=0&exposure=0&format=png"))
    assert np.array_equal(view, A.expose_srgb(lf.data[2, 0], 0.0))
    pr = c.get(f"/api/look/{i}/probe?x=47&y=39&mode=view&u=2&v=0").get_json()
    assert pr["value"] == lf.data[2, 0, 39, 47].tolist()


# ---------------------------------------------------- response, meta, json
def test_response_curve_plot_probe_and_meta_beside_it(tmp_path):
    p = tmp_path / "response.json"
    ResponseCurve.linear(8).save(p)
    curve = ResponseCurve.load(p)
    c = client([tmp_path])
    rows = c.get("/api/look/list").get_json()
    assert [r["kind"] for r in rows] == ["response"]  # the sidecar is not an artifact
    d = c.get("/api/look/0").get_json()
    assert d["kind"] == "response" and d["bit_depth"] == 8
    assert np.array_equal(np.array(d["curves"]), curve.g)
    assert d["meta"]["schema"] == "lumigraph.response"  # the .meta.json beside it
    img = decode(c.get("/api/look/0/image"))
    assert img.ndim == 3 and img.shape[2] == 3 and img.std() > 0  # a plot, not a blank
    assert c.get("/api/look/0/probe?x=200").get_json()["value"] == curve.g[:, 200].tolist()


def test_json_artifact_is_shown_as_text(tmp_path):
    p = tmp_path / "model.json"
    p.write_text('{"rms_px": 0.25, "blocks": []}')
    d = client([p]).get("/api/look/0").get_json()
    assert d["kind"] == "json" and '"rms_px": 0.25' in d["text"] and d["has_image"] is False


# ------------------------------------------------------------------ geometry
def test_point_cloud_geometry(tmp_path, rng):
    pts = rng.normal(0, 10, (50, 3))
    cols = rng.integers(0, 256, (50, 3), dtype=np.uint8)
    p = tmp_path / "points.ply"
    write_ply(p, pts, cols)
    c = client([p])
    d = c.get("/api/look/0").get_json()
    assert d["kind"] == "pointcloud" and d["has_geometry"] and not d["has_image"]
    g = c.get("/api/look/0/geometry").get_json()
    got = np.array(g["positions"]).reshape(-1, 3)
    # rounded to the decimals it says: within half a unit of the last one
    tol = 0.5 * 10.0 ** -g["decimals"] * (1 + 1e-9)
    assert np.all(np.abs(got - pts) <= tol) and g["colors"] == cols.ravel().tolist()
    assert g["faces"] is None and g["count"] == 50
    assert c.get("/api/look/0/image").status_code == 422


def test_facade_mesh_from_blocks_json_model_ply_and_model_obj(tmp_path):
    from lumigraph.stereo.debevec1996.model import load_blocks
    from lumigraph.stereo.debevec1996.outputs import mesh_obj_text, mesh_ply_bytes

    blocks = tmp_path / "blocks.json"
    shutil.copy(ROOT / "fixtures" / "facade" / "blocks.json", blocks)
    mesh = load_blocks(blocks).mesh()
    alone = tmp_path / "alone"  # no blocks.json beside: the mesh files are read themselves
    alone.mkdir()
    for folder in (tmp_path, alone):
        (folder / "model.ply").write_bytes(mesh_ply_bytes(mesh.vertices, mesh.faces))
        (folder / "model.obj").write_text(mesh_obj_text(mesh.vertices, mesh.faces))
    paths = [blocks, tmp_path / "model.ply", tmp_path / "model.obj", alone / "model.ply",
             alone / "model.obj"]
    c = client(paths)
    for i, path in enumerate(paths):
        d = c.get(f"/api/look/{i}").get_json()
        assert d["kind"] == "mesh" and d["error"] is None, (path, d["error"])
        g = c.get(f"/api/look/{i}/geometry").get_json()
        assert g["faces"] == mesh.faces.ravel().tolist()  # order and winding
        got = np.array(g["positions"]).reshape(-1, 3)
        # rounded to the decimals it says; the OBJ keeps 9 significant digits
        tol = 0.5 * 10.0 ** -g["decimals"] * (1 + 1e-9)
        tol += 5e-9 * np.abs(mesh.vertices) if path.suffix == ".obj" else 0
        assert np.all(np.abs(got - mesh.vertices) <= tol)


def test_a_ply_with_faces_is_a_mesh_whatever_its_name(tmp_path, rng):
    from lumigraph.stereo.debevec1996.outputs import mesh_ply_bytes

    v = rng.normal(0, 1, (7, 3))
    f = np.array([[0, 1, 2], [6, 3, 5], [4, 2, 1]])  # no symmetry: order and winding show
    (tmp_path / "scan.ply").write_bytes(mesh_ply_bytes(v, f))
    write_ply(tmp_path / "cloud.ply", v)
    c = client([tmp_path / "scan.ply", tmp_path / "cloud.ply"])
    assert c.get("/api/look/0").get_json()["kind"] == "mesh"
    assert c.get("/api/look/0/geometry").get_json()["faces"] == f.ravel().tolist()
    assert c.get("/api/look/1").get_json()["kind"] == "pointcloud"
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nf 1 2 3\n")
    d = client([bad]).get("/api/look/0").get_json()
    assert d["error"].startswith(f"{bad}: line 2:") and d["kind"] == "mesh"


# -------------------------------------------------------------- bad input
def test_unreadable_artifact_is_one_line_and_the_server_keeps_serving(tmp_path, rng):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr at all")
    short = tmp_path / "short.pfm"
    short.write_bytes(b"Pf\n10 10\n-1.0\n" + b"\0" * 12)
    good = tmp_path / "good.png"
    write_image(good, rng.integers(0, 256, (4, 4, 3), dtype=np.uint8))
    c = client([bad, short, tmp_path / "missing.flo", good])
    for i, path in enumerate([bad, short, tmp_path / "missing.flo"]):
        d = c.get(f"/api/look/{i}").get_json()
        assert d["error"].startswith(f"{path}: ") and "\n" not in d["error"], d["error"]
        r = c.get(f"/api/look/{i}/image")
        assert r.status_code == 422 and r.get_json()["error"] == d["error"]
        assert decode(c.get("/api/look/3/image")).shape == (4, 4, 3)  # still served
    rows = c.get("/api/look/list").get_json()
    assert rows[2]["error"].endswith("file not found") and "error" not in rows[3]


def test_bad_requests_name_what_is_wrong(tmp_path, rng):
    p = tmp_path / "r.exr"
    write_hdr_image(p, rng.random((4, 5, 3)).astype(np.float32))
    c = client([p])
    r = c.get("/api/look/0/image?exposure=99")
    assert r.status_code == 400 and r.get_json()["error"].startswith("exposure: expected")
    r = c.get("/api/look/0/image?tone=magic")
    assert r.status_code == 400 and r.get_json()["error"].startswith("tone: expected one of")
    r = c.get("/api/look/0/probe?x=5&y=0")
    assert r.status_code == 400 and "outside the 5x4 image" in r.get_json()["error"]
    assert c.get("/api/look/7").status_code == 404
    assert c.get("/api/look/0/geometry").status_code == 422


def test_a_rewritten_file_is_read_again(tmp_path):
    import os

    p = tmp_path / "r.pfm"
    write_pfm(p, np.full((2, 2, 3), 1.0, np.float32))
    c = client([p])
    assert c.get("/api/look/0/probe?x=0&y=0").get_json()["value"] == [1.0] * 3
    write_pfm(p, np.full((2, 2, 3), 2.0, np.float32))
    st = p.stat()
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # a coarse clock: a later mtime
    assert c.get("/api/look/0/probe?x=0&y=0").get_json()["value"] == [2.0] * 3


def test_wide_disparity_display_copy_averages_only_known_pixels(tmp_path, rng):
    w = 2 * A.DISPLAY_MAX_PX
    disp = (rng.random((4, w)) * 10).astype(np.float32)
    disp[0:2, 0:2] = np.nan  # a block wholly unknown
    disp[2, 2] = np.nan  # a block with one unknown pixel
    p = tmp_path / "disparity.pfm"
    write_pfm(p, disp)
    art = A.load(p)
    blocks = disp.astype(np.float64).reshape(2, 2, A.DISPLAY_MAX_PX, 2)
    known = np.isfinite(blocks).sum(axis=(1, 3))
    mean = np.where(known > 0, np.nansum(blocks, axis=(1, 3)) / np.maximum(known, 1), np.nan)
    assert np.isnan(art.small[0, 0]) and np.isnan(mean[0, 0])
    ok = np.isfinite(mean)
    # float32 sums of four and a division: a few float32 roundings of the values (<= 10)
    assert np.allclose(art.small[ok], mean[ok], rtol=0, atol=8 * 10 * np.finfo(np.float32).eps)
    pr = client([p]).get("/api/look/0/probe?x=4095&y=3").get_json()
    assert pr["value"] == [float(disp[3, 4095])]


def test_a_folder_lists_its_artifacts(tmp_path, rng):
    shutil.copytree(ROOT / "fixtures" / "lightfield", tmp_path / "lf")
    write_image(tmp_path / "a.png", rng.integers(0, 256, (3, 3), dtype=np.uint8))
    (tmp_path / "sub").mkdir()
    ResponseCurve.linear(8).save(tmp_path / "sub" / "response.json")
    (tmp_path / "notes.txt").write_text("not an artifact")
    (tmp_path / ".hidden.png").write_bytes(b"")
    c = client([tmp_path, tmp_path / "notes.txt"])
    rows = c.get("/api/look/list").get_json()
    names = [(Path(r["path"]).relative_to(tmp_path).as_posix(), r["kind"]) for r in rows]
    assert names == [("a.png", "image"), ("lf/lightfield.json", "lightfield"),
                     ("sub/response.json", "response"), ("notes.txt", None)]
    assert rows[-1]["error"].endswith("not an artifact lumigraph view shows")
    d = c.get(f"/api/look/{rows[-1]['id']}").get_json()
    assert d["error"].startswith(f"{tmp_path / 'notes.txt'}: not an artifact")
