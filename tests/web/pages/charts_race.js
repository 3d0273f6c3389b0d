// The chart page shows the chart last clicked, whichever answer arrives last.
"use strict";
const path = require("path");
const { load, tick, answer, pending, $, check } = require("./dom.js");
const S = process.argv[2];

const detail = (name) => ({ name, finished: true, markdown: "# chart\n\nrows of " + name, rows: [],
  files: ["chart.png"], cell_pictures: [] });
const shown = () => (/rows of (\S+)</.exec($("chart").innerHTML) || [])[1];

(async () => {
  load(path.join(S, "common.js"), path.join(S, "charts.js"));
  await tick();
  answer("/api/scenes", 200, { scenes: ["paper"] });
  await tick();
  answer("/api/charts", 200, { charts: [{ name: "trial-2023", finished: true, cells: 8 },
    { name: "trial-2024", finished: true, cells: 8 }] });
  await tick();
  answer("/api/chart-jobs", 200, { state: "idle" });
  await tick();
  const links = $("folders").children.map((li) => li.children[0]);
  links[0].fire("click");
  links[1].fire("click");
  await tick();
  const [first, last] = pending.filter((p) => p.path.startsWith("/api/charts/"));
  last.done = true; last.answer(200, detail("trial-2024")); await tick();
  check("the chart clicked last is shown", shown() === "trial-2024");
  first.done = true; first.answer(404, { error: "chart: gone" }); await tick();
  first.done = true;
  check("an earlier click's late answer (or error) changes nothing", shown() === "trial-2024" &&
    $("error").textContent === "");
  console.log("ok");
  process.exit(0);
})();
