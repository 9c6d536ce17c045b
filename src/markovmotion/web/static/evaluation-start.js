// Evaluation start page: the studies this server runs (walks, interactions); register a
// new evaluator of the one chosen and go to their page.
import { fetchJSON } from "/static/stage.js";

async function begin(study) {
  try {
    const { token } = await fetchJSON(`/api/evaluation?study=${study}`, { method: "POST" });
    location.href = `/evaluation/${token}`;
  } catch (e) {
    document.getElementById("error").textContent = e.message;
  }
}

document.getElementById("begin").addEventListener("click", () => begin("gait"));
document.getElementById("begin-interaction").addEventListener("click", () => begin("interaction"));

(async () => {
  let studies = null;
  try {
    ({ studies } = await fetchJSON("/api/studies"));
  } catch (e) {
    document.getElementById("error").textContent = e.message;
    return;
  }
  if (!studies.length) return; // the server sends its no-evaluation page instead of this one
  document.getElementById("study-gait").hidden = !studies.includes("gait");
  document.getElementById("study-interaction").hidden = !studies.includes("interaction");
  document.body.dataset.studies = studies.join(" ");
})();
