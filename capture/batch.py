"""Batches of independent items, in-process or on a Dask distributed cluster.

A batch command (``hdr merge`` over many brackets, ``flow`` over a sequence,
``calib undistort`` over many images, ``separate`` over many stacks) describes
its work as :class:`Item` values: a name, the files the item reads, the
artifacts it writes, and the work itself as an importable function
(``"module:function"``) with plain keyword arguments, so an item pickles and
runs the same in this process or on any worker of a cluster.

:func:`run_batch` runs them:

- in this process, one after the other (the default; Dask is not imported);
- on a local cluster of ``workers`` processes
  (``distributed.LocalCluster(n_workers=N, threads_per_worker=1,
  processes=True)``);
- on an existing cluster at ``scheduler`` (``tcp://HOST:PORT``).

Each item's artifacts are written by whoever runs it, atomically, with their
``.meta.json`` sidecars (:mod:`lumigraph.capture.artifact`); each sidecar
records the item's *key* (a hash of its options and of every input file's
bytes). A rerun skips an item whose artifacts are all present with the
current key, so a batch killed half-way resumes where it stopped. An item
that fails is reported by name with its one-line reason; the others complete.
``index.json`` in the output folder lists the items, their status, outputs
and input hashes; its ``index.json.meta.json`` adds each item's time, worker,
key and warnings, and the engine.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> _ = (d / "a.txt").write_text("hello")
>>> item = Item("a", inputs=(str(d / "a.txt"),), outputs=(str(d / "out" / "a.json"),),
...             func="lumigraph.capture.batch:copy_json_item",
...             kwargs={"source": str(d / "a.txt"), "out": str(d / "out" / "a.json")})
>>> r = run_batch([item], out_dir=d / "out", quiet=True)
>>> r.counts, r.exit_status
({'done': 1, 'skipped': 0, 'failed': 0}, 0)
>>> run_batch([item], out_dir=d / "out", quiet=True).counts   # a rerun: nothing to do
{'done': 0, 'skipped': 1, 'failed': 0}
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from lumigraph.capture.errors import InputError

INDEX_NAME = "index.json"
INDEX_SCHEMA = "lumigraph.batch"
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
THREADS_ENV = "LUMIGRAPH_NUM_THREADS"
# What a worker process pins to one thread: each worker is one item at a time
# on one core, so threaded BLAS, OpenCV or our own thread pools (hdr merge's
# chunks, block matching's bands: THREADS_ENV) would oversubscribe the machine
# -- and a 1-worker cluster would already use every core, leaving a second
# worker nothing to add.
ONE_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                  THREADS_ENV: "1"}


def default_threads(cap: int = 4) -> int:
    """How many threads a library call's own pool may use when the caller
    does not say: ``$LUMIGRAPH_NUM_THREADS`` (1 in a batch worker), else the
    machine's cores, at most ``cap``.

    >>> import os
    >>> os.environ[THREADS_ENV] = "1"; default_threads()
    1
    >>> del os.environ[THREADS_ENV]; 1 <= default_threads(cap=2) <= 2
    True
    """
    with contextlib.suppress(ValueError):
        n = int(os.environ.get(THREADS_ENV, ""))
        if n >= 1:
            return min(n, cap)
    return max(1, min(cap, os.cpu_count() or 1))


@dataclass(frozen=True)
class Item:
    """One independent piece of a batch.

    Attributes
    ----------
    name : str
        How messages and ``index.json`` name the item (a bracket's folder name).
    inputs : tuple of str
        Files (or folders: their visible files) the item reads; their bytes
        are hashed into the item's key.
    outputs : tuple of str
        Every artifact the item writes (each with its sidecar); the item is
        done when all are present and carry its key.
    func : str
        ``"module:function"``, importable wherever the item runs.
    kwargs : dict
        Plain keyword arguments of ``func`` (strings, numbers, lists).
    """

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    func: str
    kwargs: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Outcome:
    """What became of one item: ``status`` is ``"done"``, ``"skipped"`` (its
    artifacts were already there, with its key) or ``"failed"`` (``reason``,
    one line)."""

    name: str
    status: str
    reason: str = ""
    seconds: float = 0.0
    worker: str = ""
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class BatchResult:
    """The outcomes of a batch, in item order, and where its index is."""

    outcomes: tuple[Outcome, ...]
    index: Path
    engine: str
    wall_s: float

    @property
    def counts(self) -> dict[str, int]:
        return {s: sum(o.status == s for o in self.outcomes) for s in ("done", "skipped", "failed")}

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes if o.status == "failed"]

    @property
    def exit_status(self) -> int:
        """0 when every item is done (or was already), 4 when some failed."""
        from lumigraph.capture.commandline import EXIT_OK, EXIT_PARTIAL

        return EXIT_PARTIAL if self.failed else EXIT_OK


class ItemFailed(Exception):
    """An item's work refused its input or could not be done: ``reason`` is
    the one line the batch reports under the item's name."""

    def __init__(self, reason: str):
        self.reason = reason
        super().__init__(reason)


def stack_folders(paths: Sequence[str | os.PathLike]) -> list[Path] | None:
    """The stacks of a batch given as inputs: several folders holding
    ``stack.json`` (or several ``stack.json`` files), or one folder of such
    folders; None when ``paths`` are one stack (its images, or its folder)."""
    ins = [Path(p) for p in paths]
    folders = [p.parent if p.name == "stack.json" and p.is_file() else p for p in ins]
    if len(folders) > 1 and all((f / "stack.json").is_file() for f in folders):
        return folders
    if len(ins) == 1 and ins[0].is_dir() and not (ins[0] / "stack.json").exists():
        subs = sorted(d for d in ins[0].iterdir() if d.is_dir() and (d / "stack.json").is_file())
        if subs:
            return subs
    return None


def item_name(folder: Path) -> str:
    """An item's name from its input folder (``.`` named after the real folder)."""
    return folder.name if folder.name not in ("", ".", "..") else folder.resolve().name


# ---------------------------------------------------------------- keys


def _visible_files(folder: Path) -> list[Path]:
    """The files of a folder an item reads: not hidden (our temporaries), not
    sidecars (their timestamps change on every run)."""
    return sorted(f for f in folder.iterdir()
                  if f.is_file() and not f.name.startswith(".") and not f.name.endswith(".meta.json"))


def input_hashes(paths: Iterable[str | os.PathLike], *,
                 cache: dict[str, str] | None = None) -> dict[str, str]:
    """``{file: sha256}`` of every input file (a folder: each of its visible
    files). ``cache`` keeps the hashes of files shared by many items (one
    response curve for every bracket)."""
    from lumigraph.capture.artifact import file_sha256

    cache = {} if cache is None else cache
    out: dict[str, str] = {}
    for p in paths:
        p = Path(p)
        files = _visible_files(p) if p.is_dir() else [p]
        for f in files:
            k = str(f)
            if k not in cache:
                try:
                    cache[k] = file_sha256(f)
                except FileNotFoundError:
                    raise InputError(f, "input file not found") from None
                except OSError as e:
                    raise InputError(f, f"cannot read it ({e.strerror or e})") from None
            out[k] = cache[k]
    return out


def item_key(item: Item, hashes: dict[str, str]) -> str:
    """The item's identity for a rerun: its work, its options, the bytes of
    its inputs."""
    text = json.dumps({"func": item.func, "kwargs": item.kwargs, "inputs": hashes},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def is_done(item: Item, key: str) -> bool:
    """Whether every artifact of ``item`` is present, complete (its bytes match
    the hash its sidecar recorded) and was written for ``key``."""
    from lumigraph.capture.artifact import file_sha256, meta_path

    for out in item.outputs:
        try:
            meta = json.loads(meta_path(out).read_text())
            if meta.get("batch", {}).get("key") != key:
                return False
            recorded = meta.get("output", {}).get("sha256")
            if recorded is not None and recorded != file_sha256(out):
                return False
        except (OSError, ValueError, AttributeError):
            return False
    return True


# ---------------------------------------------------------------- running one item


def _resolve(func: str) -> Callable:
    import importlib

    module, _, name = func.partition(":")
    return getattr(importlib.import_module(module), name)


_PINNED = False


def pin_threads() -> None:
    """One thread for OpenCV (and, for libraries loaded after this, BLAS and
    OpenMP) in a worker process."""
    global _PINNED
    if _PINNED:
        return
    for k, v in ONE_THREAD_ENV.items():
        os.environ.setdefault(k, v)
    with contextlib.suppress(ImportError):
        import cv2

        cv2.setNumThreads(1)
    _PINNED = True


def execute(item: Item, key: str, *, pin: bool = True) -> Outcome:
    """Run one item where this is called (a worker, or this process) and say
    how it went; never raises for the item's own failure."""
    from lumigraph.capture.artifact import batch_stamp
    from lumigraph.capture.errors import EstimationError, UnusableResult

    if pin:
        pin_threads()
    t0 = time.perf_counter()
    warnings: tuple[str, ...] = ()
    try:
        with batch_stamp({"item": item.name, "key": key}):
            got = _resolve(item.func)(**item.kwargs)
        if isinstance(got, list | tuple):
            warnings = tuple(str(w) for w in got)
        status, reason = "done", ""
    except ItemFailed as e:
        status, reason = "failed", e.reason
    except (InputError, EstimationError, UnusableResult) as e:
        status, reason = "failed", " ".join(str(e).split())
    except Exception as e:  # our bug, but one item's: the others still run
        status, reason = "failed", f"internal: {type(e).__name__}: {' '.join(str(e).split())}"
    return Outcome(item.name, status, reason, time.perf_counter() - t0,
                   f"{socket.gethostname()}:{os.getpid()}", warnings)


_COMMAND_LOCK = threading.Lock()
RUNS = [0]  # batches run by this process (the command line warns when --workers found none)


def command_item(name: str, *, inputs: Iterable, outputs: Iterable, module: str, prog: str,
                 argv: Sequence[str]) -> Item:
    """An :class:`Item` that runs one command line ``argv`` of the command
    module ``module`` (:func:`run_command`): the same call, and so the same
    bytes, as the single command run by hand.

    >>> it = command_item("a", inputs=["in/a"], outputs=["out/a.exr"],
    ...                   module="lumigraph.hdr.cli", prog="lumigraph hdr", argv=["merge", "in/a"])
    >>> it.func, it.outputs
    ('lumigraph.capture.batch:run_command', ('out/a.exr',))
    """
    return Item(name, inputs=tuple(str(p) for p in inputs),
                outputs=tuple(str(p) for p in outputs), func="lumigraph.capture.batch:run_command",
                kwargs={"module": module, "prog": prog, "argv": argv})


def run_items(items: Sequence[Item], *, out_dir: str | os.PathLike, args,
              description: str) -> int:
    """A command's batch from its parsed ``args`` (``workers``, ``scheduler``,
    ``quiet``): every planned output and ``index.json`` checked before any
    work, the items run (:func:`run_batch`), the outcome reported; returns
    the exit status (:func:`report`)."""
    from lumigraph.capture.commandline import check_planned

    check_planned([p for it in items for p in it.outputs] + [Path(out_dir) / "index.json"])
    result = run_batch(items, out_dir=out_dir, workers=args.workers, scheduler=args.scheduler,
                       quiet=args.quiet, description=description)
    return report(result, quiet=args.quiet)


def run_command(*, module: str, argv: Sequence[str], prog: str) -> list[str]:
    """An item that is one run of a lumigraph command (``module``'s ``main``,
    e.g. ``lumigraph.hdr.cli`` with ``["merge", BRACKET, "--response", R,
    "--out", OUT]``): the same parsing, checks, library call and atomic result
    set as the command typed by hand. Its stderr is kept; a failure becomes
    :class:`ItemFailed` with the command's one error line, and its warnings
    are returned."""
    import importlib

    from lumigraph.capture.artifact import unstaged

    main = importlib.import_module(module).main
    buf = io.StringIO()
    # sys.stderr and sys.argv are the process's: a worker started with several
    # threads runs its commands one at a time (start workers with --nthreads 1)
    with _COMMAND_LOCK:
        saved_err, saved_argv = sys.stderr, sys.argv
        sys.stderr = buf
        sys.argv = [*prog.split(), *argv]  # what the sidecars record as the command
        try:
            with unstaged():  # in-process: the item's own result set commits now, not the batch's
                rc = main(list(argv), prog=prog)
        finally:
            sys.stderr, sys.argv = saved_err, saved_argv
    lines = buf.getvalue().splitlines()
    if rc != 0:
        errors = [ln for ln in lines if ln.startswith("error: ")]
        raise ItemFailed(errors[-1][len("error: "):] if errors else f"exit status {rc}")
    return [ln[len("warning: "):] for ln in lines if ln.startswith("warning: ")]


def copy_json_item(*, source: str, out: str) -> None:
    """A tiny item for examples and tests: ``source``'s text into a JSON
    artifact ``out``."""
    from lumigraph.capture.artifact import make_meta, save_json_artifact

    text = Path(source).read_text()
    if not text:
        raise InputError(source, "is empty")
    save_json_artifact(out, {"text": text}, meta=make_meta("lumigraph.demo", inputs=[source]))


# ---------------------------------------------------------------- engines


def engine_from(workers: int | None, scheduler: str | None) -> str:
    """``"in-process"``, ``"local:N"`` or the scheduler's address (the
    ``DASK_SCHEDULER_ADDRESS`` environment variable when neither is given)."""
    if workers is not None and scheduler is not None:
        raise InputError("scheduler", "give --workers (a local cluster) or --scheduler (an existing "
                                      "one), not both")
    if workers is not None:
        return f"local:{int(workers)}"
    scheduler = scheduler or os.environ.get(SCHEDULER_ENV) or None
    return scheduler if scheduler else "in-process"


# What Dask's workers do beside the items, turned down on the clusters we
# start: a statistical profiler sampling the running task's stack every 10 ms
# (it takes the GIL from the item each time), the memory monitor every 100 ms,
# the system monitor every 500 ms, the event loop's tick every 20 ms. Measured
# on one worker merging 640x480 brackets (docs/decisions/batch.md): the
# worker's CPU per item fell from ~1.15x to ~1.0x the in-process item's, its
# idle CPU from 4 % to 0.3 % of a core. The dashboard is not started either.
QUIET_WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.tick.interval": "500ms",
}
# How long a client waits for an existing scheduler (--scheduler): a live one
# on a network answers in milliseconds, and a wrong address should be refused
# while the user still watches (Dask's default is 30 s).
CONNECT_TIMEOUT = "5s"


@contextlib.contextmanager
def local_cluster(n: int, *, warm: Sequence[str] = ()):
    """A Dask ``LocalCluster`` of ``n`` worker processes, one thread each,
    BLAS, OpenCV and our pools pinned to one thread (:data:`ONE_THREAD_ENV`),
    the workers' own background work turned down
    (:data:`QUIET_WORKER_CONFIG`), and warm: each has imported the modules
    ``warm`` (those the items will run) before the cluster is handed over,
    as the workers of a cluster that has run a batch before have."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    # the workers take the configuration current when the nanny starts them
    with dask.config.set(QUIET_WORKER_CONFIG), \
            LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                         env=ONE_THREAD_ENV, silence_logs=logging.ERROR) as cluster:
        with Client(cluster) as client:
            client.run(warm_worker, list(warm))
        yield cluster


def item_modules(items: Iterable[Item]) -> list[str]:
    """The modules ``items`` will import where they run: their functions'
    and, for :func:`run_command` items, their commands'."""
    out: dict[str, None] = {}
    for it in items:
        out[it.func.partition(":")[0]] = None
        if isinstance(it.kwargs.get("module"), str):
            out[it.kwargs["module"]] = None
    return list(out)


def warm_worker(modules: Sequence[str]) -> None:
    """Import the modules a batch item will (the first item on a cold worker
    otherwise pays for them) and pin the threads."""
    import importlib

    pin_threads()
    for m in modules:
        with contextlib.suppress(ImportError):
            importlib.import_module(m)


def _probe(address: str, timeout: str) -> None:
    """Connect to ``address`` and exchange Dask's handshake, within
    ``timeout``, then hang up. ``distributed.Client`` bounds the TCP connect
    but not the handshake's read: a port that accepts and stays silent (not a
    Dask scheduler) would hold it forever."""
    import asyncio

    from dask.utils import parse_timedelta
    from distributed.comm import connect

    seconds = parse_timedelta(timeout, "s")

    async def probe():
        comm = await asyncio.wait_for(connect(address, timeout=seconds), seconds)
        await comm.close()

    try:
        asyncio.run(probe())
    except TimeoutError:
        raise OSError(f"no Dask handshake within {timeout}") from None


@contextlib.contextmanager
def _client(engine: str, *, warm: Sequence[str] = ()):
    """A Dask client on a new local cluster (``local:N``) or an existing one."""
    import logging

    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - a dependency
        raise InputError("workers", "needs dask[distributed]: pip install 'dask[distributed]'") from None
    # distributed logs its own life (worker start/stop, a lost worker) at INFO
    # and WARNING on stderr; a run says our lines only (--debug shows more)
    logging.getLogger("distributed").setLevel(logging.ERROR)
    if engine.startswith("local:"):
        with local_cluster(int(engine.split(":", 1)[1]), warm=warm) as cluster, Client(cluster) as client:
            yield client
        return
    try:
        _probe(engine, CONNECT_TIMEOUT)
        client = Client(engine, timeout=CONNECT_TIMEOUT)
    except Exception as e:  # noqa: BLE001 - a wrong address is the user's input, whatever answers
        # a refused or silent port times out (OSError); something that is not
        # a Dask scheduler can answer with bytes Dask reads as a frame length
        # (MemoryError, ValueError): either way not a scheduler
        raise InputError("scheduler", f"cannot reach a Dask scheduler at {engine} ({type(e).__name__}: "
                                      f"{' '.join(str(e).split())[:200]}); start "
                                      "one with 'dask scheduler' or check the address") from None
    with client:
        yield client


# ---------------------------------------------------------------- the batch


def check_items(items: Sequence[Item]) -> None:
    """Refuse, before any work, a batch whose items would write one file twice."""
    seen: dict[str, str] = {}
    names: set[str] = set()
    for it in items:
        if it.name in names:
            raise InputError(it.name, "two items of the batch have this name; rename one input")
        names.add(it.name)
        for o in it.outputs:
            k = os.path.abspath(o)
            if k in seen:
                raise InputError(it.name, f"would write {o}, like item {seen[k]}; rename one input")
            seen[k] = it.name


def run_batch(items: Sequence[Item], *, out_dir: str | os.PathLike, workers: int | None = None,
              scheduler: str | None = None, quiet: bool = False, description: str = "items",
              command: Sequence[str] | None = None,
              on_outcome: Callable[[Outcome], None] | None = None) -> BatchResult:
    """Run ``items`` (see the module's description) and write ``index.json``.

    Parameters
    ----------
    items : sequence of Item
        Independent pieces of work, names and outputs distinct.
    out_dir : path
        The folder the batch writes into; ``index.json`` goes there.
    workers : int, optional
        Run on a new local cluster of this many worker processes.
    scheduler : str, optional
        Run on the existing cluster at this address (``tcp://HOST:PORT``);
        default ``$DASK_SCHEDULER_ADDRESS``. Neither: in this process.
    quiet : bool
        No progress bar (there is one only on a terminal).
    description : str
        What the progress bar calls the items.
    command : sequence of str, optional
        The command line, for the index (default ``sys.argv``).
    on_outcome : callable, optional
        Called with each :class:`Outcome` as it arrives (in completion order).

    Returns
    -------
    BatchResult
        Per item, in order: done, skipped (already there with its key) or
        failed (with its one-line reason). Items failing is not an exception:
        :attr:`BatchResult.exit_status` is 4 then.

    Raises
    ------
    InputError
        Before any work: two items writing one file, an input that cannot
        be read, both ``workers`` and ``scheduler``, an unreachable scheduler.
    """
    from lumigraph.capture import artifact
    from lumigraph.capture.commandline import progress

    t_start = time.perf_counter()
    RUNS[0] += 1
    items = list(items)
    check_items(items)
    engine = engine_from(workers, scheduler)
    out_dir = Path(out_dir)
    cache: dict[str, str] = {}
    hashes = {it.name: input_hashes(it.inputs, cache=cache) for it in items}
    keys = {it.name: item_key(it, hashes[it.name]) for it in items}
    outcomes: dict[str, Outcome] = {}
    for it in items:
        if is_done(it, keys[it.name]):
            outcomes[it.name] = Outcome(it.name, "skipped")
    todo = [it for it in items if it.name not in outcomes]
    index = out_dir / INDEX_NAME
    state = {"written": 0.0}

    def rel(p: str) -> str:
        with contextlib.suppress(ValueError):
            return os.path.relpath(p, out_dir) if Path(p).is_absolute() == out_dir.is_absolute() else p
        return p

    def write_index(final: bool = False) -> None:
        # index.json says what is done, from what (stable: a rerun that does
        # the same writes the same bytes); its sidecar, when and where
        now = time.monotonic()
        if not final and now - state["written"] < 0.5:  # a long batch rewrites it twice a second at most
            return
        state["written"] = now
        rows, runs = [], []
        for it in items:
            o = outcomes.get(it.name)
            rows.append({"name": it.name, "status": o.status if o else "pending",
                         "reason": o.reason if o else "", "outputs": [rel(p) for p in it.outputs],
                         "inputs": hashes[it.name]})
            runs.append({"name": it.name, "seconds": o.seconds if o else None,
                         "worker": o.worker if o else "", "key": keys[it.name],
                         "warnings": list(o.warnings) if o else []})
        body = {"schema": INDEX_SCHEMA, "schema_version": 1,
                "counts": {s: sum(r["status"] == s for r in rows)
                           for s in ("done", "skipped", "failed", "pending")},
                "items": rows}
        meta = artifact.make_meta(INDEX_SCHEMA, command=command,
                                  timings_s={"wall": time.perf_counter() - t_start},
                                  warnings=[f"{r['name']}: {w}" for r in runs for w in r["warnings"]],
                                  extra={"engine": engine, "items": runs})
        with artifact.unstaged():  # the record of progress is visible at once (resume)
            artifact.write_artifact(index, lambda p: p.write_text(artifact.dumps_json(body)),
                                    meta=meta)

    crash_after = artifact._failpoint("batch")

    def arrived(o: Outcome) -> None:
        outcomes[o.name] = o
        if on_outcome is not None:
            on_outcome(o)
        write_index()
        if crash_after is not None and sum(x.status == "done" for x in outcomes.values()) >= crash_after:
            os.kill(os.getpid(), 9)  # tests: the client killed mid-batch (LUMIGRAPH_FAILPOINT=batch:N)

    # the cluster is reached before anything is written: an unreachable one is
    # bad input (exit 2) with nothing in the output folder
    remote = engine != "in-process" and bool(todo)
    with _client(engine, warm=item_modules(todo)) if remote else contextlib.nullcontext() as client:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_index(final=True)
        if remote:
            _run_distributed(client, todo, keys, arrived, quiet=quiet, description=description)
        elif todo:
            for it in progress(todo, total=len(todo), description=description, quiet=quiet):
                arrived(execute(it, keys[it.name], pin=False))
    # a worker killed while writing leaves its temporaries (never a final
    # name): the folder's own are removed, a commit it left is completed
    artifact.recover_commits(out_dir)
    for folder in {Path(o).parent for it in items for o in it.outputs}:
        artifact.recover_commits(folder)
        artifact.remove_stale_temps(folder, kind="dir")
    write_index(final=True)
    return BatchResult(tuple(outcomes[it.name] for it in items), index, engine,
                       time.perf_counter() - t_start)


def _run_distributed(client, todo: list[Item], keys: dict[str, str],
                     arrived: Callable[[Outcome], None], *, quiet: bool, description: str) -> None:
    from distributed import as_completed

    from lumigraph.capture.commandline import progress

    # a key per item and key: a rerun of a changed item is new work, and
    # two batches on one cluster never share a result
    futures = {client.submit(execute, it, keys[it.name], key=f"lumigraph-{it.name}-"
                             f"{keys[it.name][:16]}", pure=False): it for it in todo}
    for fut in progress(as_completed(futures), total=len(futures), description=description,
                        quiet=quiet):
        it = futures[fut]
        try:
            o = fut.result()
        except Exception as e:  # the cluster gave up on it (workers lost too often)
            o = Outcome(it.name, "failed", f"the cluster could not run it ({type(e).__name__}: "
                                           f"{' '.join(str(e).split())})")
        arrived(o)


def report(result: BatchResult, *, quiet: bool = False) -> int:
    """The command line's end of a batch: each failed item's one line, each
    item warning, a summary; returns the exit status (0, or 4 when some
    items failed)."""
    from lumigraph.capture.commandline import warn

    for o in result.outcomes:
        for w in o.warnings:
            warn(f"{o.name}: {w}")
    for o in result.failed:
        sys.stderr.write(f"error: {o.name}: {o.reason}\n")
    c = result.counts
    if not quiet or result.failed:
        sys.stderr.write(f"{c['done']} done, {c['skipped']} already done, {c['failed']} failed "
                         f"({result.engine}, {result.wall_s:.1f} s); see {result.index}\n")
    return result.exit_status
