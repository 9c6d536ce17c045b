// Evaluation start page: register a new evaluator and go to their page.
import { fetchJSON } from "/static/stage.js";
document.getElementById("begin").addEventListener("click", async () => {
  try {
    const { token } = await fetchJSON("/api/evaluation", { method: "POST" });
    location.href = `/evaluation/${token}`;
  } catch (e) {
    document.getElementById("error").textContent = e.message;
  }
});
