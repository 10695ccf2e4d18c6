// Operator screen: draws the snapshot the server pushes (server-sent events); no logic of its
// own beyond layout: the daemon decides, the screen shows.
"use strict";
const NS = "http://www.w3.org/2000/svg";
const ICONS = {pending: "\u25CB", next: "\u25B6", selected: "\u2691", tightening: "\u21BB",
  ok: "\u2714", nok: "\u2716", skipped: "\u00BB", blocked: "\u2298", missing: "!",
  locked: "\u2297", held: "?", check: "\u26A0", loosen: "\u21BA", loosened: "\u21B6"};
const LABELS = {pending: "to do", next: "next", selected: "selected", tightening: "tighten",
  ok: "OK", nok: "NOK", skipped: "skipped", blocked: "blocked", missing: "missing",
  locked: "locked", held: "held", check: "check first", loosen: "loosen first",
  loosened: "loosened"};
// a held bolt (its result not known: unreadable, a link cut's, a lost push's) is refused as a
// locked one is, and drawn apart: it is no lock of NOKs (a supervisor's trial)
// A bolt released from a hold and open again may be tightened already: drawn apart from "to
// do" (a supervisor's trial: the operator read "to do" and tightened it twice)
const drawn = (b) => (b.state === "locked" && b.held ? "held"
  : b.check_first && (b.state === "pending" || b.state === "next") ? "check" : b.state);
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
    const g = el("g", {class: `bolt bolt-${drawn(b)}`, "data-bolt": b.bolt, "data-state": b.state,
      transform: `translate(${x.toFixed(1)},${y.toFixed(1)})`});
    g.appendChild(el("title", {}, `${b.bolt}: ${b.label}${b.reason ? " (" + b.reason + ")" : ""}`));
    g.appendChild(el("circle", {r: r}));
    const icon = el("text", {class: "icon", y: 0}, ICONS[drawn(b)] || "?");
    if (dense) icon.style.fontSize = `${Math.round(1.3 * r)}px`;   // inside its dot
    g.appendChild(icon);
    svg.appendChild(g);
    placed.push([b, g, x, y]);
  }
  placeLabels(placed, r, dense, W, H);
  return [X, Y];
}

// the crosshair only where the wrench is now: out of view (or seen and refused) there is none,
// as the wrench panel and the headline say (a grey one left where it was last seen, on a
// bolt, read as the wrench on that bolt)
function drawWrench(svg, w, W, H) {
  let g = document.getElementById("wrench-mark");
  if (!toMap || !w || w.lost || w.x === undefined) {
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
  if (g.className !== "wrench-mark") g.className = "wrench-mark";
  g.style.transform = `translate(${x.toFixed(1)}px,${y.toFixed(1)}px)`;
}

// Each bolt's label (its id, and its state words when they matter) goes where it collides
// with no other label and covers no bolt: greedy, the bolts that matter now first, trying
// above, below, right, left, the diagonals, then farther out; in a cluster, where no place
// beside its dot reads as its own, farther still with a leader line to its dot.  A label
// that finds no room is hidden (shown on hover); the bolt keeps its coloured symbol and
// state icon, so colour is still never the only cue.
const PRIORITY = {selected: 0, tightening: 0, next: 1, locked: 1, loosen: 1, nok: 1, blocked: 1,
  check: 1, missing: 2};
// A label must read as its own bolt's: it is kept only where its own dot is clearly the
// nearest, by the box's nearest edge (what the eye pairs first) and by its centre (where
// the eye lands: "B21" 14 px from B21 and 20 px from B25, its centre between the two, was
// read as B25's), each by a margin that grows with the distance (a label far from its dot
// needs a clearer lead); else it is hidden and shown on hover.  The margins also cover the
// box measured here being 3 px larger than drawn.
const NEARER = 8, CENTRE_NEARER = 6, LEAD = 0.35;
function boxDist(box, px, py) {
  const dx = Math.max(box[0] - px, 0, px - box[2]), dy = Math.max(box[1] - py, 0, py - box[3]);
  return Math.hypot(dx, dy);
}
function readsAsOwn(box, x, y, dots) {
  const own = boxDist(box, x, y);
  const cx = (box[0] + box[2]) / 2, cy = (box[1] + box[3]) / 2, ownC = Math.hypot(cx - x, cy - y);
  for (const [ox, oy] of dots) {
    if (ox === x && oy === y) continue;
    if (boxDist(box, ox, oy) < own * (1 + LEAD) + NEARER) return false;
    if (Math.hypot(cx - ox, cy - oy) < ownC * (1 + LEAD) + CENTRE_NEARER) return false;
  }
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
    // a NOK shows the value that failed: its angle where only the angle was out of its
    // window ("NOK 50.8" read as a torque fault for an angle of 0 deg)
    if (b.state === "nok" && b.failed === "angle" && b.angle_deg !== null) tag += ` ${fmt(b.angle_deg, 0)}\u00b0`;
    else if ((b.state === "ok" || b.state === "nok") && b.torque_nm !== null) tag += ` ${fmt(b.torque_nm, 1)}`;
    // the one bolt pointed out "next" says so (the others are "to do"); a held one says
    // "held" as a locked one says "locked" (a new user's trial: its icon alone on the map)
    const matters = ["selected", "tightening", "next", "nok", "blocked", "locked", "held",
      "loosen", "check"].includes(drawn(b));
    if (dense && !matters) tag = null;
    const lbl = el("g", {class: "lbl"});
    lbl.appendChild(el("text", {class: "bolt-id", y: 0}, b.bolt));
    if (tag !== null) lbl.appendChild(el("text", {class: "tag label", y: dense ? 15 : 26}, tag));
    g.appendChild(lbl);
    return {b, g, lbl, x, y, text: `${dense}|${b.bolt}|${tag}`};
  });
  const key = `${W}x${H}|${r}|` + labels.map((l) => `${l.text}@${l.x.toFixed(1)},${l.y.toFixed(1)}`).join(";");
  if (key !== lastPlacement.key) {
    if (measured.size > 5000) measured.clear();   // torque texts accumulate over vehicles
    const at = new Map();
    const taken = labels.map(({x, y}) => [x - r, y - r, x + r, y + r]);   // the symbols
    const dots = labels.map(({x, y}) => [x, y]);
    const order = [...labels].sort((p, q) => (PRIORITY[drawn(p.b)] ?? 3) - (PRIORITY[drawn(q.b)] ?? 3));
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
      // no place beside its dot in a cluster: farther out, with a leader line to its dot
      let leader = null;
      for (const far of best ? [] : LEADER_PX) {
        for (const [dx, dy] of dirs) {
          const cx = x + dx * (r + far + w / 2), cy = y + dy * (r + far + h / 2);
          const box = [cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2];
          if (box[0] < 0 || box[1] < 0 || box[2] > W || box[3] > H) continue;
          if (taken.some((t) => hit(t, box))) continue;
          leader = leaderLine(x, y, r, box, dots, taken);
          if (leader === null) continue;
          best = [cx, cy, box];
          break;
        }
        if (best) break;
      }
      if (best) {
        taken.push(best[2]);
        if (leader) taken.push(...along(leader));
        at.set(text, [false, `translate(${(best[0] - x - bb.x - bb.width / 2).toFixed(1)},` +
          `${(best[1] - y - bb.y - bb.height / 2).toFixed(1)})`,
          leader && leader.map((v, i) => v - (i % 2 ? y : x))]);
      } else
        at.set(text, [true, `translate(0,${(-r - gap - bb.y - bb.height).toFixed(1)})`, null]);
    }
    lastPlacement = {key, at};
  }
  for (const {g, lbl, text} of labels) {
    const [hidden, transform, leader] = lastPlacement.at.get(text);
    lbl.setAttribute("transform", transform);
    if (hidden) lbl.setAttribute("class", "lbl hidden");
    if (leader) g.insertBefore(el("line", {class: "leader", x1: leader[0].toFixed(1),
      y1: leader[1].toFixed(1), x2: leader[2].toFixed(1), y2: leader[3].toFixed(1)}), g.firstChild);
  }
}

// A label with a leader line: beyond its dot by one of LEADER_PX (px past the dot's edge);
// the line runs from the dot's edge to the label's nearest point and passes near no other
// dot and through no label (each is checked; placed, it takes its room like a label)
const LEADER_PX = [14, 24, 36];
function leaderLine(x, y, r, box, dots, taken) {
  // to the drawn text's box (the box placed is 3 px larger each side: the outline stroke)
  const px = Math.min(Math.max(x, box[0] + 3), box[2] - 3);
  const py = Math.min(Math.max(y, box[1] + 3), box[3] - 3);
  const len = Math.hypot(px - x, py - y);
  if (len < r + 6) return null;
  const ux = (px - x) / len, uy = (py - y) / len;
  const line = [x + ux * (r + 1), y + uy * (r + 1), px, py];
  for (const [ox, oy] of dots)
    if (!(ox === x && oy === y) && (segDist(line, ox, oy) < r + 4 || boxDist(box, ox, oy) < r + 6))
      return null;
  const inside = (t, [qx, qy]) => qx > t[0] && qx < t[2] && qy > t[1] && qy < t[3];
  const pts = along(line).map((q) => [q[0] + 1, q[1] + 1]);
  // its own dot's square (the line starts inside its corner) is no obstacle
  const own = (t) => t[0] === x - r && t[1] === y - r;
  if (taken.some((t) => !own(t) && pts.some((q) => inside(t, q)))) return null;
  return line;
}
function segDist([x1, y1, x2, y2], px, py) {
  const L = (x2 - x1) ** 2 + (y2 - y1) ** 2;
  const t = L ? Math.max(0, Math.min(1, ((px - x1) * (x2 - x1) + (py - y1) * (y2 - y1)) / L)) : 0;
  return Math.hypot(px - x1 - t * (x2 - x1), py - y1 - t * (y2 - y1));
}
// small boxes along a line, every 4 px: the room it takes from later labels
function along([x1, y1, x2, y2]) {
  const n = Math.max(1, Math.ceil(Math.hypot(x2 - x1, y2 - y1) / 4)), out = [];
  for (let i = 0; i <= n; i++) {
    const qx = x1 + (x2 - x1) * i / n, qy = y1 + (y2 - y1) * i / n;
    out.push([qx - 1, qy - 1, qx + 1, qy + 1]);
  }
  return out;
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
  // who is signed in at the station: their name goes with every rundown
  const op = view.operator || {user: null, required: false};
  setText("operator", op.user ? `operator: ${op.user}` :
    op.required ? "nobody signed in: sign in to tighten" : "nobody signed in");
  $("operator").dataset.user = op.user || "";
  $("operator").className = "operator" + (!op.user && op.required ? " needed" : "");
  // no vehicle, no bolts: "0 / 0 bolts OK 0 bolts ending NOK" said nothing (an operator trial)
  $("counters").hidden = !view.counters.total;
  setText("done", view.counters.done);
  setText("total", view.counters.total);
  setText("nok", view.counters.nok);
  setText("nok-unit", view.counters.nok === 1 ? "bolt ending NOK" : "bolts ending NOK");
  $("nok-wrap").style.color = view.counters.nok ? "" : "var(--dim)";
  // skipped bolts are neither OK nor to do: said beside "10 / 50", never left out silently
  setText("skipped", view.counters.skipped || 0);
  $("skipped-wrap").hidden = !view.counters.skipped;
  setText("held", view.counters.held || 0);   // as `stationd status` counts them
  $("held-wrap").hidden = !view.counters.held;
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
  $("wrench").dataset.seen = !w ? "none" : !w.lost ? "here" : w.seen ? "refused" : "out";
  setText("wrench", view.wrench_line);   // the view's words: the headline's reason
  const results = view.results.slice(0, 6);
  const rkey = JSON.stringify(results),
    dkey = JSON.stringify([view.devices, lineShown(view.line), view.reload_refused]);
  if (rkey !== shownKeys.results) { shownKeys.results = rkey; drawResults(results); }
  if (dkey !== shownKeys.devices) {
    shownKeys.devices = dkey;
    drawDevices(view.devices, view.line, view.reload_refused);
  }
}

// Locked bolts (too many NOKs in a row), and who may release them: the roles with the
// release right in the station's access section (the station says, the screen shows)
function drawLocks(view) {
  const locks = view.lock_lines || [], by = view.release_by || [];
  // a held bolt (its result could not be read) is also resolved by entering its outcome
  const held = (view.bolts || []).some((b) => b.held);
  const key = JSON.stringify([locks, by, held]);
  if (key === shownKeys.locks) return;
  shownKeys.locks = key;
  $("locks").hidden = !locks.length;
  const kinds = new Set((view.bolts || []).filter((b) => b.state === "locked").map(drawn));
  setText("locks-title", kinds.has("held") ? (kinds.has("locked") ? "Locked or held" : "Held")
    : "Locked");
  document.body.classList.toggle("has-locks", locks.length > 0);
  const ul = $("locks-list");
  // each lock's words without what to do (said once below), whole on hover
  ul.replaceChildren(...locks.map((line) => {
    const li = document.createElement("li");
    li.textContent = line.text;
    li.title = line.title;
    return li;
  }));
  // the outcome first: a release tightens a held bolt again (a new user's trial released one
  // that was good already)
  const how = held ? "Enter the outcome the controller shows, or release to tighten again"
    : "Release";
  setText("release-by", by.length ? `${how}: a user with the release right (${by.join(", ")})`
    : "Release: no user of this station has the release right (access.users and access.roles)");
}

// what the tables show now: they are redrawn only when it changed
const shownKeys = {results: "", devices: "", locks: ""};

// A NOK names every quantity out of its limits ("NOK: torque high, angle high"): the value
// alone, coloured, did not say which one failed to someone who cannot see colours
function failedWords(t, tLo, tHi, a, aLo, aHi) {
  const out = [];
  const side = (name, v, lo, hi) => {
    if (v === null || v === undefined) return;
    if (lo !== null && lo !== undefined && v < lo) out.push(`${name} low`);
    else if (hi !== null && hi !== undefined && v > hi) out.push(`${name} high`);
  };
  side("torque", t, tLo, tHi);
  side("angle", a, aLo, aHi);
  return out.length ? `: ${out.join(", ")}` : "";
}
window.failedWords = failedWords;

function drawResults(results) {
  const tb = $("results");
  tb.replaceChildren();
  for (const r of results) {
    const tr = document.createElement("tr");
    // a loosening is no tightening: "✔ B11 OK" under its NOK read as the bolt done
    const loosening = r.kind === "loosening";
    tr.className = !r.ok ? "res-nok" : loosening ? "res-loosened" : "res-ok";
    const lim = (v, lo, hi, d) => {
      // a loosening is judged by its own status, never by a window: the limits it came
      // with may be the bolt's tightening window (a NOK read "torque low" against it), as
      // the vehicle's page gives a loosening none (a supervisor's trial)
      if (loosening) return `<span>${fmt(v, d)}</span>`;
      const out = (lo !== null && v < lo) || (hi !== null && v > hi);
      const rng = lo !== null || hi !== null ? ` [${fmt(lo, d)}-${fmt(hi, d)}]` : "";
      // a range stays on one line ("[22.0-" / "28.0]" wrapped at 1280 px)
      return `<span class="${out ? "out" : ""}">${fmt(v, d)}</span> <small class="rng">${rng.trim()}</small>`;
    };
    const nok = loosening ? "" :
      failedWords(r.torque_nm, r.torque_min, r.torque_max, r.angle_deg, r.angle_min, r.angle_max);
    const said = !r.ok ? (loosening ? "loosening NOK" : "NOK" + nok)
      : loosening ? "loosened" : "OK";   // one line at 1280 px
    // an outcome a supervisor entered from the controller's own screen: never taken for one
    // measured (the vehicle's page says "entered by ..., not measured")
    if (r.entered_by) tr.title = `entered by ${r.entered_by} from the controller's screen, not measured`;
    const entered = r.entered_by ? ` <small class="entered">entered by ${esc(r.entered_by)}</small>` : "";
    tr.innerHTML = `<td>${esc(r.bolt)} ${said}${entered}</td>` +
      `<td>${lim(r.torque_nm, r.torque_min, r.torque_max, 1)}</td>` +
      `<td>${lim(r.angle_deg, r.angle_min, r.angle_max, 0)}</td>`;
    tb.appendChild(tr);
  }
}

// How many records wait, in the journal's words ("1 record waits", "7 records wait"; none
// yet: the forwarder asks the line database at its start, before anything is recorded)
function recordsWait(n) {
  return n === 0 ? "no record waits yet" : n === 1 ? "1 record waits" : `${n} records wait`;
}

// The line database (store and forward): never a fault of the station, so never red; amber
// while it is down or past its bounds, with how many records wait
function lineShown(line) {
  if (!line) return null;
  const text = line.alarm ? `line database: ${line.alarm}` :
    line.up === false ? `line database down: ${recordsWait(line.backlog)}` :
    `line database: ${line.backlog} behind`;
  return {text, ok: !line.alarm && line.up !== false, title: line.last_error || line.url};
}

function drawDevices(devices, line, reloadRefused) {
  const ul = $("devices");
  ul.replaceChildren();
  // a reload refused: the station runs on the file it read before, and the file on disk
  // would not start it at the next reboot (it was only in stationd status: an operator trial).
  // Whole, wrapped: the file, line and key are what the engineer at the panel fixes (cut to
  // one line, they showed only on a mouse's hover: a line engineer's trial on a touch panel)
  if (reloadRefused) {
    const li = document.createElement("li");
    li.className = "dev-wait full";
    li.dataset.device = "config";
    li.textContent = `configuration: reload refused (${reloadRefused}): running on the file ` +
      "read before";
    li.title = li.textContent;
    ul.appendChild(li);
  }
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
  const rows = [];
  for (const [name, d] of devs) {
    const li = document.createElement("li");
    const check = d.ok ? d.check : null;
    li.className = !d.ok ? (d.kind === "opening" ? "dev-wait" : "dev-bad") :
      !check || check.trusted ? "dev-ok" : check.verdict === "moved" ? "dev-bad" : "dev-wait";
    li.dataset.device = name;
    li.dataset.trust = !check ? "" : check.trusted ? "trusted" : check.verdict;
    li.textContent = !d.ok ? `${name} ${d.kind}: ${d.reason}` :
      !check ? `${name}: ok` : check.trusted ? `${name}: ok, trusted` : check.words;
    // on hover: a faulty device's whole reason first (its line may be cut), then what it
    // said it is (the controller's name, versions) and its last check
    const title = [!d.ok ? li.textContent : "", d.identity,
      check && check.trusted ? check.words : ""].filter(Boolean);
    if (title.length) li.title = title.join("\n");
    rows.push([li, name, d]);
  }
  for (const li of sameReasonOnce(rows)) ul.appendChild(oneLine(li));
}

// Eight pairs down for the same cause (their reasons alike but for their own names and URLs)
// are one line with a count, not eight long ones: the devices panel pushed the Commands out
// of the window.  Each device's whole reason is in the line's title (hover) and opens in
// place on a click.
function sameReasonOnce(rows) {
  const out = [], groups = new Map();
  for (const [li, name, d] of rows) {
    if (d.ok || !d.reason) { out.push(li); continue; }
    const key = `${li.className}|${d.kind}|${d.reason.split(name).join("\u0000")}`;
    const g = groups.get(key);
    if (!g) {
      const first = {li, names: [name], titles: [`${name} ${d.kind}: ${d.reason}`], d};
      groups.set(key, first);
      out.push(first);
      continue;
    }
    g.names.push(name);
    g.titles.push(`${name} ${d.kind}: ${d.reason}`);
  }
  return out.map((x) => {
    if (x instanceof Element) return x;
    const {li, names, titles, d} = x;
    if (names.length > 1) {
      li.dataset.devices = names.join(" ");
      li.dataset.count = String(names.length);
      li.textContent = `${namesShort(names)} (${names.length} devices) ${d.kind}: ${d.reason}`;
      li.title = titles.join("\n");
    }
    return li;
  });
}

// "pair1-4, pair7": runs of names that differ only by a number, said as a range
function namesShort(names) {
  const parts = [];
  for (const n of names) {
    const m = /^(.*?)(\d+)$/.exec(n), last = parts[parts.length - 1];
    if (m && last && last.prefix === m[1] && Number(m[2]) === last.to + 1) last.to += 1;
    else parts.push(m ? {prefix: m[1], from: Number(m[2]), to: Number(m[2])} : {name: n});
  }
  return parts.map((p) => p.name !== undefined ? p.name : p.from === p.to ? `${p.prefix}${p.from}`
    : `${p.prefix}${p.from}-${p.to}`).join(", ");
}

// one line, cut with an ellipsis; the whole text on hover, and in place on a click (kept
// across redraws)
const openRows = new Set();
function oneLine(li) {
  if (!li.title) li.title = li.textContent;
  const id = li.dataset.devices || li.dataset.device;
  if (openRows.has(id)) li.classList.add("full");
  li.addEventListener("click", () => {
    if (li.classList.toggle("full")) openRows.add(id); else openRows.delete(id);
  });
  return li;
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
    li.textContent = `${namesShort((li.dataset.devices || li.dataset.device).split(" "))}: unknown`;
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
    // live again: the session is asked again (a restarted daemon has none)
    if (document.body.classList.contains("not-live")) window.dispatchEvent(new Event("station-live"));
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
