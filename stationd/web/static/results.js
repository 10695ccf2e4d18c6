// Results screens: the vehicles and each vehicle's rundowns, read from the server's API.
"use strict";
const q = (s) => document.querySelector(s);
// A count in words, as stationd.counting says it: "1 tightening", "3 tightenings".
function counted(n, word, plural) { return `${n} ${n === 1 ? word : plural || word + "s"}`; }
function fmt(v, d) { return v === null || v === undefined ? "-" : Number(v).toFixed(d); }
// A time as date and clock apart, to the second: a narrow window wraps between the two,
// never inside the date (a T gave Firefox no place to wrap at all).
function when(t) { return String(t || "").slice(0, 19).replace("T", " "); }
function cell(tr, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  tr.appendChild(td);
  return td;
}
async function getJson(url) {
  const r = await fetch(url);
  if (!r.ok) {
    const e = new Error((await r.text()).trim());
    e.status = r.status;
    throw e;
  }
  return r.json();
}
async function listVehicles() {
  try {
    const tb = q("#vehicles tbody");
    const r = await fetch("/api/vehicles");
    if (!r.ok) throw new Error((await r.text()).trim());
    const list = await r.json();
    const total = Number(r.headers.get("X-Vehicles-Total") || list.length);
    if (!list.length) {
      const tr = document.createElement("tr");
      tr.className = "empty";
      cell(tr, "No vehicles yet: they appear here once the station opens one.").colSpan = 11;
      tb.appendChild(tr);
    }
    for (const v of list) {
      const tr = document.createElement("tr");
      tr.dataset.vin = v.vin;
      const a = document.createElement("a");
      a.href = "/vehicles/" + encodeURIComponent(v.vin);
      a.textContent = v.vin;
      cell(tr, "").appendChild(a);
      cell(tr, v.model);
      // reopened and not back yet: no rework done, not the vehicle on the lift
      cell(tr, v.status + (v.reopened_at && v.status !== "reopened" ? ", reworked" : ""),
           "status-" + v.status);
      cell(tr, v.ok.length);
      cell(tr, v.nok.length + (v.nok.length ? " (" + v.nok.join(", ") + ")" : ""), v.nok.length ? "status-NOK" : "");
      cell(tr, (v.skipped || []).length);
      cell(tr, v.missing.length);
      // loosened last (or to be loosened): neither OK nor missing, and the vehicle not done
      // (an operator trial: 2 OK + 1 NOK + 0 skipped + 45 missing of 50 bolts)
      const again = v.loosen || [];
      cell(tr, again.length + (again.length ? " (" + again.join(", ") + ")" : ""));
      // held for a person (its result not known), as the vehicle's page says them
      const held = Object.keys(v.held || {});
      cell(tr, held.length + (held.length ? " (" + held.join(", ") + ")" : ""),
           held.length ? "status-held" : "");
      cell(tr, when(v.started_at));
      cell(tr, v.status === "reopened" ? `reopened ${when(v.reopened_at)}`
        : v.ended_at ? when(v.ended_at) : "open");
      tb.appendChild(tr);
    }
    if (total > list.length) {   // said, not cut off without a word (a supervisor's trial)
      const tr = document.createElement("tr");
      tr.className = "more";
      cell(tr, `The newest ${list.length} of ${total} vehicles. A shift's vehicles: ` +
           "stationd db shift --since DATE; every rundown: stationd db export --results.")
        .colSpan = 11;
      tb.appendChild(tr);
    }
  } catch (e) { q("#error").textContent = e.message; }
}
// A rundown's torque over angle as inline SVG: the controller's trace, the limits of that
// rundown (its parameter version) as a dashed window (lines when it has no angle limits), and
// the result's final point.
const SVGNS = "http://www.w3.org/2000/svg";
function svg(name, attrs, parent, text) {
  const e = document.createElementNS(SVGNS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}
function niceStep(span) {
  const raw = span / 4, p = Math.pow(10, Math.floor(Math.log10(raw)));
  return [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw) || raw;
}
function curvePlot(r) {
  const c = r.curve, W = 380, H = 210, L = 46, R = 12, T = 12, B = 34;
  const ang = c.angle_deg, tq = c.torque_nm;
  const nums = (xs) => xs.filter((v) => v !== null && v !== undefined);
  const amax = Math.max(...ang, ...nums([r.angle_max_deg, r.angle_deg])) * 1.05 || 1;
  const tmax = Math.max(...tq, ...nums([r.torque_max_nm, r.torque_nm])) * 1.1 || 1;
  const amin = Math.min(0, ...ang), tmin = Math.min(0, ...tq);
  const x = (v) => L + (v - amin) / (amax - amin) * (W - L - R);
  const y = (v) => H - B - (v - tmin) / (tmax - tmin) * (H - T - B);
  const nok = r.status === "nok";
  const root = svg("svg", {viewBox: `0 0 ${W} ${H}`, width: W, height: H, role: "img",
                           class: "curve-plot", "data-tightening": r.tightening_id ?? ""});
  svg("title", {}, root, `Torque over angle, ${r.bolt} attempt ${r.attempt}` +
      (r.tightening_id !== null ? `, tightening ${r.tightening_id}` : ""));
  // colours that read on the page's dark theme and on a printed export alike
  root.style.color = "inherit";
  svg("rect", {x: L, y: T, width: W - L - R, height: H - T - B, fill: "none",
               stroke: "currentColor", "stroke-opacity": 0.5}, root);
  for (let v = 0, s = niceStep(amax - amin); v <= amax; v += s) {
    svg("line", {x1: x(v), x2: x(v), y1: H - B, y2: H - B + 4, stroke: "currentColor"}, root);
    svg("text", {x: x(v), y: H - B + 15, "font-size": 10, "text-anchor": "middle",
                 fill: "currentColor"}, root,
        String(Math.round(v)));
  }
  for (let v = 0, s = niceStep(tmax - tmin); v <= tmax; v += s) {
    svg("line", {x1: L - 4, x2: L, y1: y(v), y2: y(v), stroke: "currentColor"}, root);
    svg("text", {x: L - 6, y: y(v) + 3, "font-size": 10, "text-anchor": "end",
                 fill: "currentColor"}, root,
        String(Math.round(v * 10) / 10));
  }
  svg("text", {x: (L + W - R) / 2, y: H - 4, "font-size": 11, "text-anchor": "middle",
               fill: "currentColor"}, root,
      "angle (\u00b0)");
  svg("text", {x: 12, y: (T + H - B) / 2, "font-size": 11, "text-anchor": "middle",
               fill: "currentColor", transform: `rotate(-90 12 ${(T + H - B) / 2})`}, root, "torque (N\u00b7m)");
  const lim = {stroke: "#3c9", "stroke-dasharray": "5 3", fill: "none", class: "limits"};
  if (r.torque_min_nm !== null && r.torque_max_nm !== null) {
    if (r.angle_min_deg !== null && r.angle_max_deg !== null)
      svg("rect", {...lim, x: x(r.angle_min_deg), y: y(r.torque_max_nm),
                   width: x(r.angle_max_deg) - x(r.angle_min_deg),
                   height: y(r.torque_min_nm) - y(r.torque_max_nm)}, root);
    else for (const t of [r.torque_min_nm, r.torque_max_nm])
      svg("line", {...lim, x1: L, x2: W - R, y1: y(t), y2: y(t)}, root);
  }
  const pts = ang.map((a, i) => `${x(a).toFixed(1)},${y(tq[i]).toFixed(1)}`).join(" ");
  svg("polyline", {points: pts, fill: "none", stroke: nok ? "#f66" : "#5ad",
                   "stroke-width": 1.5, class: "trace"}, root);
  if (r.angle_deg !== null && r.torque_nm !== null)
    svg("circle", {cx: x(r.angle_deg), cy: y(r.torque_nm), r: 3.5, class: "final",
                   fill: nok ? "#f66" : "#5ad"}, root);
  return root;
}
// The vehicle's commands (skip, reopen, release, loosen), oldest first, with who and when
function showTrail(commands) {
  const tb = q("#trail tbody");
  tb.replaceChildren();
  for (const c of commands) {
    const tr = document.createElement("tr");
    tr.className = "command";
    tr.dataset.kind = c.kind;
    cell(tr, when(c.at));
    cell(tr, c.kind); cell(tr, c.bolt || "-"); cell(tr, c.user); cell(tr, c.source);
    cell(tr, c.comment || "");
    tb.appendChild(tr);
  }
  q("#trail").hidden = q("#trail-title").hidden = !commands.length;
}
// What the controller sent that is no rundown of a bolt, oldest first: a result that could
// not be read (its bolt held, or held then), a link cut that left a bolt's result unknown,
// a controller event (batch step, ...), a result no bolt owns. Each held bolt says whether a
// supervisor's command ended its hold since (the trail says which), as db report does.
function showOthers(v) {
  const held = v.held || {};
  // that record's hold on still (a later hold of the same bolt is another record's)
  // (a loosening's hold adds ", a loosening ..." to its note)
  const bolt = (b, note) => !b ? "-" : b + (Object.prototype.hasOwnProperty.call(held, b) &&
    (String(held[b]) === note || String(held[b]).startsWith(note + ","))
    ? " (held)" : " (held then, no longer)");
  // the station's own events that hold a bolt without a result (db.kinds)
  const holdWords = {"result unknown after a link cut": "link cut",
                     "result unknown after a lost push": "push lost"};
  // what it came as (db.kinds.message_words): a register-driven controller's is no message
  const message = (x) => x.mid ? `MID ${String(x.mid).padStart(4, "0")} revision ${x.revision}`
    : "result registers";
  const rows = [];
  for (const x of v.unreadable_results || [])
    rows.push([x.recorded_at, "could not be read", x.tightening_id, x.pset,
               bolt(x.bolt, x.tightening_id !== null && x.tightening_id !== undefined
                 ? `tightening ${x.tightening_id}`
                 : message(x)),
               // the driver's words name the MID and revision already
               x.error.startsWith("MID ") ? x.error
                 : `${message(x)}: ${x.error}`]);
  for (const e of v.controller_events || []) {
    if (Object.prototype.hasOwnProperty.call(holdWords, e.what))
      rows.push([e.recorded_at, holdWords[e.what], null, e.pset, bolt(e.bolt, e.note || ""),
                 e.note || ""]);
    else
      rows.push([e.recorded_at, e.what, e.tightening_id, e.pset,
                 e.bolt ? `tool on ${e.bolt}` : "-", "not a rundown"]);
  }
  for (const u of v.unattributed || []) {
    // made on another vehicle (the controller says which): said, or it reads as this one's
    const made = u.controller_vin && u.controller_vin !== v.vin
      ? `, made on ${u.controller_vin}` : "";
    rows.push([u.recorded_at, `unattributed ${u.what}`, u.tightening_id, u.pset, "-",
               `${(u.status || "").toUpperCase()} ${fmt(u.torque_nm, 1)} Nm, ` +
               `${fmt(u.angle_deg, 0)} deg${made} (${u.reason})`]);
  }
  rows.sort((a, b) => String(a[0]).localeCompare(String(b[0])));
  const tb = q("#others tbody");
  tb.replaceChildren();
  for (const [at, what, tid, pset, b, detail] of rows) {
    const tr = document.createElement("tr");
    tr.className = "other";
    cell(tr, when(at));
    cell(tr, what); cell(tr, tid ?? "-"); cell(tr, pset ?? "-"); cell(tr, b); cell(tr, detail);
    tb.appendChild(tr);
  }
  q("#others").hidden = q("#others-title").hidden = !rows.length;
}
// every quantity of a NOK rundown out of its limits (those of its parameter version)
function nokWords(r) {
  const out = [];
  const side = (name, v, lo, hi) => {
    if (v === null || v === undefined) return;
    if (lo !== null && lo !== undefined && v < lo) out.push(`${name} low`);
    else if (hi !== null && hi !== undefined && v > hi) out.push(`${name} high`);
  };
  side("torque", r.torque_nm, r.torque_min_nm, r.torque_max_nm);
  side("angle", r.angle_deg, r.angle_min_deg, r.angle_max_deg);
  return out.length ? `: ${out.join(", ")}` : "";
}
async function showVehicle(vin) {
  const base = "/api/vehicles/" + encodeURIComponent(vin);
  try {
    const v = await getJson(base);
    // the exports and the table only for a vehicle the database holds
    q("#csv").href = base + "/export.csv";
    q("#json").href = base + "/export.json";
    q("#exports").hidden = false;
    q("#rundowns").hidden = false;
    // reopened and not back yet: no rework done yet, and not at the station
    q("#title").textContent = `${v.vin} (${v.model}` + (v.waiting
      ? ", reopened for rework, not back at the station yet" : v.reopened_at ? ", reworked"
      : "") + ")";
    // bolts by their last rundown, then the rundowns themselves: "NOK" alone read as either
    const runs = v.bolts.flatMap((b) => b.rundowns);
    const tightenings = runs.filter((r) => (r.rundown || "tightening") === "tightening");
    const nokRuns = tightenings.filter((r) => r.status === "nok").length;
    // the bolts ending NOK named, a skipped one with who skipped it, as db report says them
    // (a supervisor read "1 ending NOK, 0 skipped" of a bolt skipped after its NOKs)
    const skippedBy = (id) => {
      const b = v.bolts.find((x) => x.bolt === id);
      return b && b.skipped_by ? ` skipped by ${b.skipped_by}` : "";
    };
    const noks = v.nok.length ? ` (${v.nok.map((id) => id + skippedBy(id)).join(", ")})` : "";
    q("#summary").textContent = `bolts: ${v.ok.length} OK, ${v.nok.length} ending NOK${noks}, ` +
      `${(v.skipped || []).length} skipped, ${v.missing.length} missing` +
      ((v.loosen || []).length ? `, ${v.loosen.length} to tighten again (${v.loosen.join(", ")})` : "") +
      (Object.keys(v.held || {}).length ? `, ${Object.keys(v.held).length} held (${Object.keys(v.held).join(", ")})` : "") +
      ((v.locked || []).length ? `, ${v.locked.length} locked (${v.locked.join(", ")})` : "") +
      (v.complete ? " (complete)" : "") +
      `; rundowns: ${counted(tightenings.length, "tightening")}, ${counted(nokRuns, "NOK result")}` +
      // the loosenings too, as db report counts them
      (runs.length > tightenings.length
        ? `, ${counted(runs.length - tightenings.length, "loosening")}` : "");
    const tb = q("#rundowns tbody");
    for (const b of v.bolts) {
      const runs = b.rundowns.length ? b.rundowns : [null];
      runs.forEach((r, i) => {
        const tr = document.createElement("tr");
        tr.className = "rundown";
        tr.dataset.bolt = b.bolt;
        cell(tr, i ? "" : b.bolt);
        // a bolt skipped after its last rundown (locked after NOKs) keeps that rundown's
        // status, and says who skipped it and why
        const then = b.skipped_by && b.status !== "skipped"
          ? `, then skipped by ${b.skipped_by}` + (b.comment ? `: ${b.comment}` : "") : "";
        // held: its result not known, a supervisor releases it or enters its outcome
        const hold = Object.prototype.hasOwnProperty.call(v.held || {}, b.bolt)
          ? v.held[b.bolt] : null;
        // locked after its NOKs: waits for a supervisor's check and release (a supervisor's
        // trial read it as a bolt that simply ended NOK)
        const locked = (v.locked || []).includes(b.bolt)
          ? ", LOCKED: a supervisor checks it and releases it" : "";
        cell(tr, i ? "" : b.status.toUpperCase() + then + (hold ? `, HELD: ${hold}` : "") + locked,
             "status-" + (b.status === "nok" ? "NOK" : b.status));
        if (!r) {
          // a skip names who skipped it and why (the exports' skipped_by and comment); else
          // the server's words: "not tightened", or, held, why not so (db report's words)
          const none = b.status === "skipped"
            ? `skipped by ${b.skipped_by || "?"}` + (b.comment ? `: ${b.comment}` : "")
            : b.unrecorded || "not tightened";
          cell(tr, "-"); cell(tr, "-"); cell(tr, none);
          for (let k = 0; k < 8; k++) cell(tr, "", k === 7 ? "crops" : "");
        }
        else {
          // the server's words: a repeat, a rework, a loosening with its loosen pset
          cell(tr, r.attempt_words ?? String(r.attempt));
          // a loosening (the NOK policy's loosen step, a loosen command) undoes a tightening
          cell(tr, r.rundown || "tightening", "rundown-" + (r.rundown || "tightening"));
          // an outcome a supervisor read on the controller's screen: never taken for measured
          cell(tr, r.status.toUpperCase() + (r.status === "nok" ? nokWords(r) : "") +
               (r.entered_by ? `, entered by ${r.entered_by}, not measured` : ""),
               "status-" + (r.status === "nok" ? "NOK" : "ok"));
          cell(tr, fmt(r.torque_nm, 1)); cell(tr, fmt(r.angle_deg, 0)); cell(tr, r.pset ?? "-");
          cell(tr, fmt(r.tilt_deg, 1)); cell(tr, fmt(r.match_distance_mm, 1));
          cell(tr, (r.recorded_at || "").slice(0, 19));
          // who was signed in at the station ("-": nobody, or a record from before)
          cell(tr, r.operator || "-", "operator");
          const td = cell(tr, "", "crops");
          for (const im of r.image_urls || []) {
            const a = document.createElement("a");
            a.href = im; a.textContent = "crop "; td.appendChild(a);
          }
        }
        tb.appendChild(tr);
        if (r && r.curve && r.curve.torque_nm && r.curve.angle_deg) {
          // the rundown's torque-angle curve, in a row of its own under it
          const cr = document.createElement("tr");
          cr.className = "curve";
          cr.dataset.bolt = b.bolt;
          const td = cell(cr, "");
          td.colSpan = 13;
          td.appendChild(curvePlot(r));
          tb.appendChild(cr);
        }
      });
    }
    // crops are saved only with records.save_images (off in config/sim): no empty column
    const crops = v.bolts.some((b) => b.rundowns.some((r) => (r.image_urls || []).length));
    q("#rundowns").classList.toggle("no-crops", !crops);
    q("#curves-note").hidden = !document.querySelector("tr.curve");
    showOthers(v);
    showTrail(v.commands || []);
  } catch (e) {
    if (e.status === 404) {
      q("#title").textContent = `no vehicle ${vin}`;
      q("#summary").textContent = "The results database holds no vehicle with this VIN.";
    } else q("#error").textContent = e.message;
  }
}

// which page this is (its script tag says: no inline script, which the screens' content
// security policy refuses)
(() => {
  const show = document.currentScript && document.currentScript.dataset.show;
  if (show === "vehicles") listVehicles();
  else if (show === "vehicle") showVehicle(decodeURIComponent(location.pathname.split("/").pop()));
})();
