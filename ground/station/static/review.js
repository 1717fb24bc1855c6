// The review queue of the live page: every hole, "for review" ones first, the current
// one large with its picture (the box is drawn in it), its "why" line and the marks.
//
// Keys (not while typing in a field): c = confirmed, x or r = rejected, v = visited,
// u = back to new, n / j / ArrowDown = next, p / k / ArrowUp = previous.
// A mark needs this browser's pairing (the operator's pairing link, checked by station.js;
// the station keeps it in an HttpOnly cookie the page's script never sees): the station
// records the mark under that pairing's operator. Other operators' marks arrive through
// the page's event stream (the page calls Review.render again).
"use strict";

const Review = (() => {
  const TIER_ORDER = { review: 0, announced: 1, confirmed: 2, rejected: 3 };
  const TIER_TEXT = { review: "for review", announced: "announced", confirmed: "confirmed", rejected: "rejected" };
  let queue = [];        // holes in queue order
  let current = null;    // id of the hole shown large
  let canMark = false;
  let last = null;       // the newest state document

  function esc(s) {
    return String(s).replace(/[&<>"']/g, c => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
  }
  // the hole's confidence for ordering: p_hole (hole level) when told, else the best
  // frame's detector score (a vehicle that sent the old STATUSTEXT form)
  const conf = h => (h.p_hole ?? h.score ?? 0);

  function order(holes) {
    return holes.slice().sort((a, b) =>
      (TIER_ORDER[a.tier] ?? 9) - (TIER_ORDER[b.tier] ?? 9) || conf(b) - conf(a) || a.id - b.id);
  }

  function byLine(h) {
    if (!h.marked_by) return "";
    const t = new Date(h.marked_by.t_unix_ns / 1e6).toLocaleTimeString();
    const p = h.marked_by.pairing ? ` (${esc(h.marked_by.pairing)})` : "";
    return `${esc(h.mark)} by ${esc(h.marked_by.operator)}${p} at ${t}`;
  }

  function facts(h) {
    const size = h.major_m != null && h.minor_m != null ? ` &middot; ${h.major_m.toFixed(2)} x ${h.minor_m.toFixed(2)} m` : "";
    const seen = h.sightings ? ` &middot; seen in ${h.sightings} frames` : "";
    const p = h.p_hole != null ? `p_hole ${h.p_hole.toFixed(2)}`
      : h.score != null ? `best frame's score ${h.score.toFixed(2)}` : "p_hole not told yet";
    return `${p}${size}${seen}`;
  }

  function buttons(h) {
    const dis = canMark ? "" : " disabled";
    const b = (m, label, key) =>
      `<button class="${h.mark === m ? "on" : ""}" data-id="${h.id}" data-mark="${m}" title="key ${key}"${dis}>${label}</button>`;
    return b("confirmed", "confirm", "c") + b("rejected", "reject", "x") + b("visited", "visited", "v")
      + (h.mark !== "new" ? b("new", "undo", "u") : "");
  }

  function detail(h) {
    if (!h) return `<p class="empty">no holes yet</p>`;
    const pic = h.picture
      ? `<img class="big" src="${h.picture}" alt="hole ${h.id}: best view, box drawn">`
      : `<div class="nopic big">picture on its way</div>`;
    return `<div class="current tier-${h.tier}" id="current" data-id="${h.id}" data-tier="${h.tier}">`
      + `<h2>hole ${h.id} <span class="badge tier-${h.tier}">${TIER_TEXT[h.tier] || esc(h.tier)}</span>`
      + ` <span class="conf">p ${conf(h).toFixed(2)}</span></h2>${pic}`
      + `<p class="why">${esc(h.why || "(no explanation yet)")}</p>`
      + `<p>${esc(h.summary)}</p><p class="by">${byLine(h)}</p>`
      + `<div class="marks">${buttons(h)}</div></div>`;
  }

  function row(h) {
    const pic = h.picture ? `<img src="${h.picture}" alt="hole ${h.id}">` : `<div class="nopic">picture<br>on its way</div>`;
    const sel = h.id === current ? " selected" : "";
    return `<div class="hole mark-${h.mark} tier-${h.tier}${sel}" id="hole-${h.id}" data-id="${h.id}" data-mark="${h.mark}" data-tier="${h.tier}">${pic}<div>`
      + `<h3>hole ${h.id} &middot; <span class="badge tier-${h.tier}">${TIER_TEXT[h.tier] || esc(h.tier)}</span></h3>`
      + `<p>${facts(h)}</p>`
      + `<p class="coord">${esc(h.mgrs || `${h.lat_deg.toFixed(7)}, ${h.lon_deg.toFixed(7)}`)}</p>`
      + `<p class="by">${byLine(h)}</p>`
      + `<div>${buttons(h)}</div></div></div>`;
  }

  function render(doc) {
    last = doc;
    canMark = !!doc.can_mark;
    queue = order(doc.holes);
    if (!queue.some(h => h.id === current)) current = queue.length ? queue[0].id : null;
    const h = queue.find(x => x.id === current) || null;
    document.getElementById("review").innerHTML = detail(h);
    document.getElementById("holes").innerHTML = queue.map(row).join("") || "";
    const nReview = queue.filter(x => x.tier === "review").length;
    document.getElementById("queue-head").textContent =
      `${queue.length} holes, ${nReview} for review` + (canMark ? "" : " (read-only: open your pairing link to mark)");
    document.body.dataset.canMark = canMark ? "yes" : "no";
    document.body.dataset.current = current === null ? "" : String(current);
  }

  function show() {  // re-draw from the state document already here
    if (!last) return;
    render(last);
    if (typeof window.draw === "function") window.draw();
  }

  function step(d) {
    if (!queue.length) return;
    const i = Math.max(0, queue.findIndex(h => h.id === current));
    current = queue[Math.min(queue.length - 1, Math.max(0, i + d))].id;
    show();
    const el = document.getElementById(`hole-${current}`);
    if (el && el.scrollIntoView) el.scrollIntoView({ block: "nearest" });
  }

  function select(id) { current = id; show(); }

  async function mark(id, m) {
    let r;
    try {
      r = await fetch(`/holes/${id}/mark`, {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ mark: m }),
      });
    } catch (e) {
      document.getElementById("queue-head").textContent = "mark not sent: the station did not answer";
      return false;
    }
    if (!r.ok) {
      document.getElementById("queue-head").textContent = `mark refused (${r.status}): ${await r.text()}`;
      return false;
    }
    return true;
  }

  async function markCurrent(m) {
    if (current === null) return;
    const id = current;
    if (await mark(id, m)) {
      // move on to the next hole still for review (or the next one in the queue)
      const rest = queue.filter(h => h.id !== id);
      const next = rest.find(h => h.tier === "review" && h.mark === "new");
      if (next && (m === "confirmed" || m === "rejected")) current = next.id;
      await window.refresh();
    }
  }

  function init() {
    document.getElementById("side").addEventListener("click", async ev => {
      const b = ev.target.closest("button[data-mark]");
      if (b) {
        ev.stopPropagation();
        if (await mark(Number(b.dataset.id), b.dataset.mark)) await window.refresh();
        return;
      }
      const r = ev.target.closest(".hole[data-id]");
      if (r) select(Number(r.dataset.id));
    });
    document.addEventListener("keydown", ev => {
      if (ev.target.closest && ev.target.closest("input, textarea, select")) return;
      if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
      const k = ev.key;
      const act = { c: "confirmed", x: "rejected", r: "rejected", v: "visited", u: "new" }[k.toLowerCase()];
      if (act) { ev.preventDefault(); markCurrent(act); }
      else if (k === "n" || k === "j" || k === "ArrowDown") { ev.preventDefault(); step(1); }
      else if (k === "p" || k === "k" || k === "ArrowUp") { ev.preventDefault(); step(-1); }
    });
  }

  return { render, select, init, current: () => current };
})();
