"""One parser per artifact: ``Rig.load`` reads every rig file (``rig.json``, a
scene's ``gt.json``), ``Camera.load`` every camera file, ``CameraArray.load``
every posed-camera file, and a bad file is one clear error naming the file
and the key."""

import json

import numpy as np
import pytest

from lumigraph.calib.rectify import Rectification, rectify
from lumigraph.capture.camera import Camera
from lumigraph.capture.errors import InputError
from lumigraph.capture.rig import CameraArray, Rig


def _rig():
    import cv2

    left = Camera(np.array([[310.0, 0, 84], [0, 305, 57], [0, 0, 1]]), [-0.2, 0.05, 1e-3, -5e-4, 0],
                  (160, 120))
    right = Camera(np.array([[300.0, 0, 78], [0, 298, 62], [0, 0, 1]]), [-0.1, 0.02, 0, 0, 0],
                   (160, 120))
    R = cv2.Rodrigues(np.array([0.01, -0.03, 0.02]))[0]
    return Rig.from_pose(left, right, R, np.array([-0.12, 0.004, 0.002]), rms_px=0.1)


def _same_rig(a: Rig, b: Rig):
    for name in ("R", "T", "E", "F"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for ca, cb in ((a.left, b.left), (a.right, b.right)):
        np.testing.assert_array_equal(ca.K, cb.K)
        np.testing.assert_array_equal(ca.dist, cb.dist)
        assert ca.image_size == cb.image_size


def test_rig_json_and_scene_gt_json_load_the_same_rig(tmp_path):
    rig = _rig()
    rig.save(tmp_path / "rig.json")
    (tmp_path / "gt.json").write_text(json.dumps({"schema": "lumigraph.gt", "scene": "x",
                                                  "rig": rig.to_dict()}))
    a, b = Rig.load(tmp_path / "rig.json"), Rig.load(tmp_path / "gt.json")
    _same_rig(a, rig)
    _same_rig(b, rig)
    assert a.extra["rms_px"] == 0.1


def test_rig_without_E_and_F_derives_them():
    d = _rig().to_dict()
    del d["E"], d["F"]
    _same_rig(Rig.from_dict(d), _rig())


def test_bad_rig_files_name_the_file_and_the_key(tmp_path):
    p = tmp_path / "gt.json"
    p.write_text(json.dumps({"scene": "x", "rig": {"left": _rig().to_dict()["left"], "R": np.eye(3).tolist()}}))
    with pytest.raises(InputError, match=r"gt\.json: key 'rig': missing keys 'right', 'T'"):
        Rig.load(p)
    p.write_text(json.dumps({"scene": "x", "camera": {}}))
    with pytest.raises(InputError, match=r"gt\.json: missing keys 'left', 'right', 'R', 'T'.*'rig' entry"):
        Rig.load(p)
    d = _rig().to_dict()
    d["right"]["K"] = "oops"
    (tmp_path / "rig.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"rig\.json: key 'right\.K': expected a 3x3 matrix"):
        Rig.load(tmp_path / "rig.json")
    with pytest.raises(InputError, match="missing.json: rig file not found"):
        Rig.load(tmp_path / "missing.json")


def test_camera_json_and_scene_gt_json_load_the_same_camera(tmp_path):
    cam = _rig().left
    cam.save(tmp_path / "camera.json")
    (tmp_path / "gt.json").write_text(json.dumps({"camera": cam.to_dict()}))
    for p in (tmp_path / "camera.json", tmp_path / "gt.json"):
        c = Camera.load(p)
        np.testing.assert_array_equal(c.K, cam.K)
        np.testing.assert_array_equal(c.dist, cam.dist)
    (tmp_path / "gt.json").write_text(json.dumps({"camera": {"K": cam.K.tolist()}}))
    with pytest.raises(InputError, match=r"gt\.json: key 'camera': missing keys 'dist', 'image_size'"):
        Camera.load(tmp_path / "gt.json")


def test_camera_array_reads_its_file_and_a_two_camera_rig(tmp_path):
    rig = _rig()
    rig.save(tmp_path / "rig.json")
    arr = CameraArray.load(tmp_path / "rig.json")
    assert len(arr.cameras) == 2
    np.testing.assert_array_equal(arr.cam_from_world[0][0], np.eye(3))
    np.testing.assert_array_equal(arr.cam_from_world[1][0], rig.R)
    np.testing.assert_array_equal(arr.cam_from_world[1][1], rig.T)
    arr.save(tmp_path / "cameras.json")
    again = CameraArray.load(tmp_path / "cameras.json")
    for (Ra, ta), (Rb, tb) in zip(arr.cam_from_world, again.cam_from_world, strict=True):
        np.testing.assert_array_equal(Ra, Rb)
        np.testing.assert_array_equal(ta, tb)
    d = json.loads((tmp_path / "cameras.json").read_text())
    del d["cameras"][1]["cam_from_world"]
    (tmp_path / "cameras.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"cameras\.json: key 'cameras\[1\]\.cam_from_world': missing"):
        CameraArray.load(tmp_path / "cameras.json")


def test_rectification_json_is_used_as_saved(tmp_path):
    """The saved rectification rebuilds the very maps it was computed with."""
    r = rectify(_rig(), alpha=0.3)
    q = Rectification.load(r.save(tmp_path / "rectification.json"))
    for a, b in zip(r.maps(), q.maps(), strict=True):
        np.testing.assert_array_equal(a, b)
    d = json.loads((tmp_path / "rectification.json").read_text())
    del d["rig"]["T"]
    (tmp_path / "rectification.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"rectification\.json: key 'rig': missing key 'T'"):
        Rectification.load(tmp_path / "rectification.json")
