"""``lumigraph hdr`` end to end, bad input, and the quick bench."""

import json
import shutil

import numpy as np
import pytest
from conftest import assert_clean_error, lumigraph

from lumigraph.capture.io import read_exr
from lumigraph.capture.render import render


def _bracket_folder(tmp_path, **kw):
    d = tmp_path / "bracket"
    render("bracket", **kw).save(d)
    return d


def test_response_merge_tonemap_convert_chain(tmp_path):
    d = _bracket_folder(tmp_path)
    r = lumigraph("hdr", "response", d, "--out", tmp_path / "r.json", "--plot", tmp_path / "c.png",
                  "-q")
    assert r.returncode == 0, r.stderr
    body = json.loads((tmp_path / "r.json").read_text())
    assert {"method", "bit_depth", "g", "exposure_times", "selection", "warnings"} <= set(body)
    assert len(body["g"]) == 3 and len(body["g"][0]) == 256
    r = lumigraph("hdr", "merge", d, "--response", tmp_path / "r.json", "--out",
                  tmp_path / "rad.exr", "-q")
    assert r.returncode == 0, r.stderr
    assert "clipped in every exposure" in r.stderr  # the emitters: said, not silent
    rad = read_exr(tmp_path / "rad.exr")
    assert rad.shape == (120, 160, 3) and np.isfinite(rad).all()
    assert (tmp_path / "rad.mask.png").exists() and (tmp_path / "rad.exr.meta.json").exists()
    r = lumigraph("hdr", "tonemap", tmp_path / "rad.exr", "--method", "reinhard-local",
                  "--out", tmp_path / "t.png", "-q")
    assert r.returncode == 0, r.stderr
    r = lumigraph("hdr", "convert", tmp_path / "rad.exr", tmp_path / "rad.tif", "-q")
    assert r.returncode == 0, r.stderr


def test_linear_input_needs_no_curve(tmp_path):
    d = _bracket_folder(tmp_path, response="linear", bit_depth=12)
    r = lumigraph("hdr", "response", d, "--out", tmp_path / "r.json")
    assert r.returncode == 0, r.stderr
    assert "no response curve is needed" in r.stderr
    assert json.loads((tmp_path / "r.json").read_text())["method"] == "linear"


def test_bad_inputs_exit_2_and_write_nothing(tmp_path):
    d = _bracket_folder(tmp_path, exposures=3)
    imgs = sorted(str(p) for p in d.glob("*.png"))
    out = tmp_path / "r.json"
    r = lumigraph("hdr", "response", *imgs, "--times", "0.01,0.01,0.1", "--out", out)
    assert_clean_error(r, "--times", "duplicated")
    r = lumigraph("hdr", "response", *imgs, "--out", out)
    assert_clean_error(r, "exposure time")
    r = lumigraph("hdr", "response", *imgs, "--times", "0.01,-1,0.1", "--out", out)
    assert_clean_error(r, "--times", "> 0")  # the parser's type: before any image is read
    other = tmp_path / "other"
    render("bracket", size=(80, 60), exposures=1).save(other)
    shutil.copy(other / "exposure_00.png", tmp_path / "small.png")
    r = lumigraph("hdr", "response", imgs[0], imgs[1], tmp_path / "small.png", "--times",
                  "1,2,3", "--out", out)
    assert_clean_error(r, "small.png")
    (tmp_path / "bad.json").write_text("{}")
    r = lumigraph("hdr", "merge", d, "--response", tmp_path / "bad.json", "--out",
                  tmp_path / "x.exr")
    assert_clean_error(r, "bad.json")
    assert not out.exists() and not (tmp_path / "x.exr").exists()


def test_python_dash_m_hdr_works():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "lumigraph.hdr", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "response" in r.stdout


@pytest.mark.slow
def test_quick_bench_through_cli(tmp_path):
    r = lumigraph("bench", "hdr", "--quick", "--out", tmp_path, "-q")
    assert r.returncode == 0, r.stderr
    js = json.loads((tmp_path / "report.json").read_text())
    names = {row["method"] for row in js["stages"]["hdr"]["rows"]}
    assert {"debevec (ours)", "CalibrateDebevec (OpenCV)", "merge (ours)"} <= names
    assert js["stages"]["hdr"]["checks"]


def test_library_errors_name_arguments_and_the_cli_names_flags(tmp_path):
    import re
    from pathlib import Path

    from lumigraph.capture.errors import InputError
    from lumigraph.hdr.debevec1997 import response_debevec1997
    from lumigraph.hdr.mitsunaga1999 import response_mitsunaga1999
    from lumigraph.hdr.samples import check_stack

    s = render("bracket", size=(48, 36), exposures=3)
    z, t = np.stack(s.images), s.stack["exposure_times_s"]
    with pytest.raises(InputError) as e:
        response_debevec1997(z, t, smoothness=-1.0)
    assert e.value.where == "smoothness"
    with pytest.raises(InputError) as e:
        response_mitsunaga1999(z, t, order=11)
    assert e.value.where == "order"
    with pytest.raises(InputError) as e:
        check_stack(z, [t[0], t[0], t[2]], bit_depth=8)
    assert e.value.where == "exposure_times_s"
    # No library module of the stage names a command-line flag.
    root = Path(__file__).resolve().parents[2]
    for f in [*(root / "hdr").glob("*.py"), *(root / "separation").glob("*.py")]:
        if f.name != "cli.py":
            assert not re.search(r"Error\(\s*f?[\"']--", f.read_text()), f
    d = _bracket_folder(tmp_path, exposures=3)
    out = tmp_path / "r.json"
    assert_clean_error(lumigraph("hdr", "response", d, "--smoothness", "-1", "--out", out),
                       "--smoothness", ">= 0 or auto")
    assert_clean_error(lumigraph("hdr", "response", d, "--method", "mitsunaga-nayar", "--order",
                                 "11", "--out", out), "--order")
    assert not out.exists()


def test_the_library_checks_samples_noise_and_temporal_and_the_cli_names_the_flags(tmp_path):
    # The ranges 'hdr response/merge/video' enforce are the library's own:
    # each function refuses a bad value naming its argument, and the command
    # line reports it under the flag that sets it.
    from lumigraph.capture.errors import InputError
    from lumigraph.hdr.kang2003 import hdr_video, tonemap_video
    from lumigraph.hdr.merge import merge
    from lumigraph.hdr.methods import RESPONSE_METHODS
    from lumigraph.hdr.response import ResponseCurve

    s = render("bracket", size=(48, 36), exposures=3)
    z, t = np.stack(s.images), s.stack["exposure_times_s"]
    curve = ResponseCurve.linear(8)
    for m in RESPONSE_METHODS.values():
        if "samples" in m.options:
            with pytest.raises(InputError) as e:
                m.load()(z, t, samples=1)
            assert e.value.where == "samples", m.name
    for kw, where in ((dict(full_well_e=0.0), "full_well_e"),
                      (dict(full_well_e=float("inf")), "full_well_e"),
                      (dict(read_noise_e=-1.0), "read_noise_e"),
                      (dict(read_noise_e=float("nan")), "read_noise_e"),
                      (dict(weights="hat", read_noise_e=4.0), "read_noise_e"),
                      (dict(weights="hat", full_well_e=2e4, read_noise_e=4.0), "full_well_e")):
        with pytest.raises(InputError) as e:
            merge(z, t, curve, **kw)
        assert e.value.where == where, kw
    # the default noise model is the same number whether given or not
    assert np.array_equal(merge(z, t, curve).radiance,
                          merge(z, t, curve, full_well_e=1e4, read_noise_e=5.0).radiance)
    with pytest.raises(InputError) as e:
        tonemap_video(np.ones((2, 4, 4, 3), np.float32), temporal=4)
    assert e.value.where == "temporal"
    with pytest.raises(InputError) as e:
        hdr_video(z[:1], t[:1], curve)
    assert e.value.where == "frames"
    d = tmp_path / "b"
    s.save(d)
    out = tmp_path / "r.json"
    for method in ("debevec", "linear"):
        assert_clean_error(lumigraph("hdr", "response", d, "--method", method, "--samples", "1",
                                     "--out", out), "--samples", ">= 2")
    assert_clean_error(lumigraph("hdr", "merge", d, "--response", tmp_path / "none.json",
                                 "--noise", "0,4", "--out", tmp_path / "x.exr"), "--noise", "full well")
    assert_clean_error(lumigraph("hdr", "video", d, "--response", tmp_path / "none.json",
                                 "--temporal", "2", "--out", tmp_path / "v"), "--temporal")
    assert not out.exists() and not (tmp_path / "x.exr").exists() and not (tmp_path / "v").exists()


def test_aperture_bracket_means_the_same_to_merge_and_video(tmp_path):
    # One shutter time, three f-numbers: every HDR verb works with the effective
    # exposure t·(N_ref/N)² of the stack reader (without it, video would see three
    # equal exposures and refuse).
    from lumigraph.capture.io import read_stack
    from lumigraph.hdr.response import ResponseCurve

    s = render("bracket", size=(64, 48), exposures=3, vary="aperture")
    d = tmp_path / "ap"
    s.save(d)
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(tmp_path / "r.json")
    stack = read_stack([d])
    assert len(set(stack.exposure_times_s)) == 1
    expected = list(stack.effective_exposure_times_s)
    assert expected == pytest.approx(s.gt["relative_exposure_exact"], rel=1e-12)
    r = lumigraph("hdr", "merge", d, "--response", tmp_path / "r.json", "--out",
                  tmp_path / "rad.exr", "-q")
    assert r.returncode == 0, r.stderr
    merged = json.loads((tmp_path / "rad.exr.meta.json").read_text())["params"]["times_s"]
    r = lumigraph("hdr", "video", d, "--response", tmp_path / "r.json", "--out",
                  tmp_path / "vid", "-q")
    assert r.returncode == 0, r.stderr
    video = json.loads((tmp_path / "vid" / "video.meta.json").read_text())["params"]["times_s"]
    assert merged == video == expected
    # Times given on the command line are the exposures themselves, for every verb.
    r = lumigraph("hdr", "video", d, "--times", "1,2,4", "--response", tmp_path / "r.json",
                  "--out", tmp_path / "vid2", "-q")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "vid2" / "video.meta.json").read_text())["params"]["times_s"] \
        == [1.0, 2.0, 4.0]


@pytest.mark.parametrize("verb,registry", [("response", "RESPONSE_METHODS"),
                                           ("tonemap", "TONEMAP_METHODS"),
                                           ("align", "ALIGN_METHODS")])
def test_method_choices_and_help_come_from_the_registries(verb, registry):
    from lumigraph.capture.registry import Registry
    from lumigraph.hdr import methods

    reg = getattr(methods, registry)
    assert isinstance(reg, Registry)
    r = lumigraph("hdr", verb, "--help")
    assert r.returncode == 0, r.stderr
    assert "{" + ",".join(reg.names) + "}" in r.stdout
    for m in reg.values():
        assert m.help in r.stdout
        assert callable(m.load())


def test_tonemap_refuses_nan_in_the_library_and_the_cli_names_the_file(tmp_path):
    from lumigraph.capture.errors import InputError
    from lumigraph.capture.io import write_exr
    from lumigraph.hdr.reinhard2002 import tonemap

    rad = np.ones((8, 8, 3), np.float32)
    rad[2, 2, 1] = np.nan
    with pytest.raises(InputError) as e:
        tonemap(rad)
    assert e.value.where == "radiance"
    write_exr(tmp_path / "nan.exr", rad)
    r = lumigraph("hdr", "tonemap", tmp_path / "nan.exr", "--out", tmp_path / "t.png")
    assert_clean_error(r, "nan.exr", "NaN/inf")
    assert not (tmp_path / "t.png").exists()
