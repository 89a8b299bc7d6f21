// The live preview: polls /state.json and refreshes /frame.jpg; no dependencies.
"use strict";
const POLL_MS = 200;

function text(value, digits) {
  if (value === null || value === undefined) return "–";
  return typeof value === "number" ? value.toFixed(digits) : String(value);
}

function cell(row, content, className) {
  const td = row.insertCell();
  if (content instanceof Node) td.appendChild(content); else td.textContent = content;
  if (className) td.className = className;
  return td;
}

function bar(fraction) {
  const outer = document.createElement("span");
  outer.className = "bar";
  const inner = document.createElement("i");
  inner.style.width = Math.round(100 * Math.max(0, Math.min(1, fraction || 0))) + "%";
  outer.appendChild(inner);
  const label = document.createElement("span");
  label.className = "progress";
  label.textContent = " " + text(fraction, 2);
  const both = document.createElement("span");
  both.append(outer, label);
  return both;
}

function showPerformers(performers) {
  const body = document.querySelector("#performers tbody");
  body.replaceChildren();
  for (const [name, p] of Object.entries(performers)) {
    const row = body.insertRow();
    row.dataset.performer = name;
    cell(row, name);
    cell(row, p.status, "status status-" + p.status);
    cell(row, p.action || "rest", "action");
    cell(row, bar(p.progress));
    cell(row, text(p.variance === null ? null : Math.sqrt(p.variance), 3), "sigma");
    cell(row, text(p.log_likelihood, 1), "likelihood");
    cell(row, p.status === "ok" ? "" : (p.message || ""), "message");
  }
}

function showCharacters(characters) {
  const body = document.querySelector("#characters tbody");
  body.replaceChildren();
  for (const [name, c] of Object.entries(characters)) {
    for (const track of c.tracks) {
      const row = body.insertRow();
      row.dataset.character = name;
      cell(row, name);
      cell(row, track.performer);
      cell(row, track.action || "rest", "action");
      cell(row, bar(track.progress));
      cell(row, text(track.blend, 2));
      cell(row, track.state || "");
    }
  }
}

function showTiming(timing) {
  const body = document.querySelector("#timing tbody");
  body.replaceChildren();
  for (const [stage, t] of Object.entries(timing || {})) {
    if (!t.count) continue;
    const row = body.insertRow();
    row.dataset.stage = stage;
    cell(row, stage.replaceAll("_", " "));
    cell(row, text(t.median, 2) + " / " + text(t.p90, 2));
  }
}

function showEvents(events) {
  const list = document.getElementById("events");
  list.replaceChildren();
  for (const e of (events || []).slice(-8)) {
    const item = document.createElement("li");
    item.textContent = "t=" + text(e.t, 2) + " s " + e.performer + ": " + e.message;
    list.appendChild(item);
  }
}

let polls = 0;
async function poll() {
  try {
    const response = await fetch("state.json", {cache: "no-store"});
    const state = await response.json();
    polls += 1;
    document.getElementById("session").textContent = state.session || "";
    document.getElementById("frame").textContent = state.frame;
    document.getElementById("time").textContent = text(state.t, 2);
    document.getElementById("mode").textContent = state.mode || "";
    document.getElementById("dropped").textContent = state.dropped;
    document.getElementById("link").textContent = state.closed ? "session ended" : "connected";
    const verdict = document.getElementById("verdict");
    const behind = state.behind > 0.04 && !state.closed
      ? " · now " + Math.round(1000 * state.behind) + " ms behind, catching up" : "";
    verdict.textContent = (state.verdict || "") + behind;
    verdict.className = (state.verdict || "").startsWith("NOT") ? "warning" : "";
    document.body.dataset.polls = polls;
    showPerformers(state.performers || {});
    showCharacters(state.characters || {});
    showTiming(state.timing);
    showEvents(state.events);
  } catch (error) {
    document.getElementById("link").textContent = "disconnected";
  }
  setTimeout(poll, POLL_MS);
}

// Reload the picture once the previous one has arrived: never more than one request in flight.
const stream = document.getElementById("stream");
function nextPicture() { setTimeout(() => { stream.src = "frame.jpg?n=" + Date.now(); }, 80); }
stream.addEventListener("load", nextPicture);
stream.addEventListener("error", () => setTimeout(nextPicture, 500));

poll();
