// Commands from the operator screen (logged in through session.js): skip a bolt of
// the vehicle at the station, release a locked bolt, enter the outcome of a held one (its
// result could not be read: read on the controller's screen), loosen a tightened one for
// rework, reopen a closed vehicle.  The station decides: the screen shows
// its answer (accepted, or refused with the reason in words) and nothing else.
"use strict";
(function () {
  const q = (id) => document.getElementById(id);
  // logging in and out, and each command's nonce and answer: session.js (the Teach panel's too)
  let me = null;   // the session's user
  // a comment is one command's: cleared once it is accepted and when the user changes (the
  // next person found the last one's words in the form: a supervisor's trial)
  const COMMENTS = ["skip-comment", "release-comment", "enter-comment", "loosen-comment",
                    "reopen-comment"];
  const clearComments = () => { for (const id of COMMENTS) if (q(id)) q(id).value = ""; };
  let mayRelease = false;   // a locked or held bolt is skipped only by who may release it
  const {command, answer} = window.StationSession.bind((rights, user) => {
    if (user !== me) clearComments();
    me = user;
    mayRelease = rights.includes("release");
    q("skip").hidden = !rights.includes("skip");
    q("reopen").hidden = !rights.includes("reopen");
    q("release").hidden = !rights.includes("release");
    q("enter").hidden = !rights.includes("release");   // the other way to end a hold
    q("loosen").hidden = !rights.includes("loosen");
  });

  // (an entered outcome's verdict and values are that bolt's too: left in the form, the next
  // hold was one click and a comment away from the last one's outcome)
  async function send(body, comment, more = []) {
    const doc = await command(body);
    if (doc && doc.accepted) for (const id of [comment, ...more]) q(id).value = "";
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
  // signing in at the station (any user, for themselves) and out: the buttons follow who the
  // station says is signed in
  function signButtons() {
    const view = window.lastView;
    const op = view && view.operator ? view.operator.user : null;
    q("sign-in").hidden = Boolean(me) && op === me;
    q("sign-out").hidden = !op;
    q("sign-out").textContent = op && op !== me ? `Sign out ${op}` : "Sign out";
  }
  // a bolt locked or held and a user who may release it: the Release form brought into
  // the Commands panel's view, once for each set of bolts and user (a supervisor's trial at
  // 1280x800: the locked panel shrank Commands to a scroll box showing Reopen, the form he
  // came for out of sight)
  let shownFor = "";
  function toRelease() {
    const key = q("release-bolt").dataset.key || "";
    if (!mayRelease || !key || q("release").hidden) { shownFor = ""; return; }
    if (shownFor === `${me} ${key}`) return;
    shownFor = `${me} ${key}`;
    const panel = q("commands"), form = q("release");
    const top = form.getBoundingClientRect().top - panel.getBoundingClientRect().top
      - panel.clientTop + panel.scrollTop;   // the form's place in the panel's content
    if (top < panel.scrollTop || top + form.offsetHeight > panel.scrollTop + panel.clientHeight) {
      panel.scrollTop = Math.max(0, top - 4);
    }
  }
  q("sign-in").addEventListener("click", () => command({kind: "sign-in", comment: ""}));
  q("sign-out").addEventListener("click", () => command({kind: "sign-out", comment: ""}));
  setInterval(() => {
    signButtons();
    // (the station refuses an operator's skip of a locked bolt: not offered, as a trial asked)
    fill("skip-bolt", (b) => b.state !== "ok" && b.state !== "skipped" &&
         (mayRelease || (!b.locked && !b.held)));
    fill("release-bolt", (b) => b.locked);
    fill("enter-bolt", (b) => b.held);
    toRelease();
    // a bolt tightened (OK, or NOK last) and not to be loosened already: rework
    fill("loosen-bolt", (b) => (b.state === "ok" || b.state === "nok") && !b.loosen && !b.locked);
  }, 500);

  q("skip").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("skip-bolt").value) { answer("choose the bolt to skip", false); return; }
    if (!q("skip-comment").value.trim()) { answer("say why the bolt is skipped", false); return; }
    send({kind: "skip", vin: view.vehicle.vin, bolt: q("skip-bolt").value, comment: q("skip-comment").value}, "skip-comment");
  });
  q("release").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("release-bolt").value) { answer("choose the locked bolt to release", false); return; }
    if (!q("release-comment").value.trim()) { answer("say why it is released (what was checked)", false); return; }
    send({kind: "release", vin: view.vehicle.vin, bolt: q("release-bolt").value, comment: q("release-comment").value}, "release-comment");
  });
  q("enter").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("enter-bolt").value) { answer("choose the held bolt", false); return; }
    if (!q("enter-ok").value) { answer("choose OK or NOK, as the controller shows it", false); return; }
    const torque = Number(q("enter-torque").value), angle = Number(q("enter-angle").value);
    if (q("enter-torque").value === "" || !Number.isFinite(torque) || torque < 0) {
      answer("the torque the controller shows, N·m", false); return;
    }
    if (q("enter-angle").value === "" || !Number.isFinite(angle)) {
      answer("the angle the controller shows, degrees", false); return;
    }
    if (!q("enter-comment").value.trim()) { answer("say what was checked on the controller", false); return; }
    send({kind: "enter-outcome", vin: view.vehicle.vin, bolt: q("enter-bolt").value,
          ok: q("enter-ok").value === "ok", torque_nm: torque, angle_deg: angle,
          comment: q("enter-comment").value}, "enter-comment",
         ["enter-ok", "enter-torque", "enter-angle"]);
  });
  q("loosen").addEventListener("submit", (e) => {
    e.preventDefault();
    const view = window.lastView;
    if (!view || !view.vehicle) { answer("no vehicle at the station", false); return; }
    if (!q("loosen-bolt").value) { answer("choose the bolt to loosen", false); return; }
    if (!q("loosen-comment").value.trim()) { answer("say why it is to be loosened", false); return; }
    send({kind: "loosen", vin: view.vehicle.vin, bolt: q("loosen-bolt").value, comment: q("loosen-comment").value}, "loosen-comment");
  });
  q("reopen").addEventListener("submit", (e) => {
    e.preventDefault();
    // said in the panel as every other form's missing choice (the browser's own bubble, where
    // it showed one, left the last command's answer below, read as this one's)
    if (!q("reopen-vin").value.trim()) { answer("type the VIN of the vehicle to reopen", false); return; }
    send({kind: "reopen", vin: q("reopen-vin").value, comment: q("reopen-comment").value}, "reopen-comment");
  });
})();
