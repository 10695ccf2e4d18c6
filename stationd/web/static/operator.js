// Operator screen: draws the snapshot the server pushes (server-sent events); no logic of its
// own beyond layout: the daemon decides, the screen shows.
"use strict";
const NS = "http://www.w3.org/2000/svg";
const ICONS = {pending: "\u25CB", next: "\u25B6", selected: "\u2691", tightening: "\u21BB",
  ok: "\u2714", nok: "\u2716", skipped: "\u00BB", blocked: "\u2298"};
const LABELS = {pending: "to do", next: "next", selected: "selected", tightening: "tighten",
  ok: "OK", nok: "NOK", skipped: "skipped", blocked: "blocked"};
const $ = (id) => document.getElementById(id);

function el(tag, attrs, text) {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}
function esc(s) { return String(s).replace(/[&<>"]/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", "\"": "&quot;"})[c]); }
function fmt(v, d) { return v === null || v === undefined ? "-" : Number(v).toFixed(d); }

function legend() {
  const L = $("legend");
  for (const s of Object.keys(LABELS)) {
    const span = document.createElement("span");
    span.innerHTML = `<span class="sw" style="background:var(--${s})"></span>${ICONS[s]} ${LABELS[s]}`;
    L.appendChild(span);
  }
}

function drawMap(view) {
  const svg = $("bolts");
  const box = $("map").getBoundingClientRect();
  const W = Math.max(200, box.width), H = Math.max(150, box.height);
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  svg.replaceChildren();
  const bolts = view.bolts;
  if (!bolts.length) return;
  const pts = bolts.map((b) => [b.x, b.y]);
  if (view.wrench && !view.wrench.lost) pts.push([view.wrench.x, view.wrench.y]);
  let x0 = Math.min(...pts.map((p) => p[0])), x1 = Math.max(...pts.map((p) => p[0]));
  let y0 = Math.min(...pts.map((p) => p[1])), y1 = Math.max(...pts.map((p) => p[1]));
  const span = Math.max(x1 - x0, y1 - y0, 100);
  const pad = 100, s = Math.min((W - 2 * pad) / Math.max(x1 - x0, span * 0.2),
                               (H - 2 * pad) / Math.max(y1 - y0, span * 0.2));
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  // vehicle X to the right, vehicle Y up (a top view)
  const X = (x) => W / 2 + (x - cx) * s, Y = (y) => H / 2 - (y - cy) * s;
  // symbols as large as the nearest two bolts allow (a 50-bolt underbody on a 1280x800 panel
  // must not pile up); when dense, only the bolts that matter now keep their state words
  let dmin = Infinity;
  for (let i = 0; i < bolts.length; i++)
    for (let j = i + 1; j < bolts.length; j++)
      dmin = Math.min(dmin, Math.hypot(X(bolts[i].x) - X(bolts[j].x), Y(bolts[i].y) - Y(bolts[j].y)));
  const r = Math.max(9, Math.min(44, s * span / 20, 0.42 * dmin));
  const dense = r < 22;
  svg.classList.toggle("dense", dense);
  for (const b of bolts) {
    const g = el("g", {class: `bolt bolt-${b.state}`, "data-bolt": b.bolt, "data-state": b.state,
      transform: `translate(${X(b.x).toFixed(1)},${Y(b.y).toFixed(1)})`});
    g.appendChild(el("title", {}, `${b.bolt}: ${b.label}${b.reason ? " (" + b.reason + ")" : ""}`));
    g.appendChild(el("circle", {r: r}));
    g.appendChild(el("text", {class: "icon", y: 0}, ICONS[b.state] || "?"));
    g.appendChild(el("text", {class: "bolt-id", y: -r - (dense ? 4 : 10)}, b.bolt));
    let tag = b.label;
    if (b.state === "selected" && b.pset !== null) tag += ` P${b.pset}`;
    if ((b.state === "ok" || b.state === "nok") && b.torque_nm !== null) tag += ` ${fmt(b.torque_nm, 1)}`;
    const matters = ["selected", "tightening", "nok", "blocked"].includes(b.state);
    if (!dense || matters)
      g.appendChild(el("text", {class: "tag label", y: r + (dense ? 16 : 28)}, tag));
    svg.appendChild(g);
  }
  const w = view.wrench;
  if (w && w.x !== undefined) {
    const g = el("g", {class: "wrench-mark" + (w.lost ? " wrench-lost" : ""), id: "wrench-mark",
      transform: `translate(${X(w.x).toFixed(1)},${Y(w.y).toFixed(1)})`});
    g.appendChild(el("circle", {r: 12}));
    g.appendChild(el("line", {x1: -26, y1: 0, x2: 26, y2: 0}));
    g.appendChild(el("line", {x1: 0, y1: -26, x2: 0, y2: 26}));
    svg.appendChild(g);
  }
}

function render(view) {
  window.lastView = view;
  $("vin").textContent = view.vehicle ? view.vehicle.vin : "no vehicle";
  $("model").textContent = view.vehicle ? view.vehicle.model + (view.vehicle.rework ? " (rework)" : "") : "";
  $("state").textContent = view.state;
  $("done").textContent = view.counters.done;
  $("total").textContent = view.counters.total;
  $("nok").textContent = view.counters.nok;
  $("nok-wrap").style.color = view.counters.nok ? "" : "var(--dim)";
  const h = $("headline");
  h.textContent = view.headline;
  h.title = view.headline;
  const stop = view.alarm || view.state === "fault" || view.refused ||
    Object.values(view.devices).some((d) => !d.ok);
  h.className = "headline " + (stop ? "stop" : view.selected ? "go" :
    view.counters.total && view.counters.done === view.counters.total ? "done" : "");
  drawMap(view);
  const w = view.wrench;
  $("wrench").textContent = !w ? "not localized" : w.lost ? `lost: ${w.reason}` :
    `X ${fmt(w.x, 0)}  Y ${fmt(w.y, 0)}  Z ${fmt(w.z, 0)} mm, tilt ${fmt(w.tilt, 1)}\u00B0` +
    (w.candidate ? `, near ${w.candidate} (${fmt(w.distance, 1)} mm)` : "");
  const tb = $("results");
  tb.replaceChildren();
  for (const r of view.results.slice(0, 6)) {
    const tr = document.createElement("tr");
    tr.className = r.ok ? "res-ok" : "res-nok";
    const lim = (v, lo, hi, d) => {
      const out = (lo !== null && v < lo) || (hi !== null && v > hi);
      const rng = lo !== null || hi !== null ? ` [${fmt(lo, d)}-${fmt(hi, d)}]` : "";
      return `<span class="${out ? "out" : ""}">${fmt(v, d)}</span><small>${rng}</small>`;
    };
    tr.innerHTML = `<td>${esc(r.bolt)} ${r.ok ? "OK" : "NOK"}</td>` +
      `<td>${lim(r.torque_nm, r.torque_min, r.torque_max, 1)}</td>` +
      `<td>${lim(r.angle_deg, r.angle_min, r.angle_max, 0)}</td>`;
    tb.appendChild(tr);
  }
  const ul = $("devices");
  ul.replaceChildren();
  for (const [name, d] of Object.entries(view.devices)) {
    const li = document.createElement("li");
    li.className = d.ok ? "dev-ok" : "dev-bad";
    li.dataset.device = name;
    li.textContent = d.ok ? `${name}: ok` : `${name}: ${d.kind} ${d.reason}`;
    ul.appendChild(li);
  }
}

function connect() {
  const es = new EventSource("/api/events");
  es.onmessage = (m) => { $("conn").hidden = true; render(JSON.parse(m.data)); };
  es.onerror = () => { $("conn").hidden = false; };
}
legend();
window.addEventListener("resize", () => { if (window.lastView) drawMap(window.lastView); });
connect();
