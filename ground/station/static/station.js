// The live page: the map (draw), the station's state (refresh), the pairing of this browser
// (pair) and the event stream that keeps the page current (listen). Served as a file: the
// page's Content-Security-Policy allows no inline script.
"use strict";
const COL = { new: "#f9a825", review: "#8e24aa", confirmed: "#c62828", visited: "#2e7d32", rejected: "#9e9e9e" };
let doc = null;

function esc(s) { return String(s).replace(/[&<>"]/g, c => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;"}[c])); }

function niceLength(m) {
  const p = Math.pow(10, Math.floor(Math.log10(m)));
  for (const k of [5, 2, 1]) if (k * p <= m) return k * p;
  return p;
}

function draw() {
  const svg = document.getElementById("svg");
  const W = svg.clientWidth || 800, H = svg.clientHeight || 600;
  const pts = [];
  for (const h of doc.holes) pts.push([h.x, h.y]);
  for (const t of doc.track) pts.push(t);
  for (const f of (doc.footprints || [])) for (const c of f) pts.push(c);
  for (const v of (doc.vehicles || [])) {
    if (v.xy) pts.push(v.xy);
    for (const c of (v.footprint_now || [])) pts.push(c);
  }
  if (doc.home) pts.push(doc.home.xy);
  const ML = window.holescanMap;  // map layers (maplayers.js)
  if (ML) for (const c of ML.corners()) pts.push(c);
  let parts = [];
  if (pts.length) {
    let x0 = Math.min(...pts.map(p => p[0])), x1 = Math.max(...pts.map(p => p[0]));
    let y0 = Math.min(...pts.map(p => p[1])), y1 = Math.max(...pts.map(p => p[1]));
    const pad = 3;
    x0 -= pad; x1 += pad; y0 -= pad; y1 += pad;
    // pixels per metre (same both ways) and the place of a point: everything fitted, or
    // the operator's pan and zoom (mapview.js)
    const { X, Y, s } = window.MapView
      ? MapView.transform(W, H, [x0, y0, x1, y1], draw)
      : (() => {
        const s = Math.min(W / (x1 - x0), H / (y1 - y0));
        const ox = (W - s * (x1 - x0)) / 2, oy = (H - s * (y1 - y0)) / 2;
        return { s, X: x => ox + (x - x0) * s, Y: y => H - oy - (y - y0) * s };
      })();
    if (ML) parts.push(ML.svg(X, Y, s, doc, draw));
    const vehicles = doc.vehicles || [];
    if (!vehicles.length) {  // a state document of an older station: one track
      for (const f of (doc.footprints || [])) {
        parts.push(`<polygon points="${f.map(c => X(c[0]) + "," + Y(c[1])).join(" ")}" fill="#90caf9" fill-opacity="0.12" stroke="#64b5f6" stroke-opacity="0.3" stroke-width="0.5"/>`);
      }
      if (doc.track.length > 1) {
        parts.push(`<polyline class="track" points="${doc.track.map(p => X(p[0]) + "," + Y(p[1])).join(" ")}" fill="none" stroke="#1565c0" stroke-width="1.5"/>`);
      }
    }
    const pts2 = cs => cs.map(c => X(c[0]) + "," + Y(c[1])).join(" ");
    for (const v of vehicles) {  // each vehicle in its colour: where it looked, its track
      for (const f of (v.footprints || [])) {
        parts.push(`<polygon class="seen" points="${pts2(f)}" fill="${v.colour}" fill-opacity="0.08" stroke="${v.colour}" stroke-opacity="0.25" stroke-width="0.5"/>`);
      }
      if (v.track.length > 1) {
        parts.push(`<polyline class="track" data-sysid="${v.sysid}" points="${pts2(v.track)}" fill="none" stroke="${v.colour}" stroke-width="1.5"/>`);
      }
    }
    if (doc.home) {
      const [hx, hy] = [X(doc.home.xy[0]), Y(doc.home.xy[1])];
      parts.push(`<g class="home"><rect x="${hx - 7}" y="${hy - 7}" width="14" height="14" fill="#fff" stroke="#333"/>`
        + `<text class="label" x="${hx - 4}" y="${hy + 4}">H</text></g>`);
    }
    for (const v of vehicles) {  // now: the camera's footprint and the vehicle, heading up
      if (v.footprint_now) {
        parts.push(`<polygon class="footprint-now" data-sysid="${v.sysid}" points="${pts2(v.footprint_now)}" fill="${v.colour}" fill-opacity="0.15" stroke="${v.colour}" stroke-width="1.5" stroke-dasharray="4 2"/>`);
      }
      if (v.xy) {
        const [vx, vy] = [X(v.xy[0]), Y(v.xy[1])];
        const hd = v.heading_deg || 0;
        parts.push(`<g class="vehicle" data-sysid="${v.sysid}" transform="translate(${vx},${vy}) rotate(${hd})">`
          + `<polygon points="0,-11 7,8 0,4 -7,8" fill="${v.colour}" stroke="#fff" stroke-width="1.5"/></g>`
          + `<text class="label" x="${vx + 10}" y="${vy + 14}">${v.sysid}</text>`);
      }
    }
    for (const h of doc.holes) {
      const c = h.mark === "new" && h.tier === "review" ? COL.review : (COL[h.mark] || COL.new);
      const cur = h.id === Review.current();
      const r = h.r95 ? h.r95 * s : 6;
      parts.push(`<g data-hole="${h.id}"><circle cx="${X(h.x)}" cy="${Y(h.y)}" r="${r}" fill="${c}" fill-opacity="0.18" stroke="${c}" stroke-width="1.5"${h.r95 ? "" : ' stroke-dasharray="3 2"'}/>`
        + `<circle cx="${X(h.x)}" cy="${Y(h.y)}" r="${cur ? 6 : 3}" fill="${c}"${cur ? ' stroke="#0d47a1" stroke-width="2"' : ""}/>`
        + `<text class="label" x="${X(h.x) + 6}" y="${Y(h.y) - 6}">${h.id}</text></g>`);
    }
    // scale bar: a round length near a fifth of the width
    const L = niceLength((W / 5) / s);
    parts.push(`<g id="scalebar" transform="translate(20,${H - 24})"><rect x="0" y="-4" width="${L * s}" height="6" fill="#333"/>`
      + `<text class="label" x="0" y="-9">${L} m</text></g>`);
  }
  // north arrow (local metres: north is up)
  parts.push(`<g id="north" transform="translate(${W - 36},46)"><polygon points="0,-26 9,6 0,0 -9,6" fill="#333"/>`
    + `<text class="label" x="-5" y="22" font-weight="bold">N</text></g>`);
  svg.innerHTML = parts.join("");
  if (typeof Locate !== "undefined") Locate.render(doc, Review.current());
}

// The pairing link (?token=...): taken out of the address bar and the tab's history at
// once, then checked with the station (POST /pair) before anything is kept. The station
// answers with an HttpOnly, SameSite=Strict cookie: the page's script never holds the
// token, and a bad link says so here instead of leaving the page read-only in silence.
function notice(text, kind) {
  const n = document.getElementById("notice");
  n.textContent = text || "";
  n.className = kind || "";
  n.hidden = !text;
}

async function pair() {
  // what earlier versions of this page kept in the browser's storage (a station token and
  // a typed name): gone, the cookie and the pairing replace them
  localStorage.removeItem("holescan-token");
  localStorage.removeItem("holescan-operator");
  const u = new URL(location.href);
  if (!u.searchParams.has("token")) return;
  const t = u.searchParams.get("token");
  u.searchParams.delete("token");
  history.replaceState(null, "", u.pathname + u.search + u.hash);
  const bad = "This pairing link is not valid (mistyped, cut short, or revoked). The page is "
    + "read-only: ask the station for a new link (holescan pair).";
  if (!/^[A-Za-z0-9_-]{20,100}$/.test(t)) { notice(bad, "error"); return; }
  try {
    const r = await fetch("/pair", { method: "POST", cache: "no-store", headers: { "Authorization": "Bearer " + t } });
    if (r.ok) {
      const d = await r.json();
      notice(`Paired: marks from this browser are recorded as ${d.operator} (${d.pairing}).`, "ok");
    } else if (r.status === 401) {
      notice(bad, "error");
    } else {
      notice(`The station refused the pairing (${r.status}): ${await r.text()}`, "error");
    }
  } catch (e) {
    notice("The station did not answer the pairing: open the link again.", "error");
  }
}

let refreshing = false, again = false;
async function refreshOnce() {
  const status = document.getElementById("status");
  try {
    const r = await fetch("/state.json", { cache: "no-store" });
    if (!r.ok) throw new Error(`${r.status} ${await r.text()}`);
    doc = await r.json();
  } catch (e) {
    status.textContent = `station not reachable (${e.message || e}): retrying ...`;
    return;
  }
  Review.render(doc);
  draw();
  document.getElementById("pairing").textContent = doc.paired
    ? `paired as ${doc.paired.operator} (${doc.paired.pairing})`
    : "read-only: open your pairing link to mark";
  const nv = (doc.vehicles || []).length;
  status.textContent = (doc.holes.length || doc.track.length || nv)
    ? `${doc.holes.length} holes, ${nv} vehicle${nv === 1 ? "" : "s"}, track ${doc.track.length} points, updated ${new Date().toLocaleTimeString()}`
    : "connected; waiting for the vehicle ...";
}

async function refresh() {  // one re-read at a time; changes meanwhile make one more
  if (refreshing) { again = true; return; }
  refreshing = true;
  try {
    do { again = false; await refreshOnce(); } while (again);
  } finally {
    refreshing = false;
  }
}

// The event stream: a browser's EventSource reconnects by itself when a stream ends (the
// station closes each after a while); when the station refuses one (503: all slots taken)
// or is gone, the page opens a new one itself, waiting longer each time (up to 30 s), and
// re-reads the state whenever a stream opens.
let backoffMs = 1000;
function listen() {
  const es = new EventSource("/events");
  window.holescanEvents = es;
  es.onopen = () => { backoffMs = 1000; document.body.dataset.live = "yes"; refresh(); };
  es.onmessage = () => refresh();
  es.onerror = () => {
    document.body.dataset.live = "no";
    if (es.readyState === EventSource.CLOSED) {
      setTimeout(listen, backoffMs);
      backoffMs = Math.min(backoffMs * 2, 30000);
    }
  };
}

document.getElementById("svg").addEventListener("click", ev => {
  const g = ev.target.closest("g[data-hole]");
  if (g) Review.select(Number(g.dataset.hole));
});
Review.init();
Locate.init();
window.addEventListener("resize", () => doc && draw());
pair().finally(() => { refresh(); listen(); });
