// Live partner page: person A streamed by the server at its frame rate through
// the virtual partner over a WebSocket; A and B drawn as their frames arrive.
import { COLOURS, Stage, bounds, fetchJSON, quantile, received, setRunning, widen } from "/static/stage.js";

const $ = (id) => document.getElementById(id);
const stage = new Stage($("stage"));
let ws = null;
let session = null;

function stats(values) {
  const mean = values.reduce((a, b) => a + b, 0) / Math.max(1, values.length);
  return `mean ${mean.toFixed(2)} · p99 ${quantile(values, 0.99).toFixed(2)}`;
}

function stopped(message) {
  setRunning(false);
  if (message) $("status").textContent = message;
  ws = null;
}

function onMessage(event) {
  const msg = received(event);
  if (!msg) return;
  if (msg.type === "start") {
    session = { ...msg, frames: 0, latency: [], interval: [], last: null, fitted: false, b: 0 };
    $("lag").textContent = String(msg.lag);
    $("status").textContent = `Streaming ${msg.frames} frames at ${msg.fps.toFixed(0)} fps.`;
    return;
  }
  if (msg.type === "end") {
    stopped(`Done: ${msg.frames} frames streamed.`);
    return;
  }
  if (msg.type !== "frame" || !session) return;
  const now = performance.now();
  if (session.last !== null) session.interval.push(now - session.last);
  session.last = now;
  session.frames += 1;
  session.latency.push(msg.latency_ms);
  if (msg.b) session.b += 1;
  // Frame A's first pose (and again with B's first), then follow the pair.
  if (!session.fitted || (msg.b && !session.fittedB)) {
    stage.fit(widen(bounds([
      { positions: msg.a, parents: session.parents_a },
      { positions: msg.b || [], parents: session.parents_b },
    ])));
    stage.follow = true;
    session.fitted = true;
    session.fittedB = Boolean(msg.b);
  }
  const figs = [{ positions: msg.a, parents: session.parents_a, colour: COLOURS[0] }];
  if (msg.b) figs.push({ positions: msg.b, parents: session.parents_b, colour: COLOURS[1] });
  stage.draw(figs);
  $("frames").textContent = String(session.frames);
  // frames the server dropped because this session fell behind its clock (not sent)
  $("dropped").textContent = msg.skipped ? `${msg.skipped} dropped (server behind)` : "";
  $("latency").textContent = msg.latency_ms.toFixed(2);
  $("latency-stats").textContent = stats(session.latency);
  if (session.interval.length) {
    $("interval").textContent = session.interval[session.interval.length - 1].toFixed(1);
    $("interval-stats").textContent = stats(session.interval);
  }
  document.body.dataset.framesA = String(session.frames);
  document.body.dataset.framesB = String(session.b);
}

async function start() {
  $("error").textContent = "";
  let request;
  const file = $("upload").files[0];
  if (file) request = { bvh: await file.text(), name: file.name };
  else if ($("motion").value) request = { path: $("motion").value };
  else { $("error").textContent = "Choose a motion for person A first."; return; }
  request.loop = $("loop").checked;
  const proto = location.protocol === "https:" ? "wss" : "ws";
  ws = new WebSocket(`${proto}://${location.host}/ws/live`);
  session = null;
  setRunning(true);
  const socket = ws;
  socket.onopen = () => socket.send(JSON.stringify(request));
  ws.onmessage = onMessage;
  ws.onclose = () => { if (ws) stopped(session ? `Stopped after ${session.frames} frames.` : ""); };
}

$("start").addEventListener("click", start);
$("stop").addEventListener("click", () => {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ type: "stop" }));
});
$("upload").addEventListener("change", () => { if ($("upload").files[0]) $("motion").value = ""; });

(async () => {
  try {
    const { files, partner, partner_reads: reads } = await fetchJSON("/api/motions");
    // a partner of skeletons refuses markers: their C3D files are not offered
    const offered = reads === "skeleton" ? files.filter((f) => !/\.c3d$/i.test(f)) : files;
    for (const f of offered) $("motion").append(new Option(f, f));
    if (!partner) $("error").textContent = "This server has no partner model: start it with markovmotion serve --partner MODEL.";
  } catch (e) {
    $("error").textContent = e.message;
  }
  stage.fit({ min: [-1500, 0, -1500], max: [1500, 1800, 1500] });
  stage.draw([]);
})();
