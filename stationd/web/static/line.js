// Line page: every station's rundowns from the line database (/api/line/results), newest first.
"use strict";
(function () {
  const q = (s) => document.querySelector(s);
  // a count in words, as stationd.counting says it: "1 rundown", "3 rundowns"
  const counted = (n, word, plural) => `${n} ${n === 1 ? word : plural || word + "s"}`;
  const fmt = (v, d) => v === null || v === undefined ? "-" : Number(v).toFixed(d);
  function cell(tr, text, cls) {
    const td = document.createElement("td");
    td.textContent = text;
    if (cls) td.className = cls;
    tr.appendChild(td);
  }
  async function show() {
    const ask = new URLSearchParams(location.search);
    q("#ask [name=vin]").value = ask.get("vin") || "";
    q("#ask [name=station]").value = ask.get("station") || "";
    q("#ask [name=bolt]").value = ask.get("bolt") || "";
    const r = await fetch("/api/line/results" + location.search);
    if (!r.ok) { q("#error").textContent = (await r.text()).trim(); return; }
    const doc = await r.json();
    const stations = new Set(doc.rundowns.map((x) => x.station_id));
    q("#what").textContent = counted(doc.rundowns.length, "rundown") + " at " +
      counted(stations.size, "station") + ", " + doc.line_db;
    for (const x of doc.rundowns) {
      const tr = document.createElement("tr");
      tr.dataset.station = x.station_id;
      cell(tr, x.at.replace("T", " ").slice(0, 19));
      for (const v of [x.station_id, x.vin, x.bolt]) cell(tr, v);
      cell(tr, (x.ok ? "OK" : "NOK") + (x.kind === "loosening" ? " (loosening)" : "") +
           (x.entered_by ? " (entered by " + x.entered_by + ")" : ""), x.ok ? "" : "out");
      if (x.entered_by) {   // read on the controller's screen, not measured: say who and why
        tr.lastChild.title = "entered from the controller's screen, not measured" +
          (x.entered_comment ? ": " + x.entered_comment : "");
      }
      cell(tr, fmt(x.torque_nm, 1));
      const [, lo, hi] = x.torque_window_nm;   // target, min, max in force
      cell(tr, lo === null && hi === null ? "-" : fmt(lo, 1) + " - " + fmt(hi, 1));
      cell(tr, fmt(x.angle_deg, 1));
      cell(tr, x.parameters_version === null ? "-" : String(x.parameters_version));
      q("#line tbody").appendChild(tr);
    }
  }
  show();
})();
