"""What ``holescan demo`` prints at the end: the truth table, the ground station, the files."""

from __future__ import annotations

import statistics

import numpy as np

from holescan.demo._run import DemoResult
from holescan.geotag import AnnounceGate

__all__ = ["REVIEW_PER_HA_MEASURED", "format_result"]

REVIEW_PER_HA_MEASURED = 195
"""For-review items per hectare surveyed at the default gate (announced p_hole >= 0.9,
review >= 0.1) on the structured-light sensor, as measured: ``benchmarks/bench_tiers.py
CACHE --seeds 13-22``, 63 held-out simulated flights (10 surveys, 35 hovers, 18 passes), 33
review items in 0.17 ha (docs/tiers.md, "Tiers"). The demo states it next to what its own
flight gave."""


def format_result(r: DemoResult) -> list[str]:
    """What the demo prints at the end."""
    c = r.summary.counters
    n_access = r.world_features.get("access", 0)
    distractors = sum(r.world_features.values()) - n_access
    cut = " (stopped early)" if r.interrupted else ""
    lines = [
        f"holescan demo: {r.capture_s:.0f} s of a simulated dawn survey{cut}, "
        f"{n_access} access holes and {distractors} distractors in the field",
        f"frames: {c.frames_captured} captured ({c.frames_captured / max(r.capture_s, 1e-9):.1f}"
        f"/s), {c.frames_detected} detected, {c.frames_unposed} not posed at capture",
        f"holes against the simulator's truth (announced: hole-level p_hole >= "
        f"{r.gate.min_p_hole:g}, >= {r.gate.min_sightings} sightings over >= "
        f"{r.gate.min_span_s:g} s; for review: p_hole >= {r.gate.review_min_p_hole:g}; "
        f"inside a true opening or within {r.match_m:g} m of its centre finds it; "
        f"{r.candidates} weaker candidates kept in the log only):",
    ]
    for row in r.truth:
        t = row.truth
        where = f"true hole {t.id} at ({t.x_m:.1f}, {t.y_m:.1f}) m, {t.major_m:.2f} m wide"
        if row.status == "found":
            h = next(h for h in r.confirmed if h.id == row.hole_id)
            lines.append(
                f"  {where}: FOUND, ANNOUNCED as hole {row.hole_id} (p_hole {h.p_hole:.2f}, "
                f"best frame's score {h.score:.2f}), {100 * row.error_m:.0f} cm off, seen in "
                f"{row.sightings} frames from {h.views} viewpoints"
            )
        elif row.status == "missed":
            lines.append(f"  {where}: MISSED (whole in view in {row.frames_in_view} frames)")
        else:
            lines.append(f"  {where}: not in view (outside what the survey saw)")
        if row.status != "found" and r.search is not None:
            lines.append(f"    the search map: {r.search.why_missed(t.id)}")
    for f in r.false:
        lines.append(
            f"  hole {f.hole.id}: FALSE (best frame's score {f.hole.score:.2f}, seen in "
            f"{f.hole.sightings} frames;"
            f" nearest feature: {f.nearest}, {f.distance_m:.2f} m)"
        )
    per_ha = len(r.review) / (r.area_m2 / 1e4) if r.area_m2 else float("nan")
    lines.append(
        f"  for review (sent to the ground with their pictures, not in the mission nor "
        f"TAK until an operator confirms): {len(r.review)} holes, {r.review_true} at a "
        f"true opening, {per_ha:.0f} per hectare surveyed ({r.area_m2:.0f} m^2)"
    )
    lines.append(
        f"    expected at the default gate: about {REVIEW_PER_HA_MEASURED} per hectare "
        "(benchmarks/bench_tiers.py: 63 held-out simulated flights, structured-light sensor, "
        "33 in 0.17 ha)"
        + ("" if r.gate == AnnounceGate() else "; this flight's gate is not the default")
    )
    for h in r.review:
        lines.append(
            f"    hole {h.id}: REVIEW (p_hole {h.p_hole:.2f}, best frame's score {h.score:.2f}, "
            f"seen in {h.sightings} frames from {h.views} viewpoints)"
        )
    errors = [row.error_m for row in r.truth if row.status == "found"]
    in_view = sum(row.status != "not in view" for row in r.truth)
    err = (
        f"; position error mean {100 * float(np.mean(errors)):.0f} cm, max "
        f"{100 * max(errors):.0f} cm"
        if errors
        else ""
    )
    lines.append(
        f"  => holes found (announced + for review): {len(r.confirmed) + len(r.review)}; "
        f"true holes found {r.found} of {in_view} in view, missed {r.missed}, "
        f"announced false {len(r.false)}" + err
    )
    if r.search is not None:
        s = r.search
        lines.append(
            f"search map: {s.searched_fraction:.1%} of the planned {s.area_m2:.0f} m2 searched "
            f"(coverage >= {s.threshold:g}: an access hole there would have been found with "
            f"that probability; {s.frames} frames fused)" + (f"; {s.note}" if s.note else "")
        )
    if r.latency_s:
        lines.append(
            f"  first sighting -> announcement: median {statistics.median(r.latency_s):.1f} s, "
            f"max {max(r.latency_s):.1f} s (autopilot clock)"
        )
    if r.review_latency_s:
        lines.append(
            f"  first sighting -> sent for review: median "
            f"{statistics.median(r.review_latency_s):.1f} s, max {max(r.review_latency_s):.1f} s"
        )
    gcs = f"ground station: {len(r.announcements)} STATUSTEXT announcements"
    if r.capture_s > 0:
        gcs += (
            f", {r.cards_sent} hole pictures sent ({r.card_bytes} B, "
            f"{r.card_bytes / r.capture_s:.0f} B/s over the flight), "
            f"{r.pictures_at_ground} of {len(r.confirmed)} announced holes have theirs, "
            f"{r.map_tiles_at_ground} live-map tiles"
        )
    if r.mission_items is not None:
        gcs += f", downloaded a mission of {r.mission_items} hole waypoints (component 191)"
    if r.mission_error is not None:
        gcs += f"; {r.mission_error}"
    lines.append(gcs)
    lines.append(f"files in {r.out}:")
    lines += [f"  flight log  {p}" for p in r.log_files]
    lines += [f"  {kind:<11} {p}" for kind, p in r.files]
    lines.append(
        f"reprocess it: holescan reprocess {' '.join(str(p) for p in r.log_files)} "
        f"--out {r.out / 'reprocessed'}"
    )
    lines.append(f"({r.elapsed_s:.0f} s in all)")
    return lines
