"""The Façade chain on the command line: render the building, solve the
model from its marks, the model's depth from the key photograph, model-based
stereo for the relief the model lacks, and a view-dependent rendering."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture import io
from lumigraph.capture.render import render
from lumigraph.capture.scenes.facade import PILASTER_M

SIZE = (240, 180)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    s = render("facade", size=SIZE, seed=2, photos=6, novel=1, supersample=1, lambertian=True)
    return s.save(tmp_path_factory.mktemp("facade") / "photos"), s


def test_chain(folder, tmp_path):
    f, s = folder
    sol = tmp_path / "solve"
    r = lumigraph("stereo", "facade", "solve", f, "--out", sol, "-q")
    assert r.returncode == 0, r.stderr
    model = json.loads((sol / "model.json").read_text())
    for name, v in s.gt["parameters"].items():  # exact marks: the true model, to rounding
        assert model["parameters"][name]["value"] == pytest.approx(v, rel=1e-6)
    key, off = "photo_02", "photo_03"
    r = lumigraph("stereo", "facade", "depth", "--model", sol / "model.json", "--camera",
                  sol / "cameras" / f"{key}.json", "--out", tmp_path / "model.pfm", "-q")
    assert r.returncode == 0, r.stderr
    zm = io.read_pfm(tmp_path / "model.pfm")
    true_zm = s.gt_arrays["model_depth_02"]
    np.testing.assert_array_equal(np.isfinite(zm), np.isfinite(true_zm))
    np.testing.assert_allclose(zm[np.isfinite(zm)], true_zm[np.isfinite(zm)], rtol=1e-5)
    r = lumigraph("stereo", "facade", "pair", "--key", sol / "cameras" / f"{key}.json", "--offset",
                  sol / "cameras" / f"{off}.json", "--out", tmp_path / "rig.json", "-q")
    assert r.returncode == 0, r.stderr
    r = lumigraph("stereo", "model-based", f / f"{key}.png", f / f"{off}.png", "--rig",
                  tmp_path / "rig.json", "--model", tmp_path / "model.pfm", "--max-offset", "0.5",
                  "--out", tmp_path / "refined.pfm", "-q")
    assert r.returncode == 0, r.stderr
    z = io.read_pfm(tmp_path / "refined.pfm")
    truth = s.gt_arrays["depth_02"]
    relief = np.abs(truth - true_zm) > PILASTER_M / 2
    ok = np.isfinite(z) & np.isfinite(truth)
    assert (ok & relief).sum() > 20
    # the pilasters stand out of the model: recovered to better than half their relief
    assert np.median(np.abs(z - truth)[ok & relief]) < PILASTER_M / 2
    # the search following the model's σ: exact marks, so σ is round-off and the
    # answer that of the plain search up to the pixels a model edge may cross
    r = lumigraph("stereo", "facade", "depth", "--model", sol / "model.json", "--camera",
                  sol / "cameras" / f"{key}.json", "--out", tmp_path / "model2.pfm",
                  "--std-out", tmp_path / "std.pfm", "-q")
    assert r.returncode == 0, r.stderr
    sd = io.read_pfm(tmp_path / "std.pfm")
    assert np.array_equal(io.read_pfm(tmp_path / "model2.pfm"), zm, equal_nan=True)
    assert np.isfinite(sd[np.isfinite(zm)]).mean() > 0.9 and np.nanmax(sd[np.isfinite(sd)]) < 1e-3
    r = lumigraph("stereo", "model-based", f / f"{key}.png", f / f"{off}.png", "--rig",
                  tmp_path / "rig.json", "--model", tmp_path / "model.pfm", "--max-offset", "0.5",
                  "--model-std", tmp_path / "std.pfm", "--out", tmp_path / "refined2.pfm", "-q")
    assert r.returncode == 0, r.stderr
    z2 = io.read_pfm(tmp_path / "refined2.pfm")
    assert not (np.isfinite(z2) & ~np.isfinite(sd)).any()  # a model edge may cross: no answer
    assert np.isfinite(z2).sum() > 0.9 * np.isfinite(z).sum()
    # a blocks.json has no σ: refused, naming it
    r = lumigraph("stereo", "facade", "depth", "--model", f / "blocks.json", "--camera",
                  sol / "cameras" / f"{key}.json", "--out", tmp_path / "m3.pfm",
                  "--std-out", tmp_path / "s3.pfm")
    assert_clean_error(r, "blocks.json", "model.json")
    r = lumigraph("stereo", "facade", "render", "--model", sol / "model.json", "--photos", f,
                  "--view", f / "novel" / "view_0.json", "--out", tmp_path / "view.png", "-q")
    assert r.returncode == 0, r.stderr
    v = io.read_image(tmp_path / "view.png")
    assert v.shape == (SIZE[1], SIZE[0], 3)
    on = s.gt_arrays["novel_model_0"]
    # a diffuse building: the rendering is the novel view up to resampling (PSNR well above a
    # grey guess's ~10 dB)
    err = v[on].astype(float) - s.gt_arrays["novel_0"][on]
    assert 10 * np.log10(255 ** 2 / np.mean(err ** 2)) > 25


def test_a_solve_starts_from_an_earlier_solve(folder, tmp_path):
    """--rough-poses takes the rotations of a gt.json or of an earlier solve's
    model.json, --blocks another block model (here the earlier solve's
    blocks.json): to solve again after adding marks, from where the last
    solve ended. With exact marks either start ends at the true model, the
    meta names the files, and the earlier solve's files are never written
    over."""
    f, s = folder
    first = tmp_path / "first"
    r = lumigraph("stereo", "facade", "solve", f, "--out", first, "-q",
                  "--rough-poses", f / "gt.json")
    assert r.returncode == 0, r.stderr
    again = tmp_path / "again"
    r = lumigraph("stereo", "facade", "solve", f, "--out", again, "-q",
                  "--rough-poses", first / "model.json", "--blocks", first / "blocks.json")
    assert r.returncode == 0, r.stderr
    before = (first / "blocks.json").read_bytes()
    r = lumigraph("stereo", "facade", "solve", f, "--out", first, "--blocks", first / "blocks.json")
    assert_clean_error(r, "blocks.json", "input")
    assert (first / "blocks.json").read_bytes() == before
    meta = json.loads((again / "model.json.meta.json").read_text())
    assert any(str(i.get("path", i)) == str(first / "blocks.json") for i in meta["inputs"])
    for out, start in ((first, f / "gt.json"), (again, first / "model.json")):
        model = json.loads((out / "model.json").read_text())
        for name, v in s.gt["parameters"].items():
            assert model["parameters"][name]["value"] == pytest.approx(v, rel=1e-6)
        meta = json.loads((out / "model.json.meta.json").read_text())
        assert any(str(i.get("path", i)).endswith(str(start.name)) for i in meta["inputs"]), meta["inputs"]
    # a camera there without its rotation: one line naming the file and the entry
    bad = json.loads((first / "model.json").read_text())
    del next(iter(bad["cameras"].values()))["R"]
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    r = lumigraph("stereo", "facade", "solve", f, "--out", tmp_path / "third",
                  "--rough-poses", tmp_path / "bad.json")
    assert_clean_error(r, "bad.json", "R")


def test_bad_input_is_one_line(folder, tmp_path):
    f, _ = folder
    # a camera without a pose
    r = lumigraph("stereo", "facade", "depth", "--model", f / "blocks.json", "--camera",
                  f / "camera.json", "--out", tmp_path / "d.pfm")
    assert_clean_error(r, "camera.json", "cam_from_world")
    # a photograph whose camera is missing
    bad = tmp_path / "photos"
    shutil.copytree(f, bad)
    (bad / "cameras" / "photo_01.json").unlink()
    r = lumigraph("stereo", "facade", "render", "--model", bad / "blocks.json", "--photos", bad,
                  "--view", bad / "novel" / "view_0.json", "--out", tmp_path / "v.png")
    assert_clean_error(r, "photo_01")
    # a photograph of another size than its camera's
    shutil.copy(f / "cameras" / "photo_01.json", bad / "cameras" / "photo_01.json")
    img = io.read_image(bad / "photo_01.png")
    io.write_image(bad / "photo_01.png", np.ascontiguousarray(img[:-2]))
    r = lumigraph("stereo", "facade", "render", "--model", bad / "blocks.json", "--photos", bad,
                  "--view", bad / "novel" / "view_0.json", "--out", tmp_path / "v.png")
    assert_clean_error(r, "photo_01.png", "camera")


def test_linear_photographs_stay_linear(folder, tmp_path):
    f, s = folder
    lin = tmp_path / "linear"
    shutil.copytree(f, lin)
    names = []
    for name, img in zip(s.image_names, s.images, strict=True):
        exr = name.replace(".png", ".exr")
        # radiance = 4 x code: far above 1 and above 255, so a tone curve or an
        # 8-bit clip on the way would show
        io.write_exr(lin / exr, (img * 4.0).astype(np.float32))
        names.append(exr)
    io.write_stack_json(lin, names, blocks="blocks.json", edges="edges.json")
    for n in s.image_names:  # the cameras are found by the photographs' stems
        assert (lin / "cameras" / n.replace(".png", ".json")).is_file()
    args = ("stereo", "facade", "render", "--model", lin / "blocks.json", "--photos", lin,
            "--view", lin / "novel" / "view_0.json")
    r = lumigraph(*args, "--out", tmp_path / "view.exr", "-q")
    assert r.returncode == 0, r.stderr
    r = lumigraph(*args, "--out", tmp_path / "codes.png", "--photos", f, "-q")
    assert r.returncode == 0, r.stderr
    v = io.read_exr(tmp_path / "view.exr")
    codes = io.read_image(tmp_path / "codes.png").astype(np.float64)
    # the same blend of radiance as of codes, up to the PNG's rounding (half a code):
    # linear (no tone curve) and not clipped (the bright pixels are above 255)
    assert np.abs(v / 4.0 - codes).max() <= 0.5 + 1e-3
    assert v.max() > 255.0 and v.max() == pytest.approx(4.0 * codes.max(), abs=4 * 0.5 + 1e-3)
    # radiance into an 8-bit PNG would not be linear: refused
    r = lumigraph(*args, "--out", tmp_path / "view.png")
    assert_clean_error(r, "view.png", ".exr")


def test_several_views_in_one_call(folder, tmp_path):
    f, _ = folder
    base = ("stereo", "facade", "render", "--model", f / "blocks.json", "--photos", f,
            "--method", "view-map")
    views = [f / "novel" / "view_0.json", f / "cameras" / "photo_01.json"]
    r = lumigraph(*base, "--view", *views, "--out", tmp_path / "many")
    assert r.returncode == 0, r.stderr
    assert "view 2/2" in r.stderr  # progress per view
    index = json.loads((tmp_path / "many" / "index.json").read_text())
    assert sorted(index) == ["photo_01.png", "view_0.png"]
    for v in views:
        # the shared preparation changes nothing: each image is the one-view call's, bit for bit
        r = lumigraph(*base, "--view", v, "--out", tmp_path / f"{v.stem}.png", "-q")
        assert r.returncode == 0, r.stderr
        assert np.array_equal(io.read_image(tmp_path / "many" / f"{v.stem}.png"),
                              io.read_image(tmp_path / f"{v.stem}.png"))
        assert (tmp_path / "many" / f"{v.stem}.png.meta.json").is_file()
    # a folder of views: every camera.json in it, in name order
    r = lumigraph(*base, "--view", f / "cameras", "--out", tmp_path / "cams", "-q")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "cams").glob("*.png")) == \
        sorted(f"{p.stem}.png" for p in (f / "cameras").glob("*.json"))
    # several views into one file, and two views of one name: refused, naming the file
    r = lumigraph(*base, "--view", *views, "--out", tmp_path / "one.png")
    assert_clean_error(r, "one.png", "folder")
    r = lumigraph(*base, "--view", views[0], views[0], "--out", tmp_path / "twice")
    assert_clean_error(r, "view_0")


@pytest.mark.slow
def test_reflection_layer_on_the_command_line(folder, tmp_path):
    f, _ = folder
    base = ("stereo", "facade", "render", "--model", f / "blocks.json", "--photos", f,
            "--view", f / "novel" / "view_0.json")
    r = lumigraph(*base, "--reflection", "--out", tmp_path / "layer.png")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "layer.png.meta.json").read_text())
    assert meta["params"]["reflection"] is True
    groups = meta["reflection_layer"]
    # every orientation's choice on stderr and in the meta, with every candidate's score
    assert r.stderr.count("planes facing") == len(groups) > 0
    for g in groups:
        assert "none" in g["held_out_mse"] and len(g["held_out_mse"]) == 13
        if g["used"]:
            assert g["held_out_mse"][g["chosen"]] < g["held_out_mse"]["none"]
        else:
            assert g["chosen"] == "none"
    # the layer corrects the blend only
    r = lumigraph(*base, "--reflection", "--method", "view-map", "--out", tmp_path / "vm.png")
    assert_clean_error(r, "--reflection", "blend")


def test_reflection_layer_from_two_photographs_warns_it_is_not_used(folder, tmp_path):
    # two photographs: leaving one out leaves no point seen twice, so no layer can be
    # tested, none is used, and the command says so on stderr (not only in the meta)
    f, _ = folder
    two = tmp_path / "two"
    shutil.copytree(f, two)
    stack = json.loads((two / "stack.json").read_text())
    stack["images"] = ["photo_02.png", "photo_03.png"]
    (two / "stack.json").write_text(json.dumps(stack))
    r = lumigraph("stereo", "facade", "render", "--model", two / "blocks.json", "--photos", two,
                  "--view", two / "novel" / "view_0.json", "--reflection", "--out", tmp_path / "v.png")
    assert r.returncode == 0, r.stderr
    assert "no plane orientation's layer" in r.stderr and "plain blend" in r.stderr
    meta = json.loads((tmp_path / "v.png.meta.json").read_text())
    assert meta["reflection_layer"] and not any(g["used"] for g in meta["reflection_layer"])
    # two photographs of a building leave walls that one alone sees: the share is in
    # the meta and the summary line, and on stderr as a warning past a fifth of the view
    one = meta["quality"]["seen_by_one_fraction"]
    assert 0 < one < 1 and "seen by one photograph only" in r.stderr, one
    assert (one > 0.2) == ("colour there is that photograph's" in r.stderr)
    # one photograph: every pixel it sees is seen by it alone, and the warning says so
    stack["images"] = ["photo_02.png"]
    (two / "stack.json").write_text(json.dumps(stack))
    r = lumigraph("stereo", "facade", "render", "--model", two / "blocks.json", "--photos", two,
                  "--view", two / "novel" / "view_0.json", "--out", tmp_path / "v1.png")
    assert r.returncode == 0, r.stderr
    q = json.loads((tmp_path / "v1.png.meta.json").read_text())["quality"]
    assert q["seen_by_one_fraction"] == pytest.approx(1 - q["hole_fraction"], abs=1e-12)
    assert "colour there is that photograph's" in r.stderr
    # the view map counts them as well
    r = lumigraph("stereo", "facade", "render", "--model", two / "blocks.json", "--photos", two,
                  "--view", two / "novel" / "view_0.json", "--method", "view-map",
                  "--out", tmp_path / "v2.png")
    assert r.returncode == 0, r.stderr
    q = json.loads((tmp_path / "v2.png.meta.json").read_text())["quality"]
    assert q["seen_by_one_fraction"] == pytest.approx(1 - q["hole_fraction"], abs=1e-12)
    assert "colour there is that photograph's" in r.stderr


@pytest.mark.slow
def test_reflection_layer_on_a_glossy_building(tmp_path):
    s = render("facade", size=(160, 120), seed=2, photos=8, novel=1, supersample=1)
    f = s.save(tmp_path / "photos")
    r = lumigraph("stereo", "facade", "render", "--model", f / "blocks.json", "--photos", f,
                  "--view", f / "novel" / "view_0.json", "--reflection", "--out", tmp_path / "v.png")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "v.png.meta.json").read_text())
    used = [g for g in meta["reflection_layer"] if g["used"]]
    assert used  # the glossy walls' reflections are found
    for g in used:  # a used layer predicts held-out photographs better than none
        assert g["held_out_mse"][g["chosen"]] < g["held_out_mse"]["none"]
    assert "layer " in r.stderr
