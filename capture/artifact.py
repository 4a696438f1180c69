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
import contextvars
import hashlib
import json
import math
import os
import re
import signal
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


# Result sets (one commit per command). A command's writes are staged as
# temporary files beside their final paths; when the command succeeds they are
# made visible together: a journal naming every (temporary, final) pair is
# written atomically -- the commit point -- then each is renamed into place,
# sidecars before their primaries, and the journal removed. A run killed before
# the journal leaves the previous set untouched (its temporaries are removed by
# the next run on those outputs); one killed after it leaves a journal that the
# next run on that folder completes (:func:`recover_commits`). See
# docs/decisions/result-sets.md.
_SET: contextvars.ContextVar[ResultSet | None] = contextvars.ContextVar("lumigraph_result_set",
                                                                       default=None)
_GUARD: contextvars.ContextVar[OutputGuard | None] = contextvars.ContextVar("lumigraph_guard",
                                                                           default=None)
# The batch item being run (lumigraph.capture.batch): every sidecar written
# while it is set records it, so a rerun can tell a finished item's artifacts.
_BATCH: contextvars.ContextVar[dict | None] = contextvars.ContextVar("lumigraph_batch", default=None)
_TEMPS: set[str] = set()  # our own temporaries: a writer nested in another replaces them directly
JOURNAL_PREFIX = ".lumigraph-commit."
STALE_EMPTY_JOURNAL_S = 60.0  # an unlocked empty journal temporary older than this is a dead writer's


def _temp_pattern(final: Path) -> re.Pattern:
    """Temporaries of ``final`` made by :func:`atomic_path`: ``.NAME.<random>.tmpSUFFIX``,
    and those of a writer nested in it (a temporary of that temporary)."""
    one = rf"\.[A-Za-z0-9_]+\.tmp{re.escape(final.suffix)}"
    return re.compile(rf"^\.+{re.escape(final.name)}{one}(?:{one})*$")


# Any temporary of ours: hidden, a random part, ".tmp" and the final's suffix.
_ANY_TEMP = re.compile(r"^\.+.+\.[A-Za-z0-9_]{8}\.tmp(\.[^.]+)?$")


class ResultSet:
    """The files one command writes, staged and then committed together."""

    def __init__(self, outputs: Iterable[tuple[str | os.PathLike, str]] = ()):
        self.staged: list[tuple[Path, Path]] = []
        # (path, "file" | "dir"): what the command declared it writes; other
        # writes (a scratch file, a cache) are not part of the set
        outputs = list(outputs)
        self.files = {os.path.abspath(p) for p, k in outputs if k == "file"}
        self.dirs = [os.path.abspath(p) for p, k in outputs if k == "dir"]
        # the first declared file (a command's --out) is what make checks: it
        # goes into place last, so its presence means the whole set is there
        self.primary = next((os.path.abspath(p) for p, k in outputs if k == "file"), None)

    def covers(self, final: Path) -> bool:
        """Whether ``final`` is one of the declared outputs, a sidecar of one, or
        inside a declared output folder."""
        f = os.path.abspath(final)
        if f in self.files or (f.endswith(".meta.json") and f[: -len(".meta.json")] in self.files):
            return True
        return any(f.startswith(d.rstrip(os.sep) + os.sep) for d in self.dirs)

    def add(self, tmp: Path, final: Path) -> None:
        self.staged = [(t, f) for t, f in self.staged if f != final]  # a rewrite: the last wins
        self.staged.append((tmp, final))

    def abort(self) -> None:
        for tmp, _ in self.staged:
            _TEMPS.discard(str(tmp))
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        self.staged = []

    def commit(self) -> None:
        if not self.staged:
            return
        import fcntl

        def last(move):
            f = os.path.abspath(move[1])
            return self.primary is not None and f in (self.primary, self.primary + ".meta.json")

        ordered = [m for m in self.staged if not last(m)] + [m for m in self.staged if last(m)]
        moves = [(os.path.abspath(t), os.path.abspath(f)) for t, f in ordered]
        folder = ordered[-1][1].parent
        fd, jtmp = _journal_file(folder)
        if _failpoint("journal") is not None:
            os.kill(os.getpid(), 9)  # tests: a crash before the journal is locked
        try:
            # locked before it becomes visible, so a recovering run sees it live
            fcntl.flock(fd, fcntl.LOCK_EX)
            os.write(fd, json.dumps({"version": 1, "pid": os.getpid(), "moves": moves}).encode())
            os.fsync(fd)
            if jtmp is None:  # the commit point: the journal appears whole and locked
                journal = _link_journal(fd, folder)
            else:
                journal = Path(jtmp[: -len(".tmp")])
                os.replace(jtmp, journal)  # the commit point
            _fsync_dir(folder)
            crash_at, ctrl_c_at = _failpoint("commit"), _failpoint("interrupt")
            for i, (tmp, final) in enumerate(moves):
                if i == crash_at:
                    os.kill(os.getpid(), 9)  # tests: a crash between two renames
                if i == ctrl_c_at:
                    os.kill(os.getpid(), signal.SIGINT)  # tests: a Ctrl-C inside the commit
                os.replace(tmp, final)
                _TEMPS.discard(tmp)
            if crash_at == len(moves):
                os.kill(os.getpid(), 9)
            if ctrl_c_at is not None and ctrl_c_at >= len(moves):
                os.kill(os.getpid(), signal.SIGINT)
            journal.unlink()
        finally:
            os.close(fd)
            if jtmp is not None:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(jtmp)
        self.staged = []


def _journal_file(folder: Path) -> tuple[int, str | None]:
    """An open file for a commit's journal: unnamed (``O_TMPFILE``) where the
    file system allows, so a kill before it is written and locked leaves
    nothing behind; else a named temporary, ``(fd, its path)``, that a kill
    between its creation and its lock leaves empty and unlocked (removed by
    :func:`recover_commits` once it is :data:`STALE_EMPTY_JOURNAL_S` old)."""
    if hasattr(os, "O_TMPFILE") and os.path.isdir("/proc/self/fd"):
        with contextlib.suppress(OSError):  # EOPNOTSUPP, EISDIR (old kernels), ...
            return os.open(folder, os.O_TMPFILE | os.O_RDWR, 0o600), None
    return tempfile.mkstemp(prefix=JOURNAL_PREFIX, suffix=".json.tmp", dir=folder)


def _link_journal(fd: int, folder: Path) -> Path:
    """Give the unnamed journal ``fd`` a fresh name in ``folder`` (never an
    existing one: ``link`` refuses to replace)."""
    # linkat with AT_SYMLINK_FOLLOW, which os.link uses only with a dir_fd
    dfd = os.open(folder, os.O_RDONLY)
    try:
        for _ in range(100):
            name = f"{JOURNAL_PREFIX}{os.urandom(6).hex()}.json"
            try:
                os.link(f"/proc/self/fd/{fd}", name, dst_dir_fd=dfd, follow_symlinks=True)
                return folder / name
            except FileExistsError:
                continue
    finally:
        os.close(dfd)
    raise FileExistsError(f"{folder}: no free name for a commit journal")


def _failpoint(name: str) -> int | None:
    """``LUMIGRAPH_FAILPOINT=commit:N``: die by SIGKILL before the N-th rename of
    a commit (the kill tests' way to land inside the commit's short window);
    ``journal:0``: die as soon as the journal's file is open, before its lock;
    ``interrupt:N``: a Ctrl-C (SIGINT to itself) before the N-th rename, or
    after the last one for N past them."""
    spec = os.environ.get("LUMIGRAPH_FAILPOINT", "")
    if spec.startswith(name + ":"):
        with contextlib.suppress(ValueError):
            return int(spec.split(":", 1)[1])
    return None


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


@contextlib.contextmanager
def result_set(outputs: Iterable[tuple[str | os.PathLike, str]]) -> Iterator[ResultSet]:
    """Stage every artifact written inside the block to one of ``outputs``
    (``(path, "file" | "dir")`` pairs: a file, or anything in a folder);
    commit them together at the block's end, or discard them all if it raises.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with result_set([(d, "dir")]):
    ...     write_json(d / "a.json", {"n": 1})
    ...     (d / "a.json").exists()
    False
    >>> (d / "a.json").exists()
    True
    """
    if _SET.get() is not None:  # nested: the outer set commits
        yield _SET.get()
        return
    rs = ResultSet(outputs)
    token = _SET.set(rs)
    try:
        yield rs
    except BaseException:
        rs.abort()
        raise
    finally:
        _SET.reset(token)
    rs.commit()


def recover_commits(folder: str | os.PathLike) -> int:
    """Complete the commits that a killed run left in ``folder``: every journal
    whose writer is gone has its remaining temporaries renamed into place.
    Returns how many journals were completed. Called before a run writes into
    ``folder`` (:func:`lumigraph.capture.commandline.check_output_path`)."""
    import fcntl

    done = 0
    folder = Path(folder)
    if not folder.is_dir():
        return 0
    for jtmp in folder.glob(JOURNAL_PREFIX + "*.json.tmp"):  # a writer killed before its commit point
        with contextlib.suppress(OSError):
            fd = os.open(jtmp, os.O_RDONLY)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                st = os.fstat(fd)
                # unlocked and empty: a writer between creating it and locking
                # it (batch workers commit into one folder at once) -- or one
                # killed there; only the latter grows old
                if st.st_size > 0 or time.time() - st.st_mtime > STALE_EMPTY_JOURNAL_S:
                    jtmp.unlink()
            except BlockingIOError:
                pass  # alive
            finally:
                os.close(fd)
    for journal in sorted(folder.glob(JOURNAL_PREFIX + "*.json")):
        try:
            fd = os.open(journal, os.O_RDONLY)
        except FileNotFoundError:
            continue
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue  # its writer is alive and committing
            if not journal.exists():
                continue
            try:
                moves = json.loads(journal.read_text())["moves"]
            except (ValueError, KeyError, TypeError):
                moves = []  # not ours to complete; a journal is written whole or not at all
            for tmp, final in moves:
                if os.path.exists(tmp):
                    os.replace(tmp, final)
            journal.unlink()
            done += 1
        finally:
            os.close(fd)
    return done


def remove_stale_temps(final: str | os.PathLike, *, kind: str = "file") -> list[Path]:
    """Remove temporaries that a killed run left: those of the file ``final``
    (and of its sidecar), or, for an output folder, every temporary of ours in
    it. Only safe while this process holds the output's lock."""
    final = Path(final)
    gone = []
    folder = final if kind == "dir" else final.parent
    if not folder.is_dir():
        return gone
    pats = [_ANY_TEMP] if kind == "dir" else [_temp_pattern(final), _temp_pattern(meta_path(final))]
    for f in folder.iterdir():
        if any(p.match(f.name) for p in pats) and str(f) not in _TEMPS and f.is_file():
            with contextlib.suppress(FileNotFoundError):
                f.unlink()
                gone.append(f)
    return gone


class OutputGuard:
    """What a command must not overwrite: its input files (never), and files
    in its input folders that are not its own earlier outputs (``force``
    allows those). Installed by :func:`guard`; checked on every write."""

    def __init__(self, inputs: Iterable[str | os.PathLike], *, producer: str, force: bool = False):
        self.files: set[Path] = set()
        self.folders: set[Path] = set()
        for p in inputs:
            p = Path(p)
            if p.is_dir():
                self.folders.add(p.resolve())
            elif p.exists():
                self.files.add(p.resolve())
                self.folders.add(p.resolve().parent)
        self.producer = producer
        self.force = force

    def problem(self, final: Path) -> str | None:
        """Why writing ``final`` is refused, or None."""
        real = final.resolve()
        if real in self.files or (final.exists() and any(_same(final, f) for f in self.files)):
            return "is one of this command's inputs; choose another output"
        if final.exists() and real.parent in self.folders:
            # beside the inputs: this command's own earlier output is replaced
            # (make reruns a step into the folder it reads from); anything else
            # may be the user's, and only --force replaces it
            if self.force or producer_of(final) == self.producer:
                return None
            return ("exists beside this command's inputs and was not written by this command; "
                    "choose another output, or add --force to replace it")
        return None

    def check(self, final: str | os.PathLike, *, where: str | None = None) -> None:
        from lumigraph.capture.errors import InputError

        why = self.problem(Path(final))
        if why:
            raise InputError(where or final, f"{final} {why}" if where else why)


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def producer_of(path: str | os.PathLike) -> str | None:
    """The command that wrote ``path`` (``"lumigraph hdr merge"``), from its
    sidecar, or None when it has none (not ours)."""
    p = Path(path)
    side = p if p.name.endswith(".meta.json") else meta_path(p)  # a sidecar speaks for itself
    try:
        return json.loads(side.read_text()).get("producer")
    except (OSError, ValueError, AttributeError):
        return None


@contextlib.contextmanager
def guard(inputs: Iterable[str | os.PathLike], *, producer: str, force: bool = False):
    """Refuse, for the block's duration, any write over ``inputs`` (see
    :class:`OutputGuard`); ``producer`` is recorded in every sidecar written."""
    g = OutputGuard(inputs, producer=producer, force=force)
    token = _GUARD.set(g)
    try:
        yield g
    finally:
        _GUARD.reset(token)


def current_guard() -> OutputGuard | None:
    return _GUARD.get()


@contextlib.contextmanager
def unstaged():
    """Write immediately inside the block even within a result set (a cache
    that is not part of the command's results)."""
    token = _SET.set(None)
    gtoken = _GUARD.set(None)
    try:
        yield
    finally:
        _GUARD.reset(gtoken)
        _SET.reset(token)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, immediate: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix, so writers that
    choose the format from the extension still work); on success it replaces
    ``path`` with the mode the umask gives (:func:`file_mode`), on any
    exception it is removed and ``path`` is left untouched.

    Inside :func:`result_set` the replacement waits for the set's commit;
    ``immediate=True`` (caches) replaces at once. Under :func:`guard`, a path
    the guard protects is refused before anything is written.
    """
    final = Path(path)
    nested = str(final) in _TEMPS  # a writer called on another writer's temporary
    if not nested:
        g = _GUARD.get()
        if g is not None:
            g.check(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=f".tmp{final.suffix}",
                               dir=final.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    _TEMPS.add(tmp)
    rs = None if (immediate or nested) else _SET.get()
    if rs is not None and not rs.covers(final):
        rs = None
    staged = False
    try:
        yield tmp_path
        # mkstemp made it 0600; a writer may also have replaced the file: set
        # the mode on whatever is there now, just before it becomes visible.
        os.chmod(tmp_path, file_mode())
        if rs is not None:
            rs.add(tmp_path, final)
            staged = True
        else:
            os.replace(tmp_path, final)
    finally:
        if not staged:
            _TEMPS.discard(tmp)
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
    g = _GUARD.get()
    if g is not None:  # which command wrote it: an earlier output it may replace (OutputGuard)
        meta["producer"] = g.producer
    stamp = _BATCH.get()
    if stamp is not None:  # written as one item of a batch: its key (inputs + options)
        meta["batch"] = dict(stamp)
    if extra:
        meta.update(extra)
    return meta


@contextlib.contextmanager
def batch_stamp(stamp: dict):
    """Record ``stamp`` (a batch item's name and key) in every sidecar built
    inside the block (:func:`make_meta`)."""
    token = _BATCH.set(dict(stamp))
    try:
        yield
    finally:
        _BATCH.reset(token)


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
