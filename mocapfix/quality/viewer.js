// mocapfix view: plays the layers of the JSON in #mocapfix-data on a Canvas 2D
// (see mocapfix/quality/viewer.py for the data layout and why it is hand-written).
// Names and labels reach the page only through textContent.
(function () {
  "use strict";
  const data = JSON.parse(document.getElementById("mocapfix-data").textContent);
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const $ = (id) => document.getElementById(id);
  const BG = "#16191d", GRID = "#3a4048", AXIS = "#59616c", BEFORE = "#8a9099";
  const PALETTE = ["#4fc3f7", "#ffb74d", "#aed581", "#ce93d8", "#f06292", "#fff176"];
  const FILLED = "#ff4fd8", CHANGED = "#b388ff", DELETED = "#ff1744";
  const FLAGS = ["#ffee58", "#ff7043", "#26c6da", "#8d6e63", "#ec407a", "#9ccc65"];  // by step
  const CHANGE_M = 0.001;           // a sample moved by less than 1 mm is never marked
  const MISSING = -32768;

  function bytes(text) {
    const bin = atob(text), out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out.buffer;
  }

  // -- decode: int16 codes, a "before" rebuilt from its base, then metres ---------------
  const layers = data.layers.map((L, n) => Object.assign({}, L, {
    index: n, visible: true, codes: L.positions !== undefined ? new Int16Array(bytes(L.positions)) : null,
  }));
  for (const L of layers) {
    if (L.codes) continue;
    L.codes = layers[L.base].codes.slice();
    if (L.delta) {
      const d = new Int8Array(bytes(L.delta));
      for (let i = 0; i < d.length; i++) if (d[i]) L.codes[i] += d[i];
    }
    const idx = new Uint32Array(bytes(L.diffIndex)), val = new Int16Array(bytes(L.diffValues));
    for (let k = 0; k < idx.length; k++) {
      const at = idx[k] * 3;
      L.codes[at] = val[3 * k]; L.codes[at + 1] = val[3 * k + 1]; L.codes[at + 2] = val[3 * k + 2];
    }
  }
  for (const L of layers) {
    const c = L.codes, xyz = new Float32Array(c.length);
    for (let i = 0; i < c.length; i += 3) {
      if (c[i] === MISSING) { xyz[i] = xyz[i + 1] = xyz[i + 2] = NaN; continue; }
      for (let a = 0; a < 3; a++) xyz[i + a] = L.origin[a] + (c[i + a] + 32767) * L.step[a];
    }
    L.xyz = xyz;
    L.conf = L.confidence ? new Uint8Array(bytes(L.confidence)) : null;
    L.joints = L.names.length;
    L.color = L.role === "before" ? BEFORE : PALETTE[n_of(L)];
  }
  function n_of(L) { return layers.filter((o) => o.role !== "before" && o.index < L.index).length % PALETTE.length; }

  // -- marks of an overlay: filled (with its error), moved, deleted ---------------------
  const counts = { filled: 0, changed: 0, deleted: 0 };
  let changeM = CHANGE_M;
  for (const A of layers) {
    if (A.role !== "after" || !layers[A.index - 1] || layers[A.index - 1].role !== "before") continue;
    const B = layers[A.index - 1];
    A.mark = new Uint8Array(A.frames * A.joints);
    B.mark = new Uint8Array(B.frames * B.joints);
    A.error = new Float32Array(A.frames * A.joints).fill(NaN);
    A.flag = new Uint8Array(A.frames * A.joints);            // 0: none; k + 1: flagKinds[k]
    for (const [j, start, length, kind] of A.flags) {
      const lo = Math.ceil(start / A.stride), hi = Math.floor((start + length - 1) / A.stride);
      for (let f = Math.max(lo, 0); f <= Math.min(hi, A.frames - 1); f++) A.flag[f * A.joints + j] = kind + 1;
    }
    B.flag = A.flag; B.flagKinds = A.flagKinds;
    // a filter moves every sample a little: mark only what moved well beyond the typical
    // move (3x the median move of the samples present before and after), never under 1 mm
    const moved = new Float32Array(A.mark.length), some = [];
    const every = Math.max(1, Math.floor(A.mark.length / 50000));
    for (let s = 0; s < A.mark.length; s++) {
      const i = 3 * s, gb = B.codes[i] === MISSING, ga = A.codes[i] === MISSING;
      if (gb && !ga) { A.mark[s] = 1; counts.filled++; }
      else if (!gb && ga) { B.mark[s] = 3; counts.deleted++; }
      else if (!gb) {
        moved[s] = Math.hypot(A.xyz[i] - B.xyz[i], A.xyz[i + 1] - B.xyz[i + 1], A.xyz[i + 2] - B.xyz[i + 2]);
        if (s % every === 0) some.push(moved[s]);
      }
    }
    some.sort((a, b) => a - b);
    changeM = Math.max(CHANGE_M, 3 * (some.length ? some[some.length >> 1] : 0));
    for (let s = 0; s < moved.length; s++) {
      if (moved[s] >= changeM || (A.flag[s] && moved[s] > 0)) { A.mark[s] = 2; counts.changed++; }
    }
    for (const [j, start, length, err] of A.fills) {
      const lo = Math.ceil(start / A.stride), hi = Math.floor((start + length - 1) / A.stride);
      for (let f = Math.max(lo, 0); f <= Math.min(hi, A.frames - 1); f++) {
        if (A.mark[f * A.joints + j] === 1) A.error[f * A.joints + j] = err === null ? -1 : err;
      }
    }
  }
  function errorColor(mm) {           // 1 mm green .. 30 mm red, log scale
    const x = Math.min(1, Math.max(0, Math.log(Math.max(mm, 1)) / Math.log(30)));
    return "hsl(" + Math.round(130 * (1 - x)) + ",90%,50%)";
  }

  // -- the scene in "view" coordinates (X, Y on the ground, Z up), camera ---------------
  let up = data.up;
  function viewOf(p, a) {            // world (a, a+1, a+2) -> [X, Y, Z] with Z = world[up]
    const x = p[a], y = p[a + 1], z = p[a + 2];
    if (up === 2) return [x, y, z];
    if (up === 1) return [x, -z, y];
    return [y, z, x];
  }
  const cam = { yaw: -0.7, pitch: 0.3, dist: 5, fov: 40 * Math.PI / 180, t: [0, 0, 0] };
  const scene = { lo: [0, 0, 0], hi: [1, 1, 1], radius: 1, ground: 0, body: 1 };
  function frameScene() {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const L of layers) {
      for (let i = 0; i < L.xyz.length; i += 3 * Math.max(1, Math.floor(L.xyz.length / 60000))) {
        if (Number.isNaN(L.xyz[i])) continue;
        const v = viewOf(L.xyz, i);
        for (let a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], v[a]); hi[a] = Math.max(hi[a], v[a]); }
      }
    }
    if (!Number.isFinite(lo[0])) { lo.fill(-1); hi.fill(1); }
    scene.lo = lo; scene.hi = hi; scene.ground = lo[2];
    scene.radius = Math.max(0.5, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2);
    cam.t = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
    cam.dist = scene.radius * 3;
    // the size of the body: median over frames of the half-diagonal of its points
    const sizes = [], J = main.joints;
    for (let f = 0; f < main.frames; f += Math.max(1, Math.floor(main.frames / 200))) {
      const l = [Infinity, Infinity, Infinity], h = [-Infinity, -Infinity, -Infinity];
      for (let j = 0; j < J; j++) {
        const i = (f * J + j) * 3;
        if (Number.isNaN(main.xyz[i])) continue;
        for (let a = 0; a < 3; a++) { l[a] = Math.min(l[a], main.xyz[i + a]); h[a] = Math.max(h[a], main.xyz[i + a]); }
      }
      if (Number.isFinite(l[0])) sizes.push(Math.hypot(h[0] - l[0], h[1] - l[1], h[2] - l[2]) / 2);
    }
    sizes.sort((a, b) => a - b);
    scene.body = Math.max(0.25, sizes.length ? sizes[sizes.length >> 1] : scene.radius);
    if (follow) cam.dist = scene.body * 4;
  }
  function centre() {               // where the camera looks when following: the body
    const L = layers.find((o) => o.visible && o.role !== "before") || layers.find((o) => o.visible);
    if (!L) return;
    const f = frameOf(L), J = L.joints, c = [0, 0, 0];
    let n = 0;
    for (let j = 0; j < J; j++) {
      const i = (f * J + j) * 3;
      if (Number.isNaN(L.xyz[i])) continue;
      const v = viewOf(L.xyz, i);
      c[0] += v[0]; c[1] += v[1]; c[2] += v[2]; n++;
    }
    if (n) cam.t = [c[0] / n, c[1] / n, c[2] / n];
  }
  let W = 0, H = 0, focal = 1, cy = 0, sy = 0, cp = 0, sp = 0;
  function setupCamera() {
    focal = H / 2 / Math.tan(cam.fov / 2);
    cy = Math.cos(cam.yaw); sy = Math.sin(cam.yaw); cp = Math.cos(cam.pitch); sp = Math.sin(cam.pitch);
  }
  const out = [0, 0, 0];
  function project(X, Y, Z) {        // -> out = [px, py, depth]; depth <= near: behind
    const dx = X - cam.t[0], dy = Y - cam.t[1], dz = Z - cam.t[2];
    const x1 = cy * dx + sy * dy, y1 = -sy * dx + cy * dy;
    const depth = y1 * cp - dz * sp + cam.dist, v = y1 * sp + dz * cp;
    out[0] = W / 2 + focal * x1 / depth; out[1] = H / 2 - focal * v / depth; out[2] = depth;
    return out;
  }
  const NEAR = 0.05;

  // -- time ---------------------------------------------------------------------------
  const main = layers.reduce((a, b) => (b.frames / b.fps > a.frames / a.fps ? b : a), layers[0]);
  const duration = Math.max(0, (main.frames - 1) / main.fps);
  let time = 0, playing = true, speed = 1, follow = false;
  const scrub = $("scrub");
  scrub.max = String(Math.max(0, main.frames - 1));
  function frameOf(L) { return Math.max(0, Math.min(L.frames - 1, Math.round(time * L.fps))); }

  // -- drawing ------------------------------------------------------------------------
  let picks = [], drawn = [];
  function gridStep(r) {
    const raw = r / 4, p = Math.pow(10, Math.floor(Math.log10(raw)));
    return [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw);
  }
  function line3(a, b, segments) {
    for (let k = 0; k < segments; k++) {
      const u0 = k / segments, u1 = (k + 1) / segments;
      const p0 = project(a[0] + (b[0] - a[0]) * u0, a[1] + (b[1] - a[1]) * u0, a[2] + (b[2] - a[2]) * u0).slice();
      const p1 = project(a[0] + (b[0] - a[0]) * u1, a[1] + (b[1] - a[1]) * u1, a[2] + (b[2] - a[2]) * u1);
      if (p0[2] <= NEAR || p1[2] <= NEAR) continue;
      ctx.moveTo(p0[0], p0[1]); ctx.lineTo(p1[0], p1[1]);
    }
  }
  function drawGrid() {
    const step = gridStep(scene.radius * 1.5), cx = cam.t[0], cyy = cam.t[1], z = scene.ground;
    const n = 6, x0 = Math.round(cx / step) * step, y0 = Math.round(cyy / step) * step;
    ctx.lineWidth = 1;
    ctx.strokeStyle = GRID;
    ctx.beginPath();
    for (let k = -n; k <= n; k++) {
      line3([x0 + k * step, y0 - n * step, z], [x0 + k * step, y0 + n * step, z], 12);
      line3([x0 - n * step, y0 + k * step, z], [x0 + n * step, y0 + k * step, z], 12);
    }
    ctx.stroke();
    ctx.strokeStyle = AXIS;
    ctx.beginPath();
    line3([x0, y0, z], [x0 + step, y0, z], 1); line3([x0, y0, z], [x0, y0 + step, z], 1);
    ctx.stroke();
  }
  function draw() {
    if (follow) centre();
    setupCamera();
    ctx.fillStyle = BG;
    ctx.fillRect(0, 0, W, H);
    drawGrid();
    picks = []; drawn = [];
    for (const L of layers) {
      drawn.push(0);
      if (!L.visible) continue;
      const f = frameOf(L), J = L.joints, base = f * J * 3;
      const sx = new Float32Array(J), syy = new Float32Array(J), ok = new Uint8Array(J);
      for (let j = 0; j < J; j++) {
        const i = base + 3 * j;
        if (Number.isNaN(L.xyz[i])) continue;
        const v = viewOf(L.xyz, i), p = project(v[0], v[1], v[2]);
        if (p[2] <= NEAR) continue;
        sx[j] = p[0]; syy[j] = p[1]; ok[j] = 1;
      }
      ctx.strokeStyle = L.color;
      ctx.globalAlpha = L.role === "before" ? 0.55 : 0.9;
      ctx.lineWidth = 2;
      ctx.beginPath();
      for (const [a, b] of L.bones) {
        if (ok[a] && ok[b]) { ctx.moveTo(sx[a], syy[a]); ctx.lineTo(sx[b], syy[b]); }
      }
      ctx.stroke();
      ctx.globalAlpha = 1;
      for (let j = 0; j < J; j++) {
        if (!ok[j]) continue;
        const s = f * J + j, m = L.mark ? L.mark[s] : 0;
        let color = L.color, r = L.role === "before" ? 6 : 3.5;
        if (m === 1) { const e = L.error[s]; color = e >= 0 ? errorColor(e) : FILLED; r = 5; }
        else if (m === 2) { color = CHANGED; r = 4.5; }
        else if (m === 3) { color = DELETED; r = 5; }
        if (L.flag && L.flag[s] && (m === 2 || m === 3)) color = FLAGS[(L.flag[s] - 1) % FLAGS.length];
        // a "before" sample is a ring around its "after" dot; so is a low-confidence one
        const ring = m === 0 && (L.role === "before" || (L.conf && L.conf[s] < 255));
        ctx.beginPath();
        ctx.arc(sx[j], syy[j], r, 0, 2 * Math.PI);
        if (ring) { ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.stroke(); }
        else { ctx.fillStyle = color; ctx.fill(); }
        picks.push([sx[j], syy[j], L.index, j, s]);
        drawn[drawn.length - 1]++;
      }
    }
    const f = frameOf(main);
    tell(f * main.stride);
    scrub.value = String(f);
    $("time").textContent = time.toFixed(2) + " s  frame " + (f * main.stride) + "/" + ((main.frames - 1) * main.stride);
  }

  // -- legend, controls ---------------------------------------------------------------
  function legendRow(color, text, layer) {
    const row = document.createElement("label"), dot = document.createElement("span");
    if (layer) {
      const box = document.createElement("input");
      box.type = "checkbox"; box.checked = true;
      box.addEventListener("change", () => { layer.visible = box.checked; draw(); });
      row.appendChild(box);
    }
    dot.className = "swatch";
    if (color === "ring") dot.style.border = "1.5px solid #e6e8eb"; else dot.style.background = color;
    row.appendChild(dot);
    row.appendChild(document.createTextNode(text));
    $("legend").appendChild(row);
  }
  for (const L of layers) legendRow(L.color, L.label, L);
  if (layers.some((L) => L.conf)) legendRow("ring", "inferred / low confidence");
  const overlay = layers.some((L) => L.mark);
  if (overlay) {
    legendRow(errorColor(1), "filled, est. error 1 mm");
    legendRow(errorColor(30), "filled, est. error ≥ 30 mm");
    legendRow(FILLED, "filled (no estimate)");
    legendRow(CHANGED, "moved ≥ " + (changeM * 1000).toFixed(1) + " mm");
    legendRow(DELETED, "deleted (before)");
    for (const L of layers) {
      if (L.role === "after") L.flagKinds.forEach((k, n) => legendRow(FLAGS[n % FLAGS.length], "judged wrong by " + k));
    }
  }
  const notes = [];
  if (data.stride > 1) notes.push("every " + data.stride + "th frame shown (size budget " + (data.budget / 1e6).toFixed(1) + " MB)");
  if (overlay) notes.push(counts.filled + " filled, " + counts.changed + " moved, " + counts.deleted + " deleted samples");
  notes.push("drag: orbit · shift/right-drag: pan · wheel: zoom · space: play");
  $("note").textContent = notes.join("\n");
  $("up").value = String(up);

  $("play").addEventListener("click", () => setPlaying(!playing));
  function setPlaying(on) { playing = on; $("play").textContent = on ? "Pause" : "Play"; last = null; }
  scrub.addEventListener("input", () => { time = Number(scrub.value) / main.fps; draw(); });
  $("speed").addEventListener("change", (e) => { speed = Number(e.target.value); });
  function setFollow(on) {
    follow = on; $("follow").checked = on;
    if (on) cam.dist = scene.body * 4; else frameScene();
    draw();
  }
  $("follow").addEventListener("change", (e) => setFollow(e.target.checked));
  $("up").addEventListener("change", (e) => { up = Number(e.target.value); frameScene(); draw(); });
  window.addEventListener("keydown", (e) => {
    if (e.target.tagName === "INPUT" && e.target.type !== "range") return;
    if (e.key === " ") { setPlaying(!playing); e.preventDefault(); }
    if (e.key === "ArrowRight" || e.key === "ArrowLeft") {
      setPlaying(false);
      time = Math.min(duration, Math.max(0, time + (e.key === "ArrowRight" ? 1 : -1) / main.fps));
      draw(); e.preventDefault();
    }
  });

  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("mousedown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
    canvas.classList.add("dragging");
  });
  window.addEventListener("mouseup", () => { drag = null; canvas.classList.remove("dragging"); });
  window.addEventListener("mousemove", (e) => {
    if (drag) {
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) {
        if (follow) setFollow(false);
        const k = cam.dist / focal;
        cam.t[0] -= k * (cy * dx - sy * sp * dy) ;
        cam.t[1] -= k * (sy * dx + cy * sp * dy);
        cam.t[2] += k * cp * dy;
      } else {
        cam.yaw -= dx * 0.01;
        cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + dy * 0.01));
      }
      draw();
    }
    hover(e.clientX, e.clientY);
  });
  canvas.addEventListener("wheel", (e) => {
    cam.dist = Math.max(0.05, cam.dist * Math.exp(e.deltaY * 0.001)); draw(); e.preventDefault();
  }, { passive: false });
  canvas.addEventListener("dblclick", () => { frameScene(); draw(); });   // reset the view

  const tip = $("tip");
  function describe(p) {
    const L = layers[p[2]], name = L.names[p[3]];
    const lines = [name.length > 300 ? name.slice(0, 300) + "…" : name, L.label];
    const m = L.mark ? L.mark[p[4]] : 0;
    if (m === 1) lines.push(L.error[p[4]] >= 0 ? "filled, est. error " + L.error[p[4]].toFixed(1) + " mm" : "filled");
    if (m === 2) lines.push("moved by the cleaner");
    if (m === 3) lines.push("deleted by the cleaner");
    if (L.flag && L.flag[p[4]]) lines.push("judged wrong by " + L.flagKinds[L.flag[p[4]] - 1]);
    if (L.conf && L.conf[p[4]] < 255) lines.push("confidence " + (L.conf[p[4]] / 255).toFixed(2));
    return lines.join("\n");
  }
  function hover(x, y) {
    const r = canvas.getBoundingClientRect();
    let best = null, bestD = 63;
    for (const p of picks) {
      const d = (p[0] + r.left - x) ** 2 + (p[1] + r.top - y) ** 2;
      if (d <= bestD) { bestD = d; best = p; }      // ties: the later layer (the "after")
    }
    if (!best) { tip.hidden = true; return; }
    tip.textContent = describe(best);
    tip.style.left = (x + 12) + "px"; tip.style.top = (y + 12) + "px";
    tip.hidden = false;
  }

  function resize() {
    W = window.innerWidth; H = Math.max(100, window.innerHeight - $("bar").offsetHeight);
    const dpr = window.devicePixelRatio || 1;
    canvas.width = Math.round(W * dpr); canvas.height = Math.round(H * dpr);
    canvas.style.width = W + "px"; canvas.style.height = H + "px";
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    draw();
  }
  window.addEventListener("resize", resize);

  // -- the page around an embedded viewer (the clean report): the frame both ways ------
  // {mocapfix: "frame", frame: N} (N in the file's frames) and nothing else; the report
  // draws its time cursor from ours and sends the frame of a plot clicked.
  const host = window.parent !== window ? window.parent : null;
  let told = -1;
  function tell(frame) {
    if (!host || frame === told) return;
    told = frame;
    // "*": this sandboxed document has no origin to name, and a frame number is no secret
    host.postMessage({ mocapfix: "frame", frame: frame }, "*");
  }
  window.addEventListener("message", (e) => {
    const m = e.data;
    if (!host || e.source !== host || typeof m !== "object" || m === null || m.mocapfix !== "frame"
        || !Number.isInteger(m.frame) || m.frame < 0 || Object.keys(m).length !== 2) return;
    setPlaying(false);
    time = Math.min(duration, m.frame / main.stride / main.fps);
    draw();
  });

  let last = null;
  function tick(now) {
    if (playing) {
      if (last !== null) {
        time += (now - last) / 1000 * speed;
        if (time > duration) time = duration > 0 ? time % duration : 0;
      }
      last = now;
      draw();
    }
    requestAnimationFrame(tick);
  }

  const start = /frame=(\d+)/.exec(location.hash);   // view.html#frame=120: paused there
  if (start) { playing = false; $("play").textContent = "Play"; time = Number(start[1]) / main.stride / main.fps; }
  frameScene();
  // a take that travels (a walk across the room) is followed; one in place is framed whole
  if (scene.radius > 3 * scene.body) { follow = true; $("follow").checked = true; cam.dist = scene.body * 4; }
  resize();
  requestAnimationFrame(tick);
  // for tests and scripts: the state and a way to hold a frame
  window.mocapfixView = {
    layers, counts, main,
    pause() { setPlaying(false); },
    setFrame(f) { setPlaying(false); time = f / main.fps; draw(); },
    drawn() { return drawn.slice(); },
    picks() { return picks.map((p) => p.slice()); },
    describe,
  };
  document.body.setAttribute("data-ready", performance.now().toFixed(1));
})();
