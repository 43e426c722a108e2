// The class board (/board: create a class; /board/ID: watch its seats). Reads GET /api/classes/ID every
// POLL_MS (reading wakes no seat); pictures reload when a seat's view count changes.
"use strict";

const QUERY = new URLSearchParams(location.search);
const TOKEN = QUERY.get("token");
const POLL_MS = 2000;
const CLASS_ID = location.pathname.split("/")[2] || "";
const $ = (id) => document.getElementById(id);
const shown = {}; // seat number -> the view count its picture shows

function withToken(url) {
  if (!TOKEN) return url;
  return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(TOKEN);
}

async function api(method, path, body) {
  const headers = {};
  if (TOKEN) headers.Authorization = "Bearer " + TOKEN;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  const data = r.status === 204 ? null : await r.json().catch(() => null);
  if (!r.ok) {
    const detail = data && data.detail;
    throw new Error(typeof detail === "string" ? detail : `${method} ${path}: ${r.status}`);
  }
  return data;
}

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") node.className = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c);
  return node;
}

// ------------------------------------------------------------------ a new class

async function showCreate() {
  $("new-class").hidden = false;
  $("status").textContent = "";
  const [models, planners, classes] = await Promise.all([
    api("GET", "/api/models"), api("GET", "/api/planners"), api("GET", "/api/classes"),
  ]);
  for (const m of models) $("models").append(el("option", { value: m.name }, m.name));
  $("models").value = models[0] ? models[0].name : "";
  for (const p of planners) $("planner").append(el("option", { value: p }, p));
  for (const c of classes) {
    const link = el("a", { href: withToken(`/board/${c.id}`) }, `${c.code}`);
    $("class-list").append(el("li", {}, link, ` · ${c.seats.length} seats · ${c.models.join(", ")}`));
  }
  if (!classes.length) $("class-list").append(el("li", { class: "muted" }, "none yet"));
  $("create-form").addEventListener("submit", async (e) => {
    e.preventDefault();
    const button = e.submitter || document.querySelector("#create-form button");
    const chosen = [...$("models").selectedOptions].map((o) => o.value);
    const body = {
      seats: Number($("seats").value),
      model: chosen.length > 1 ? chosen : chosen[0] || null,
      planner: $("planner").value,
      guided: $("guided").checked,
    };
    button.disabled = true;
    $("create-error").textContent = `creating ${body.seats} sessions…`;
    try {
      const made = await api("POST", "/api/classes", body);
      location.href = withToken(`/board/${made.id}`);
    } catch (err) {
      $("create-error").textContent = err.message;
      button.disabled = false;
    }
  });
}

// ------------------------------------------------------------------ the board

function joinUrl(code) {
  return `${location.origin}/join/${code}` + (TOKEN ? `?token=${encodeURIComponent(TOKEN)}` : "");
}

function seatCard(s) {
  const pct = s.coverage == null ? "–" : `${(100 * s.coverage).toFixed(0)} %`;
  let pic;
  if (s.picture) {
    pic = el("img", { class: "pic", alt: `seat ${s.seat}'s scene`, "data-views": String(s.views) });
    pic.src = withToken(`/api/classes/${CLASS_ID}/seats/${s.seat}/picture.png?v=${s.views}`);
  } else {
    pic = el("div", { class: "pic empty" }, s.asleep ? "asleep" : "no view yet");
  }
  const project = el("button", { title: "show this seat's 3D view on the projector (read-only)", onclick: () => openProjector(s) }, "Project");
  const reset = el("button", { title: "delete this seat's session and start a new one", onclick: () => resetSeat(s) }, "Reset");
  return el("div", { class: "seat" + (s.joined ? "" : " free"), "data-seat": String(s.seat), "data-testid": `seat-${s.seat}` },
    el("div", { class: "top" },
      el("span", { class: "num" }, `${s.seat}`),
      el("span", { class: "muted" }, s.model),
      el("span", { class: `state ${s.state}`, "data-testid": `seat-${s.seat}-state` }, s.state)),
    pic,
    el("div", { class: "nums" },
      el("span", {}, `views ${s.views}`), el("span", {}, `coverage ${pct}`)),
    el("div", { class: "nums muted" }, el("span", {}, s.joined ? "joined" : "free seat"), el("span", {}, s.resets ? `reset ×${s.resets}` : "")),
    el("div", { class: "actions" }, project, reset));
}

function render(board) {
  $("class-title").textContent = `· ${board.seats.length} seats · ${board.models.join(", ")} · ${board.planner}` + (board.guided ? " · guided" : "");
  $("code").textContent = board.code;
  $("join-url").textContent = joinUrl(board.code).replace(/\?token=.*/, "");
  const loopback = ["127.0.0.1", "localhost", "[::1]"].includes(location.hostname);
  $("reach").hidden = !loopback;
  $("reach").textContent = "This page is open on a loopback address: students' devices cannot reach it. Start the server on the lab network (nbv serve --host 0.0.0.0 --token …) and open the board at its address.";
  $("pause").textContent = board.paused ? "Resume all" : "Pause all";
  $("pause").classList.toggle("paused", board.paused);
  const joined = board.seats.filter((s) => s.joined).length;
  const asleep = board.seats.filter((s) => s.asleep).length;
  $("summary").textContent = `${joined}/${board.seats.length} joined · ${board.live} live, ${asleep} asleep · live limit ${board.live_limit}`;
  const grid = $("seats-grid");
  for (const s of board.seats) {
    const old = grid.querySelector(`[data-seat="${s.seat}"]`);
    const card = seatCard(s);
    const oldPic = old && old.querySelector("img.pic");
    if (oldPic && s.picture && shown[s.seat] === s.views) card.querySelector(".pic").replaceWith(oldPic); // no flicker
    shown[s.seat] = s.views;
    if (old) old.replaceWith(card); else grid.append(card);
  }
  $("status").textContent = board.paused ? "paused: every seat refuses changes" : `updated ${new Date().toLocaleTimeString()}`;
}

async function poll() {
  try {
    render(await api("GET", `/api/classes/${CLASS_ID}`));
  } catch (err) {
    $("status").textContent = err.message;
  }
}

async function resetSeat(s) {
  if (!confirm(`Reset seat ${s.seat}? Its scan is deleted and it starts again (its student reloads the page).`)) return;
  try {
    await api("POST", `/api/classes/${CLASS_ID}/seats/${s.seat}/reset`);
    delete shown[s.seat];
    await poll();
  } catch (err) {
    $("status").textContent = err.message;
  }
}

async function openProjector(s) {
  try {
    const v = await api("POST", `/api/classes/${CLASS_ID}/seats/${s.seat}/watch`);
    $("projector-title").textContent = `Seat ${s.seat} · ${s.model}`;
    $("projector-info").textContent = `views ${s.views}` + (s.coverage == null ? "" : ` · coverage ${(100 * s.coverage).toFixed(0)} %`);
    $("projector-view").src = v.url;
    $("projector").hidden = false;
  } catch (err) {
    $("status").textContent = err.message;
  }
}

async function boot() {
  if (!CLASS_ID) {
    await showCreate();
    return;
  }
  $("board").hidden = false;
  $("qr").src = withToken(`/api/classes/${CLASS_ID}/qr.svg`);
  $("pause").addEventListener("click", async () => {
    const paused = $("pause").classList.contains("paused");
    try {
      render(await api("POST", `/api/classes/${CLASS_ID}/pause`, { paused: !paused }));
    } catch (err) {
      $("status").textContent = err.message;
    }
  });
  $("projector-close").addEventListener("click", () => {
    $("projector").hidden = true;
    $("projector-view").src = "about:blank";
  });
  await poll();
  setInterval(poll, POLL_MS);
}

boot().catch((err) => { $("status").textContent = err.message; });
