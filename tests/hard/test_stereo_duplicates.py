"""Hard case: duplicate views (zero baseline) and degenerate SfM input are
refused with the reason, before COLMAP runs."""

from conftest import assert_clean_error, lumigraph

from lumigraph.capture.render import render


def test_duplicate_views_refused(tmp_path):
    s = render("stereo-views", size=(96, 72), views=3, supersample=1)
    folder = s.save(tmp_path / "v")
    imgs = [folder / n for n in s.image_names]
    import shutil

    shutil.copy(imgs[0], folder / "again.png")
    r = lumigraph("stereo", "sfm", imgs[0], imgs[1], folder / "again.png", "--out", tmp_path / "o")
    assert_clean_error(r, "duplicate")
    r = lumigraph("stereo", "sfm", imgs[0], "--out", tmp_path / "o")
    assert_clean_error(r, "at least 2 images")
    assert not (tmp_path / "o" / "points.ply").exists()
