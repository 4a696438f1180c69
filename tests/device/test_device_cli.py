"""--device on the command line: a missing GPU or a missing extra is bad
input (exit 2, one line), and a plain import loads no torch."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

# Importing torch takes seconds and its modules stay loaded: the checks run in
# a fresh interpreter each.
_NO_TORCH = textwrap.dedent("""
    import importlib.abc, importlib.util, sys

    class _Blocked(importlib.abc.MetaPathFinder):
        # torch and kornia are not installed: import fails, find_spec says None
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in ("torch", "kornia"):
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
            return None

    _find = importlib.util.find_spec
    importlib.util.find_spec = lambda name, *a, **k: (
        None if name.split(".")[0] in ("torch", "kornia") else _find(name, *a, **k))
    sys.meta_path.insert(0, _Blocked())
""")


def _lumigraph(argv, *, prelude="", cwd=None):
    code = prelude + textwrap.dedent(f"""
        import sys
        sys.argv = ["lumigraph", *{list(map(str, argv))!r}]
        from lumigraph._entry import main
        sys.exit(main())
    """)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd,
                          timeout=120)


@pytest.fixture
def radiance(tmp_path):
    from lumigraph.capture.io import write_exr

    p = tmp_path / "in.exr"
    write_exr(p, np.exp(np.random.default_rng(0).normal(0, 1, (8, 12, 3))).astype(np.float32))
    return p


def _one_line_error(r):
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    return lines[0]


def _in_process(argv, capsys):
    """The command in this process (torch, once imported, stays: no second
    multi-second import in a child)."""
    from lumigraph.command import main

    capsys.readouterr()
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def test_cuda_without_a_gpu_is_exit_2_one_line(radiance, tmp_path, capsys):
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA GPU")
    code, err = _in_process(["hdr", "tonemap", radiance, "--device", "cuda", "--out",
                             tmp_path / "o.png"], capsys)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --device:"), err
    assert "no CUDA GPU" in lines[0]
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("device", ["torch-cpu", "cuda"])
def test_torch_device_without_the_extra_names_it(radiance, tmp_path, device):
    r = _lumigraph(["hdr", "tonemap", radiance, "--device", device, "--out", tmp_path / "o.png"],
                   prelude=_NO_TORCH)
    line = _one_line_error(r)
    assert "pip install 'lumigraph[gpu]'" in line, line
    assert line.startswith("error: --device:")


def test_auto_without_the_extra_runs_on_the_cpu(radiance, tmp_path):
    r = _lumigraph(["hdr", "tonemap", radiance, "--device", "auto", "--out", tmp_path / "o.png"],
                   prelude=_NO_TORCH)
    assert r.returncode == 0, r.stderr
    meta = json.loads((tmp_path / "o.png.meta.json").read_text())
    assert meta["params"]["device"] == "cpu"


def test_torch_cpu_tonemap_writes_what_cpu_writes(radiance, tmp_path, capsys):
    pytest.importorskip("torch")
    pytest.importorskip("kornia")
    from lumigraph.capture.io import read_image

    for dev in ("cpu", "torch-cpu"):
        code, err = _in_process(["hdr", "tonemap", radiance, "--device", dev, "--out",
                                 tmp_path / f"{dev}.png"], capsys)
        assert code == 0, err
    a, b = read_image(tmp_path / "cpu.png"), read_image(tmp_path / "torch-cpu.png")
    # float32 against float64: at most one code apart (test_hdr_torch derives it)
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 1


def test_importing_lumigraph_and_every_module_loads_no_torch():
    """``pip install lumigraph`` without the extra: every stage's library and
    cli module imports without torch or kornia being loaded."""
    code = textwrap.dedent("""
        import importlib, pkgutil, sys
        import lumigraph
        names = []
        for sub in ("capture", "calib", "hdr", "stereo", "lightfield", "separation"):
            pkg = importlib.import_module(f"lumigraph.{sub}")
            names += [m.name for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
        names += [m.name for m in pkgutil.iter_modules(lumigraph.__path__, "lumigraph.")]
        for n in names:
            if not n.endswith("__main__"):
                importlib.import_module(n)
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("torch", "kornia"))
        print(len(names), loaded[:5])
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    count, loaded = r.stdout.split(" ", 1)
    assert int(count) > 50 and loaded.strip() == "[]", r.stdout


def test_lumigraph_runs_without_the_extra(radiance, tmp_path):
    r = _lumigraph(["hdr", "tonemap", radiance, "--out", tmp_path / "o.png"], prelude=_NO_TORCH)
    assert r.returncode == 0, r.stderr
