"""Real-capture hard cases of issue 13: EXIF Orientation (portrait phone JPEGs,
orientation 6 and 8, in every image reader), and exposure times that disagree
with the images' brightness order (reversed, shuffled, a swapped pair, two
exposures only): exit 2 naming the files, ``--force`` accepts."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image, ImageOps

from lumigraph.capture.io import apply_orientation, image_orientation, read_image, read_stack

ORIENTATION = 0x0112


def _stored(h=24, w=36):
    """A stored (sensor-order) RGB image whose every pixel is unique, so any
    wrong rotation or mirror shows."""
    y, x = np.mgrid[0:h, 0:w]
    return np.stack([x * 7 % 256, y * 10 % 256, (x + 3 * y) % 256], axis=-1).astype(np.uint8)


def _save(path, arr, orientation):
    im = Image.fromarray(arr)
    ex = Image.Exif()
    ex[ORIENTATION] = orientation
    if path.suffix == ".jpg":
        im.save(path, quality=100, subsampling=0, exif=ex.tobytes())
    elif path.suffix == ".png":
        im.save(path, exif=ex.tobytes())
    else:
        im.save(path, tiffinfo={ORIENTATION: orientation})


@pytest.mark.parametrize("suffix", [".png", ".tif"])
@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_orientation_is_read_as_pillow_exif_transpose_shows_it(orientation, suffix,
                                                                      tmp_path):
    arr = _stored()
    f = tmp_path / f"a{suffix}"
    _save(f, arr, orientation)
    with Image.open(f) as im:
        want = np.asarray(ImageOps.exif_transpose(im))
    assert np.array_equal(apply_orientation(arr, orientation), want)
    assert np.array_equal(read_image(f), want)


@pytest.mark.parametrize("suffix", [".jpg", ".png", ".tif"])
@pytest.mark.parametrize("orientation", [6, 8])
def test_portrait_file_is_read_upright_and_recorded(tmp_path, suffix, orientation):
    arr = _stored()  # stored landscape 36x24; displayed portrait 24x36
    f = tmp_path / f"portrait{suffix}"
    _save(f, arr, orientation)
    img = read_image(f)
    assert img.shape[:2] == (36, 24)
    assert image_orientation(f) == orientation
    want = apply_orientation(arr, orientation)
    # JPEG is lossy: within a few codes at quality 100, 4:4:4; PNG/TIFF exactly
    tol = 8 if suffix == ".jpg" else 0
    assert np.abs(img.astype(int) - want.astype(int)).max() <= tol
    stack = read_stack([f, f], times=[0.01, 0.02])
    assert stack.orientations == (orientation, orientation)
    assert stack.images.shape[1:3] == (36, 24)


def test_unoriented_file_is_read_as_stored(tmp_path):
    arr = _stored()
    f = tmp_path / "plain.png"
    Image.fromarray(arr).save(f)
    assert image_orientation(f) == 1
    assert np.array_equal(read_image(f), arr)


# ------------------------------------------------------ exposure order vs brightness
@pytest.fixture(scope="module")
def bracket(tmp_path_factory):
    from lumigraph.capture.render import render

    d = tmp_path_factory.mktemp("order") / "bracket"
    s = render("bracket", size=(96, 72), seed=0)
    s.save(d)
    import json

    files = [d / f for f in json.loads((d / "stack.json").read_text())["images"]]
    return files, list(s.stack["exposure_times_s"])


def _check(files, times, **kw):
    from lumigraph.capture.exposure import check_brightness_order

    stack = read_stack(files)
    return check_brightness_order(stack.images, times, stack.paths, **kw)


def test_times_in_file_order_pass(bracket):
    files, t = bracket
    assert _check(files, t) == []
    assert _check(files[:2], t[:2]) == []  # two exposures only


@pytest.mark.parametrize("how", ["reversed", "shuffled", "swapped pair", "two swapped"])
def test_times_out_of_the_images_order_are_an_error_naming_the_files(bracket, how):
    from lumigraph.capture.errors import InputError

    files, t = bracket
    if how == "reversed":
        bad = t[::-1]
    elif how == "shuffled":
        bad = [t[i] for i in np.random.default_rng(5).permutation(len(t))]
        assert bad != t
    elif how == "swapped pair":
        bad = list(t)
        bad[2], bad[3] = bad[3], bad[2]
    else:
        files, bad = files[:2], t[:2][::-1]
    with pytest.raises(InputError) as e:
        _check(files, bad)
    named = [f.name for f in files if f.name in str(e.value)]
    assert len(named) >= 2, str(e.value)  # the longer exposure's file and the other one
    assert len(_check(files, bad, force=True)) >= 1  # --force: warnings instead


def test_cli_refuses_reversed_times_with_exit_2_and_force_accepts_them(bracket, tmp_path):
    from conftest import assert_clean_error, lumigraph

    files, t = bracket
    times = ",".join(f"{x:.9g}" for x in t[::-1])
    args = ("hdr", "response", *files, "--times", times, "--samples", "200", "-q")
    p = lumigraph(*args, "--out", tmp_path / "r.json")
    assert_clean_error(p, files[-1].name, files[-2].name, "--force")
    p = lumigraph(*args, "--out", tmp_path / "f.json", "--force")
    assert p.returncode == 0, p.stderr
    assert "darker" in p.stderr
    import json

    meta = json.loads((tmp_path / "f.json.meta.json").read_text())
    assert any("darker" in w for w in meta["warnings"])


def test_cli_reference_times_reach_the_fit_and_an_unknown_file_is_exit_2(bracket, tmp_path):
    import json

    from conftest import assert_clean_error, lumigraph

    files, t = bracket
    rough = ",".join(f"{x * (1.1 if k % 2 else 0.92):.9g}" for k, x in enumerate(t))
    args = ("hdr", "response", *files, "--times", rough, "--method", "mitsunaga-nayar",
            "--samples", "200", "-q")
    p = lumigraph(*args, "--reference-time", f"{files[0].name}={t[0]!r}",
                  "--reference-time", f"{files[-1]}={t[-1]!r}", "--out", tmp_path / "r.json")
    assert p.returncode == 0, p.stderr
    meta = json.loads((tmp_path / "r.json.meta.json").read_text())
    assert meta["quality"]["power_fixed_by"] == "the reference exposures"
    assert set(meta["quality"]["reference_exposures"]) == {"0", str(len(files) - 1)}
    p = lumigraph(*args, "--reference-time", "nosuch.png=0.01", "--out", tmp_path / "x.json")
    assert_clean_error(p, "--reference-time", "nosuch.png")
