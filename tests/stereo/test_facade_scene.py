"""The Façade ground-truth scene: its geometry is the block model's, its marks
lie on the true projected edges, its depth maps are the model's."""

from __future__ import annotations

import numpy as np
import pytest

from lumigraph.capture.render import render
from lumigraph.capture.scenes import facade
from lumigraph.stereo.debevec1996.edges import EdgeMarks
from lumigraph.stereo.debevec1996.model import BlockModel
from lumigraph.stereo.debevec1996.raster import model_depth

SIZE = (128, 96)


@pytest.fixture(scope="module")
def scene():
    return render("facade", size=SIZE, seed=3, photos=6, novel=2, supersample=1)


def _true_model(scene):
    m = BlockModel.from_dict(scene.files["blocks.json"])
    return m, m.with_values({n: v for n, v in scene.gt["parameters"].items()
                             if n in m.parameter_names})


def test_geometry_is_the_block_models(scene):
    _, true = _true_model(scene)
    b = facade.Building(scene.gt["parameters"])
    assert set(b.edges()) == set(true.edges())
    for name, (p0, p1) in true.edges().items():
        np.testing.assert_allclose(b.edges()[name][0], p0, atol=1e-12)
        np.testing.assert_allclose(b.edges()[name][1], p1, atol=1e-12)
    np.testing.assert_allclose(b.mesh().vertices, true.mesh().vertices, atol=1e-12)
    assert (b.mesh().faces == true.mesh().faces).all()
    # every block parameter is in gt.json under its stable name, with its value
    assert scene.gt["parameters"] == pytest.approx(true.named_values())


def test_marks_lie_on_the_projected_edges(scene):
    _, true = _true_model(scene)
    edges = true.edges()
    marks = scene.files["edges.json"]["photographs"]
    assert set(marks) == set(scene.image_names)
    for photo, cam in scene.gt["cameras"].items():
        K, R, t = (np.array(cam[k]) for k in ("K", "R", "t"))
        assert len(marks[photo]) >= 6
        for m in marks[photo]:
            p0, p1 = edges[m["edge"]]
            a, b = (K @ (R @ p + t) for p in (p0, p1))
            line = np.cross(a, b)
            line /= np.hypot(*line[:2])
            x0, y0, x1, y1 = m["segment"]
            d = [line @ [x0, y0, 1.0], line @ [x1, y1, 1.0]]
            assert max(map(abs, d)) < 1e-6  # exact: no edge noise asked for
    # the folder's marks are a valid edges.json for the model
    EdgeMarks.from_dict(scene.files["edges.json"], model=BlockModel.from_dict(scene.files["blocks.json"]),
                        photographs=list(scene.image_names))


def test_depth_maps_are_the_models(scene):
    _, true = _true_model(scene)
    mesh = true.mesh()
    for i, cam in enumerate(scene.gt["cameras"].values()):
        K, R, t = (np.array(cam[k]) for k in ("K", "R", "t"))
        z = model_depth(mesh, K, R, t, SIZE)
        zm = scene.gt_arrays[f"model_depth_{i:02d}"]
        assert (np.isfinite(z) == np.isfinite(zm)).mean() > 0.999  # the ground hides nothing
        both = np.isfinite(z) & np.isfinite(zm)
        np.testing.assert_allclose(zm[both], z[both], rtol=1e-6)


def test_edge_noise_moves_the_endpoints():
    a = render("facade", size=(64, 48), seed=1, photos=6, novel=0, supersample=1)
    b = render("facade", size=(64, 48), seed=1, photos=6, novel=0, supersample=1, edge_noise=0.5)
    sa = np.array([m["segment"] for m in a.files["edges.json"]["photographs"]["photo_00.png"]])
    sb = np.array([m["segment"] for m in b.files["edges.json"]["photographs"]["photo_00.png"]])
    assert sa.shape == sb.shape
    d = (sb - sa).ravel()
    # the draws are N(0, 0.5²): their RMS within a wide band around 0.5 (n >= 24)
    assert 0.25 < np.sqrt(np.mean(d ** 2)) < 0.8


def _azimuths(cams, centre=(-0.5, 0.0)):
    C = np.array([-np.array(c["R"]).T @ np.array(c["t"]) for c in cams.values()])
    return np.degrees(np.arctan2(C[:, 1] - centre[1], C[:, 0] - centre[0]))


def test_the_ring_layout_photographs_the_building_all_round():
    """``layout="ring"``: the photographs' azimuths (about the building's centre)
    are 360°/n apart, up to the ±4° jitter either side; each novel view lies
    between two consecutive photographs. The arc keeps every camera in front of
    the building (−y): no azimuth within 30° of the back (+90°)."""
    n = 10
    ring = render("facade", size=(64, 48), seed=2, photos=n, novel=n, supersample=1, layout="ring")
    arc = render("facade", size=(64, 48), seed=2, photos=8, novel=4, supersample=1)
    a = np.sort(_azimuths(ring.gt["cameras"]) % 360)
    gaps = np.diff(np.r_[a, a[0] + 360])
    assert np.all(np.abs(gaps - 360 / n) <= 8 + 1e-9)
    for v in _azimuths(ring.gt["novel_cameras"]) % 360:
        # the angular distance to the nearest photograph: half a gap, ± the two jitters
        d = np.min(np.abs((a - v + 180) % 360 - 180))
        assert abs(d - 180 / n) <= 8 + 1e-9
    back = np.abs((_azimuths(arc.gt["cameras"]) - 90 + 180) % 360 - 180)
    assert back.min() > 30
    assert len(ring.images) == n and len(ring.gt["novel_cameras"]) == n
