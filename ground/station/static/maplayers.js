// holescan live page: the flight's map layers (served by ground/station/maplayers.py).
// The orthophoto under everything, the coverage (seen green / not seen red) above it, both
// toggleable; tiles placed in the page's local metres by /map.json. No CDN, no tile server.
// Hooks the page calls: holescanMap.corners() (extent, for the view) and
// holescanMap.svg(X, Y, s, doc, redraw) (the layers' SVG, drawn first).
"use strict";
window.holescanMap = (function () {
  const show = { ortho: true, cov: true };
  let tiles = [];
  let version = -1;
  let asked = null;     // the origin map.json was last asked for ("lat,lon" or "")
  let redraw = null;
  let busy = false;

  function toggles() {
    if (document.getElementById("maplayers")) return;
    const map = document.getElementById("map");
    if (!map) return;
    const box = document.createElement("div");
    box.id = "maplayers";
    box.innerHTML =
      '<label><input type="checkbox" id="layer-ortho" checked> orthophoto</label><br>'
      + '<label><input type="checkbox" id="layer-cov" checked> coverage: '
      + '<span class="seen">&#9632; seen</span> '
      + '<span class="unseen">&#9632; not seen</span></label>'
      + '<div id="map-tiles"></div>';
    map.appendChild(box);
    for (const layer of ["ortho", "cov"]) {
      document.getElementById("layer-" + layer).addEventListener("change", ev => {
        show[layer] = ev.target.checked;
        if (redraw) redraw();
      });
    }
  }

  async function load(origin) {
    if (busy) return;
    busy = true;
    try {
      const q = origin ? `?lat=${origin[0]}&lon=${origin[1]}` : "";
      const r = await fetch("/map.json" + q, { cache: "no-store" });
      if (!r.ok) return;
      const d = await r.json();
      const key = origin ? origin.join(",") : "";
      if (d.version !== version || key !== asked) {
        tiles = d.tiles; version = d.version; asked = key;
        const info = document.getElementById("map-tiles");
        if (info) {
          const n = l => tiles.filter(t => t.layer === l).length;
          info.textContent = `${n("cov")} coverage, ${n("ortho")} orthophoto tiles`;
        }
        if (redraw) redraw();
      }
    } catch (e) {
      // the station is restarting: the next poll tries again
    } finally {
      busy = false;
    }
  }

  let origin = null;
  setInterval(() => load(origin), 2000);

  function corners() {
    const out = [];
    for (const t of tiles) out.push([t.x0, t.y0], [t.x1, t.y1]);
    return out;
  }

  function svg(X, Y, s, doc, redrawFn) {
    redraw = redrawFn;
    toggles();
    origin = doc && doc.origin ? doc.origin : null;
    if ((origin ? origin.join(",") : "") !== asked) load(origin);
    const parts = [];
    for (const layer of ["ortho", "cov"]) {
      if (!show[layer]) continue;
      parts.push(`<g class="maplayer" data-layer="${layer}">`);
      for (const t of tiles) {
        if (t.layer !== layer) continue;
        const w = (t.x1 - t.x0) * s, h = (t.y1 - t.y0) * s;
        parts.push(`<image href="${t.href}" x="${X(t.x0)}" y="${Y(t.y1)}" width="${w}" height="${h}"`
          + ` preserveAspectRatio="none"/>`);
      }
      parts.push("</g>");
    }
    return parts.join("");
  }

  return { svg, corners, show };
})();
