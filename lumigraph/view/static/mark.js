// Marking mode of `lumigraph view` (issue 18 part A): Façade edges on the
// photographs, drawn on a 2-D canvas; the session lives in the server
// (/api/facade/..., lumigraph/view/app.py), which saves every change.
// Image coordinates are OpenCV's: (0, 0) is the centre of the top-left pixel.
"use strict";

(function () {
  const COLOURS = {
    mark: "#00dc00", unassigned: "#ffffff", selected: "#ffd400",
    outlier: "#ff00ff", reprojMarked: "#ff2020", reprojOther: "#3c78ff", proposal: "#ff9a00", detected: "#40d0d0",
  };
  const S = {
    state: null, photo: 0, images: {}, detected: {}, selected: null, selectedProposal: null,
    view: { s: 1, ox: 0, oy: 0 }, drag: null, busy: 0, fitted: {},
  };
  const $ = (id) => document.getElementById(id);
  const canvas = $("photo-canvas");
  const ctx = canvas.getContext("2d");

  // ------------------------------------------------------------ server
  function showError(msg) {
    const e = $("error");
    e.textContent = msg;
    e.hidden = !msg;
  }
  async function api(method, url, body) {
    S.busy += 1;
    try {
      const opts = { method, headers: {} };
      if (body !== undefined) {
        opts.headers["Content-Type"] = "application/json";
        opts.body = JSON.stringify(body);
      }
      const r = await fetch(url, opts);
      const data = await r.json().catch(() => ({ error: `${url}: answer is not JSON (${r.status})` }));
      if (!r.ok || (data && data.error && r.status >= 400)) {
        showError(data.error || `${url}: HTTP ${r.status}`);
        throw new Error(data.error || String(r.status));
      }
      showError("");
      return data;
    } finally {
      S.busy -= 1;
    }
  }
  function status(text) { $("status").textContent = text; }

  async function refresh() {
    S.state = await api("GET", "/api/facade/state");
    if (S.selected !== null && !S.state.marks.some((m) => m.id === S.selected)) S.selected = null;
    renderSide();
    draw();
  }

  // ------------------------------------------------------------ geometry
  const photoName = () => S.state.photos[S.photo].name;
  const toScreen = (x, y) => [S.view.ox + x * S.view.s, S.view.oy + y * S.view.s];
  const toImage = (sx, sy) => [(sx - S.view.ox) / S.view.s, (sy - S.view.oy) / S.view.s];
  function distToSegment(px, py, seg) {  // screen px
    const [ax, ay] = toScreen(seg[0], seg[1]);
    const [bx, by] = toScreen(seg[2], seg[3]);
    const dx = bx - ax, dy = by - ay;
    const L2 = dx * dx + dy * dy || 1e-9;
    const t = Math.max(0, Math.min(1, ((px - ax) * dx + (py - ay) * dy) / L2));
    return Math.hypot(px - ax - t * dx, py - ay - t * dy);
  }
  function fit() {
    const p = S.state.photos[S.photo];
    const s = Math.min(canvas.width / p.width, canvas.height / p.height);
    S.view = { s, ox: (canvas.width - p.width * s) / 2 + 0.5 * s,
               oy: (canvas.height - p.height * s) / 2 + 0.5 * s };
  }
  function eventPoint(ev) {
    const r = canvas.getBoundingClientRect();
    return [(ev.clientX - r.left) * canvas.width / r.width, (ev.clientY - r.top) * canvas.height / r.height];
  }

  // ------------------------------------------------------------ drawing
  function line(seg, colour, width, dash) {
    const [ax, ay] = toScreen(seg[0], seg[1]);
    const [bx, by] = toScreen(seg[2], seg[3]);
    ctx.strokeStyle = colour;
    ctx.lineWidth = width;
    ctx.setLineDash(dash || []);
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
    ctx.setLineDash([]);
  }
  function label(seg, text, colour) {
    const [ax, ay] = toScreen((seg[0] + seg[2]) / 2, (seg[1] + seg[3]) / 2);
    ctx.font = "11px sans-serif";
    ctx.fillStyle = colour;
    ctx.fillText(text, ax + 4, ay - 4);
  }
  function draw() {
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (!S.state) return;
    const name = photoName();
    const img = S.images[name];
    const p = S.state.photos[S.photo];
    if (img && img.complete) {
      ctx.imageSmoothingEnabled = S.view.s < 2;
      ctx.drawImage(img, S.view.ox - 0.5 * S.view.s, S.view.oy - 0.5 * S.view.s,
                    p.width * S.view.s, p.height * S.view.s);
    }
    if ($("show-detected").checked && S.detected[name]) {
      for (const seg of S.detected[name]) line(seg, COLOURS.detected, 1);
    }
    const marks = S.state.marks.filter((m) => m.photo === name);
    const marked = new Set(marks.map((m) => m.edge).filter((e) => e));
    for (const pr of S.state.proposals.filter((q) => q.photo === name)) {
      line(pr.segment, COLOURS.proposal, pr.id === S.selectedProposal ? 3 : 2, [6, 4]);
      label(pr.segment, pr.edge, COLOURS.proposal);
    }
    const sol = S.state.solution;
    const resid = (sol && sol.residual_by_id) || {};
    const outliers = new Set(((sol && sol.outliers) || []).filter((o) => o.photo === name).map((o) => o.edge));
    for (const m of marks) {
      const colour = m.id === S.selected ? COLOURS.selected : !m.edge ? COLOURS.unassigned
        : outliers.has(m.edge) ? COLOURS.outlier : COLOURS.mark;
      line(m.segment, colour, m.id === S.selected ? 3 : 2, m.edge ? [] : [4, 3]);
      // the residual (px) beside every mark; the edge's name where it helps
      const r = resid[m.id];
      const text = [m.id === S.selected || !m.edge ? (m.edge || "(unassigned)") : "",
                    outliers.has(m.edge) ? "mis-marked?" : "",
                    r !== undefined ? `${r.toFixed(2)} px` : ""].filter((t) => t).join(" ");
      label(m.segment, text, colour);
    }
    // the reprojected model on top, thin, so the marks show around it
    const proj = sol && sol.projected && sol.projected[name];
    if (proj) {
      for (const [edge, seg] of Object.entries(proj)) {
        if (!marked.has(edge)) line(seg, edge === S.currentEdge ? COLOURS.selected : COLOURS.reprojOther, 1);
      }
      for (const [edge, seg] of Object.entries(proj)) {
        if (marked.has(edge)) line(seg, COLOURS.reprojMarked, 1.5);
      }
    }
    if (S.drag && S.drag.kind === "draw") {
      line([...S.drag.a, ...S.drag.b], COLOURS.selected, 1, [3, 3]);
    }
  }

  // ------------------------------------------------------------ side panel
  function renderSide() {
    const name = photoName();
    const sel = $("photo-select");
    if (sel.options.length !== S.state.photos.length) {
      sel.innerHTML = "";
      for (const p of S.state.photos) {
        const o = document.createElement("option");
        o.value = p.index;
        o.textContent = p.name;
        sel.appendChild(o);
      }
    }
    sel.value = S.photo;
    const marked = new Set(S.state.marks.filter((m) => m.photo === name).map((m) => m.edge));
    const f = $("edge-filter").value.trim();
    const ul = $("edge-list");
    ul.innerHTML = "";
    for (const e of S.state.edges) {
      if (f && !e.includes(f)) continue;
      const li = document.createElement("li");
      li.textContent = e;
      li.dataset.edge = e;
      if (marked.has(e)) li.classList.add("marked");
      if (e === S.currentEdge) li.classList.add("current");
      li.addEventListener("click", () => chooseEdge(e));
      ul.appendChild(li);
    }
    const pl = $("proposal-list");
    pl.innerHTML = "";
    const mine = S.state.proposals.filter((q) => q.photo === name);
    $("proposal-count").textContent = S.state.proposals.length
      ? `(${mine.length} here, ${S.state.proposals.length} in all)` : "";
    $("accept-all").disabled = S.state.proposals.length === 0;
    for (const q of mine) {
      const li = document.createElement("li");
      li.dataset.proposal = q.id;
      li.textContent = q.edge;
      const ok = document.createElement("button");
      ok.textContent = "accept";
      ok.className = "accept";
      ok.addEventListener("click", (ev) => { ev.stopPropagation(); decide(q.id, "accept"); });
      const no = document.createElement("button");
      no.textContent = "reject";
      no.className = "reject";
      no.addEventListener("click", (ev) => { ev.stopPropagation(); decide(q.id, "reject"); });
      li.append(ok, no);
      li.addEventListener("click", () => { S.selectedProposal = q.id; draw(); });
      pl.appendChild(li);
    }
    $("delete-mark").disabled = S.selected === null;
    renderSolution();
  }
  function renderSolution() {
    const sol = S.state.solution;
    const ref = S.state.refusal;
    const d = $("solution");
    if (!sol && !ref) { d.textContent = "not solved yet"; return; }
    d.innerHTML = "";
    if (ref) renderRefusal(d, ref);
    if (!sol) return;
    const rows = Object.entries(sol.parameters)
      .map(([n, v]) => `<tr><td>${n}</td><td>${v.value.toFixed(4)}</td><td>± ${v.std.toExponential(1)}</td></tr>`)
      .join("");
    const warn = sol.warnings.map((w) => `<li>${w.replace(/</g, "&lt;")}</li>`).join("");
    const out = sol.outliers.map((o) => `<li>mis-marked? ${o.photo} ${o.edge} (${o.rms_px.toFixed(1)} px)</li>`).join("");
    d.insertAdjacentHTML("beforeend",
      (ref ? `<p class="hint">the last solve that succeeded:</p>` : "") +
      `<p id="solve-rms">RMS ${sol.rms_px.toFixed(3)} px, σ ${sol.sigma_px.toFixed(3)} px</p>` +
      `<ul>${warn}${out}</ul><div id="check"></div><div id="weak"></div><table>${rows}</table>`);
    renderCheck(sol.check || []);
    renderWeak(sol.weak || []);
  }
  // the hand-drawn marks farthest from where the other marks put their
  // edges (the server's marks_to_check): where a snap most likely took a line the image shows
  // beside the model's edge; a click opens the photograph with the mark
  // selected, to redraw it (snapping off) if it is not on the edge
  function renderCheck(check) {
    const box = $("check");
    if (!check.length) return;
    const h = document.createElement("p");
    h.className = "weak-head";
    const scored = check.some((q) => typeof q.score === "number");
    h.textContent = (scored
      ? "Check these hand marks (farthest from where the other marks put their edges; "
      : "Check these hand marks (farthest from the solved model; ") +
      "redraw one with snapping off if it is not on its edge, then Solve):";
    box.appendChild(h);
    const ul = document.createElement("ul");
    for (const q of check) {
      const li = document.createElement("li");
      li.dataset.mark = q.id;
      const a = document.createElement("button");
      a.type = "button";
      a.className = "suggest";
      const far = typeof q.score === "number" ? `, ${q.score.toFixed(1)}σ off the others` : "";
      a.textContent = `${q.photo} ${q.edge} (${q.rms_px.toFixed(2)} px${far})`;
      a.addEventListener("click", async () => {
        const i = S.state.photos.findIndex((p) => p.name === q.photo);
        if (i >= 0) await choosePhoto(i);
        S.selected = q.id;
        S.currentEdge = q.edge;
        status(`${q.edge} on ${q.photo} selected: ${q.rms_px.toFixed(2)} px from the solved ` +
               "model; if the mark is off the edge, untick snap and drag it again");
        renderSide();
        draw();
      });
      li.appendChild(a);
      ul.appendChild(li);
    }
    box.appendChild(ul);
  }
  // a click on a suggested edge opens its photograph with the edge highlighted
  function suggestButton(q, title) {
    const a = document.createElement("button");
    a.type = "button";
    a.className = "suggest";
    a.title = title;
    a.textContent = `${q.photo} ${q.edge}` + (q.hidden_in_solve ? " (hidden in the solve?)" : "")
      + (q.seam ? " (a seam: a line only where the blocks differ in colour)" : "");
    a.addEventListener("click", async () => {
      const i = S.state.photos.findIndex((p) => p.name === q.photo);
      if (i >= 0) await choosePhoto(i);
      S.currentEdge = q.edge;
      status(`${q.edge} highlighted on ${q.photo}: drag it if you see it, then click the edge`);
      renderSide();
      draw();
    });
    return a;
  }
  // the last Solve refused (the marks do not constrain some unknowns): its
  // line, and per unknown the unmarked edges that would constrain it (the
  // server's unconstrained_spots), in the weak list's look
  function renderRefusal(d, ref) {
    const box = document.createElement("div");
    box.id = "unconstrained";
    const e = document.createElement("p");
    e.className = "refused";
    e.textContent = `Not solved: ${ref.error}`;
    box.appendChild(e);
    suggestList(box, "Unconstrained", (ref.unconstrained || []).filter((u) => u.suggest.length),
      (u) => `${u.parameter}: `,
      (u, q) => q.constrains
        ? `with this edge and those before it that the solve shows marked: ${u.parameter} ± ` +
          `${q.std_after.toPrecision(2)} (at the solve's noise)`
        : `one of the edges ${u.parameter} needs (with those before it, not yet enough)`);
    d.appendChild(box);
  }
  // a heading and, per parameter, its suggested edges as buttons (the weak list
  // and a refusal's list look the same), in order: each the best with those
  // before it marked, so they are best taken from the left
  function suggestList(box, what, items, label, title) {
    if (!items.length) return;
    const h = document.createElement("p");
    h.className = "weak-head";
    h.textContent = `${what} (mark the edges below where the photograph shows them, then Solve):`;
    box.appendChild(h);
    const ul = document.createElement("ul");
    for (const u of items) {
      const li = document.createElement("li");
      li.dataset.parameter = u.parameter;
      li.textContent = label(u);
      for (const q of u.suggest) li.appendChild(suggestButton(q, title(u, q)));
      ul.appendChild(li);
    }
    box.appendChild(ul);
  }
  // the parameters the marks hold clearly less well than the rest, each with
  // the unmarked edges that would hold it best (the server's weak_spots):
  // a click opens the photograph with that edge highlighted, to mark it there
  function renderWeak(weak) {
    const pct = (v) => `${(100 * v).toFixed(1)} %`;
    suggestList($("weak"), "Weakly constrained", weak,
      (w) => `${w.parameter} ± ${pct(w.rel_std)} (median parameter ± ${pct(w.median_rel_std)}): `,
      (w, q) => `with this edge and those before it that the solve shows marked: ${w.parameter} ± ` +
        `${q.std_after.toPrecision(2)} (now ± ${w.std.toPrecision(2)})`);
  }

  // ------------------------------------------------------------ actions
  async function choosePhoto(i) {
    S.photo = Number(i);
    S.selected = null;
    const name = photoName();
    if (!S.fitted[name]) { fit(); S.fitted[name] = true; }
    if (!S.images[name]) {
      const img = new Image();
      img.onload = () => draw();
      img.src = `/api/facade/photo/${S.photo}`;
      S.images[name] = img;
    }
    renderSide();
    draw();
    if ($("show-detected").checked) loadDetected();
  }
  async function loadDetected() {
    const name = photoName();
    if (!S.detected[name]) {
      S.detected[name] = (await api("GET", `/api/facade/detected/${S.photo}`)).segments;
    }
    draw();
  }
  async function chooseEdge(edge) {
    S.currentEdge = edge;
    if (S.selected !== null) {
      await api("POST", `/api/facade/marks/${S.selected}`, { edge });
      status(`assigned to ${edge}; saved`);
      await refresh();
    } else {
      renderSide();
      draw();
    }
  }
  async function decide(id, what) {
    await api("POST", `/api/facade/proposals/${id}/${what}`);
    status(`proposal ${what}ed`);
    await refresh();
  }

  // ------------------------------------------------------------ mouse
  canvas.addEventListener("contextmenu", (ev) => ev.preventDefault());
  canvas.addEventListener("mousedown", (ev) => {
    const pt = eventPoint(ev);
    if (ev.button === 1 || (ev.button === 0 && ev.shiftKey)) {
      S.drag = { kind: "pan", start: pt, ox: S.view.ox, oy: S.view.oy };
      ev.preventDefault();
    } else if (ev.button === 0) {
      S.drag = { kind: "draw", start: pt, a: toImage(...pt), b: toImage(...pt) };
    }
  });
  window.addEventListener("mousemove", (ev) => {
    if (!S.drag) return;
    const pt = eventPoint(ev);
    if (S.drag.kind === "pan") {
      S.view.ox = S.drag.ox + pt[0] - S.drag.start[0];
      S.view.oy = S.drag.oy + pt[1] - S.drag.start[1];
    } else {
      S.drag.b = toImage(...pt);
    }
    draw();
  });
  window.addEventListener("mouseup", async (ev) => {
    const d = S.drag;
    S.drag = null;
    if (!d || d.kind !== "draw") return;
    const pt = eventPoint(ev);
    const moved = Math.hypot(pt[0] - d.start[0], pt[1] - d.start[1]);
    if (moved >= 5) {
      const p = S.state.photos[S.photo];
      const clip = (v, hi) => Math.max(-0.5, Math.min(hi - 0.5, v));
      const seg = [clip(d.a[0], p.width), clip(d.a[1], p.height), clip(d.b[0], p.width), clip(d.b[1], p.height)];
      try {
        const m = await api("POST", "/api/facade/marks", { photo: photoName(), segment: seg,
                                                           snap: $("snap").checked });
        S.selected = m.id;
        // a snap that moved the drag farther than a careful hand errs is
        // shown as such, with the way back ("keep as drawn")
        S.lastDrag = m.snapped ? { id: m.id, dragged: m.dragged } : null;
        $("unsnap").disabled = !m.snapped;
        // the scatter of the image's steps about the snapped line: a weak or
        // broken edge (relief the model lacks) counts for less in the Solve
        const spread = typeof m.spread_px === "number" ? `, the image's edge scatters ` +
                       `${m.spread_px.toFixed(2)} px about it` : "";
        status(m.snapped ? `segment snapped to a detected line (moved ${m.jump_px.toFixed(1)} px${spread}; ` +
                           "not the line you traced? keep as drawn); click its model edge" :
               $("snap").checked ? "segment drawn (no detected line near); click its model edge" :
                                   "segment drawn; click its model edge");
      } finally {
        await refresh();
      }
    } else {
      click(d.start);
    }
  });
  function click(pt) {
    const name = photoName();
    let best = null, bestD = 8;
    for (const m of S.state.marks.filter((q) => q.photo === name)) {
      const dist = distToSegment(pt[0], pt[1], m.segment);
      if (dist < bestD) { best = m; bestD = dist; }
    }
    if (best) {
      S.selected = best.id;
      S.currentEdge = best.edge;
      renderSide();
      draw();
      return;
    }
    const sol = S.state.solution;
    const proj = sol && sol.projected && sol.projected[name];
    if (proj) {  // a click on a reprojected edge: assign the selected segment to it
      let edge = null;
      bestD = 6;
      for (const [e, seg] of Object.entries(proj)) {
        const dist = distToSegment(pt[0], pt[1], seg);
        if (dist < bestD) { edge = e; bestD = dist; }
      }
      if (edge) { chooseEdge(edge); return; }
    }
    S.selected = null;
    renderSide();
    draw();
  }
  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const pt = eventPoint(ev);
    const [x, y] = toImage(...pt);
    const k = Math.pow(1.2, -Math.sign(ev.deltaY));
    S.view.s = Math.max(0.05, Math.min(64, S.view.s * k));
    S.view.ox = pt[0] - x * S.view.s;
    S.view.oy = pt[1] - y * S.view.s;
    draw();
  }, { passive: false });
  window.addEventListener("keydown", (ev) => {
    if ((ev.key === "Delete" || ev.key === "Backspace") && S.selected !== null &&
        document.activeElement.tagName !== "INPUT") {
      deleteSelected();
    }
  });
  async function deleteSelected() {
    await api("DELETE", `/api/facade/marks/${S.selected}`);
    S.selected = null;
    status("segment deleted; saved");
    await refresh();
  }

  // ------------------------------------------------------------ buttons
  $("photo-select").addEventListener("change", (ev) => choosePhoto(ev.target.value));
  $("edge-filter").addEventListener("input", renderSide);
  $("show-detected").addEventListener("change", () => ($("show-detected").checked ? loadDetected() : draw()));
  $("delete-mark").addEventListener("click", deleteSelected);
  $("solve").addEventListener("click", async () => {
    status("solving…");
    try {
      const sol = await api("POST", "/api/facade/solve", { noise_px: Number($("noise").value) });
      status(`solved: RMS ${sol.rms_px.toFixed(3)} px`);
    } catch (e) {
      status("not solved");
    }
    await refresh();
    if (S.state.refusal && S.state.refusal.unconstrained.some((u) => u.suggest.length)) {
      status("not solved: the Solve panel lists the edges that would constrain what it refused");
    }
  });
  $("propose").addEventListener("click", async () => {
    status("proposing (detecting lines, matching the model)…");
    try {
      const r = await api("POST", "/api/facade/propose", {});
      status(`${r.proposals.length} proposals: accept or reject each`);
    } catch (e) {
      status("nothing proposed");
    }
    await refresh();
  });
  $("resnap").addEventListener("click", async () => {
    status("re-snapping to the solved model…");
    try {
      const r = await api("POST", "/api/facade/resnap", {});
      status(`re-snapped: ${r.moved.length} moved, ${r.flagged.length} flagged (check them), ` +
             `${r.deleted.length} outliers deleted; Solve again`);
    } catch (e) {
      status("not re-snapped");
    }
    await refresh();
  });
  $("unsnap").addEventListener("click", async () => {
    const d = S.lastDrag;
    if (!d) return;
    await api("POST", `/api/facade/marks/${d.id}`, { segment: d.dragged });
    S.lastDrag = null;
    $("unsnap").disabled = true;
    status("segment kept as drawn (not snapped); saved");
    await refresh();
  });
  $("accept-all").addEventListener("click", async () => {
    const r = await api("POST", "/api/facade/proposals/all/accept");
    status(`${r.accepted.length} proposals accepted; saved`);
    await refresh();
  });
  function setMode(mark) {
    $("mark").hidden = !mark;
    $("look").hidden = mark;
    $("mode-mark").classList.toggle("active", mark);
    $("mode-look").classList.toggle("active", !mark);
  }
  $("mode-look").addEventListener("click", () => setMode(false));
  $("mode-mark").addEventListener("click", () => setMode(true));

  // ------------------------------------------------------------ start
  async function start() {
    const mode = await api("GET", "/api/mode");
    if (!mode.facade) { setMode(false); S.ready = true; return; }
    $("mode-mark").hidden = false;
    setMode(true);
    await refresh();
    await choosePhoto(0);
    S.ready = true;
  }
  // for the page's tests (and the curious): the state and the view mapping
  window.lumiMark = {
    get state() { return S.state; },
    get busy() { return S.busy; },
    get ready() { return !!S.ready; },
    get photo() { return S.photo; },
    get selected() { return S.selected; },
    get scale() { return S.view.s; },
    toScreen, toImage, choosePhoto, refresh,
  };
  start().catch((e) => showError(String(e.message || e)));
})();
