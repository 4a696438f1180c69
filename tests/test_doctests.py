"""Every docstring example in the library, collected through the installed
``lumigraph`` namespace (never by file path, which would import the stage
folders under their bare names and give two copies of every class)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import lumigraph

SUBPACKAGES = ("capture", "calib", "hdr", "stereo", "lightfield", "separation")
# packages of the shell whose modules are walked too
SHELL_PACKAGES = ("view",)


def _modules() -> list[str]:
    names = [m.name for m in pkgutil.iter_modules(lumigraph.__path__, "lumigraph.")]
    names.append("lumigraph")
    for sub in SUBPACKAGES + SHELL_PACKAGES:
        pkg = importlib.import_module(f"lumigraph.{sub}")
        names.append(pkg.__name__)
        names += [m.name for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
    # __main__ modules run their command on import.
    return sorted({n for n in names if not n.endswith("__main__")})


def _examples(name: str) -> list[doctest.DocTest]:
    module = importlib.import_module(name)
    return [t for t in doctest.DocTestFinder(exclude_empty=True).find(module, name) if t.examples]


ALL_MODULES = _modules()
MODULES = [n for n in ALL_MODULES if _examples(n)]


def test_every_stage_is_collected():
    for sub in SUBPACKAGES:
        assert any(n.startswith(f"lumigraph.{sub}.") for n in MODULES), sub
    assert "lumigraph.command" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, monkeypatch, tmp_path):
    from lumigraph.capture.device import torch_available

    if name.endswith("_torch") and not torch_available():
        pytest.skip("the torch ports' examples need the gpu extra: pip install 'lumigraph[gpu]'")
    monkeypatch.chdir(tmp_path)  # an example that writes a file writes it here
    runner = doctest.DocTestRunner(optionflags=0)
    tests = _examples(name)
    for t in tests:
        runner.run(t, out=lambda s: None)
    failed, attempted = runner.summarize(verbose=False)
    if failed:
        # run again, on freshly found examples (the first run cleared their
        # globals), to show the report of what failed
        report = []
        runner2 = doctest.DocTestRunner(optionflags=0)
        for t in _examples(name):
            runner2.run(t, out=report.append)
        pytest.fail("".join(report))
    assert attempted > 0
