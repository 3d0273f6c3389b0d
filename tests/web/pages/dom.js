// A minimal DOM and fetch stand-in that runs the pages' scripts (agents/web/static, unchanged) in node:
// requests wait until the test answers them (`answer`), so answers can come late, out of order or never.
"use strict";
const fs = require("fs");
const vm = require("vm");

function makeEl(id) {
  const el = {
    id, hidden: false, innerHTML: "", disabled: false, files: [],
    dataset: {}, attrs: {}, children: [], listeners: {}, clientWidth: 400, options: [],
    classList: { set: new Set(), toggle(c, on) { on ? this.set.add(c) : this.set.delete(c); },
      contains(c) { return this.set.has(c); } },
    setAttribute(k, v) { this.attrs[k] = v; },
    addEventListener(t, f) { (this.listeners[t] = this.listeners[t] || []).push(f); },
    appendChild(c) { this.children.push(c); if (c.id) els[c.id] = c; return c; },
    append(...cs) { for (const c of cs) this.appendChild(c); },
    add(opt) { this.options.push(opt); if (opt.selected || this.options.length === 1) this.value = opt.value; },
    fire(t) { for (const f of this.listeners[t] || []) f({}); },
  };
  let v = "", t = "";
  Object.defineProperty(el, "textContent", { get: () => t, set: (x) => { t = String(x);
    el.innerHTML = t.replace(/&/g, "&amp;").replace(/</g, "&lt;").replace(/>/g, "&gt;"); }, enumerable: true });
  Object.defineProperty(el, "value", { get: () => v, set: (x) => { v = String(x); }, enumerable: true });
  return el;
}
const els = {};
const document = {
  getElementById(id) { return els[id] || (els[id] = makeEl(id)); },
  createElement(tag) { const e = makeEl(null); e.tag = tag; return e; },
  body: makeEl("body"),
};
// Object.assign(createElement("input"), {id: ...}) sets id after creation: register lazily
const origGet = document.getElementById;
document.getElementById = (id) => {
  if (els[id]) return els[id];
  const found = findById(id);
  return found || origGet(id);
};
function findById(id) {
  const stack = Object.values(els);
  while (stack.length) {
    const e = stack.pop();
    if (e.id === id) { els[id] = e; return e; }
    stack.push(...e.children);
  }
  return null;
}

const pending = [];  // {path, body, resolve(status, json), signal}
function fetch(path, options = {}) {
  return new Promise((resolve, reject) => {
    const entry = { path, body: options.body ? JSON.parse(options.body) : null, method: options.method || "GET" };
    entry.answer = (status, json) => resolve({ ok: status < 400, status, statusText: String(status),
      json: async () => json });
    if (options.signal) options.signal.addEventListener("abort", () => {
      entry.aborted = true; const e = new Error("aborted"); e.name = "AbortError"; reject(e);
    });
    pending.push(entry);
  });
}
const Plotly = { calls: [], react(id) { this.calls.push(id); }, purge(id) { this.calls.push("purge:" + id); },
  Plots: { resize() {} } };
class Option { constructor(text, value, d, selected) { this.text = text; this.value = value; this.selected = selected; } }
class Blob { constructor(parts) { this.parts = parts; } }
const window = { confirm: () => true, print() {}, matchMedia: () => ({ addEventListener() {} }) };
const context = { document, window, fetch, Plotly, Option, Blob, URL: { createObjectURL: () => "blob:x" },
  performance, setTimeout, clearTimeout, console, AbortController, Error, JSON, Number, Math, Object, String,
  Promise, Array, Set };
context.globalThis = context;
vm.createContext(context);

function load(...files) {
  for (const f of files) vm.runInContext(fs.readFileSync(f, "utf8"), context, { filename: f });
}
const tick = (ms = 0) => new Promise((r) => setTimeout(r, ms));
function next(path) {  // the oldest unanswered, unaborted request to `path`
  return pending.find((p) => p.path === path && !p.done && !p.aborted);
}
function answer(path, status, json) {
  const p = next(path);
  if (!p) throw new Error("no pending request to " + path);
  p.done = true;
  p.answer(status, json);
  return p;
}
module.exports = { els, document, pending, load, tick, next, answer, context, $: (id) => document.getElementById(id) };

function check(what, condition) {  // an assertion whose failure names the step and ends the run with status 1
  if (!condition) {
    console.error("FAILED: " + what);
    process.exit(1);
  }
}
module.exports.check = check;
