// The protoduino console's page (docs/console.md): one WebSocket to the console, a picture of
// the board every 100 ms, commands back. The driving page sends the board's heartbeat every
// failsafe_timeout / 4: when it stops (tab closed, laptop asleep, network gone) the device's
// failsafe drives every output safe. Plots: uPlot (served by the console, no CDN).
"use strict";

const C = {
  state: null, // the latest picture
  plots: {}, // pin -> uPlot
  ws: null,
  beatTimer: null,
  layout: "", // the pins shown, to rebuild the tables only when they change
};
window.protoduinoConsole = C;

const $ = (id) => document.getElementById(id);
const fmt = (v, digits = 0) => (v === null || v === undefined ? "-" : Number(v).toFixed(digits));

function send(message) {
  if (C.ws && C.ws.readyState === WebSocket.OPEN) C.ws.send(JSON.stringify(message));
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${scheme}://${location.host}/ws`);
  C.ws = ws;
  ws.onmessage = (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === "state") show(msg);
    else if (msg.type === "error") $("error").textContent = msg.text;
  };
  ws.onclose = () => {
    stopBeating();
    banner("bad", "The console is unreachable: reconnecting... (without this page the " +
      "outputs go safe when the failsafe timeout passes)");
    $("role").textContent = "offline";
    $("role").className = "role";
    setTimeout(connect, 1000);
  };
}

function banner(kind, text) {
  const b = $("banner");
  b.className = `banner ${kind}`;
  b.textContent = text;
}

function startBeating(period) {
  if (C.beatTimer !== null && C.beatPeriod === period) return;
  stopBeating();
  C.beatPeriod = period;
  send({ op: "beat" });
  C.beatTimer = setInterval(() => send({ op: "beat" }), period * 1000);
}

function stopBeating() {
  if (C.beatTimer !== null) clearInterval(C.beatTimer);
  C.beatTimer = null;
}

function show(s) {
  C.state = s;
  $("board").textContent = `${s.board.name} ${s.board.firmware} on ${s.board.url}`;
  const driver = s.role === "driver";
  $("role").textContent = driver ? "driving" : "watching";
  $("role").className = driver ? "role driver" : "role";
  $("take").hidden = driver || s.driven;
  if (driver) startBeating(s.beat_period);
  else stopBeating();
  const link = s.link.state;
  if (link === "active") {
    banner("ok", driver
      ? `Board connected. This page drives it: close it and the outputs go safe ${s.failsafe_timeout} s later.`
      : (s.driven ? "Board connected. Another page drives it; this one watches (STOP works here too)."
        : "Board connected. No page drives it: the outputs are safe. Take control to drive."));
  } else {
    banner("bad", `Board link ${link}: commands wait; the device's failsafe keeps the outputs safe.`);
  }
  const fs = s.failsafe;
  $("failsafe").className = fs.active || fs.latched ? "failsafe active" : "failsafe live";
  $("failsafe").textContent = fs.active
    ? `FAILSAFE ACTIVE (${fs.cause}): every output at its safe value, ${fmt(fs.age, 1)} s ago`
    : (fs.latched ? `SAFE after ${fs.latched} (${fmt(fs.latched_age, 1)} s ago): every output ` +
        "holds its safe value until it is commanded again"
      : "Outputs live: the failsafe has not tripped since the last command");
  layout(s);
  update(s);
}

function layout(s) {
  const key = JSON.stringify([s.outputs.map((o) => [o.pin, o.mode]), s.inputs.map((i) => [i.pin, i.mode]), s.board.modes]);
  if (key === C.layout) return;
  C.layout = key;
  const body = $("outputs").tBodies[0];
  body.innerHTML = "";
  for (const o of s.outputs) {
    const row = body.insertRow();
    row.id = `out-${o.pin}`;
    row.innerHTML = `<td>${o.pin}</td><td>${escapeHtml(o.name)}</td><td>${o.mode}</td>` +
      `<td id="readback-${o.pin}"></td><td>${o.safe === null ? "detach" : o.safe}</td><td></td>`;
    row.cells[5].appendChild(control(o));
  }
  const inputs = $("inputs");
  for (const p of Object.values(C.plots)) p.destroy();
  C.plots = {};
  inputs.innerHTML = "";
  for (const i of s.inputs) {
    const div = document.createElement("div");
    div.className = "input";
    div.id = `in-${i.pin}`;
    div.innerHTML = `<div>${escapeHtml(i.name)} (pin ${i.pin}, ${i.mode}): <span class="value" id="value-${i.pin}"></span>` +
      ` <span class="age" id="age-${i.pin}"></span></div><div id="plot-${i.pin}"></div>`;
    inputs.appendChild(div);
    C.plots[i.pin] = new uPlot({
      width: 460, height: 150,
      legend: { show: false },
      scales: { x: { time: false } },
      axes: [{ label: "s ago", size: 40 }, { size: 50 }],
      series: [{}, { label: i.name, stroke: "#1565c0", width: 2, paths: uPlot.paths.stepped({ align: 1 }) }],
    }, [[], []], div.lastChild);
  }
  const pins = $("cfg-pin");
  pins.innerHTML = "";
  for (let p = 0; p < s.board.num_pins; p++) {
    if (!s.board.reserved.includes(p)) pins.add(new Option(String(p), String(p)));
  }
  const modes = $("cfg-mode");
  modes.innerHTML = "";
  for (const m of s.board.modes) modes.add(new Option(m, m));
}

function control(o) {
  const span = document.createElement("span");
  if (o.mode === "servo") {
    const slider = Object.assign(document.createElement("input"),
      { type: "range", min: 0, max: 180, step: 1, id: `servo-${o.pin}` });
    const us = Object.assign(document.createElement("input"),
      { type: "number", min: 400, max: 2600, step: 1, id: `servo-us-${o.pin}`, className: "us", title: "microseconds" });
    slider.value = o.safe === null ? 90 : o.safe;
    throttled(slider, (v) => send({ op: "write", pin: o.pin, value: Number(v) }));
    us.addEventListener("change", () => send({ op: "write", pin: o.pin, value: Number(us.value), unit: "us" }));
    us.addEventListener("keydown", (event) => { if (event.key === "Enter") us.blur(); });
    span.append(slider, " deg ", us, " us");
  } else if (o.mode === "digital") {
    const button = Object.assign(document.createElement("button"), { id: `toggle-${o.pin}`, className: "toggle" });
    button.addEventListener("click", () => send({ op: "write", pin: o.pin, value: button.classList.contains("on") ? 0 : 1 }));
    span.append(button);
  } else {
    const slider = Object.assign(document.createElement("input"),
      { type: "range", min: 0, max: 255, step: 1, id: `pwm-${o.pin}` });
    slider.value = o.safe || 0;
    throttled(slider, (v) => send({ op: "write", pin: o.pin, value: Number(v) }));
    span.append(slider, " duty");
  }
  return span;
}

// A slider writes as it moves, at most once per animation frame, and once more where it stops.
function throttled(slider, write) {
  let pending = false;
  slider.addEventListener("input", () => {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; write(slider.value); });
  });
  slider.addEventListener("change", () => write(slider.value));
}

function update(s) {
  for (const o of s.outputs) {
    const cell = $(`readback-${o.pin}`);
    if (!cell) continue;
    let text = fmt(o.value);
    if (o.mode === "servo" && o.value !== null) text += " us";
    if (o.mode === "digital" && o.value !== null) text = o.value ? "on" : "off";
    if (o.target !== null && o.target !== o.value) text += ` (to ${o.target})`;
    cell.textContent = text;
    const toggle = $(`toggle-${o.pin}`);
    if (toggle) {
      const on = o.commanded === true;
      toggle.classList.toggle("on", on);
      toggle.textContent = on ? "ON" : "OFF";
    }
    const us = $(`servo-us-${o.pin}`);
    if (us && document.activeElement !== us && o.commanded !== null) us.value = o.commanded;
  }
  $("window").textContent = `(the last ${s.window} s)`;
  for (const i of s.inputs) {
    $(`value-${i.pin}`).textContent = fmt(i.value);
    const age = $(`age-${i.pin}`);
    age.textContent = i.age === null ? "no report yet" : `${fmt(i.age, 1)} s old`;
    age.className = i.age !== null && i.age > 2 ? "age stale" : "age";
    const xs = i.history.map((h) => h[0]);
    const ys = i.history.map((h) => h[1]);
    if (i.value !== null) { xs.push(0); ys.push(i.value); }
    const plot = C.plots[i.pin];
    if (plot) {
      plot.setScale("x", { min: -s.window, max: 0 });
      plot.setData([xs, ys], false);
    }
  }
  const l = s.link;
  $("link").tBodies[0].innerHTML = [
    ["state", l.state], ["round trip", l.rtt === null ? "-" : `${fmt(l.rtt * 1000, 1)} ms`],
    ["commands", l.commands], ["acks", l.acks], ["retransmits", l.retransmits],
    ["timeouts", l.timeouts], ["rejected", l.rejected], ["dropped", l.dropped],
    ["reconnects", l.reconnects], ["reboots", l.reboots], ["input reports", l.input_reports],
    ["pages", s.pages],
  ].map(([k, v]) => `<tr><td>${k}</td><td id="link-${k.replace(" ", "-")}">${v}</td></tr>`).join("");
  $("events").innerHTML = s.events.slice().reverse()
    .map((e) => `<li>${fmt(e.age, 1)} s ago: <b>${e.kind}</b> ${escapeHtml(e.text)}</li>`).join("");
}

function escapeHtml(text) {
  const div = document.createElement("div");
  div.textContent = text;
  return div.innerHTML;
}

$("stop").addEventListener("click", () => send({ op: "stop" }));
$("take").addEventListener("click", () => send({ op: "take" }));
$("configure").addEventListener("submit", (event) => {
  event.preventDefault();
  $("error").textContent = "";
  send({
    op: "configure", pin: Number($("cfg-pin").value), mode: $("cfg-mode").value,
    safe: $("cfg-safe").value, pull_up: $("cfg-pullup").checked, name: $("cfg-name").value,
  });
});
connect();
