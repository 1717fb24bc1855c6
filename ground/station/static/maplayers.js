// holescan live page: the flight's map layers (served by ground/station/maplayers.py).
// The team's offline basemap (MBTiles or GeoTIFF, chosen in the box) under everything, the
// drone's orthophoto over it, the coverage (seen green / not seen red) above, each
// switchable; each drone's own coverage (searched in its colour / not searched grey) as a
// layer of its own, off until switched on (the combined coverage stays the crew's "where
// did we look"); tiles placed in the page's local metres by /map.json and
// /basemap/ID/view.json. No CDN, no tile server on the internet.
// Hooks the page calls: holescanMap.corners() (extent, for the view) and
// holescanMap.svg(X, Y, s, doc, redraw) (the layers' SVG, drawn first).
"use strict";
window.holescanMap = (function () {
  const show = { ortho: true, cov: true };
  const showVehicle = {};   // sysid -> shown (each drone's own coverage; off at first)
  let tiles = [];
  let vehicles = [];        // /map.json's vehicles: [{sysid, colour, tiles}]
  let version = -1;
  let asked = null;     // the origin map.json was last asked for ("lat,lon" or "")
  let redraw = null;
  let busy = false;
  let basemaps = [];    // /basemaps.json
  let basemap = -1;     // the one shown (-1: none)
  let baseTiles = [];
  let baseKey = "";     // the view baseTiles were asked for
  let baseBusy = false;

  function toggles() {
    if (document.getElementById("maplayers")) return;
    const map = document.getElementById("map");
    if (!map) return;
    const box = document.createElement("div");
    box.id = "maplayers";
    box.innerHTML =
      '<label class="basemap">basemap <select id="layer-basemap"><option value="-1">none</option></select></label>'
      + '<label><input type="checkbox" id="layer-ortho" checked> drone orthophoto</label>'
      + '<label><input type="checkbox" id="layer-cov" checked> coverage: '
      + '<span class="seen">&#9632; seen</span> '
      + '<span class="unseen">&#9632; not seen</span></label>'
      + '<details id="layer-vehicles" hidden><summary>each drone\'s coverage</summary></details>'
      + '<div id="map-tiles"></div>';
    map.appendChild(box);
    const sel = document.getElementById("layer-basemap");
    sel.addEventListener("change", ev => {
      basemap = Number(ev.target.value);
      baseTiles = []; baseKey = "";
      if (redraw) redraw();
    });
    fetch("/basemaps.json", { cache: "no-store" }).then(r => r.ok ? r.json() : { basemaps: [] }).then(d => {
      basemaps = d.basemaps || [];
      for (const b of basemaps) {
        const o = document.createElement("option");
        o.value = String(b.id);
        o.textContent = b.name;
        sel.appendChild(o);
      }
      if (basemaps.length && basemap < 0) { basemap = basemaps[0].id; sel.value = String(basemap); }
      if (redraw) redraw();
    }).catch(() => {});
    for (const layer of ["ortho", "cov"]) {
      document.getElementById("layer-" + layer).addEventListener("change", ev => {
        show[layer] = ev.target.checked;
        if (redraw) redraw();
      });
    }
  }

  // one check box per drone with tiles, its label in the drone's colour
  function vehicleToggles() {
    const box = document.getElementById("layer-vehicles");
    if (!box) return;
    box.hidden = vehicles.length === 0;
    for (const v of vehicles) {
      const id = "layer-cov-" + v.sysid;
      let input = document.getElementById(id);
      if (!input) {
        const label = document.createElement("label");
        input = document.createElement("input");
        input.type = "checkbox";
        input.id = id;
        input.dataset.sysid = String(v.sysid);
        input.addEventListener("change", ev => {
          showVehicle[v.sysid] = ev.target.checked;
          if (redraw) redraw();
        });
        const NS = "http://www.w3.org/2000/svg";  // the swatch: an SVG square (no style)
        const swatch = document.createElementNS(NS, "svg");
        swatch.setAttribute("class", "swatch");
        swatch.setAttribute("width", "12");
        swatch.setAttribute("height", "12");
        swatch.appendChild(document.createElementNS(NS, "rect"));
        swatch.firstChild.setAttribute("width", "12");
        swatch.firstChild.setAttribute("height", "12");
        const text = document.createElement("span");
        text.textContent = ` drone ${v.sysid}: searched (`;
        const grey = document.createElement("span");
        grey.className = "notsearched";
        grey.textContent = "\u25A0";
        label.append(input, " ", swatch, text, grey, " not)");
        box.appendChild(label);
      }
      const rect = input.parentElement.querySelector(".swatch rect");
      if (rect) rect.setAttribute("fill", v.colour);
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
        vehicles = Array.isArray(d.vehicles) ? d.vehicles : [];
        vehicleToggles();
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

  // the basemap's tiles for the view the page shows (its box in the page's metres)
  async function loadBase(key, q) {
    if (baseBusy) return;
    baseBusy = true;
    try {
      const r = await fetch(`/basemap/${basemap}/view.json?${q}`, { cache: "no-store" });
      if (r.ok) { baseTiles = (await r.json()).tiles; baseKey = key; if (redraw) redraw(); }
    } catch (e) {
      // the station is restarting: the next draw asks again
    } finally {
      baseBusy = false;
    }
  }

  function baseSvg(X, Y, s) {
    const el = document.getElementById("svg");
    if (basemap < 0 || !origin || !el) return "";
    const W = el.clientWidth || 800, H = el.clientHeight || 600;
    const x0 = -X(0) / s, x1 = (W - X(0)) / s, y0 = (Y(0) - H) / s, y1 = Y(0) / s;
    const r = v => v.toFixed(1);
    const q = `lat=${origin[0]}&lon=${origin[1]}&x0=${r(x0)}&y0=${r(y0)}&x1=${r(x1)}&y1=${r(y1)}&px=${Math.round(W)}`;
    const key = `${basemap}|${q}`;
    if (key !== baseKey) loadBase(key, q);
    const parts = ['<g class="maplayer" data-layer="basemap">'];
    for (const t of baseTiles) {
      const w = (t.x1 - t.x0) * s, h = (t.y1 - t.y0) * s;
      parts.push(`<image href="${t.href}" x="${X(t.x0)}" y="${Y(t.y1)}" width="${w}" height="${h}"`
        + ` preserveAspectRatio="none"/>`);
    }
    parts.push("</g>");
    return parts.join("");
  }

  function svg(X, Y, s, doc, redrawFn) {
    redraw = redrawFn;
    toggles();
    origin = doc && doc.origin ? doc.origin : null;
    if ((origin ? origin.join(",") : "") !== asked) load(origin);
    const parts = [baseSvg(X, Y, s)];
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
    for (const v of vehicles) {  // each drone's own coverage, over the combined one
      if (!showVehicle[v.sysid]) continue;
      parts.push(`<g class="maplayer" data-layer="cov-${Number(v.sysid)}">`);
      for (const t of v.tiles) {
        const w = (t.x1 - t.x0) * s, h = (t.y1 - t.y0) * s;
        parts.push(`<image href="${t.href}" x="${X(t.x0)}" y="${Y(t.y1)}" width="${w}" height="${h}"`
          + ` preserveAspectRatio="none"/>`);
      }
      parts.push("</g>");
    }
    return parts.join("");
  }

  return { svg, corners, show, showVehicle, basemap: () => basemap, baseTiles: () => baseTiles };
})();
