// Where the selected hole is, in the words a rescuer reads out (the panel #locate), and
// the vehicles heard (the panel #vehicles). Served as a file (the page's CSP allows no
// inline script or style: colours are SVG attributes).
//
// Locate: the hole's lat/lon and MGRS grid reference (the station computes it), each with
// a copy button (the clipboard API, else a selected text field and the copy command),
// distance and bearing from the launch point and from each vehicle (the station's), and
// from this device when the operator asks ("from me": the browser's geolocation, only on
// that click), the hole's age, and the vehicles that reported it, first and last.
"use strict";

const Locate = (() => {
  let me = null;        // this device's position {lat, lon, acc} after "from me"
  let meError = "";
  let doc = null, current = null;
  let fetchedAt = 0;    // performance.now() when doc arrived (ages count on from it)

  function esc(s) {
    return String(s).replace(/[&<>"']/g, c => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
  }
  const ROSE = ["N", "NNE", "NE", "ENE", "E", "ESE", "SE", "SSE", "S", "SSW", "SW", "WSW", "W", "WNW", "NW", "NNW"];

  // distance (m) and bearing (deg) on the local tangent plane, as the station computes
  // its own (ground/station/locate.py): exact to centimetres over a few kilometres
  function rangeBearing(lat0, lon0, lat1, lon1) {
    const a = 6378137.0, e2 = 6.69437999014e-3, p = lat0 * Math.PI / 180;
    const w = Math.sqrt(1 - e2 * Math.sin(p) ** 2);
    const rn = a * (1 - e2) / (w ** 3), re = a / w;   // meridian and prime-vertical radii
    const dn = (lat1 - lat0) * Math.PI / 180 * rn;
    const de = (lon1 - lon0) * Math.PI / 180 * re * Math.cos(p);
    const b = (Math.atan2(de, dn) * 180 / Math.PI + 360) % 360;
    return { distance_m: Math.hypot(de, dn), bearing_deg: b, compass: ROSE[Math.round(b / 22.5) % 16] };
  }

  function rangeText(r) {
    if (!r || r.distance_m == null) return "unknown";
    const d = r.distance_m >= 1000 ? `${(r.distance_m / 1000).toFixed(2)} km` : `${r.distance_m.toFixed(1)} m`;
    return `${d} bearing ${Math.round(r.bearing_deg).toString().padStart(3, "0")}&deg; (${esc(r.compass)})`;
  }

  function ago(tNs) {
    if (!doc || !tNs) return "unknown";
    const s = Math.max(0, (doc.now_unix_ns - tNs) / 1e9 + (performance.now() - fetchedAt) / 1000);
    if (s < 60) return `${Math.round(s)} s ago`;
    if (s < 3600) return `${Math.round(s / 60)} min ago`;
    return `${(s / 3600).toFixed(1)} h ago`;
  }

  function copyButton(text, what) {
    return `<button class="copy" data-copy="${esc(text)}" title="copy the ${what}">copy</button>`;
  }

  async function copy(text, button) {
    let ok = false;
    try {
      if (navigator.clipboard && window.isSecureContext) {
        await navigator.clipboard.writeText(text);
        ok = true;
      }
    } catch (e) { ok = false; }
    if (!ok) {  // plain http on the LAN: no clipboard API; the old way still works
      const t = document.createElement("textarea");
      t.value = text;
      t.setAttribute("readonly", "");
      t.className = "offscreen";
      document.body.appendChild(t);
      t.select();
      try { ok = document.execCommand("copy"); } catch (e) { ok = false; }
      t.remove();
    }
    button.textContent = ok ? "copied" : "select + copy by hand";
    setTimeout(() => { button.textContent = "copy"; }, 2000);
  }

  function panel(h) {
    if (!h) return "";
    const ll = `${h.lat_deg.toFixed(7)}, ${h.lon_deg.toFixed(7)}`;
    const rows = [
      `<tr><th>lat, lon</th><td class="coord" id="loc-latlon">${ll}</td><td>${copyButton(ll, "latitude, longitude")}</td></tr>`,
      `<tr><th>MGRS</th><td class="coord" id="loc-mgrs">${h.mgrs ? esc(h.mgrs) : "none here"}</td><td>${h.mgrs ? copyButton(h.mgrs, "grid reference") : ""}</td></tr>`,
    ];
    const home = doc.home ? ` <span class="by">(${esc(doc.home.source)})</span>` : "";
    rows.push(`<tr><th>from home</th><td colspan="2" id="loc-home">${rangeText(h.from_home)}${home}</td></tr>`);
    for (const r of (h.from_vehicles || [])) {
      rows.push(`<tr><th>from vehicle ${r.sysid}</th><td colspan="2" class="loc-vehicle">${rangeText(r)}</td></tr>`);
    }
    const mine = me ? rangeText(rangeBearing(me.lat, me.lon, h.lat_deg, h.lon_deg))
      + ` <span class="by">(this device, &plusmn;${Math.round(me.acc)} m)</span>` : esc(meError);
    rows.push(`<tr><th>from me</th><td colspan="2" id="loc-me">${mine} <button id="from-me" title="use this device's position (asked once, on this click)">${me ? "update" : "from me"}</button></td></tr>`);
    const circle = h.r95 != null
      ? `the circle holds the hole with 95 % probability: radius ${h.r95.toFixed(2)} m (1.62 x its 1-sigma ${h.sigma_h_m.toFixed(2)} m)`
      : "uncertainty not told yet (dashed circle)";
    rows.push(`<tr><th>where</th><td colspan="2">${circle}</td></tr>`);
    rows.push(`<tr><th>age</th><td colspan="2" id="loc-age">first seen ${ago(h.t_first_unix_ns)}, updated ${ago(h.t_updated_unix_ns)}</td></tr>`);
    const vs = (h.vehicles || []).map(v =>
      `vehicle ${v.sysid} (its hole ${v.hole_id}): first ${ago(v.t_first_unix_ns)}, last ${ago(v.t_last_unix_ns)}`);
    if (vs.length) rows.push(`<tr><th>seen by</th><td colspan="2" id="loc-vehicles">${vs.join("<br>")}</td></tr>`);
    return `<table class="locate">${rows.join("")}</table>`;
  }

  function vehicleRow(v) {
    const swatch = `<svg width="12" height="12" aria-hidden="true"><rect width="12" height="12" fill="${esc(v.colour)}"/></svg>`;
    const f = (x, d, u) => x == null ? "?" : `${Number(x).toFixed(d)}${u}`;
    const batt = v.battery_v == null && v.battery_pct == null ? "battery ?"
      : `battery ${f(v.battery_v, 1, " V")}${v.battery_pct != null ? ` ${v.battery_pct} %` : ""}`;
    const loss = v.loss_recent == null ? "" : ` &middot; loss ${(100 * v.loss_recent).toFixed(0)} %`;
    const rssi = v.rssi == null ? "" : ` &middot; rssi ${v.rssi}/${v.remote_rssi ?? "?"}`;
    const heard = v.heard_s_ago == null ? "never heard" : `heard ${v.heard_s_ago.toFixed(0)} s ago`;
    const stale = v.heard_s_ago != null && v.heard_s_ago > 5 ? " stale" : "";
    const armed = v.armed == null ? "" : (v.armed ? " ARMED" : " disarmed");
    return `<div class="vehicle${stale}" data-sysid="${v.sysid}">${swatch} <b>vehicle ${v.sysid}</b> ${esc(v.mode || "mode ?")}${armed}`
      + ` &middot; ${f(v.rel_alt_m, 1, " m")} up &middot; heading ${f(v.heading_deg, 0, "&deg;")}`
      + ` &middot; ${f(v.groundspeed_m_s, 1, " m/s")}<br><span class="by">${batt}${loss}${rssi} &middot; ${heard}`
      + ` &middot; camera ${esc(v.camera || "?")}</span></div>`;
  }

  function render(d, id) {
    if (d !== doc) fetchedAt = performance.now();
    doc = d; current = id;
    const box = document.getElementById("locate");
    const h = doc ? doc.holes.find(x => x.id === id) : null;
    if (box) box.innerHTML = panel(h);
    const vbox = document.getElementById("vehicles");
    if (vbox && doc) vbox.innerHTML = (doc.vehicles || []).map(vehicleRow).join("");
  }

  function init() {
    document.addEventListener("click", ev => {
      const c = ev.target.closest("button.copy");
      if (c) { ev.stopPropagation(); copy(c.dataset.copy, c); return; }
      if (ev.target.closest("#from-me")) {
        ev.stopPropagation();
        if (!navigator.geolocation) { meError = "this browser gives no position"; render(doc, current); return; }
        navigator.geolocation.getCurrentPosition(
          p => { me = { lat: p.coords.latitude, lon: p.coords.longitude, acc: p.coords.accuracy }; meError = ""; render(doc, current); },
          e => { meError = `no position (${e.message || e.code})`; render(doc, current); },
          { enableHighAccuracy: true, timeout: 15000, maximumAge: 10000 });
      }
    });
    setInterval(() => { if (doc) render(doc, current); }, 5000);  // the ages count on
  }

  return { render, init, rangeBearing };
})();
