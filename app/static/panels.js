// The page's panels that only read: the candidate table, the inspector, the legend and layers, the charts,
// the session picker and the compare view. app.js owns the state (S) and calls these.
"use strict";

const $ = (id) => document.getElementById(id);
const PAGE_SIZE = 15;
const KIND_COLORS = { occupied: "#2e63d8", frontier: "#d0312d" };

function num(v, digits) {
  if (v === null || v === undefined || !isFinite(v)) return "–";
  const a = Math.abs(v);
  if (a !== 0 && (a >= 1e5 || a < 1e-3)) return v.toExponential(2);
  return (+v.toFixed(digits === undefined ? 1 : digits)).toString();
}

function esc(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" })[c]);
}

// "bunny" for "/work/shared/models/bunny.ply", "upload:abc/mug.obj" -> "mug"
function shortModel(name) {
  if (!name) return "–";
  const base = String(name).split(/[\\/]/).pop();
  return base.replace(/\.(ply|obj|stl|off|glb|gltf)$/i, "");
}

// ------------------------------------------------------------------ candidate table (every candidate, paged)

const Table = { items: [], sort: { key: "score", dir: -1 }, page: 0 };

function sortedCandidates() {
  const { key, dir } = Table.sort;
  const val = (c) => (key === "reason" ? (c.eligible ? "" : c.reason) : c[key]);
  return Table.items.slice().sort((a, b) => {
    if (key === "score" && a.eligible !== b.eligible) return a.eligible ? -1 : 1; // eligible first by F
    const x = val(a), y = val(b);
    return (x < y ? -1 : x > y ? 1 : 0) * dir || a.index - b.index;
  });
}

function renderTable(selected, onPick) {
  const tbody = $("candidates").querySelector("tbody");
  tbody.innerHTML = "";
  const rows = sortedCandidates();
  const pages = Math.max(1, Math.ceil(rows.length / PAGE_SIZE));
  Table.page = Math.min(Math.max(0, Table.page), pages - 1);
  for (const c of rows.slice(Table.page * PAGE_SIZE, (Table.page + 1) * PAGE_SIZE)) {
    const tr = document.createElement("tr");
    tr.dataset.index = c.index;
    tr.className = (c.best ? "best " : "") + (c.eligible ? "" : "ineligible ") + (c.index === selected ? "selected" : "");
    const why = c.eligible ? "yes" : esc(c.reason || "no");
    if (!c.eligible && c.reason) tr.title = `not eligible: ${c.reason}`;
    const short = (v) => num(v, Math.abs(v) >= 100 ? 0 : 1); // narrow columns: no decimals on big numbers
    tr.innerHTML = `<td>${c.index}</td><td>${short(c.score)}</td><td>${short(c.frontier)}</td><td>${short(c.occupied)}</td>` +
      `<td>S${c.sector}</td><td class="why">${why}</td>` +
      `<td class="c-move" data-testid="move-s">${c.move_seconds == null ? "–" : c.move_seconds.toFixed(1)}</td>` +
      `<td class="c-tour">${c.tour_order == null ? "" : c.tour_order}</td>`;
    tr.addEventListener("click", () => onPick(c.index));
    tbody.appendChild(tr);
  }
  // a column no candidate fills (the default planner has no move times and no tour) is not shown
  $("candidates").classList.toggle("no-move", !rows.some((c) => c.move_seconds != null));
  $("candidates").classList.toggle("no-tour", !rows.some((c) => c.tour_order != null));
  $("page-info").textContent = rows.length ? `page ${Table.page + 1} / ${pages} · ${rows.length} candidates` : "no plan";
  for (const th of $("candidates").querySelectorAll("th[data-sort]")) {
    th.classList.toggle("sorted", th.dataset.sort === Table.sort.key);
    th.dataset.dir = th.dataset.sort === Table.sort.key ? (Table.sort.dir > 0 ? "▲" : "▼") : "";
  }
}

// Show the page holding candidate `index` (a click on a sphere selects a row that may be on another page).
function pageOf(index) {
  const at = sortedCandidates().findIndex((c) => c.index === index);
  if (at >= 0) Table.page = Math.floor(at / PAGE_SIZE);
}

// "tour: 4 views, predicted robot time to done 9.8 s (moves)" from the table's rows ("" without a tour); a view of
// the ring opening (tour.opening = "ring"): "ring opening: a low view round from the first, then the tour; move 3.1 s".
function tourSummary(items) {
  const tour = items.filter((c) => c.tour_order != null);
  if (!tour.length) return "";
  const total = Math.max(...tour.map((c) => c.tour_seconds || 0));
  if (tour[0].tour_method === "ring") {
    return `ring opening: a low view round from the first, then the tour; move ${total.toFixed(1)} s`;
  }
  const views = tour.length === 1 ? "1 view" : `${tour.length} views`;
  return `tour: ${views}, predicted robot time to done ${total.toFixed(1)} s (moves)`;
}

function candidateOf(index) {
  return Table.items.find((c) => c.index === index) || null;
}

// ------------------------------------------------------------------ inspector

function renderInspector(d, imgUrl) {
  const img = $("projection");
  const tbody = $("breakdown").querySelector("tbody");
  tbody.innerHTML = "";
  if (!d) {
    $("selected-label").textContent = "no selection";
    img.hidden = true;
    return;
  }
  $("selected-label").textContent =
    `candidate ${d.index}${d.best ? " (planner's choice)" : ""}: F = ${num(d.score)} ` +
    `(${num(d.frontier)} − ${num(d.occupied)})${d.eligible ? "" : ", not eligible: " + (d.reason || "?")}`;
  const rows = d.ellipsoids.filter((e) => e.rank >= 0).sort((a, b) => a.rank - b.rank);
  for (const e of rows) {
    const tr = document.createElement("tr");
    tr.innerHTML = `<td style="color:${KIND_COLORS[e.kind] || "#444"}">${esc(e.label)}</td>` +
      `<td>${e.rank}</td><td>${num(e.weight, 3)}</td><td>${num(e.pixels, 0)}</td><td>${num(e.weighted, 0)}</td>`;
    tbody.appendChild(tr);
  }
  img.src = imgUrl;
  img.hidden = false;
}

// ------------------------------------------------------------------ legend and layers

const SECTOR_HELP = "Sectors S0…Sβ-1 split the hemisphere by longitude. 'scanned': a view was taken there; " +
  "'eligible': the next view may come from it; 'locked': not before every sector has been scanned.";

function renderLegend(scene) {
  const stops = scene.colormap.map((c, i, a) => `rgb(${c.join(",")}) ${(100 * i) / (a.length - 1)}%`);
  $("cb-grad").style.background = `linear-gradient(to right, ${stops.join(",")})`;
  $("cb-what").textContent = "view score F";
  $("colorbar").title = `candidate colour: ${scene.scale}; from the 5th to the 95th percentile of F ` +
    `(${num(scene.score_range[0], 0)} … ${num(scene.score_range[1], 0)}), beyond either end the end colour; grey: not eligible. ` +
    "F = frontier − occupied: it is negative when a view would see more already-known surface than unknown space; " +
    "only the order matters, the highest F wins.";
  $("cb-lo").textContent = "worse";
  $("cb-hi").textContent = "better";
  const box = $("voxel-legend");
  box.innerHTML = "";
  for (const name of ["occupied", "frontier", "unknown", "empty"]) {
    const c = scene.colors[name];
    const s = document.createElement("span");
    s.innerHTML = `<i class="swatch" style="background:rgb(${c.join(",")})"></i>${name}`;
    box.appendChild(s);
  }
  if (scene.colors.path) {  // the path layer: the camera along the move to the selected view, before approval
    const c = scene.colors.path;
    const s = document.createElement("span");
    s.dataset.legend = "path";
    s.title = "the path layer: where the camera goes (and the frames it would take) on the move to the selected view";
    s.innerHTML = `<i class="swatch" style="background:rgb(${c.join(",")})"></i>move path`;
    box.appendChild(s);
  }
  const sec = document.createElement("span");
  sec.className = "help-tip";
  sec.title = SECTOR_HELP;
  sec.textContent = "sectors (?)";
  box.appendChild(sec);
  renderReachLegend(scene);
}

// The reach layer's legend: each class's colour, with its number of views once the map is computed.
function renderReachLegend(scene) {
  const box = $("reach-legend");
  if (!box || !scene.reach_classes) return;
  const counts = Object.fromEntries((scene.reach || []).map((r) => [r.class, r.count]));
  box.innerHTML = "<b>reach:</b>";
  box.title = "the hemisphere's views coloured by what the session's arm reaches (IK, joint limits, collisions, " +
    "the plate's turn), as the planner judges them";
  for (const r of scene.reach_classes) {
    if (scene.reach && !(r.class in counts)) continue;
    const s = document.createElement("span");
    s.dataset.reachClass = r.class;
    s.innerHTML = `<i class="swatch" style="background:rgb(${r.color.join(",")})"></i>${r.label}` +
      (r.class in counts ? ` (${counts[r.class]})` : "");
    box.appendChild(s);
  }
  if (!scene.reach) box.append(" computing…");
}

function renderLayers(layers, onToggle) {
  const box = $("layers");
  box.innerHTML = "";
  const reach = $("reach-legend");
  if (reach) reach.hidden = !layers.reach;
  let k = 0;
  for (const [name, on] of Object.entries(layers)) {
    if (name === "gizmo") { $("gizmo").checked = on; continue; }
    k += 1;
    const label = document.createElement("label");
    label.title = k <= 9 ? `toggle with ${k}` : "";
    const cb = document.createElement("input");
    cb.type = "checkbox";
    cb.checked = on;
    cb.dataset.layer = name;
    cb.addEventListener("change", () => onToggle(name, cb.checked));
    label.append(cb, name);
    box.appendChild(label);
  }
}

// ------------------------------------------------------------------ charts

// m: GET /metrics; cursor: the timeline's view (a red line on the per-view charts), null: none.
function renderCharts(m, cursor) {
  const it = m.iterations;
  cursor = cursor === undefined ? null : cursor;
  const pct = (key) => it.map((r) => [r.iteration, r[key] === null || r[key] === undefined ? null : 100 * r[key]]);
  const cov = [{ points: pct("coverage"), color: "#15894a", label: "coverage" },
    { points: pct("precision_5mm"), color: "#2e63d8", label: "precision@5mm" },
    { points: pct("fscore_5mm"), color: "#e08a00", label: "F@5mm" }];
  const ceiling = m.ceiling === undefined || m.ceiling === null ? null : 100 * m.ceiling;
  $("ceiling-note").textContent = ceiling === null ? "" : `(dashed: reachable ceiling ${num(ceiling)} %)`;
  lineChart($("chart-coverage"), cov, { xInteger: true, yMin: 0, yMax: 100, xLabel: "view", yLabel: "%", hline: ceiling, cursor });
  lineChart($("chart-points"), [{ points: it.map((r) => [r.iteration, r.points]), color: "#2e63d8" }], { xInteger: true, yMin: 0, xLabel: "view", yLabel: "points", cursor });
  lineChart($("chart-time"), [{ points: it.map((r) => [r.iteration, r.plan_seconds]), color: "#8a4fd8" }], { xInteger: true, yMin: 0, xLabel: "view", yLabel: "s", cursor });
  // BIC: each kind normalised to [0, 1] (their magnitudes differ by orders), real values on hover
  const series = m.fits.map((f) => {
    const ys = f.bic.map((p) => p[1]);
    const lo = Math.min(...ys), hi = Math.max(...ys);
    const norm = (y) => (hi > lo ? (y - lo) / (hi - lo) : 0.5);
    const chosen = f.bic.find((p) => p[0] === f.t_chosen);
    return {
      points: f.bic.map((p) => [p[0], norm(p[1])]),
      hover: f.bic.map((p) => `${f.kind}: T=${p[0]}, BIC=${num(p[1], 0)}`),
      color: KIND_COLORS[f.kind] || "#444", label: f.kind,
      marker: chosen ? [chosen[0], norm(chosen[1])] : null,
    };
  });
  lineChart($("chart-bic"), series, { xInteger: true, yMin: 0, yMax: 1, xLabel: "T (components)", yLabel: "norm. BIC" });
  $("bic-legend").innerHTML = m.fits.map((f) => `<span style="color:${KIND_COLORS[f.kind]}">${f.kind} T=${f.t_chosen}</span>`).join(" · ") +
    (m.fit_iteration ? ` <span class="muted">(view ${m.fit_iteration})</span>` : "");
}

// ------------------------------------------------------------------ picker and compare

function renderPicker(list, hrefOf) {
  const tbody = $("picker-table").querySelector("tbody");
  tbody.innerHTML = "";
  for (const s of list) {
    const tr = document.createElement("tr");
    tr.innerHTML = `<td><a href="${hrefOf(s.id)}" data-session="${esc(s.id)}">${esc(s.id)}</a></td>` +
      `<td title="${esc(s.model)}">${esc(shortModel(s.model))}</td><td>${esc(s.planner || "projection")}</td>` +
      `<td>${esc(s.state)}</td><td>${s.iteration}</td><td>${s.coverage === null ? "–" : (100 * s.coverage).toFixed(1) + " %"}</td>`;
    tbody.appendChild(tr);
  }
  $("picker-empty").hidden = list.length > 0;
  $("picker-sessions").hidden = list.length === 0; // nothing to open: no empty list on the first screen
}

const PALETTE = ["#2e63d8", "#d0312d", "#15894a", "#8a4fd8", "#e08a00", "#0a8ea0"];

// sessions: [{status, metrics}] of sessions on the same object, drawn over each other. view: the timeline's view
// index all sessions are stepped to (their coverage and plan time up to it, a cursor on the charts), null: now.
function renderCompare(sessions, hrefOf, view) {
  view = view === undefined ? null : view;
  const box = $("compare");
  const upTo = (s) => s.metrics.iterations.filter((r) => view === null || r.iteration <= view);
  const pct = (c) => c === null || c === undefined ? "–" : (100 * c).toFixed(1) + " %";
  const rows = sessions.map((s, i) => {
    const it = upTo(s), last = it.length ? it[it.length - 1] : null;
    return `<tr data-session="${esc(s.status.id)}"><td><i class="swatch" style="background:${PALETTE[i % PALETTE.length]}"></i>` +
    `<a href="${hrefOf(s.status.id)}" target="_blank" rel="noopener">${esc(s.status.id)}</a></td><td>${esc(s.status.planner || "projection")}</td>` +
    `<td class="views">${view === null ? s.status.iteration : Math.min(view, s.status.iteration)}</td>` +
    `<td class="coverage">${view === null ? pct(s.status.coverage) : pct(last && last.coverage)}</td>` +
    `<td>${num(it.reduce((a, r) => a + (r.plan_seconds || 0), 0), 2)}</td></tr>`;
  }).join("");
  const model = sessions.length ? shortModel(sessions[0].status.model) : "";
  box.innerHTML = `<h2>Compare · ${esc(model)}${view === null ? "" : ` · at view ${view}`}</h2><table class="small"><thead><tr><th>session (opens in a tab)</th><th>planner</th>` +
    `<th>views</th><th>coverage</th><th>plan time (s)</th></tr></thead><tbody>${rows}</tbody></table>` +
    `<div class="compare-charts"><figure><figcaption>coverage (%) vs view</figcaption><svg id="cmp-coverage"></svg></figure>` +
    `<figure><figcaption>plan time (s) vs view</figcaption><svg id="cmp-time"></svg></figure></div>`;
  const series = (f) => sessions.map((s, i) => ({ points: s.metrics.iterations.map(f), color: PALETTE[i % PALETTE.length], label: s.status.id }));
  lineChart($("cmp-coverage"), series((r) => [r.iteration, r.coverage === null ? null : 100 * r.coverage]), { xInteger: true, yMin: 0, yMax: 100, xLabel: "view", yLabel: "%", cursor: view });
  lineChart($("cmp-time"), series((r) => [r.iteration, r.plan_seconds]), { xInteger: true, yMin: 0, xLabel: "view", yLabel: "s", cursor: view });
}

// ------------------------------------------------------------------ progress of a long operation

// A bar and a line: "planning · reachability (2 of 6) · 120 / 400 · 43 % · 1.2 s". p: ProgressOut or null.
function renderProgress(box, p, verb) {
  box.hidden = !p;
  if (!p) return;
  const items = p.total > 0 ? ` · ${p.done} / ${p.total}` : "";
  box.querySelector(".fill").style.width = `${Math.max(0, Math.min(100, p.percent))}%`;
  box.querySelector(".what").textContent =
    `${verb} · ${p.stage} (${p.step} of ${p.steps})${items} · ${p.percent.toFixed(0)} % · ${p.elapsed.toFixed(1)} s`;
}

// ------------------------------------------------------------------ keyboard shortcuts and help

const SHORTCUTS = [
  ["c", "capture the first view"], ["p", "plan"], ["a", "approve the selected candidate"],
  ["n / j", "select the next candidate (table order)"], ["k", "select the previous candidate"],
  ["u", "run auto"], ["s", "stop a plan or auto"], ["d", "discard the last view"], ["g", "toggle the override gizmo"],
  ["1 … 9", "toggle the layers in the 3D view's layer bar"], ["← / →", "timeline: the view before / after (→ past the last: now)"], ["?", "this help"], ["Esc", "close the help"],
];

// Which views ICP rejected (and why) and which of the planner's choices the cell refused before a view.
function renderViewNotes(box, views) {
  const notes = [];
  for (const v of views) {
    if (v.icp_rejected) {
      notes.push(`view ${v.iteration}: ICP's correction was not applied (${v.icp_rejected.replace(/^rejected: /, "")}); ` +
        "the camera's reported pose was kept. Nothing to do when the cell reports exact poses (a simulated cell " +
        "without a calibration error); on a real cell, several in a row mean the poses drift: check the calibration.");
    }
    for (const r of v.refused || []) notes.push(`view ${v.iteration}: candidate ${r.candidate} refused (${r.reason}), the next one taken`);
  }
  box.innerHTML = notes.map((n) => `<div class="view-note">${esc(n)}</div>`).join("");
}

function renderHelp() {
  $("help-keys").innerHTML = SHORTCUTS.map(([k, what]) => `<tr><td><kbd>${esc(k)}</kbd></td><td>${esc(what)}</td></tr>`).join("");
}

window.Panels = { Table, renderTable, pageOf, candidateOf, tourSummary, renderInspector, renderLegend, renderLayers, renderCharts,
  renderViewNotes, renderPicker, renderCompare, renderHelp, renderProgress, shortModel, num, esc };
