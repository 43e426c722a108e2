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
// A tab's layer choices, per session and per tab (sessionStorage): a new tab or another session starts from the
// server's layers, not from the last person's choices.
const layerKey = () => `nbv-layers:${S.session}`;
const GUIDE_KEY = "nbv-guide"; // this tab's guide switch (sessionStorage): "on", "off" or unset (the session's)
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

// A server's answer in words a person can act on (the session limit: what to do about it).
function explainError(msg) {
  if (/^(409|429|503)/.test(msg) && /live session|max_live_sessions|too many sessions/i.test(msg)) {
    return msg + " — the server holds this many live sessions at once: close or delete a session you no longer " +
      "need, or ask whoever runs the server to raise server.max_live_sessions.";
  }
  return msg;
}

function showError(msg) {
  $("error").textContent = msg;
  $("error").hidden = !msg;
}

function showNotice(msg) {
  $("notice").textContent = msg;
  $("notice").hidden = !msg;
}

// Where an action's error shows: by the form for a create (errorBox), else the Scan box.
async function action(label, fn, errorBox) {
  if (S.inFlight) return;
  S.inFlight = true;
  $("busy").textContent = label + "…";
  updateButtons();
  try {
    showError("");
    showNotice("");
    if (errorBox) { $(errorBox).hidden = true; }
    await fn();
  } catch (e) {
    const stale = e.message.startsWith("409") && /stale|already used|not the pending plan/.test(e.message);
    const stopped = e.message.startsWith("409") && /was stopped|cancelled/.test(e.message);
    if (stopped) showNotice("Stopped: " + e.message.slice(5));
    else if (stale) showNotice("The plan changed (another tab planned or approved): " + e.message.slice(5) + ". The new state is shown; check it and approve again.");
    else if (errorBox) { $(errorBox).textContent = explainError(e.message); $(errorBox).hidden = false; }
    else showError(e.message);
  } finally {
    S.inFlight = false;
    $("busy").textContent = "";
    updateButtons();
  }
}

// ------------------------------------------------------------------ form (restored on reload)

const FORM_IDS = ["model", "planner", "arm-preset", "sensor", "calibration", "move-capture", "p-resolution", "p-parallels", "p-count", "p-sectors", "p-revisit", "p-gamma",
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

const RECORDED = "recorded:";

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
  // Recorded view sets (real scans): the session's candidates are the set's views, no simulator.
  const sets = await api("GET", "/api/recorded");
  if (sets.length) {
    const og = document.createElement("optgroup");
    og.label = "recorded view sets";
    for (const name of sets) {
      const o = document.createElement("option");
      o.value = RECORDED + name;
      o.textContent = name;
      o.title = "real views: the planner chooses among them";
      og.appendChild(o);
    }
    sel.appendChild(og);
  }
  if (keep) sel.value = keep;
}

// The create body's model and source for the object select's value (a recorded set: RECORDED + its name).
function objectChoice(value) {
  if (value && value.startsWith(RECORDED)) return { model: null, source: { kind: "recorded", recorded: value.slice(RECORDED.length) } };
  return { model: value || null };
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
  const saved = JSON.parse(localStorage.getItem(FORM_KEY) || "{}")["arm-preset"];
  const sel = $("arm-preset");
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
    try { saved = JSON.parse(sessionStorage.getItem(layerKey()) || "{}"); } catch (e) { saved = {}; }
    const scene = await api("GET", `/api/scene/${S.viewer}`);
    const known = Object.fromEntries(Object.entries(saved).filter(([k]) => k in scene.layers));
    S.layers = Object.keys(known).length ? await api("PUT", `/api/scene/${S.viewer}/layers`, known) : scene.layers;
    P.renderLayers(S.layers, toggleLayer);
    P.renderLegend(scene);
    if (S.status) await showObjectBeforeFirstView(S.status);
  } catch (e) {
    showError("3D viewer unavailable: " + e.message);
  }
}

// The first screen (no session open in this tab): a viewer of no session shows the simulated cell and the server's
// default object as a demo scan would start (POST /api/viewer/preview); opening a session loads its own page.
async function openPreview() {
  try {
    const v = await api("POST", "/api/viewer/preview");
    $("viewer").src = v.url;
    $("viewer").hidden = false;
  } catch (e) {
    $("viewer").hidden = true; // a server without the 3D view: the first screen without it
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
  const listed = S.sessions.findIndex((s) => s.id === st.id);
  if (listed >= 0 && (S.sessions[listed].state !== st.state || S.sessions[listed].iteration !== st.iteration)) {
    S.sessions[listed] = { ...S.sessions[listed], state: st.state, iteration: st.iteration, coverage: st.coverage };
    renderSessions(); // the Open session list says what the Scan panel says
  }
  renderTimeline();
  await showObjectBeforeFirstView(st);
  Guide.render();
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
    if (!S.planId) await FitPanel.load(); // the last plan's fit (none before the first plan: no request)
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
  $("export-bag").classList.toggle("disabled", !st || !st.iteration);
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
  Guide.render(); // its "why this view won" reads the candidates
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
  return action("previewing the move", async () => {
    const r = await api("POST", `/api/sessions/${S.session}/arm/preview`);
    const t = S.arm && S.arm.target;
    const secs = r && typeof r.duration === "number" ? r.duration : t && t.duration;
    showNotice(`Preview: the translucent arm in the 3D view plays the move${secs ? ` (${secs.toFixed(1)} s)` : ""}; ` +
      "nothing moves until you approve.");
  });
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
  sessionStorage.setItem(layerKey(), JSON.stringify(m.layers));
  P.renderLayers(S.layers, toggleLayer);
  await FitPanel.onViewer(m);
}

function toggleLayer(name, on) {
  return api("PUT", `/api/scene/${S.viewer}/layers`, { [name]: on }).then((layers) => {
    S.layers = layers;
    sessionStorage.setItem(layerKey(), JSON.stringify(layers));
    P.renderLayers(layers, toggleLayer);
    if (name === "reach" && on) refreshReachLegend(20);
  }).catch((e) => showError(e.message));
}

// The reach map is computed off the request: the legend asks again until it has the counts (or the layer is off).
async function refreshReachLegend(tries) {
  if (!S.viewer || !S.layers || !S.layers.reach) return;
  const scene = await api("GET", `/api/scene/${S.viewer}`);
  P.renderLegend(scene);
  if (!scene.reach && tries > 1) setTimeout(() => refreshReachLegend(tries - 1), 1000);
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
    const body = { ...objectChoice($("model").value), planner: $("planner").value, config: paramConfig(),
      seed: Number($("p-seed").value), progress_id: progressId,
      camera: camera.sensor || camera.calibration ? camera : null, arm: $("arm-preset").value || null,
      move_capture: $("move-capture").value === "" ? null : Number($("move-capture").value) };
    const follow = await followCreate(progressId);
    try {
      const r = await api("POST", "/api/sessions", body);
      location.href = pageUrl({ session: r.id });
    } finally {
      follow.close();
    }
  }, "create-error"));
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
  $("compare-open").addEventListener("click", openCompareDialog);
  $("compare-cancel").addEventListener("click", () => { $("compare-dialog").hidden = true; });
  $("compare-go").addEventListener("click", () => {
    const ids = Array.from($("compare-list").querySelectorAll("input:checked")).map((c) => c.value);
    if (ids.length < 1) return;
    $("compare-dialog").hidden = true;
    window.open(pageUrl({ compare: ids.join(",") }), "_blank");
  });
  $("demo").addEventListener("click", startDemo);
  $("charts-box").addEventListener("toggle", () => { // drawn folded they have no size: draw them again when opened
    if ($("charts-box").open && S.metrics) { P.renderCharts(S.metrics, TL.view); FitPanel.markChart(); }
  });
  $("guided-toggle").addEventListener("change", (e) => {
    sessionStorage.setItem(GUIDE_KEY, e.target.checked ? "on" : "off");
    Guide.render();
  });
  $("guide-close").addEventListener("click", () => {
    sessionStorage.setItem(GUIDE_KEY, "off");
    Guide.render();
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
    g: () => $("gizmo").click(), "?": () => { $("help").hidden = !$("help").hidden; },
    Escape: () => { $("help").hidden = true; $("compare-dialog").hidden = true; },
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

// ------------------------------------------------------------------ the first screen and the guide

// The demo: a session on the default object, opened at once (the 3D view of the cell and the object, its mesh shown
// before the first picture), then its first view taken and the next one planned by the session's page (runDemo):
// Approve is ready, a first approved view in two clicks from the first screen.
async function startDemo() {
  const box = $("demo-progress");
  const err = $("demo-error");
  err.hidden = true;
  $("demo").disabled = true;
  const say = (what, percent) => P.renderProgress(box, { stage: what, step: 1, steps: 1, done: 0, total: 0, percent, elapsed: 0 }, "demo");
  try {
    say("creating the session on the default object", 20);
    // the server's default object, planner and cell; "explain each step" makes it a guided session (journaled)
    const r = await api("POST", "/api/sessions", { guided: $("demo-guided").checked });
    location.href = pageUrl({ session: r.id, demo: "1" });
  } catch (e) {
    box.hidden = true;
    err.textContent = explainError(e.message);
    err.hidden = false;
    $("demo").disabled = false;
  }
}

// The demo's session page (?demo=1, dropped from the address at once so a reload does not repeat it): once the
// session shows "new", its first picture, then a plan.
async function runDemo() {
  history.replaceState(null, "", pageUrl({ session: S.session }));
  for (let i = 0; i < 100 && !(S.status && S.status.state); i++) await new Promise((r) => setTimeout(r, 100));
  if (!S.status || S.status.state !== "new") return;
  let captured = false;
  await action("taking the first picture", async () => { await api("POST", `/api/sessions/${S.session}/capture`); captured = true; });
  if (!captured) return;
  await action("planning the next view (scoring every candidate)", () => api("POST", `/api/sessions/${S.session}/plan`));
}

// Before the first picture the map is empty: the object's mesh is shown so the plate does not look empty (turned
// off again by the first view unless the person chose it).
let meshShownByPage = false;
async function showObjectBeforeFirstView(st) {
  if (!S.viewer || !S.layers || !("mesh" in S.layers)) return;
  const saved = sessionStorage.getItem(layerKey());
  if (st.iteration === 0 && !S.layers.mesh && !saved) {
    meshShownByPage = true;
    await toggleLayer("mesh", true);
  } else if (st.iteration > 0 && meshShownByPage) {
    meshShownByPage = false;
    if (S.layers.mesh) await toggleLayer("mesh", false);
  }
}

// The guided mode: at each step a short panel over the 3D view says what one sees and why, with a button that
// shows it (the layers that draw it). On when the session is guided (a class switched it on) or this tab's guide box.
const Guide = (() => {
  const LAYERS = {
    cell: { mesh: true, turntable: true },
    voxels: { occupied: true, frontier: true, unknown: true, ellipsoids: false, candidates: false, sectors: false, cloud: false },
    ellipsoids: { occupied: false, frontier: false, unknown: false, ellipsoids: true, candidates: false, sectors: false },
    score: { ellipsoids: true, candidates: true, nbv: true, sectors: false, unknown: false },
    sectors: { sectors: true, candidates: true, nbv: true, views: true },
    icp: { cloud: true, views: true, occupied: false, frontier: false, unknown: false, ellipsoids: false, candidates: false },
  };

  function on() {
    const local = sessionStorage.getItem(GUIDE_KEY);
    if (local === "on") return true;
    if (local === "off") return false;
    return !!(S.status && S.status.guided === true); // the session's flag (absent: false)
  }

  function card(title, paragraphs, show) {
    return { title, html: paragraphs.map((t) => `<p>${t}</p>`).join(""), show };
  }

  const occ = '<span class="k-occupied">occupied</span>';
  const fro = '<span class="k-frontier">frontier</span>';

  function steps() {
    const st = S.status;
    if (!st) return [];
    const n = st.iteration;
    const out = [];
    if (n === 0) {
      out.push(card("The cell", [
        "The object sits on a turntable; the arm holds a depth camera. The scan starts knowing nothing about the object's shape.",
        "<b>Capture</b> takes the first picture from where the camera is now.",
      ], "cell"));
      return out;
    }
    const v = st.voxels || {};
    out.push(card(`What the ${n === 1 ? "first picture" : n + " pictures"} taught`, [
      `Space is cut into small cubes (voxels). ${occ} (${v.occupied || 0}): a surface was seen there. ` +
      `<i>empty</i>: the camera saw through it. <i>unknown</i> (${v.unknown || 0}): never seen. ` +
      `${fro} (${v.frontier || 0}): unknown cubes next to empty ones — where new surface may hide.`,
    ], "voxels"));
    if (n >= 2) {
      const last = (st.views || [])[n - 1] || {};
      out.push(card(`ICP at view ${n}`, [
        last.icp_rejected
          ? `ICP tried to align the new picture to the earlier ones and its check did not pass (${P.esc(last.icp_rejected)}), so the camera's ` +
            "reported pose was kept. With a simulated cell that reports exact poses this changes nothing; on a real cell, " +
            "many rejections in a row mean the poses drift."
          : "ICP aligned the new picture to the points of the earlier ones (it corrects small errors of the arm's reported pose); " +
            "the check passed, so the correction was applied. The cloud layer shows the points of every view together.",
      ], "icp"));
    }
    if (st.state === "planning") {
      out.push(card("Planning", ["The planner groups the voxels into ellipsoids and scores every candidate view…"], "ellipsoids"));
      return out;
    }
    const plan = st.pending_plan;
    if (plan) {
      out.push(card("Ellipsoids", [
        `Each kind of voxel is summarised by a few ellipsoids (a Gaussian mixture; BIC chooses how many): ${fro} ellipsoids ` +
        `mark what is still to be seen, ${occ} ellipsoids what is already known.`,
      ], "ellipsoids"));
      const locked = P.Table.items.filter((c) => !c.eligible && /sector/.test(c.reason || "")).length;
      out.push(card("Sectors", [
        `The hemisphere of views is cut by longitude into sectors. A view comes from a sector not scanned yet, so the ` +
        `scan goes round the object before it looks again from one side${locked ? ` (${locked} candidates wait in scanned sectors: grey)` : ""}.`,
      ], "sectors"));
      const items = P.Table.items.filter((c) => c.eligible).sort((a, b) => b.score - a.score);
      const best = items[0], second = items[1];
      if (best) {
        const lacked = !second ? "" : second.frontier < best.frontier
          ? `the runner-up #${second.index} (F ${P.num(second.score, 0)}) would see less ${fro} (${P.num(second.frontier, 0)} vs ${P.num(best.frontier, 0)})`
          : `the runner-up #${second.index} (F ${P.num(second.score, 0)}) would see more ${occ} surface again (${P.num(second.occupied, 0)} vs ${P.num(best.occupied, 0)})`;
        out.push(card(`Why view #${best.index} won`, [
          `Each candidate (a sphere) projects the ellipsoids into its picture: F = ${fro} − ${occ} area, nearer ones counting more. ` +
          `The highest F sees the most unknown and the least known: #${best.index} has F = ${P.num(best.frontier, 0)} − ${P.num(best.occupied, 0)} = ${P.num(best.score, 0)}` +
          `${lacked ? "; " + lacked : ""}. F is often negative: only the order matters.`,
          "The planner's choice is the orange camera frustum (★ in the table); <b>Approve</b> moves the arm there.",
        ], "score"));
      }
    }
    return out;
  }

  function render() {
    const shown = on();
    $("guided-toggle").checked = shown;
    const box = $("guide");
    box.hidden = !shown || !S.status;
    if (box.hidden) return;
    const cards = steps().reverse(); // the newest step first, the earlier ones below it
    $("guide-title").textContent = cards.length ? cards[0].title : "";
    $("guide-body").innerHTML = cards.map((c, i) =>
      `<div class="guide-step${i ? " earlier" : ""}" data-step="${c.show}">` + (i ? `<b>${P.esc(c.title)}</b>` : "") + c.html +
      `<button class="show-me small" data-show="${c.show}" title="set the 3D view's layers to show this">Show in 3D</button></div>`).join("");
    for (const b of box.querySelectorAll("button.show-me")) b.addEventListener("click", () => show(b.dataset.show));
  }

  async function show(what) {
    const want = LAYERS[what];
    if (!want || !S.viewer || !S.layers) return;
    const known = Object.fromEntries(Object.entries(want).filter(([k]) => k in S.layers));
    try {
      S.layers = await api("PUT", `/api/scene/${S.viewer}/layers`, known);
      sessionStorage.setItem(layerKey(), JSON.stringify(S.layers));
      P.renderLayers(S.layers, toggleLayer);
    } catch (e) { showError(e.message); }
  }

  return { render, show, on };
})();

// Compare: sessions on the same object as this one, ticked in a list (this one ticked).
function openCompareDialog() {
  const here = S.sessions.find((s) => s.id === S.session);
  const same = S.sessions.filter((s) => !here || s.model === here.model);
  $("compare-list").innerHTML = same.length ? same.map((s) =>
    `<label><input type="checkbox" value="${P.esc(s.id)}"${s.id === S.session ? " checked" : ""}> ${P.esc(s.id)} · ` +
    `${P.esc(s.planner || "projection")} · ${s.iteration} views · ${s.coverage === null ? "–" : (100 * s.coverage).toFixed(1) + " %"}</label>`).join("")
    : '<p class="small muted">No sessions yet.</p>';
  $("compare-dialog").hidden = false;
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
  $("tl-loading").textContent = view === null ? "" : `loading view ${view}…`;
  try {
    await showViewNow(view);
  } finally {
    $("tl-loading").textContent = "";
  }
}

async function showViewNow(view) {
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
  // the Scan box speaks of then: no state, termination or notice of now
  $("state").textContent = `view ${step.view} (past)`;
  $("terminated").hidden = true;
  showNotice("");
  $("iteration").textContent = step.view;
  $("coverage").textContent = step.coverage !== null ? (100 * step.coverage).toFixed(1) + " %" : "–";
  $("points").textContent = step.move_frames ? `${step.points} (${step.move_frames} move frames)` : step.points;
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
    document.body.classList.add("comparing");
    $("health").textContent = "compare";
    await showCompare(compare.split(",").filter(Boolean));
  } else if (S.session) {
    document.body.classList.add("has-session");
    // a short window: the 3D view gets the height, the charts are one click away (7 · Charts)
    if (window.innerHeight < 800) $("charts-box").open = false;
    document.title = `${S.session} · NBV workbench`;
    $("export-ply").href = withToken(`/api/sessions/${S.session}/cloud.ply`);
    $("export-json").href = withToken(`/api/sessions/${S.session}/export`);
    for (const fmt of SURFACE_FORMATS) {
      $(`export-surface-${fmt}`).href = withToken(`/api/sessions/${S.session}/surface.ply?format=${fmt}`);
    }
    $("tl-recording").href = withToken(`/api/sessions/${S.session}/recording`);
    $("export-bag").href = withToken(`/api/sessions/${S.session}/export.mcap`);
    connectEvents(500);
    await openViewer();
    if (QUERY.get("demo")) runDemo();
  } else {
    document.body.classList.add("first-screen"); // no empty panels: the 3D view of the cell beside the welcome
    $("picker").hidden = false;
    $("legend").hidden = true;
    $("health").textContent = "choose a session";
    $("create-box").open = true;
    openPreview();
  }
  Guide.render();
  updateButtons();
}

init();
