// Commissioning screen: per pair, the latest left/right frames (JPEG, reduced, encoded by the
// server on request) with the detector's overlay drawn in SVG over them.
"use strict";
const NS = "http://www.w3.org/2000/svg";
const $ = (id) => document.getElementById(id);
// the frames are asked for at the width they are shown (steps of 320 px: cached server-side)
const WIDTH = Math.min(1920, Math.max(320, Math.ceil(window.innerWidth * (window.devicePixelRatio || 1) / 2 / 320) * 320));
function fmt(v, d) { return v === null || v === undefined ? "-" : Number(v).toFixed(d); }
function el(tag, attrs) {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  return e;
}

function overlay(cam) {
  const s = cam.summary || {};
  const svg = el("svg", {viewBox: `0 0 ${cam.width} ${cam.height}`, preserveAspectRatio: "none"});
  const k = cam.width / WIDTH;
  if (s.roi) {
    const [x, y, w, h] = s.roi;
    svg.appendChild(el("rect", {class: "roi", x, y, width: w, height: h, fill: "none",
      stroke: "#2f8fff", "stroke-width": 3 * k}));
  }
  for (const e of s.ellipses || []) {   // [cx, cy, a, b, angle_deg]
    const [cx, cy, a, b, ang] = e;
    svg.appendChild(el("ellipse", {class: "ellipse", cx, cy, rx: a, ry: b, fill: "none",
      stroke: "#ffd400", "stroke-width": 3 * k, transform: `rotate(${ang || 0} ${cx} ${cy})`}));
  }
  if (s.centre) {
    const [cx, cy] = s.centre, r = 12 * k;
    svg.appendChild(el("path", {class: "centre", d: `M${cx - r} ${cy}H${cx + r}M${cx} ${cy - r}V${cy + r}`,
      stroke: "#ff3b3b", "stroke-width": 3 * k}));
  }
  return svg;
}

// Only the frames on screen are fetched again: a frame scrolled out of view keeps its last
// picture (its facts and overlay still update) and costs the daemon no encoding; at 1920x1080
// one or two pairs of the four are in view.
const shown = new Set();
const seen = new IntersectionObserver((entries) => {
  for (const e of entries) {
    if (e.isIntersecting) shown.add(e.target.dataset.camera);
    else shown.delete(e.target.dataset.camera);
  }
});

function camDiv(cam, stamp, old) {
  const s = cam.summary || {};
  const d = document.createElement("div");
  d.className = "cam";
  d.dataset.camera = `${cam.pair}/${cam.side}`;
  const fr = document.createElement("div");
  fr.className = "frame";
  const key = `${cam.pair}/${cam.side}`;
  const keep = old[key] && !shown.has(key);
  // a kept frame stays where it is until the swap (moving it now would shorten the page
  // and scroll what is in view): a placeholder marks its new place
  const img = keep ? old[key] : document.createElement("img");
  img.alt = `${cam.pair} ${cam.side}`;
  if (!keep)
    img.src = `/api/cameras/${encodeURIComponent(cam.pair)}/${cam.side}/frame.jpg?w=${WIDTH}&s=${stamp}`;
  img.onclick = (ev) => {
    const r = img.getBoundingClientRect();
    const x = Math.round((ev.clientX - r.left) / r.width * cam.width);
    const y = Math.round((ev.clientY - r.top) / r.height * cam.height);
    openCrop();
    $("crop-title").textContent = `${cam.pair} ${cam.side} at (${x}, ${y}), full resolution`;
    $("crop-img").src = `/api/cameras/${encodeURIComponent(cam.pair)}/${cam.side}/crop.jpg?x=${x}&y=${y}&size=512&s=${Date.now()}`;
  };
  if (keep) {
    const spot = document.createElement("span");
    spot.className = "kept";
    fr.appendChild(spot);
    fr.kept = [spot, img];
  } else fr.appendChild(img);
  fr.appendChild(overlay(cam));
  d.appendChild(fr);
  const facts = document.createElement("div");
  facts.className = "facts";
  // a frame rate is only true of a camera that is grabbing now: an old frame says its age
  const old_ = !recent(cam);
  d.classList.toggle("old", old_);
  if (old_) {
    const tag = document.createElement("div");
    tag.className = "old-tag";
    tag.textContent = `\u26A0 OLD FRAME: ${ago(cam.age_s)}`;
    fr.appendChild(tag);
  }
  facts.textContent = `${cam.side}: ${cam.width}x${cam.height}, ` +
    (old_ ? `no new frame for ${ago(cam.age_s)}` :
     `${fmt(cam.fps, 1)} fps, grabbed ${fmt(cam.age_s, 1)} s ago`) +
    `, sharpness ${fmt(s.sharpness, 0)}` +
    (s.exposure_us ? `, exposure ${s.exposure_us} \u00B5s` : "") +
    (s.found === undefined ? "" : s.found ? ", marker found" : ", no marker");
  d.appendChild(facts);
  if (s.reason) {
    // a marker seen and refused (tilted, ambiguous) in red; none in view is the idle state
    // of a camera whose wrench is elsewhere, said plainly (an operator trial: every camera
    // of an idle station in bold red "refused: no purple region ...")
    const r = document.createElement("div");
    r.className = s.found ? "refusal" : "no-marker";
    r.textContent = s.found ? `refused: ${s.reason}` : `no marker: ${s.reason}`;
    d.appendChild(r);
  }
  return d;
}

// recent: within three frame periods, and never more than RECENT_S (a 1 fps camera's frame
// 3 s old is late, not live)
const RECENT_S = 2;
function recent(cam) {
  const period = cam.fps ? 1 / cam.fps : RECENT_S;
  return cam.age_s !== null && cam.age_s <= Math.min(RECENT_S, Math.max(0.5, 3 * period));
}
function ago(s) {
  return s < 120 ? `${fmt(s, 0)} s` : s < 7200 ? `${fmt(s / 60, 0)} min` : `${fmt(s / 3600, 1)} h`;
}

// each configured pair's health line: a pair that is down says why, even without a frame
function healthLine(h) {
  const p = document.createElement("div");
  p.className = "pair-health " + (!h ? "" : h.ok ? "dev-ok" : h.kind === "opening" ? "dev-wait" : "dev-bad");
  p.textContent = !h ? "" : h.ok ? "ok" : h.kind === "opening" ? "not opened yet" :
    `${h.kind || "fault"}: ${h.reason}`;
  return p;
}

// the pair's calibration check (with reference markers): trusted, moved with the figure, or
// not checked with why; a pair that is up but not trusted has its bolts refused
function trustLine(check) {
  const p = document.createElement("div");
  p.className = "pair-trust " + (check.trusted ? "dev-ok" : check.verdict === "moved" ? "dev-bad" : "dev-wait");
  p.dataset.trust = check.trusted ? "trusted" : check.verdict;
  p.textContent = check.trusted ? `trusted (${check.words})` : check.words;
  return p;
}
const moved = (h) => !!(h && h.check && h.check.verdict === "moved" && !h.check.trusted);

function openCrop() {
  $("crop").hidden = false;
  $("crop-close").focus();
}
function closeCrop() { $("crop").hidden = true; }
$("crop-close").onclick = closeCrop;
document.addEventListener("keydown", (e) => { if (e.key === "Escape") closeCrop(); });

// A refresh builds the new frames off screen and swaps them in only once every image has
// decoded, and the next refresh waits for that: the shown frames never go blank while the
// server encodes (8 reduced 20 MP frames can take longer than the refresh period on a busy
// station PC), and the refresh rate falls to what the server delivers instead of piling up.
let busy = false;
async function refresh() {
  if (busy) return;
  busy = true;
  try {
    const [cams, configured] = await Promise.all([
      fetch("/api/cameras").then((r) => r.json()),
      fetch("/api/pairs").then((r) => r.ok ? r.json() : []).catch(() => [])]);
    const pairs = {}, health = {};
    for (const h of configured) { pairs[h.pair] = []; health[h.pair] = h; }   // in their order
    for (const c of cams) (pairs[c.pair] = pairs[c.pair] || []).push(c);
    const stamp = Date.now();
    const old = {};   // the frames now shown, by camera: an off-screen one is moved over
    for (const d of document.querySelectorAll("#pairs .cam"))
      old[d.dataset.camera] = d.querySelector(".frame img");
    const sections = [];
    for (const [name, list] of Object.entries(pairs)) {
      const p = document.createElement("section");
      p.className = "pair" + (health[name] && (!health[name].ok || moved(health[name])) ? " pair-bad" : "");
      p.dataset.pair = name;
      p.innerHTML = "<h2></h2>";
      // config/sim names its pairs "pair1"...: not "pair pair1"
      p.firstChild.textContent = /^pair/i.test(name) ? name : `pair ${name}`;
      if (health[name]) p.appendChild(healthLine(health[name]));
      if (health[name] && health[name].check) p.appendChild(trustLine(health[name].check));
      if (!list.length) {
        const none = document.createElement("div");
        none.className = "no-frames";
        none.textContent = "No frames from this pair yet.";
        p.appendChild(none);
      }
      const row = document.createElement("div");
      row.className = "cams";
      for (const c of list) row.appendChild(camDiv(c, stamp, old));
      p.appendChild(row);
      sections.push(p);
    }
    const imgs = sections.flatMap((p) => [...p.querySelectorAll("img")]);
    await Promise.allSettled(imgs.map((i) => i.decode()));  // a missing frame shows its alt
    for (const p of sections)
      for (const fr of p.querySelectorAll(".frame"))
        if (fr.kept) fr.kept[0].replaceWith(fr.kept[1]);
    const root = $("pairs");
    if (!sections.length) root.textContent = "No frames yet: the daemon has handed over none.";
    else root.replaceChildren(...sections);
    seen.disconnect();
    for (const d of root.querySelectorAll(".cam")) seen.observe(d);
  } finally {
    busy = false;
  }
}
refresh();
setInterval(() => { if ($("live").checked) refresh(); }, 1000);
