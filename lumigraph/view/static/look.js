// Looking mode of `lumigraph view`: the artifact list, each artifact drawn with
// its controls (sliders and choices from /api/look/<id>), the value under the
// cursor (/probe), the .meta.json beside it, and a small WebGL view (orbit by
// dragging, zoom with the wheel) for point clouds and the Façade mesh.
// No library: everything here ships in the package (no network at run time).
//
// Use: LumiLook.mount(element) (done on load for an element with id "look").
"use strict";

(function () {
  const api = (path) => fetch(path).then(async (r) => {
    const body = await r.json().catch(() => ({ error: `${path}: HTTP ${r.status}` }));
    return body;
  });

  function el(tag, attrs, ...kids) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === "class") e.className = v;
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v);
    }
    for (const k of kids) e.append(k instanceof Node ? k : document.createTextNode(String(k)));
    return e;
  }

  function fmt(v) {
    if (v === null || v === undefined) return "unknown";
    if (Array.isArray(v)) return "(" + v.map(fmt).join(", ") + ")";
    if (typeof v === "number") return Math.abs(v) >= 1e4 || (v !== 0 && Math.abs(v) < 1e-3)
      ? v.toExponential(4) : String(+v.toPrecision(6));
    return String(v);
  }

  // One request at a time per channel; a newer one replaces a waiting one
  // (a slider dragged fast asks for the latest picture only).
  function latest(run) {
    let busy = false, next = null;
    const go = (arg) => {
      if (busy) { next = arg; return; }
      busy = true;
      Promise.resolve(run(arg)).finally(() => {
        busy = false;
        if (next !== null) { const a = next; next = null; go(a); }
      });
    };
    return go;
  }

  function mount(root) {
    root.classList.add("lumi-look");
    const list = el("ul", { class: "look-list" });
    const pane = el("div", { class: "look-pane" });
    // an inner box lays the list beside the pane (the page may hide root itself)
    pane.style.flex = "1"; pane.style.minWidth = "0";
    root.replaceChildren(el("div", { class: "look-body", style: "display:flex;gap:1em" },
      el("div", { class: "look-side", style: "min-width:14em;max-width:24em;overflow:auto" },
        el("h2", {}, "Artifacts"), list), pane));
    api("/api/look/list").then((rows) => {
      if (!Array.isArray(rows)) { list.append(el("li", { class: "error" }, rows.error)); return; }
      if (!rows.length) list.append(el("li", {}, "no artifacts given"));
      for (const row of rows) {
        const name = row.path.split("/").slice(-2).join("/");
        const li = el("li", { class: row.error ? "error" : "", title: row.error || row.path },
          el("button", { onclick: () => open(row, pane, li) }, name),
          el("span", { class: "kind" }, " " + (row.kind || "?")));
        list.append(li);
      }
      if (rows.length) open(rows[0], pane, list.firstChild);
    });
  }

  function open(row, pane, li) {
    for (const x of li.parentNode.children) x.classList.remove("current");
    li.classList.add("current");
    pane.replaceChildren(el("p", {}, `opening ${row.path} …`));
    api(`/api/look/${row.id}`).then((d) => show(row, d, pane));
  }

  function show(row, d, pane) {
    const head = el("h2", {}, row.path);
    const error = el("p", { class: "error look-error" }, d.error || "");
    const info = el("p", { class: "look-info" },
      d.kind ? `${d.kind}` + (d.shape ? ` · shape ${d.shape.join("×")}` : "")
        + (d.units ? ` · ${d.units}` : "") : "");
    const meta = el("details", { class: "look-meta" }, el("summary", {}, ".meta.json"),
      el("pre", {}, d.meta ? JSON.stringify(d.meta, null, 2) : "(no .meta.json beside it)"));
    pane.replaceChildren(head, error, info);
    if (d.error) { pane.append(meta); return; }
    if (d.kind === "json") { pane.append(el("pre", { class: "look-json" }, d.text), meta); return; }
    if (d.has_geometry) { pane.append(geometryView(row.id, error), meta); return; }
    const values = {};
    const controls = el("div", { class: "look-controls" });
    const probe = el("p", { class: "look-probe" }, "move the cursor over the picture");
    // fits the pane whatever the page's stylesheet says; the probe maps back
    const img = el("img", { class: "look-image", alt: row.path,
      style: "max-width:100%;height:auto;cursor:crosshair" });
    const query = () => new URLSearchParams(Object.entries(values)
      .filter(([, v]) => v !== "" && v !== null)).toString();
    const draw = latest(() => new Promise((resolve) => {
      const url = `/api/look/${row.id}/image?${query()}`;
      fetch(url).then(async (r) => {
        if (!r.ok) { error.textContent = (await r.json().catch(() => ({}))).error || `HTTP ${r.status}`; resolve(); return; }
        error.textContent = "";
        const blob = await r.blob();
        const old = img.src;
        img.onload = () => { if (old.startsWith("blob:")) URL.revokeObjectURL(old); resolve(); };
        img.onerror = () => resolve();
        img.src = URL.createObjectURL(blob);
      }).catch((e) => { error.textContent = String(e); resolve(); });
    }));
    for (const c of d.controls) {
      values[c.name] = c.default;
      const out = el("output", {}, fmt(c.default === "" ? "—" : c.default));
      let input;
      if (c.kind === "select") {
        input = el("select", {}, ...c.options.map((o) => el("option", { value: o }, o)));
        input.value = c.default;
      } else {
        input = el("input", { type: "range", min: c.min, max: c.max, step: c.step });
        input.value = c.default === "" ? c.max : c.default;
      }
      input.name = c.name;
      input.addEventListener("input", () => {
        values[c.name] = input.value;
        out.textContent = fmt(+input.value || input.value);
        // the depth slider overrides the slope; moving the slope takes it back
        if (c.name === "slope" && "depth" in values) {
          values.depth = "";
          const dOut = controls.querySelector("[data-for=depth] output");
          if (dOut) dOut.textContent = "—";
        }
        draw(null);
      });
      controls.append(el("label", { "data-for": c.name, style: "display:block;margin:0.25em 0" },
        c.label + " ", input, " ", out));
    }
    const probeAt = latest((ev) => {
      const sx = img.naturalWidth / img.clientWidth, scale = d.display_scale || 1;
      const x = (ev.offsetX * sx) / scale, y = (ev.offsetY * sx) / scale;
      if (d.kind === "response") return Promise.resolve();
      return api(`/api/look/${row.id}/probe?x=${x}&y=${y}&${query()}`).then((p) => {
        probe.textContent = p.error ? p.error
          : `(${p.x}, ${p.y}): ${fmt(p.value)} ${p.units || ""}` + (p.length !== undefined
            ? ` · length ${fmt(p.length)} px` : "") + (p.slope !== undefined ? ` · slope ${fmt(p.slope)}` : "");
      });
    });
    img.addEventListener("mousemove", (ev) => probeAt(ev));
    pane.append(controls, el("div", { class: "look-frame" }, img), probe, meta);
    draw(null);
  }

  // ------------------------------------------------------------ 3-D view
  function geometryView(id, error) {
    const canvas = el("canvas", { class: "look-3d", width: 800, height: 600,
      style: "max-width:100%;cursor:grab" });
    const note = el("p", { class: "look-info" }, "drag to orbit, wheel to zoom");
    const box = el("div", {}, canvas, note);
    api(`/api/look/${id}/geometry`).then((g) => {
      if (g.error) { error.textContent = g.error; return; }
      const gl = canvas.getContext("webgl");
      if (!gl) { error.textContent = "this browser has no WebGL"; return; }
      note.textContent = `${g.count} ${g.kind === "mesh" ? "vertices, " + g.faces.length / 3 + " faces" : "points"}`
        + (g.every > 1 ? ` (every ${g.every}th shown)` : "") + " · drag to orbit, wheel to zoom";
      draw3d(gl, canvas, g);
    });
    return box;
  }

  function draw3d(gl, canvas, g) {
    const P = g.positions;
    const n = P.length / 3;
    // centre and size from the median and the 95th-percentile distance of a
    // sample: a few stray points far away must not shrink the model to a dot
    const step = Math.max(1, Math.floor(n / 5000));
    const sample = [];
    for (let i = 0; i < n; i += step) sample.push(i);
    const median = (a) => { const b = a.slice().sort((x, y) => x - y); return b[b.length >> 1]; };
    const c = [0, 1, 2].map((k) => median(sample.map((i) => P[3 * i + k])));
    const dists = sample.map((i) => Math.hypot(P[3 * i] - c[0], P[3 * i + 1] - c[1], P[3 * i + 2] - c[2]));
    dists.sort((x, y) => x - y);
    const r = Math.max(1e-9, g.faces ? dists[dists.length - 1] : dists[Math.floor(0.95 * (dists.length - 1))]);
    let pos, col, mode, count;
    if (g.faces) {  // flat-shaded triangles: each face's vertices with its normal's shade
      const F = g.faces;
      pos = new Float32Array(F.length * 3); col = new Float32Array(F.length * 3);
      for (let f = 0; f < F.length; f += 3) {
        const a = F[f] * 3, b = F[f + 1] * 3, d = F[f + 2] * 3;
        const u = [P[b] - P[a], P[b + 1] - P[a + 1], P[b + 2] - P[a + 2]];
        const v = [P[d] - P[a], P[d + 1] - P[a + 1], P[d + 2] - P[a + 2]];
        const nn = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        const len = Math.hypot(...nn) || 1;
        const shade = 0.35 + 0.65 * Math.abs((nn[0] * 0.3 + nn[1] * 0.5 + nn[2] * 0.8) / len / 1.0);
        for (let k = 0; k < 3; k++) {
          const s = F[f + k] * 3;
          pos.set([P[s] - c[0], P[s + 1] - c[1], P[s + 2] - c[2]], (f + k) * 3);
          col.set([0.85 * shade, 0.8 * shade, 0.7 * shade], (f + k) * 3);
        }
      }
      mode = gl.TRIANGLES; count = F.length;
    } else {
      pos = new Float32Array(P.length); col = new Float32Array(P.length);
      for (let i = 0; i < P.length; i++) pos[i] = P[i] - c[i % 3];
      for (let i = 0; i < P.length; i++) col[i] = g.colors ? g.colors[i] / 255 : 0.9;
      mode = gl.POINTS; count = n;
    }
    const vs = `attribute vec3 p; attribute vec3 c; uniform mat4 m; varying vec3 vc;
      void main() { gl_Position = m * vec4(p, 1.0); gl_PointSize = 2.0; vc = c; }`;
    const fs = `precision mediump float; varying vec3 vc; void main() { gl_FragColor = vec4(vc, 1.0); }`;
    const prog = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s); gl.attachShader(prog, s);
    }
    gl.linkProgram(prog); gl.useProgram(prog);
    for (const [name, data] of [["p", pos], ["c", col]]) {
      const buf = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
      const loc = gl.getAttribLocation(prog, name); gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
    }
    const m = gl.getUniformLocation(prog, "m");
    // A mesh (the Façade model) has z up: orbit about z, seen from a little above.
    // A point cloud is in camera coordinates (x right, y down, z forward): start
    // from the camera (pitch pi turns y down and z away) and orbit about y.
    const mesh = !!g.faces;
    let yaw = mesh ? 0.5 : 0, pitch = mesh ? -1.2 : Math.PI, dist = (mesh ? 3 : 2) * r;
    const rx = (a) => [1, 0, 0, 0, Math.cos(a), -Math.sin(a), 0, Math.sin(a), Math.cos(a)];
    const ry = (a) => [Math.cos(a), 0, Math.sin(a), 0, 1, 0, -Math.sin(a), 0, Math.cos(a)];
    const rz = (a) => [Math.cos(a), -Math.sin(a), 0, Math.sin(a), Math.cos(a), 0, 0, 0, 1];
    const mul3 = (A, B) => [0, 1, 2].flatMap((i) => [0, 1, 2].map((j) =>
      A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j]));
    const render = () => {
      const Q = mul3(rx(pitch), mesh ? rz(yaw) : ry(yaw));  // row-major 3x3
      // column-major 4x4: the rotation, then the camera dist away along -z
      const R = [Q[0], Q[3], Q[6], 0, Q[1], Q[4], Q[7], 0, Q[2], Q[5], Q[8], 0, 0, 0, -dist, 1];
      const f = 1 / Math.tan(0.4), a = canvas.width / canvas.height, near = dist / 1000, far = dist + 20 * r;
      const Pm = [f / a, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0];
      const M = new Float32Array(16);  // Pm * R, column-major
      for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
        let s = 0; for (let k = 0; k < 4; k++) s += Pm[k * 4 + i] * R[j * 4 + k]; M[j * 4 + i] = s;
      }
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.clearColor(0.1, 0.1, 0.12, 1); gl.enable(gl.DEPTH_TEST);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.uniformMatrix4fv(m, false, M); gl.drawArrays(mode, 0, count);
    };
    let drag = null;
    canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; });
    window.addEventListener("mouseup", () => { drag = null; });
    canvas.addEventListener("mousemove", (e) => {
      if (!drag) return;
      yaw += (e.clientX - drag[0]) * 0.01; pitch += (e.clientY - drag[1]) * 0.01;
      drag = [e.clientX, e.clientY]; render();
    });
    canvas.addEventListener("wheel", (e) => {
      e.preventDefault(); dist *= Math.exp(e.deltaY * 0.001); render();
    }, { passive: false });
    render();
  }

  window.LumiLook = { mount };
  document.addEventListener("DOMContentLoaded", () => {
    const root = document.getElementById("look");
    if (root) mount(root);
  });
})();
