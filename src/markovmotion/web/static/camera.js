// Camera partner page: the webcam's frames (JPEG) go to the server over a WebSocket;
// the server tracks the person (MediaPipe Pose) and the virtual partner answers. The
// page draws the frame with the landmarks, and the person and the partner in 3-D.
import { COLOURS, Stage, bounds, quantile, received, setRunning, widen } from "/static/stage.js";

const $ = (id) => document.getElementById(id);
const stage = new Stage($("stage"));
const overlay = $("overlay");
const video = $("video");
const grab = document.createElement("canvas");
// frames sent and not yet answered: ?inflight=1 for the lowest latency; 3 (default) keeps the
// server's two MediaPipe graphs busy with one more frame waiting (docs/web.md's table)
const IN_FLIGHT = Math.max(1, Math.min(4, Number(new URLSearchParams(location.search).get("inflight")) || 3));
const MAX_SIDE = 640; // frames are scaled down to at most this many pixels a side
// MediaPipe's landmark pairs drawn over the frame: arms, trunk, legs, feet, face to ears
const LINKS = [[11, 13], [13, 15], [12, 14], [14, 16], [11, 12], [11, 23], [12, 24], [23, 24],
  [23, 25], [25, 27], [24, 26], [26, 28], [27, 29], [29, 31], [27, 31], [28, 30], [30, 32],
  [28, 32], [0, 7], [0, 8]];
let ws = null, stream = null, session = null;

// the last 120 values of a running statistic
function keep(values, x) {
  values.push(x);
  if (values.length > 240) values.splice(0, values.length - 120);
}

function stopped(message) {
  setRunning(false);
  if (message) $("status").textContent = message;
  if (stream) for (const t of stream.getTracks()) t.stop();
  stream = null;
  ws = null;
  if (session) session.running = false;
}

// Sends the camera's newest frame, once: after an answer (a frame that came while the
// frames in flight were full), or when a new camera frame comes; never the same frame twice
// (an answer once re-sent the frame already sent, and the rate answered passed the camera's).
function send() {
  if (!session || !session.running || session.pending.length >= IN_FLIGHT || !video.videoWidth) return;
  if (session.frameId === session.sentId) return;
  session.sentId = session.frameId;
  const t = performance.now();
  const scale = Math.min(1, MAX_SIDE / Math.max(video.videoWidth, video.videoHeight));
  grab.width = Math.round(video.videoWidth * scale);
  grab.height = Math.round(video.videoHeight * scale);
  grab.getContext("2d").drawImage(video, 0, 0, grab.width, grab.height);
  session.pending.push(t);
  session.sent += 1;
  const socket = ws; // the socket this frame is for: the page may stop while it is encoded
  grab.toBlob(async (blob) => {
    if (!blob || !socket || socket.readyState !== WebSocket.OPEN) return;
    const data = await blob.arrayBuffer();
    // stopped (or closed) during the await: the frame is dropped, not sent to a closed socket
    if (socket !== ws || socket.readyState !== WebSocket.OPEN) return;
    if (session) keep(session.encode, performance.now() - t); // grab + JPEG, ms
    socket.send(data);
  }, "image/jpeg", 0.8);
}

function onCameraFrame(now, metadata) {
  if (!session || !session.running) return;
  session.seen += 1;
  // the camera frame's own number where the browser gives it (requestVideoFrameCallback),
  // else the video's time, which moves only when a new frame is shown
  session.frameId = metadata && metadata.presentedFrames !== undefined ? metadata.presentedFrames : video.currentTime;
  send();
  if (video.requestVideoFrameCallback) video.requestVideoFrameCallback(onCameraFrame);
  else requestAnimationFrame(onCameraFrame);
}

// The camera's present frame with the landmarks of the last answer (a frame or two older).
function drawOverlay(msg) {
  const ctx = overlay.getContext("2d");
  overlay.width = grab.width;
  overlay.height = grab.height;
  ctx.drawImage(video, 0, 0, overlay.width, overlay.height);
  if (!msg.pixels) return;
  const sx = overlay.width / msg.width, sy = overlay.height / msg.height;
  const p = (k) => [(msg.pixels[2 * k] + 0.5) * sx, (msg.pixels[2 * k + 1] + 0.5) * sy];
  ctx.strokeStyle = COLOURS[0];
  ctx.lineWidth = 3;
  for (const [i, j] of LINKS) {
    const [a, b] = [p(i), p(j)];
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
  }
}

function report() {
  const s = session, now = performance.now();
  while (s.answers.length && s.answers[0] < now - 2000) s.answers.shift();
  const span = s.answers.length > 1 ? (s.answers[s.answers.length - 1] - s.answers[0]) / 1000 : 0;
  const fps = span > 0 ? (s.answers.length - 1) / span : 0;
  const recent = s.latency.slice(-120);
  const encode = s.encode.slice(-120), track = s.tracks.slice(-120);
  const avg = (xs) => xs.reduce((a, b) => a + b, 0) / Math.max(1, xs.length);
  const mean = avg(recent);
  $("fps").textContent = fps.toFixed(1);
  $("dropped").textContent = `camera frames ${s.seen} · sent ${s.sent}`;
  $("latency").textContent = mean.toFixed(0);
  $("latency-stats").textContent = `median ${quantile(recent, 0.5).toFixed(0)} · p99 ${quantile(recent, 0.99).toFixed(0)}`;
  $("work").textContent = `${s.track.toFixed(0)} · ${s.partner.toFixed(1)}`;
  $("found").textContent = `${Math.round((100 * s.found) / Math.max(1, s.frames))} %`;
  Object.assign(document.body.dataset, {
    framesA: String(s.found), framesB: String(s.b), frames: String(s.frames),
    fps: fps.toFixed(2), latency: mean.toFixed(1), latencyP99: quantile(recent, 0.99).toFixed(1),
    cameraFrames: String(s.seen), sent: String(s.sent),
    encodeMs: avg(encode).toFixed(1), trackMs: avg(track).toFixed(1),
  });
}

function onMessage(event) {
  const msg = received(event);
  if (!msg) return;
  if (msg.type === "start") {
    session = { ...msg, running: true, pending: [], answers: [], latency: [], encode: [], tracks: [], seen: 0, sent: 0,
      frameId: -1, sentId: -1,
      frames: 0, found: 0, b: 0, track: 0, partner: 0, fitted: false, fittedB: false };
    $("lag").textContent = String(msg.lag);
    session.tracking = `Tracking; the partner answers at ${msg.fps.toFixed(0)} fps, ${msg.lag} frames behind you.`;
    session.missing = 0;
    $("status").textContent = session.tracking;
    onCameraFrame();
    return;
  }
  if (msg.type !== "frame" || !session) return;
  const s = session, now = performance.now();
  keep(s.latency, now - s.pending.shift());
  s.answers.push(now);
  s.frames += 1;
  s.track = msg.track_ms;
  keep(s.tracks, msg.track_ms);
  s.partner = msg.partner_ms;
  if (msg.a) s.found += 1;
  if (msg.b) s.b += 1;
  // nobody found for a second: say so (the partner goes on answering its last A)
  s.missing = msg.a ? 0 : s.missing + 1;
  const lost = s.missing >= Math.max(10, Math.round(s.fps));
  $("status").textContent = lost
    ? "Nobody found in the last second: stand where the camera sees you, head to feet."
    : s.tracking;
  document.body.dataset.nobody = lost ? "1" : "0";
  send();
  drawOverlay(msg);
  const figs = [];
  if (msg.a) figs.push({ positions: msg.a, parents: s.parents_a, colour: COLOURS[0] });
  if (msg.b) figs.push({ positions: msg.b, parents: s.parents_b, colour: COLOURS[1] });
  if (figs.length && (!s.fitted || (msg.b && !s.fittedB))) {
    stage.fit(widen(bounds(figs)));
    stage.follow = true;
    s.fitted = true;
    s.fittedB = Boolean(msg.b);
  }
  if (figs.length) stage.draw(figs);
  report();
}

async function start() {
  $("error").textContent = "";
  const fov = Number($("fov").value);
  try {
    stream = await navigator.mediaDevices.getUserMedia({ video: { width: { ideal: 640 }, height: { ideal: 480 }, frameRate: { ideal: 30 } }, audio: false });
  } catch (e) {
    $("error").textContent = `The camera cannot be opened: ${e.message || e.name}`;
    return;
  }
  video.srcObject = stream;
  await video.play();
  const proto = location.protocol === "https:" ? "wss" : "ws";
  ws = new WebSocket(`${proto}://${location.host}/ws/camera`);
  ws.binaryType = "arraybuffer";
  session = null;
  setRunning(true);
  $("status").textContent = "Starting the tracker …";
  const socket = ws;
  socket.onopen = () => socket.send(JSON.stringify({ fov }));
  ws.onmessage = onMessage;
  ws.onclose = () => { if (ws) stopped(session ? `Stopped after ${session.frames} frames.` : ""); };
}

$("start").addEventListener("click", start);
$("stop").addEventListener("click", () => {
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ type: "stop" }));
  if (session) session.running = false;
});

stage.fit({ min: [-1500, 0, -4500], max: [1500, 1800, -1500] });
stage.draw([]);
