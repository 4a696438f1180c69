"""The bad-input corpus: every command x every fault class is exit 2 with
one line, nothing written, the inputs unchanged.

Every command is one entry of ``tests/cli_catalog.py`` (a valid, fast
invocation). Each fault damages one thing of that invocation:

* an input file (every file the command reads: a named file, or a folder's
  ``stack.json`` / ``lightfield.json`` and its first image) replaced by each
  fault of ``fixtures/make_bad_inputs.py`` that applies to its kind: empty,
  garbage, truncated, a decompression bomb (a header claiming 60000^2 pixels
  or exabytes), JSON that is not UTF-8, a list where an object is due, wrong
  types, NaN; and a 1x1 image (exit 2, or exit 0 where a method works per
  pixel, never exit 1);
* the output: under a file (cannot be created), one of the inputs, an existing
  folder where a file is due.

Bad options are the parser's (``test_options_typed.py``: every numeric option,
every value outside its range, non-finite or non-numeric).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import cli_catalog as cat  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("make_bad_inputs", ROOT / "fixtures" / "make_bad_inputs.py")
bad = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bad)

IMAGES = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".pfm", ".hdr"}
ENTRIES = [e for e in cat.ENTRIES if e.inputs]


def _hashes(folder: Path) -> dict:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _read_files(m) -> list[Path]:
    """The files the command reads, one per input: a file itself; in a folder,
    its index (stack.json, lightfield.json) and the first image it lists."""
    out = []
    for p in m.inputs:
        if p.is_file():
            out.append(p)
            continue
        for index in ("stack.json", "lightfield.json"):
            if (p / index).is_file():
                out.append(p / index)
                body = json.loads((p / index).read_text())
                names = body.get("images") or body.get("views") or []
                first = names[0] if names and isinstance(names[0], str) else None
                if first and (p / first).is_file():
                    out.append(p / first)
                break
    return out


def _faults_for(path: Path) -> list[str]:
    faults = bad.applicable(path.suffix.lower())
    if path.suffix.lower() in IMAGES and path.suffix.lower() not in (".hdr",):
        faults.append("one-pixel")
    return faults


def _one_pixel(path: Path) -> None:
    from lumigraph.capture.io import read_image, write_exr, write_image, write_pfm

    img = read_image(path)
    px = np.ascontiguousarray(img[:1, :1])
    path.unlink()
    if path.suffix == ".exr":
        write_exr(path, px.astype(np.float32))
    elif path.suffix == ".pfm":
        write_pfm(path, px.astype(np.float32))
    else:
        write_image(path, px)


def _cases():
    for e in ENTRIES:
        yield pytest.param(e.name, id=e.name)


def _check(rc: int, err: str, m, before: dict, what: str) -> None:
    lines = err.strip().splitlines()
    assert rc == 2, f"{what}: exit {rc}, stderr {err!r}"
    assert "Traceback" not in err, f"{what}: a traceback: {err}"
    errs = [line for line in lines if line.startswith("error: ")]
    assert len(lines) == 1 and len(errs) == 1, f"{what}: expected exactly one line: {err!r}"
    assert not errs[0].startswith("error: internal"), f"{what}: {errs[0]}"
    written = [p for p in m.names["out"].rglob("*") if p.is_file()] \
        if m.names["out"].exists() else []
    assert not written, f"{what}: wrote {written}"
    assert _hashes(m.names["in"]) == before, f"{what}: an input was modified"


@pytest.mark.parametrize("name", list(_cases()))
def test_bad_input_files(name, tmp_path):
    entry = cat.BY_NAME[name]
    m0 = cat.materialise(entry, tmp_path / "base")
    targets = [p.relative_to(m0.names["in"]) for p in _read_files(m0)]
    assert targets, f"{name}: no input file found to damage"
    k, failures = 0, []
    for rel in targets:
        for fault in _faults_for(m0.names["in"] / rel):
            k += 1
            work = tmp_path / f"case{k}"
            shutil.copytree(m0.names["in"], work / "in")
            m = cat.materialise(entry, work, prepared={"in": work / "in"})
            target = m.names["in"] / rel
            if fault == "one-pixel":
                _one_pixel(target)
            else:
                try:
                    data = bad.make(fault, target.suffix.lower(), target.read_bytes())
                except ValueError:
                    continue
                target.write_bytes(data)
            before = _hashes(m.names["in"])
            rc, _, err = cat.run_cli(m.argv)
            if fault == "one-pixel" and rc == 0:
                # a 1x1 image is a fault for a method that needs a neighbourhood
                # (exit 2), not for one that works per pixel (inspect, convert,
                # tone mapping): either way never an internal fault
                continue
            try:
                _check(rc, err, m, before, f"{name} with {rel} {fault}")
            except AssertionError as e:
                failures.append(str(e).splitlines()[0])
    assert not failures, "\n".join(failures)


def _first_out(m) -> tuple[int, str]:
    for i, a in enumerate(m.argv):
        if a.startswith(str(m.names["out"])):
            return i, a
    raise AssertionError("no output in argv")


@pytest.mark.parametrize("name", [pytest.param(e.name, id=e.name) for e in cat.ENTRIES])
def test_bad_outputs(name, tmp_path):
    entry = cat.BY_NAME[name]
    m = cat.materialise(entry, tmp_path)
    i, out = _first_out(m)
    a_file = m.names["in"] / "a-file"  # a file where the output's folder should be
    a_file.write_text("not a folder")
    suffix = Path(out).suffix
    cases = {"under a file": str(a_file / ("x" + suffix))}
    same = [p for p in _read_files(m) if p.suffix == suffix and p.is_file()]
    if suffix and same:
        cases["an input"] = str(same[0])
    if suffix:
        folder = tmp_path / ("existing" + suffix)
        folder.mkdir()
        cases["an existing folder"] = str(folder)
    before = _hashes(m.names["in"])
    for what, path in cases.items():
        argv = list(m.argv)
        argv[i] = path
        rc, _, err = cat.run_cli(argv)
        _check(rc, err, m, before, f"{name} --out {what}")
        if argv[i - 1].startswith("--"):  # the one line names the option at fault
            assert err.startswith(f"error: {argv[i - 1]}: "), err
