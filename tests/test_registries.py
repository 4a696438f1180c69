"""The name tables the command line chooses from are registries of one shape
(``lumigraph.capture.registry``): the scenes of ``lumigraph render``, the stages
of ``lumigraph`` and the bench stages of ``lumigraph bench``."""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil

import pytest
from conftest import lumigraph as lumigraph_cli

import lumigraph.capture.scenes
from lumigraph import bench, command
from lumigraph.capture.registry import Registry
from lumigraph.capture.render import SCENES, SceneSpec, get_scene, scenes


def _module(target: str) -> str:
    return target.split(":")[0]


def test_tables_are_registries():
    for reg in (SCENES, command.STAGES, bench.BENCH_STAGES):
        assert isinstance(reg, Registry)
        assert all(m.help and "\n" not in m.help for m in reg.values()), reg


def test_every_scene_has_its_spec_beside_its_renderer():
    specs = scenes()
    assert list(specs) == list(SCENES.names)
    for name, method in SCENES.items():
        spec = specs[name]
        assert isinstance(spec, SceneSpec) and spec.name == name
        assert spec.summary == method.help
        assert callable(method.load()) and spec.render_fn is method.load()
        # the spec lives in the renderer's own module
        assert importlib.import_module(_module(method.target)).SPECS[name] is spec


def test_every_spec_is_registered():
    pkg = lumigraph.capture.scenes
    found = {}
    for m in pkgutil.iter_modules(pkg.__path__, pkg.__name__ + "."):
        for name in getattr(importlib.import_module(m.name), "SPECS", {}):
            found[name] = m.name
    assert found == {n: _module(m.target) for n, m in SCENES.items()}


def test_unknown_scene_lists_the_choices():
    from lumigraph.capture.errors import InputError

    with pytest.raises(InputError, match="unknown scene; choose from boards, boards-stereo"):
        get_scene("nosuch")


def test_render_list_prints_every_scene_its_summary_and_options():
    r = lumigraph_cli("render", "--list")
    assert r.returncode == 0, r.stderr
    blocks = r.stdout.strip().split("\n\n")
    assert len(blocks) == len(SCENES)
    for block, name in zip(blocks, sorted(SCENES), strict=True):
        spec = get_scene(name)
        w, h = spec.default_size
        expected = [f"{name}  (default size {w}x{h})", f"    {SCENES[name].help}",
                    *(f"    {o.describe()}" for o in spec.options)]
        assert block.splitlines() == expected


def test_shell_stages_resolve():
    for name, method in command.STAGES.items():
        assert callable(method.load()), name  # every stage's main (light imports by design)
    for name, method in bench.BENCH_STAGES.items():
        assert importlib.util.find_spec(_module(method.target)) is not None, name


def test_top_help_lists_every_stage_once():
    r = lumigraph_cli("--help")
    assert r.returncode == 0, r.stderr
    for name, method in command.STAGES.items():
        assert f"  {name:<11} {method.help}" in r.stdout.splitlines()


def _method_options():
    """(file, line, choices node) of every ``add_argument("--method", …)`` in the CLIs."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for path in sorted([*root.glob("*/cli.py"), *root.glob("*/*_cli.py")]):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument"
                    and node.args and isinstance(node.args[0], ast.Constant)
                    and node.args[0].value == "--method"):
                choices = next((k.value for k in node.keywords if k.arg == "choices"), None)
                yield path.relative_to(root), node.lineno, choices


def test_every_method_option_takes_its_choices_from_a_registry():
    import ast

    found = list(_method_options())
    assert len(found) >= 6, found  # hdr x3, flow, lightfield, separation, triangulate
    for path, line, choices in found:
        names = [n for n in ast.walk(choices) if isinstance(n, ast.Attribute) and n.attr == "names"]
        assert names, f"{path}:{line}: --method choices are not a registry's .names"


def test_triangulation_methods_are_one_pipeline_in_three_modes():
    import numpy as np

    from lumigraph.capture.camera import Camera
    from lumigraph.stereo.triangulate import METHODS, triangulate

    K = np.array([[500.0, 0, 160], [0, 480, 120], [0, 0, 1]])
    cams = [Camera(K, np.zeros(5), (320, 240))] * 2
    poses = [(np.eye(3), np.zeros(3)), (np.eye(3), np.array([-0.2, 0.0, 0.0]))]
    X = np.array([[0.1, -0.05, 2.0], [-0.3, 0.2, 3.0]])
    px = np.stack([cams[0].project(X + t) for _, t in poses])
    for name, m in METHODS.items():
        via_registry = m(px, cams, poses)
        direct = triangulate(px, cams, poses, method=name)
        np.testing.assert_array_equal(via_registry.points, direct.points)
        np.testing.assert_allclose(via_registry.points, X, atol=1e-9)
