// A user's session on a screen, shared by the operator screen's Commands panel and the
// commissioning screen's Teach panel: log in (a session cookie the server sets), log out, and
// give a command (a single-use nonce from the station, then the command).  The station decides:
// a command's answer is what it said (accepted, or refused with the reason in words).
//
// A page has one login form: #login (#login-user, #login-password), #signed (#who, #logout) and
// #cmd-answer; StationSession.bind(onWho) wires them and returns {command, show, answer}.
"use strict";
window.StationSession = (function () {
  const q = (id) => document.getElementById(id);

  // what a request that reached no station says: the fetch failed (the daemon stopped, the
  // network down); a click that silently did nothing was taken for a command given
  const NO_STATION = "no connection to the station";

  async function post(path, body) {
    let r;
    try {
      r = await fetch(path, {method: "POST", credentials: "same-origin",
        headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)});
    } catch (e) {
      return {status: 0, doc: null, text: "", unreached: true};
    }
    const text = await r.text();
    let doc = null;
    try { doc = JSON.parse(text); } catch (e) { doc = null; }
    return {status: r.status, doc, text: text.trim()};
  }

  function answer(text, ok) {
    const a = q("cmd-answer");
    a.textContent = text;
    a.className = ok ? "cmd-ok" : "cmd-refused";
    a.dataset.ok = ok ? "1" : "0";
    // in sight where the command was given: on a panel PC or a tablet the forms reach below
    // the window (or the panel scrolls), and an answer out of view was no answer at all
    a.scrollIntoView({block: "nearest"});
  }

  function bind(onWho) {
    let shown;   // the session last shown (JSON), so a refresh that finds it alike changes nothing
    function show(who) {
      shown = JSON.stringify(who && who.user ? who : null);
      const signed = Boolean(who && who.user);
      q("login").hidden = signed;
      q("signed").hidden = !signed;
      q("who").textContent = signed ? `${who.user} (${who.rights.join(", ") || "no rights"})` : "";
      onWho(signed ? who.rights : [], signed ? who.user : null);
    }

    // the station's answer, shown; resolves to the answer's JSON (null: no answer from the
    // station: not logged in, a refused nonce, the station not serving)
    async function command(body) {
      // a single-use nonce for each command: a captured request cannot be sent again, and
      // the panel PC's clock does not matter
      let n;
      try {
        n = await fetch("/api/nonce", {credentials: "same-origin"});
      } catch (e) {
        answer(`${NO_STATION}: not sent`, false);
        return null;
      }
      if (!n.ok) {
        if (n.status === 401) show(null);
        answer((await n.text()).trim() || `HTTP ${n.status}`, false);
        return null;
      }
      const r = await post("/api/commands", {...body, nonce: (await n.json()).nonce});
      if (r.unreached) {   // it may or may not have reached the station: the journal says
        answer(`${NO_STATION}: the answer did not come (stationd status or the journal says ` +
               "whether it was taken)", false);
        return null;
      }
      if (r.doc && "accepted" in r.doc) {
        answer(r.doc.accepted ? r.doc.words : `refused: ${r.doc.reason.words}`, r.doc.accepted);
        return r.doc;
      }
      if (r.status === 401) show(null);
      answer(r.text || `HTTP ${r.status}`, false);
      return null;
    }

    q("login").addEventListener("submit", async (e) => {
      e.preventDefault();
      const r = await post("/api/login", {user: q("login-user").value, password: q("login-password").value});
      q("login-password").value = "";
      if (r.unreached) answer(`${NO_STATION}: not logged in`, false);
      else if (r.status === 200 && r.doc) { show(r.doc); answer(`logged in as ${r.doc.user}`, true); }
      else answer(r.text || `HTTP ${r.status}`, false);
    });
    q("logout").addEventListener("click", async () => {
      const r = await post("/api/logout", {});
      if (r.unreached) {   // the session is the station's: ended only when it hears of it
        answer(`${NO_STATION}: not logged out`, false);
        return;
      }
      show(null);
      answer("logged out", true);
    });
    // who is logged in, asked again: at the start, when the screen is live again (a daemon
    // restarted has no session: the panel looked logged in and lost the first command typed)
    // and every 30 s (a reload changed the rights); shown only when it changed (the forms keep
    // what is being typed)
    function refresh() {
      fetch("/api/me", {credentials: "same-origin"}).then((r) => r.ok ? r.json() : null)
        .then((who) => { if (JSON.stringify(who && who.user ? who : null) !== shown) show(who); },
              () => {});
    }
    refresh();
    window.addEventListener("station-live", refresh);
    setInterval(refresh, 30000);
    return {command, show, answer};
  }

  return {bind, post};
})();
