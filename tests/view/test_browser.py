"""Marking mode in a real headless browser: Debian's Chromium driven by
Selenium 4 through the Debian chromedriver (``make sysdeps`` installs both;
selenium is in the ``dev`` extra). Skipped with the reason when they are
missing, except on CI (``CI`` set), where that fails.

The page is served by the real server (``start_server``, 127.0.0.1, a free
port, in a thread) over a rendered Façade scene (320x240, six photographs,
σ = 0.5 px marks). Every photograph but the first starts fully marked; the
first has three of its four hand marks. The test draws the fourth by a mouse
drag on the canvas, assigns it by clicking its edge in the list, presses
Propose, accepts or rejects each proposal of that photograph (as a user's eye
would: accepted when it lies on its true edge), presses Solve, then
Re-snap to model and Solve again, and checks the saved ``edges.json`` and a
screenshot: the reprojected edge's colour
(red) drawn along the true line of the edge it drew. A second scene, the
wing's right side marked once: Solve lists wing/width as weakly constrained,
a click on a suggested edge opens its photograph with the edge highlighted,
and marking it there lowers the width's σ. A third, the tower's top and the
spire unmarked: Solve is refused, and the panel lists the edges that would
constrain the tower's and the spire's heights, leading to them. And the whole
flow from scratch (every photograph unmarked) through the page's controls,
checked against issue 17's bound.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from facade_helpers import (  # noqa: E402
    EDGE_NOISE_PX,
    distance,
    four_hand_marks,
    onto_line,
    refusal_marks,
    truth_lines,
)

CHROMIUM = "/usr/bin/chromium"
DRIVER = "/usr/bin/chromedriver"


@contextlib.contextmanager
def _served(app):
    """The real server (``start_server``) on a free 127.0.0.1 port, in a thread,
    shut down when the block ends however it ends."""
    from lumigraph.view.app import start_server

    server = start_server(app, port=None)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        thread.join(5)


@contextlib.contextmanager
def _marking_page(d, session):
    """The marking page of ``session`` served (:func:`_served`) and loaded in the
    browser ``d``, idle; the server is shut down when the block ends."""
    from lumigraph.view.app import create_app

    with _served(create_app(artifacts=[], facade=session)) as server:
        d.get(f"http://127.0.0.1:{server.port}/")
        _idle(d)
        yield server


def _need_browser():
    missing = [p for p in (CHROMIUM, DRIVER) if not os.path.exists(p)]
    try:
        import selenium  # noqa: F401
    except ImportError:
        missing.append("selenium (pip install -e '.[dev]')")
    if missing:
        msg = (f"headless browser test needs {', '.join(missing)}: install the Debian packages "
               "chromium and chromium-driver (make sysdeps)")
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)


@pytest.fixture(scope="module")
def browser():
    _need_browser()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
              "--window-size=1300,900", "--force-device-scale-factor=1"):
        opts.add_argument(a)
    d = webdriver.Chrome(service=Service(DRIVER), options=opts)
    yield d
    d.quit()


def _wait(d, script, timeout=30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        got = d.execute_script(script)
        if got:
            return got
        time.sleep(0.05)
    shown = d.execute_script("return document.getElementById('error').textContent")
    raise AssertionError(f"timed out waiting for: {script}; page error: {shown}")


def _idle(d):
    _wait(d, "return window.lumiMark && window.lumiMark.ready && window.lumiMark.busy === 0")


def test_draw_assign_propose_solve_in_the_browser(browser, tmp_path):
    from selenium.webdriver.common.by import By

    from lumigraph.capture.render import render
    from lumigraph.stereo.debevec1996.edges import load_edges
    from lumigraph.view.marking import FacadeSession

    t0 = time.monotonic()
    s = render("facade", size=(320, 240), seed=2, photos=6, novel=0, supersample=2,
               edge_noise=EDGE_NOISE_PX)
    folder = s.save(tmp_path / "scene")
    truth = truth_lines(folder)
    body = json.loads((folder / "edges.json").read_text())
    first = "photo_00.png"
    hand = _four_hand_marks_sorted(folder, body["photographs"][first])
    drawn, body["photographs"][first] = hand[0], hand[1:]
    edges = tmp_path / "edges.json"
    edges.write_text(json.dumps(body))

    session = FacadeSession.open(folder, edges=edges)
    d = browser
    with _marking_page(d, session):
        canvas = d.find_element(By.ID, "photo-canvas")
        # drag along the edge, as a hand would: the marked segment plus 0.5 px noise
        seg = np.asarray(drawn["segment"]) + np.random.default_rng(3).normal(0, EDGE_NOISE_PX, 4)
        _drag(d, canvas, seg)
        _wait(d, "return window.lumiMark.selected !== null && window.lumiMark.busy === 0")
        # the snap says how far it moved the drag and how far the image's
        # edge scatters about it, and offers the way back
        assert "moved" in d.find_element(By.ID, "status").text
        assert "scatters" in d.find_element(By.ID, "status").text
        assert d.find_element(By.ID, "unsnap").is_enabled()
        d.find_element(By.CSS_SELECTOR, f'#edge-list li[data-edge="{drawn["edge"]}"]').click()
        _wait(d, "return window.lumiMark.busy === 0 && window.lumiMark.state.marks.some("
                 f"m => m.photo === '{first}' && m.edge === '{drawn['edge']}')")

        saved = load_edges(edges, model=session.model, photographs=session.photos)
        mine = [m for m in saved.of(first) if m.edge == drawn["edge"]]
        assert len(mine) == 1
        # snapped onto the edge: within half a pixel of the true line (one
        # rendered sample per pixel side pair locates an edge that well)
        assert distance(mine[0].segment, truth[first][drawn["edge"]]) <= 0.5
        # saved with the image's scatter about it, which the Solve weighs it by
        assert mine[0].spread_px is not None

        d.find_element(By.ID, "propose").click()
        _wait(d, "return window.lumiMark.busy === 0 && "
                 "document.getElementById('status').textContent.includes('proposals')", 60)
        for q in [q for q in d.execute_script("return window.lumiMark.state.proposals")
                  if q["photo"] == first]:
            ok = distance(q["segment"], truth[first][q["edge"]]) <= 3 * EDGE_NOISE_PX
            d.find_element(By.CSS_SELECTOR, f'#proposal-list li[data-proposal="{q["id"]}"] '
                                            f'button.{"accept" if ok else "reject"}').click()
            _wait(d, f"return window.lumiMark.busy === 0 && !window.lumiMark.state.proposals"
                     f".some(p => p.id === {q['id']})")
        d.find_element(By.ID, "solve").click()
        _wait(d, "return window.lumiMark.busy === 0 && window.lumiMark.state.solution !== null", 60)
        # the second look: Re-snap to the solved model, Solve again
        d.find_element(By.ID, "resnap").click()
        _wait(d, "return window.lumiMark.busy === 0 && "
                 "document.getElementById('status').textContent.startsWith('re-snapped')", 60)
        d.find_element(By.ID, "solve").click()
        _wait(d, "return window.lumiMark.busy === 0 && "
                 "document.getElementById('status').textContent.startsWith('solved')", 60)
        sol = d.execute_script("return window.lumiMark.state.solution")
        assert d.find_element(By.ID, "solve-rms").text.startswith("RMS")
        assert d.execute_script("return document.getElementById('error').hidden")

        saved = load_edges(edges, model=session.model, photographs=session.photos)
        assert len(saved.of(first)) > 4 and any(m.proposed for m in saved.of(first))
        # every mark's residual is from σ = 0.5 px endpoint noise: within 3σ
        assert max(sol["residual_by_id"].values()) <= 3 * EDGE_NOISE_PX

        # the screenshot: the drawn edge reprojected in red along its true line
        import cv2

        shot = cv2.imdecode(np.frombuffer(canvas.screenshot_as_png, np.uint8), cv2.IMREAD_COLOR)
        red = (shot[..., 2] > 180) & (shot[..., 1] < 100) & (shot[..., 0] < 100)
        p0, p1 = truth[first][drawn["edge"]]
        hits = 0
        ts = np.linspace(0.1, 0.9, 17)
        for t in ts:
            x, y = d.execute_script("return window.lumiMark.toScreen(arguments[0], arguments[1])",
                                    *(p0 + t * (p1 - p0)))
            # the reprojection lies within 0.5 px (image) of the true line;
            # two screen pixels of slack for the line's width and rounding
            r = 2 + int(np.ceil(0.5 * d.execute_script("return window.lumiMark.scale")))
            win = red[max(0, round(y) - r): round(y) + r + 1, max(0, round(x) - r): round(x) + r + 1]
            hits += bool(win.any())
        assert hits >= 0.8 * len(ts), f"red reprojection found at {hits} of {len(ts)} points"
        # the hand marks to check are listed, and a click selects the first on its photograph
        listed = d.find_elements(By.CSS_SELECTOR, "#check li button")
        assert [int(b.find_element(By.XPATH, "..").get_attribute("data-mark")) for b in listed] == \
            [q["id"] for q in sol["check"]] and listed
        listed[0].click()
        _wait(d, f"return window.lumiMark.busy === 0 && window.lumiMark.selected === {sol['check'][0]['id']}")
    print(f"browser test: {time.monotonic() - t0:.1f} s")


def _scene_session(tmp_path, edit):
    """The Façade scene (320x240, seed 2, 6 photographs) saved under ``tmp_path``,
    its marks edited in place by ``edit(photographs)`` and opened for marking.
    Returns the scene's marks before the edit (``{photo: [mark]}``) and the session."""
    from lumigraph.capture.render import render
    from lumigraph.view.marking import FacadeSession

    s = render("facade", size=(320, 240), seed=2, photos=6, novel=0, supersample=2,
               edge_noise=EDGE_NOISE_PX)
    folder = s.save(tmp_path / "scene")
    body = json.loads((folder / "edges.json").read_text())
    full = {p: list(v) for p, v in body["photographs"].items()}
    edit(body["photographs"])
    edges = tmp_path / "edges.json"
    edges.write_text(json.dumps(body))
    return full, FacadeSession.open(folder, edges=edges)


def _drag(d, canvas, seg):
    """A mouse drag on the canvas from image point seg[:2] to seg[2:]."""
    from selenium.webdriver.common.action_chains import ActionChains

    w, h = canvas.size["width"], canvas.size["height"]
    a = d.execute_script("return window.lumiMark.toScreen(arguments[0], arguments[1])", *seg[:2])
    b = d.execute_script("return window.lumiMark.toScreen(arguments[0], arguments[1])", *seg[2:])
    (ActionChains(d).move_to_element_with_offset(canvas, round(a[0] - w / 2), round(a[1] - h / 2))
     .click_and_hold().move_by_offset(round((b[0] - a[0]) / 2), round((b[1] - a[1]) / 2))
     .move_by_offset(round(b[0] - a[0]) - round((b[0] - a[0]) / 2),
                     round(b[1] - a[1]) - round((b[1] - a[1]) / 2))
     .release().perform())


def test_the_weak_list_leads_to_the_edge_to_mark(browser, tmp_path):
    """The scene's marks with the wing's right side kept in one mark only:
    Solve lists wing/width as weakly constrained with its suggested edges;
    clicking the first one the photographs show opens its photograph with
    the edge highlighted; dragging it, clicking the edge and Solving again
    lowers wing/width's σ."""
    from selenium.webdriver.common.by import By


    def one_right_side(photographs):
        kept = False
        for p, ms in photographs.items():
            right = [m for m in ms if m["edge"].startswith("wing/") and m["edge"].endswith("-right")]
            if not kept and right:
                kept, right = True, right[1:]
            photographs[p] = [m for m in ms if m not in right]

    full, session = _scene_session(tmp_path, one_right_side)
    d = browser
    with _marking_page(d, session):
        # the mark noise field reaches the Solve (its default: the next test)
        noise = d.find_element(By.ID, "noise")
        noise.clear()
        noise.send_keys("0.75")
        d.find_element(By.ID, "solve").click()
        _wait(d, "return window.lumiMark.busy === 0 && window.lumiMark.state.solution !== null", 60)
        before = d.execute_script("return window.lumiMark.state.solution")
        assert before["noise_px"] == 0.75
        w = before["weak"][0]
        assert w["parameter"] == "wing/width"
        items = d.find_elements(By.CSS_SELECTOR, '#weak li[data-parameter="wing/width"] button.suggest')
        assert len(items) == len(w["suggest"])
        k, q, m = next((k, q, m) for k, q in enumerate(w["suggest"]) for m in full[q["photo"]]
                       if m["edge"] == q["edge"])
        items[k].click()
        _wait(d, "return window.lumiMark.busy === 0")
        names = [p["name"] for p in d.execute_script("return window.lumiMark.state.photos")]
        assert names[d.execute_script("return window.lumiMark.photo")] == q["photo"]
        assert d.find_element(By.CSS_SELECTOR, "#edge-list li.current").text == q["edge"]
        seg = np.asarray(m["segment"]) + np.random.default_rng(5).normal(0, EDGE_NOISE_PX, 4)
        _drag(d, d.find_element(By.ID, "photo-canvas"), seg)
        _wait(d, "return window.lumiMark.selected !== null && window.lumiMark.busy === 0")
        d.find_element(By.CSS_SELECTOR, "#edge-list li.current").click()
        _wait(d, "return window.lumiMark.busy === 0 && window.lumiMark.state.marks.some("
                 f"m => m.photo === '{q['photo']}' && m.edge === '{q['edge']}')")
        d.find_element(By.ID, "solve").click()
        _wait(d, "return window.lumiMark.busy === 0 && "
                 "document.getElementById('status').textContent.startsWith('solved')", 60)
        after = d.execute_script("return window.lumiMark.state.solution")
        assert after["parameters"]["wing/width"]["std"] < w["std"]


def test_a_refusal_lists_the_edges_that_would_constrain_and_leads_to_them(browser, tmp_path):
    """The scene's marks without the tower's top and the spire: Solve is
    refused (tower/height, spire/height free); the Solve panel shows the
    refusal and, per unknown, the edges that would constrain it; clicking
    the first tower/height suggestion the photographs show opens its
    photograph with the edge highlighted."""
    from selenium.webdriver.common.by import By


    def no_tower_top_or_spire(photographs):
        for p, ms in photographs.items():
            photographs[p] = [m for m in ms if not m["edge"].startswith(("tower/top", "spire/"))]

    full, session = _scene_session(tmp_path, no_tower_top_or_spire)
    d = browser
    with _marking_page(d, session):
        d.find_element(By.ID, "solve").click()
        _wait(d, "return window.lumiMark.busy === 0 && window.lumiMark.state.refusal !== null", 60)
        ref = d.execute_script("return window.lumiMark.state.refusal")
        assert "do not constrain" in d.find_element(By.CSS_SELECTOR, "#unconstrained .refused").text
        u = next(u for u in ref["unconstrained"] if u["parameter"] == "tower/height")
        items = d.find_elements(By.CSS_SELECTOR,
                                '#unconstrained li[data-parameter="tower/height"] button.suggest')
        assert len(items) == len(u["suggest"]) > 0
        k, q = next((k, q) for k, q in enumerate(u["suggest"])
                    if any(m["edge"] == q["edge"] for m in full[q["photo"]]))
        items[k].click()
        _wait(d, "return window.lumiMark.busy === 0")
        names = [p["name"] for p in d.execute_script("return window.lumiMark.state.photos")]
        assert names[d.execute_script("return window.lumiMark.photo")] == q["photo"]
        assert d.find_element(By.CSS_SELECTOR, "#edge-list li.current").text == q["edge"]


def _four_hand_marks_sorted(folder, marks):
    """The four hand marks of a photograph, longest first."""
    from lumigraph.stereo.debevec1996.model import load_blocks

    four = four_hand_marks(load_blocks(folder / "blocks.json"), marks)
    return sorted(four, key=lambda m: -np.hypot(m["segment"][2] - m["segment"][0],
                                                m["segment"][3] - m["segment"][1]))


def test_an_unreadable_artifact_shows_its_one_line_error_and_the_server_keeps_serving(browser,
                                                                                     tmp_path):
    """Looking mode: the page opens on a broken EXR; its error line is shown
    where the picture would be, the marking tab stays hidden, and the server
    answers the next request."""
    import urllib.request

    from selenium.webdriver.common.by import By

    from lumigraph.view.app import create_app

    bad = tmp_path / "broken.exr"
    bad.write_bytes(b"not an exr at all")
    with _served(create_app(artifacts=[bad])) as server:
        browser.get(f"http://127.0.0.1:{server.port}/")
        _wait(browser, "return window.lumiMark && window.lumiMark.ready")
        shown = _wait(browser, "const e = document.querySelector('#look .look-error');"
                               "return e && e.textContent")
        assert shown.startswith(f"{bad}: ") and "\n" not in shown, shown
        assert not browser.find_element(By.ID, "mode-mark").is_displayed()
        assert browser.find_element(By.ID, "look").get_attribute("hidden") is None
        with urllib.request.urlopen(f"http://127.0.0.1:{server.port}/api/mode", timeout=10) as r:
            assert r.status == 200


def test_the_page_loads_without_a_facade_session(browser):
    """Looking mode only: the page starts, the marking tab stays hidden."""
    from selenium.webdriver.common.by import By

    from lumigraph.view.app import create_app

    with _served(create_app(artifacts=[])) as server:
        browser.get(f"http://127.0.0.1:{server.port}/")
        _wait(browser, "return window.lumiMark && window.lumiMark.ready")
        assert not browser.find_element(By.ID, "mode-mark").is_displayed()
        assert browser.find_element(By.ID, "look").get_attribute("hidden") is None


# The probe shows numbers as look.js's fmt does: six significant digits, so a
# shown value is the file's within half a unit of its sixth digit.
def _six_digits(v: float) -> float:
    return 0.5 * 10.0 ** (np.floor(np.log10(abs(v))) - 5) if v else 0.0


def _probe_text(d, img, xi: int, yi: int, zoom: int) -> str:
    """Move the mouse to the middle of file pixel (xi, yi) of ``img`` (drawn
    ``zoom`` CSS px per pixel) and wait until the probe line names that pixel."""
    from selenium.webdriver.common.action_chains import ActionChains

    w, h = img.size["width"], img.size["height"]
    # Selenium 4 offsets are from the element's centre
    (ActionChains(d).move_to_element_with_offset(img, round((xi + 0.5) * zoom - w / 2),
                                                 round((yi + 0.5) * zoom - h / 2)).perform())
    return _wait(d, "const p = document.querySelector('#look .look-probe');"
                    f"return p && p.textContent.startsWith('({xi}, {yi}):') && p.textContent")


def test_the_cursor_probe_shows_the_files_value_under_the_mouse(browser, tmp_path):
    """Looking mode: a ``.flo`` and a disparity PFM opened in the page; the mouse
    on a known pixel shows that pixel's vector (or disparity, or "unknown")
    as the project's reader reads it from the file. The pictures are drawn 8
    CSS px per pixel (as a zoomed page shows them), so the pointer sits inside
    its pixel whatever the rounding of the page's layout."""
    import re

    from selenium.webdriver.common.by import By

    from lumigraph.capture.io import read_flo, read_pfm, write_flo, write_pfm
    from lumigraph.view.app import create_app

    rng = np.random.default_rng(18)
    h, w, zoom = 30, 40, 8  # not square: a swapped x, y shows
    flow = rng.uniform(-20, 20, (h, w, 2)).astype(np.float32)
    write_flo(tmp_path / "motion.flo", flow)
    disp = rng.uniform(1, 60, (h, w)).astype(np.float32)
    disp[7, 31] = np.nan  # unknown
    write_pfm(tmp_path / "disp.pfm", disp)
    flow, disp = read_flo(tmp_path / "motion.flo"), read_pfm(tmp_path / "disp.pfm")
    d = browser
    number = r"(-?[\d.]+(?:e[-+]?\d+)?)"
    with _served(create_app(artifacts=[tmp_path / "motion.flo", tmp_path / "disp.pfm"])) as server:
        d.get(f"http://127.0.0.1:{server.port}/")
        for k, pixels in ((0, [(31, 7), (3, 22), (39, 0)]), (1, [(12, 25), (31, 7)])):
            if k:
                d.find_element(By.CSS_SELECTOR, "#look .look-list li:nth-child(2) button").click()
            _wait(d, "const i = document.querySelector('#look img.look-image');"
                     f"return i && i.alt.endsWith('{['motion.flo', 'disp.pfm'][k]}') && "
                     "i.complete && i.naturalWidth > 0")
            img = d.find_element(By.CSS_SELECTOR, "#look img.look-image")
            assert d.execute_script("return [arguments[0].naturalWidth, "
                                    "arguments[0].naturalHeight]", img) == [w, h]
            d.execute_script(f"arguments[0].style.width = '{w * zoom}px'", img)
            for xi, yi in pixels:
                text = _probe_text(d, img, xi, yi, zoom)
                if k == 0:
                    m = re.match(rf"\((\d+), (\d+)\): \({number}, {number}\) px", text)
                    assert m, text
                    for shown, true in zip(map(float, m.groups()[2:]), flow[yi, xi],
                                           strict=True):
                        assert abs(shown - true) <= _six_digits(true), (text, flow[yi, xi])
                elif np.isnan(disp[yi, xi]):
                    assert text.startswith(f"({xi}, {yi}): (unknown) px"), text
                else:
                    m = re.match(rf"\((\d+), (\d+)\): \({number}\) px", text)
                    assert m, text
                    assert abs(float(m.group(3)) - disp[yi, xi]) <= _six_digits(disp[yi, xi]), \
                        (text, disp[yi, xi])


@pytest.mark.slow
def test_marking_from_scratch_in_the_browser_meets_the_facade_bound(browser, tmp_path):
    """Issue 18's done-when in the browser, as a new user would go: every
    photograph starts unmarked. On each, four edges dragged by mouse
    (σ = 0.5 px about where the photograph shows the edge) and snapped, each
    assigned by clicking its edge in the list; Propose, each proposal
    accepted or rejected by its button (the user's eye: accepted when within
    three times the marks' noise of its true edge); Solve, and on a refusal
    the edges its panel lists dragged (at most three rounds); the edges the
    weak list suggests dragged; twice: Re-snap to model, Propose, review,
    Solve, the weak list; the hand marks the Solve lists to check selected
    from its list, deleted and dragged again with snap unticked; Solve.

    The same steps as ``test_marking_from_scratch_with_propose_meets_the_facade_bound``
    (the API), here through the page's own controls, its "mark noise" left
    at the default (0.5 px); the bound is issue 17's: the RMS relative parameter error within
    1.2x of the fully marked (σ = 0.5 px) solve of the same scene. Seed 2 is
    a tuned scene; the reported figures are docs/decisions/view-marking.md's."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    from lumigraph.stereo.debevec1996.edges import load_edges
    from lumigraph.stereo.debevec1996.model import load_blocks
    from lumigraph.stereo.debevec1996.solve import solve_facade
    from lumigraph.view.marking import SOLVE_NOISE_PX

    t0 = time.monotonic()
    full, session = _scene_session(tmp_path, lambda ph: ph.update({p: [] for p in ph}))
    folder = tmp_path / "scene"
    truth = truth_lines(folder)
    names = list(session.photos)
    rng = np.random.default_rng(7)
    d = browser
    js = "window.lumiMark."

    def state():
        return d.execute_script("return " + js + "state")

    def open_photo(p):
        i = names.index(p)
        if d.execute_script("return " + js + "photo") != i:
            Select(d.find_element(By.ID, "photo-select")).select_by_value(str(i))
            _wait(d, f"return {js}photo === {i} && window.lumiMark.busy === 0")

    def drag(p, m, *, snap=True):
        """Drag edge m["edge"] on photograph p where the photograph shows it
        (the scene's mark put back on its true line) with 0.5 px of hand
        noise, then click the edge in the list."""
        open_photo(p)
        box = d.find_element(By.ID, "snap")
        if box.is_selected() != snap:
            box.click()
        w, h = session.sizes[p]
        seg = onto_line(m["segment"], truth[p][m["edge"]]) + rng.normal(0, EDGE_NOISE_PX, 4)
        seg = np.clip(seg, -0.5, [w - 0.5, h - 0.5] * 2)
        n = len(state()["marks"])
        _drag(d, d.find_element(By.ID, "photo-canvas"), seg)
        _wait(d, f"return {js}busy === 0 && {js}state.marks.length === {n + 1} && {js}selected !== null")
        k = d.execute_script("return " + js + "selected")
        d.find_element(By.CSS_SELECTOR, f'#edge-list li[data-edge="{m["edge"]}"]').click()
        _wait(d, f"return {js}busy === 0 && {js}state.marks.some(q => q.id === {k} && q.edge === '{m['edge']}')")

    def review():
        d.find_element(By.ID, "propose").click()
        _wait(d, f"return {js}busy === 0 && /proposals|nothing proposed/.test("
                 "document.getElementById('status').textContent)", 120)
        for p in names:
            mine = [q for q in state()["proposals"] if q["photo"] == p]
            if mine:
                open_photo(p)
            for q in mine:
                ok = distance(q["segment"], truth[p][q["edge"]]) <= 3 * EDGE_NOISE_PX
                d.find_element(By.CSS_SELECTOR, f'#proposal-list li[data-proposal="{q["id"]}"] '
                                                f'button.{"accept" if ok else "reject"}').click()
                _wait(d, f"return {js}busy === 0 && !{js}state.proposals.some(r => r.id === {q['id']})")
        assert not state()["proposals"]

    def solve():
        """Press Solve; the solution, or None when refused."""
        d.find_element(By.ID, "solve").click()
        _wait(d, f"return {js}busy === 0 && /^(solved|not solved)/.test("
                 "document.getElementById('status').textContent)", 120)
        return None if state()["refusal"] else state()["solution"]

    def have():
        return {(m["photo"], m["edge"]) for m in state()["marks"]}

    def heed_weak(sol):
        added = 0
        for w in sol["weak"]:
            n = 0
            for q in w["suggest"]:
                m = next((m for m in full[q["photo"]] if m["edge"] == q["edge"]), None)
                if m is not None and (q["photo"], q["edge"]) not in have() and n < 4:
                    drag(q["photo"], m)
                    n += 1
            added += n
        if not added:
            return sol
        sol = solve()
        assert sol is not None, state()["refusal"]
        return sol

    model = load_blocks(folder / "blocks.json")
    with _marking_page(d, session):
        for p in names:
            for m in four_hand_marks(model, full[p]):
                drag(p, m)
        review()
        for attempt in range(4):
            sol = solve()
            if sol is not None or attempt == 3:
                break
            ref = state()["refusal"]
            assert "do not constrain" in ref["error"], ref["error"]
            for p, m in refusal_marks(ref["unconstrained"], full, have()):
                drag(p, m)
        assert sol is not None, state()["refusal"]
        sol = heed_weak(sol)
        for _ in range(2):
            d.find_element(By.ID, "resnap").click()
            _wait(d, f"return {js}busy === 0 && document.getElementById('status').textContent"
                     ".startsWith('re-snapped')", 120)
            review()
            sol = solve()
            assert sol is not None, state()["refusal"]
            sol = heed_weak(sol)
        byedge = {p: {m["edge"]: m for m in full[p]} for p in names}
        for q in sol["check"]:
            d.find_element(By.CSS_SELECTOR, f'#check li[data-mark="{q["id"]}"] button').click()
            _wait(d, f"return {js}busy === 0 && {js}selected === {q['id']}")
            d.find_element(By.ID, "delete-mark").click()
            _wait(d, f"return {js}busy === 0 && !{js}state.marks.some(m => m.id === {q['id']})")
            drag(q["photo"], byedge[q["photo"]][q["edge"]], snap=False)
        sol = solve()
        assert sol is not None, state()["refusal"]
        n_marks = len(state()["marks"])
        # every Solve at the page's mark noise field, left at its default
        assert sol["noise_px"] == SOLVE_NOISE_PX == float(
            d.find_element(By.ID, "noise").get_attribute("value"))

    gt = json.loads((folder / "gt.json").read_text())["parameters"]
    free = list(model.parameter_names)
    scratch = np.sqrt(np.mean([((sol["parameters"][n]["value"] - gt[n]) / gt[n]) ** 2 for n in free]))
    ref = solve_facade(model, load_edges(folder / "edges.json", model=model, photographs=names),
                       {p: session.camera.K for p in names}, noise_px=EDGE_NOISE_PX)
    fully = np.sqrt(np.mean([((ref.params[n] - gt[n]) / gt[n]) ** 2 for n in free]))
    print(f"from scratch in the browser: RMS relative parameter error {scratch:.5f}, fully marked "
          f"{fully:.5f}, ratio {scratch / fully:.2f} (bound 1.2), {n_marks} marks, "
          f"{time.monotonic() - t0:.0f} s")
    assert scratch <= 1.2 * fully
    saved = load_edges(tmp_path / "edges.json", model=model, photographs=names)
    assert sum(len(saved.of(p)) for p in names) == n_marks
    assert any(m.proposed for p in names for m in saved.of(p))
