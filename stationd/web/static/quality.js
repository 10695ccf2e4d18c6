// Quality screen: process capability per bolt and pset, and the NOK trend, from /api/spc.
"use strict";
(function () {
  const q = (s) => document.querySelector(s);
  const fmt = (v, d) => v === null || v === undefined ? "-" : Number(v).toFixed(d);
  function cell(tr, text, cls) {
    const td = document.createElement("td");
    td.textContent = text;
    if (cls) td.className = cls;
    tr.appendChild(td);
  }
  // a capability below 1.33 (the usual minimum for a capable process) is marked
  const mark = (v) => v !== null && v !== undefined && v < 1.33 ? "out" : "";
  async function show() {
    const r = await fetch("/api/spc" + location.search);
    if (!r.ok) { q("#error").textContent = (await r.text()).trim(); return; }
    const doc = await r.json();
    for (const b of doc.bolts) {
      const tr = document.createElement("tr");
      tr.dataset.bolt = b.bolt;
      for (const v of [b.model, b.bolt, b.pset ?? "-", b.torque.n, b.nok]) cell(tr, String(v));
      for (const k of ["torque", "angle"]) {
        cell(tr, fmt(b[k].mean, 1));
        cell(tr, fmt(b[k].cp, 2), mark(b[k].cp));
        cell(tr, fmt(b[k].cpk, 2), mark(b[k].cpk));
      }
      q("#spc tbody").appendChild(tr);
    }
    for (const d of doc.trend) {
      const tr = document.createElement("tr");
      for (const v of [d.day, d.results, d.nok]) cell(tr, String(v));
      cell(tr, d.nok_rate === null ? "-" : (100 * d.nok_rate).toFixed(1) + " %");
      q("#trend tbody").appendChild(tr);
    }
  }
  show();
})();
