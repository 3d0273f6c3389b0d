// The fit page: a tray CSV and the keys to fit -> POST /api/fit -> estimates, intervals, pictures, fitted scene.
"use strict";
const $ = (id) => document.getElementById(id);
const CONFIG = { displayModeBar: false };
const LAYOUT = { margin: { l: 50, r: 10, t: 30, b: 40 }, font: { size: 11 }, legend: { orientation: "h", y: -0.2 } };

function lines(text) {
  return text.split("\n").map((l) => l.trim()).filter((l) => l);
}

function escaped(text) {
  const div = document.createElement("div");
  div.textContent = text;
  return div.innerHTML;
}

async function start() {
  const file = $("trays").files[0];
  if (!file) { $("error").textContent = "choose a tray test CSV first"; return; }
  if (file.size > 1000000) { $("error").textContent = "tray test: larger than 1 MB"; return; }
  const set = {};
  for (const line of lines($("sets").value)) {
    const at = line.indexOf("=");
    set[at < 0 ? line : line.slice(0, at).trim()] = at < 0 ? "" : line.slice(at + 1).trim();
  }
  const body = { scene: $("scene").value, set, trays: await file.text(), fit: lines($("keys").value),
    granules: Number($("granules").value) };
  $("status").textContent = "fitting (seconds to minutes)...";
  $("error").textContent = "";
  $("start").disabled = true;
  try {
    const response = await fetch("/api/fit", { method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body) });
    const data = await response.json();
    if (!response.ok) throw new Error(data.error || response.statusText);
    show(data);
  } catch (err) {
    $("error").textContent = err.message;
  } finally {
    $("status").textContent = "";
    $("start").disabled = false;
  }
}

function show(data) {
  const f = data.fit, p = data.plot;
  const rows = Object.entries(f.parameters).map(([key, v]) =>
    `<tr><td>${escaped(key)}</td><td>${v.estimate.toPrecision(4)}</td>` +
    `<td>[${v.low.toPrecision(4)}, ${v.high.toPrecision(4)}]</td>` +
    `<td>${f.identifiable[key] ? "yes" : "no: the test does not determine it"}</td></tr>`).join("");
  const cv = f.cv_percent_at_target === null ? "" : `<p>fitted CV at ${f.target_swath_m} m (${f.driving}): ` +
    `${f.cv_percent_at_target.toFixed(1)} % (90 % band ${f.cv_percent_at_target_band[0].toFixed(1)}-` +
    `${f.cv_percent_at_target_band[1].toFixed(1)} %); effective swath ${f.effective_swath_m} m</p>`;
  const trades = f.trade_offs.map((t) => `<p>trade-off: ${escaped(t.keys[0])} and ${escaped(t.keys[1])} ` +
    `(correlation ${t.correlation.toFixed(2)})</p>`).join("");
  $("table").innerHTML = `<table id="estimates"><tr><th>key</th><th>estimate</th><th>90 % interval</th>` +
    `<th>identifiable</th></tr>${rows}</table>${cv}${trades}<p>${f.trays_used} trays, ${f.evaluations} ` +
    `evaluations, ${f.wall_s.toFixed(0)} s; catch noise ${(100 * f.catch_noise_sd).toFixed(1)} % per tray</p>`;
  const blob = new Blob([data.scene_yaml_text], { type: "application/x-yaml" });
  $("download").innerHTML = "";
  const link = Object.assign(document.createElement("a"),
    { href: URL.createObjectURL(blob), download: f.scene + "-fitted.yaml", textContent: "download the fitted scene" });
  $("download").appendChild(link);
  Plotly.react("pattern", [
    { x: p.center_m.concat([...p.center_m].reverse()), y: p.high_g.concat([...p.low_g].reverse()), fill: "toself",
      fillcolor: "rgba(8,81,156,0.15)", line: { width: 0 }, name: "90 % band", hoverinfo: "skip" },
    { x: p.center_m, y: p.fitted_g, mode: "lines", line: { shape: "hvh", color: "#08519c" }, name: "fitted" },
    { x: p.measured_x_m, y: p.measured_g, mode: "markers", marker: { color: "#d62728", size: 7 }, name: "measured" },
  ], { ...LAYOUT, title: { text: "Tray pattern: measured and fitted" }, xaxis: { title: { text: "x, across (m)" } },
    yaxis: { title: { text: "mass per tray (g)" }, rangemode: "tozero" } }, CONFIG);
  const t = data.threshold_percent, right = Math.max(...p.widths_m);
  Plotly.react("curve", [
    { x: p.widths_m.concat([...p.widths_m].reverse()), y: p.cv_high_percent.concat([...p.cv_low_percent].reverse()),
      fill: "toself", fillcolor: "rgba(8,81,156,0.15)", line: { width: 0 }, name: "90 % band", hoverinfo: "skip" },
    { x: p.widths_m, y: p.cv_percent, mode: "lines+markers", line: { color: "#08519c" }, marker: { size: 4 },
      name: "CV at the estimate" },
    { x: [0, right], y: [t, t], mode: "lines", line: { dash: "dash", color: "#d62728" }, name: "threshold " + t + " %" },
  ], { ...LAYOUT, title: { text: "CV against working width (fitted)" },
    xaxis: { title: { text: "working width (m)" } },
    yaxis: { title: { text: "CV (%)" }, range: [0, Math.min(100, Math.max(2 * t, ...p.cv_percent) * 1.1)] } }, CONFIG);
  document.body.dataset.fitted = "yes";
}

async function init() {
  const response = await fetch("/api/scenes");
  const data = await response.json();
  for (const name of data.scenes) $("scene").add(new Option(name, name, false, name === "paper"));
  $("start").addEventListener("click", start);
}

init().catch((err) => { $("error").textContent = err.message; });
