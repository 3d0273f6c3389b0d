// The fit page: a tray CSV and the keys to fit -> POST /api/fit -> estimates, intervals, pictures, fitted scene;
// and the working width wanted -> POST /api/advise -> what to change. A new run clears the last result at once,
// so a failed one never leaves an old answer (or its download) on the page; so does a change of any input, and
// an answer whose inputs changed while it computed is not shown.
"use strict";
const $ = (id) => document.getElementById(id);
const FONT = { size: 12 };
const CONFIG = { displayModeBar: false, responsive: true };
const LAYOUT = { margin: { l: 56, r: 12, t: 56, b: 46 }, font: FONT,
  legend: { orientation: "h", x: 0, y: 1.02, xanchor: "left", yanchor: "bottom", font: FONT } };
const WORDS = { "--trays": "tray test", "--fit": "keys to fit", "--set": "settings of the test",
  "--granules": "granules per evaluation", "--width": "working width wanted", "--scene": "scene",
  "--budget": "search budget", "--seed": "seed" };

const INPUTS = ["scene", "sets", "trays", "keys", "granules", "width"];
let generation = 0;  // counts the changes of the inputs: an answer is shown only for the inputs shown

function lines(text) {
  return text.split("\n").map((l) => l.trim()).filter((l) => l);
}

function clear() {  // the last result off the page: estimates, advice, download, pictures
  for (const id of ["table", "advice", "download"]) $(id).innerHTML = "";
  for (const id of ["pattern", "curve"]) Plotly.purge(id);
  delete document.body.dataset.fitted;
  delete document.body.dataset.advised;
}

async function body() {
  const file = $("trays").files[0];
  if (!file) throw new Error("tray test: choose a CSV file first");
  if (file.size > 1000000) throw new Error("tray test: larger than 1 MB");
  const set = {};
  for (const line of lines($("sets").value)) {
    const at = line.indexOf("=");
    set[at < 0 ? line : line.slice(0, at).trim()] = at < 0 ? "" : line.slice(at + 1).trim();
  }
  return { scene: $("scene").value, set, trays: await file.text(), fit: lines($("keys").value) };
}

function changed() {  // an input changed: what is shown (or computing) no longer answers the page's inputs
  generation += 1;
  if (document.body.dataset.fitted || document.body.dataset.advised) {
    clear();
    $("error").textContent = "the inputs changed: the last result is cleared; run it again";
  }
}

async function run(kind) {
  clear();
  const mine = ++generation;
  $("error").textContent = "";
  for (const id of ["start", "advise"]) $(id).disabled = true;
  try {
    const request = await body();
    if (kind === "fit") {
      const granules = Number($("granules").value);
      if (!$("granules").value || !Number.isInteger(granules) || granules < 1 || granules > 1000000) {
        throw new Error("granules per evaluation: enter a whole number in [1, 1000000]");
      }
      request.granules = granules;
    } else {
      const width = Number($("width").value);
      if (!$("width").value || !(width > 0 && width <= 100)) {
        throw new Error("working width wanted: enter a number in (0, 100] m");
      }
      request.width = width;
      if (!request.fit.length) delete request.fit;  // advise's own keys
    }
    $("status").textContent = kind === "fit" ? "fitting (seconds to minutes)..." :
      "fitting, then searching the settings (one to three minutes)...";
    const data = await api("/api/" + kind, { method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(request) });
    if (mine !== generation) {
      $("error").textContent = "the inputs changed while it computed: not shown; run it again";
      return;
    }
    if (kind === "fit") showFit(data.fit, data);
    else showAdvice(data);
  } catch (err) {
    if (mine !== generation) return;  // the inputs changed since: the page says so already
    clear();
    $("error").textContent = inPageWords(err.message, WORDS);
  } finally {
    $("status").textContent = "";
    for (const id of ["start", "advise"]) $(id).disabled = false;
  }
}

function cvLine(f) {  // the fitted CV at the test's width, beside the measured trays' own
  if (f.cv_percent_at_target === null) return "";
  const measured = f.measured_cv_percent_at_target === undefined || f.measured_cv_percent_at_target === null ? "" :
    `measured trays ${f.measured_cv_percent_at_target.toFixed(1)} %; `;
  return `<p id="fit-cv">CV at ${f.target_swath_m} m (${escaped(f.driving)}): ${measured}fitted model ` +
    `${f.cv_percent_at_target.toFixed(1)} % (90 % band ${f.cv_percent_at_target_band[0].toFixed(1)}-` +
    `${f.cv_percent_at_target_band[1].toFixed(1)} %); effective swath ${f.effective_swath_m} m</p>`;
}

function showFit(f, data) {
  const rows = Object.entries(f.parameters).map(([key, v]) =>
    `<tr><td>${escaped(key)}</td><td>${v.estimate.toPrecision(4)}</td>` +
    `<td>[${v.low.toPrecision(4)}, ${v.high.toPrecision(4)}]</td>` +
    `<td>${f.identifiable[key] ? "yes" : "no: the test does not determine it"}</td></tr>`).join("");
  const trades = f.trade_offs.map((t) => `<p>trade-off: ${escaped(t.keys[0])} and ${escaped(t.keys[1])} ` +
    `(correlation ${t.correlation.toFixed(2)})</p>`).join("");
  $("table").innerHTML = `<table id="estimates"><tr><th>key</th><th>estimate</th><th>90 % interval</th>` +
    `<th>identifiable</th></tr>${rows}</table>${cvLine(f)}${trades}<p>${f.trays_used} trays, ${f.evaluations} ` +
    `evaluations, ${f.wall_s.toFixed(0)} s; catch noise ${(100 * f.catch_noise_sd).toFixed(1)} % per tray</p>`;
  if (data.scene_yaml_text) {
    const blob = new Blob([data.scene_yaml_text], { type: "application/x-yaml" });
    $("download").appendChild(Object.assign(document.createElement("a"),
      { href: URL.createObjectURL(blob), download: f.scene + "-fitted.yaml", textContent: "download the fitted scene" }));
  }
  draw(data.plot, data.threshold_percent);
  document.body.dataset.fitted = "yes";
}

function showAdvice(data) {
  const a = data.advice;
  const band = (cv, lo, hi) => cv === null ? "-" : `${cv.toFixed(1)} % (${lo.toFixed(1)}-${hi.toFixed(1)} %)`;
  const rows = Object.keys(a.advised).map((key) => {
    const from = a.tested[key], to = a.advised[key], changed = JSON.stringify(from) !== JSON.stringify(to);
    return `<tr><td>${escaped(key)}</td><td>${escaped(String(from))}</td><td>${escaped(String(to))}</td>` +
      `<td>${changed ? "change" : "keep"}</td></tr>`;
  }).join("");
  $("advice").innerHTML = `<p class="headline" id="instruction">${escaped(a.instruction)}</p>` +
    `<table id="changes"><tr><th>setting</th><th>tested</th><th>advised</th><th></th></tr>${rows}</table>` +
    `<p>expected CV at ${a.width_m} m: ${band(a.cv_before_percent, a.cv_before_percent_low, a.cv_before_percent_high)}` +
    ` as tested, ${band(a.cv_after_percent, a.cv_after_percent_low, a.cv_after_percent_high)} advised (the fitted ` +
    `model over its 90 % band); over batches of the fertilizer, p90 ${a.cv_p90_after_percent.toFixed(1)} % ` +
    `advised; ${a.search.simulations} search runs, ${a.wall_s.toFixed(0)} s</p>`;
  showFit(a.fit, data);
  document.body.dataset.advised = "yes";
}

function draw(p, t) {
  const measured = { x: p.measured_x_m, y: p.measured_g, mode: "markers", marker: { color: "#d62728", size: 7 },
    name: "measured trays" };
  Plotly.react("pattern", [
    { x: p.center_m.concat([...p.center_m].reverse()), y: p.high_g.concat([...p.low_g].reverse()), fill: "toself",
      fillcolor: "rgba(8,81,156,0.15)", line: { width: 0 }, name: "90 % band", hoverinfo: "skip" },
    { x: p.center_m, y: p.fitted_g, mode: "lines", line: { shape: "hvh", color: "#08519c" }, name: "fitted" },
    measured,
  ], { ...LAYOUT, xaxis: { title: { text: "x, across (m)" } },
    yaxis: { title: { text: "mass per tray (g)" }, rangemode: "tozero" } }, CONFIG);
  const right = Math.max(...p.widths_m);
  const traces = [
    { x: p.widths_m.concat([...p.widths_m].reverse()), y: p.cv_high_percent.concat([...p.cv_low_percent].reverse()),
      fill: "toself", fillcolor: "rgba(8,81,156,0.15)", line: { width: 0 }, name: "90 % band", hoverinfo: "skip" },
    { x: p.widths_m, y: p.cv_percent, mode: "lines+markers", line: { color: "#08519c" }, marker: { size: 4 },
      name: "fitted model" },
    { x: [0, right], y: [t, t], mode: "lines", line: { dash: "dash", color: "#d62728" }, name: "threshold " + t + " %" },
  ];
  if (p.measured_cv_percent) traces.push({ x: p.widths_m, y: p.measured_cv_percent, mode: "lines",
    line: { color: "black", dash: "dot" }, name: "measured trays" });
  Plotly.react("curve", traces, { ...LAYOUT, xaxis: { title: { text: "working width (m)" } },
    yaxis: { title: { text: "CV (%)" }, range: [0, Math.min(100, Math.max(2 * t, ...p.cv_percent) * 1.1)] } }, CONFIG);
}

async function init() {
  const data = await api("/api/scenes");
  for (const name of data.scenes) $("scene").add(new Option(name, name, false, name === "paper"));
  for (const id of INPUTS) for (const kind of ["input", "change"]) $(id).addEventListener(kind, changed);
  $("start").addEventListener("click", () => run("fit"));
  $("advise").addEventListener("click", () => run("advise"));
}

init().catch((err) => { $("error").textContent = err.message; });
