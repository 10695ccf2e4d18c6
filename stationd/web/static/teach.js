// The commissioning screen's Teach panel: a user with the teach right (logged in through
// session.js) starts teach mode for a vehicle model, holds the tool on a bolt and presses
// "Teach B07"; the station measures the bolt end (the mean of steady localizations, their
// dispersion) and the panel lists each taught bolt against the CAD table of the station's
// database (the X-Y difference, flagged beyond the matching tolerance or closer to a neighbour
// than the spacing rule allows).  At the end: stop teach mode, download the taught table
// (GET /api/teach/table: the file `stationd db import` takes, a new parameter version of each
// bolt that moved).  The station decides every step; a refusal shows its reason.
"use strict";
(function () {
  const q = (id) => document.getElementById(id);
  const fmt = (v, d) => v === null || v === undefined ? "-" : Number(v).toFixed(d);
  let measuring = false;

  const {command} = window.StationSession.bind((rights) => {
    q("teach-controls").hidden = !rights.includes("teach");
  });

  // the model shown: the one being taught, else the one typed
  function model() { return q("teach-model").value.trim(); }

  function options(id, values) {
    const list = q(id);
    const key = values.join(",");
    if (list.dataset.key === key) return;
    list.dataset.key = key;
    list.replaceChildren(...values.map((v) => new Option(v, v)));
  }

  function cell(text) {
    const td = document.createElement("td");
    td.textContent = text;
    return td;
  }

  function flags(t, tol) {
    const out = [];
    if (t.beyond) out.push(`beyond the tolerance (${fmt(tol, 0)} mm)`);
    if (t.neighbours.length) out.push(`too close to ${t.neighbours.join(", ")}`);
    if (t.cad_mm === null) out.push("not in the CAD table");
    return out;
  }

  function draw(doc) {
    options("teach-models", doc.models || []);
    options("teach-bolts", (doc.cad || []).map((b) => b.bolt));
    const taught = doc.taught || [];
    const rows = taught.map((t) => {
      const tr = document.createElement("tr");
      tr.dataset.bolt = t.bolt;
      const f = flags(t, doc.tolerance_mm);
      tr.dataset.flags = f.length ? "1" : "0";
      if (f.length) tr.className = "nok";
      const [x, y, z] = t.position_mm;
      tr.append(cell(t.bolt), cell(fmt(x, 1)), cell(fmt(y, 1)), cell(fmt(z, 1)),
        cell(fmt(t.dispersion_mm, 2)), cell(fmt(t.difference_mm, 1)), cell(f.join("; ") || "ok"));
      return tr;
    });
    q("taught").replaceChildren(...rows);
    q("taught-table").hidden = !rows.length;
    const link = q("teach-download");
    link.hidden = !rows.length;
    if (rows.length) link.href = `/api/teach/table?model=${encodeURIComponent(doc.model)}`;
  }

  async function refresh() {
    try {
      const view = await fetch("/api/view").then((r) => r.json());
      const teaching = view.state === "teaching";
      q("teach-state").textContent = teaching ? view.reason : `station: ${view.reason || view.state}`;
      q("teach-state").dataset.teaching = teaching ? "1" : "0";
      const first = await fetch("/api/teach").then((r) => r.json());
      // teach mode on (this screen's, another's, the command line's): its model is shown
      if (first.current && (teaching || !model())) q("teach-model").value = first.current;
      draw(model() ? await fetch(`/api/teach?model=${encodeURIComponent(model())}`).then((r) => r.json()) : first);
    } catch (e) {
      q("teach-state").textContent = "no answer from the station";
    }
  }

  function boltLabel() {
    const b = q("teach-bolt").value.trim();
    q("teach-point-go").textContent = measuring ? `Measuring ${b}...` : b ? `Teach ${b}` : "Teach";
    q("teach-point-go").disabled = measuring;
  }
  q("teach-bolt").addEventListener("input", boltLabel);

  q("teach-start").addEventListener("submit", async (e) => {
    e.preventDefault();
    await command({kind: "teach-start", model: model()});
    refresh();
  });
  q("teach-point").addEventListener("submit", async (e) => {
    e.preventDefault();
    if (measuring) return;
    measuring = true;   // the station answers once measured (up to 10 s)
    boltLabel();
    try {
      const doc = await command({kind: "teach-point", bolt: q("teach-bolt").value.trim()});
      if (doc && doc.accepted && doc.result) {
        const [x, y, z] = doc.result.position_mm;
        q("cmd-answer").textContent = `${q("teach-bolt").value.trim()} taught: ${fmt(x, 1)} ` +
          `${fmt(y, 1)} ${fmt(z, 1)} mm, dispersion ${fmt(doc.result.dispersion_mm, 2)} mm`;
      }
    } finally {
      measuring = false;
      boltLabel();
      refresh();
    }
  });
  q("teach-stop").addEventListener("click", async () => {
    await command({kind: "teach-stop"});
    refresh();
  });
  refresh();
  setInterval(refresh, 1000);
})();
