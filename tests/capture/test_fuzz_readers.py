"""Property-based fuzzing of every reader: PNG, JPEG, TIFF (with EXIF), OpenEXR,
PFM, Middlebury .flo, Radiance RGBE, LogLuv TIFF and PLY.

Each reader gets a small valid seed file (two for some formats) and at least
200 mutants of it, drawn by hypothesis (derandomized, no example database, so
every CI run draws the same cases): bit flips, byte edits, inserts, deletes,
truncation, slices copied elsewhere, and edits of the header's own fields
(sizes, counts, offsets, types) to boundary integers or, in text headers, to
boundary tokens. PNG mutants get their chunk CRCs fixed half the time, so an
edited IHDR reaches the decoder instead of failing its checksum.

The property: a reader returns an array of finite shape or raises InputError.
Each reader's batch runs in a child process whose address space is limited to
1 GiB above its size after start-up (so an allocation of a gigabyte fails),
with a 10 s alarm per case (and faulthandler's watchdog for a hang in C); a
case that breaks the property, crashes the child or overruns has its bytes
saved under the test's tmp_path for reproduction (``python
tests/capture/test_fuzz_readers.py READER DIR --replay FILE`` reruns one).

A longer, random search (not part of the suite): ``LUMIGRAPH_FUZZ_EXAMPLES=5000
LUMIGRAPH_FUZZ_RANDOM=1 python tests/capture/test_fuzz_readers.py png /tmp/fuzz``
writes ``/tmp/fuzz/report.json``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import traceback
from pathlib import Path

import pytest

EXAMPLES = 200
CASE_SECONDS = 10
MEMORY_HEADROOM = 1 << 30
READERS = ("png", "jpeg", "tiff", "exr", "pfm", "flo", "rgbe", "logluv", "ply")


# --------------------------------------------------------------------- the seeds
def _seeds(reader: str) -> list[tuple[str, bytes]]:
    """``(extension, bytes)`` of small valid files, written by our writers."""
    import tempfile

    import numpy as np

    from lumigraph.capture import io
    from lumigraph.hdr import formats

    rng = np.random.default_rng(7)
    img8 = rng.integers(0, 256, (6, 9, 3), dtype=np.uint8)
    lin = rng.uniform(0.01, 4.0, (6, 9, 3)).astype(np.float32)
    out = []
    with tempfile.TemporaryDirectory() as d:
        def save(name, write):
            p = Path(d) / name
            write(p)
            out.append((p.suffix, p.read_bytes()))

        if reader == "png":
            save("a.png", lambda p: io.write_image(p, img8))
            save("b.png", lambda p: io.write_image(p, (img8[..., :2].astype(np.uint16) << 4)
                                                  .reshape(6, 18), bit_depth=12))
        elif reader == "jpeg":
            from PIL import Image

            def jpeg(p):
                im = Image.fromarray(img8)
                exif = Image.Exif()
                exif.get_ifd(0x8769)[0x829A] = (1, 250)
                im.save(p, quality=90, exif=exif)

            save("a.jpg", jpeg)
            save("g.jpg", lambda p: Image.fromarray(img8[..., 0]).save(p, progressive=True))
        elif reader == "tiff":
            save("a.tif", lambda p: io.write_image(p, img8))
            save("b.tif", lambda p: io.write_image(p, img8[..., 0].astype(np.uint16) * 257))
        elif reader == "exr":
            save("a.exr", lambda p: io.write_exr(p, lin))
            save("h.exr", lambda p: io.write_exr(p, lin[..., 0], half=True))
        elif reader == "pfm":
            save("a.pfm", lambda p: io.write_pfm(p, lin))
            save("g.pfm", lambda p: io.write_pfm(p, lin[..., 0]))
        elif reader == "flo":
            save("a.flo", lambda p: io.write_flo(p, lin[..., :2]))
        elif reader == "rgbe":
            save("a.hdr", lambda p: formats.write_rgbe(p, np.repeat(lin, 2, axis=1)))
            save("f.hdr", lambda p: formats.write_rgbe(p, lin[:, :5]))  # flat scanlines
        elif reader == "logluv":
            save("l32.tif", lambda p: formats.write_logluv_tiff(p, lin, bits=32))
            save("l24.tif", lambda p: formats.write_logluv_tiff(p, lin, bits=24))
        elif reader == "ply":
            save("a.ply", lambda p: io.write_ply(p, rng.normal(size=(12, 3)),
                                                 rng.integers(0, 256, (12, 3), dtype=np.uint8)))
            save("b.ply", lambda p: io.write_ply(p, rng.normal(size=(5, 3))))
            # meshes (read_ply(faces=True)): binary triangles (4-byte list lengths),
            # ascii with a quad
            save("m.ply", lambda p: p.write_bytes(
                b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
                b"property float y\nproperty float z\nelement face 2\n"
                b"property list uint int vertex_indices\nend_header\n"
                + rng.normal(size=(4, 3)).astype("<f4").tobytes()
                + b"".join(np.array([3], "<u4").tobytes() + np.array(f, "<i4").tobytes()
                           for f in ([0, 1, 2], [0, 2, 3]))))
            save("q.ply", lambda p: p.write_bytes(
                b"ply\nformat ascii 1.0\nelement vertex 5\nproperty double x\n"
                b"property double y\nproperty double z\nproperty uchar red\n"
                b"property uchar green\nproperty uchar blue\nelement face 2\n"
                b"property list uchar uint vertex_index\nend_header\n"
                b"0 0 0 1 2 3\n1 0 0 4 5 6\n1 1 0 7 8 9\n0 1 0 1 1 1\n2 2 1 0 0 0\n"
                b"4 0 1 2 3\n3 1 4 2\n"))
        else:
            raise ValueError(reader)
    return out


def _read(reader: str):
    """The reader(s) a case calls; each must return or raise InputError."""
    from lumigraph.capture import io
    from lumigraph.hdr import formats

    table = {"png": [io.read_image], "jpeg": [io.read_image, io.read_exif],
             "tiff": [io.read_image, io.read_exif], "exr": [io.read_exr], "pfm": [io.read_pfm],
             "flo": [io.read_flo], "rgbe": [formats.read_rgbe],
             "logluv": [formats.read_logluv_tiff],
             "ply": [io.read_ply, lambda p: io.read_ply(p, faces=True)]}
    return table[reader]


# ------------------------------------------------------- where the header fields are
# (offset, size, struct format) of a binary field, or (offset, length, None) of a text token
def _png_fields(b: bytes):
    import struct

    f = [(16, 4, ">I"), (20, 4, ">I")] + [(k, 1, "B") for k in range(24, 29)]
    pos = 8
    while pos + 8 <= len(b):
        f.append((pos, 4, ">I"))
        pos += 12 + struct.unpack(">I", b[pos:pos + 4])[0]
    return f


def _jpeg_fields(b: bytes):
    import struct

    f, pos = [], 2
    while pos + 4 <= len(b) and b[pos] == 0xFF:
        marker = b[pos + 1]
        f += [(pos + 1, 1, "B"), (pos + 2, 2, ">H")]
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            f += [(pos + 4, 1, "B"), (pos + 5, 2, ">H"), (pos + 7, 2, ">H"), (pos + 9, 1, "B")]
            f += [(pos + 10 + 3 * i + k, 1, "B") for i in range(b[pos + 9]) for k in (0, 1, 2)]
        if marker == 0xDA:
            f += [(pos + 4 + k, 1, "B") for k in range(8)]
            break
        pos += 2 + struct.unpack(">H", b[pos + 2:pos + 4])[0]
    return f


def _tiff_fields(b: bytes):
    import struct

    (off,) = struct.unpack("<I", b[4:8])
    (n,) = struct.unpack("<H", b[off:off + 2])
    f = [(4, 4, "<I"), (off, 2, "<H")]
    for k in range(n):
        at = off + 2 + 12 * k
        f += [(at, 2, "<H"), (at + 2, 2, "<H"), (at + 4, 4, "<I"), (at + 8, 4, "<I"),
              (at + 8, 2, "<H")]
    return f


def _exr_fields(b: bytes):
    import struct

    f, pos = [(4, 4, "<i")], 8
    while b[pos] != 0:
        name_end = b.index(b"\0", pos)
        type_end = b.index(b"\0", name_end + 1)
        name = b[pos:name_end]
        size_at = type_end + 1
        (size,) = struct.unpack("<i", b[size_at:size_at + 4])
        f.append((size_at, 4, "<i"))
        val = size_at + 4
        if name in (b"dataWindow", b"displayWindow"):
            f += [(val + 4 * k, 4, "<i") for k in range(4)]
        elif name == b"compression":
            f.append((val, 1, "B"))
        elif name == b"channels":
            q = val
            while b[q] != 0:
                q = b.index(b"\0", q) + 1
                f += [(q, 4, "<i"), (q + 8, 4, "<i"), (q + 12, 4, "<i")]
                q += 16
        pos = val + size
    table = pos + 1
    (first,) = struct.unpack("<Q", b[table:table + 8])
    f += [(table, 8, "<Q"), (first, 4, "<i"), (first + 4, 4, "<i")]
    return f


def _flo_fields(b: bytes):
    return [(0, 4, "<f"), (4, 4, "<i"), (8, 4, "<i")]


def _text_fields(b: bytes, header_end: int):
    """Every whitespace-separated token of a text header, as a field."""
    import re

    return [(m.start(), m.end() - m.start(), None) for m in re.finditer(rb"\S+", b[:header_end])]


def _pfm_fields(b: bytes):
    return _text_fields(b, b.index(b"\n", b.index(b"\n", 3) + 1) + 1)


def _rgbe_fields(b: bytes):
    end = b.index(b"\n\n") + 2
    line_end = b.index(b"\n", end) + 1
    f = _text_fields(b, line_end)
    return f + [(line_end + k, 1, "B") for k in range(4)] + [(line_end + 2, 2, ">H")]


def _ply_fields(b: bytes):
    return _text_fields(b, b.index(b"end_header\n"))


FIELDS = {"png": _png_fields, "jpeg": _jpeg_fields, "tiff": _tiff_fields, "exr": _exr_fields,
          "pfm": _pfm_fields, "flo": _flo_fields, "rgbe": _rgbe_fields, "logluv": _tiff_fields,
          "ply": _ply_fields}

BOUNDARY = [0, 1, 2, 3, 4, 7, 8, 9, 15, 16, 127, 128, 129, 192, 194, 201, 216, 217, 218, 255, 256,
            257, 4095, 4096, 32767, 32768, 34676, 34677, 65535, 65536, 60000, 1 << 24, 2 ** 31 - 1,
            2 ** 31, 2 ** 32 - 1, 2 ** 63, 2 ** 64 - 1]
TOKENS = [b"0", b"1", b"-1", b"9", b"60000", b"65536", b"2147483648", b"4294967297",
          b"99999999999999999999", b"1e9", b"nan", b"inf", b"-inf", b"-0", b"0x10", b"",
          b"PF", b"Pf", b"-Y", b"+X", b"+Y", b"-X", b"list", b"uchar", b"double", b"vertex",
          b"face", b"property", b"element", b"binary_big_endian", b"ascii", b"\xff"]


def _fix_png_crcs(b: bytearray) -> bytearray:
    import struct
    import zlib

    pos = 8
    while pos + 12 <= len(b):
        (n,) = struct.unpack(">I", b[pos:pos + 4])
        if pos + 12 + n > len(b):
            break
        b[pos + 8 + n:pos + 12 + n] = struct.pack(">I", zlib.crc32(b[pos + 4:pos + 8 + n]))
        pos += 12 + n
    return b


def mutants(reader: str, seeds):
    """A hypothesis strategy of ``(extension, bytes)`` mutants of ``seeds``."""
    import struct

    from hypothesis import strategies as st

    fields = [FIELDS[reader](b) for _, b in seeds]
    ops = ["flip", "byte", "insert", "delete", "truncate", "copy", "field", "field", "field"]

    @st.composite
    def strategy(draw):
        k = draw(st.integers(0, len(seeds) - 1))
        ext, data = seeds[k][0], bytearray(seeds[k][1])
        for _ in range(draw(st.integers(1, 3))):
            op = draw(st.sampled_from(ops))
            at = draw(st.integers(0, max(len(data) - 1, 0)))
            if op == "flip" and data:
                data[at] ^= 1 << draw(st.integers(0, 7))
            elif op == "byte" and data:
                data[at] = draw(st.sampled_from([0, 1, 0x7F, 0x80, 0xFF]) | st.integers(0, 255))
            elif op == "insert":
                data[at:at] = draw(st.binary(min_size=1, max_size=16))
            elif op == "delete":
                del data[at:at + draw(st.integers(1, 16))]
            elif op == "truncate":
                del data[at:]
            elif op == "copy" and data:
                n = draw(st.integers(1, 64))
                to = draw(st.integers(0, len(data)))
                data[to:to] = data[at:at + n]
            elif op == "field":
                off, size, fmt = draw(st.sampled_from(fields[k]))
                if off + size > len(data):
                    continue
                if fmt is None:
                    data[off:off + size] = draw(st.sampled_from(TOKENS))
                elif fmt.endswith("f"):
                    value = draw(st.sampled_from([0.0, -1.0, 1e10, float("nan"), float("inf")]))
                    data[off:off + size] = struct.pack(fmt, value)
                else:
                    old = int.from_bytes(data[off:off + size], "big" if fmt[0] == ">" else "little")
                    value = draw(st.sampled_from(BOUNDARY + [old + 1, max(old - 1, 0), old * 256]))
                    data[off:off + size] = (value % (1 << (8 * size))).to_bytes(
                        size, "big" if fmt[0] == ">" else "little")
        if reader == "png" and draw(st.booleans()):
            data = _fix_png_crcs(data)
        return ext, bytes(data)

    return strategy()


# ------------------------------------------------------------------ the child process
def _address_space() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmSize in /proc/self/status")


def _check_result(result) -> None:
    """What a reader returns: arrays of finite, positive shape."""
    import numpy as np

    from lumigraph.capture.io import Exif

    if isinstance(result, Exif):
        return
    arrays = [a for a in (result if isinstance(result, tuple) else (result,)) if a is not None]
    for a in arrays:
        assert isinstance(a, np.ndarray), type(a)
        assert a.ndim in (2, 3) and all(0 <= d < 1 << 31 for d in a.shape), a.shape


def _run_case(readers, path: Path) -> str:
    """``"ok"``, ``"refused"``, or raises what the readers let through."""
    from lumigraph.capture.errors import InputError

    outcome = "ok"
    for read in readers:
        try:
            _check_result(read(path))
        except InputError as e:
            assert str(path) in str(e) or e.where in (str(path), "LUMIGRAPH_MAX_PIXELS"), e
            outcome = "refused"
    return outcome


def child(reader: str, out: Path) -> None:
    """Run one reader's batch; write ``report.json`` (and failures) to ``out``."""
    import faulthandler
    import resource
    import signal

    from hypothesis import HealthCheck, Phase, given, settings

    faulthandler.enable()
    seeds = _seeds(reader)
    readers = _read(reader)
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    for ext, data in seeds:  # the seeds themselves read back (and warm up lazy imports)
        (work / f"seed{ext}").write_bytes(data)
        assert _run_case(readers, work / f"seed{ext}") == "ok", ext
    base = _address_space()
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    resource.setrlimit(resource.RLIMIT_AS, (base + MEMORY_HEADROOM, resource.RLIM_INFINITY))

    def alarm(signum, frame):
        raise TimeoutError(f"case ran over {CASE_SECONDS} s")

    signal.signal(signal.SIGALRM, alarm)
    stats = {"examples": 0, "ok": 0, "refused": 0, "slowest_s": 0.0, "failures": []}

    examples = int(os.environ.get("LUMIGRAPH_FUZZ_EXAMPLES", EXAMPLES))
    fixed = not os.environ.get("LUMIGRAPH_FUZZ_RANDOM")

    @settings(max_examples=examples, derandomize=fixed, database=None, deadline=None,
              phases=[Phase.generate], suppress_health_check=list(HealthCheck))
    @given(mutants(reader, seeds))
    def fuzz(case):
        ext, data = case
        n = stats["examples"]
        stats["examples"] += 1
        path = work / f"case{ext}"
        path.write_bytes(data)
        (out / "current.json").write_text(json.dumps({"index": n, "ext": ext}))
        faulthandler.dump_traceback_later(CASE_SECONDS + 5, exit=True)  # a hang in C
        signal.alarm(CASE_SECONDS)
        t0 = time.perf_counter()
        try:
            stats[_run_case(readers, path)] += 1
        except BaseException as e:  # noqa: BLE001 - everything but InputError is a finding
            if isinstance(e, KeyboardInterrupt):
                raise
            saved = out / f"{reader}-failure-{n}{ext}"
            saved.write_bytes(data)
            stats["failures"].append({"file": str(saved), "error": f"{type(e).__name__}: {e}"[:300],
                                      "traceback": traceback.format_exc()[-1500:]})
        finally:
            signal.alarm(0)
            faulthandler.cancel_dump_traceback_later()
            stats["slowest_s"] = max(stats["slowest_s"], time.perf_counter() - t0)

    fuzz()
    stats["peak_rss_growth"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - base_rss
    (out / "report.json").write_text(json.dumps(stats, indent=1))


# ------------------------------------------------------------------------ the test
@pytest.mark.parametrize("reader", READERS)
def test_reader_returns_or_refuses_every_mutant(reader, tmp_path):
    pytest.importorskip("hypothesis")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    env.pop("LUMIGRAPH_MAX_PIXELS", None)  # the default limit, as a user has it
    proc = subprocess.run([sys.executable, __file__, reader, str(tmp_path)], capture_output=True,
                          text=True, timeout=300, env=env)
    report = tmp_path / "report.json"
    if not report.exists():  # the child died: keep the case it was on
        cur = json.loads((tmp_path / "current.json").read_text()) \
            if (tmp_path / "current.json").exists() else None
        saved = None
        if cur is not None:
            saved = tmp_path / f"{reader}-crash-{cur['index']}{cur['ext']}"
            saved.write_bytes((tmp_path / "work" / f"case{cur['ext']}").read_bytes())
        pytest.fail(f"{reader}: the fuzzing child died (exit {proc.returncode}) on {saved}:\n"
                    f"{proc.stderr[-3000:]}")
    r = json.loads(report.read_text())
    assert r["examples"] >= EXAMPLES, r
    assert not r["failures"], json.dumps(r["failures"][:5], indent=1)
    assert r["slowest_s"] < CASE_SECONDS, r
    # a fuzz that only ever hit the magic number would prove little: both outcomes occur
    assert r["ok"] > 0 and r["refused"] > 0, r
    # no case grew the child's memory by the headroom (an attempt past it fails above)
    assert r["peak_rss_growth"] < MEMORY_HEADROOM, r


if __name__ == "__main__":
    if "--replay" in sys.argv:  # python test_fuzz_readers.py READER DIR --replay FILE
        for read in _read(sys.argv[1]):
            print(read.__name__, "->", end=" ")
            try:
                res = read(sys.argv[sys.argv.index("--replay") + 1])
                print(getattr(res, "shape", type(res).__name__))
            except Exception as e:  # noqa: BLE001
                print(f"{type(e).__name__}: {e}")
    else:
        child(sys.argv[1], Path(sys.argv[2]))
