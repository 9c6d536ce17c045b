// Results page: every figure of the gait paper's §6, recomputed by the server
// from the answers (GET /api/results), drawn as tables and bars.
import { fetchJSON } from "/static/stage.js";

const $ = (id) => document.getElementById(id);
const token = new URLSearchParams(location.search).get("token") || "";
const pct = (v) => (v === null || v === undefined ? "–" : `${v.toFixed(1)} %`);
const num = (v, d = 2) => (v === null || v === undefined ? "–" : v.toFixed(d));
const KIND = { real: "Original", synthetic: "Synthesized" };
const NAT = { real: ["real", "#2a9d5b"], synthetic: ["synthetic", "#c9372c"], dont_know: ["I don't know", "#9aa6b8"] };

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  for (const c of children) e.append(c);
  return e;
}

function table(head, rows) {
  const t = el("table", { class: "data" });
  t.append(el("tr", {}, ...head.map((h) => el("th", {}, h))));
  for (const r of rows) t.append(el("tr", {}, ...r.map((c, i) => (i === 0 ? el("th", {}, c) : el("td", {}, c)))));
  return t;
}

function card(title, value, id) {
  return el("div", { class: "card", id }, el("div", { class: "muted" }, title), el("div", { class: "big mono" }, value));
}

function render(r) {
  const gait = (r.studies || ["gait"]).includes("gait");
  $("counts").replaceChildren(
    card("evaluators registered", String(r.registered), "n-registered"),
    ...(gait ? [
      card("evaluators who answered", String(r.evaluators), "n-evaluators"),
      card("naturalness answers", String(r.answers.naturalness), "n-naturalness"),
      card("style answers", String(r.answers.recognition), "n-recognition"),
      card("resemblance answers", String(r.answers.resemblance), "n-resemblance"),
    ] : []),
    ...(r.interaction ? [
      card("observers of interactions", String(r.interaction.observers), "n-observers"),
      card("interaction answers", String(r.interaction.answers), "n-interaction"),
    ] : []),
  );

  const nat = $("naturalness");
  nat.replaceChildren();
  for (const kind of ["real", "synthetic"]) {
    const row = r.naturalness[kind];
    const track = el("div", { class: "track" });
    for (const [k, [label, colour]] of Object.entries(NAT)) {
      const f = el("div", { class: "fill", title: `${label}: ${pct(row[k])}` });
      f.style.width = `${row[k] || 0}%`;
      f.style.background = colour;
      track.append(f);
    }
    nat.append(el("div", { class: "bar", id: `nat-${kind}` },
      el("span", {}, `${KIND[kind]} (n = ${row.n})`), track,
      el("span", { class: "mono" }, pct(row.real))));
  }
  nat.append(el("div", { class: "legend" },
    ...Object.values(NAT).map(([label, colour]) => { const s = el("span", {}, label); s.style.setProperty("--c", colour); return s; })));
  nat.append(table(["", "real", "synthetic", "I don't know", "n"],
    ["real", "synthetic"].map((k) => [KIND[k], pct(r.naturalness[k].real), pct(r.naturalness[k].synthetic), pct(r.naturalness[k].dont_know), String(r.naturalness[k].n)])));

  const rec = r.recognition;
  $("recognition").replaceChildren(
    table(["", "Original", "Synthesized"], [
      ["Static", pct(rec.real.static), pct(rec.synthetic.static)],
      ["Displacement", pct(rec.real.displacement), pct(rec.synthetic.displacement)],
      ["All", pct(rec.real.all), pct(rec.synthetic.all)],
      ["Efficiency η (eq. 16)", num(r.efficiency.real), num(r.efficiency.synthetic)],
      ["answers", String(rec.real.n), String(rec.synthetic.n)],
    ]),
    el("p", { class: "muted", id: "correlation" },
      `Chance level ${pct(r.chance)} (${r.styles.length + 2} choices). Pearson correlation of the per-style recognition of original and synthesized walks: `,
      el("b", {}, num(r.correlation, 4)), "."),
    table(["style", "Original", "Synthesized"], r.styles.map((s, i) => [s, pct(r.per_style.real[i]), pct(r.per_style.synthetic[i])])),
  );

  const conf = $("confusion");
  conf.replaceChildren();
  for (const kind of ["real", "synthetic"]) {
    const c = r.confusion[kind];
    const head = [`${KIND[kind]} (actual)`, ...c.columns.map((k) => r.labels[k] || k)];
    const t = table(head, c.rows.map((s, i) => [r.labels[s] || s, ...c.percent[i].map((v) => (v === null ? "–" : v.toFixed(0)))]));
    t.id = `confusion-${kind}`;
    t.querySelectorAll("tr").forEach((tr, i) => {
      if (i === 0) return;
      tr.querySelectorAll("td").forEach((td, j) => {
        const v = c.percent[i - 1][j] || 0;
        td.style.background = `rgba(47,111,214,${(v / 100) * 0.75})`;
        if (c.columns[j] === c.rows[i - 1]) td.style.fontWeight = "700";
      });
    });
    conf.append(el("h3", {}, KIND[kind]), t);
  }

  const hist = r.resemblance_histogram;
  const most = Math.max(1, ...hist);
  const bars = el("div", { class: "bars" });
  for (let level = 4; level >= 0; level--) {
    const track = el("div", { class: "track" });
    const f = el("div", { class: "fill" });
    f.style.width = `${(100 * hist[level]) / most}%`;
    f.style.background = "#2f6fd6";
    track.append(f);
    bars.append(el("div", { class: "bar" }, el("span", {}, `${level} · ${r.resemblance_levels[level]}`), track, el("span", { class: "mono" }, String(hist[level]))));
  }
  $("resemblance").replaceChildren(
    el("p", {}, "Mean score (4 = identical, 0 = nothing in common): ", el("b", { id: "resemblance-score" }, num(r.resemblance_score)),
      ` over ${hist.reduce((a, b) => a + b, 0)} comparisons.`),
    bars,
  );
  document.querySelectorAll("section.gait").forEach((s) => { s.hidden = !gait; });
  renderInteraction(r.interaction);
  document.body.dataset.loaded = "yes";
}

// The observer study (dual-HMM paper §4.2): identification per behaviour, real vs generated,
// how many noticed something unusual (Tables 1-2), and each video's comments.
function renderInteraction(s) {
  $("interaction").hidden = !s;
  if (!s) return;
  const KINDS = { real: "real", generated: "generated" };
  const ratio = (c) => `${c.correct}/${c.n}`;
  const noticed = (c) => `${c.unusual}/${c.n}`;
  const t = table(
    ["behaviour", ...s.kinds.flatMap((k) => [`identified, ${KINDS[k]}`, `noticed something unusual, ${KINDS[k]}`])],
    [...s.labels.map((l) => [l, s.rates[l]]), ["all", s.overall]].map(([label, row]) => [
      label, ...s.kinds.flatMap((k) => [`${pct(row[k].rate)} (${ratio(row[k])})`, noticed(row[k])]),
    ]),
  );
  t.id = "interaction-rates";
  t.querySelectorAll("tr").forEach((tr, i) => {
    if (i === 0) return;
    const label = i <= s.labels.length ? s.labels[i - 1] : "all";
    tr.dataset.label = label;
    tr.querySelectorAll("td").forEach((td, j) => {
      td.dataset.kind = s.kinds[Math.floor(j / 2)];
      td.dataset.what = j % 2 ? "unusual" : "rate";
    });
  });
  $("interaction-summary").replaceChildren(
    el("p", { class: "muted" }, `${s.observers} observers, ${s.answers} answers.`), t);
  $("interaction-clips").replaceChildren(...s.clips.map((c) => {
    const box = el("div", { class: "clip", id: `clip-${c.clip}` },
      el("h4", {}, `${c.clip} · ${c.label} · ${KINDS[c.kind] || c.kind}${c.take ? ` (${c.take})` : ""}`),
      el("p", { class: "muted" }, `identified ${ratio(c)} (${pct(c.rate)}); noticed something unusual ${noticed(c)}`));
    box.append(c.comments.length
      ? el("ul", { class: "comments" }, ...c.comments.map((text) => el("li", { class: "comment" }, text)))
      : el("p", { class: "muted" }, "no comments"));
    return box;
  }));
}

async function load() {
  try {
    render(await fetchJSON(`/api/results?token=${encodeURIComponent(token)}`));
  } catch (e) {
    $("error").textContent = e.message;
  }
}

$("csv").href = `/api/results.csv?token=${encodeURIComponent(token)}`;
$("refresh").addEventListener("click", (e) => { e.preventDefault(); load(); });
load();
