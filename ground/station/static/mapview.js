// holescan live page: the map's view. Pan and zoom with the mouse (wheel: zoom about the
// pointer; drag: pan), with a finger (drag: pan; two fingers: pinch to zoom, about their
// middle) and with the buttons (+, -, fit). Until the map is moved the view fits
// everything the page draws and follows the flight; "fit" goes back to that.
// Hooks the page calls: MapView.transform(W, H, box, redraw) -> {X, Y, s} for a draw
// (box: [x0, y0, x1, y1] in local metres, what fitting shows); MapView.state() for tests.
"use strict";
window.MapView = (function () {
  const S_MIN = 0.05, S_MAX = 2000;   // pixels per metre: 20 km to 0.5 mm across 1,000 px
  let view = null;      // {cx, cy, s}: centre (local metres), pixels per metre; null: fit
  let last = null;      // the last draw's {cx, cy, s, W, H}
  let redraw = null;
  const pointers = new Map();   // pointerId -> [x, y] (client px) of the pointers down
  let dragging = false;         // a pointer moved far enough to be a pan, not a click

  const clamp = s => Math.min(S_MAX, Math.max(S_MIN, s));

  function transform(W, H, box, redrawFn) {
    redraw = redrawFn;
    buttons();
    let cx, cy, s;
    if (view) {
      ({ cx, cy, s } = view);
    } else {
      const [x0, y0, x1, y1] = box;
      s = clamp(Math.min(W / (x1 - x0), H / (y1 - y0)));
      cx = (x0 + x1) / 2; cy = (y0 + y1) / 2;
    }
    last = { cx, cy, s, W, H };
    return { s, X: x => W / 2 + (x - cx) * s, Y: y => H / 2 - (y - cy) * s };
  }

  function moved() {
    const el = document.getElementById("map");
    if (el) el.classList.toggle("moved", view !== null);
    if (redraw) redraw();
  }

  // the view from the last draw's, once the operator touches the map
  function current() {
    if (!view && last) view = { cx: last.cx, cy: last.cy, s: last.s };
    return view;
  }

  function local(px, py) {   // client px -> px within the map's svg
    const r = document.getElementById("svg").getBoundingClientRect();
    return [px - r.left, py - r.top];
  }

  function zoomAt(k, px, py) {   // zoom by k about the svg point (px, py)
    const v = current();
    if (!v || !last || !isFinite(k) || k <= 0) return;
    const mx = v.cx + (px - last.W / 2) / v.s, my = v.cy - (py - last.H / 2) / v.s;
    v.s = clamp(v.s * k);
    v.cx = mx - (px - last.W / 2) / v.s;
    v.cy = my + (py - last.H / 2) / v.s;
    moved();
  }

  function pan(dx, dy) {   // move the map by (dx, dy) px
    const v = current();
    if (!v) return;
    v.cx -= dx / v.s; v.cy += dy / v.s;
    moved();
  }

  function fit() { view = null; moved(); }

  function middle() {
    const ps = [...pointers.values()];
    return [(ps[0][0] + ps[1][0]) / 2, (ps[0][1] + ps[1][1]) / 2, Math.hypot(ps[0][0] - ps[1][0], ps[0][1] - ps[1][1])];
  }

  function attach() {
    const svg = document.getElementById("svg");
    if (!svg || svg.dataset.view) return;
    svg.dataset.view = "1";
    svg.addEventListener("wheel", ev => {
      ev.preventDefault();
      const unit = ev.deltaMode === 1 ? 16 : ev.deltaMode === 2 ? 400 : 1;   // lines, pages
      const [x, y] = local(ev.clientX, ev.clientY);
      zoomAt(Math.exp(-ev.deltaY * unit / 500), x, y);
    }, { passive: false });
    svg.addEventListener("pointerdown", ev => {
      pointers.set(ev.pointerId, [ev.clientX, ev.clientY]);
      dragging = pointers.size > 1;
    });
    svg.addEventListener("pointermove", ev => {
      const was = pointers.get(ev.pointerId);
      if (!was) return;
      if (pointers.size === 1) {
        const dx = ev.clientX - was[0], dy = ev.clientY - was[1];
        if (!dragging && Math.hypot(dx, dy) < 4) return;   // still a click
        if (!dragging) { dragging = true; svg.setPointerCapture(ev.pointerId); }
        pointers.set(ev.pointerId, [ev.clientX, ev.clientY]);
        pan(dx, dy);
        return;
      }
      const [mx0, my0, d0] = middle();
      pointers.set(ev.pointerId, [ev.clientX, ev.clientY]);
      const [mx1, my1, d1] = middle();
      const [x, y] = local(mx1, my1);
      if (d0 > 0 && d1 > 0) zoomAt(d1 / d0, x, y);
      pan(mx1 - mx0, my1 - my0);
    });
    const up = ev => {
      pointers.delete(ev.pointerId);
      if (pointers.size === 0) setTimeout(() => { dragging = false; }, 0);
    };
    svg.addEventListener("pointerup", up);
    svg.addEventListener("pointercancel", up);
    // a drag is not a click on what lies under its end
    svg.addEventListener("click", ev => { if (dragging) ev.stopPropagation(); }, true);
  }

  function buttons() {
    attach();
    if (document.getElementById("zoom")) return;
    const map = document.getElementById("map");
    if (!map) return;
    const box = document.createElement("div");
    box.id = "zoom";
    const add = (id, text, title, fn) => {
      const b = document.createElement("button");
      b.id = id; b.type = "button"; b.textContent = text; b.title = title;
      b.setAttribute("aria-label", title);
      b.addEventListener("click", fn);
      box.appendChild(b);
    };
    const centre = () => last ? [last.W / 2, last.H / 2] : [0, 0];
    add("zoom-in", "+", "zoom in", () => zoomAt(1.5, ...centre()));
    add("zoom-out", "\u2212", "zoom out", () => zoomAt(1 / 1.5, ...centre()));
    add("zoom-fit", "fit", "fit everything and follow the flight", fit);
    map.appendChild(box);
  }

  return { transform, state: () => ({ view, last }), fit };
})();
