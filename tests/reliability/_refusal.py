"""One check for a refused command line, run in this process (fast): exit 2,
exactly one stderr line ``error: <flag or file>: ...``, nothing at the
outputs, the inputs' bytes unchanged."""

from __future__ import annotations

import hashlib
from pathlib import Path


def snapshot(*paths) -> dict[str, str]:
    """Every file under ``paths`` (files or folders) -> its sha256."""
    out = {}
    for p in map(Path, paths):
        for f in ([p] if p.is_file() else sorted(p.rglob("*")) if p.is_dir() else []):
            if f.is_file():
                out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def assert_refused(main, argv, where, capsys, *, outputs=(), inputs=(), fragments=(), code=2):
    """``main(argv)`` exits ``code`` with one line starting ``error: {where}:``
    (holding ``fragments``), writes none of ``outputs`` and leaves every file
    under ``inputs`` as it was (same names, same bytes). Returns the line."""
    before = snapshot(*inputs)
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == code, (rc, err)
    assert len(err) == 1 and err[0].startswith(f"error: {where}:"), err
    for f in fragments:
        assert f in err[0], (f, err[0])
    for o in map(Path, outputs):
        assert not o.exists(), f"{o} was written"
        assert not o.with_name(o.name + ".meta.json").exists(), f"{o}'s sidecar was written"
    assert snapshot(*inputs) == before, "an input changed"
    return err[0]
