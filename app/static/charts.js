// Tiny inline-SVG line charts (no library, nothing fetched from the internet).
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";

function svgEl(tag, attrs, parent) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs || {})) el.setAttribute(k, v);
  if (parent) parent.appendChild(el);
  return el;
}

function niceTicks(lo, hi, n) {
  if (!isFinite(lo) || !isFinite(hi)) return [];
  if (hi === lo) { hi = lo + 1; }
  const raw = (hi - lo) / Math.max(1, n);
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) || raw;
  const ticks = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + 1e-9 * step; t += step) ticks.push(+t.toPrecision(12));
  return ticks;
}

function fmt(v) {
  const a = Math.abs(v);
  if (a === 0) return "0";
  if (a >= 10000 || a < 0.01) return v.toExponential(1);
  if (a >= 100) return v.toFixed(0);
  return +v.toPrecision(3) + "";
}

/**
 * Draw series [{points: [[x, y], ...], color, label, marker: [x, y] | null, hover: [text per point]}] into an <svg>.
 * opts: {yMin, yMax, xInteger, xLabel, yLabel, hline: y of a dashed reference line (null: none),
 *        cursor: x of the timeline's cursor, a vertical line (null: none)}
 * Every point has a hover text (its series' hover, else "x, y").
 */
function lineChart(svg, series, opts) {
  opts = opts || {};
  while (svg.firstChild) svg.removeChild(svg.firstChild);
  const W = svg.clientWidth || 300, H = svg.clientHeight || 150;
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const m = { l: opts.yLabel ? 58 : 46, r: 8, t: 6, b: opts.xLabel ? 28 : 18 };
  const pts = series.flatMap((s) => s.points).filter((p) => p[1] !== null && isFinite(p[1]));
  if (pts.length === 0) {
    svgEl("text", { x: W / 2, y: H / 2, "text-anchor": "middle" }, svg).textContent = "no data yet";
    return;
  }
  const xs = pts.map((p) => p[0]);
  let ys = pts.map((p) => p[1]);
  let x0 = Math.min(...xs), x1 = Math.max(...xs);
  if (opts.hline !== undefined && opts.hline !== null) ys = ys.concat([opts.hline]);
  let y0 = opts.yMin !== undefined ? opts.yMin : Math.min(...ys);
  let y1 = opts.yMax !== undefined ? opts.yMax : Math.max(...ys);
  if (x1 === x0) { x0 -= 1; x1 += 1; }
  if (y1 === y0) { const d = Math.abs(y0) * 0.1 || 1; y0 -= d; y1 += d; }
  const X = (x) => m.l + ((x - x0) / (x1 - x0)) * (W - m.l - m.r);
  const Y = (y) => H - m.b - ((y - y0) / (y1 - y0)) * (H - m.t - m.b);
  // as many ticks as fit without their labels touching (18 px a row, 40 px a column)
  const yTicks = Math.max(1, Math.min(4, Math.floor((H - m.t - m.b) / 18)));
  const xTicks = Math.max(2, Math.min(6, Math.floor((W - m.l - m.r) / 40)));
  for (const t of niceTicks(y0, y1, yTicks)) {
    svgEl("line", { x1: m.l, x2: W - m.r, y1: Y(t), y2: Y(t), stroke: "#eceef2" }, svg);
    svgEl("text", { x: m.l - 4, y: Y(t) + 3, "text-anchor": "end" }, svg).textContent = fmt(t);
  }
  let xt = niceTicks(x0, x1, xTicks);
  if (opts.xInteger) xt = xt.filter((t) => Number.isInteger(t));
  for (const t of xt) {
    svgEl("text", { x: X(t), y: H - m.b + 12, "text-anchor": "middle" }, svg).textContent = fmt(t);
  }
  if (opts.xLabel) svgEl("text", { x: (m.l + W - m.r) / 2, y: H - 3, "text-anchor": "middle", class: "axis" }, svg).textContent = opts.xLabel;
  if (opts.yLabel) svgEl("text", { x: 10, y: (m.t + H - m.b) / 2, "text-anchor": "middle", class: "axis", transform: `rotate(-90 10 ${(m.t + H - m.b) / 2})` }, svg).textContent = opts.yLabel;
  if (opts.hline !== undefined && opts.hline !== null) {
    svgEl("line", { x1: m.l, x2: W - m.r, y1: Y(opts.hline), y2: Y(opts.hline), stroke: "#15894a", "stroke-dasharray": "5 4", class: "ceiling" }, svg);
  }
  if (opts.cursor !== undefined && opts.cursor !== null) {
    svgEl("line", { x1: X(opts.cursor), x2: X(opts.cursor), y1: m.t, y2: H - m.b, stroke: "#d0312d", "stroke-width": 1.5,
      "stroke-dasharray": "3 3", class: "cursor", "data-x": opts.cursor }, svg);
  }
  svgEl("line", { x1: m.l, x2: m.l, y1: m.t, y2: H - m.b, stroke: "#b9bfca" }, svg);
  svgEl("line", { x1: m.l, x2: W - m.r, y1: H - m.b, y2: H - m.b, stroke: "#b9bfca" }, svg);
  let legendY = m.t + 8;
  for (const s of series) {
    const good = s.points.filter((p) => p[1] !== null && isFinite(p[1]));
    if (good.length === 0) continue;
    const d = good.map((p, i) => `${i ? "L" : "M"}${X(p[0]).toFixed(1)},${Y(p[1]).toFixed(1)}`).join("");
    svgEl("path", { d, fill: "none", stroke: s.color, "stroke-width": 1.8 }, svg);
    s.points.forEach((p, i) => {
      if (p[1] === null || !isFinite(p[1])) return;
      const dot = svgEl("circle", { cx: X(p[0]), cy: Y(p[1]), r: 2.6, fill: s.color, "data-x": p[0], "data-series": s.label || "" }, svg);
      svgEl("title", {}, dot).textContent = s.hover ? s.hover[i] : `${fmt(p[0])}, ${fmt(p[1])}`;
    });
    if (s.marker) {
      svgEl("circle", { cx: X(s.marker[0]), cy: Y(s.marker[1]), r: 5, fill: "none", stroke: s.color, "stroke-width": 2 }, svg);
    }
    if (s.label) {
      const t = svgEl("text", { x: W - m.r - 2, y: legendY, "text-anchor": "end" }, svg);
      t.textContent = s.label;
      t.setAttribute("style", `fill:${s.color}`);
      legendY += 11;
    }
  }
}

window.lineChart = lineChart;
