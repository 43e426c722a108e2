// Calibrate mode: /?calibrate=new opens a calibration of a cell, /?calibrate=ID shows one.
// The 3D view shows the calibration (plate, target, each pose's camera, the arm and the previewed move); the panels
// list the poses to preview, approve or skip, each capture's residual, the estimate with its uncertainty, and
// "write to cell file". Uses app.js's api(), pageUrl() and showError() (globals of the page's scripts).
"use strict";

window.Calibrate = (() => {
  const C = { id: null, status: null, running: false, stop: false, viewer: null };
  const $ = (id) => document.getElementById(id);
  const fmt = (v, d = 2) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));
  const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);

  function panel() {
    const side = $("side");
    for (const el of side.querySelectorAll("details.panel")) el.hidden = true;
    for (const el of $("right").children) el.hidden = true;
    $("picker").hidden = true;
    $("legend").hidden = true;
    const box = document.createElement("section");
    box.id = "calibrate";
    box.className = "panel";
    box.dataset.testid = "calibrate";
    box.innerHTML = `
      <h2>Calibrate a cell</h2>
      <p class="small muted">Put the sphere target on the plate (docs/hardware.md, “Commissioning a cell”), preview
        each pose, approve it (the arm moves, the camera captures, the spheres are fitted) or skip it.</p>
      <div id="cal-new">
        <label>Cell <select id="cal-kind" data-testid="cal-kind">
          <option value="sim">simulated (calibration error drawn)</option>
          <option value="hardware">this server's cell file</option>
          <option value="dry">this server's cell file, dry run</option></select></label>
        <label title="simulated cell: the calibration error model">Calibration error
          <select id="cal-error"><option>poor</option><option>typical</option><option>good</option></select></label>
        <div class="grid params">
          <label>seed <input id="cal-seed" type="number" min="0" value="0"></label>
          <label title="views per plate angle (1..6)">views <input id="cal-views" type="number" min="1" max="6" value="6"></label>
        </div>
        <label title="plate angles of the poses, degrees">plate angles <input id="cal-angles" value="0,60,120,180,-120,-60"></label>
        <button id="cal-start" class="primary" data-testid="cal-start">Start calibration</button>
      </div>
      <div id="cal-run" hidden>
        <div id="cal-info" class="small muted" data-testid="cal-info"></div>
        <div class="buttons">
          <button id="cal-approve-all" class="go" data-testid="cal-approve-all" title="approve every pending pose in turn">Approve all</button>
          <button id="cal-stop" data-testid="cal-stop" title="stop after the current pose" disabled>Stop</button>
          <button id="cal-close" class="danger" title="close this calibration and release the cell">Close</button>
        </div>
        <h2>Estimate</h2>
        <div id="cal-estimate" data-testid="cal-estimate" class="small"></div>
        <button id="cal-write" data-testid="cal-write" disabled title="write the hand-eye transform and the axis into the cell file (the old file is kept as a backup)">Write to cell file</button>
        <div id="cal-written" class="small" data-testid="cal-written"></div>
      </div>`;
    side.appendChild(box);
    box.querySelector("h2").after($("error")); // errors show above the form (the status panel is hidden)
    if ($("charts-box")) $("charts-box").hidden = true;
    const right = document.createElement("section");
    right.id = "cal-poses-box";
    right.innerHTML = `<h2>Poses</h2>
      <table id="cal-poses" data-testid="cal-poses"><thead><tr><th>#</th><th title="plate angle, azimuth offset, elevation, roll (degrees)">pose</th>
        <th title="hover a status: the spheres fitted and their fit RMS, or why the pose was skipped">status</th><th title="RMS of this capture's sphere centres under the estimate, mm">resid. mm</th><th></th></tr></thead><tbody></tbody></table>`;
    $("right").appendChild(right);
    $("cal-start").onclick = start;
    $("cal-approve-all").onclick = approveAll;
    $("cal-stop").onclick = () => { C.stop = true; };
    $("cal-write").onclick = writeCell;
    $("cal-close").onclick = closeRun;
    $("cal-poses").onclick = (e) => {
      const b = e.target.closest("button[data-act]");
      if (b) act(b.dataset.act, Number(b.dataset.index));
    };
  }

  async function start() {
    const kind = $("cal-kind").value;
    const body = {
      kind: kind === "dry" ? "hardware" : kind,
      seed: Number($("cal-seed").value) || 0,
      views: Number($("cal-views").value) || 6,
      plate_angles_deg: $("cal-angles").value.split(",").map(Number),
    };
    if (kind === "dry") body.dry_run = true;
    if (kind === "sim") body.calibration = $("cal-error").value;
    $("cal-start").disabled = true;
    $("health").textContent = "opening the cell…";
    try {
      const st = await api("POST", "/api/calibrations", body);
      history.replaceState(null, "", pageUrl({ calibrate: st.id }));
      await show(st);
    } catch (e) {
      showError("calibration: " + e.message);
      $("health").textContent = "calibrate";
    } finally {
      $("cal-start").disabled = false;
    }
  }

  async function show(st) {
    C.id = st.id;
    $("cal-new").hidden = true;
    $("cal-run").hidden = false;
    document.title = `${st.id} · calibrate · NBV workbench`;
    render(st);
    try {
      const v = await api("POST", `/api/calibrations/${st.id}/viewer`);
      C.viewer = v.viewer; // this tab's viewer id (/api/scene/ID/camera moves its camera)
      $("viewer").hidden = false;
      $("viewer").src = v.url;
    } catch (e) { showError("3D viewer unavailable: " + e.message); }
  }

  function render(st) {
    C.status = st;
    const n = st.counts;
    const src = st.source.kind === "sim" ? `simulated, calibration ${st.source.calibration}, seed ${st.source.seed}`
      : st.source.dry_run ? "dry run of the cell file" : `cell file ${st.source.cell}`;
    $("health").textContent = st.busy ? st.busy + "…" : "calibrate";
    $("cal-info").textContent = `${st.id} · ${src} · target ${st.target.spheres} × ${fmt(st.target.diameter_mm, 0)} mm spheres · ` +
      `${n.captured} captured, ${n.skipped} skipped, ${n.pending} pending of ${st.poses.length}`;
    const rows = st.poses.map((p) => {
      const sel = st.selected === p.index ? " class=\"selected\"" : "";
      const fits = p.fit_rms_mm.map((r) => (r === null ? "–" : fmt(r, 2))).join(", ");
      const tip = p.reason || (p.status === "captured" ? `${p.spheres} spheres fitted, fit rms [${fits}] mm` : "");
      const why = tip ? ` title="${esc(tip)}"` : "";
      const buttons = p.status === "captured" ? `<button data-act="skip" data-index="${p.index}" title="drop this capture">drop</button>`
        : `<button data-act="preview" data-index="${p.index}">preview</button><button data-act="approve" data-index="${p.index}" class="go">approve</button>` +
          (p.status === "pending" ? `<button data-act="skip" data-index="${p.index}">skip</button>` : "");
      return `<tr data-index="${p.index}" data-status="${p.status}"${sel}><td>${p.index}</td><td class="small">${esc(p.label)}</td>` +
        `<td class="st-${p.status}"${why}>${p.status}${p.reason ? " ⓘ" : ""}</td>` +
        `<td data-testid="residual">${fmt(p.residual_mm, 3)}</td><td class="acts">${buttons}</td></tr>`;
    });
    $("cal-poses").querySelector("tbody").innerHTML = rows.join("");
    const e = st.estimate;
    if (!e) {
      $("cal-estimate").innerHTML = `<span class="muted">${esc(st.note)}</span>`;
    } else {
      const t = e.hand_eye_translation.map((v) => fmt(v * 1000, 2)).join(", ");
      const r = e.hand_eye_rotation_deg.map((v) => fmt(v, 3)).join(", ");
      const p = e.axis_point.slice(0, 2).map((v) => fmt(v * 1000, 2)).join(", ");
      let truth = "";
      if (st.truth) {
        truth = `<tr><th>error vs truth</th><td>hand-eye ${fmt(st.truth.hand_eye_error_mm, 3)} mm, ${fmt(st.truth.hand_eye_error_deg, 3)}°;
          axis ${fmt(st.truth.axis_error_mm, 3)} mm, ${fmt(st.truth.axis_error_deg, 3)}° (nominal: ${fmt(st.truth.nominal_error.hand_eye_mm, 2)} mm,
          ${fmt(st.truth.nominal_error.hand_eye_deg, 2)}°; ${fmt(st.truth.nominal_error.axis_mm, 2)} mm, ${fmt(st.truth.nominal_error.axis_deg, 2)}°)</td></tr>`;
      }
      $("cal-estimate").innerHTML = `<table class="kv">
        <tr><th>hand-eye translation</th><td>[${t}] mm ± ${fmt(e.hand_eye_std_mm, 3)} mm (95 %: ${fmt(e.hand_eye_bound95_mm, 3)})</td></tr>
        <tr><th>hand-eye rotation (xyz)</th><td>[${r}]° ± ${fmt(e.hand_eye_std_deg, 4)}° (95 %: ${fmt(e.hand_eye_bound95_deg, 4)})</td></tr>
        <tr><th>turntable axis</th><td>through [${p}] mm ± ${fmt(e.axis_std_mm, 3)} mm (95 %: ${fmt(e.axis_bound95_mm, 3)}),
          tilt ${fmt(e.axis_tilt_deg, 3)}° ± ${fmt(e.axis_std_deg, 4)}° (95 %: ${fmt(e.axis_bound95_deg, 4)})</td></tr>
        <tr><th>residual</th><td>${fmt(e.rms_mm, 3)} mm rms over ${Object.keys(e.residuals_mm).length} captures</td></tr>${truth}</table>
        <div class="muted">± one sigma; 95 %: the bound of the error norm · ${esc(st.note)}</div>`;
    }
    $("cal-write").disabled = !e || !st.writable || !!st.busy || C.running;
    $("cal-write").title = st.writable ? "write into the cell file (the old file is kept as a backup)"
      : "nothing to write: a simulated cell or a dry run measures the simulator";
    $("cal-written").textContent = st.written ? `written to ${st.written.path}; the old file kept as ${st.written.backup}` : "";
    $("cal-approve-all").disabled = C.running || n.pending === 0;
    $("cal-stop").disabled = !C.running;
  }

  async function act(what, index) {
    try {
      if (what === "preview") {
        const p = await api("POST", `/api/calibrations/${C.id}/poses/${index}/preview`);
        const st = await api("GET", `/api/calibrations/${C.id}`);
        render(st);
        if (!p.reachable) showError(`pose ${index}: unreachable (${p.reason}); approving it skips it`);
        else $("health").textContent = `pose ${index}: plate ${fmt(p.plate_angle_deg, 0)}°, move ${fmt(p.duration, 1)} s`;
      } else {
        render(await api("POST", `/api/calibrations/${C.id}/poses/${index}/${what}`));
      }
    } catch (e) {
      showError(`pose ${index}: ${e.message}`);
      try { render(await api("GET", `/api/calibrations/${C.id}`)); } catch (_) { /* keep the last status */ }
    }
  }

  async function approveAll() {
    C.running = true;
    C.stop = false;
    render(C.status);
    try {
      for (const p of C.status.poses) {
        if (C.stop) break;
        if (C.status.poses[p.index].status !== "pending") continue;
        await act("approve", p.index);
      }
    } finally {
      C.running = false;
      render(C.status);
    }
  }

  async function writeCell() {
    try {
      const w = await api("POST", `/api/calibrations/${C.id}/write`);
      render(await api("GET", `/api/calibrations/${C.id}`));
      $("health").textContent = `written (backup ${w.backup})`;
    } catch (e) { showError("write: " + e.message); }
  }

  async function closeRun() {
    try { await api("DELETE", `/api/calibrations/${C.id}`); } catch (e) { showError(e.message); return; }
    location.href = pageUrl({});
  }

  // app.js's init() calls this for /?calibrate=…
  async function open(id) {
    panel();
    if (!id || id === "new") {
      $("viewer").hidden = true;
      $("health").textContent = "calibrate";
      return;
    }
    try { await show(await api("GET", `/api/calibrations/${id}`)); } catch (e) {
      showError(`calibration ${id}: ${e.message}`);
      $("viewer").hidden = true;
    }
  }

  return { open, state: C };
})();
