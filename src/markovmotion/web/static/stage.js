// Stick figures in 3-D on a plain 2-D canvas: a perspective camera that orbits
// (drag), zooms (wheel) and re-frames (double click), over a ground grid.
// Positions are in millimetres, Y up, one flat array of J*3 numbers per pose.

const NEAR = 50;
export const COLOURS = ["#2f6fd6", "#e07b22", "#2a9d5b", "#b0399a", "#c9372c", "#6b5bd6"];

function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}
function norm(a) { const n = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / n, a[1] / n, a[2] / n]; }

// Whether each joint is drawn: it ends or starts a bone, or the figure is only markers.
function drawn(parents) {
  if (parents.every((p) => p < 0)) return parents.map(() => true);
  const shown = parents.map((p) => p >= 0);
  parents.forEach((p) => { if (p >= 0) shown[p] = true; });
  return shown;
}

// Bounding box {min, max} of the drawn joints of figures [{positions (flat), parents}].
export function bounds(figures) {
  const min = [Infinity, Infinity, Infinity], max = [-Infinity, -Infinity, -Infinity];
  for (const { positions: p, parents } of figures) {
    const shown = drawn(parents);
    const J = parents.length;
    for (let i = 0; i + 2 < p.length; i += 3) {
      if (!shown[(i / 3) % J]) continue;
      for (let k = 0; k < 3; k++) {
        const v = p[i + k];
        if (v === null || !Number.isFinite(v)) continue;
        if (v < min[k]) min[k] = v;
        if (v > max[k]) max[k] = v;
      }
    }
  }
  if (!Number.isFinite(min[0])) return { min: [-1000, 0, -1000], max: [1000, 1800, 1000] };
  return { min, max };
}

// The box widened horizontally to at least 2*half mm around its centre (a following camera's view).
export function widen(box, half = 1500) {
  for (const k of [0, 2]) {
    const c = (box.min[k] + box.max[k]) / 2, h = Math.max(half, (box.max[k] - box.min[k]) / 2);
    box.min[k] = c - h;
    box.max[k] = c + h;
  }
  return box;
}

export class Stage {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.yaw = 0.5;
    this.pitch = 0.25;
    this.distance = 5000;
    this.target = [0, 900, 0];
    this.fov = (40 * Math.PI) / 180;
    this.grid = { y: 0, x0: -2000, x1: 2000, z0: -2000, z1: 2000, step: 500 };
    this.touched = false;
    this.follow = false; // keep the figures' centroid in the middle (horizontally)
    this.figures = [];
    this.label = "";
    this.pointLight = false; // Johansson's display: dots on black, no floor
    this._listen();
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  _listen() {
    const c = this.canvas;
    let drag = null;
    c.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; c.setPointerCapture(e.pointerId); });
    c.addEventListener("pointerup", () => { drag = null; });
    c.addEventListener("pointermove", (e) => {
      if (!drag) return;
      this.yaw -= (e.clientX - drag[0]) * 0.008;
      this.pitch = Math.max(-0.2, Math.min(1.45, this.pitch + (e.clientY - drag[1]) * 0.006));
      drag = [e.clientX, e.clientY];
      this.touched = true;
      this.draw();
    });
    c.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.distance = Math.max(300, Math.min(100000, this.distance * Math.exp(e.deltaY * 0.0012)));
      this.touched = true;
      this.draw();
    }, { passive: false });
    c.addEventListener("dblclick", () => { if (this.box) this.fit(this.box); this.draw(); });
  }

  // Frame the box {min, max} (mm): look at its centre from the side of its longest
  // horizontal extent, just far enough for its eight corners to fit the canvas,
  // with the grid under it.
  fit(box) {
    this.box = box;
    const { min, max } = box;
    const size = sub(max, min);
    this.target = [(min[0] + max[0]) / 2, (min[1] + max[1]) / 2, (min[2] + max[2]) / 2];
    this.yaw = (size[0] >= size[2] ? 0 : Math.PI / 2) + 0.35;
    this.pitch = 0.22;
    this.distance = 1;
    const { f, r, u } = this._camera();
    const aspect = Math.max(0.3, (this.canvas.clientWidth || 4) / (this.canvas.clientHeight || 3));
    const tv = Math.tan(this.fov / 2), th = tv * aspect;
    let d = 1500;
    for (let i = 0; i < 8; i++) {
      const c = sub([i & 1 ? max[0] : min[0], i & 2 ? max[1] : min[1], i & 4 ? max[2] : min[2]], this.target);
      d = Math.max(d, Math.abs(dot(c, r)) / th - dot(c, f), Math.abs(dot(c, u)) / tv - dot(c, f));
    }
    this.distance = 1.12 * d;
    const radius = 0.5 * Math.hypot(size[0], size[2]);
    const step = radius > 4000 ? 1000 : 500;
    const pad = Math.max(1000, 0.3 * radius);
    this.grid = {
      y: min[1],
      step,
      x0: Math.floor((min[0] - pad) / step) * step,
      x1: Math.ceil((max[0] + pad) / step) * step,
      z0: Math.floor((min[2] - pad) / step) * step,
      z1: Math.ceil((max[2] + pad) / step) * step,
    };
    this.touched = false;
  }

  _camera() {
    const c = Math.cos(this.pitch);
    const eye = [
      this.target[0] + this.distance * c * Math.sin(this.yaw),
      this.target[1] + this.distance * Math.sin(this.pitch),
      this.target[2] + this.distance * c * Math.cos(this.yaw),
    ];
    const f = norm(sub(this.target, eye));
    const r = norm(cross(f, [0, 1, 0]));
    const u = cross(r, f);
    return { eye, f, r, u };
  }

  _resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(this.canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(this.canvas.clientHeight * dpr));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    return dpr;
  }

  // Move the target (and the grid with it) over the centroid of the figures.
  _follow() {
    let sx = 0, sz = 0, n = 0;
    for (const fig of this.figures) {
      const P = fig.positions || [];
      for (let i = 0; i + 2 < P.length; i += 3) {
        if (P[i] === null || !Number.isFinite(P[i])) continue;
        sx += P[i]; sz += P[i + 2]; n++;
      }
    }
    if (!n) return;
    const g = this.grid, dx = Math.round((sx / n - this.target[0]) / g.step) * g.step;
    const dz = Math.round((sz / n - this.target[2]) / g.step) * g.step;
    this.target[0] = sx / n;
    this.target[2] = sz / n;
    g.x0 += dx; g.x1 += dx; g.z0 += dz; g.z1 += dz;
  }

  // figures: [{positions (flat J*3), parents, colour}] — the poses of this frame.
  draw(figures) {
    if (figures) this.figures = figures;
    if (this.follow) this._follow();
    const dpr = this._resize();
    const ctx = this.ctx, W = this.canvas.width, H = this.canvas.height;
    const cam = this._camera();
    const focal = H / 2 / Math.tan(this.fov / 2);
    const view = (p) => { const d = sub(p, cam.eye); return [dot(d, cam.r), dot(d, cam.u), dot(d, cam.f)]; };
    const screen = (v) => [W / 2 + (focal * v[0]) / v[2], H / 2 - (focal * v[1]) / v[2]];
    // A segment in view space clipped to the near plane, or null.
    const clip = (a, b) => {
      if (a[2] < NEAR && b[2] < NEAR) return null;
      if (a[2] < NEAR || b[2] < NEAR) {
        const t = (NEAR - a[2]) / (b[2] - a[2]);
        const m = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), NEAR];
        if (a[2] < NEAR) a = m; else b = m;
      }
      return [screen(a), screen(b)];
    };

    const sky = ctx.createLinearGradient(0, 0, 0, H);
    sky.addColorStop(0, "#f7f9fc");
    sky.addColorStop(1, "#e4e9f1");
    ctx.fillStyle = this.pointLight ? "#000" : sky;
    ctx.fillRect(0, 0, W, H);

    const g = this.pointLight ? { x0: 1, x1: 0, z0: 1, z1: 0, step: 1 } : this.grid; // no floor
    ctx.lineWidth = 1 * dpr;
    for (let x = g.x0; x <= g.x1 + 1e-6; x += g.step) {
      const s = clip(view([x, g.y, g.z0]), view([x, g.y, g.z1]));
      if (!s) continue;
      ctx.strokeStyle = x === 0 ? "#9aa6b8" : "#c9d1dd";
      ctx.beginPath(); ctx.moveTo(...s[0]); ctx.lineTo(...s[1]); ctx.stroke();
    }
    for (let z = g.z0; z <= g.z1 + 1e-6; z += g.step) {
      const s = clip(view([g.x0, g.y, z]), view([g.x1, g.y, z]));
      if (!s) continue;
      ctx.strokeStyle = z === 0 ? "#9aa6b8" : "#c9d1dd";
      ctx.beginPath(); ctx.moveTo(...s[0]); ctx.lineTo(...s[1]); ctx.stroke();
    }

    // Bones and joints of every figure, far to near.
    const prims = [];
    for (const fig of this.figures) {
      const P = fig.positions;
      if (!P) continue;
      const J = fig.parents.length;
      fig.markers = fig.parents.every((p) => p < 0); // C3D markers: dots, no bones
      const v = new Array(J);
      for (let j = 0; j < J; j++) {
        const x = P[3 * j], y = P[3 * j + 1], z = P[3 * j + 2];
        v[j] = x === null || !Number.isFinite(x) ? null : view([x, y, z]);
      }
      for (let j = 0; j < J; j++) {
        const p = fig.parents[j];
        if (!v[j]) continue;
        if (p >= 0 && v[p]) {
          const s = clip(v[p], v[j]);
          if (s) prims.push({ depth: (v[p][2] + v[j][2]) / 2, seg: s, colour: fig.colour });
        } else if (fig.markers && v[j][2] > NEAR) {
          prims.push({ depth: v[j][2], dot: screen(v[j]), colour: fig.colour });
        }
      }
    }
    prims.sort((a, b) => b.depth - a.depth);
    ctx.lineCap = "round";
    for (const q of prims) {
      const w = Math.max(1.5, Math.min(9, (focal * 32) / q.depth));
      ctx.strokeStyle = q.colour;
      ctx.fillStyle = q.colour;
      if (q.seg) {
        ctx.lineWidth = w;
        ctx.beginPath(); ctx.moveTo(...q.seg[0]); ctx.lineTo(...q.seg[1]); ctx.stroke();
      } else {
        ctx.beginPath(); ctx.arc(q.dot[0], q.dot[1], w * 0.7, 0, 2 * Math.PI); ctx.fill();
      }
    }
    if (this.label) {
      ctx.fillStyle = this.pointLight ? "#8a93a6" : "#44506a";
      ctx.font = `${13 * dpr}px system-ui, sans-serif`;
      ctx.fillText(this.label, 10 * dpr, 20 * dpr);
    }
  }
}

// Decoded motion JSON from the server: {name, fps, frames, joints, parents, positions}.
// A stimulus of the perceptual tests: a stage on its canvas and a play button under it, in a
// "stimulus" box (frame it with stage.fit once the box is on the page); the button, or a click
// on the canvas while the player is stopped, calls start.
export function stimulus(player, start) {
  const wrap = document.createElement("div");
  wrap.className = "stimulus";
  const canvas = document.createElement("canvas");
  canvas.className = "stage";
  const play = document.createElement("button");
  play.className = "play primary";
  play.textContent = "▶ Play";
  wrap.append(canvas, play);
  play.addEventListener("click", start);
  canvas.addEventListener("click", () => { if (!player.playing) start(); });
  return { wrap, stage: new Stage(canvas), play };
}

export function poseAt(motion, frame) {
  const n = motion.parents.length * 3;
  const f = Math.max(0, Math.min(motion.frames - 1, frame));
  return motion.positions.slice(f * n, (f + 1) * n);
}

// Plays motions of any frame rates together on one clock, looping at the longest.
export class Player {
  constructor(onFrame) {
    this.motions = [];
    this.time = 0;
    this.speed = 1;
    this.playing = false;
    this.loop = true;
    this.onFrame = onFrame;
    this.onEnd = null;
    this._last = null;
    requestAnimationFrame((t) => this._tick(t));
  }

  get duration() { return Math.max(0, ...this.motions.map((m) => m.frames / m.fps)); }
  get fps() { return Math.max(1, ...this.motions.map((m) => m.fps)); }
  get frames() { return Math.max(0, ...this.motions.map((m) => m.frames)); }
  frameOf(m) { return Math.min(m.frames - 1, Math.floor(this.time * m.fps + 1e-6)); }
  get frame() { return Math.floor(this.time * this.fps + 1e-6); }

  set(motions) { this.motions = motions; this.time = 0; this.render(); }
  seek(seconds) { this.time = Math.max(0, Math.min(this.duration, seconds)); this.render(); }
  play() {
    if (this.time >= this.duration - 1e-6) this.time = 0;
    this.playing = true;
    this._last = null;
  }
  pause() { this.playing = false; }
  render() { if (this.onFrame) this.onFrame(this); }

  _tick(now) {
    if (this.playing && this.motions.length) {
      if (this._last !== null) this.time += ((now - this._last) / 1000) * this.speed;
      const end = this.duration;
      if (this.time >= end) {
        if (this.loop) this.time %= end;
        else { this.time = end - 1e-6; this.playing = false; if (this.onEnd) this.onEnd(); }
      }
      this._last = now;
      this.render();
    }
    requestAnimationFrame((t) => this._tick(t));
  }
}

// The q-quantile of a list of numbers (NaN if empty), for the pages' latency figures.
export function quantile(values, q) {
  if (!values.length) return NaN;
  const s = [...values].sort((a, b) => a - b);
  return s[Math.min(s.length - 1, Math.floor(q * s.length))];
}

// A WebSocket message of a streaming page as an object; an error message is shown in #error
// and gives null.
export function received(event) {
  const msg = JSON.parse(event.data);
  if (msg.type !== "error") return msg;
  document.getElementById("error").textContent = msg.message;
  return null;
}

// A streaming page's Start and Stop buttons (#start, #stop): one enabled at a time.
export function setRunning(running) {
  document.getElementById("start").disabled = running;
  document.getElementById("stop").disabled = !running;
}

export async function fetchJSON(url, options) {
  const r = await fetch(url, options);
  let body = null;
  try { body = await r.json(); } catch { body = null; }
  if (!r.ok) {
    const detail = body && body.detail ? body.detail : `${r.status} ${r.statusText}`;
    throw new Error(typeof detail === "string" ? detail : JSON.stringify(detail));
  }
  return body;
}
