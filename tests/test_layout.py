"""Guards on the package layout (DESIGN §2) and import costs (§3).

Everything imports as ``lumigraph.<stage>``; the stage folders stay where the
user put them (``package-dir`` maps each name onto its folder), and no bare
top-level name of ours is installed: PyPI has unrelated distributions that
import as ``capture``, ``calib``, ``stereo`` and ``lightfield``.
"""

import importlib
import importlib.metadata
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STAGES = ["capture", "calib", "hdr", "stereo", "lightfield", "separation"]
BARE = [*STAGES, "fixtures"]


@pytest.mark.parametrize("name", STAGES)
def test_stage_resolves_to_its_folder_in_this_repository(name):
    mod = importlib.import_module(f"lumigraph.{name}")
    assert Path(mod.__file__).resolve().parent == ROOT / name


def test_lumigraph_is_ours():
    assert set(importlib.metadata.packages_distributions().get("lumigraph", [])) == {"lumigraph"}


@pytest.mark.parametrize("name", BARE)
def test_no_bare_name_of_ours_in_this_environment(name):
    # run outside the checkout, so the folders beside the cwd cannot be found
    code = f"import importlib.util as u; print(u.find_spec({name!r}) is None)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path("/"))
    assert out.stdout.strip() == "True", f"a bare {name!r} is importable"


def _tracked_copy(dest: Path) -> Path:
    """Copy the files git tracks (as they are in the working tree) to ``dest``:
    building there leaves the checkout as it was (setuptools writes ``build/``
    and ``*.egg-info`` beside the sources it builds)."""
    r = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    for name in r.stdout.decode().split("\0"):
        src = ROOT / name
        if name and src.is_file():  # a tracked file deleted in the working tree is left out
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return dest


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A non-editable wheel of this checkout's tracked files, built without
    network access in a copy (nothing is written into the repository)."""
    out = tmp_path_factory.mktemp("wheel")
    src = _tracked_copy(tmp_path_factory.mktemp("source"))
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                        "-q", "-w", str(out), str(src)], capture_output=True, text=True,
                       env={**os.environ, "PIP_NO_INDEX": "1"}, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    (whl,) = out.glob("lumigraph-*.whl")
    return whl


def test_wheel_installs_only_the_lumigraph_namespace(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith((".dist-info", ".data"))}
    assert tops == {"lumigraph"}, tops
    for stage in STAGES:
        assert f"lumigraph/{stage}/__init__.py" in names
    assert "lumigraph/view/static/look.js" in names  # the page's assets ship (no CDN)
    assert any(n.startswith("lumigraph/stereo/_ssd") and n.endswith(".so") for n in names)


def test_console_script_runs_the_shell(wheel):
    # the `lumigraph` script a user (and the Makefile) runs is lumigraph._entry:main,
    # which imports lumigraph.command:main inside its Ctrl-C handler
    with zipfile.ZipFile(wheel) as z:
        (ep,) = [n for n in z.namelist() if n.endswith(".dist-info/entry_points.txt")]
        lines = z.read(ep).decode().splitlines()
    scripts = lines[lines.index("[console_scripts]") + 1:]
    target = next(ln.split("=", 1)[1].strip() for ln in scripts if ln.split("=")[0].strip() == "lumigraph")
    module, attr = target.split(":")
    from lumigraph import _entry

    assert getattr(importlib.import_module(module), attr) is _entry.main
    src = Path(_entry.__file__).read_text()
    assert "from lumigraph.command import main" in src and "KeyboardInterrupt" in src


def test_installed_wheel_imports_through_namespace_only(wheel, tmp_path):
    # Unpacked into its own folder and run from elsewhere: what a user of
    # `pip install lumigraph` sees, with no checkout on the path.
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    code = ("import importlib, importlib.util as u, sys\n"
            f"bare = [n for n in {BARE!r} if u.find_spec(n) is not None]\n"
            f"mods = [importlib.import_module('lumigraph.' + n).__file__ for n in {STAGES!r}]\n"
            "import lumigraph.command as c\n"
            "assert c.main(['--version']) == 0\n"
            "print(bare, all(m.startswith(sys.argv[1]) for m in mods))\n")
    env = {**os.environ, "PYTHONPATH": str(site), "PYTHONNOUSERSITE": "1"}
    # PYTHONPATH comes before site-packages, so the wheel's lumigraph answers
    # (the check on every module's file proves it), not this editable install.
    r = subprocess.run([sys.executable, "-c", code, str(site)], capture_output=True,
                       text=True, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("\n")[-2] == "[] True", r.stdout


def test_data_folders_are_not_packages():
    for folder in ("tests", "fixtures"):
        assert not (ROOT / folder / "__init__.py").exists()


def test_stage_imports_stay_cheap():
    code = ("import sys, lumigraph.capture, lumigraph.calib, lumigraph.hdr, lumigraph.stereo, "
            "lumigraph.lightfield, lumigraph.separation, lumigraph.capture.commandline, "
            "lumigraph.command;"
            "heavy = [m for m in ('torch', 'kornia', 'mitsuba', 'pycolmap', 'cv2', 'matplotlib')"
            " if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_no_utils_grab_bag():
    assert not list(ROOT.glob("*/utils.py"))


def test_unrelated_packages_of_our_folder_names_coexist(tmp_path):
    # What broke for a user: an unrelated `lightfield` (an API client on PyPI)
    # and ours fought over one name. Now each keeps its own.
    for name in ("lightfield", "capture", "calib", "stereo"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(f"WHO = 'theirs-{name}'\n")
    code = ("import importlib, lightfield, capture, calib, stereo\n"
            "import lumigraph.lightfield, lumigraph.capture, lumigraph.calib, lumigraph.stereo\n"
            "theirs = [m.WHO for m in (lightfield, capture, calib, stereo)]\n"
            "ours = [hasattr(importlib.import_module('lumigraph.' + n), 'WHO')\n"
            "        for n in ('lightfield', 'capture', 'calib', 'stereo')]\n"
            "print(theirs, ours, lumigraph.lightfield.LightField.__module__)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(tmp_path)}, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == ("['theirs-lightfield', 'theirs-capture', 'theirs-calib', "
                                "'theirs-stereo'] [False, False, False, False] "
                                "lumigraph.lightfield.field")
