"""Guards on the package layout (DESIGN §2) and import costs (§3)."""

import importlib
import importlib.metadata
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = ["capture", "calib", "hdr", "stereo", "lightfield", "separation"]


@pytest.mark.parametrize("name", OURS)
def test_package_resolves_inside_this_repository(name):
    mod = importlib.import_module(name)
    assert Path(mod.__file__).resolve().parent == ROOT / name


@pytest.mark.parametrize("name", OURS)
def test_package_belongs_to_lumigraph_alone(name):
    owners = set(importlib.metadata.packages_distributions().get(name, []))
    assert owners == {"lumigraph"}, f"{name} is provided by {owners}"


def test_data_folders_are_not_packages():
    for folder in ("tests", "fixtures"):
        assert not (ROOT / folder / "__init__.py").exists()


def test_stage_imports_stay_cheap():
    code = ("import sys, capture, calib, hdr, stereo, lightfield, separation, capture.command;"
            "heavy = [m for m in ('torch', 'kornia', 'mitsuba', 'pycolmap', 'cv2', 'matplotlib')"
            " if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_no_utils_grab_bag():
    assert not list(ROOT.glob("*/utils.py"))
