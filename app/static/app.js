// The workbench page: plain JS over the REST API (see /docs). It polls the session and redraws.
"use strict";

const $ = (id) => document.getElementById(id);
const S = {
  session: null, // id of the session shown
  status: null, // last GET /api/sessions/{id}
  planId: null, // plan_id whose candidates are listed
  selectedShown: undefined, // selection the inspector shows
  metricsKey: null, // iteration/plan the charts show
  inFlight: false,
  viewerSet: false,
};

// ------------------------------------------------------------------ helpers

// A server started with a token is opened as http://host:port/?token=...: every API call carries it.
const TOKEN = new URLSearchParams(location.search).get("token");

function withToken(url) {
  if (!TOKEN) return url;
  return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(TOKEN);
}

async function api(method, path, body) {
  const init = { method, headers: {} };
  if (TOKEN) init.headers["Authorization"] = "Bearer " + TOKEN;
  if (body instanceof FormData) init.body = body;
  else if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const res = await fetch(path, init);
  const type = res.headers.get("content-type") || "";
  const data = type.includes("json") ? await res.json() : null;
  if (!res.ok) {
    let detail = data && data.detail !== undefined ? data.detail : res.statusText;
    if (Array.isArray(detail)) detail = detail.map((d) => `${(d.loc || []).slice(1).join(".")}: ${d.msg}`).join("; ");
    throw new Error(`${res.status}: ${detail}`);
  }
  return data;
}

function num(v, digits) {
  if (v === null || v === undefined || !isFinite(v)) return "–";
  const a = Math.abs(v);
  if (a !== 0 && (a >= 1e5 || a < 1e-3)) return v.toExponential(2);
  return (+v.toFixed(digits === undefined ? 1 : digits)).toString();
}

function showError(msg) {
  const el = $("error");
  el.textContent = msg;
  el.hidden = !msg;
}

async function action(label, fn) {
  if (S.inFlight) return;
  S.inFlight = true;
  $("busy").textContent = label + "…";
  updateButtons();
  try {
    showError("");
    await fn();
  } catch (e) {
    showError(e.message);
  } finally {
    S.inFlight = false;
    $("busy").textContent = "";
    await refresh();
  }
}

// ------------------------------------------------------------------ models and sessions

async function loadModels(select) {
  const models = await api("GET", "/api/models");
  const sel = $("model");
  const keep = select || sel.value;
  sel.innerHTML = "";
  const groups = { builtin: "built-in", file: "models directory", upload: "uploads" };
  for (const [kind, title] of Object.entries(groups)) {
    const items = models.filter((m) => m.kind === kind);
    if (!items.length) continue;
    const og = document.createElement("optgroup");
    og.label = title;
    for (const m of items) {
      const o = document.createElement("option");
      o.value = m.name;
      o.textContent = m.name;
      o.title = m.description;
      og.appendChild(o);
    }
    sel.appendChild(og);
  }
  if (keep) sel.value = keep;
}

async function loadSessions() {
  const list = await api("GET", "/api/sessions");
  const sel = $("session-select");
  sel.innerHTML = '<option value="">(none)</option>';
  for (const s of list) {
    const o = document.createElement("option");
    o.value = s.id;
    o.textContent = `${s.id} · ${s.model} · ${s.state} · ${s.iteration} views`;
    sel.appendChild(o);
  }
  sel.value = S.session || "";
  return list;
}

function paramConfig() {
  const v = (id) => Number($(id).value);
  return {
    voxel: { resolution: v("p-resolution"), gamma: v("p-gamma") },
    candidates: { count: v("p-count"), parallels: v("p-parallels"), working_distance: v("p-dc") },
    partitions: { sectors: v("p-sectors"), revisit_deg: v("p-revisit") },
    cluster: { t_min: v("p-tmin"), t_max: v("p-tmax") },
    termination: { max_views: v("p-views") },
  };
}

async function showSession(id) {
  S.session = id || null;
  S.planId = null;
  S.selectedShown = undefined;
  S.metricsKey = null;
  $("session-select").value = id || "";
  if (id) await api("PUT", "/api/scene", { session: id }).catch(() => null); // no 3D view, or not resumed yet
  $("export-ply").href = id ? withToken(`/api/sessions/${id}/cloud.ply`) : "#";
  $("export-json").href = id ? withToken(`/api/sessions/${id}/export`) : "#";
  await refresh();
}

// ------------------------------------------------------------------ rendering

function updateButtons() {
  const st = S.status;
  const state = st ? st.state : null;
  const it = st ? st.iteration : 0;
  const busy = S.inFlight || ["capturing", "planning", "moving", "auto"].includes(state);
  $("capture").disabled = busy || !st || !(state === "new" || (state === "error" && it === 0));
  $("plan").disabled = busy || !st || it === 0 || !["ready", "planned", "done", "error"].includes(state);
  $("approve").disabled = busy || !st || state !== "planned" || st.selected === null;
  $("auto").disabled = busy || !st || it === 0 || !["ready", "planned", "done"].includes(state);
  $("stop").hidden = state !== "auto";
  $("resume").hidden = state !== "interrupted";
  $("resume").disabled = S.inFlight;
  $("retry").hidden = !(state === "error" && st && st.retry);
  $("retry").disabled = S.inFlight;
  const custom = st && st.custom_pose;
  $("approve-custom").disabled = busy || !custom || !custom.reachable || state !== "planned";
  $("create").disabled = S.inFlight;
  for (const id of ["export-ply", "export-json"]) $(id).classList.toggle("disabled", !st);
}

function renderStatus(st) {
  $("state").textContent = st ? st.state : "–";
  $("iteration").textContent = st ? st.iteration : 0;
  $("coverage").textContent = st && st.coverage !== null ? (100 * st.coverage).toFixed(1) + " %" : "–";
  $("points").textContent = st ? st.points : 0;
  if (st && st.error) showError(st.error);
  const term = $("terminated");
  term.hidden = !(st && st.terminated);
  if (st && st.terminated) term.textContent = `The planner would stop here (${st.terminated}); you may still plan and approve more views.`;
  if (st && st.state === "auto") $("busy").textContent = `auto mode: ${st.auto_remaining} step(s) left`;
  else if (!S.inFlight) $("busy").textContent = "";
  const custom = st && st.custom_pose;
  $("custom").textContent = custom
    ? `custom pose at (${custom.pose.position.map((v) => v.toFixed(3)).join(", ")}): ${custom.reason}`
    : "no custom pose";
  $("custom").className = "small " + (custom ? (custom.reachable ? "" : "error") : "muted");
  updateButtons();
}

async function loadCandidates() {
  const tbody = $("candidates").querySelector("tbody");
  tbody.innerHTML = "";
  $("plan-id").textContent = S.planId ? `plan ${S.planId}` : "";
  if (!S.planId) return;
  const items = await api("GET", `/api/sessions/${S.session}/candidates?sort=score&limit=12`);
  for (const c of items) {
    const tr = document.createElement("tr");
    tr.dataset.index = c.index;
    tr.className = (c.best ? "best " : "") + (c.eligible ? "" : "ineligible");
    tr.innerHTML = `<td>${c.index}</td><td>${num(c.score)}</td><td>${num(c.frontier)}</td><td>${num(c.occupied)}</td><td>${c.sector}</td>`;
    tr.addEventListener("click", () => action("selecting", () => api("PUT", `/api/sessions/${S.session}/selection`, { index: c.index })));
    tbody.appendChild(tr);
  }
  const scene = await api("GET", "/api/scene").catch(() => null);
  if (scene) renderColorbar(scene);
}

function markSelectedRow(selected) {
  for (const tr of $("candidates").querySelectorAll("tbody tr")) {
    tr.classList.toggle("selected", Number(tr.dataset.index) === selected);
  }
}

async function loadInspector(selected) {
  const img = $("projection");
  const tbody = $("breakdown").querySelector("tbody");
  tbody.innerHTML = "";
  if (selected === null || selected === undefined || !S.planId) {
    $("selected-label").textContent = "no selection";
    img.hidden = true;
    return;
  }
  const d = await api("GET", `/api/sessions/${S.session}/candidates/${selected}`);
  $("selected-label").textContent =
    `candidate ${d.index}${d.best ? " (planner's choice)" : ""}: F = ${num(d.score)} ` +
    `(${num(d.frontier)} − ${num(d.occupied)})${d.eligible ? "" : ", ineligible"}`;
  const rows = d.ellipsoids.filter((e) => e.rank >= 0).sort((a, b) => a.rank - b.rank);
  for (const e of rows) {
    const tr = document.createElement("tr");
    tr.innerHTML = `<td style="color:${e.kind === "frontier" ? "#d0312d" : "#2e63d8"}">${e.label}</td>` +
      `<td>${e.rank}</td><td>${num(e.weight, 3)}</td><td>${num(e.pixels, 0)}</td><td>${num(e.weighted, 0)}</td>`;
    tbody.appendChild(tr);
  }
  img.src = withToken(`/api/sessions/${S.session}/candidates/${selected}/projection.png?plan=${S.planId}`);
  img.hidden = false;
}

function renderColorbar(scene) {
  const stops = scene.colormap.map((c, i, a) => `rgb(${c.join(",")}) ${(100 * i) / (a.length - 1)}%`);
  $("cb-grad").style.background = `linear-gradient(to right, ${stops.join(",")})`;
  $("cb-lo").textContent = "F " + num(scene.score_range[0]);
  $("cb-hi").textContent = num(scene.score_range[1]);
}

async function loadLayers() {
  const scene = await api("GET", "/api/scene").catch(() => null);
  const box = $("layers");
  box.innerHTML = "";
  if (!scene) return;
  renderColorbar(scene);
  for (const [name, on] of Object.entries(scene.layers)) {
    if (name === "gizmo") { $("gizmo").checked = on; continue; }
    const label = document.createElement("label");
    const cb = document.createElement("input");
    cb.type = "checkbox";
    cb.checked = on;
    cb.dataset.layer = name;
    cb.addEventListener("change", () => api("PUT", "/api/scene/layers", { [name]: cb.checked }).catch((e) => showError(e.message)));
    label.append(cb, name);
    box.appendChild(label);
  }
}

async function loadMetrics() {
  const m = await api("GET", `/api/sessions/${S.session}/metrics`);
  const it = m.iterations;
  lineChart($("chart-coverage"), [{ points: it.map((r) => [r.iteration, r.coverage === null ? null : 100 * r.coverage]), color: "#15894a", label: "%" }], { xInteger: true, yMin: 0, yMax: 100 });
  lineChart($("chart-points"), [{ points: it.map((r) => [r.iteration, r.points]), color: "#2e63d8" }], { xInteger: true, yMin: 0 });
  lineChart($("chart-time"), [{ points: it.map((r) => [r.iteration, r.plan_seconds]), color: "#8a4fd8" }], { xInteger: true, yMin: 0 });
  const colors = { occupied: "#2e63d8", frontier: "#d0312d" };
  lineChart($("chart-bic"), m.fits.map((f) => {
    const chosen = f.bic.find((p) => p[0] === f.t_chosen);
    return { points: f.bic, color: colors[f.kind] || "#444", marker: chosen || null };
  }), { xInteger: true });
  $("bic-legend").innerHTML = m.fits.map((f) => `<span style="color:${colors[f.kind]}">${f.kind} T=${f.t_chosen}</span>`).join(" · ") +
    (m.fit_iteration ? ` <span class="muted">(view ${m.fit_iteration})</span>` : "");
}

// ------------------------------------------------------------------ polling

async function refresh() {
  if (!S.session) {
    S.status = null;
    renderStatus(null);
    return;
  }
  let st;
  try {
    st = await api("GET", `/api/sessions/${S.session}`);
  } catch (e) {
    if (e.message.startsWith("404")) { await showSession(null); await loadSessions(); }
    return;
  }
  S.status = st;
  renderStatus(st);
  const opt = $("session-select").querySelector(`option[value="${st.id}"]`);
  if (opt) opt.textContent = `${st.id} · ${st.model} · ${st.state} · ${st.iteration} views`;
  const planId = st.pending_plan ? st.pending_plan.plan_id : null;
  if (planId !== S.planId) {
    S.planId = planId;
    S.selectedShown = undefined;
    await loadCandidates();
  }
  if (st.selected !== S.selectedShown) {
    S.selectedShown = st.selected;
    markSelectedRow(st.selected);
    await loadInspector(st.selected);
  }
  const key = `${st.iteration}/${planId}`;
  if (key !== S.metricsKey && !["capturing", "planning", "moving", "interrupted"].includes(st.state)) {
    S.metricsKey = key;
    await loadMetrics();
  }
}

async function poll() {
  try {
    await refresh();
  } catch (e) {
    console.warn(e);
  }
  setTimeout(poll, 1000);
}

// ------------------------------------------------------------------ wiring

function wire() {
  $("create").addEventListener("click", () => action("creating the session", async () => {
    const body = { model: $("model").value || null, config: paramConfig(), seed: Number($("p-seed").value) };
    const r = await api("POST", "/api/sessions", body);
    S.session = r.id;
    await loadSessions();
    await showSession(r.id);
  }));
  $("session-select").addEventListener("change", (e) => showSession(e.target.value));
  $("upload").addEventListener("change", (e) => action("uploading", async () => {
    const f = e.target.files[0];
    if (!f) return;
    const form = new FormData();
    form.append("file", f);
    const m = await api("POST", "/api/models", form);
    await loadModels(m.name);
  }));
  $("capture").addEventListener("click", () => action("capturing the first view", () => api("POST", `/api/sessions/${S.session}/capture`)));
  $("plan").addEventListener("click", () => action("planning", () => api("POST", `/api/sessions/${S.session}/plan`)));
  $("approve").addEventListener("click", () => action("moving and capturing", () => {
    const st = S.status;
    return api("POST", `/api/sessions/${S.session}/approve`, { plan_id: st.pending_plan.plan_id, index: st.selected });
  }));
  $("approve-custom").addEventListener("click", () => action("moving to the custom pose", () => {
    const st = S.status;
    return api("POST", `/api/sessions/${S.session}/approve`, { plan_id: st.pending_plan.plan_id, pose: st.custom_pose.pose });
  }));
  $("auto").addEventListener("click", () => action("starting auto mode", () => api("POST", `/api/sessions/${S.session}/auto`, { count: Number($("auto-count").value) })));
  $("stop").addEventListener("click", () => api("POST", `/api/sessions/${S.session}/stop`).catch((e) => showError(e.message)));
  $("resume").addEventListener("click", () => action("rebuilding the session from its journal", async () => {
    const r = await api("POST", `/api/sessions/${S.session}/resume`);
    if (!r.verified) showError("resumed with differences: " + r.mismatches.join("; "));
    await loadSessions();
    await showSession(S.session);
  }));
  $("retry").addEventListener("click", () => action("retrying the failed step", () => api("POST", `/api/sessions/${S.session}/retry`)));
  $("gizmo").addEventListener("change", (e) => api("PUT", "/api/scene/layers", { gizmo: e.target.checked }).catch((err) => showError(err.message)));
}

async function init() {
  wire();
  try {
    await api("GET", "/api/health");
    $("health").textContent = "server ok";
  } catch (e) {
    $("health").textContent = "server unreachable";
  }
  try {
    const v = await api("GET", "/api/viewer");
    $("viewer").src = v.url;
    S.viewerSet = true;
    if (v.note) showError(v.note);
  } catch (e) {
    showError("3D viewer unavailable: " + e.message);
  }
  await loadModels();
  const list = await loadSessions();
  await loadLayers();
  if (list.length) await showSession(list[list.length - 1].id);
  poll();
}

init();
