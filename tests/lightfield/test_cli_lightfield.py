"""``lumigraph lightfield`` end to end, and its bad-input errors."""

import json

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.io import read_exr, write_image
from lumigraph.capture.render import render


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("lfscene")
    render("lightfield-array", size=(48, 40), grid="3x3", thin_lens=False).save(d)
    return d


@pytest.fixture(scope="module")
def lfdir(scene_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("lf") / "lf"
    r = lumigraph("lightfield", "import", scene_dir, "--out", out)
    assert r.returncode == 0, r.stderr
    return out


def test_import_from_rendered_folder_is_linear_and_exact(lfdir):
    from lumigraph.lightfield.field import LightField

    lf = LightField.load(lfdir)
    assert lf.grid == (3, 3) and lf.size == (48, 40) and lf.focal_px == 48.0
    s = render("lightfield-array", size=(48, 40), grid="3x3", thin_lens=False)
    # 16-bit linear codes back to radiance: within half a code of the truth.
    assert np.abs(lf.data - s.gt_arrays["views"]).max() <= 0.5 / 65535 + 1e-7


def test_import_files_srgb_and_bad_inputs(tmp_path):
    imgs = [np.full((8, 10, 3), 10 * k, np.uint8) for k in range(6)]
    files = []
    for k, im in enumerate(imgs):
        files.append(tmp_path / f"v{k}.png")
        write_image(files[-1], im)
    r = lumigraph("lightfield", "import", *files, "--grid", "2x3", "--spacing", "0.1",
                  "--out", tmp_path / "ok")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "ok" / "lightfield.json").read_text())
    assert meta["grid"] == [2, 3] and meta["views"][3] == "view-01-00.exr"
    v = read_exr(tmp_path / "ok" / "view-01-02.exr")
    assert v[0, 0, 0] == pytest.approx(((50 / 255 + 0.055) / 1.055) ** 2.4, rel=1e-5)

    r = lumigraph("lightfield", "import", *files[:5], "--grid", "2x3", "--spacing", "1",
                  "--out", tmp_path / "bad1")
    assert_clean_error(r, "--grid", "needs 6 images, got 5")
    assert not (tmp_path / "bad1").exists()
    write_image(tmp_path / "small.png", np.zeros((6, 10, 3), np.uint8))
    r = lumigraph("lightfield", "import", *files[:5], tmp_path / "small.png", "--grid", "2x3",
                  "--spacing", "1", "--out", tmp_path / "bad2")
    assert_clean_error(r, "small.png", "one size")
    assert not (tmp_path / "bad2").exists()
    r = lumigraph("lightfield", "import", *files, "--grid", "2by3", "--spacing", "1",
                  "--out", tmp_path / "bad3")
    assert_clean_error(r, "--grid")
    assert not (tmp_path / "bad3").exists()
    # without --spacing: imported (refocus by slope); depths refused, naming --spacing
    # (tests/lightfield/test_cli_number_lists.py)


def test_refocus_one_several_auto_and_warnings(lfdir, tmp_path):
    r = lumigraph("lightfield", "refocus", lfdir, "--slope", "0.5", "--out", tmp_path / "f.exr")
    assert r.returncode == 0, r.stderr
    assert read_exr(tmp_path / "f.exr").shape == (40, 48, 3)
    meta = json.loads((tmp_path / "f.exr.meta.json").read_text())
    assert meta["model"]["method"] == "shift-add"
    depths = [str(48 / s) for s in np.linspace(0.1, 1.0, 10)]
    r = lumigraph("lightfield", "refocus", lfdir, "--depth", *depths, "--method", "auto",
                  "--out", tmp_path / "stack")
    assert r.returncode == 0, r.stderr
    index = json.loads((tmp_path / "stack" / "index.json").read_text())
    assert len(index) == 10 and index["refocus-009.exr"]["slope"] == pytest.approx(1.0)
    meta = json.loads((tmp_path / "stack" / "index.json.meta.json").read_text())
    assert meta["model"]["method"] == "fourier"
    r = lumigraph("lightfield", "refocus", lfdir, "--alpha", "4", "--out", tmp_path / "a.exr")
    assert r.returncode == 0 and "outside Ng's exact refocusing range" in r.stderr
    assert json.loads((tmp_path / "a.exr.meta.json").read_text())["warnings"]


def test_refocus_bad_input(lfdir, tmp_path):
    r = lumigraph("lightfield", "refocus", lfdir, "--slope", "0.5", "0.6", "--out",
                  tmp_path / "x.exr")
    assert_clean_error(r, "error: --out:", "2 values write a folder")  # not a folder named x.exr
    r = lumigraph("lightfield", "refocus", lfdir, "--slope", "0.5", "--out", tmp_path / "y.png")
    assert_clean_error(r, "--out", ".exr")
    r = lumigraph("lightfield", "refocus", lfdir, "--depth", "-3", "--out", tmp_path / "z.exr")
    assert_clean_error(r, "--depth", "> 0")
    r = lumigraph("lightfield", "refocus", tmp_path, "--slope", "1", "--out", tmp_path / "w.exr")
    assert_clean_error(r, "lightfield.json")
    assert not any((tmp_path / n).exists() for n in ("x.exr", "y.png", "z.exr", "w.exr"))


def test_render_and_decode(lfdir, tmp_path):
    r = lumigraph("lightfield", "render", lfdir, "--position", "0.5", "0.5", "0",
                  "--out", tmp_path / "v.exr")
    assert r.returncode == 0, r.stderr
    v = read_exr(tmp_path / "v.exr")
    assert v.shape == (40, 48, 4) and (v[..., 3] == 1).all()
    r = lumigraph("lightfield", "render", lfdir, "--position", "9", "0", "0",
                  "--out", tmp_path / "none.exr")
    assert_clean_error(r, "--position", "leaves the light slab")
    assert not (tmp_path / "none.exr").exists()

    s = render("lightfield-lenslet-hex", size=(12, 12))
    s.save(tmp_path / "raw")
    r = lumigraph("lightfield", "decode", tmp_path / "raw" / "raw.png", "--white",
                  tmp_path / "raw" / "white.png", "--out", tmp_path / "dec")
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "dec" / "lightfield.json").read_text())
    assert meta["grid"] == [5, 5] and meta["info"]["lenslet_grid"]["lattice"] == "hex"
    write_image(tmp_path / "w2.png", np.zeros((30, 30), np.uint16))
    r = lumigraph("lightfield", "decode", tmp_path / "raw" / "raw.png", "--white",
                  tmp_path / "w2.png", "--out", tmp_path / "dec2")
    assert_clean_error(r, "w2.png", "white image")
    assert not (tmp_path / "dec2").exists()


@pytest.mark.slow
def test_python_dash_m_and_bench_quick(tmp_path):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "lumigraph.lightfield", "--help"], capture_output=True,
                       text=True)
    assert r.returncode == 0 and "refocus" in r.stdout
    r = lumigraph("bench", "lightfield", "--quick", "--out", tmp_path, "-q")
    assert r.returncode == 0, r.stderr
    js = json.loads((tmp_path / "report.json").read_text())
    checks = {c["target"]: c for c in js["stages"]["lightfield"]["checks"]}
    assert any("lenslet hex" in t and c["passed"] for t, c in checks.items())
    assert (tmp_path / "lightfield.png").exists()


def test_value_checks_live_in_the_library_and_the_cli_names_flags(lfdir, tmp_path):
    # the library checks the values it takes, naming the argument ...
    from lumigraph.capture.errors import InputError
    from lumigraph.lightfield.field import LightField, check_from_images
    from lumigraph.lightfield.levoy1996 import render_view
    from lumigraph.lightfield.refocus import check_disparity_slopes, estimate_disparity

    with pytest.raises(InputError, match="^spacing: expected a positive number, got 0"):
        check_from_images(4, grid=(2, 2), spacing=0)
    with pytest.raises(InputError, match="^focal_px: expected a positive number, got inf"):
        check_from_images(4, grid=(2, 2), spacing=1, focal_px=float("inf"))
    with pytest.raises(InputError, match="^grid: a 2x2 grid needs 4 images, got 3"):
        check_from_images(3, grid=(2, 2), spacing=1)
    lf = LightField(np.zeros((2, 2, 4, 5, 1), np.float32))
    with pytest.raises(InputError, match="^spacing"):
        LightField(lf.data, spacing=-1.0)
    with pytest.raises(InputError, match="^position: Z != 0 needs the light field's focal_px"):
        render_view(lf, (0, 0, 1))
    with pytest.raises(InputError, match="^slopes: expected at least 3"):
        check_disparity_slopes([0.0, 1.0])
    with pytest.raises(InputError, match="^slopes: expected increasing"):
        estimate_disparity(lf, [0.0, 0.0, 0.0])
    # ... and the command line names the flag, checked before any file is read (the ranges
    # by the parser, in the library's terms; what needs the files by the library)
    gone = [tmp_path / f"v{k}.png" for k in range(4)]
    out = tmp_path / "lf"
    for extra, line in ((("--spacing", "0"), "error: --spacing: expected a number > 0, got '0'"),
                        (("--spacing", "inf"), "error: --spacing: expected a number > 0, got 'inf'"),
                        (("--spacing", "1", "--focal-px", "-5"), "error: --focal-px: expected a number > 0"),
                        (("--spacing", "1", "--grid", "3x3"), "error: --grid: a 3x3 grid needs 9 images")):
        r = lumigraph("lightfield", "import", *gone, "--grid", "2x2", *extra, "--out", out)
        assert_clean_error(r, line)
    assert not out.exists()
    for slopes, line in (("1,0,5", "error: --slopes: expected MIN,MAX,N with MIN < MAX"),
                         ("0,1,2", "error: --slopes: expected MIN,MAX,N with MIN < MAX and N an "
                                   "integer >= 3"),
                         ("0,1", "error: --slopes: expected MIN,MAX,N"),
                         ("0,1,nan", "error: --slopes: expected MIN,MAX,N"),
                         ("0,1,-4", "error: --slopes: expected MIN,MAX,N")):
        r = lumigraph("lightfield", "depth", tmp_path / "no-lf", f"--slopes={slopes}",
                      "--out", tmp_path / "d.pfm")
        assert_clean_error(r, line)
    # a light field imported without a focal length cannot move the pinhole off the plane
    views = []
    for k in range(4):
        views.append(tmp_path / f"w{k}.png")
        write_image(views[-1], np.full((8, 10, 3), 40 * k, np.uint8))
    r = lumigraph("lightfield", "import", *views, "--grid", "2x2", "--spacing", "1", "--out", out)
    assert r.returncode == 0, r.stderr
    r = lumigraph("lightfield", "render", out, "--position", "0", "0", "1", "--out", tmp_path / "v.exr")
    assert_clean_error(r, "error: --position: Z != 0 needs the light field's focal_px")
    assert not (tmp_path / "v.exr").exists() and not (tmp_path / "d.pfm").exists()


def test_depth_hard_edges_is_the_library_without_softening(lfdir, tmp_path):
    from lumigraph.capture.io import read_pfm
    from lumigraph.lightfield.field import LightField
    from lumigraph.lightfield.wang2015 import estimate_disparity

    r = lumigraph("lightfield", "depth", lfdir, "--slopes=-1,1,9", "--edges", "hard",
                  "--out", tmp_path / "hard.pfm")
    assert r.returncode == 0, r.stderr
    lib = estimate_disparity(LightField.load(lfdir), np.linspace(-1, 1, 9), soft_edges=False)
    # the same call: identical floats
    np.testing.assert_array_equal(read_pfm(tmp_path / "hard.pfm"), lib.disparity)
    meta = json.loads((tmp_path / "hard.pfm.meta.json").read_text())
    assert meta["params"]["soft_edges"] is False
    r = lumigraph("lightfield", "depth", lfdir, "--slopes=-1,1,9", "--method", "variance",
                  "--edges", "hard", "--out", tmp_path / "v.pfm")
    assert_clean_error(r, "--edges", "wang2015")
    assert not (tmp_path / "v.pfm").exists()
