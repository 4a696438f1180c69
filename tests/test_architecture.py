"""The floor order of ARCHITECTURE.md, enforced: no module imports upward.

Every ``import``/``from`` statement (top level or inside a function) and every
string that names a ``lumigraph.<package>.<module>`` (registries and lazy
loaders import those on use) is an edge. An edge may go down or stay on its
floor; an edge up fails, naming the file and line.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Bottom to top; the same list is drawn in ARCHITECTURE.md (checked below).
FLOORS = ["capture", "calib", "stereo", "hdr", "lightfield", "separation", "shell"]
FOLDERS = {"capture": "capture", "calib": "calib", "stereo": "stereo", "hdr": "hdr",
           "lightfield": "lightfield", "separation": "separation", "shell": "lumigraph"}
MODULE_NAME = re.compile(r"^lumigraph\.(capture|calib|stereo|hdr|lightfield|separation)(\.|$)")
STRING_NAME = re.compile(r"\blumigraph\.(capture|calib|stereo|hdr|lightfield|separation)\.[a-z_0-9]+")


def floor_of(module: str) -> str | None:
    """The floor of a dotted ``lumigraph`` module name (None: not ours or the bare root)."""
    m = MODULE_NAME.match(module)
    if m:
        return m.group(1)
    if module.startswith("lumigraph."):
        return "shell"
    return None


def edges(path: Path):
    """(line, imported module) for every import and module-naming string in ``path``."""
    tree = ast.parse(path.read_text(), str(path))
    # docstrings are prose: they may point the reader up a floor
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and n.body and isinstance(n.body[0], ast.Expr)
            and isinstance(n.body[0].value, ast.Constant)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.lineno, node.module
            for a in node.names:  # from lumigraph import command
                if node.module == "lumigraph" and not a.name.startswith("__"):
                    yield node.lineno, f"lumigraph.{a.name}"
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            for m in STRING_NAME.finditer(node.value):
                yield node.lineno, m.group(0)


def sources():
    for floor, folder in FOLDERS.items():
        for p in sorted((ROOT / folder).rglob("*.py")):
            yield floor, p


def test_no_upward_import():
    bad = []
    for floor, path in sources():
        for line, target in edges(path):
            to = floor_of(target)
            if to is None or to == floor:
                continue
            if FLOORS.index(to) > FLOORS.index(floor):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {floor} imports {target} ({to})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_no_bare_stage_imports():
    pat = re.compile(r"^\s*(from|import) (capture|calib|hdr|stereo|lightfield|separation)\b",
                     re.M)
    bad = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*.py")
           if ".venv" not in p.parts and "out" not in p.parts and pat.search(p.read_text())]
    assert not bad, bad


def test_the_checker_sees_an_upward_edge(tmp_path):
    p = tmp_path / "m.py"
    p.write_text('"""See lumigraph.lightfield.refocus."""\n'
                 "def f():\n    from lumigraph.hdr.merge import merge\n"
                 "REG = {'x': 'lumigraph.separation.nayar2006:checker'}\n")
    found = [(line, floor_of(t)) for line, t in edges(p)]
    assert (3, "hdr") in found and (4, "separation") in found
    assert (1, "lightfield") not in found  # a docstring is prose, not an import


def test_architecture_md_draws_this_order():
    text = (ROOT / "ARCHITECTURE.md").read_text()
    drawn = re.findall(r"^\s*(\d)\s+(\w+)\b", text.split("## Floors", 1)[1].split("##", 1)[0], re.M)
    assert [name for _, name in sorted(drawn)] == FLOORS


@pytest.mark.parametrize("floor", FLOORS[:-1])
def test_every_floor_exists(floor):
    assert (ROOT / FOLDERS[floor] / "__init__.py").exists()
