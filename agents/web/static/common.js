// What the three pages share: the JSON API, escaping, and a server message in the page's own words.
"use strict";

async function api(path, options) {  // options: fetch's; an error answer is thrown as its one line
  const response = await fetch(path, options);
  const data = await response.json();
  if (!response.ok) throw new Error(data.error || response.statusText);
  return data;
}

function escaped(text) {
  const div = document.createElement("div");
  div.textContent = text;
  return div.innerHTML;
}

function inPageWords(message, words) {  // the CLI's flags and keys in a message, named as the page's controls
  let text = message;
  for (const [flag, control] of Object.entries(words)) text = text.split(flag).join(control);
  return text;
}

function duration(seconds) {  // "2 min 05 s", "45 s"
  const s = Math.max(0, Math.round(seconds));
  return s < 60 ? s + " s" : Math.floor(s / 60) + " min " + String(s % 60).padStart(2, "0") + " s";
}
