"""The Façade solve's mesh files read back: ``model.ply`` by ``capture.io.read_ply``
(faces) and ``model.obj`` by ``stereo.debevec1996.outputs.read_obj``, the readers
beside the writers. Fixtures are asymmetric (a reversed vertex order or a
flipped face would show), and the rendered scene's real model is read too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lumigraph.capture.errors import InputError
from lumigraph.capture.io import read_ply
from lumigraph.stereo.debevec1996.model import load_blocks
from lumigraph.stereo.debevec1996.outputs import mesh_obj_text, mesh_ply_bytes, read_obj

ROOT = Path(__file__).resolve().parents[2]
# no symmetry: distinct, unordered vertices; faces of both windings
V = np.array([[0.5, -1.25, 2.0], [3.0, 0.125, -0.75], [-2.5, 4.0, 1.5],
              [1.75, 2.5, -3.0], [-0.25, -3.5, 0.625]])
F = np.array([[2, 0, 1], [3, 4, 1], [1, 0, 3], [4, 2, 0]])
# mesh_obj_text writes 9 significant digits: half a unit of the ninth
OBJ_REL = 5e-9


def _facade_mesh():
    return load_blocks(ROOT / "fixtures" / "facade" / "blocks.json").mesh()


def test_ply_of_the_facade_writer_reads_back_bit_for_bit(tmp_path):
    mesh = _facade_mesh()
    for name, (v, f) in {"small": (V, F), "facade": (mesh.vertices, mesh.faces)}.items():
        p = tmp_path / f"{name}.ply"
        p.write_bytes(mesh_ply_bytes(v, f))
        pts, cols, tris = read_ply(p, faces=True)
        assert np.array_equal(pts, v) and cols is None
        assert np.array_equal(tris, f)  # order and winding of every face


def test_obj_of_the_facade_writer_reads_back(tmp_path):
    mesh = _facade_mesh()
    for name, (v, f) in {"small": (V, F), "facade": (mesh.vertices, mesh.faces)}.items():
        p = tmp_path / f"{name}.obj"
        p.write_text(mesh_obj_text(v, f))
        verts, tris = read_obj(p)
        assert np.allclose(verts, v, rtol=OBJ_REL, atol=0) and np.array_equal(tris, f)


def test_obj_polygons_references_and_skipped_statements(tmp_path):
    p = tmp_path / "m.obj"
    p.write_text("# made by hand\nmtllib m.mtl\no thing\n"
                 "v 0.5 -1.25 2.0\nv 3 0.125 -0.75 1.0\nv -2.5 4 1.5 0.1 0.2 0.3\n"
                 "vt 0 0\nvn 0 0 1\ng side\nusemtl red\ns off\n"
                 "v 1.75 2.5 -3.0\nv -0.25 -3.5 0.625   # a comment after a vertex\n"
                 "f 3/1 1/1 2/1\n"           # a triangle, v/t
                 "f 4//1 5//1 2//1 1//1\n"   # a quad, v//n: two triangles, one fan
                 "f -4/1/1 -1/1/1 -3/1/1\n"  # negative: counted back from vertex 5
                 "\n")
    verts, tris = read_obj(p)
    assert np.array_equal(verts, V)
    assert tris.tolist() == [[2, 0, 1], [3, 4, 1], [3, 1, 0], [1, 4, 2]]


@pytest.mark.parametrize("text, line, fragment", [
    ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3, "a face needs 3 or more vertices"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, "'4' names no vertex"),
    ("v 0 0 0\nf 1 2 3\nv 1 0 0\nv 0 1 0\n", 2, "names no vertex"),  # before they exist
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", 4, "'0' names no vertex"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x/1\n", 4, "'x/1' names no vertex"),
    ("v 0 0\n", 1, "a vertex is 'v x y z'"),
    ("v 0 0 nan\n", 1, "a vertex is 'v x y z'"),
    ("v 0 0 0\nbogus 1 2\n", 2, "'bogus' is not an OBJ statement"),
])
def test_obj_bad_lines_name_the_file_and_line(tmp_path, text, line, fragment):
    p = tmp_path / "bad.obj"
    p.write_text(text)
    with pytest.raises(InputError, match=fragment) as e:
        read_obj(p)
    assert e.value.where == str(p) and f"line {line}:" in str(e.value)


def test_obj_that_is_not_text_or_missing(tmp_path):
    p = tmp_path / "bin.obj"
    p.write_bytes(b"v 0 0 0\n\xff\xfe\x00")
    with pytest.raises(InputError, match="not a text OBJ"):
        read_obj(p)
    with pytest.raises(InputError, match="file not found"):
        read_obj(tmp_path / "missing.obj")
