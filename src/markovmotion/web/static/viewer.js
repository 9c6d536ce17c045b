// Viewer page: pick motions of the library (or upload a BVH), play them in one
// scene or side by side. ?files=a.bvh,b.bvh preloads motions.
import { COLOURS, Player, Stage, bounds, fetchJSON, poseAt, widen } from "/static/stage.js";

const $ = (id) => document.getElementById(id);
const MAX = 6;
let chosen = []; // [{key, motion}]
let stages = [];
let files = [];

const player = new Player(draw);

function colour(i) { return COLOURS[i % COLOURS.length]; }

function draw(p) {
  const figs = chosen.map((c, i) => ({
    positions: poseAt(c.motion, p.frameOf(c.motion)),
    parents: c.motion.parents,
    colour: colour(i),
  }));
  if ($("together").checked) {
    if (stages[0]) stages[0].draw(figs);
  } else {
    stages.forEach((s, i) => s.draw(figs.slice(i, i + 1)));
  }
  const frame = Math.min(p.frame, Math.max(0, p.frames - 1));
  $("slider").max = String(Math.max(0, Math.round(p.duration * p.fps) - 1));
  $("slider").value = String(frame);
  $("clock").textContent = `frame ${frame} / ${Math.max(0, p.frames - 1)} · ${p.time.toFixed(2)} s`;
  document.body.dataset.frame = String(frame);
}

function layout() {
  const box = $("stages");
  box.innerHTML = "";
  const together = $("together").checked;
  const n = together ? 1 : Math.max(1, chosen.length);
  box.className = `stages cols-${Math.min(3, n)}`;
  stages = [];
  for (let i = 0; i < n; i++) {
    const c = document.createElement("canvas");
    c.className = "stage";
    box.appendChild(c);
    const s = new Stage(c);
    const shown = together ? chosen : chosen.slice(i, i + 1);
    s.follow = $("follow").checked;
    const first = shown.map((m) => ({ positions: poseAt(m.motion, 0), parents: m.motion.parents }));
    s.fit(s.follow ? widen(bounds(first)) : bounds(shown.map((m) => m.motion)));
    if (!together && chosen[i]) s.label = chosen[i].motion.name;
    stages.push(s);
  }
  $("legend").innerHTML = "";
  chosen.forEach((c, i) => {
    const span = document.createElement("span");
    span.style.setProperty("--c", colour(i));
    span.textContent = `${c.motion.name} (${c.motion.frames} frames, ${c.motion.fps.toFixed(0)} fps)`;
    $("legend").appendChild(span);
  });
  document.querySelectorAll("#files li").forEach((li) => {
    li.classList.toggle("chosen", chosen.some((c) => c.key === li.dataset.path));
  });
  player.set(chosen.map((c) => c.motion));
}

async function add(key, loader) {
  $("error").textContent = "";
  if (chosen.some((c) => c.key === key)) return;
  if (chosen.length >= MAX) { $("error").textContent = `At most ${MAX} motions at once.`; return; }
  try {
    const motion = await loader();
    chosen.push({ key, motion });
    layout();
    if (!player.playing) { player.play(); $("play").textContent = "Pause"; }
  } catch (e) {
    $("error").textContent = e.message;
  }
}

function addFile(path) {
  return add(path, () => fetchJSON(`/api/motion?path=${encodeURIComponent(path)}`));
}

function listFiles() {
  const q = $("filter").value.toLowerCase();
  const ul = $("files");
  ul.innerHTML = "";
  for (const f of files.filter((f) => f.toLowerCase().includes(q)).slice(0, 500)) {
    const li = document.createElement("li");
    li.textContent = f;
    li.dataset.path = f;
    li.classList.toggle("chosen", chosen.some((c) => c.key === f));
    li.addEventListener("click", () => addFile(f));
    ul.appendChild(li);
  }
}

$("filter").addEventListener("input", listFiles);
$("together").addEventListener("change", layout);
$("follow").addEventListener("change", layout);
$("clear").addEventListener("click", () => { chosen = []; layout(); });
$("play").addEventListener("click", () => {
  if (player.playing) { player.pause(); $("play").textContent = "Play"; }
  else { player.play(); $("play").textContent = "Pause"; }
});
$("slider").addEventListener("input", () => player.seek(Number($("slider").value) / player.fps));
$("speed").addEventListener("change", () => { player.speed = Number($("speed").value); });
$("upload").addEventListener("change", () => {
  const file = $("upload").files[0];
  if (!file) return;
  const form = new FormData();
  form.append("file", file);
  add(`upload:${file.name}:${Date.now()}`, () => fetchJSON("/api/upload", { method: "POST", body: form }));
  $("upload").value = "";
});

(async () => {
  try {
    files = (await fetchJSON("/api/motions")).files;
  } catch (e) {
    $("error").textContent = e.message;
  }
  listFiles();
  layout();
  const pre = new URLSearchParams(location.search).get("files");
  if (pre) for (const f of pre.split(",")) await addFile(f);
})();
