// The workbench page: one session per tab (?session=ID), live from pushed events (/api/events), no polling.
// The 3D view is an iframe of the viser client bound to this tab's session by a single-use ticket
// (POST /api/viewer). Panels that only read live in panels.js.
"use strict";

const P = window.Panels;
const QUERY = new URLSearchParams(location.search);
// A server started with a token is opened as http://host:port/?token=...: every API call carries it.
const TOKEN = QUERY.get("token");
const S = {
  session: QUERY.get("session"), // the one session this tab shows (null: the picker)
  status: null, // last pushed status of it
  planId: null, // plan whose candidates are listed
  selectedShown: undefined, // the selection the table and inspector show (what Approve sends)
  arm: null, // GET /api/sessions/ID/arm: the arm, the move to the selection, unreachable candidates' reasons
  armKey: null,
  metricsKey: null,
  inFlight: false,
  viewer: null, // this tab's viewer id (layers, camera)
  layers: null,
  autoTotal: 0,
  events: null,
  progress: null, // the session's long operation (ProgressOut), pushed
  chain: Promise.resolve(), // pushed messages are handled one after the other
  metrics: null, // the last GET /metrics (the charts, redrawn with the timeline's cursor)
  sessions: [], // the session list (GET /api/sessions), kept current by pushed "sessions" messages
};
// The timeline (the session after view j, or now): the tab's viewer shows it (PUT /api/scene/VIEWER/timeline),
// the panels show its step (GET /api/sessions/ID/timeline/j[/candidates]); in compare mode every session at j.
const TL = {
  view: null, // the view shown, null: now
  want: null, // the view asked for last (a drag asks faster than steps are drawn: the last one wins)
  busy: false,
  step: null, // the step shown (TimelineStepOut)
  timer: null, // playing
  compare: null, // compare mode: its redraw(view)
  views: 0, // compare mode: the most views of the sessions compared
};
const FORM_KEY = "nbv-form";
const LAYER_KEY = "nbv-layers";
const SURFACE_FORMATS = ["ply", "obj", "glb"]; // GET /api/sessions/{id}/surface.ply?format=

// ------------------------------------------------------------------ helpers

function withToken(url) {
  if (!TOKEN) return url;
  return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(TOKEN);
}

// The page's pushed events (/api/events?session=ID or ?create=PROGRESS_ID), same host, the token if any.
function eventSocket(key, value) {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  return new WebSocket(`${proto}://${location.host}` + withToken(`/api/events?${key}=${encodeURIComponent(value)}`));
}

function pageUrl(params) {
  const q = new URLSearchParams(params);
  if (TOKEN) q.set("token", TOKEN);
  const s = q.toString();
  return "/" + (s ? "?" + s : "");
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

function showError(msg) {
  $("error").textContent = msg;
  $("error").hidden = !msg;
}

function showNotice(msg) {
  $("notice").textContent = msg;
  $("notice").hidden = !msg;
}

async function action(label, fn) {
  if (S.inFlight) return;
  S.inFlight = true;
  $("busy").textContent = label + "…";
  updateButtons();
  try {
    showError("");
    showNotice("");
    await fn();
  } catch (e) {
    const stale = e.message.startsWith("409") && /stale|already used|not the pending plan/.test(e.message);
    const stopped = e.message.startsWith("409") && /was stopped|cancelled/.test(e.message);
    if (stopped) showNotice("Stopped: " + e.message.slice(5));
    else if (stale) showNotice("The plan changed (another tab planned or approved): " + e.message.slice(5) + ". The new state is shown; check it and approve again.");
    else showError(e.message);
  } finally {
    S.inFlight = false;
    $("busy").textContent = "";
    updateButtons();
  }
}

// ------------------------------------------------------------------ form (restored on reload)

const FORM_IDS = ["model", "planner", "arm", "sensor", "calibration", "p-resolution", "p-parallels", "p-count", "p-sectors", "p-revisit", "p-gamma",
  "p-dc", "p-tmin", "p-tmax", "p-views", "p-seed", "auto-count"];

function saveForm() {
  const v = {};
  for (const id of FORM_IDS) v[id] = $(id).value;
  localStorage.setItem(FORM_KEY, JSON.stringify(v));
}

function restoreForm() {
  let v = {};
  try { v = JSON.parse(localStorage.getItem(FORM_KEY) || "{}"); } catch (e) { v = {}; }
  for (const id of FORM_IDS) if (v[id] !== undefined && v[id] !== "") $(id).value = v[id];
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

// ------------------------------------------------------------------ models, planners, sessions

async function loadModels(select) {
  const models = await api("GET", "/api/models");
  const sel = $("model");
  const keep = select || sel.value || (JSON.parse(localStorage.getItem(FORM_KEY) || "{}").model);
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
      o.textContent = P.shortModel(m.name);
      o.title = m.description;
      og.appendChild(o);
    }
    sel.appendChild(og);
  }
  if (keep) sel.value = keep;
}

async function loadPlanners() {
  const names = await api("GET", "/api/planners");
  const sel = $("planner");
  const keep = sel.value || JSON.parse(localStorage.getItem(FORM_KEY) || "{}").planner || "projection";
  sel.innerHTML = names.map((n) => `<option value="${P.esc(n)}">${P.esc(n)}${n === "projection" ? " (the paper's)" : ""}</option>`).join("");
  sel.value = names.includes(keep) ? keep : "projection";
}

// The simulated camera's sensor and calibration models (GET /api/sensors); "" asks for the server's default.
async function loadSensors() {
  const names = await api("GET", "/api/sensors");
  const saved = JSON.parse(localStorage.getItem(FORM_KEY) || "{}");
  for (const [id, list] of [["sensor", names.sensors], ["calibration", names.calibrations]]) {
    const sel = $(id);
    sel.innerHTML = '<option value="">(server default)</option>' +
      list.map((n) => `<option value="${P.esc(n)}">${P.esc(n)}</option>`).join("");
    sel.value = list.includes(saved[id]) ? saved[id] : "";
  }
}

// The arms a session may use (GET /api/arms): the presets, then the reach sphere; "" asks for the server's default.
async function loadArms() {
  const { arms } = await api("GET", "/api/arms");
  const saved = JSON.parse(localStorage.getItem(FORM_KEY) || "{}").arm;
  const sel = $("arm");
  sel.innerHTML = '<option value="">(server default)</option>' + arms.map((a) =>
    `<option value="${P.esc(a.name)}" title="${P.esc(a.note)}">${P.esc(a.title)}${a.dof ? ` (${a.dof} joints)` : ""}</option>`).join("");
  sel.value = arms.some((a) => a.name === saved) ? saved : "";
}

async function loadSessions() {
  S.sessions = await api("GET", "/api/sessions");
  renderSessions();
  return S.sessions;
}

// The session picker (the select and, without a session, the picker table) from S.sessions.
function renderSessions() {
  const list = S.sessions;
  const sel = $("session-select");
  sel.innerHTML = '<option value="">(choose)</option>';
  for (const s of list) {
    const o = document.createElement("option");
    o.value = s.id;
    o.textContent = `${s.id} · ${P.shortModel(s.model)} · ${s.planner || "projection"} · ${s.state} · ${s.iteration} views`;
    o.title = s.model;
    sel.appendChild(o);
  }
  sel.value = S.session || "";
  if (!S.session && !QUERY.get("compare")) P.renderPicker(list, (id) => pageUrl({ session: id }));
}

// A pushed change of the session list: a session's new state or view count is put in place (no request),
// a created or deleted session reloads the list.
async function onSessions(m) {
  const at = m.session ? S.sessions.findIndex((s) => s.id === m.id) : -1;
  if (m.change === "state" && at >= 0) {
    S.sessions[at] = m.session;
    renderSessions();
  } else await loadSessions();
}

// ------------------------------------------------------------------ this tab's session: viewer and events

async function openViewer() {
  try {
    const v = await api("POST", "/api/viewer", { session: S.session });
    S.viewer = v.viewer;
    TL.view = TL.want = TL.step = null; // a new viewer shows now
    renderTimeline();
    $("viewer").src = v.url;
    if (v.note) showNotice(v.note);
    let saved = {};
    try { saved = JSON.parse(localStorage.getItem(LAYER_KEY) || "{}"); } catch (e) { saved = {}; }
    const scene = await api("GET", `/api/scene/${S.viewer}`);
    const known = Object.fromEntries(Object.entries(saved).filter(([k]) => k in scene.layers));
    S.layers = Object.keys(known).length ? await api("PUT", `/api/scene/${S.viewer}/layers`, known) : scene.layers;
    P.renderLayers(S.layers, toggleLayer);
    P.renderLegend(scene);
  } catch (e) {
    showError("3D viewer unavailable: " + e.message);
  }
}

function connectEvents(delay) {
  const ws = eventSocket("session", S.session);
  S.events = ws;
  let opened = false;
  ws.onopen = () => {
    opened = true;
    $("health").textContent = "live";
    $("health").className = "ok";
  };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    S.chain = S.chain.then(() => onMessage(m)).catch((e) => console.warn(e));
  };
  ws.onclose = (ev) => {
    $("health").textContent = "live updates lost: reconnecting…";
    $("health").className = "bad";
    if (ev.code === 4404) { showError(`session ${S.session} is unknown (deleted, or the server forgot it)`); return; }
    const next = Math.min(5000, (delay || 500) * 2);
    setTimeout(async () => {
      connectEvents(opened ? 500 : next);
      if (opened) await openViewer(); // the server may have restarted: a new ticket
    }, opened ? 500 : next);
  };
}

function showProgress(p) {
  S.progress = p;
  const verbs = { plan: "planning", discard: "discarding the last view", resume: "resuming" };
  P.renderProgress($("progress"), p, p ? verbs[p.operation] || p.operation : "");
  updateButtons();
}

// A create's progress (reading, checking and sampling the mesh, building the cell) on its own event stream,
// open before the create starts (at most 2 s of waiting: without it the create just shows no stages).
async function followCreate(progressId) {
  const ws = eventSocket("create", progressId);
  const box = $("create-progress");
  $("create-cancel").dataset.progressId = progressId;
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    if (m.type === "create" && m.id === progressId) P.renderProgress(box, m.progress, "creating");
  };
  await new Promise((resolve) => {
    ws.addEventListener("open", resolve);
    ws.addEventListener("error", resolve);
    setTimeout(resolve, 2000);
  });
  return { close: () => { ws.close(); box.hidden = true; } };
}

async function onMessage(m) {
  if (m.type === "progress") showProgress(m.progress);
  else if (m.type === "status") await onStatus(m.status, m.event);
  else if (m.type === "sessions") await onSessions(m);
  else if (m.type === "viewer") await onViewer(m);
  else if (m.type === "deleted") {
    showError(`session ${S.session} was deleted`);
    S.status = null;
    renderStatus(null);
  } else if (m.type === "error") showError(m.detail);
}

async function onStatus(st, event) {
  S.status = st;
  renderTimeline();
  if (TL.view !== null) { updateButtons(); return; } // the panels show the timeline's step, not now
  renderStatus(st);
  showProgress(st.progress || null);
  const planId = st.pending_plan ? st.pending_plan.plan_id : null;
  if (planId !== S.planId || event === "captured") {
    S.planId = planId;
    S.selectedShown = undefined;
    await loadCandidates();
  }
  if (st.selected !== S.selectedShown) {
    S.selectedShown = st.selected;
    if (st.selected !== null) P.pageOf(st.selected);
    P.renderTable(st.selected, pick);
    updateButtons();
    await loadInspector(st.selected);
    await FitPanel.load();
  }
  const custom = st.custom_pose ? st.custom_pose.pose.position.join(",") + st.custom_pose.pose.wxyz : "";
  const armKey = `${st.iteration}/${planId}/${st.selected}/${custom}`;
  if (armKey !== S.armKey && S.viewer && !["capturing", "planning", "moving", "auto", "discarding"].includes(st.state)) {
    S.armKey = armKey;
    await loadArm();
  }
  const key = `${st.iteration}/${planId}`;
  if (key !== S.metricsKey && !["capturing", "planning", "moving", "discarding", "interrupted"].includes(st.state)) {
    S.metricsKey = key;
    S.metrics = await api("GET", `/api/sessions/${S.session}/metrics`);
    P.renderCharts(S.metrics, TL.view);
    FitPanel.markChart();
  }
}

// ------------------------------------------------------------------ rendering

function updateButtons() {
  const st = S.status;
  const state = st ? st.state : null;
  const it = st ? st.iteration : 0;
  // on the timeline the page shows the past: nothing acts on the session until it shows now again
  const busy = S.inFlight || TL.view !== null || ["capturing", "planning", "moving", "auto", "discarding"].includes(state);
  $("capture").disabled = busy || !st || !(state === "new" || (state === "error" && it === 0));
  $("plan").disabled = busy || !st || it === 0 || !["ready", "planned", "done", "error"].includes(state);
  // approve acts on the candidate the table and the inspector show: off until the page shows the selected one
  $("approve").disabled = busy || !st || state !== "planned" || st.selected === null || S.selectedShown !== st.selected;
  const target = S.arm && S.arm.target;
  $("preview").hidden = !(S.arm && S.arm.has_arm);
  $("preview").disabled = busy || !st || state !== "planned" || !target || !target.reachable;
  const terminated = st && st.terminated;
  $("auto").disabled = busy || !st || it === 0 || !!terminated || !["ready", "planned"].includes(state);
  $("auto-why").textContent = terminated ? `Auto is off: the planner stopped (${terminated}). Plan and approve by hand to go on.` :
    (st && it === 0 ? "Auto needs a first view: capture first." : "");
  $("discard").disabled = busy || !st || it === 0 || state === "interrupted";
  // Stop: kills a running plan (in its worker), ends auto mode; on hardware it also halts a running move at once
  const stoppablePlan = state === "planning" && S.progress && S.progress.stoppable;
  $("stop").hidden = !(["auto", "moving"].includes(state) || stoppablePlan);
  $("resume").hidden = state !== "interrupted";
  $("resume").disabled = S.inFlight;
  $("retry").hidden = !(state === "error" && st && st.retry);
  $("retry").disabled = S.inFlight;
  const custom = st && st.custom_pose;
  $("approve-custom").disabled = busy || !custom || !custom.reachable || state !== "planned";
  $("create").disabled = S.inFlight;
  $("delete").disabled = S.inFlight || !S.session;
  for (const id of ["export-ply", "export-json"]) $(id).classList.toggle("disabled", !st);
  for (const fmt of SURFACE_FORMATS) $(`export-surface-${fmt}`).classList.toggle("disabled", !st || !st.iteration);
}

function renderStatus(st) {
  $("state").textContent = st ? st.state : "–";
  $("iteration").textContent = st ? st.iteration : 0;
  $("coverage").textContent = st && st.coverage !== null ? (100 * st.coverage).toFixed(1) + " %" : "–";
  $("points").textContent = st ? st.points : 0;
  $("session-info").textContent = st ? `${st.id} · ${P.shortModel(st.model)} · planner ${st.planner || "projection"} · seed ${st.seed}` : "";
  if (st && st.error) showError(st.error);
  P.renderViewNotes($("view-notes"), st ? st.views || [] : []);
  const term = $("terminated");
  term.hidden = !(st && st.terminated);
  if (st && st.terminated) term.textContent = `The planner would stop here (${st.terminated}); you may still plan and approve more views.`;
  if (st && st.state === "auto") {
    const total = Math.max(S.autoTotal, st.auto_remaining);
    $("busy").textContent = `auto: step ${total - st.auto_remaining + 1} of ${total}`;
  } else if (!S.inFlight) $("busy").textContent = "";
  const custom = st && st.custom_pose;
  $("custom").textContent = custom
    ? `custom pose at (${custom.pose.position.map((v) => v.toFixed(3)).join(", ")}): ${custom.reason}`
    : "no custom pose";
  $("custom").className = "small " + (custom ? (custom.reachable ? "" : "error") : "muted");
  updateButtons();
}

async function loadCandidates() {
  $("plan-id").textContent = S.planId ? `plan ${S.planId}` : "";
  P.Table.items = S.planId ? await api("GET", `/api/sessions/${S.session}/candidates`) : [];
  P.renderTable(S.status ? S.status.selected : null, pick);
  $("tour-info").textContent = P.tourSummary(P.Table.items);
  $("tour-info").hidden = !$("tour-info").textContent;
  if (S.viewer) P.renderLegend(await api("GET", `/api/scene/${S.viewer}`));
}

// The arm (a cell with an arm model): where the selected view takes it, or why it cannot; the table's
// "unreachable" rows get the cell's reason (no_ik, joint_limit, collision:<link>:<obstacle>).
async function loadArm() {
  try {
    S.arm = await api("GET", `/api/sessions/${S.session}/arm`);
  } catch (e) {
    S.arm = null;
  }
  const box = $("arm");
  const arm = S.arm;
  box.hidden = !(arm && arm.has_arm);
  if (arm && arm.has_arm) {
    const t = arm.target;
    const what = t ? (t.kind === "custom" ? "the custom pose" : `candidate ${t.index}`) : null;
    box.textContent = !t ? "arm: no view selected" : t.reachable
      ? `arm: move to ${what} in ${t.duration.toFixed(1)} s (plate ${(t.plate_angle * 180 / Math.PI).toFixed(0)}°, ${t.path_method || "path"})`
      : `arm: ${what} is ${t.reason}`;
    box.className = "small " + (t && !t.reachable ? "error" : "muted");
    let changed = false;
    for (const c of P.Table.items) {
      const why = arm.unreachable[String(c.index)];
      if (why && c.reason === "unreachable") { c.reason = `unreachable: ${why}`; changed = true; }
    }
    if (changed) P.renderTable(S.selectedShown, pick);
  }
  updateButtons();
}

function preview() {
  return action("previewing the move", () => api("POST", `/api/sessions/${S.session}/arm/preview`));
}

async function loadInspector(selected) {
  if (selected === null || selected === undefined || !S.planId) { P.renderInspector(null); return; }
  const d = await api("GET", `/api/sessions/${S.session}/candidates/${selected}`);
  P.renderInspector(d, withToken(`/api/sessions/${S.session}/candidates/${selected}/projection.png?plan=${S.planId}`));
}

// ------------------------------------------------------------------ actions

function pick(index) {
  if (TL.view !== null) return; // the timeline's candidates are looked at, not selected
  return action("selecting", () => api("PUT", `/api/sessions/${S.session}/selection`, { index }));
}

// A viewer's state pushed to the page (its layers, however they were set; its Fit focus and refits).
async function onViewer(m) {
  if (m.viewer !== S.viewer) return;
  S.layers = m.layers;
  localStorage.setItem(LAYER_KEY, JSON.stringify(m.layers));
  P.renderLayers(S.layers, toggleLayer);
  await FitPanel.onViewer(m);
}

function toggleLayer(name, on) {
  return api("PUT", `/api/scene/${S.viewer}/layers`, { [name]: on }).then((layers) => {
    S.layers = layers;
    localStorage.setItem(LAYER_KEY, JSON.stringify(layers));
    P.renderLayers(layers, toggleLayer);
  }).catch((e) => showError(e.message));
}

function approveShown() {
  const st = S.status;
  const index = S.selectedShown; // exactly what the table and the inspector show
  if (!st || !st.pending_plan || index === null || index === undefined) return;
  const c = P.candidateOf(index);
  if (c && !c.eligible && !confirm(`Candidate ${index} is not eligible (${c.reason || "ineligible"}).\n` +
    "Approve it anyway? It is recorded as an override.")) return;
  return action("moving and capturing", () => api("POST", `/api/sessions/${S.session}/approve`, { plan_id: st.pending_plan.plan_id, index }));
}

function step(delta) {
  const rows = P.Table.items.length ? Array.from($("candidates").querySelectorAll("tbody tr")).map((tr) => Number(tr.dataset.index)) : [];
  if (!rows.length || !S.status || !S.status.pending_plan) return;
  const at = rows.indexOf(S.selectedShown);
  const next = rows[Math.min(rows.length - 1, Math.max(0, at + delta))];
  if (next !== undefined) pick(next);
}

function wire() {
  for (const id of FORM_IDS) $(id).addEventListener("change", saveForm);
  $("create").addEventListener("click", () => action("creating the session", async () => {
    saveForm();
    const progressId = "c" + Math.random().toString(36).slice(2) + Date.now().toString(36);
    const camera = { sensor: $("sensor").value || null, calibration: $("calibration").value || null };
    const body = { model: $("model").value || null, planner: $("planner").value, config: paramConfig(),
      seed: Number($("p-seed").value), progress_id: progressId,
      camera: camera.sensor || camera.calibration ? camera : null, arm: $("arm").value || null };
    const follow = await followCreate(progressId);
    try {
      const r = await api("POST", "/api/sessions", body);
      location.href = pageUrl({ session: r.id });
    } finally {
      follow.close();
    }
  }));
  $("create-cancel").addEventListener("click", () => {
    const id = $("create-cancel").dataset.progressId;
    if (id) api("DELETE", `/api/creations/${encodeURIComponent(id)}`).catch((e) => showError(e.message));
  });
  $("session-select").addEventListener("change", (e) => { location.href = pageUrl(e.target.value ? { session: e.target.value } : {}); });
  $("upload").addEventListener("change", (e) => action("uploading", async () => {
    const f = e.target.files[0];
    if (!f) return;
    const form = new FormData();
    form.append("file", f);
    const m = await api("POST", "/api/models", form);
    await loadModels(m.name);
  }));
  const post = (label, path) => () => action(label, () => api("POST", `/api/sessions/${S.session}/${path}`));
  $("capture").addEventListener("click", post("capturing the first view", "capture"));
  $("plan").addEventListener("click", post("planning", "plan"));
  $("approve").addEventListener("click", approveShown);
  $("preview").addEventListener("click", preview);
  $("approve-custom").addEventListener("click", () => action("moving to the custom pose", () => {
    const st = S.status;
    return api("POST", `/api/sessions/${S.session}/approve`, { plan_id: st.pending_plan.plan_id, pose: st.custom_pose.pose });
  }));
  $("auto").addEventListener("click", () => action("starting auto mode", () => {
    S.autoTotal = Number($("auto-count").value);
    return api("POST", `/api/sessions/${S.session}/auto`, { count: S.autoTotal });
  }));
  $("stop").addEventListener("click", () => api("POST", `/api/sessions/${S.session}/stop`).catch((e) => showError(e.message)));
  $("resume").addEventListener("click", () => action("rebuilding the session from its journal", async () => {
    const r = await api("POST", `/api/sessions/${S.session}/resume`);
    if (!r.verified) showError("resumed with differences: " + r.mismatches.join("; "));
    location.reload();
  }));
  $("retry").addEventListener("click", post("retrying the failed step", "retry"));
  $("discard").addEventListener("click", () => {
    if (!S.status || !confirm(`Discard view ${S.status.iteration}? The session is rebuilt from its journal without it.`)) return;
    action("rebuilding without the last view", () => api("POST", `/api/sessions/${S.session}/discard`));
  });
  $("delete").addEventListener("click", () => {
    if (!confirm(`Delete session ${S.session}? Its journal goes to the trash folder until the server restarts.`)) return;
    action("deleting", async () => {
      await api("DELETE", `/api/sessions/${S.session}`);
      location.href = pageUrl({});
    });
  });
  $("compare-open").addEventListener("click", () => {
    const ids = prompt("Sessions to compare (ids, comma-separated; the same object):", S.session || "");
    if (ids) window.open(pageUrl({ compare: ids.replace(/\s+/g, "") }), "_blank");
  });
  $("gizmo").addEventListener("change", (e) => toggleLayer("gizmo", e.target.checked));
  for (const th of $("candidates").querySelectorAll("th[data-sort]")) {
    th.addEventListener("click", () => {
      const key = th.dataset.sort;
      P.Table.sort = { key, dir: P.Table.sort.key === key ? -P.Table.sort.dir : (key === "index" || key === "sector" || key === "reason" ? 1 : -1) };
      P.Table.page = 0;
      P.renderTable(S.selectedShown, pick);
    });
  }
  $("page-prev").addEventListener("click", () => { P.Table.page -= 1; P.renderTable(S.selectedShown, pick); });
  $("page-next").addEventListener("click", () => { P.Table.page += 1; P.renderTable(S.selectedShown, pick); });
  $("help-open").addEventListener("click", () => { $("help").hidden = false; });
  $("help-close").addEventListener("click", () => { $("help").hidden = true; });
  $("tl-slider").addEventListener("input", (e) => {
    const v = Number(e.target.value);
    goTo(v > timelineViews() ? null : v);
  });
  $("tl-now").addEventListener("click", () => { stopPlaying(); goTo(null); });
  $("tl-play").addEventListener("click", () => (TL.timer ? stopPlaying() : play()));
  $("snapshot").addEventListener("click", snapshot);
  document.addEventListener("keydown", onKey);
}

function onKey(e) {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  if (["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement.tagName)) return;
  const click = (id) => { if (!$(id).disabled && !$(id).hidden) $(id).click(); };
  const keys = {
    c: () => click("capture"), p: () => click("plan"), a: () => click("approve"), u: () => click("auto"),
    s: () => click("stop"), d: () => click("discard"), n: () => step(1), j: () => step(1), k: () => step(-1),
    g: () => $("gizmo").click(), "?": () => { $("help").hidden = !$("help").hidden; }, Escape: () => { $("help").hidden = true; },
  };
  if (keys[e.key]) { e.preventDefault(); keys[e.key](); return; }
  if ((e.key === "ArrowLeft" || e.key === "ArrowRight") && !$("timeline").hidden) {
    e.preventDefault();
    stepTimeline(e.key === "ArrowLeft" ? -1 : 1);
    return;
  }
  if (/^[1-9]$/.test(e.key) && S.layers) {
    const names = Object.keys(S.layers).filter((n) => n !== "gizmo");
    const name = names[Number(e.key) - 1];
    if (name) toggleLayer(name, !S.layers[name]);
  }
}

// ------------------------------------------------------------------ the timeline

function timelineViews() {
  return TL.compare ? TL.views : (S.status ? S.status.iteration : 0);
}

// The bar: the slider over views 1..n and, at its right end, now.
function renderTimeline() {
  const n = timelineViews();
  const bar = $("timeline");
  bar.hidden = n === 0;
  const slider = $("tl-slider");
  slider.max = String(n + 1);
  slider.value = String(TL.view === null ? n + 1 : TL.view);
  bar.classList.toggle("past", TL.view !== null);
  $("tl-label").textContent = TL.view === null ? `now · ${n} view${n === 1 ? "" : "s"}` : `view ${TL.view} of ${n}`;
  $("tl-now").disabled = TL.view === null;
  $("tl-play").textContent = TL.timer ? "❚❚" : "▶";
  const st = TL.step;
  let note = "";
  if (TL.view !== null && !TL.compare && st) {
    const d = st.decision;
    const best = st.best ? `best #${st.best.index} (F ${P.num(st.best.score, 3)})` : "no plan";
    const took = !d ? "no decision yet" : d.custom ? `${d.kind}: a custom pose` :
      `${d.kind} #${d.index}${d.index !== d.best_index ? " (override)" : ""}`;
    note = `plan ${st.plan_id || "–"} · ${best} · ${took} · actions off until Now`;
  }
  $("tl-note").textContent = note;
}

// Show view `view` (null: now); requests run one after the other, the last one asked wins.
async function goTo(view) {
  TL.want = view;
  if (TL.busy) return;
  TL.busy = true;
  try {
    while (TL.want !== TL.view) await showView(TL.want);
  } catch (e) {
    TL.want = TL.view;
    showError("timeline: " + e.message);
  } finally {
    TL.busy = false;
    renderTimeline();
  }
}

async function showView(view) {
  if (TL.compare) {
    TL.view = view;
    TL.compare(view);
    renderTimeline();
    return;
  }
  const step = await api("PUT", `/api/scene/${S.viewer}/timeline`, { view });
  TL.view = view;
  TL.step = step;
  renderTimeline();
  if (view === null) { // now: every panel from the session's status again
    S.planId = undefined;
    S.selectedShown = undefined;
    S.armKey = S.metricsKey = null;
    if (S.status) await onStatus(S.status, "captured");
    return;
  }
  renderStep(step);
  P.Table.items = await api("GET", `/api/sessions/${S.session}/timeline/${view}/candidates`);
  const shown = step.approved !== null ? step.approved : (step.best ? step.best.index : null);
  if (shown !== null) P.pageOf(shown);
  P.renderTable(shown, pick);
  if (S.metrics) P.renderCharts(S.metrics, view);
  if (S.viewer) P.renderLegend(await api("GET", `/api/scene/${S.viewer}`));
}

// The status and candidate panels as they were after the step's view.
function renderStep(step) {
  $("iteration").textContent = step.view;
  $("coverage").textContent = step.coverage !== null ? (100 * step.coverage).toFixed(1) + " %" : "–";
  $("points").textContent = step.points;
  $("plan-id").textContent = step.plan_id ? `plan ${step.plan_id} · after view ${step.view}` : `no plan after view ${step.view}`;
  $("selected-label").textContent = step.approved !== null ? `candidate ${step.approved} (approved)` : "no selection";
  if (!$("arm").hidden) {
    $("arm").textContent = `arm: where it took view ${step.view}; the ghost: where the approved view took it`;
    $("arm").className = "small muted";
  }
  P.renderInspector(null);
  $("fit-label").textContent = "(the session now: the timeline does not refit)";
  updateButtons();
}

function stepTimeline(delta) {
  stopPlaying();
  const n = timelineViews();
  const at = TL.want === null ? n + 1 : TL.want;
  const next = Math.min(n + 1, Math.max(1, at + delta));
  goTo(next > n ? null : next);
}

function play() {
  if (timelineViews() === 0) return;
  if (TL.want === null) goTo(1);
  TL.timer = setInterval(() => {
    if (TL.busy) return; // the step before is still being drawn
    const n = timelineViews();
    if (TL.view === null || TL.view >= n) { stopPlaying(); goTo(null); return; }
    goTo(TL.view + 1);
  }, 1200);
  renderTimeline();
}

function stopPlaying() {
  if (TL.timer) clearInterval(TL.timer);
  TL.timer = null;
  renderTimeline();
}

// A PNG of the tab's 3D view as it is now (the viewer renders it at its canvas size), saved as a download.
async function snapshot() {
  if (!S.viewer) return;
  try {
    const init = { headers: TOKEN ? { Authorization: "Bearer " + TOKEN } : {} };
    const res = await fetch(`/api/scene/${S.viewer}/view.png`, init);
    if (!res.ok) throw new Error(`${res.status}: ${(await res.json()).detail}`);
    const a = document.createElement("a");
    a.href = URL.createObjectURL(await res.blob());
    a.download = `${S.session}-${TL.view === null ? "now" : "view" + TL.view}.png`;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
  } catch (e) {
    showError("PNG: " + e.message);
  }
}

// ------------------------------------------------------------------ compare mode

async function showCompare(ids) {
  $("compare").hidden = false;
  $("viewer").hidden = true;
  $("legend").hidden = true;
  const draw = async () => {
    const sessions = [];
    for (const id of ids) {
      try {
        sessions.push({ status: await api("GET", `/api/sessions/${id}`), metrics: await api("GET", `/api/sessions/${id}/metrics`) });
      } catch (e) { showError(`${id}: ${e.message}`); }
    }
    TL.views = Math.max(0, ...sessions.map((s) => s.status.iteration));
    TL.compare = (view) => P.renderCompare(sessions, (id) => pageUrl({ session: id }), view);
    TL.compare(TL.view);
    renderTimeline();
  };
  $("tl-recording").hidden = true;
  $("snapshot").hidden = true;
  await draw();
  for (const id of ids) { // live: redraw when a compared session takes a view
    const ws = eventSocket("session", id);
    ws.onmessage = (ev) => { if (JSON.parse(ev.data).event === "captured") draw(); };
  }
}

async function init() {
  P.renderHelp();
  wire();
  restoreForm();
  await Promise.all([loadModels(), loadPlanners(), loadSensors(), loadArms()]);
  await loadSessions();
  const compare = QUERY.get("compare");
  $("calibrate-open").href = pageUrl({ calibrate: "new" });
  if (QUERY.has("calibrate")) {
    await window.Calibrate.open(QUERY.get("calibrate")); // calibrate.js: commissioning a cell
  } else if (compare) {
    $("health").textContent = "compare";
    await showCompare(compare.split(",").filter(Boolean));
  } else if (S.session) {
    document.title = `${S.session} · NBV workbench`;
    $("export-ply").href = withToken(`/api/sessions/${S.session}/cloud.ply`);
    $("export-json").href = withToken(`/api/sessions/${S.session}/export`);
    for (const fmt of SURFACE_FORMATS) {
      $(`export-surface-${fmt}`).href = withToken(`/api/sessions/${S.session}/surface.ply?format=${fmt}`);
    }
    $("tl-recording").href = withToken(`/api/sessions/${S.session}/recording`);
    connectEvents(500);
    await openViewer();
  } else {
    $("picker").hidden = false;
    $("viewer").hidden = true;
    $("legend").hidden = true;
    $("health").textContent = "choose a session";
    $("create-box").open = true;
  }
  updateButtons();
}

init();
