"""``lumigraph view`` on the command line: the URL printed and the page
served from 127.0.0.1, a port in use (exit 2 with ``--port``, another port
without), ``--check``, and bad inputs as one-line exit 2."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import urllib.request

import pytest
from cli_catalog import run_cli


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from lumigraph.capture.render import render

    s = render("facade", size=(96, 72), seed=0, photos=6, novel=0, supersample=1)
    return s.save(tmp_path_factory.mktemp("facade") / "scene")


@pytest.fixture
def busy_port():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield sock.getsockname()[1]


def test_a_port_in_use_with_port_given_is_exit_2_one_line(busy_port):
    rc, out, err = run_cli(["view", "--port", str(busy_port), "--no-browser"])
    assert rc == 2 and out == ""
    assert err.strip() == (f"error: --port: port {busy_port} on 127.0.0.1 is in use; choose "
                           "another, or leave out --port to take a free one")


def test_a_port_in_use_by_default_takes_another(busy_port):
    from lumigraph.view.app import create_app, start_server

    server = start_server(create_app(artifacts=[]), default=busy_port)
    try:
        assert server.port != busy_port and server.host == "127.0.0.1"
    finally:
        server.server_close()


def _as_from_a_terminal():
    # Ctrl-C as a terminal delivers it. An ignored signal stays ignored
    # across exec, and a blocked one blocked: a test process that inherited
    # either (a run started in the background ignores SIGINT) would test its
    # own signal state, not the server. This test hung twice on 2026-12-03
    # in whole-suite runs started in the background, with nothing on the
    # server's stderr; the cause is not pinned down (alone, in the
    # background too, it passes), so the stack dump below stays
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGABRT})


def test_view_prints_the_url_and_serves_until_interrupted(scene, tmp_path):
    # stderr to a file, not a pipe nobody drains (a full pipe would block the server)
    err = tmp_path / "stderr.txt"
    with open(err, "w") as err_file:
        # (faulthandler: a stuck server is sent SIGABRT below and prints every thread's stack)
        p = subprocess.Popen([sys.executable, "-m", "lumigraph", "view", "--facade", str(scene),
                              "--edges", str(tmp_path / "edges.json"), "--no-browser"],
                             stdout=subprocess.PIPE, stderr=err_file, text=True,
                             env={**os.environ, "PYTHONFAULTHANDLER": "1"},
                             preexec_fn=_as_from_a_terminal)
    try:
        line = p.stdout.readline()
        assert line.startswith("lumigraph view: http://127.0.0.1:"), (line, err.read_text())
        url = line.split()[2]
        with urllib.request.urlopen(url + "api/mode", timeout=10) as r:
            assert json.loads(r.read()) == {"facade": True, "artifacts": 0}
        with urllib.request.urlopen(url, timeout=10) as r:
            page = r.read().decode()
        assert '<section id="look"></section>' in page and "/static/look.js" in page
        assert "http" not in page.replace("http://127.0.0.1", "")  # no CDN
    finally:
        p.send_signal(signal.SIGINT)
        # A liveness limit, not a measurement: it stops in well under a second alone, but
        # a fresh clone's `make test` once took over 20 s here on two busy cores. If it
        # does not stop, its stderr says where it was.
        try:
            rc = p.wait(60)
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGABRT)       # faulthandler dumps the stacks, then it dies
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
            raise AssertionError(f"did not stop on SIGINT within 60 s (status after SIGABRT: "
                                 f"{p.returncode}); stderr: "
                                 f"{err.read_text()[-6000:]!r}") from None
    assert rc == 0, err.read_text()


def test_check_opens_the_inputs_and_exits(scene, tmp_path):
    rc, out, err = run_cli(["view", "--facade", scene, "--edges", tmp_path / "e.json", "--check"])
    assert rc == 0, err
    assert not (tmp_path / "e.json").exists()


@pytest.mark.parametrize("damage,fragment", [
    (lambda f: (f / "blocks.json").write_text('{"blocks": [{"name": "b", "kind": "cone"}]}'),
     "blocks.json"),
    (lambda f: (f / "camera.json").unlink(), "camera.json"),
    (lambda f: (f / "photo_01.png").write_bytes(b"garbage"), "photo_01.png"),
])
def test_bad_facade_inputs_are_exit_2_naming_the_file(scene, tmp_path, damage, fragment):
    import shutil

    work = tmp_path / "scene"
    shutil.copytree(scene, work)
    damage(work)
    rc, _, err = run_cli(["view", "--facade", work, "--edges", tmp_path / "e.json", "--check"])
    assert rc == 2 and len(err.strip().splitlines()) == 1 and fragment in err, err


def test_edges_without_facade_is_exit_2(tmp_path):
    rc, _, err = run_cli(["view", "--edges", tmp_path / "e.json", "--check"])
    assert rc == 2 and err.startswith("error: --facade: "), err
    rc, _, err = run_cli(["view", "--facade", tmp_path, "--check"])
    assert rc == 2 and err.startswith("error: --edges: "), err
