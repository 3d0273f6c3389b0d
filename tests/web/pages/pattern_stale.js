// The pattern page never shows a picture for other controls than those shown: a draft in flight
// when the user types (a bad or a good value) or loads a scene is not shown when it answers.
"use strict";
const path = require("path");
const { load, tick, answer, next, $, document, check } = require("./dom.js");
const S = process.argv[2];

const INFO = { name: "paper", description: "", fertilizer: "pellet", fertilizers: ["pellet"], tray_width_m: 0.5,
  controls: [{ key: "spinner.rpm", index: null, label: "disc speed", unit: "rpm", step: 10, min: 200, max: 1100,
    value: 800 }] };
function payload(rpm) {
  return { cv_text: `CV-for-${rpm}rpm`, swath_text: "x",
    metrics: { cv_percent_at_target: 7, cv_threshold_percent: 15, target_swath_m: 24, runs: 2, granules: 256,
      precision_percent: 0.2, precision_met: true, model: "compiled", driving: "racetrack", effective_swath_m: 24,
      cv_standard_error_percent: 0.2, cv_curve: { bout_width_m: [1, 24], cv_percent: [5, 7] } },
    plot: { plan: { disc_radius_m: 0.3, reach_m: 1, rays: [], tracks: [], vanes: [], feed_m: [0, 0], plates: [],
      twin: false }, trays: { center_m: [0], width_m: 0.5 }, landing: [[], []] } };
}
const shown = () => $("cv").textContent;
const greyed = () => document.body.dataset.stale === "yes" && $("figures").classList.contains("stale");
const answerPattern = () => answer("/api/pattern", 200, payload(next("/api/pattern").body.set["spinner.rpm"]));

async function draftInFlight(rpm) {  // the slider dragged to `rpm`: its draft request, not yet answered
  $("s0").value = String(rpm); $("s0").fire("input");
  await tick();
  return next("/api/pattern");
}

(async () => {
  load(path.join(S, "common.js"), path.join(S, "pattern.js"));
  await tick();
  answer("/api/scenes", 200, { scenes: ["paper"], precise: { precision: 0.1, max_runs: 512 }, version: "x" });
  await tick();
  answer("/api/scene", 200, JSON.parse(JSON.stringify(INFO)));
  await tick();
  answerPattern();
  await tick();
  check("the first picture is shown", shown().startsWith("CV-for-800rpm") && !greyed());

  // a bad value typed while a draft for 900 computes
  const draft = await draftInFlight(900);
  $("c0").value = "5"; $("c0").fire("input");
  check("the draft in flight is aborted when the field is typed in", draft.aborted === true);
  await tick(1200);
  check("after the typing, the pictures stay greyed with the field's error",
    greyed() && $("error").textContent.includes("disc speed") && !shown().includes("900"));

  // a good value typed while a draft computes: the draft's answer is not shown as current
  $("c0").value = "1000"; $("c0").fire("change");
  await tick();
  answerPattern();
  await tick();
  check("a settled value is shown", shown().startsWith("CV-for-1000rpm") && !greyed());
  const second = await draftInFlight(900);
  $("c0").value = "1050"; $("c0").fire("input");
  check("typing a good value aborts the draft for the old one", second.aborted === true && greyed());
  while (!next("/api/pattern")) await tick(10);
  check("the typed value is what is sent", next("/api/pattern").body.set["spinner.rpm"] === 1050);
  answerPattern();
  await tick();
  check("the typed value's answer is shown", shown().startsWith("CV-for-1050rpm") && !greyed());

  // a scene upload refused while a draft computes
  const third = await draftInFlight(700);
  $("upload").files = [{ size: 20, text: async () => "spinner: [" }];
  $("upload").value = "mine.yaml";
  $("upload").fire("change");
  await tick();
  check("loading a scene aborts the draft of the old one", third.aborted === true);
  answer("/api/scene", 422, { error: "uploaded scene: not valid YAML at line 1, column 10" });
  await tick();
  check("a refused upload leaves the pictures greyed with its error, the file field cleared",
    greyed() && $("error").textContent.includes("not valid YAML") && $("upload").value === "" &&
    shown().startsWith("CV-for-1050rpm"));
  console.log("ok");
  process.exit(0);
})();
