"""Batches on the real engine: a ``dask scheduler`` and two ``dask worker``
processes on 127.0.0.1, started here and stopped at the end whatever happens.

- the cluster writes byte for byte what the in-process run writes;
- a worker killed by SIGKILL in the middle of writing an item: the batch still
  completes (the scheduler gives the item to the other worker) and nothing
  partial is left;
- the client killed mid-batch: a rerun runs only the items that are missing.

The kills land at fixed points (``LUMIGRAPH_FAILPOINT``): a worker dies
between two renames of its item's commit (``commit:1``, the worst place), the
client after its first finished item (``batch:1``).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

N_BRACKETS = 5
SIZE = (48, 36)
STARTUP_S = 120  # a loaded 2-core CI machine can take long to import distributed


def _env(**extra) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", **extra}
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    env.pop("LUMIGRAPH_FAILPOINT", None)
    env.update(extra)
    return env


class Cluster:
    """A scheduler and workers in their own processes (no nanny: a worker is
    the process we started, so killing it kills the worker)."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.file = folder / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        self.workers: dict[str, subprocess.Popen] = {}
        self.scheduler = self._start("scheduler", "--host", "127.0.0.1", "--port", "0",
                                     "--no-dashboard", "--scheduler-file", self.file)

    def _start(self, what, *args, env=None):
        log = open(self.folder / f"{what}-{len(self.procs)}.log", "w")  # noqa: SIM115 - closed by the process's end
        p = subprocess.Popen([sys.executable, "-m", f"distributed.cli.dask_{what}", *map(str, args)],
                             stdout=log, stderr=subprocess.STDOUT, env=env or _env(),
                             start_new_session=True)
        self.procs.append(p)
        return p

    def client(self):
        from distributed import Client

        return Client(scheduler_file=str(self.file), timeout=STARTUP_S)

    @property
    def address(self) -> str:
        return json.loads(self.file.read_text())["address"]

    def add_worker(self, name: str, **env) -> None:
        self.workers[name] = self._start("worker", "--scheduler-file", self.file, "--nthreads", "1",
                                         "--no-nanny", "--name", name, "--no-dashboard",
                                         env=_env(**env))

    def wait_for(self, names) -> None:
        """Until exactly the workers ``names`` are connected (awaited on the
        scheduler, not slept)."""
        deadline = time.monotonic() + STARTUP_S
        while not self.file.exists():  # the scheduler writes it once listening
            assert self.scheduler.poll() is None, (self.folder / "scheduler-0.log").read_text()
            assert time.monotonic() < deadline, "scheduler did not start"
            time.sleep(0.05)
        with self.client() as c:
            c.wait_for_workers(len(self.workers), timeout=STARTUP_S)
            got = {w["name"] for w in c.scheduler_info(n_workers=-1)["workers"].values()}
        assert got == set(names), got

    def wait_idle(self) -> None:
        """Until the scheduler and every worker hold no task (a dead client's
        work released, what a worker was running finished)."""
        def busy(c) -> int:
            n = c.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks))
            return n + sum(c.run(lambda dask_worker: len(dask_worker.state.tasks)).values())

        deadline = time.monotonic() + STARTUP_S
        with self.client() as c:
            while busy(c):
                assert time.monotonic() < deadline, "the cluster stayed busy"
                time.sleep(0.05)

    def stop(self) -> None:
        for p in reversed(self.procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
        for p in self.procs:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=30)


@pytest.fixture
def cluster(tmp_path):
    folder = tmp_path / "cluster"
    folder.mkdir()
    c = Cluster(folder)
    try:
        yield c
    finally:
        c.stop()


@pytest.fixture(scope="module")
def brackets(tmp_path_factory):
    """``N_BRACKETS`` small rendered brackets in one folder, and a response."""
    from lumigraph.capture.render import render
    from lumigraph.hdr.cli import main as hdr

    d = tmp_path_factory.mktemp("brackets")
    for seed in range(N_BRACKETS):
        render("bracket", size=SIZE, seed=seed).save(d / "shots" / f"b{seed}")
    assert hdr(["response", str(d / "shots" / "b0"), "--out", str(d / "response.json"), "-q"]) == 0
    return d


def _merge(brackets: Path, out: Path, *extra: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumigraph", "hdr", "merge", brackets / "shots",
                           "--response", brackets / "response.json", "--out", out, *extra],
                          capture_output=True, text=True, env=env or _env(), timeout=300)


def _artifacts(folder: Path) -> dict[str, bytes]:
    """Every primary artifact (not the sidecars and index, which hold times and paths)."""
    return {f.name: f.read_bytes() for f in sorted(folder.iterdir())
            if not f.name.endswith(".json")}


@pytest.fixture(scope="module")
def reference(brackets):
    out = brackets / "in-process"
    r = _merge(brackets, out, "-q")
    assert r.returncode == 0, r.stderr
    arts = _artifacts(out)
    assert len(arts) == 2 * N_BRACKETS  # a radiance map and a mask per bracket
    return arts


def _index(out: Path) -> dict:
    """Each item's row of index.json with its time and worker from the sidecar."""
    runs = {r["name"]: r for r in json.loads((out / "index.json.meta.json").read_text())["items"]}
    return {it["name"]: {**it, **runs[it["name"]]}
            for it in json.loads((out / "index.json").read_text())["items"]}


def _no_leftovers(out: Path) -> None:
    hidden = [f.name for f in out.iterdir() if f.name.startswith(".")]
    assert hidden == [], f"temporaries or journals left: {hidden}"


def test_the_cluster_writes_what_the_in_process_run_writes(cluster, brackets, reference, tmp_path):
    cluster.add_worker("w1")
    cluster.add_worker("w2")
    cluster.wait_for(["w1", "w2"])
    out = tmp_path / "cluster-run"
    r = _merge(brackets, out, "--scheduler", cluster.address, "-q")
    assert r.returncode == 0, r.stderr
    assert _artifacts(out) == reference
    index = _index(out)
    assert {i["status"] for i in index.values()} == {"done"}
    workers = {i["worker"].rsplit(":", 1)[1] for i in index.values()}
    assert workers <= {str(p.pid) for p in cluster.workers.values()}  # not this process, not the client
    _no_leftovers(out)


def test_a_worker_killed_mid_item_loses_nothing(cluster, brackets, reference, tmp_path):
    cluster.add_worker("doomed", LUMIGRAPH_FAILPOINT="commit:1")  # SIGKILL between two renames
    cluster.add_worker("healthy")
    cluster.wait_for(["doomed", "healthy"])
    out = tmp_path / "cluster-run"
    r = _merge(brackets, out, "--scheduler", cluster.address, "-q")
    assert r.returncode == 0, r.stderr
    assert cluster.workers["doomed"].wait(timeout=60) == -signal.SIGKILL  # it did die mid-commit
    assert _artifacts(out) == reference  # every item, whole
    healthy = str(cluster.workers["healthy"].pid)
    assert {i["worker"].rsplit(":", 1)[1] for i in _index(out).values()} == {healthy}
    _no_leftovers(out)


def test_a_killed_client_resumes_with_the_missing_items_only(cluster, brackets, reference, tmp_path):
    cluster.add_worker("w1")
    cluster.wait_for(["w1"])
    out = tmp_path / "cluster-run"
    r = _merge(brackets, out, "--scheduler", cluster.address, "-q",
               env=_env(LUMIGRAPH_FAILPOINT="batch:1"))  # the client dies after one item
    assert r.returncode == -signal.SIGKILL, r.stderr
    cluster.wait_idle()  # what the dead client's worker was running has landed (or not)
    before = {f.name: f.stat().st_mtime_ns for f in out.iterdir() if f.suffix == ".exr"}
    assert 1 <= len(before) < N_BRACKETS, before
    r = _merge(brackets, out, "--scheduler", cluster.address, "-q")
    assert r.returncode == 0, r.stderr
    index = _index(out)
    for name in before:  # there before the rerun: not run again, not rewritten
        name = name[: -len(".exr")]
        assert index[name]["status"] == "skipped", index[name]
        assert (out / f"{name}.exr").stat().st_mtime_ns == before[f"{name}.exr"]
    assert sum(i["status"] == "done" for i in index.values()) == N_BRACKETS - len(before)
    assert _artifacts(out) == reference
    _no_leftovers(out)


def _lumigraph(*argv, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lumigraph", *map(str, argv)], capture_output=True,
                          text=True, env=env or _env(), timeout=300)


def test_flow_and_undistort_on_the_cluster_write_what_they_write_in_process(cluster, tmp_path):
    """The sequence commands that batch only on request (flow, calib undistort,
    hdr video with its tone mapping): the same bytes either way."""
    from lumigraph.capture.render import render

    root = Path(__file__).resolve().parents[2]
    frames = render("flow-sequence", size=SIZE, seed=1, frames=4).save(tmp_path / "seq")
    frames = sorted(Path(frames).glob("frame*.png"))
    shots = [root / "fixtures" / "flow" / f"frame0{k}.png" for k in (0, 1)]
    # hdr video: each output frame one item reading its neighbour frames
    from lumigraph.hdr.response import ResponseCurve

    video = tmp_path / "video-in"
    s = render("bracket_video", size=SIZE, frames=4, seed=2)
    s.save(video / "vid")
    ResponseCurve("gt", 8, s.gt_arrays["g"]).save(video / "response.json")
    cluster.add_worker("w1")
    cluster.add_worker("w2")
    cluster.wait_for(["w1", "w2"])
    for where, extra in (("plain", ()), ("cluster", ("--scheduler", cluster.address))):
        r = _lumigraph("flow", *frames, "--out", tmp_path / where / "flow", "-q", *extra)
        assert r.returncode == 0, r.stderr
        r = _lumigraph("calib", "undistort", "--camera", root / "fixtures" / "camera.json", *shots,
                       "--out", tmp_path / where / "undistorted", "-q", *extra)
        assert r.returncode == 0, r.stderr
        r = _lumigraph("hdr", "video", video / "vid", "--response", video / "response.json",
                       "--out", tmp_path / where / "video", "--tonemap", "-q", *extra)
        assert r.returncode == 0, r.stderr
    for what in ("flow", "undistorted", "video"):
        plain, batch = _artifacts(tmp_path / "plain" / what), _artifacts(tmp_path / "cluster" / what)
        assert plain and plain == batch, what
        assert {i["status"] for i in _index(tmp_path / "cluster" / what).values()} == {"done"}
