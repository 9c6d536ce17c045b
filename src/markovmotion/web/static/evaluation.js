// Evaluation page (gait paper §6): three tests of ten items, one at a time; the
// evaluator starts each animation by clicking it and may watch it again. Every
// answer is sent at once; coming back to the same link resumes.
import { COLOURS, Player, bounds, fetchJSON, poseAt, stimulus } from "/static/stage.js";

const $ = (id) => document.getElementById(id);
const token = decodeURIComponent(location.pathname.split("/").pop());
const TITLES = { naturalness: "1 · Naturalness", recognition: "2 · Style", resemblance: "3 · Resemblance" };
let state = null;
let current = null; // {test, item}
let shown = []; // [{stage, motion}]

const player = new Player((p) => {
  shown.forEach((s) => s.stage.draw([{
    positions: poseAt(s.motion, p.frameOf(s.motion)), parents: s.motion.parents, colour: COLOURS[0],
  }]));
  document.body.dataset.frame = String(p.frame);
});
player.loop = false;

function remaining(test) { return test.items.filter((i) => i.answer === null); }

function tabs() {
  const box = $("tabs");
  box.innerHTML = "";
  for (const test of state.tests) {
    const b = document.createElement("button");
    const done = test.items.length - remaining(test).length;
    b.textContent = `${TITLES[test.name]} (${done}/${test.items.length})`;
    b.dataset.test = test.name;
    b.classList.toggle("here", current && current.test === test);
    b.addEventListener("click", () => openTest(test));
    box.appendChild(b);
  }
}

function next() {
  const test = (current && remaining(current.test).length ? current.test : null)
    || state.tests.find((t) => remaining(t).length);
  if (!test) {
    current = null;
    $("test").hidden = true;
    $("done").hidden = false;
    document.body.dataset.test = "done";
    tabs();
    return;
  }
  openTest(test);
}

async function openTest(test) {
  $("error").textContent = "";
  const todo = remaining(test);
  $("test").hidden = false;
  $("done").hidden = true;
  if (!todo.length) {
    current = { test, item: null };
    tabs();
    $("question").textContent = `${TITLES[test.name]}: done`;
    $("progress").textContent = "You have answered every question of this test.";
    $("stages").innerHTML = "";
    $("choices").innerHTML = "";
    return;
  }
  const item = todo[0];
  current = { test, item };
  tabs();
  $("question").textContent = test.question;
  const n = test.items.length - todo.length + 1;
  $("progress").textContent = `Question ${n} of ${test.items.length}. Click the animation to play it.`;
  $("choices").innerHTML = "";
  player.pause();
  const sides = item.pair ? [0, 1] : [0];
  let motions;
  try {
    motions = await Promise.all(
      sides.map((s) => fetchJSON(`/api/evaluation/${encodeURIComponent(token)}/${test.name}/${item.position}/${s}`)),
    );
  } catch (e) {
    $("error").textContent = e.message;
    return;
  }
  if (current.item !== item) return;
  const box = $("stages");
  box.innerHTML = "";
  box.className = `stages cols-${sides.length}`;
  shown = motions.map((motion, k) => {
    const { wrap, stage, play } = stimulus(player, start);
    box.appendChild(wrap);
    stage.fit(bounds([motion]));
    if (item.pair) stage.label = k === 0 ? "Video A" : "Video B";
    return { stage, motion, play };
  });
  player.set(motions);
  document.body.dataset.test = test.name;
  document.body.dataset.position = String(item.position);
  for (const [value, label] of test.choices) {
    const b = document.createElement("button");
    b.textContent = label;
    b.dataset.value = value;
    b.addEventListener("click", () => answer(test, item, value, b));
    $("choices").appendChild(b);
  }
}

function start() {
  player.seek(0);
  player.play();
  shown.forEach((s) => { s.play.hidden = true; });
}
player.onEnd = () => shown.forEach((s) => { s.play.hidden = false; s.play.textContent = "↻ Play again"; });

async function answer(test, item, value, button) {
  button.classList.add("picked");
  document.querySelectorAll("#choices button").forEach((b) => { b.disabled = true; });
  try {
    await fetchJSON(`/api/evaluation/${encodeURIComponent(token)}/${test.name}/${item.position}`, {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ answer: value }),
    });
    item.answer = value;
    next();
  } catch (e) {
    $("error").textContent = `Your answer could not be saved: ${e.message}`;
    document.querySelectorAll("#choices button").forEach((b) => { b.disabled = false; });
  }
}

(async () => {
  $("self").href = location.href;
  $("self").textContent = location.href;
  try {
    state = await fetchJSON(`/api/evaluation/${encodeURIComponent(token)}`);
  } catch (e) {
    $("error").textContent = e.message;
    return;
  }
  next();
})();
