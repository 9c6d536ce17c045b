// Observer study of the dual-HMM paper (§4.2): every clip once, as a point-light display
// (white dots on black, both people). The observer names the action, may say they noticed
// something strange or unusual and write what; each answer is sent at once, and coming
// back to the same link resumes at the first clip not answered.
import { Player, bounds, fetchJSON, poseAt, stimulus } from "/static/stage.js";

const $ = (id) => document.getElementById(id);
const token = decodeURIComponent(location.pathname.split("/").pop());
let test = null;
let shown = null; // {stage, motion, play}
let picked = null;

const player = new Player((p) => {
  if (!shown) return;
  shown.stage.draw([{ positions: poseAt(shown.motion, p.frameOf(shown.motion)), parents: shown.motion.parents, colour: "#ffffff" }]);
  document.body.dataset.frame = String(p.frame);
});
player.loop = false;
player.onEnd = () => { if (shown) { shown.play.hidden = false; shown.play.textContent = "↻ Play again"; } };

function start() {
  player.seek(0);
  player.play();
  if (shown) shown.play.hidden = true;
}

async function next() {
  $("error").textContent = "";
  const todo = test.items.filter((i) => i.answer === null);
  if (!todo.length) {
    $("test").hidden = true;
    $("done").hidden = false;
    document.body.dataset.test = "done";
    return;
  }
  const item = todo[0];
  player.pause();
  $("question").textContent = test.question;
  $("progress").textContent = `Video ${test.items.length - todo.length + 1} of ${test.items.length}. Click the video to play it.`;
  $("choices").innerHTML = "";
  $("unusual").checked = false;
  $("comment").value = "";
  $("submit").disabled = true;
  picked = null;
  let motion;
  try {
    motion = await fetchJSON(`/api/evaluation/${encodeURIComponent(token)}/${test.name}/${item.position}/0`);
  } catch (e) {
    $("error").textContent = e.message;
    return;
  }
  const { wrap, stage, play } = stimulus(player, start);
  $("stages").replaceChildren(wrap);
  stage.pointLight = true;
  stage.fit(bounds([motion]));
  shown = { stage, motion, play };
  player.set([motion]);
  for (const [value, label] of test.choices) {
    const b = document.createElement("button");
    b.textContent = label;
    b.dataset.value = value;
    b.addEventListener("click", () => {
      picked = value;
      document.querySelectorAll("#choices button").forEach((o) => o.classList.toggle("picked", o === b));
      $("submit").disabled = false;
    });
    $("choices").appendChild(b);
  }
  $("submit").onclick = () => answer(item);
  document.body.dataset.test = test.name;
  document.body.dataset.position = String(item.position);
}

async function answer(item) {
  if (picked === null) return;
  $("submit").disabled = true;
  const body = { answer: picked, unusual: $("unusual").checked, comment: $("comment").value };
  try {
    await fetchJSON(`/api/evaluation/${encodeURIComponent(token)}/${test.name}/${item.position}`, {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify(body),
    });
    Object.assign(item, body);
    next();
  } catch (e) {
    $("error").textContent = `Your answer could not be saved: ${e.message}`;
    $("submit").disabled = false;
  }
}

$("comment").addEventListener("input", () => { if ($("comment").value.trim()) $("unusual").checked = true; });

(async () => {
  $("self").href = location.href;
  $("self").textContent = location.href;
  try {
    test = (await fetchJSON(`/api/evaluation/${encodeURIComponent(token)}`)).tests[0];
  } catch (e) {
    $("error").textContent = e.message;
    return;
  }
  next();
})();
