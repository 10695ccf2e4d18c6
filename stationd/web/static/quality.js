// Quality screen: process capability per bolt and pset with a plot of its last results
// against their limits, and the NOK trend, from /api/spc.
"use strict";
(function () {
  const q = (s) => document.querySelector(s);
  const fmt = (v, d) => v === null || v === undefined ? "-" : Number(v).toFixed(d);
  const SVG = "http://www.w3.org/2000/svg";
  // the plot's box (px) and its inner margin: small enough for 50 rows on one screen
  const W = 180, H = 46, PAD = 5;
  const UNIT = { torque: "Nm", angle: "\u00b0" };
  function cell(tr, text, cls) {
    const td = document.createElement("td");
    td.textContent = text;
    if (cls) td.className = cls;
    tr.appendChild(td);
    return td;
  }
  function el(name, attrs, parent) {
    const e = document.createElementNS(SVG, name);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }
  const num = (v) => v !== null && v !== undefined && Number.isFinite(Number(v));
  // a capability below 1.33 (the usual minimum for a capable process) is marked
  const mark = (v) => v !== null && v !== undefined && v < 1.33 ? "out" : "";

  // One group's last results of `kind` (torque or angle) over their order, with the limit
  // lines (min, max solid; target dashed); a NOK is a larger hollow ring, not only red; a
  // result without a value is a tick on the bottom edge.  The vertical scale spans the
  // limits and every value, so a point beyond a limit is drawn beyond its line.
  function plot(kind, last, lim) {
    const svg = el("svg", { class: "plot " + kind, width: W, height: H,
                            viewBox: `0 0 ${W} ${H}`, "data-kind": kind });
    const vals = last.map((r) => r[kind]).filter(num).map(Number);
    const lines = ["min", "target", "max"].filter((k) => num(lim[k]));
    let lo = Math.min(...vals, ...lines.map((k) => Number(lim[k])));
    let hi = Math.max(...vals, ...lines.map((k) => Number(lim[k])));
    if (!Number.isFinite(lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-9) { lo -= 1; hi += 1; }
    const y = (v) => PAD + (hi - v) / (hi - lo) * (H - 2 * PAD);
    const n = last.length;
    const x = (i) => n === 1 ? W / 2 : PAD + i * (W - 2 * PAD) / (n - 1);
    svg.dataset.lo = lo;
    svg.dataset.hi = hi;
    for (const k of lines) {
      const yy = y(Number(lim[k])).toFixed(2);
      el("line", { class: "lim " + k, x1: 0, x2: W, y1: yy, y2: yy,
                   "data-value": lim[k] }, svg);
    }
    const path = [];
    last.forEach((r, i) => { if (num(r[kind])) path.push(`${x(i).toFixed(2)},${y(r[kind]).toFixed(2)}`); });
    if (path.length > 1) el("polyline", { class: "trace", points: path.join(" ") }, svg);
    last.forEach((r, i) => {
      const cls = "pt " + (r.ok ? "ok" : "nok");
      const xx = x(i).toFixed(2);
      const p = num(r[kind])
        ? el("circle", { class: cls, cx: xx, cy: y(r[kind]).toFixed(2), r: r.ok ? 2.2 : 3.6,
                         "data-value": r[kind] }, svg)
        : el("line", { class: cls + " none", x1: xx, x2: xx, y1: H - 4, y2: H }, svg);
      const t = el("title", {}, p);
      t.textContent = `${r.at.replace("T", " ").slice(0, 19)} ${r.ok ? "OK" : "NOK"} ` +
        (num(r[kind]) ? `${Number(r[kind]).toFixed(1)} ${UNIT[kind]}` : "no value");
    });
    const t = el("title", {}, svg);
    t.textContent = `${kind}: last ${n} results; limits ` +
      lines.map((k) => `${k} ${lim[k]}`).join(", ");
    return svg;
  }

  async function show() {
    const r = await fetch("/api/spc" + location.search);
    if (!r.ok) { q("#error").textContent = (await r.text()).trim(); return; }
    const doc = await r.json();
    const rows = document.createDocumentFragment();   // one insertion for 50 bolts
    for (const b of doc.bolts) {
      const tr = document.createElement("tr");
      tr.dataset.bolt = b.bolt;
      for (const v of [b.model, b.bolt, b.pset ?? "-"]) cell(tr, String(v));
      // the version and, on hover, its limits: a bolt whose limits changed has a row per
      // version, which looked twice the same row (a newcomer's trial)
      const lim = (k, u) => ["min", "max"].filter((m) => num(b.limits[k][m]))
        .map((m) => `${m} ${b.limits[k][m]} ${u}`).join(", ");
      cell(tr, b.parameter_version === null || b.parameter_version === undefined ? "-"
        : "v" + b.parameter_version, "version").title =
        [["torque", "Nm"], ["angle", "\u00b0"]].filter(([k]) => b.limits[k])
          .map(([k, u]) => `${k}: ${lim(k, u) || "no limits"}`).join("; ");
      for (const v of [b.torque.n, b.nok]) cell(tr, String(v));
      for (const k of ["torque", "angle"]) {
        cell(tr, fmt(b[k].mean, 1));
        cell(tr, fmt(b[k].cp, 2), mark(b[k].cp));
        cell(tr, fmt(b[k].cpk, 2), mark(b[k].cpk));
      }
      const td = cell(tr, "", "plots");
      for (const k of ["torque", "angle"]) td.appendChild(plot(k, b.last, b.limits[k]));
      rows.appendChild(tr);
    }
    q("#spc tbody").appendChild(rows);
    for (const d of doc.trend) {
      const tr = document.createElement("tr");
      for (const v of [d.day, d.results, d.nok]) cell(tr, String(v));
      cell(tr, d.nok_rate === null ? "-" : (100 * d.nok_rate).toFixed(1) + " %");
      q("#trend tbody").appendChild(tr);
    }
  }
  // the plot column shows torque or angle: both are drawn, the choice only hides one
  for (const b of document.querySelectorAll("input[name=plot]")) {
    b.addEventListener("change", () => { q("#spc").dataset.plot = b.value; });
  }
  show();
})();
