// The chart page: chart folders under the server's --charts folder, one chart job at a time.
"use strict";
const $ = (id) => document.getElementById(id);
const WORDS = { "--widths": "working widths", "--fertilizers": "fertilizers", "--budget": "simulations per cell",
  "--workers": "workers", "--out": "folder name", "--scene": "scene", "--granules": "granules", "--seed": "seed",
  "--driving": "driving" };
const fail = (err) => { $("error").textContent = inPageWords(err.message, WORDS); };

function markdown(text) {  // chart.md as HTML: headings, the pipe table, list items, paragraphs (text escaped)
  const out = [];
  let table = null;
  for (const line of text.split("\n")) {
    if (line.startsWith("|")) {
      const cells = line.slice(1, -1).split("|").map((c) => escaped(c.trim()).replaceAll("&lt;br&gt;", "<br>"));
      if (cells.every((c) => /^-+$/.test(c))) continue;
      const tag = table === null ? "th" : "td";
      table = (table || "") + "<tr>" + cells.map((c) => `<${tag}>${c}</${tag}>`).join("") + "</tr>";
      continue;
    }
    if (table !== null) { out.push("<table>" + table + "</table>"); table = null; }
    if (line.startsWith("# ")) out.push("<h2>" + escaped(line.slice(2)) + "</h2>");
    else if (line.startsWith("- ")) out.push("<li>" + escaped(line.slice(2)) + "</li>");
    else if (line.trim()) out.push("<p>" + escaped(line) + "</p>");
  }
  if (table !== null) out.push("<table>" + table + "</table>");
  return out.join("\n");
}

function fileUrl(folder, name) {
  return "/files/charts/" + folder.split("/").concat(name.split("/")).map(encodeURIComponent).join("/");
}

let asked = 0;  // the latest chart asked for: an earlier one's answer, arriving later, is not shown

async function showChart(name) {
  const mine = ++asked;
  try {
    const c = await api("/api/charts/" + name.split("/").map(encodeURIComponent).join("/"));
    if (mine !== asked) return;
    const parts = [c.markdown ? markdown(c.markdown) :
      "<p>Not finished yet: " + c.cell_pictures.length + " cell picture(s) so far.</p>"];
    const links = c.files.map((f) => `<a href="${fileUrl(name, f)}">${escaped(f)}</a>`).join(" · ");
    parts.push('<p class="noprint">files: ' + links + "</p>");
    if (c.files.includes("chart.html")) {
      parts.unshift(`<p class="noprint"><a href="${fileUrl(name, "chart.html")}">printable chart</a></p>`);
    }
    if (c.files.includes("chart.png")) parts.push(`<img alt="chart" src="${fileUrl(name, "chart.png")}">`);
    for (const p of c.cell_pictures) parts.push(`<img alt="${escaped(p)}" src="${fileUrl(name, p)}">`);
    $("chart").innerHTML = parts.join("\n");
    $("error").textContent = "";
  } catch (err) {
    if (mine === asked) fail(err);
  }
}

async function listCharts() {
  const data = await api("/api/charts");
  $("folders").innerHTML = "";
  for (const c of data.charts) {
    const li = document.createElement("li");
    const a = document.createElement("a");
    a.textContent = c.name + (c.running ? " (running: " + c.cells + " cell(s) so far)" :
      c.finished ? "" : " (" + c.cells + " cell(s), not finished)");
    a.addEventListener("click", () => showChart(c.name));
    li.appendChild(a);
    $("folders").appendChild(li);
  }
  if (!data.charts.length) $("folders").innerHTML = "<li>none yet</li>";
}

function showJob(s) {  // cells done, elapsed and the time left, from the first second
  $("job-remove").hidden = !["cancelled", "failed"].includes(s.state);
  if (s.state === "idle") { $("job-status").textContent = "no job"; return; }
  const left = s.state !== "running" ? "" : s.left_s === null ? "; estimating the time left" :
    "; about " + duration(s.left_s) + " left" + (s.done ? "" : " (estimated from one timed run)");
  $("job-status").textContent = `${s.out}: ${s.state}, ${s.done} of ${s.total} cell(s), ` +
    `${duration(s.elapsed_s)} elapsed${left}; ${s.message}`;
  $("job-progress").max = s.total || 1;
  $("job-progress").value = s.done || 0;
  document.body.dataset.job = s.state;
}

let lastState = null;

async function poll() {
  try {
    const s = await api("/api/chart-jobs");
    showJob(s);
    if (s.state === "running") { setTimeout(poll, 1000); if (lastState !== "running") listCharts(); }
    else if (lastState === "running") listCharts();  // the job's folder appears or changes
    lastState = s.state;
  } catch (err) {
    fail(err);
  }
}

async function removeJob() {
  const s = await api("/api/chart-jobs");
  if (!window.confirm(`Remove the folder ${s.out} and its ${s.done} finished cell(s)?`)) return;
  try {
    await api("/api/charts/" + encodeURIComponent(s.out), { method: "DELETE" });
    $("error").textContent = "";
    await listCharts();
    showJob(await api("/api/chart-jobs"));
  } catch (err) {
    fail(err);
  }
}

async function startJob() {
  const body = { scene: $("job-scene").value, fertilizers: $("job-fertilizers").value,
    widths: $("job-widths").value, budget: Number($("job-budget").value), out: $("job-out").value };
  if ($("job-workers").value) body.workers = Number($("job-workers").value);
  try {
    showJob(await api("/api/chart-jobs", { method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body) }));
    $("error").textContent = "";
    poll();
  } catch (err) {
    fail(err);
  }
}

async function cancelJob() {
  $("job-status").textContent = "cancelling...";
  try {
    showJob(await api("/api/chart-jobs", { method: "DELETE" }));
  } catch (err) {
    fail(err);
  }
}

async function start() {
  const scenes = await api("/api/scenes");
  for (const name of scenes.scenes) $("job-scene").add(new Option(name, name, false, name === "paper"));
  $("job-start").addEventListener("click", startJob);
  $("job-cancel").addEventListener("click", cancelJob);
  $("job-remove").addEventListener("click", removeJob);
  await listCharts();
  poll();
}

start().catch(fail);
