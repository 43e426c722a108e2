// The Fit panel: debugging the ellipsoid fit this tab's viewer shows (GET /api/scene/{viewer}/fit).
// - one row per ellipsoid, worst-filled first per kind, a warning for those under the fill threshold;
// - one ellipsoid at a time: a row, an inspector row or a click on an ellipsoid in 3D focuses it (the clusters
//   layer dims the rest); the Fit panel and the inspector mark the focused row;
// - the fit at another T: click a T on the BIC chart (that kind refitted in the session's worker; the plan stays),
//   the T shown is ringed on the chart, "back to the plan's fit" undoes it.
// app.js calls FitPanel.load() when the plan or the selection changed, FitPanel.markChart() after the charts,
// FitPanel.onViewer(m) for a pushed {"type": "viewer"} message of this tab's viewer.
"use strict";

const FitPanel = (() => {
  const F = { info: null, busy: false };
  const KIND_TEXT = { occupied: "occupied", frontier: "frontier" };

  async function load() {
    // a fit exists once a plan was made (the pending one, or the last one's in the metrics): before, no request
    // (it would answer 409, a console error in every new session)
    const planned = S.planId || (S.metrics && S.metrics.fits && S.metrics.fits.length);
    if (!S.viewer || !planned) { F.info = null; render(); return; }
    try {
      F.info = await api("GET", `/api/scene/${S.viewer}/fit`);
    } catch (e) {
      F.info = null; // no plan yet, or the viewer not connected
    }
    render();
  }

  function pct(v) { return v === null || v === undefined ? "–" : (100 * v).toFixed(v < 0.1 ? 1 : 0) + " %"; }

  function render() {
    const box = $("fit-box");
    if (!box) return;
    const info = F.info;
    const tbody = $("fit").querySelector("tbody");
    tbody.innerHTML = "";
    $("fit-kinds").innerHTML = "";
    $("fit-warning").hidden = true;
    $("fit-label").textContent = info && info.focus ? `focus ${info.focus}` : "";
    if (!info) { $("fit-kinds").textContent = "no plan yet"; markInspector(); markChart(); return; }
    for (const k of info.kinds) {
      const line = document.createElement("div");
      line.className = "fit-kind";
      line.dataset.kind = k.kind;
      const what = k.refit ? `fit at T=${k.t_shown} (BIC ${P.num(k.bic, 0)}), the plan's T=${k.t_plan}` : `the plan's fit, T=${k.t_plan}`;
      line.innerHTML = `<b style="color:${KIND_COLORS[k.kind]}">${KIND_TEXT[k.kind]}</b>: ${k.ellipsoids} ellipsoids, ${k.voxels} voxels · ${P.esc(what)}`;
      if (k.refit) {
        const back = document.createElement("button");
        back.id = `fit-back-${k.kind}`;
        back.className = "small";
        back.textContent = "back to the plan's fit";
        back.addEventListener("click", () => refit(k.kind, null));
        line.appendChild(back);
      }
      $("fit-kinds").appendChild(line);
    }
    const low = info.rows.filter((r) => r.low_fill);
    if (low.length) {
      const w = $("fit-warning");
      w.hidden = false;
      w.textContent = `${low.length} ellipsoid${low.length > 1 ? "s" : ""} cover${low.length > 1 ? "" : "s"} over ` +
        `${Math.round(1 / info.low_fill_threshold)}× the volume of ${low.length > 1 ? "their" : "its"} voxels ` +
        `(fill < ${pct(info.low_fill_threshold)}): ${low.map((r) => r.label).join(", ")}`;
    }
    for (const r of info.rows) {
      const tr = document.createElement("tr");
      tr.dataset.label = r.label;
      tr.dataset.kind = r.kind;
      tr.className = (r.label === info.focus ? "focused " : "") + (r.low_fill ? "low-fill" : "");
      if (r.low_fill) tr.title = `fill ${pct(r.fill)}: the ellipsoid covers ${(1 / r.fill).toFixed(0)}× its voxels' volume`;
      tr.innerHTML = `<td><i class="swatch" style="background:rgb(${r.color.join(",")})"></i>${P.esc(r.label)}${r.low_fill ? " ⚠" : ""}</td>` +
        `<td>${r.voxels}</td><td>${P.num(r.volume * 1e6, 1)}</td><td>${pct(r.fill)}</td>` +
        `<td>${P.num(r.weight, 3)}</td><td>${r.weighted === null ? "–" : P.num(r.weighted, 0)}</td>`;
      tr.addEventListener("click", () => focus(r.label === info.focus ? null : r.label));
      tbody.appendChild(tr);
    }
    markInspector();
    markChart();
  }

  // The inspector's breakdown rows name the ellipsoids too: mark the focused one, a click there focuses.
  function markInspector() {
    const focusLabel = F.info ? F.info.focus : null;
    for (const tr of $("breakdown").querySelectorAll("tbody tr")) {
      const label = tr.cells[0] ? tr.cells[0].textContent : "";
      tr.dataset.label = label;
      tr.classList.toggle("focused", label === focusLabel);
    }
  }

  // Ring the T each kind shows on the BIC chart when it is a refit; every point of it is clickable.
  function markChart() {
    const svg = $("chart-bic");
    if (!svg) return;
    for (const old of svg.querySelectorAll(".fit-picked")) old.remove();
    for (const dot of svg.querySelectorAll("circle[data-x][data-series]")) dot.classList.add("fit-t");
    if (!F.info) return;
    for (const k of F.info.kinds) {
      if (!k.refit) continue;
      const dot = svg.querySelector(`circle[data-series='${k.kind}'][data-x='${k.t_shown}']`);
      if (!dot) continue;
      svgEl("circle", { cx: dot.getAttribute("cx"), cy: dot.getAttribute("cy"), r: 7, fill: "none", stroke: KIND_COLORS[k.kind],
        "stroke-width": 2, "stroke-dasharray": "3 2", class: "fit-picked", "data-kind": k.kind, "data-t": k.t_shown }, svg);
    }
  }

  async function call(path, body) {
    if (F.busy || !S.viewer) return;
    F.busy = true;
    $("fit-busy").textContent = body.t !== undefined && body.t !== null ? `fitting ${body.kind} at T=${body.t}…` : "";
    try {
      F.info = await api("PUT", `/api/scene/${S.viewer}/fit${path}`, body);
      showError("");
    } catch (e) {
      showError(e.message);
    } finally {
      F.busy = false;
      $("fit-busy").textContent = "";
    }
    render();
  }

  async function focus(label) {
    if (label !== null && S.layers && !S.layers.clusters) await toggleLayer("clusters", true);
    return call("/focus", { label });
  }

  function refit(kind, t) { return call("", { kind, t }); }

  async function onViewer(m) {
    const info = F.info;
    const refits = info ? Object.fromEntries(info.kinds.filter((k) => k.refit).map((k) => [k.kind, k.t_shown])) : {};
    if (!info || m.focus !== info.focus || JSON.stringify(m.refits) !== JSON.stringify(refits)) await load();
  }

  function wire() {
    $("chart-bic").addEventListener("click", (e) => {
      const dot = e.target.closest("circle[data-x][data-series]");
      if (!dot || !(dot.dataset.series in KIND_TEXT)) return;
      refit(dot.dataset.series, Number(dot.dataset.x));
    });
    $("breakdown").querySelector("tbody").addEventListener("click", (e) => {
      const tr = e.target.closest("tr");
      if (!tr || !tr.dataset.label) return;
      focus(F.info && F.info.focus === tr.dataset.label ? null : tr.dataset.label);
    });
  }

  document.addEventListener("DOMContentLoaded", wire);
  return { load, render, markChart, markInspector, onViewer, focus, refit, state: F };
})();

window.FitPanel = FitPanel;
