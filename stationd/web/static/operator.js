// Operator screen: draws the snapshot the server pushes (server-sent events); no logic of its
// own beyond layout: the daemon decides, the screen shows.
"use strict";
const NS = "http://www.w3.org/2000/svg";
const ICONS = {pending: "\u25CB", next: "\u25B6", selected: "\u2691", tightening: "\u21BB",
  ok: "\u2714", nok: "\u2716", skipped: "\u00BB", blocked: "\u2298", missing: "!",
  locked: "\u2297", loosen: "\u21BA", loosened: "\u21B6"};
const LABELS = {pending: "to do", next: "next", selected: "selected", tightening: "tighten",
  ok: "OK", nok: "NOK", skipped: "skipped", blocked: "blocked", missing: "missing",
  locked: "locked", loosen: "loosen first", loosened: "loosened"};
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
    span.innerHTML = `<span class="sw sw-${s}"></span>${ICONS[s]} ${LABELS[s]}`;
    L.appendChild(span);
  }
}

// The map is rebuilt only when the bolts or the screen's size change (a state, a label, a
// resize); a snapshot that only moves the wrench (most of them: up to 10 a second while it
// is carried) moves its mark and nothing else.  The browser often runs on the station's own
// cores: a full redraw per snapshot cost it a tenth of a core, taken from the vision.
let mapKey = "", toMap = null;
function drawMap(view) {
  const svg = $("bolts");
  const box = $("map").getBoundingClientRect();
  const W = Math.max(200, box.width), H = Math.max(150, box.height);
  const bolts = view.bolts;
  const key = `${W}x${H}|${JSON.stringify(bolts)}`;
  if (key !== mapKey) {
    mapKey = key;
    toMap = buildMap(svg, bolts, W, H);
  }
  drawWrench(svg, view.wrench, W, H);
}

const R_FLOOR = 6;   // px: the smallest dot that still shows its icon
function buildMap(svg, bolts, W, H) {
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  svg.replaceChildren();
  if (!bolts.length) return null;
  // the frame is the bolts' (a wrench beyond them is drawn at the edge): the map does not
  // rescale as the wrench moves
  const xs = bolts.map((b) => b.x), ys = bolts.map((b) => b.y);
  const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
  const span = Math.max(x1 - x0, y1 - y0, 100);
  // a margin for the labels of the outer bolts, smaller on a short panel (the bolts' spread
  // is what keeps their dots apart)
  const pad = Math.max(50, Math.min(100, 0.15 * Math.min(W, H))), s = Math.min((W - 2 * pad) / Math.max(x1 - x0, span * 0.2),
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
  // the dots never overlap: the radius follows the closest two bolts (their 3 px outlines
  // included), down to a floor that keeps the icon readable; only bolts closer than twice
  // the floor (none on config/sim's vehicle at 1280x657) could still touch
  const r = Math.max(R_FLOOR, Math.min(44, s * span / 20, (dmin - 5) / 2));
  const dense = r < 22;
  svg.classList.toggle("dense", dense);
  const placed = [];   // bolt -> [group, x, y]
  for (const b of bolts) {
    const x = X(b.x), y = Y(b.y);
    const g = el("g", {class: `bolt bolt-${b.state}`, "data-bolt": b.bolt, "data-state": b.state,
      transform: `translate(${x.toFixed(1)},${y.toFixed(1)})`});
    g.appendChild(el("title", {}, `${b.bolt}: ${b.label}${b.reason ? " (" + b.reason + ")" : ""}`));
    g.appendChild(el("circle", {r: r}));
    const icon = el("text", {class: "icon", y: 0}, ICONS[b.state] || "?");
    if (dense) icon.style.fontSize = `${Math.round(1.3 * r)}px`;   // inside its dot
    g.appendChild(icon);
    svg.appendChild(g);
    placed.push([b, g, x, y]);
  }
  placeLabels(placed, r, dense, W, H);
  return [X, Y];
}

function drawWrench(svg, w, W, H) {
  let g = document.getElementById("wrench-mark");
  if (!toMap || !w || w.x === undefined) {
    if (g) g.remove();
    return;
  }
  if (!g) {
    g = document.createElement("div");
    g.id = "wrench-mark";
    const mark = el("svg", {viewBox: "-30 -30 60 60"});
    mark.appendChild(el("circle", {r: 12}));
    mark.appendChild(el("line", {x1: -26, y1: 0, x2: 26, y2: 0}));
    mark.appendChild(el("line", {x1: 0, y1: -26, x2: 0, y2: 26}));
    g.appendChild(mark);
    $("map").appendChild(g);
  }
  const [X, Y] = toMap;
  // map units are CSS pixels (the view box is the map's own size)
  const x = Math.min(W - 14, Math.max(14, X(w.x))), y = Math.min(H - 14, Math.max(14, Y(w.y)));
  const cls = "wrench-mark" + (w.lost ? " wrench-lost" : "");
  if (g.className !== cls) g.className = cls;
  g.style.transform = `translate(${x.toFixed(1)}px,${y.toFixed(1)}px)`;
}

// Each bolt's label (its id, and its state words when they matter) goes where it collides
// with no other label and covers no bolt: greedy, the bolts that matter now first, trying
// above, below, right, left, the diagonals, then farther out.  A label that finds no room is
// hidden (shown on hover); the bolt keeps its coloured symbol and state icon, so colour is
// still never the only cue.
const PRIORITY = {selected: 0, tightening: 0, locked: 1, loosen: 1, nok: 1, blocked: 1, next: 2,
  missing: 2};
// A label must read as its own bolt's: it is kept only where its box is nearer its own dot
// than any other dot by NEARER px (the box's nearest edge to the dot's centre: what the eye
// pairs), else it is hidden and shown on hover (a label 22 px from B20 and 56 px from B36
// was read as B20's); NEARER covers the box measured here being 3 px larger than drawn
const NEARER = 4;
function boxDist(box, px, py) {
  const dx = Math.max(box[0] - px, 0, px - box[2]), dy = Math.max(box[1] - py, 0, py - box[3]);
  return Math.hypot(dx, dy);
}
function readsAsOwn(box, x, y, dots) {
  const own = boxDist(box, x, y);
  for (const [ox, oy] of dots)
    if (!(ox === x && oy === y) && boxDist(box, ox, oy) < own + NEARER) return false;
  return true;
}
// The map is redrawn with every snapshot (up to 10 a second, the wrench moving): the
// placement is recomputed only when a label or the layout changed, and each label text is
// measured once, so a redraw costs the browser (often on the station's own cores) no layout.
let lastPlacement = {key: "", at: new Map()};
// above, below, the sides, the diagonals, then between them (a label beside a cluster)
const DIRS = [[0, -1], [0, 1], [1, 0], [-1, 0], [1, -1], [-1, -1], [1, 1], [-1, 1],
  [0.5, -1], [-0.5, -1], [0.5, 1], [-0.5, 1], [1, -0.5], [-1, -0.5], [1, 0.5], [-1, 0.5]];
const measured = new Map();
function placeLabels(placed, r, dense, W, H) {
  const hit = (a, b) => a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
  const gap = dense ? 2 : 5;
  const labels = placed.map(([b, g, x, y]) => {
    let tag = b.label;
    // the pset that goes to the controller: a bolt to loosen gets its loosen pset first
    const on = b.state === "selected" || b.state === "tightening";
    if (on && b.loosen && b.loosen_pset !== null) tag += ` P${b.loosen_pset}`;
    else if (b.state === "selected" && b.pset !== null) tag += ` P${b.pset}`;
    if (b.state === "loosen" && b.loosen_pset !== null) tag += ` P${b.loosen_pset}`;
    if ((b.state === "ok" || b.state === "nok") && b.torque_nm !== null) tag += ` ${fmt(b.torque_nm, 1)}`;
    const matters = ["selected", "tightening", "nok", "blocked", "locked", "loosen"].includes(b.state);
    if (dense && !matters) tag = null;
    const lbl = el("g", {class: "lbl"});
    lbl.appendChild(el("text", {class: "bolt-id", y: 0}, b.bolt));
    if (tag !== null) lbl.appendChild(el("text", {class: "tag label", y: dense ? 15 : 26}, tag));
    g.appendChild(lbl);
    return {b, lbl, x, y, text: `${dense}|${b.bolt}|${tag}`};
  });
  const key = `${W}x${H}|${r}|` + labels.map((l) => `${l.text}@${l.x.toFixed(1)},${l.y.toFixed(1)}`).join(";");
  if (key !== lastPlacement.key) {
    if (measured.size > 5000) measured.clear();   // torque texts accumulate over vehicles
    const at = new Map();
    const taken = labels.map(({x, y}) => [x - r, y - r, x + r, y + r]);   // the symbols
    const dots = labels.map(({x, y}) => [x, y]);
    const order = [...labels].sort((p, q) => (PRIORITY[p.b.state] ?? 3) - (PRIORITY[q.b.state] ?? 3));
    for (const {lbl, x, y, text} of order) {
      if (!measured.has(text)) {
        const bb = lbl.getBBox();
        measured.set(text, {x: bb.x, y: bb.y, width: bb.width, height: bb.height});
      }
      // getBBox leaves out the text's 4 px outline stroke (Firefox's screen box includes it)
      const bb = measured.get(text), w = bb.width + 6, h = bb.height + 6;
      // a bolt with a close neighbour tries the side away from it first (the pair's labels
      // go outward, not both into the gap between them)
      let nx = 0, ny = 0, nd = Infinity;
      for (const [ox, oy] of dots) {
        const d = Math.hypot(ox - x, oy - y);
        if (d > 0 && d < nd) [nx, ny, nd] = [(ox - x) / d, (oy - y) / d, d];
      }
      const dirs = nd < 6 * r ? [...DIRS].sort((a, b) => (a[0] * nx + a[1] * ny) /
        Math.hypot(...a) - (b[0] * nx + b[1] * ny) / Math.hypot(...b)) : DIRS;
      let best = null;
      for (const k of [0, 0.5, 1.2]) {
        for (const [dx, dy] of dirs) {
          // the label's edge just off the symbol in that direction (farther out: k * r)
          const cx = x + dx * (r + k * r + gap + w / 2), cy = y + dy * (r + k * r + gap + h / 2);
          const box = [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2];
          if (box[0] < 0 || box[1] < 0 || box[2] > W || box[3] > H) continue;
          if (taken.some((t) => hit(t, box))) continue;
          if (!readsAsOwn(box, x, y, dots)) continue;
          best = [cx, cy, box];
          break;
        }
        if (best) break;
      }
      if (best) {
        taken.push(best[2]);
        at.set(text, [false, `translate(${(best[0] - x - bb.x - bb.width / 2).toFixed(1)},` +
          `${(best[1] - y - bb.y - bb.height / 2).toFixed(1)})`]);
      } else
        at.set(text, [true, `translate(0,${(-r - gap - bb.y - bb.height).toFixed(1)})`]);
    }
    lastPlacement = {key, at};
  }
  for (const {lbl, text} of labels) {
    const [hidden, transform] = lastPlacement.at.get(text);
    lbl.setAttribute("transform", transform);
    if (hidden) lbl.setAttribute("class", "lbl hidden");
  }
}

// a text is written only when it changed: rewriting the same words still costs the browser
// a style and layout pass, ten times a second
function setText(id, text) {
  const e = $(id);
  if (e.textContent !== String(text)) e.textContent = text;
}

function render(view) {
  window.lastView = view;
  setText("vin", view.vehicle ? view.vehicle.vin : "no vehicle");
  setText("model", view.vehicle ? view.vehicle.model + (view.vehicle.rework ? " (rework)" : "") : "");
  setText("state", view.state);
  setText("done", view.counters.done);
  setText("total", view.counters.total);
  setText("nok", view.counters.nok);
  $("nok-wrap").style.color = view.counters.nok ? "" : "var(--dim)";
  const h = $("headline");
  setText("headline", view.headline);
  h.title = view.headline_title || view.headline;   // a closed vehicle's every bolt
  // red: fault, stop; amber: a refusal the operator resolves; neutral: the wrench is not on a
  // bolt (a normal state between bolts, never shown as an alarm)
  h.className = "headline " + (view.tone || "");
  h.dataset.tone = view.tone || "";
  drawMap(view);
  drawLocks(view);
  const w = view.wrench;
  // the per-pair reasons of a wrench out of view are the commissioning screen's business:
  // here one line, the full text on hover
  $("wrench").title = w && w.lost ? w.reason : "";
  setText("wrench", !w ? "not localized" : w.lost ? "not in view (details: Cameras)" :
    `X ${fmt(w.x, 0)}  Y ${fmt(w.y, 0)}  Z ${fmt(w.z, 0)} mm, tilt ${fmt(w.tilt, 1)}\u00B0` +
    (w.candidate ? `, near ${w.candidate} (${fmt(w.distance, 1)} mm)` : ""));
  const results = view.results.slice(0, 6);
  const rkey = JSON.stringify(results), dkey = JSON.stringify([view.devices, lineShown(view.line)]);
  if (rkey !== shownKeys.results) { shownKeys.results = rkey; drawResults(results); }
  if (dkey !== shownKeys.devices) { shownKeys.devices = dkey; drawDevices(view.devices, view.line); }
}

// Locked bolts (too many NOKs in a row), and who may release them: the roles with the
// release right in the station's access section (the station says, the screen shows)
function drawLocks(view) {
  const locks = view.locks || [], by = view.release_by || [];
  const key = JSON.stringify([locks, by]);
  if (key === shownKeys.locks) return;
  shownKeys.locks = key;
  $("locks").hidden = !locks.length;
  document.body.classList.toggle("has-locks", locks.length > 0);
  const ul = $("locks-list");
  ul.replaceChildren(...locks.map((text) => {
    const li = document.createElement("li");
    li.textContent = text;
    return li;
  }));
  setText("release-by", by.length ? `Release: a user with the release right (${by.join(", ")})`
    : "Release: no role of this station has the release right (access.roles)");
}

// what the tables show now: they are redrawn only when it changed
const shownKeys = {results: "", devices: "", locks: ""};

function drawResults(results) {
  const tb = $("results");
  tb.replaceChildren();
  for (const r of results) {
    const tr = document.createElement("tr");
    tr.className = r.ok ? "res-ok" : "res-nok";
    const lim = (v, lo, hi, d) => {
      const out = (lo !== null && v < lo) || (hi !== null && v > hi);
      const rng = lo !== null || hi !== null ? ` [${fmt(lo, d)}-${fmt(hi, d)}]` : "";
      // a range stays on one line ("[22.0-" / "28.0]" wrapped at 1280 px)
      return `<span class="${out ? "out" : ""}">${fmt(v, d)}</span> <small class="rng">${rng.trim()}</small>`;
    };
    tr.innerHTML = `<td>${esc(r.bolt)} ${r.ok ? "OK" : "NOK"}</td>` +
      `<td>${lim(r.torque_nm, r.torque_min, r.torque_max, 1)}</td>` +
      `<td>${lim(r.angle_deg, r.angle_min, r.angle_max, 0)}</td>`;
    tb.appendChild(tr);
  }
}

// The line database (store and forward): never a fault of the station, so never red; amber
// while it is down or past its bounds, with how many records wait
function lineShown(line) {
  if (!line) return null;
  const text = line.alarm ? `line database: ${line.alarm}` :
    line.up === false ? `line database down: ${line.backlog} record(s) wait` :
    `line database: ${line.backlog} behind`;
  return {text, ok: !line.alarm && line.up !== false, title: line.last_error || line.url};
}

function drawDevices(devices, line) {
  const ul = $("devices");
  ul.replaceChildren();
  const l = lineShown(line);
  if (l) {
    const li = document.createElement("li");
    li.className = l.ok ? "dev-ok" : "dev-wait";
    li.dataset.device = "line";
    li.textContent = l.text;
    li.title = l.title || "";
    ul.appendChild(li);
  }
  // the faulty first, each on its own lines (a long URL wraps); the healthy on one line.  A
  // pair that is up but not trusted by the calibration check counts as faulty here: moved
  // (red, with the figure) or not checked yet (neutral, with why); its bolts are refused
  const fine = (d) => d.ok && (!d.check || d.check.trusted);
  const devs = Object.entries(devices).sort((a, b) => Number(fine(a[1])) - Number(fine(b[1])));
  for (const [name, d] of devs) {
    const li = document.createElement("li");
    const check = d.ok ? d.check : null;
    li.className = !d.ok ? (d.kind === "opening" ? "dev-wait" : "dev-bad") :
      !check || check.trusted ? "dev-ok" : check.verdict === "moved" ? "dev-bad" : "dev-wait";
    li.dataset.device = name;
    li.dataset.trust = !check ? "" : check.trusted ? "trusted" : check.verdict;
    li.textContent = !d.ok ? `${name} ${d.kind}: ${d.reason}` :
      !check ? `${name}: ok` : check.trusted ? `${name}: ok, trusted` : check.words;
    // what the device said it is (the controller's name, versions), its last check: on hover
    const title = [d.identity, check && check.trusted ? check.words : ""].filter(Boolean);
    if (title.length) li.title = title.join("\n");
    ul.appendChild(li);
  }
}

// A screen that no longer hears the station must not look live: a green "ok" or a "tighten"
// left standing after the daemon stopped would be believed.  LOST_MS after the stream
// broke (the browser retries every second: a daemon restarting is back within that) the
// content is dimmed, the headline says so and no device is shown "ok"; the next snapshot
// brings it all back.
const LOST_MS = 2000;
const NOT_LIVE = "No connection to the station: this screen is not live";
let lostTimer = null;
function notLive() {
  document.body.classList.add("not-live");
  $("conn").hidden = false;
  const h = $("headline");
  setText("headline", NOT_LIVE);
  h.title = NOT_LIVE;
  h.className = "headline stop";
  h.dataset.tone = "offline";
  for (const li of $("devices").querySelectorAll("li")) {
    li.className = "dev-unknown";
    li.textContent = `${li.dataset.device}: unknown`;
  }
  shownKeys.devices = "";   // redrawn from the next snapshot
  setText("state", "not live");
}
// The server sends its snapshot again every heartbeat_s when nothing happens: a stream
// silent for three of them has stalled without breaking (a dead link, a hung daemon), which
// onerror never hears; the screen then says it is not live and connects again.
// After a stall the new stream's first message is the server's last snapshot, which proves
// only that its HTTP server answers: the screen is live again from the next one (an update
// or a heartbeat: the station feeds it), not before.
let silentTimer = null;
function connect(afterStall = false) {
  const es = new EventSource("/api/events");
  const stalled = () => { notLive(); es.close(); connect(true); };
  let waitFresh = afterStall;
  es.onmessage = (m) => {
    const view = JSON.parse(m.data);
    clearTimeout(silentTimer);
    if (view.heartbeat_s) silentTimer = setTimeout(stalled, 3000 * view.heartbeat_s);
    if (waitFresh) { waitFresh = false; return; }
    clearTimeout(lostTimer);
    lostTimer = null;
    document.body.classList.remove("not-live");
    $("conn").hidden = true;
    render(view);
  };
  es.onerror = () => {
    if (lostTimer === null) lostTimer = setTimeout(notLive, LOST_MS);
    // a refused reconnection (an HTTP error) ends the browser's own retries: retry here
    if (es.readyState === EventSource.CLOSED) { es.close(); setTimeout(connect, 1000); }
  };
}
legend();
window.addEventListener("resize", () => { if (window.lastView) drawMap(window.lastView); });
connect();
