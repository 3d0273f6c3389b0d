// The pattern page: controls -> POST /api/pattern -> four Plotly pictures and the CV.
//
// The pictures always answer the controls shown, or say that they do not: a slider's moves are answered by
// drafts (the two pilot runs), its release (pointer, key or change) and a short pause by the settled answer;
// a typed value is checked before anything is sent (an empty or out-of-range field is never sent); a newer
// request aborts the one in flight (the server stops it too), except that drafts wait for the draft in flight;
// typing in a field, and loading a scene, abort it too (its answer would not answer what is shown);
// while an answer is computing, and after an error, the pictures are greyed out and labelled.
"use strict";
const $ = (id) => document.getElementById(id);
const SETTLE_MS = 350;  // a pause this long after the last move settles, as a release does
const state = { scene: null, yaml: null, info: null, precise: null, version: "", seq: 0, inflight: null,
  waiting: null, timer: null, shownKey: null, shownMode: null };
window.__requests = [];  // what the browser test reads: [{seq, mode, started, ended, outcome}]
const FONT = { size: 12 };
const CONFIG = { displayModeBar: false, responsive: true };  // drag zooms, a double click resets
const LAYOUT = { margin: { l: 56, r: 12, t: 8, b: 46 }, font: FONT, showlegend: true,
  legend: { orientation: "h", x: 0, y: 1.02, xanchor: "left", yanchor: "bottom", font: FONT },
  xaxis: { automargin: true }, yaxis: { automargin: true } };
const LEGEND_ROWS_PX = 22;  // the legend sits above the plot area: the top margin grows with its rows

function post(path, body, signal) {
  return api(path, { method: "POST", signal, headers: { "Content-Type": "application/json" },
    body: JSON.stringify(body) });
}

function pageWords(message) {  // the server's message in the page's words: its controls, not scene keys or flags
  const words = { "--set ": "", "--precision": "precision", "--max-runs": "runs" };
  for (const c of (state.info ? state.info.controls : [])) words[c.key] = c.label;
  return inPageWords(message, words);
}

function problems() {  // the controls whose field cannot be sent: empty, not a number, or outside its range
  const out = [];
  for (const c of state.info.controls) {
    const field = $("c" + c.i), text = field.value.trim(), value = Number(text);
    const bad = text === "" || !Number.isFinite(value) || value < c.min || value > c.max;
    field.setAttribute("aria-invalid", bad ? "true" : "false");
    if (bad) out.push(`${c.label}: enter a number in [${c.min}, ${c.max}] ${c.unit}`);
  }
  return out;
}

function request(mode) {
  const sets = {};
  for (const c of state.info.controls) {
    const value = Number($("c" + c.i).value);
    if (c.index === null) sets[c.key] = value;
    else (sets[c.key] = sets[c.key] || [])[c.index] = value;
  }
  if ($("fertilizer").value !== state.info.fertilizer) sets.fertilizer = $("fertilizer").value;
  const body = state.yaml !== null ? { yaml: state.yaml, set: sets } : { scene: state.scene, set: sets };
  if (mode === "draft") body.max_runs = 2;  // the pilot runs: a picture at once while a slider moves
  if (mode === "precise") Object.assign(body, state.precise);
  return body;
}

function stale(text) {  // grey the pictures out and say why; null: they answer the controls shown
  $("figures").classList.toggle("stale", text !== null);
  $("stale").hidden = text === null;
  $("stale").textContent = text || "";
  document.body.dataset.stale = text === null ? "no" : "yes";
}

function supersede() {  // the controls shown are no longer what is computing: stop it, drop what waits
  clearTimeout(state.timer);
  state.waiting = null;
  if (state.inflight) {
    state.inflight.abort();
    state.inflight = null;  // its answer, or its abort, changes nothing on the page
    $("status").textContent = "";
  }
}

function run(mode) {  // the controls changed (mode draft) or settled (full, precise)
  clearTimeout(state.timer);
  const bad = problems();
  if (bad.length) {
    supersede();
    $("error").textContent = bad.join("\n");
    stale("not updated: " + bad[0]);
    return;
  }
  const body = request(mode), key = JSON.stringify(body);
  if (mode === "draft") state.timer = setTimeout(() => run("full"), SETTLE_MS);
  if (key === state.shownKey && !state.inflight) { stale(null); return; }  // shown already
  if (state.inflight && state.inflight.key === key) return;  // being computed
  if (state.inflight && state.inflight.mode === "draft" && mode === "draft") {  // drafts take turns
    state.waiting = { mode, body, key };
    return;
  }
  state.waiting = null;
  send(mode, body, key);
}

async function send(mode, body, key) {
  if (state.inflight) state.inflight.abort();  // superseded: the server stops it as well
  const controller = new AbortController();
  const entry = { seq: ++state.seq, mode, started: performance.now(), ended: null, outcome: null };
  window.__requests.push(entry);
  const mine = { key, mode, abort: () => controller.abort() };
  state.inflight = mine;
  $("status").textContent = mode === "precise" ? "computing the precise estimate..." : "computing...";
  stale(mode === "precise" ? "computing the precise estimate..." : "computing...");
  try {
    const data = await post("/api/pattern", body, controller.signal);
    if (state.inflight !== mine) { entry.outcome = "superseded"; return; }
    entry.outcome = "shown";
    $("error").textContent = "";
    state.shownKey = key; state.shownMode = mode;
    show(data, mode, body);
  } catch (err) {
    entry.outcome = err.name === "AbortError" ? "aborted" : "error";
    if (state.inflight === mine) {
      $("error").textContent = pageWords(err.message);
      stale("not updated: " + pageWords(err.message));
    }
  } finally {
    entry.ended = performance.now();
    if (state.inflight === mine) {
      state.inflight = null;
      $("status").textContent = "";
      const next = state.waiting;
      state.waiting = null;
      if (next) send(next.mode, next.body, next.key);
      else if (entry.outcome === "shown") stale(null);
    }
  }
}

function show(data, mode, body) {
  const m = data.metrics, p = data.plot;
  $("cv").textContent = data.cv_text + " at " + m.target_swath_m + " m";
  $("summary").innerHTML = "";
  const over = m.cv_percent_at_target === null || m.cv_percent_at_target > m.cv_threshold_percent;
  const rows = [["effective swath", data.swath_text, over],
    ["runs", m.runs + " of " + m.granules + " granules (" + (mode === "draft" ? "draft: the pilot runs" :
      "standard error " + m.precision_percent + " pp asked, " + (m.precision_met ? "reached" : "not reached")) + ")"],
    ["model", m.model], ["driving", m.driving]];
  for (const [k, v, warn] of rows) {
    const div = document.createElement("div");
    div.textContent = k + ": " + v;
    if (warn) div.className = "warning";
    $("summary").appendChild(div);
  }
  drawPlan(p.plan); drawPattern(p.trays, m); drawCurve(m); drawLanding(p.landing, m);
  record(data, body);
  window.__shown = { metrics: m, set: body.set, scene: body.scene || null, mode };
  document.body.dataset.rev = String(state.seq);
  document.body.dataset.mode = mode;
}

function record(data, body) {  // what a print of the page carries (print only)
  const m = data.metrics;
  const settings = state.info.controls.map((c) => `<tr><td>${escaped(c.label)}</td><td>` +
    `${escaped(String($("c" + c.i).value))} ${escaped(c.unit)}</td></tr>`).join("");
  $("record").innerHTML = `<h2>spreadgym: scene ${escaped(state.info.name)}, ${escaped($("fertilizer").value)}</h2>` +
    `<table><tr><th>setting</th><th>value</th></tr>${settings}` +
    `<tr><td>driving</td><td>${escaped(m.driving)}</td></tr></table>` +
    `<p>CV at ${m.target_swath_m} m: ${escaped(data.cv_text)} (${m.runs} runs of ${m.granules} granules, ` +
    `${escaped(m.model)} model); effective swath: ${escaped(data.swath_text)}</p>` +
    `<p>printed ${new Date().toISOString().slice(0, 16).replace("T", " ")}, spreadgym ${escaped(state.version)}` +
    (state.yaml !== null ? " (an uploaded scene)" : "") + "</p>";
}

function joined(paths) {  // many paths as one trace, separated by gaps
  const x = [], y = [];
  for (const [px, py] of paths) { x.push(...px, null); y.push(...py, null); }
  return { x, y };
}

function layout(traces, extra) {  // the legend above the plot area, never over a title; its rows make room
  const width = Math.max(200, ($("plan").clientWidth || 400) - 70);
  const chars = traces.filter((t) => t.showlegend !== false && t.name).reduce((n, t) => n + t.name.length + 6, 0);
  const rows = Math.max(1, Math.ceil(chars * 7.2 / width));
  return { ...LAYOUT, ...extra, margin: { ...LAYOUT.margin, t: 10 + rows * LEGEND_ROWS_PX } };
}

function drawPlan(plan) {
  const r = plan.disc_radius_m, lim = 1.06 * plan.reach_m;
  const shapes = [{ type: "circle", x0: -r, x1: r, y0: -r, y1: r, fillcolor: "#eeeeee", line: { color: "#555" },
    layer: "below" }];
  const traces = [
    { ...joined(plan.rays), mode: "lines", name: "flight direction", line: { color: "#9ecae1", width: 1 } },
    { ...joined(plan.tracks), mode: "lines", name: "path on the disc", line: { color: "#d62728", width: 1.2 } },
    { ...joined(plan.vanes), mode: "lines", name: "vanes", line: { color: "#333", width: 3 } },
    { x: [plan.feed_m[0]], y: [plan.feed_m[1]], mode: "markers", name: "feed point",
      marker: { symbol: "triangle-down", size: 9, color: "black" } },
  ];
  if (plan.plates.length) traces.push({ ...joined(plan.plates), mode: "lines", name: "deflector plates",
    line: { color: "#8c564b", width: 5 } });
  Plotly.react("plan", traces, layout(traces, { shapes,
    xaxis: { range: [-lim, lim], title: { text: plan.twin ? "x, across (m); the first disc" : "x, across (m)" } },
    yaxis: { range: [-lim, lim], scaleanchor: "x", title: { text: "y, forward (m)" } } }), CONFIG);
}

function drawPattern(trays, m) {
  const W = m.target_swath_m;
  $("pattern-title").textContent = "Transverse pattern (" + m.driving + ")";
  if (!trays.single_percent) {
    $("pattern-title").textContent = "Transverse pattern: nothing landed";
    Plotly.react("pattern", [], layout([], {}), CONFIG);
    return;
  }
  const traces = [
    { x: trays.center_m, y: trays.single_percent, type: "bar", name: "single pass", marker: { color: "#c6dbef" },
      width: 0.9 * trays.width_m },
    { x: trays.overlap_x_m, y: trays.overlap_percent, mode: "lines", line: { shape: "hvh", color: "#08519c" },
      name: "overlapped at " + W + " m" },
  ];
  Plotly.react("pattern", traces, layout(traces, {
    shapes: [{ type: "rect", x0: -W / 2, x1: W / 2, y0: 0, y1: 1, yref: "paper", fillcolor: "#fff2cc",
      line: { width: 0 }, layer: "below" }],
    xaxis: { title: { text: "x, across (m)" } }, yaxis: { title: { text: "rate (% of mean)" }, rangemode: "tozero" } }),
  CONFIG);
}

function curveTop(m) {  // the CV axis: to 100 % or twice the threshold, whichever the curve needs
  const t = m.cv_threshold_percent;
  return Math.min(Math.max(100, 2 * t), Math.max(2 * t, 1.1 * Math.max(0, ...m.cv_curve.cv_percent)));
}

function drawCurve(m) {
  const c = m.cv_curve, t = m.cv_threshold_percent, W = m.target_swath_m, top = curveTop(m);
  const right = Math.max(W, m.effective_swath_m, ...c.bout_width_m) * 1.03 + 0.25;
  const traces = [
    { x: c.bout_width_m, y: c.cv_percent, mode: "lines+markers", name: "CV (" + m.driving + ")",
      line: { color: "#08519c" }, marker: { size: 5 } },
    { x: [0, right], y: [t, t], mode: "lines", name: "threshold " + t + " %", line: { dash: "dash", color: "#d62728" } },
  ];
  if (m.effective_swath_m > 0) traces.push({ x: [m.effective_swath_m, m.effective_swath_m], y: [0, top],
    mode: "lines", name: "effective swath " + m.effective_swath_m + " m", line: { color: "#2ca02c", width: 2 } });
  if (m.cv_percent_at_target !== null) {
    const cv = m.cv_percent_at_target, se = m.cv_standard_error_percent, off = cv > top;
    // a CV above the axis stays on the picture: pinned at the top, with its value written beside it
    traces.push({ x: [W], y: [off ? 0.96 * top : cv], mode: off ? "markers+text" : "markers",
      name: "CV at " + W + " m" + (off ? " (" + cv.toFixed(1) + " %, above the scale)" : ""),
      text: off ? [cv.toFixed(1) + " % ↑"] : undefined, textposition: "middle right", textfont: FONT,
      marker: { symbol: off ? "triangle-up" : "star", size: 13, color: "#ffd700", line: { color: "black", width: 1 } },
      error_y: se === null || off ? undefined : { type: "data", array: [se], color: "black" } });
  }
  Plotly.react("curve", traces, layout(traces, {
    xaxis: { title: { text: "working width (m)" }, range: [0, right] }, yaxis: { title: { text: "CV (%)" }, range: [0, top] } }),
  CONFIG);
}

function drawLanding(points, m) {
  $("landing-title").textContent = "Landing points (" + points[0].length + " shown)";
  Plotly.react("landing", [{ x: points[0], y: points[1], mode: "markers", type: "scattergl", name: "landing point",
    marker: { size: 3, color: "#6a51a3", opacity: 0.5 } }],
  { ...LAYOUT, showlegend: false, xaxis: { title: { text: "x, across (m)" } },
    yaxis: { title: { text: "y, along (m)" }, scaleanchor: "x" } }, CONFIG);
}

function buildControls(info) {
  const box = $("controls");
  box.innerHTML = "";
  info.controls.forEach((c, i) => {
    c.i = i;
    const label = document.createElement("label");
    label.textContent = c.label + " (" + c.unit + ") ";
    const number = Object.assign(document.createElement("input"),
      { type: "number", min: c.min, max: c.max, step: c.step, value: c.value, id: "c" + i });
    const slider = Object.assign(document.createElement("input"),
      { type: "range", min: c.min, max: c.max, step: c.step, value: c.value, id: "s" + i });
    number.setAttribute("aria-label", `${c.label} (${c.unit}), a number in [${c.min}, ${c.max}]`);
    slider.setAttribute("aria-label", `${c.label} (${c.unit})`);
    slider.dataset.key = c.key;
    number.dataset.key = c.key;
    let moved = false;  // the slider moved since its last release
    slider.addEventListener("input", () => { moved = true; number.value = slider.value; run("draft"); });
    for (const release of ["change", "pointerup", "keyup", "touchend"]) {  // a drag back to its start fires no change
      slider.addEventListener(release, () => {
        if (!moved) return;  // a key or click that did not move it (focus arriving by Tab) changes nothing
        moved = false;
        number.value = slider.value;
        run("full");
      });
    }
    number.addEventListener("input", () => {  // typing: checked at once, sent after a pause or on enter
      supersede();  // an answer for the value before the typing would not answer the field shown
      const bad = problems();
      if (bad.length) { $("error").textContent = bad.join("\n"); stale("not updated: " + bad[0]); return; }
      $("error").textContent = "";
      stale("not updated yet: typing");
      state.timer = setTimeout(() => { slider.value = number.value; run("full"); }, 2 * SETTLE_MS);
    });
    number.addEventListener("change", () => { if (!problems().length) slider.value = number.value; run("full"); });
    label.append(number, slider);
    box.appendChild(label);
  });
  const fert = $("fertilizer");
  fert.innerHTML = "";
  for (const name of info.fertilizers) fert.add(new Option(name, name, false, name === info.fertilizer));
}

async function selectScene(body) {
  supersede();  // the old scene's answer would not answer the scene being loaded
  stale("not updated yet: loading the scene");
  try {
    const info = await post("/api/scene", body);
    state.info = info;
    state.yaml = body.yaml === undefined ? null : body.yaml;
    state.shownKey = null;
    buildControls(state.info);
    $("error").textContent = "";
    run("full");
  } catch (err) {
    if (body.yaml !== undefined) $("upload").value = "";  // the refused file is not the scene shown
    $("error").textContent = pageWords(err.message);
    stale("not updated: " + pageWords(err.message));
  }
}

async function start() {
  const data = await api("/api/scenes");
  state.precise = data.precise;
  state.version = data.version;
  for (const name of data.scenes) $("scene").add(new Option(name, name, false, name === "paper"));
  state.scene = $("scene").value;
  $("scene").addEventListener("change", () => {
    state.scene = $("scene").value; $("upload").value = "";
    selectScene({ scene: state.scene });
  });
  $("upload").addEventListener("change", async () => {
    const file = $("upload").files[0];
    if (!file) return;
    if (file.size > 1000000) { $("error").textContent = "uploaded scene: larger than 1 MB"; return; }
    selectScene({ yaml: await file.text() });
  });
  $("fertilizer").addEventListener("change", () => run("full"));
  $("precise").addEventListener("click", () => run("precise"));
  $("print").addEventListener("click", () => window.print());
  const fit = () => { for (const id of ["plan", "pattern", "curve", "landing"]) Plotly.Plots.resize(id); };
  window.matchMedia("print").addEventListener("change", fit);  // the pictures fit the paper, then the screen again
  await selectScene({ scene: state.scene });
}

start().catch((err) => { $("error").textContent = pageWords(err.message); stale("not updated: " + err.message); });
