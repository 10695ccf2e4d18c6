// Commands from the operator screen: log in (a session cookie the server sets), skip a bolt of
// the vehicle at the station, release a locked bolt, loosen a tightened one for rework, reopen
// a closed vehicle.  The station decides: the screen shows
// its answer (accepted, or refused with the reason in words) and nothing else.
"use strict";
(function () {
  const q = (id) => document.getElementById(id);
  let rights = [];

  function show(who) {
    const signed = Boolean(who && who.user);
    rights = signed ? who.rights : [];
    q("login").hidden = signed;
    q("signed").hidden = !signed;
    q("who").textContent = signed ? `${who.user} (${who.rights.join(", ") || "no rights"})` : "";
    q("skip").hidden = !rights.includes("skip");
    q("reopen").hidden = !rights.includes("reopen");
    q("release").hidden = !rights.includes("release");
    q("loosen").hidden = !rights.includes("loosen");
  }

  function answer(text, ok) {
    const a = q("cmd-answer");
    a.textContent = text;
    a.className = ok ? "cmd-ok" : "cmd-refused";
    a.dataset.ok = ok ? "1" : "0";
  }

  async function post(path, body) {
    const r = await fetch(path, {method: "POST", credentials: "same-origin",
      headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)});
    const text = await r.text();
    let doc = null;
    try { doc = JSON.parse(text); } catch (e) { doc = null; }
    return {status: r.status, doc, text: text.trim()};
  }

  async function command(body) {
    // a single-use nonce from the station for each command: a captured request cannot be
    // sent again, and the panel PC's clock does not matter
    const n = await fetch("/api/nonce", {credentials: "same-origin"});
    if (!n.ok) {
      if (n.status === 401) show(null);
      answer((await n.text()).trim() || `HTTP ${n.status}`, false);
      return;
    }
    const r = await post("/api/commands", {...body, nonce: (await n.json()).nonce});
    if (r.doc && "accepted" in r.doc) answer(r.doc.accepted ? r.doc.words :
      `refused: ${r.doc.reason.words}`, r.doc.accepted);
    else {
      if (r.status === 401) show(null);
      answer(r.text || `HTTP ${r.status}`, false);
    }
  }

  // the bolts one may skip (those of the vehicle at the station not done yet) and those one
  // may release (locked after too many NOKs)
  function fill(id, want) {
    const view = window.lastView;
    const sel = q(id);
    const bolts = view && view.vehicle ? view.bolts.filter(want) : [];
    const key = bolts.map((b) => b.bolt).join(",");
    if (sel.dataset.key === key) return;
    const keep = sel.value;
    sel.dataset.key = key;
    // no bolt chosen until the user chooses one: one click must not act on the first
    sel.replaceChildren(new Option("bolt...", ""), ...bolts.map((b) => new Option(b.bolt, b.bolt)));
    if (bolts.some((b) => b.bolt === keep)) sel.value = keep;
  }
  setInterval(() => {
    fill("skip-bolt", (b) => b.state !== "ok" && b.state !== "skipped");
    fill("release-bolt", (b) => b.locked);
    // a bolt tightened (OK, or NOK last) and not to be loosened already: rework
    fill("loosen-bolt", (b) => (b.state === "ok" || b.state === "nok") && !b.loosen && !b.locked);
  }, 500);

  q("login").addEventListener("submit", async (e) => {
    e.preventDefault();
    const r = await post("/api/login", {user: q("login-user").value, password: q("login-password").value});
    q("login-password").value = "";
    if (r.status === 200 && r.doc) { show(r.doc); answer(`logged in as ${r.doc.user}`, true); }
    else answer(r.text || `HTTP ${r.status}`, false);
  });
  q("logout").addEventListener("click", async () => {
    await post("/api/logout", {});
    show(null);
    answer("logged out", true);
  });
  q("skip").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("skip-bolt").value) { answer("choose the bolt to skip", false); return; }
    command({kind: "skip", vin: view.vehicle.vin, bolt: q("skip-bolt").value, comment: q("skip-comment").value});
  });
  q("release").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("release-bolt").value) { answer("choose the locked bolt to release", false); return; }
    command({kind: "release", vin: view.vehicle.vin, bolt: q("release-bolt").value, comment: q("release-comment").value});
  });
  q("loosen").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("loosen-bolt").value) { answer("choose the bolt to loosen", false); return; }
    command({kind: "loosen", vin: view.vehicle.vin, bolt: q("loosen-bolt").value, comment: q("loosen-comment").value});
  });
  q("reopen").addEventListener("submit", (e) => {
    e.preventDefault();
    command({kind: "reopen", vin: q("reopen-vin").value, comment: q("reopen-comment").value});
  });
  fetch("/api/me", {credentials: "same-origin"}).then((r) => r.ok ? r.json() : null).then(show, () => show(null));
})();
