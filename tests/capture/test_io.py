"""Round trips of every artifact format, each read back by a second, independent
reader where one exists, and a truncated-file test for each reader."""

import struct
import subprocess

import cv2
import numpy as np
import pytest
from conftest import need_tool

from lumigraph.capture import io
from lumigraph.capture.errors import InputError

RNG = np.random.default_rng(1234)


def _truncate(path, keep=0.6):
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


# --------------------------------------------------------------------- PNG / TIFF
@pytest.mark.parametrize("ext", [".png", ".tif"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_ldr_roundtrip_and_opencv_reads_same_pixels(tmp_path, ext, dtype):
    top = np.iinfo(dtype).max
    img = RNG.integers(0, top + 1, (7, 11, 3), dtype=dtype)  # asymmetric size: no transposes
    p = tmp_path / f"a{ext}"
    io.write_image(p, img)
    back = io.read_image(p)
    assert back.dtype == dtype and np.array_equal(back, img)
    theirs = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)  # independent reader, BGR order
    assert theirs.dtype == dtype and np.array_equal(theirs[..., ::-1], img)


def test_png_keeps_true_bit_depth_12(tmp_path):
    img = RNG.integers(0, 4096, (5, 6, 3), dtype=np.uint16)
    p = tmp_path / "twelve.png"
    io.write_image(p, img, bit_depth=12)
    assert io.png_significant_bits(p) == 12
    assert np.array_equal(cv2.imread(str(p), cv2.IMREAD_UNCHANGED)[..., ::-1], img)
    io.write_stack_json(tmp_path, ["twelve.png"])
    assert io.read_stack([tmp_path]).bit_depth == 12


def test_write_image_refuses_values_beyond_bit_depth(tmp_path):
    with pytest.raises(ValueError, match="do not fit in 10 bits"):
        io.write_image(tmp_path / "x.png", np.full((2, 2), 1024, np.uint16), bit_depth=10)


@pytest.mark.parametrize("ext", [".png", ".tif", ".jpg"])
def test_truncated_ldr_is_refused(tmp_path, ext):
    img = RNG.integers(0, 256, (64, 80, 3), dtype=np.uint8)
    p = tmp_path / f"t{ext}"
    if ext == ".jpg":
        from PIL import Image

        Image.fromarray(img).save(p, quality=95)
    else:
        io.write_image(p, img)
    _truncate(p)
    with pytest.raises(InputError, match=p.name):
        io.read_image(p)


def test_missing_empty_and_wrong_extension(tmp_path):
    with pytest.raises(InputError, match="not found"):
        io.read_image(tmp_path / "nope.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        io.read_image(tmp_path / "empty.png")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(InputError, match="unsupported image extension"):
        io.read_image(tmp_path / "notes.txt")


# ------------------------------------------------------------------------- JPEG EXIF
def _jpeg_with_exif(path, t=(1, 250), f=(18, 10), iso=1000):
    from PIL import Image

    im = Image.fromarray(RNG.integers(0, 256, (16, 24, 3), dtype=np.uint8))
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    from PIL.TiffImagePlugin import IFDRational

    sub[0x829A] = IFDRational(*t)
    sub[0x829D] = IFDRational(*f)
    sub[0x8827] = iso
    im.save(path, exif=exif, quality=92)


def test_jpeg_exif_exposure(tmp_path):
    p = tmp_path / "e.jpg"
    _jpeg_with_exif(p)
    e = io.read_exif(p)
    assert e.exposure_time_s == pytest.approx(1 / 250, rel=1e-12)
    assert e.f_number == pytest.approx(1.8) and e.iso == 1000


def test_real_iphone_exif_matches_its_ss_file():
    from conftest import need_shared

    folder = need_shared("data", "hdr-real", "iphone_xr_night")
    jpgs = sorted(folder.glob("*.jpeg"))
    assert jpgs
    times = sorted(io.read_exif(p).exposure_time_s for p in jpgs)
    assert times[0] == pytest.approx(1 / 250, rel=1e-6) and times[-1] == pytest.approx(1.0)


# ------------------------------------------------------------------------------ EXR
@pytest.mark.parametrize("half", [False, True])
def test_exr_roundtrip_and_exrheader_reads_it(tmp_path, half):
    img = np.exp(RNG.uniform(-5, 5, (9, 13, 3))).astype(np.float32)
    p = tmp_path / "r.exr"
    io.write_exr(p, img, half=half)
    back = io.read_exr(p)
    if half:
        assert np.allclose(back, img, rtol=2.0 ** -11, atol=0)  # half: 11-bit mantissa
    else:
        assert np.array_equal(back, img)
    tool = need_tool("exrheader", "openexr")
    out = subprocess.run([tool, str(p)], capture_output=True, text=True, check=True).stdout
    assert "dataWindow" in out and "(0 0) - (12 8)" in out
    assert ("16-bit floating-point" if half else "32-bit floating-point") in out
    assert "zip" in out.lower()


def test_exr_single_channel_and_determinism(tmp_path):
    img = RNG.random((4, 5)).astype(np.float32)
    io.write_exr(tmp_path / "a.exr", img)
    io.write_exr(tmp_path / "b.exr", img)
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()
    assert np.array_equal(io.read_exr(tmp_path / "a.exr"), img)


def test_truncated_exr_is_refused(tmp_path):
    p = tmp_path / "t.exr"
    io.write_exr(p, RNG.random((64, 64, 3)).astype(np.float32))
    _truncate(p, 0.5)
    with pytest.raises(InputError, match="t.exr"):
        io.read_exr(p)


def test_nan_in_float_input_is_refused(tmp_path):
    img = np.ones((4, 4, 3), np.float32)
    img[1, 2, 0] = np.nan
    io.write_exr(tmp_path / "n.exr", img)
    with pytest.raises(InputError, match="NaN"):
        io.read_image(tmp_path / "n.exr")


# ------------------------------------------------------------------------------ PFM
def test_pfm_roundtrip_unknown_as_inf_and_opencv_reads_it(tmp_path):
    d = RNG.uniform(0, 60, (7, 10)).astype(np.float32)
    d[2, 3] = np.nan
    p = tmp_path / "d.pfm"
    io.write_pfm(p, d)
    back = io.read_pfm(p)
    assert np.array_equal(np.isnan(back), np.isnan(d))
    assert np.array_equal(back[~np.isnan(d)], d[~np.isnan(d)])
    theirs = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)  # OpenCV's PFM reader
    assert theirs.shape == d.shape and np.isinf(theirs[2, 3])
    assert np.array_equal(theirs[~np.isnan(d)], d[~np.isnan(d)])


def test_pfm_colour_roundtrip_and_opencv_bgr(tmp_path):
    img = RNG.random((5, 8, 3)).astype(np.float32)
    p = tmp_path / "c.pfm"
    io.write_pfm(p, img)
    assert np.array_equal(io.read_pfm(p), img)
    assert np.array_equal(cv2.imread(str(p), cv2.IMREAD_UNCHANGED)[..., ::-1], img)


def test_truncated_pfm_is_refused(tmp_path):
    p = tmp_path / "t.pfm"
    io.write_pfm(p, RNG.random((20, 20)).astype(np.float32))
    _truncate(p)
    with pytest.raises(InputError, match="truncated"):
        io.read_pfm(p)


# ------------------------------------------------------------------------------ .flo
def test_flo_roundtrip_and_opencv_reads_it(tmp_path):
    flow = RNG.normal(0, 5, (6, 9, 2)).astype(np.float32)
    flow[4, 1] = np.nan
    p = tmp_path / "f.flo"
    io.write_flo(p, flow)
    back = io.read_flo(p)
    known = ~np.isnan(flow).any(axis=2)
    assert np.array_equal(back[known], flow[known]) and np.isnan(back[4, 1]).all()
    theirs = cv2.readOpticalFlow(str(p))
    assert theirs.shape == (6, 9, 2) and np.array_equal(theirs[known], flow[known])
    assert (np.abs(theirs[4, 1]) > 1e9).all()  # Middlebury's unknown marker


def test_flo_written_by_opencv_reads_back(tmp_path):
    flow = RNG.normal(0, 3, (5, 7, 2)).astype(np.float32)
    p = tmp_path / "cv.flo"
    assert cv2.writeOpticalFlow(str(p), flow)
    assert np.array_equal(io.read_flo(p), flow)


def test_real_middlebury_flow_has_unknowns():
    from conftest import need_shared

    f = need_shared("data", "flow-real", "RubberWhale", "flow10.flo")
    flow = io.read_flo(f)
    assert flow.shape[2] == 2 and np.isnan(flow).any() and np.isfinite(flow).any()


def test_truncated_and_bad_flo(tmp_path):
    p = tmp_path / "t.flo"
    io.write_flo(p, np.zeros((30, 30, 2), np.float32))
    _truncate(p)
    with pytest.raises(InputError, match="truncated"):
        io.read_flo(p)
    (tmp_path / "bad.flo").write_bytes(struct.pack("<fii", 1.0, 2, 2) + b"\0" * 32)
    with pytest.raises(InputError, match="magic"):
        io.read_flo(tmp_path / "bad.flo")


# ------------------------------------------------------------------------------ PLY
def _parse_ply_header(raw: bytes) -> list[str]:
    """An independent minimal parse of the header, as a viewer would."""
    head = raw[: raw.index(b"end_header\n")].decode("ascii")
    return head.splitlines()


def test_ply_roundtrip_and_header(tmp_path):
    pts = RNG.normal(0, 1, (17, 3))
    cols = RNG.integers(0, 256, (17, 3), dtype=np.uint8)
    p = tmp_path / "p.ply"
    io.write_ply(p, pts, cols)
    raw = p.read_bytes()
    head = _parse_ply_header(raw)
    assert head[:3] == ["ply", "format binary_little_endian 1.0", "element vertex 17"]
    assert head[3:] == ["property double x", "property double y", "property double z",
                        "property uchar red", "property uchar green", "property uchar blue"]
    body = raw[raw.index(b"end_header\n") + 11:]
    assert len(body) == 17 * (3 * 8 + 3)
    first = struct.unpack("<dddBBB", body[:27])
    assert np.allclose(first[:3], pts[0], rtol=0, atol=0) and first[3:] == tuple(cols[0])
    back_pts, back_cols = io.read_ply(p)
    assert np.array_equal(back_pts, pts) and np.array_equal(back_cols, cols)


def test_truncated_ply_is_refused(tmp_path):
    p = tmp_path / "t.ply"
    io.write_ply(p, RNG.normal(size=(50, 3)))
    _truncate(p, 0.8)
    with pytest.raises(InputError, match="truncated"):
        io.read_ply(p)


# A mesh no symmetry can hide: five vertices at distinct, unordered positions;
# faces of mixed winding, a quad and a pentagon (fan-triangulated on reading).
MESH_V = np.array([[0.5, -1.25, 2.0], [3.0, 0.125, -0.75], [-2.5, 4.0, 1.5],
                   [1.75, 2.5, -3.0], [-0.25, -3.5, 0.625]])
MESH_POLYS = [[2, 0, 1], [3, 4, 1, 0], [1, 3, 2, 4, 0]]
# the fans (v0, vi, vi+1), by hand
MESH_TRIS = [[2, 0, 1], [3, 4, 1], [3, 1, 0], [1, 3, 2], [1, 2, 4], [1, 4, 0]]


def _ascii_mesh(index_name="vertex_indices", extra_elements=True, faces=MESH_POLYS) -> bytes:
    head = ["ply", "format ascii 1.0", "comment asymmetric"]
    if extra_elements:  # an element before the vertices, with data: read past
        head += ["element material 2", "property float shine", "property list uchar int ids"]
    head += [f"element vertex {len(MESH_V)}", "property double x", "property double y",
             "property double z", "property uchar red", "property uchar green",
             "property uchar blue", f"element face {len(faces)}",
             f"property list uchar int {index_name}"]
    if extra_elements:
        head += ["element edge 1", "property int vertex1", "property int vertex2"]
    body = ["0.5 1 7", "1.5 3 1 2 3"] if extra_elements else []
    body += [" ".join(repr(float(x)) for x in v) + f" {10 * i} {10 * i + 1} {10 * i + 2}"
             for i, v in enumerate(MESH_V)]
    body += [" ".join(map(str, [len(f)] + f)) for f in faces]
    body += ["0 1"] if extra_elements else []
    return ("\n".join(head + ["end_header"] + body) + "\n").encode("ascii")


def _binary_mesh(count_type="uchar", index_type="int") -> bytes:
    t = {"uchar": "u1", "ushort": "<u2", "int": "<i4", "uint": "<u4"}
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\n"
            "property float y\nproperty float z\nelement face 3\n"
            f"property list {count_type} {index_type} vertex_index\nend_header\n")
    body = MESH_V.astype("<f4").tobytes() + b"".join(
        np.array([len(f)], t[count_type]).tobytes() + np.array(f, t[index_type]).tobytes()
        for f in MESH_POLYS)
    return head.encode("ascii") + body


def test_ply_mesh_ascii_keeps_vertex_order_winding_and_colours(tmp_path):
    for name, extra in [("vertex_indices", True), ("vertex_index", False)]:
        p = tmp_path / f"{name}.ply"
        p.write_bytes(_ascii_mesh(name, extra))
        pts, cols, tris = io.read_ply(p, faces=True)
        assert np.array_equal(pts, MESH_V) and tris.tolist() == MESH_TRIS
        assert cols.tolist() == [[10 * i, 10 * i + 1, 10 * i + 2] for i in range(5)]
        back_pts, back_cols = io.read_ply(p)  # the point-cloud call: the same vertices
        assert np.array_equal(back_pts, MESH_V) and np.array_equal(back_cols, cols)


@pytest.mark.parametrize("count_type, index_type", [("uchar", "int"), ("ushort", "uint")])
def test_ply_mesh_binary_of_mixed_polygons(tmp_path, count_type, index_type):
    p = tmp_path / "m.ply"
    p.write_bytes(_binary_mesh(count_type, index_type))
    pts, cols, tris = io.read_ply(p, faces=True)
    assert np.array_equal(pts, MESH_V.astype(np.float32)) and cols is None
    assert tris.tolist() == MESH_TRIS
    # the fan keeps each polygon's winding: every triangle of the planar quad
    # [0, 1, 2, 3] of a square turns the same way as the square
    sq = tmp_path / "sq.ply"
    sq.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                   b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                   b"end_header\n0 0 0\n2 0 0\n2 1 0\n0 1 0\n4 0 1 2 3\n")
    v, _, t = io.read_ply(sq, faces=True)
    normals = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert np.all(normals[:, 2] > 0) and np.all(normals[:, :2] == 0)


def test_ply_triangles_with_a_property_around_the_list_read_at_once(tmp_path):
    # every face of one length: read as one table (ascii) or fixed records (binary)
    head = ("ply\nformat {fmt} 1.0\nelement vertex 5\nproperty double x\nproperty double y\n"
            "property double z\nelement face 6\nproperty ushort group\n"
            "property list uchar int vertex_indices\nproperty float weight\nend_header\n")
    tris = np.array(MESH_TRIS)
    a = tmp_path / "a.ply"
    a.write_bytes(head.format(fmt="ascii").encode() + "".join(
        " ".join(repr(float(x)) for x in v) + "\n" for v in MESH_V).encode()
        + "".join(f"{7 * i} 3 {t[0]} {t[1]} {t[2]} {i / 4}\n" for i, t in enumerate(tris)).encode())
    rec = np.empty(6, [("g", "<u2"), ("n", "u1"), ("i", "<i4", (3,)), ("w", "<f4")])
    rec["g"], rec["n"], rec["i"], rec["w"] = 7 * np.arange(6), 3, tris, np.arange(6) / 4
    b = tmp_path / "b.ply"
    b.write_bytes(head.format(fmt="binary_little_endian").encode() + MESH_V.astype("<f8").tobytes()
                  + rec.tobytes())
    for p in (a, b):
        pts, _, got = io.read_ply(p, faces=True)
        assert np.array_equal(pts, MESH_V) and np.array_equal(got, tris), p


def test_point_cloud_ply_has_no_faces(tmp_path):
    p = tmp_path / "p.ply"
    io.write_ply(p, MESH_V)
    pts, cols, tris = io.read_ply(p, faces=True)
    assert np.array_equal(pts, MESH_V) and cols is None and tris.shape == (0, 3)


@pytest.mark.parametrize("polys, fragment", [
    ([[0, 1, 5]], "refers to vertex 5, and there are 5"),
    ([[0, 1, -1]], "refers to vertex -1"),
    ([[0, 1]], "face 0 has 2 vertices"),
])
def test_ply_bad_faces_are_refused_naming_the_file(tmp_path, polys, fragment):
    p = tmp_path / "bad.ply"
    p.write_bytes(_ascii_mesh(extra_elements=False, faces=polys))
    with pytest.raises(InputError, match=fragment) as e:
        io.read_ply(p, faces=True)
    assert e.value.where == str(p) or str(p) in str(e.value)


def test_ply_truncated_face_list_and_unknown_format_are_refused(tmp_path):
    p = tmp_path / "t.ply"
    p.write_bytes(_binary_mesh()[:-3])
    with pytest.raises(InputError, match="truncated"):
        io.read_ply(p, faces=True)
    huge = tmp_path / "huge.ply"  # a uint list length far past the data
    huge.write_bytes(_binary_mesh("uint", "int").replace(
        b"end_header\n" + MESH_V.astype("<f4").tobytes() + np.array([3], "<u4").tobytes(),
        b"end_header\n" + MESH_V.astype("<f4").tobytes() + np.array([2**32 - 1], "<u4").tobytes()))
    with pytest.raises(InputError, match="truncated in record 0 of the face element"):
        io.read_ply(huge, faces=True)
    q = tmp_path / "be.ply"
    q.write_bytes(_binary_mesh().replace(b"binary_little_endian", b"binary_big_endian"))
    with pytest.raises(InputError, match="only ascii and binary_little_endian"):
        io.read_ply(q)
    a = tmp_path / "word.ply"
    a.write_bytes(_ascii_mesh(extra_elements=False).replace(b"0.5 ", b"half ", 1))
    with pytest.raises(InputError, match="not a number"):
        io.read_ply(a)


# ------------------------------------------------------------------------------ RAW
def test_raw_reader_refuses_non_raw(tmp_path):
    p = tmp_path / "fake.dng"
    p.write_bytes(b"II*\0" + b"\0" * 100)
    with pytest.raises(InputError, match="cannot decode RAW"):
        io.read_raw(p)


# ----------------------------------------------------------------------------- stacks
def test_stack_from_files_with_times_and_mismatch(tmp_path):
    a = RNG.integers(0, 256, (8, 10, 3), dtype=np.uint8)
    for i in range(3):
        io.write_image(tmp_path / f"i{i}.png", a)
    io.write_image(tmp_path / "odd.png", a[:, :9])
    st = io.read_stack([tmp_path / f"i{i}.png" for i in range(3)], times=[1 / 30, 1 / 8, 0.5])
    assert st.images.shape == (3, 8, 10, 3) and st.bit_depth == 8
    assert st.exposure_times_s == pytest.approx((1 / 30, 1 / 8, 0.5))
    with pytest.raises(InputError, match="odd.png"):
        io.read_stack([tmp_path / "i0.png", tmp_path / "odd.png"])
    with pytest.raises(InputError, match="no EXIF exposure time"):
        io.read_stack([tmp_path / "i0.png"], need_times=True)
    with pytest.raises(InputError, match="positive"):
        io.read_stack([tmp_path / "i0.png"], times=[-1.0])


def test_exr_pixels_decoded_by_pfstools(tmp_path):
    """An independent decoder of the pixel values: pfstools' pfsinexr, piped to
    its PFM writer. pfs converts RGB to XYZ and back in float32, which costs a
    few float32 ulps of the pixel's largest channel (cond(M_sRGB) ~ 5, eps
    1.2e-7, so ~1e-6): the bound is 4e-6 of the pixel maximum."""
    need_tool("pfsinexr", "pfstools")
    img = np.exp(RNG.uniform(-3, 3, (6, 9, 3))).astype(np.float32)
    io.write_exr(tmp_path / "p.exr", img)
    subprocess.run(f"pfsinexr {tmp_path / 'p.exr'} | pfsoutpfm {tmp_path / 'p.pfm'}",
                   shell=True, check=True)
    theirs = io.read_pfm(tmp_path / "p.pfm")
    rel = np.abs(theirs.astype(np.float64) - img).max(axis=-1) / img.max(axis=-1)
    assert theirs.shape == img.shape and rel.max() < 4e-6
