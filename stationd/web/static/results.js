// Results screens: the vehicles and each vehicle's rundowns, read from the server's API.
"use strict";
const q = (s) => document.querySelector(s);
function fmt(v, d) { return v === null || v === undefined ? "-" : Number(v).toFixed(d); }
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
    const list = await getJson("/api/vehicles");
    if (!list.length) {
      const tr = document.createElement("tr");
      tr.className = "empty";
      cell(tr, "No vehicles yet: they appear here once the station opens one.").colSpan = 8;
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
      cell(tr, v.status + (v.reopened_at ? ", reworked" : ""), "status-" + v.status);
      cell(tr, v.ok.length);
      cell(tr, v.nok.length + (v.nok.length ? " (" + v.nok.join(", ") + ")" : ""), v.nok.length ? "status-NOK" : "");
      cell(tr, v.missing.length);
      cell(tr, (v.started_at || "").slice(0, 19));
      cell(tr, (v.ended_at || "open").slice(0, 19));
      tb.appendChild(tr);
    }
  } catch (e) { q("#error").textContent = e.message; }
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
    q("#title").textContent = `${v.vin} (${v.model}${v.reopened_at ? ", reworked" : ""})`;
    q("#summary").textContent = `${v.ok.length} OK, ${v.nok.length} NOK, ${v.missing.length} missing` +
      (v.complete ? ": complete" : "");
    const tb = q("#rundowns tbody");
    for (const b of v.bolts) {
      const runs = b.rundowns.length ? b.rundowns : [null];
      runs.forEach((r, i) => {
        const tr = document.createElement("tr");
        tr.className = "rundown";
        tr.dataset.bolt = b.bolt;
        cell(tr, i ? "" : b.bolt);
        cell(tr, i ? "" : b.status.toUpperCase(), "status-" + (b.status === "nok" ? "NOK" : b.status));
        if (!r) {
          cell(tr, "-"); cell(tr, "not tightened");
          for (let k = 0; k < 7; k++) cell(tr, "", k === 6 ? "crops" : "");
        }
        else {
          cell(tr, r.attempt + (r.attempt > 1 ? " (rework)" : ""));
          cell(tr, r.status.toUpperCase(), "status-" + (r.status === "nok" ? "NOK" : "ok"));
          cell(tr, fmt(r.torque_nm, 1)); cell(tr, fmt(r.angle_deg, 0)); cell(tr, r.pset ?? "-");
          cell(tr, fmt(r.tilt_deg, 1)); cell(tr, fmt(r.match_distance_mm, 1));
          cell(tr, (r.recorded_at || "").slice(0, 19));
          const td = cell(tr, "", "crops");
          for (const im of r.image_urls || []) {
            const a = document.createElement("a");
            a.href = im; a.textContent = "crop "; td.appendChild(a);
          }
        }
        tb.appendChild(tr);
      });
    }
    // crops are saved only with records.save_images (off in config/sim): no empty column
    const crops = v.bolts.some((b) => b.rundowns.some((r) => (r.image_urls || []).length));
    q("#rundowns").classList.toggle("no-crops", !crops);
  } catch (e) {
    if (e.status === 404) {
      q("#title").textContent = `no vehicle ${vin}`;
      q("#summary").textContent = "The results database holds no vehicle with this VIN.";
    } else q("#error").textContent = e.message;
  }
}
