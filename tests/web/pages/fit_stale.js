// The fit page never shows an answer for other inputs than those shown: one computed while the
// inputs changed is dropped, and a shown one is cleared when an input changes.
"use strict";
const path = require("path");
const { load, tick, answer, next, $, document, check } = require("./dom.js");
const S = process.argv[2];

const FIT = { fit: { scene: "paper", parameters: { "contact.vane_restitution": { estimate: 0.41, low: 0.38, high: 0.45 } },
  identifiable: { "contact.vane_restitution": true }, trade_offs: [], cv_percent_at_target: null, trays_used: 40,
  evaluations: 30, wall_s: 12, catch_noise_sd: 0.05 }, scene_yaml_text: "a: 1", threshold_percent: 15,
  plot: { measured_x_m: [], measured_g: [], center_m: [0], fitted_g: [1], low_g: [1], high_g: [1], widths_m: [1],
    cv_percent: [1], cv_low_percent: [1], cv_high_percent: [1], measured_cv_percent: null } };
const estimates = () => /0\.41/.test($("table").innerHTML);

(async () => {
  load(path.join(S, "common.js"), path.join(S, "fit.js"));
  await tick();
  answer("/api/scenes", 200, { scenes: ["paper", "twin"], precise: {}, version: "x" });
  await tick();
  $("granules").value = "1024"; $("keys").value = "contact.vane_restitution=0.3:0.7";
  $("trays").files = [{ name: "field-A.csv", size: 10, text: async () => "x_m,mass_g" }];
  $("start").fire("click");
  await tick();
  check("a fit is sent", next("/api/fit") !== undefined);
  $("scene").value = "twin"; $("scene").fire("change");  // the user changes the inputs while it fits
  answer("/api/fit", 200, FIT);
  await tick();
  check("the answer for the old inputs is not shown",
    !estimates() && $("download").children.length === 0 && document.body.dataset.fitted === undefined &&
    $("error").textContent.includes("inputs changed"));
  $("start").fire("click");
  await tick();
  answer("/api/fit", 200, FIT);
  await tick();
  check("a fit of the inputs shown is shown", estimates() && document.body.dataset.fitted === "yes");
  $("trays").files = [{ name: "field-B.csv", size: 10, text: async () => "x_m,mass_g" }];
  $("trays").fire("change");
  check("a new tray file clears the shown fit and its download",
    !estimates() && $("download").innerHTML === "" && document.body.dataset.fitted === undefined);
  console.log("ok");
  process.exit(0);
})();
