// The pattern page: controls -> POST /api/pattern -> four Plotly pictures and the CV.
"use strict";
const $ = (id) => document.getElementById(id);
const state = { scene: null, yaml: null, info: null, precise: null, sent: 0, shown: 0, busy: false, next: null };
const CONFIG = { displayModeBar: false };  // drag zooms, a double click resets
const LAYOUT = { margin: { l: 50, r: 10, t: 30, b: 40 }, font: { size: 11 }, showlegend: true,
  legend: { orientation: "h", y: -0.2 } };

async function api(path, body) {
  const response = await fetch(path, body === undefined ? {} :
    { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
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

function run(mode) {  // one request at a time; the latest change waits for the one in flight
  state.next = mode;
  if (!state.busy) send();
}

async function send() {
  const mode = state.next;
  state.next = null;
  state.busy = true;
  const seq = ++state.sent;
  $("status").textContent = mode === "precise" ? "computing the precise estimate..." : "computing...";
  try {
    const data = await api("/api/pattern", request(mode));
    $("error").textContent = "";
    if (seq > state.shown) { state.shown = seq; show(data, mode); }
  } catch (err) {
    $("error").textContent = err.message;
  } finally {
    state.busy = false;
    $("status").textContent = "";
    if (state.next !== null) send();
  }
}

function show(data, mode) {
  const m = data.metrics, p = data.plot;
  $("cv").textContent = data.cv_text + " at " + m.target_swath_m + " m";
  $("summary").innerHTML = "";
  const rows = [["effective swath", m.effective_swath_m + " m (CV <= " + m.cv_threshold_percent + " %)"],
    ["runs", m.runs + " of " + m.granules + " granules (" + (mode === "draft" ? "draft: the pilot runs" :
      "standard error " + m.precision_percent + " pp asked, " + (m.precision_met ? "reached" : "not reached")) + ")"],
    ["model", m.model], ["driving", m.driving]];
  for (const [k, v] of rows) {
    const div = document.createElement("div");
    div.textContent = k + ": " + v;
    $("summary").appendChild(div);
  }
  drawPlan(p.plan); drawPattern(p.trays, m); drawCurve(m); drawLanding(p.landing, m);
  document.body.dataset.rev = String(state.shown);
  document.body.dataset.mode = mode;
}

function joined(paths) {  // many paths as one trace, separated by gaps
  const x = [], y = [];
  for (const [px, py] of paths) { x.push(...px, null); y.push(...py, null); }
  return { x, y };
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
  Plotly.react("plan", traces, { ...LAYOUT, title: { text: plan.twin ? "Plan view (first disc)" : "Plan view" }, shapes,
    xaxis: { range: [-lim, lim], title: { text: "x, across (m)" } },
    yaxis: { range: [-lim, lim], scaleanchor: "x", title: { text: "y, forward (m)" } } }, CONFIG);
}

function drawPattern(trays, m) {
  const W = m.target_swath_m;
  if (!trays.single_percent) {
    Plotly.react("pattern", [], { ...LAYOUT, title: { text: "Transverse pattern: nothing landed" } });
    return;
  }
  Plotly.react("pattern", [
    { x: trays.center_m, y: trays.single_percent, type: "bar", name: "single pass", marker: { color: "#c6dbef" },
      width: 0.9 * trays.width_m },
    { x: trays.overlap_x_m, y: trays.overlap_percent, mode: "lines", line: { shape: "hvh", color: "#08519c" },
      name: "overlapped at " + W + " m" },
  ], { ...LAYOUT, title: { text: "Transverse pattern (" + m.driving + ")" },
    shapes: [{ type: "rect", x0: -W / 2, x1: W / 2, y0: 0, y1: 1, yref: "paper", fillcolor: "#fff2cc",
      line: { width: 0 }, layer: "below" }],
    xaxis: { title: { text: "x, across (m)" } }, yaxis: { title: { text: "rate (% of mean at the width)" }, rangemode: "tozero" } },
  CONFIG);
}

function drawCurve(m) {
  const c = m.cv_curve, t = m.cv_threshold_percent, W = m.target_swath_m;
  const top = Math.min(Math.max(100, 2 * t), Math.max(2 * t, 1.1 * Math.max(0, ...c.cv_percent)));
  const right = Math.max(W, m.effective_swath_m, ...c.bout_width_m) * 1.03 + 0.25;
  const traces = [
    { x: c.bout_width_m, y: c.cv_percent, mode: "lines+markers", name: "CV (" + m.driving + ")",
      line: { color: "#08519c" }, marker: { size: 5 } },
    { x: [0, right], y: [t, t], mode: "lines", name: "threshold " + t + " %", line: { dash: "dash", color: "#d62728" } },
  ];
  if (m.effective_swath_m > 0) traces.push({ x: [m.effective_swath_m, m.effective_swath_m], y: [0, top],
    mode: "lines", name: "effective swath " + m.effective_swath_m + " m", line: { color: "#2ca02c", width: 2 } });
  if (m.cv_percent_at_target !== null) {
    const se = m.cv_standard_error_percent;
    traces.push({ x: [W], y: [m.cv_percent_at_target], mode: "markers", name: "CV at " + W + " m",
      marker: { symbol: "star", size: 13, color: "#ffd700", line: { color: "black", width: 1 } },
      error_y: se === null ? undefined : { type: "data", array: [se], color: "black" } });
  }
  Plotly.react("curve", traces, { ...LAYOUT, title: { text: "CV against working width" },
    xaxis: { title: { text: "working width (m)" }, range: [0, right] }, yaxis: { title: { text: "CV (%)" }, range: [0, top] } },
  CONFIG);
}

function drawLanding(points, m) {
  Plotly.react("landing", [{ x: points[0], y: points[1], mode: "markers", type: "scattergl", name: "landing point",
    marker: { size: 3, color: "#6a51a3", opacity: 0.5 } }],
  { ...LAYOUT, title: { text: "Landing points (" + points[0].length + " shown)" }, showlegend: false,
    xaxis: { title: { text: "x, across (m)" } }, yaxis: { title: { text: "y, along (m)" }, scaleanchor: "x" } }, CONFIG);
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
    slider.dataset.key = c.key;
    slider.addEventListener("input", () => { number.value = slider.value; run("draft"); });
    slider.addEventListener("change", () => { number.value = slider.value; run("full"); });
    number.addEventListener("change", () => { slider.value = number.value; run("full"); });
    label.append(number, slider);
    box.appendChild(label);
  });
  const fert = $("fertilizer");
  fert.innerHTML = "";
  for (const name of info.fertilizers) fert.add(new Option(name, name, false, name === info.fertilizer));
}

async function selectScene(body) {
  try {
    state.info = await api("/api/scene", body);
    state.yaml = body.yaml === undefined ? null : body.yaml;
    buildControls(state.info);
    $("error").textContent = "";
    run("full");
  } catch (err) {
    $("error").textContent = err.message;
  }
}

async function start() {
  const data = await api("/api/scenes");
  state.precise = data.precise;
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
  await selectScene({ scene: state.scene });
}

start().catch((err) => { $("error").textContent = err.message; });
