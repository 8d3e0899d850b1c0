// testbed live console: plain JavaScript, no build step. Samples the keyboard and the
// Gamepad API at 20 Hz and sends stick intents; draws each state the server publishes.
"use strict";

const $ = (id) => document.getElementById(id);
const STICK_HZ = 20, DEADZONE = 0.05;
const STALE_S = 3; // operator state older than this [s] is flagged stale (docs/live.md)
const ws = new WebSocket(`ws://${location.host}/ws`);
let role = "viewer", state = null, drawn = null, offsetMs = null, bestRtt = Infinity;
const rtts = [], pixelLags = [], trackOp = [], trackTruth = [], depthOp = [], depthTruth = [];
const keys = new Set();
const fmt = (v, d = 2) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));

// a mode this page asked for, shown by the menu until a drawn state says the server took it
// (states in flight would put the old one back for a moment), for at most MODE_PICK_MS
let modePicked = null, modePickedAt = 0;
const MODE_PICK_MS = 3000;
function send(obj) {
  if (ws.readyState !== 1) return;
  if (obj.t === "mode") { modePicked = obj.mode; modePickedAt = performance.now(); }
  if (obj.t === "goto") modePicked = null; // GUIDED, if the server takes it
  ws.send(JSON.stringify(obj));
}
window.consoleSend = send; // for scripted checks

// ---------------------------------------------------------------- input
// The flying keys (and T) belong to the pilot wherever the focus is, except in a field one types
// into: their default action is prevented, so a focused menu never takes them as type-ahead (S
// would pick "stabilize" in the mode menu and send it). A focused menu takes no letters at all.
const FLYING_KEYS = new Set(["KeyW", "KeyS", "KeyA", "KeyD", "KeyQ", "KeyE", "KeyR", "KeyF", "KeyT"]);
const typesText = (el) => !!el && el.tagName === "INPUT" && el.type !== "checkbox";
addEventListener("keydown", (e) => {
  if (typesText(e.target)) return;
  if (FLYING_KEYS.has(e.code) || (e.target.tagName === "SELECT" && e.key.length === 1)) e.preventDefault();
  if (e.code === "KeyT") { if (!e.repeat) $("truth").checked = !$("truth").checked; return; }
  keys.add(e.code); if (e.shiftKey) keys.add("Shift");
}, true);
addEventListener("keyup", (e) => { keys.delete(e.code); if (!e.shiftKey) keys.delete("Shift"); });
addEventListener("blur", () => keys.clear());

function axis(plus, minus) { return (keys.has(plus) ? 1 : 0) - (keys.has(minus) ? 1 : 0); }
const dz = (v) => (Math.abs(v) < DEADZONE ? 0 : Math.max(-1, Math.min(1, v)));
const padButtons = {};

function sampleSticks() {
  const gain = keys.has("Shift") ? 1.0 : 0.5;
  let s = { x: gain * axis("KeyW", "KeyS"), y: gain * axis("KeyD", "KeyA"),
            z: gain * axis("KeyF", "KeyR"), yaw: gain * axis("KeyE", "KeyQ") };
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  const pad = Array.from(pads || []).find((p) => p && p.connected);
  if (pad) {
    $("pad").textContent = "gamepad: " + (pad.id || "?");
    const a = pad.axes;
    // QGC's default (mode 2): left stick yaw / throttle (heave), right stick roll (sway) / pitch (surge)
    const g = { x: dz(-(a[3] || 0)), y: dz(a[2] || 0), z: dz(a[1] || 0), yaw: dz(a[0] || 0) };
    if (g.x || g.y || g.z || g.yaw) s = g;
    // ArduSub's default buttons (standard mapping): A manual, B stabilize, X depth hold,
    // back disarm, start arm
    const actions = { 0: { t: "mode", mode: "manual" }, 1: { t: "mode", mode: "stabilize" },
      2: { t: "mode", mode: "depth_hold" }, 8: { t: "arm", armed: false }, 9: { t: "arm", armed: true } };
    for (const [i, msg] of Object.entries(actions)) {
      const pressed = !!(pad.buttons[i] && pad.buttons[i].pressed);
      if (pressed && !padButtons[i]) send(msg);
      padButtons[i] = pressed;
    }
  }
  return s;
}

// sample at 100 Hz (the Gamepad API has no events for axes); send on change, at once on a
// key event, and every 50 ms regardless (the server's dead man wants news)
let lastSent = "", lastSentAt = 0;
function tick(force) {
  const s = sampleSticks(), text = JSON.stringify({ t: "sticks", ...s }), now = performance.now();
  $("sticks").textContent = `${fmt(s.x)} ${fmt(s.y)} ${fmt(s.z)} ${fmt(s.yaw)}`;
  if (role !== "pilot" || ws.readyState !== 1) return;
  if (force || text !== lastSent || now - lastSentAt >= 1000 / STICK_HZ) {
    ws.send(text); lastSent = text; lastSentAt = now;
  }
}
setInterval(() => tick(false), 10);
addEventListener("keydown", () => tick(true));
addEventListener("keyup", () => tick(true));

// clock probe: offset of the server's monotonic clock from ours (minimum-RTT sample)
setInterval(() => send({ t: "ping", c: performance.now() }), 1000);
setInterval(() => {
  const med = (xs) => { if (!xs.length) return null; const s = [...xs].sort((p, q) => p - q);
    return s[Math.floor(s.length / 2)]; };
  const report = { t: "lat", pixels_ms: med(pixelLags), rtt_ms: med(rtts) };
  pixelLags.length = 0; rtts.length = 0;
  if (report.pixels_ms !== null || report.rtt_ms !== null) send(report);
}, 2000);

$("arm").onclick = () => send({ t: "arm", armed: true });
$("disarm").onclick = () => send({ t: "arm", armed: false });
$("mode").onchange = () => {
  send({ t: "mode", mode: $("mode").value });
  $("mode").blur(); // the keys fly again at once, never pick another mode
};
// The link fields show the values in effect (from the state, 6 significant digits; distance
// blank while it is the scenario's) until edited; a blank field is not sent, and a value the
// server refuses is said in the notes and beside the fields, and its field put back.
const LINK_FIELDS = { ber: "ber", gap: "gap_s", distance: "distance_m" };
const filledWith = {}; // the link value each field was last filled with
const fieldText = (v) => (v === null || v === undefined ? "" : String(Number(Number(v).toPrecision(6))));
function fillLinkFields(L) {
  for (const [id, key] of Object.entries(LINK_FIELDS)) {
    // a new value in effect refills the field, unless the pilot is typing in it
    if (filledWith[id] !== L[key] && document.activeElement !== $(id)) restoreField(id, L);
  }
}
function restoreField(id, L) { $(id).value = fieldText(L[LINK_FIELDS[id]]); filledWith[id] = L[LINK_FIELDS[id]]; }
const pageNotes = []; // the page's own notices (refusals), shown after the server's notes
function showNotes() { $("notes").textContent = (state ? state.console.notes : []).concat(pageNotes).join("\n"); }
function refused(text) {
  const line = `t = ${state ? fmt(state.t, 1) : "–"} s: refused: ${text}`;
  pageNotes.push(line); if (pageNotes.length > 5) pageNotes.shift();
  $("link-refused").textContent = line; showNotes();
}
function setLink(id) {
  const key = LINK_FIELDS[id], text = $(id).value.trim();
  $("link-refused").textContent = "";
  if (text !== "") { send({ t: "link", [key]: Number(text) }); return; }
  refused(`${key}: no value given`); if (state) restoreField(id, state.link);
}
$("set-ber").onclick = () => setLink("ber");
$("set-gap").onclick = () => setLink("gap");
$("reset-gap").onclick = () => send({ t: "link", gap_s: null });
$("set-distance").onclick = () => setLink("distance");
$("reset-distance").onclick = () => send({ t: "link", distance_m: null });
$("outage").onclick = () => send({ t: "outage", duration_s: 3 });
for (let i = 0; i <= 15; i++) $("shift").add(new Option(String(i), String(i), i === 4, i === 4));

// ---------------------------------------------------------------- ROI drag on the image
let roi = null, drag = null;
function imagePixel(e) {
  const c = $("image"), r = c.getBoundingClientRect();
  const x = Math.round(((e.clientX - r.left) / r.width) * c.width);
  const y = Math.round(((e.clientY - r.top) / r.height) * c.height);
  return [Math.max(0, Math.min(c.width - 1, x)), Math.max(0, Math.min(c.height - 1, y))];
}
function sendImage() {
  send({ t: "image", roi, shift: roi ? Number($("shift").value) : 0,
         budget: Math.max(1, Math.min(65535, Math.round(Number($("budget").value) || 1200))) });
}
$("image").onmousedown = (e) => { drag = { a: imagePixel(e), b: imagePixel(e) }; };
$("image").onmousemove = (e) => { if (drag) drag.b = imagePixel(e); };
$("image").onmouseup = (e) => {
  if (!drag) return; drag.b = imagePixel(e);
  const [x0, x1] = [drag.a[0], drag.b[0]].sort((p, q) => p - q);
  const [y0, y1] = [drag.a[1], drag.b[1]].sort((p, q) => p - q);
  drag = null;
  if (x1 - x0 >= 2 && y1 - y0 >= 2) { roi = [x0, y0, x1, y1]; sendImage(); }
};
// A page that opens (or reloads, or takes over the seat) starts from the coder's settings in
// effect: changing only the budget must not clear another pilot's ROI.
let imageSynced = false;
function adoptCoder(cd) {
  const [x0, y0, x1, y1] = cd.roi;
  roi = x1 > x0 && y1 > y0 ? [x0, y0, x1, y1] : null;
  if (cd.shift > 0) $("shift").value = String(cd.shift);
  $("budget").value = String(cd.budget);
  imageSynced = true;
}
$("send-image").onclick = sendImage;
$("clear-roi").onclick = () => { roi = null; sendImage(); };

// ---------------------------------------------------------------- track: click to go to
let view = { cx: 0, cy: 0, scale: 40 };
$("track").onclick = (e) => {
  const c = $("track"), r = c.getBoundingClientRect();
  const px = e.clientX - r.left, py = e.clientY - r.top;
  const north = view.cx + (c.height / 2 - py) / view.scale, east = view.cy + (px - c.width / 2) / view.scale;
  send({ t: "goto", x: Math.round(north * 100) / 100, y: Math.round(east * 100) / 100 });
};

// ---------------------------------------------------------------- state in
ws.onmessage = (ev) => {
  let msg; try { msg = JSON.parse(ev.data); } catch { return; }
  if (msg.t === "pong") {
    const now = performance.now(), rtt = now - msg.c; rtts.push(rtt);
    if (rtt <= bestRtt || offsetMs === null) { bestRtt = rtt; offsetMs = msg.s - (msg.c + now) / 2; }
    return;
  }
  if (msg.t === "rejected") { // e.g. "ber: must be in [0, 0.5], got 0.6"
    refused(String(msg.reason));
    const key = String(msg.reason).split(":")[0];
    for (const id of Object.keys(LINK_FIELDS)) if (LINK_FIELDS[id] === key && state) restoreField(id, state.link);
    return;
  }
  state = msg; role = msg.role;
  const add = (list, p, max) => { list.push(p); if (list.length > max) list.shift(); };
  if (msg.operator) add(trackOp, msg.operator.pos, 3000);
  add(trackTruth, msg.truth.pos, 3000);
  add(depthOp, [msg.t, msg.operator ? msg.operator.pos[2] : null], 600);
  add(depthTruth, [msg.t, msg.truth.pos[2]], 600);
  requestAnimationFrame(draw);
};
ws.onclose = () => { $("role").textContent = "disconnected"; };

function rows(table, data) {
  table.innerHTML = data.map((r) => "<tr>" + r.map((c, i) =>
    `<${i ? "td" : "td"} class="${i ? "v" : "k"}">${c}</td>`).join("") + "</tr>").join("");
}

function drawImage(img) {
  const c = $("image"), g = c.getContext("2d");
  if (img && img.view) {
    const v = img.view;
    if (c.width !== v.w || c.height !== v.h) { c.width = v.w; c.height = v.h; }
    const raw = atob(v.grey), data = g.createImageData(v.w, v.h);
    for (let i = 0; i < raw.length; i++) {
      const q = raw.charCodeAt(i); data.data[4 * i] = data.data[4 * i + 1] = data.data[4 * i + 2] = q;
      data.data[4 * i + 3] = 255;
    }
    g.putImageData(data, 0, 0);
  }
  const box = drag ? [Math.min(drag.a[0], drag.b[0]), Math.min(drag.a[1], drag.b[1]),
    Math.max(drag.a[0], drag.b[0]), Math.max(drag.a[1], drag.b[1])] : roi;
  if (box) { g.strokeStyle = "#0f0"; g.lineWidth = 1; g.strokeRect(box[0] + 0.5, box[1] + 0.5, box[2] - box[0], box[3] - box[1]); }
  if (img) {
    $("img-age").textContent = img.age_s === null ? "–" : `${fmt(img.age_s, 1)} s`;
    $("img-bytes").textContent = img.bytes;
    $("img-done").textContent = img.completed;
    const cd = img.coder;
    $("img-coder").textContent = `roi ${cd.roi.join(",")} shift ${cd.shift} budget ${cd.budget}`;
    if (!imageSynced) adoptCoder(cd);
  }
}

function drawTrack(s, truth) {
  const c = $("track"), g = c.getContext("2d");
  g.fillStyle = "#000"; g.fillRect(0, 0, c.width, c.height);
  const pts = trackOp.concat(truth ? trackTruth : []);
  let span = 2;
  const here = s.truth.pos;
  for (const p of pts) span = Math.max(span, Math.abs(p[0] - here[0]) * 1.2, Math.abs(p[1] - here[1]) * 1.2);
  view = { cx: here[0], cy: here[1], scale: Math.min(c.width, c.height) / (2 * span + 1) };
  const xy = (p) => [c.width / 2 + (p[1] - view.cy) * view.scale, c.height / 2 - (p[0] - view.cx) * view.scale];
  g.strokeStyle = "#333";
  for (let m = -50; m <= 50; m++) {
    const [gx] = xy([0, Math.round(view.cy) + m]); const [, gy] = xy([Math.round(view.cx) + m, 0]);
    g.beginPath(); g.moveTo(gx, 0); g.lineTo(gx, c.height); g.stroke();
    g.beginPath(); g.moveTo(0, gy); g.lineTo(c.width, gy); g.stroke();
  }
  const path = (list, colour) => {
    if (!list.length) return;
    g.strokeStyle = colour; g.beginPath();
    list.forEach((p, i) => { const [x, y] = xy(p); i ? g.lineTo(x, y) : g.moveTo(x, y); });
    g.stroke(); const [x, y] = xy(list[list.length - 1]);
    g.fillStyle = colour; g.beginPath(); g.arc(x, y, 4, 0, 2 * Math.PI); g.fill();
  };
  path(trackOp, "#4af");
  if (truth) path(trackTruth, "#f90");
  const goal = s.truth.target; // the go-to point the vehicle holds (GUIDED)
  if (goal) {
    const [x, y] = xy(goal); g.strokeStyle = "#6f6"; g.beginPath();
    g.moveTo(x - 6, y - 6); g.lineTo(x + 6, y + 6); g.moveTo(x - 6, y + 6); g.lineTo(x + 6, y - 6); g.stroke();
  }
}

function drawDepth(truth) {
  const c = $("depth"), g = c.getContext("2d");
  g.fillStyle = "#000"; g.fillRect(0, 0, c.width, c.height);
  const all = depthOp.concat(depthTruth).filter((p) => p[1] !== null);
  if (!all.length) return;
  const t1 = all.reduce((m, p) => Math.max(m, p[0]), 0), t0 = t1 - 60;
  const dMax = Math.max(2, ...all.map((p) => p[1] + 0.5));
  const xy = (p) => [((p[0] - t0) / 60) * c.width, (p[1] / dMax) * c.height];
  g.fillStyle = "#666"; g.fillText(`depth 0..${dMax.toFixed(1)} m, last 60 s`, 4, 12);
  const line = (list, colour) => {
    g.strokeStyle = colour; g.beginPath(); let first = true;
    for (const p of list) { if (p[1] === null || p[0] < t0) continue;
      const [x, y] = xy(p); first ? g.moveTo(x, y) : g.lineTo(x, y); first = false; }
    g.stroke();
  };
  line(depthOp, "#4af"); if (truth) line(depthTruth, "#f90");
}

// the packet timeline's colours, and its legend drawn from them (one place for both)
const KIND_COLOUR = { tx_start: "#888", deliver: "#3c3", corrupt: "#f93", collide: "#f33",
  deaf: "#f6a", outage: "#b5f", drop: "#fff", out_of_range: "#0cc" };
const KIND_LABEL = [["tx_start", "sent"], ["deliver", "delivered"], ["corrupt", "corrupted"],
  ["collide", "collided"], ["deaf", "lost transmitting"], ["outage", "outage"], ["drop", "dropped"], ["out_of_range", "out of range"]];
$("legend").innerHTML = KIND_LABEL.map(([kind, label]) =>
  `<span style="color:${KIND_COLOUR[kind]}">■</span> ${label}`).join(" · ");
function drawTimeline(s) {
  const c = $("timeline"), g = c.getContext("2d");
  g.fillStyle = "#000"; g.fillRect(0, 0, c.width, c.height);
  const t1 = s.t, t0 = t1 - 30;
  for (const [t, dir, kind] of s.link.timeline) {
    if (t < t0) continue;
    const x = ((t - t0) / 30) * c.width, y = dir === "uplink" ? 5 : 50;
    g.fillStyle = KIND_COLOUR[kind] || "#ccc";
    g.fillRect(x, y + (kind === "tx_start" ? 0 : 12), 2, kind === "tx_start" ? 10 : 22);
  }
}

function draw() {
  const s = state; if (!s || s === drawn) return;
  drawn = s;
  const truth = $("truth").checked;
  $("role").textContent = s.role; $("t").textContent = fmt(s.t, 1); $("viewers").textContent = s.viewers;
  drawImage(s.image);
  const o = s.operator, tr = s.truth;
  const both = (a, b, d = 2) => (truth ? `${a} <span style="color:#f90">(${b})</span>` : a);
  // stale: the operator's last state is older than STALE_S; its values are greyed and the age
  // flagged (the truth beside them, when shown, is not stale)
  const stale = !!o && o.age_s !== null && o.age_s > STALE_S;
  $("telemetry").classList.toggle("stale", stale);
  const ageText = !o ? "–" : stale ? `<span class="bad">${fmt(o.age_s)} stale (&gt; ${STALE_S} s)</span>` : fmt(o.age_s);
  rows($("telemetry"), o ? [
    ["depth [m]", both(fmt(o.pos[2]), fmt(tr.pos[2]))],
    ["north, east [m]", both(`${fmt(o.pos[0])}, ${fmt(o.pos[1])}`, `${fmt(tr.pos[0])}, ${fmt(tr.pos[1])}`)],
    ["heading [deg]", both(fmt(o.rpy[2], 1), fmt(tr.rpy[2], 1))],
    ["roll, pitch [deg]", both(`${fmt(o.rpy[0], 1)}, ${fmt(o.rpy[1], 1)}`, `${fmt(tr.rpy[0], 1)}, ${fmt(tr.rpy[1], 1)}`)],
    ["armed", both(String(o.armed), String(tr.armed))],
    // the mode the vehicle last reported; while it is not the one asked for, both, in red
    ["mode", !o.mode || o.mode === s.pilot.mode ? o.mode
      : `<span class="bad">${o.mode} (asked ${s.pilot.mode})</span>`],
    ["state age [s]", ageText],
    // the vehicle's failsafe is physics truth (the operator is not told it): truth overlay only
    ...(truth ? [["failsafe (truth)", `<span style="color:#f90">(${tr.failsafe})</span>`]] : []),
  ] : [["telemetry", "waiting for the first reply"]]);
  drawTrack(s, truth); drawDepth(truth); drawTimeline(s);
  const pilot = s.role === "pilot"; // a viewer watches: its controls are greyed (and ignored)
  for (const el of document.querySelectorAll("button, select, input")) el.disabled = !pilot;
  $("truth").disabled = false;
  for (const id of ["set-ber", "set-gap", "reset-gap", "set-distance", "reset-distance", "outage"])
    $(id).disabled = !pilot || !s.link.simulated; // HIL ports: the real link is not ours to change
  fillLinkFields(s.link);
  // the menu shows the mode the operator asks for, whoever asked (the menu, a gamepad button,
  // a go-to, the scenario's start), except while the pilot has it open
  if (modePicked !== null && (s.pilot.mode === modePicked
      || performance.now() - modePickedAt > MODE_PICK_MS)) modePicked = null;
  if (s.pilot.mode && modePicked === null && document.activeElement !== $("mode"))
    $("mode").value = s.pilot.mode;
  const L = s.link, u = L.uplink, d = L.downlink, pct = (p) => (p === null ? "–" : `${(100 * p).toFixed(1)} %`);
  rows($("link"), [["", "uplink", "downlink"], ["sent", u.sent, d.sent], ["delivered", u.delivered, d.delivered],
    ["corrupted", u.corrupted, d.corrupted], ["collided", u.collided, d.collided],
    ["outage", u.outage, d.outage], ["out of range", u.out_of_range, d.out_of_range],
    ["dropped", u.dropped, d.dropped], ["PER", pct(u.per), pct(d.per)]]);
  rows($("ages"), [["command lag [s]", fmt(L.command_lag_s)], ["command age [s]", fmt(L.command_age_s)],
    ["odometry age [s]", fmt(L.odometry_age_s)], ["BER", L.ber], ["gap [s]", fmt(L.gap_s, 3)],
    ["distance [m]", L.distance_m === null ? "scenario" : L.distance_m],
    ["outage now", L.outage ? '<span class="bad">yes</span>' : "no"]]);
  const C = s.console, lat = C.input_latency_ms;
  rows($("latency"), [["input → intent (server queue) p50/p95 [ms]", `${fmt(lat.p50)} / ${fmt(lat.p95)}`],
    ["browser ↔ server round trip [ms]", fmt(bestRtt === Infinity ? null : bestRtt)],
    ["state → pixels [ms]", fmt(pixelLags.length ? pixelLags[pixelLags.length - 1] : null)],
    ["scheduler lateness p95 [ms]", fmt(C.lateness_ms.p95)],
    ["inputs ok / malformed / range / flood", `${C.inputs.accepted} / ${C.inputs.malformed} / ${C.inputs.out_of_range} / ${C.inputs.flooded}`]]);
  showNotes();
  rows($("events"), s.events.slice().reverse().map((e) => [fmt(e[0], 1), `${e[1]} ${e[2]} ${e[3]}`]));
  if (offsetMs !== null) pixelLags.push(performance.now() + offsetMs - s.server_ns / 1e6);
}
