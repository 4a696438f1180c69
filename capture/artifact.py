"""Atomic artifact writes and the ``<output>.meta.json`` sidecar (DESIGN §4).

Every file a stage produces is written to a temporary file in the same folder
and moved into place with ``os.replace``, sidecar first and primary last, so an
interrupted run never leaves a half-written artifact for ``make`` to trust.

Permissions: ``tempfile.mkstemp`` creates its file with mode 0600 whatever the
umask; before the move the file gets ``0o666 & ~umask`` (:func:`file_mode`),
the mode ``open()`` would have given it, so a shared render farm can read what
a stage wrote when the umask says so.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> path = write_artifact(d / "x.txt", lambda p: p.write_text("hi"),
...                       meta=make_meta("demo.text", params={"n": 1}))
>>> sorted(f.name for f in d.iterdir())
['x.txt', 'x.txt.meta.json']
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

META_SCHEMA_VERSION = 1
_VERSIONED = ("numpy", "scipy", "cv2", "OpenEXR", "rawpy", "skimage", "torch", "kornia",
              "pycolmap", "mitsuba", "PIL", "colour_hdri")


_UMASK_LOCK = threading.Lock()


def current_umask() -> int:
    """The process's umask, read without changing it where the system allows.

    The umask can only be *set* portably (``os.umask`` returns the old value
    while installing a new one), and a set-then-restore pair is not
    thread-safe: a file another thread creates in between gets the temporary
    mask. So: on Linux read it from ``/proc/self/status`` (``Umask:``, since
    Linux 4.7), which changes nothing; elsewhere swap it under a module lock,
    which keeps our own writers from racing each other (and leaves a window
    only for foreign code creating files at that instant). It is read on every
    write, not cached at import, so a umask set later (a daemon, a test) counts.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _UMASK_LOCK:
        mask = os.umask(0o077)
        os.umask(mask)
    return mask


def file_mode() -> int:
    """The mode of a newly written artifact: ``0o666 & ~umask`` (what ``open()``
    gives a new file), e.g. 0644 under umask 022 and 0600 under 077."""
    return 0o666 & ~current_umask()


def meta_path(path: str | os.PathLike) -> Path:
    """The sidecar path of an artifact: ``<output>.meta.json``."""
    p = Path(path)
    return p.with_name(p.name + ".meta.json")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix, so writers that
    choose the format from the extension still work); on success it replaces
    ``path`` with the mode the umask gives (:func:`file_mode`), on any
    exception it is removed and ``path`` is left untouched."""
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=f".tmp{final.suffix}",
                               dir=final.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp made it 0600; a writer may also have replaced the file: set
        # the mode on whatever is there now, just before it becomes visible.
        os.chmod(tmp_path, file_mode())
        os.replace(tmp_path, final)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def _finite(obj):
    """JSON has no NaN/inf: write them as null so every reader accepts the file."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


def dumps_json(obj) -> str:
    """Canonical JSON text: sorted keys, float64 round-trip precision (Python's
    ``repr``), NaN/inf as ``null``, newline-terminated."""
    plain = json.loads(json.dumps(obj, default=_json_default))
    return json.dumps(_finite(plain), indent=2, sort_keys=True, allow_nan=False) + "\n"


def write_json(path: str | os.PathLike, obj) -> None:
    """Write ``obj`` as canonical JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(dumps_json(obj))


def save_json_artifact(path: str | os.PathLike, body: dict, *, meta: dict | None = None) -> Path:
    """Write a JSON artifact (``camera.json``, ``rig.json``, ``response.json``, …)
    atomically, with its ``.meta.json`` sidecar when ``meta`` is given."""
    if meta is None:
        write_json(path, body)
        return Path(path)
    return write_artifact(path, lambda tmp: tmp.write_text(dumps_json(body)), meta=meta)


def load_json_artifact(path: str | os.PathLike, what: str, *,
                       schemas: tuple[str, ...] | None = None,
                       versions: tuple[int, ...] = (1,)) -> dict:
    """Read a JSON artifact: a JSON object in UTF-8, standard JSON (no NaN or
    infinity anywhere), of one of ``schemas`` (its ``schema`` key, when it
    has one) at a ``schema_version`` this version reads.

    Parameters
    ----------
    path : path-like
        The file.
    what : str
        The kind, for messages (``"camera"``, ``"rig"``, ``"stack"``).
    schemas : tuple of str, optional
        The ``schema`` values accepted (``("lumigraph.rig", "lumigraph.gt")``);
        any, when None.
    versions : tuple of int
        The ``schema_version`` values accepted.

    Raises
    ------
    InputError
        Naming the file (and the key, for a non-finite number or the schema):
        missing, unreadable, not UTF-8, not JSON, not an object, or of
        another kind or version.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "camera.json"
    >>> _ = p.write_text('{"K": [[NaN, 0, 1]]}')
    >>> from lumigraph.capture.errors import InputError
    >>> try:
    ...     load_json_artifact(p, "camera")
    ... except InputError as e:
    ...     print(e.problem)
    key 'K[0][0]': JSON has no NaN or infinity; write a number (or null where the file allows one)
    """
    from lumigraph.capture.errors import InputError
    from lumigraph.capture.schema import check_schema, fail, first_non_finite, shown

    p = Path(path)
    if not p.is_file():
        raise InputError(p, f"{what} file not found" if not p.exists()
                         else f"expected a {what} file, found a folder or device")
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise InputError(p, f"cannot read the {what} file ({e.strerror or e})") from None
    try:
        text = raw.decode("utf-8-sig")  # a byte-order mark (Windows editors) is harmless
    except UnicodeDecodeError as e:
        raise InputError(p, f"not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); "
                            f"save the {what} file as UTF-8 JSON") from None
    try:
        body = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(p, f"invalid JSON in the {what} file ({e})") from None
    except (ValueError, RecursionError) as e:  # an integer of > 4300 digits, absurd nesting
        raise InputError(p, f"invalid JSON in the {what} file ({type(e).__name__}: "
                            f"{str(e)[:80]})") from None
    if not isinstance(body, dict):
        raise InputError(p, f"expected a JSON object describing a {what}, got {shown(body)}")
    bad = first_non_finite(body)
    if bad is not None:
        raise fail(p, bad, "JSON has no NaN or infinity; write a number (or null where the "
                           "file allows one)")
    if schemas is not None:
        check_schema(body, path=p, schemas=schemas, versions=versions)
    return body


def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def library_versions() -> dict[str, str]:
    """Versions of the libraries this process has imported (no new imports)."""
    out = {"python": sys.version.split()[0]}
    for name in _VERSIONED:
        mod = sys.modules.get(name)
        if mod is not None:
            out[name] = str(getattr(mod, "__version__", "unknown"))
    from lumigraph import __version__
    out["lumigraph"] = __version__
    return out


def make_meta(schema: str, *, inputs: Iterable[str | os.PathLike] = (), params: dict | None = None,
              model: dict | None = None, quality: dict | None = None,
              timings_s: dict | None = None, warnings: Iterable[str] = (),
              command: list[str] | None = None, extra: dict | None = None) -> dict:
    """Build the sidecar dictionary (DESIGN §4).

    Parameters
    ----------
    schema : str
        What the primary artifact is, e.g. ``"lumigraph.response"``.
    inputs : iterable of paths
        Input files; each is recorded with its SHA-256.
    params, model, quality, timings_s, extra : dict, optional
        Parameters used; the chosen model and why (candidates' scores);
        quality figures (RMS, residuals); wall times in seconds.
    warnings : iterable of str
        Anything the user should know about the result.
    command : list of str, optional
        The command line; defaults to ``sys.argv``.
    """
    ins = []
    for p in inputs:
        p = Path(p)
        ins.append({"path": str(p), "sha256": file_sha256(p) if p.is_file() else None})
    meta = {
        "schema": schema,
        "schema_version": META_SCHEMA_VERSION,
        "command": list(sys.argv if command is None else command),
        "created_unix_s": time.time(),
        "inputs": ins,
        "params": params or {},
        "model": model or {},
        "quality": quality or {},
        "timings_s": timings_s or {},
        "warnings": list(warnings),
        "versions": library_versions(),
    }
    if extra:
        meta.update(extra)
    return meta


def write_artifact(path: str | os.PathLike, write: Callable[[Path], object], *, meta: dict) -> Path:
    """Write a primary artifact and its sidecar atomically.

    ``write(tmp_path)`` writes the primary file to the temporary path it is
    given. The sidecar is moved into place first and the primary last, so the
    primary's presence (what ``make`` checks) implies both are complete.
    """
    final = Path(path)
    with atomic_path(final) as tmp_primary:
        write(tmp_primary)
        if not tmp_primary.exists():
            raise RuntimeError(f"writer produced no file for {final}")
        meta = dict(meta)
        meta.setdefault("output", {})
        meta["output"] = {"path": str(final), "sha256": file_sha256(tmp_primary)}
        write_json(meta_path(final), meta)
    return final
