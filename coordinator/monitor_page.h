// The web monitor's page (coordinator/monitor.h): one HTML document, its script and its style,
// served from the binary. No build step and no third-party script: the page is plain DOM code,
// and every value from the farm goes in as text (textContent), never as markup, since job names
// and error messages come from users.
#pragma once

namespace rf {

inline constexpr const char* kMonitorHtml = R"html(<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>rayfarm monitor</title>
<link rel="stylesheet" href="/monitor.css">
<script src="/monitor.js" defer></script>
</head>
<body>
<header><h1>rayfarm</h1><span id="who"></span>
<button id="logout" hidden>Log out</button></header>
<section id="login" hidden>
<form id="login-form">
<label for="token">Client token</label>
<input id="token" name="token" type="password" autocomplete="off" placeholder="rft_...">
<button id="login-button" type="submit">Log in</button>
</form>
<p id="login-error" class="error"></p>
</section>
<main id="app" hidden>
<p id="status-line" class="muted"></p>
<h2>Jobs</h2>
<table id="jobs"><thead><tr><th>Job</th><th>Name</th><th>Owner</th><th>State</th>
<th>Progress</th><th>Frames</th><th>relMSE</th><th>ETA</th><th></th></tr></thead>
<tbody></tbody></table>
<p><button id="more-jobs" hidden>More jobs</button></p>
<section id="detail" hidden>
<h2 id="detail-title"></h2>
<p id="detail-line" class="muted"></p>
<div id="frames"></div>
<p><button id="more-frames" hidden>More frames</button></p>
</section>
<h2>Workers</h2>
<table id="workers"><thead><tr><th>Worker</th><th>Host</th><th>Cores</th><th>Tags</th>
<th>Current tasks</th><th>Failures</th><th>Last contact</th></tr></thead>
<tbody></tbody></table>
<p><button id="more-workers" hidden>More workers</button></p>
</main>
</body>
</html>
)html";

inline constexpr const char* kMonitorCss = R"css(
body { font: 14px system-ui, sans-serif; margin: 0; color: #1d1d1f; background: #fafafa; }
header { display: flex; gap: 1em; align-items: center; padding: 0.5em 1em; background: #22262e;
         color: #eee; }
header h1 { font-size: 18px; margin: 0; }
main, section { padding: 0 1em 1em; }
table { border-collapse: collapse; width: 100%; background: #fff; }
th, td { text-align: left; padding: 4px 8px; border-bottom: 1px solid #e3e3e3; }
th { font-weight: 600; background: #f0f0f0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.bar { width: 120px; height: 10px; background: #e3e3e3; display: inline-block; }
.bar span { display: block; height: 100%; background: #3b82f6; }
.state-completed { color: #15803d; } .state-failed { color: #b91c1c; }
.state-cancelled { color: #6b7280; } .state-running { color: #1d4ed8; }
.error { color: #b91c1c; } .muted { color: #6b7280; }
button { margin-right: 4px; }
button.link { background: none; border: none; color: #1d4ed8; cursor: pointer; padding: 0;
              text-decoration: underline; font: inherit; }
#frames { display: flex; flex-wrap: wrap; gap: 12px; }
.frame { background: #fff; border: 1px solid #e3e3e3; padding: 8px; width: 540px; }
.frame img { width: 256px; image-rendering: pixelated; background: #000; vertical-align: top; }
.frame .plots { display: inline-flex; flex-direction: column; gap: 4px; margin-left: 8px; }
.plot { background: #fcfcfc; border: 1px solid #eee; }
.plot .curve { fill: none; stroke: #1d4ed8; stroke-width: 1.5; }
.plot .target { stroke: #b91c1c; stroke-dasharray: 4 3; }
.plot text { font-size: 10px; fill: #6b7280; }
)css";

inline constexpr const char* kMonitorJs = R"js(
"use strict";
let csrf = "";
let refreshTimer = null;
let pages = 1;
let workerPages = 1;
let openJob = null;
let framesShown = 12;
const $ = (id) => document.getElementById(id);

function text(tag, value, cls) {
  const el = document.createElement(tag);
  el.textContent = value === null || value === undefined ? "" : String(value);
  if (cls) el.className = cls;
  return el;
}

function duration(s) {
  if (s === null || s === undefined) return "-";
  if (s < 60) return Math.round(s) + " s";
  if (s < 3600) return Math.round(s / 60) + " min";
  return (s / 3600).toFixed(1) + " h";
}

async function api(method, path, body) {
  const opts = { method, credentials: "same-origin", headers: {} };
  if (method === "POST") {
    opts.headers["X-CSRF-Token"] = csrf;
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body || {});
  }
  const res = await fetch(path, opts);
  const data = await res.json().catch(() => ({}));
  if (res.status === 401) { showLogin(data.error || ""); throw new Error("logged out"); }
  if (!res.ok) throw new Error(data.error || res.statusText);
  return data;
}

function showLogin(message) {
  if (refreshTimer) { clearInterval(refreshTimer); refreshTimer = null; }
  $("app").hidden = true; $("logout").hidden = true; $("login").hidden = false;
  $("who").textContent = "";
  $("login-error").textContent = message || "";
}

function showApp(session) {
  csrf = session.csrf;
  $("login").hidden = true; $("app").hidden = false;
  $("logout").hidden = !!session.open;
  $("who").textContent = session.open ? "local (no token file)"
      : (session.admin ? "admin " : "tenant ") + session.tenant;
  refresh();
  if (!refreshTimer) refreshTimer = setInterval(refresh, 2000);
}

function jobButtons(job) {
  const td = document.createElement("td");
  const add = (label, op) => {
    const b = text("button", label);
    b.dataset.op = op; b.dataset.job = job.job_id;
    b.addEventListener("click", async () => {
      b.disabled = true;
      try { await api("POST", "/api/jobs/" + encodeURIComponent(job.job_id) + "/" + op); }
      catch (e) { $("status-line").textContent = op + " " + job.job_id + ": " + e.message; }
      refresh();
    });
    td.appendChild(b);
  };
  const ended = ["completed", "failed", "cancelled"].includes(job.state);
  if (!ended) add(job.paused ? "Resume" : "Pause", job.paused ? "resume" : "pause");
  if (!ended) add("Cancel", "cancel");
  if (job.state === "failed" || job.state === "cancelled") add("Retry", "retry");
  return td;
}

function jobRow(job) {
  const tr = document.createElement("tr");
  tr.id = "job-" + job.job_id;
  tr.dataset.state = job.state;
  const idCell = document.createElement("td");
  const open = text("button", job.job_id, "link");
  open.addEventListener("click", () => { openJob = job.job_id; framesShown = 12; refreshDetail(); });
  idCell.appendChild(open);
  tr.appendChild(idCell);
  tr.appendChild(text("td", job.name));
  tr.appendChild(text("td", job.tenant));
  const state = job.paused ? job.state + ", paused" : job.state;
  const st = text("td", state, "state-" + job.state);
  if (job.error) st.title = job.error;
  if (job.waiting_for) st.title = "waiting: " + job.waiting_for;
  tr.appendChild(st);
  const p = document.createElement("td");
  const bar = document.createElement("span"); bar.className = "bar";
  const fill = document.createElement("span");
  fill.style.width = (100 * job.progress).toFixed(1) + "%";
  bar.appendChild(fill); p.appendChild(bar);
  p.appendChild(text("span", " " + (100 * job.progress).toFixed(0) + "%"));
  tr.appendChild(p);
  tr.appendChild(text("td", job.frames_done + "/" + job.frames_total, "num"));
  tr.appendChild(text("td", job.worst_rel_mse === null ? "n/a" : job.worst_rel_mse.toPrecision(3), "num"));
  tr.appendChild(text("td", job.paused ? "paused" : duration(job.eta_seconds), "num"));
  tr.appendChild(jobButtons(job));
  return tr;
}

function workerRow(w) {
  const tr = document.createElement("tr");
  tr.appendChild(text("td", w.worker_id));
  tr.appendChild(text("td", w.hostname));
  tr.appendChild(text("td", w.cores, "num"));
  tr.appendChild(text("td", w.tags.join(", ")));
  tr.appendChild(text("td", w.tasks.length ? w.tasks.join(", ") : "idle"));
  tr.appendChild(text("td", w.failures, "num"));
  tr.appendChild(text("td", w.refused ? "refused: " + w.refused
      : (w.seconds_since_contact === null ? "not this run" : duration(w.seconds_since_contact) + " ago")));
  return tr;
}

async function refresh() {
  try {
    let jobs = [], after = "", page = 0, next = null;
    do {
      const q = "/api/jobs?limit=100" + (after ? "&after=" + encodeURIComponent(after) : "");
      const data = await api("GET", q);
      jobs = jobs.concat(data.jobs); next = data.next_after; after = next; page++;
    } while (next && page < pages);
    const tbody = $("jobs").tBodies[0];
    tbody.replaceChildren(...jobs.map(jobRow));
    $("more-jobs").hidden = !next;
    let workers = [], wafter = "", wpage = 0, wnext = null;
    do {
      const q = "/api/workers?limit=100" + (wafter ? "&after=" + encodeURIComponent(wafter) : "");
      const data = await api("GET", q);
      workers = workers.concat(data.workers); wnext = data.next_after; wafter = wnext; wpage++;
    } while (wnext && wpage < workerPages);
    $("workers").tBodies[0].replaceChildren(...workers.map(workerRow));
    $("more-workers").hidden = !wnext;
    $("status-line").textContent = jobs.length + (next ? "+" : "") + " jobs, " + workers.length +
        (wnext ? "+" : "") + " workers; updated " + new Date().toLocaleTimeString();
    await refreshDetail();
  } catch (e) {
    if (e.message !== "logged out") $("status-line").textContent = "update failed: " + e.message;
  }
}

const SVG = "http://www.w3.org/2000/svg";
function svg(tag, attrs) {
  const el = document.createElementNS(SVG, tag);
  for (const k in attrs) el.setAttribute(k, attrs[k]);
  return el;
}

// relMSE (log scale) against x (passes or seconds since the first point), the noise target
// dashed.
function plot(points, xOf, xLabel, target) {
  const W = 260, H = 110, L = 34, B = 16;
  const s = svg("svg", { width: W, height: H, class: "plot" });
  const pts = points.filter((p) => p[2] !== null);
  s.appendChild(svg("text", { x: L, y: H - 3 })).textContent = xLabel;
  if (!pts.length) {
    s.appendChild(svg("text", { x: L, y: H / 2 })).textContent = "relMSE n/a before two passes";
    return s;
  }
  const ys = pts.map((p) => Math.log10(p[2]));
  if (target) ys.push(Math.log10(target));
  let y0 = Math.floor(Math.min(...ys)), y1 = Math.ceil(Math.max(...ys));
  if (y1 === y0) y1 = y0 + 1;
  const xs = pts.map(xOf), x0 = Math.min(...xs), x1 = Math.max(...xs, x0 + 1e-9);
  const X = (v) => L + (W - L - 6) * (v - x0) / (x1 - x0);
  const Y = (v) => 10 + (H - B - 14) * (y1 - v) / (y1 - y0);
  for (let e = y0; e <= y1; e++) {
    s.appendChild(svg("text", { x: 2, y: Y(e) + 3 })).textContent = "1e" + e;
  }
  if (target) s.appendChild(svg("line", { x1: L, x2: W - 6, y1: Y(Math.log10(target)),
                                          y2: Y(Math.log10(target)), class: "target" }));
  s.appendChild(svg("polyline", { class: "curve",
      points: pts.map((p) => X(xOf(p)).toFixed(1) + "," + Y(Math.log10(p[2])).toFixed(1)).join(" ") }));
  s.appendChild(svg("text", { x: W - 70, y: H - 3 })).textContent =
      xOf(pts[pts.length - 1]).toFixed(0) + " " + xLabel.split(" ")[0];
  return s;
}

async function frameCard(job, f) {
  const card = document.createElement("div");
  card.className = "frame"; card.id = "frame-" + f.frame;
  card.appendChild(text("div", "frame " + f.frame + ": " + f.passes_merged + "/" + f.passes_total +
      " passes, " + Math.round(f.spp) + " spp, relMSE " +
      (f.rel_mse === null ? "n/a" : f.rel_mse.toPrecision(3)) +
      (f.done ? ", done" : ", ETA " + duration(f.eta_seconds))));
  if (f.passes_merged > 0) {
    const img = document.createElement("img");
    img.alt = "frame " + f.frame;
    img.className = "preview";
    // A new URL only when the merged prefix changes: the browser fetches only then.
    img.src = "/api/jobs/" + encodeURIComponent(job.job_id) + "/frames/" + f.frame +
        "/preview.png?passes=" + f.passes_merged + "&run=" + f.run;
    card.appendChild(img);
    const h = await api("GET", "/api/jobs/" + encodeURIComponent(job.job_id) + "/frames/" +
        f.frame + "/history");
    const plots = document.createElement("div"); plots.className = "plots";
    const t0 = h.points.length ? h.points[0][0] : 0;
    plots.appendChild(plot(h.points, (p) => p[1], "passes", h.noise_target));
    plots.appendChild(plot(h.points, (p) => p[0] - t0, "seconds", h.noise_target));
    card.appendChild(plots);
  }
  return card;
}

async function refreshDetail() {
  if (!openJob) return;
  try {
    const job = await api("GET", "/api/jobs/" + encodeURIComponent(openJob) + "?frames=" +
        (framesShown + 1));
    $("detail").hidden = false;
    $("detail-title").textContent = job.job_id + " " + job.name;
    $("detail-line").textContent = job.state + ", scene " + job.scene_path +
        (job.noise_target ? ", noise target " + job.noise_target : "") +
        (job.error ? ", " + job.error : "");
    const frames = job.frames.slice(0, framesShown);
    const cards = [];
    for (const f of frames) {
      const old = document.getElementById("frame-" + f.frame);
      // Unchanged frames keep their card (and image): no refetch, no flicker.
      if (old && old.dataset.key === f.passes_merged + "/" + f.run + "/" + f.done) {
        cards.push(old); continue;
      }
      const card = await frameCard(job, f);
      card.dataset.key = f.passes_merged + "/" + f.run + "/" + f.done;
      cards.push(card);
    }
    $("frames").replaceChildren(...cards);
    $("more-frames").hidden = job.frames_total <= framesShown;
  } catch (e) {
    if (e.message !== "logged out") $("detail-line").textContent = "update failed: " + e.message;
  }
}

async function start() {
  $("login-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    try {
      const res = await fetch("/api/login", { method: "POST", credentials: "same-origin",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ token: $("token").value }) });
      const data = await res.json().catch(() => ({}));
      $("token").value = "";
      if (!res.ok) { $("login-error").textContent = data.error || res.statusText; return; }
      showApp(data);
    } catch (e) { $("login-error").textContent = e.message; }
  });
  $("logout").addEventListener("click", async () => {
    try { await api("POST", "/api/logout"); } catch (e) {}
    showLogin("");
  });
  $("more-jobs").addEventListener("click", () => { pages++; refresh(); });
  $("more-workers").addEventListener("click", () => { workerPages++; refresh(); });
  $("more-frames").addEventListener("click", () => { framesShown += 12; refreshDetail(); });
  try {
    const res = await fetch("/api/session", { credentials: "same-origin" });
    if (res.ok) return showApp(await res.json());
    // No token file: a session for the asking (the port is loopback only).
    const open = await fetch("/api/login", { method: "POST", credentials: "same-origin",
      headers: { "Content-Type": "application/json" }, body: "{}" });
    const data = await open.json().catch(() => ({}));
    if (open.ok && data.open) return showApp(data);
  } catch (e) {}
  showLogin("");
}

start();
)js";

}  // namespace rf
