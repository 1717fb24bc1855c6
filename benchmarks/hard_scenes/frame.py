"""One frame: plan -> world -> rays -> colour and depth -> truth."""

from __future__ import annotations

import numpy as np
from camera import Intrinsics, ground_at, pixel_dirs
from features import OPENINGS, apply_features
from labels import hole_annotation, opening_view, pixel_objects, region_entry, shadow_entries
from plan import sample_plan
from raycast import SURF_NONE, cast
from sensor import structured_light, xtion_depth
from shade import develop, radiance
from terrain import build_terrain
from world import NO_RETURN, Grid, caster_field, horizon_field

from holescan.sim.registration_bands import draw_bands

#: Frames per recording: consecutive frames share their border bands (one registration).
RECORDING_FRAMES = 10

REGION_KINDS = (
    "no_return_metal",
    "no_return_puddle",
    "no_return_plastic",
    "mound",
    "ledge",
    "steep_slab",
)


def make_grid(intr: Intrinsics, R, C, cell: float, margin: float = 0.6) -> Grid:
    """A grid under everything the camera can see between z = +1.6 and z = -1.3."""
    W, H = intr.width, intr.height
    t = np.linspace(0, 1, 33)
    u = np.concatenate([t * W, np.full(33, W), t * W, np.zeros(33)]) - 0.5
    v = np.concatenate([np.zeros(33), t * H, np.full(33, H), t * H]) - 0.5
    pts = np.concatenate([ground_at(intr, R, C, u, v, z)[:, :2] for z in (1.6, -1.3)])
    lo, hi = pts.min(0) - margin, pts.max(0) + margin
    nx, ny = np.ceil((hi - lo) / cell).astype(int) + 1
    grid = Grid(float(lo[0]), float(lo[1]), int(nx), int(ny), cell)
    seen = ground_at(intr, R, C, u, v, 0.0)[:, :2]
    grid.focus = (seen.min(0) - 0.5, seen.max(0) + 0.5)  # where the rubble is in view
    return grid


def _r(v, nd=3):
    return round(float(v), nd)


def render_frame(
    seed: int,
    index: int,
    intr_full: Intrinsics,
    scale: float = 1.0,
    sensor_model: str = "structured-light",
) -> dict:
    ss = np.random.SeedSequence([seed, index])
    r_plan, r_world, r_light, r_sensor = (np.random.default_rng(s) for s in ss.spawn(4))
    # Its own stream, so that the scenes are the same whichever sensor model renders them.
    r_sl = np.random.default_rng(np.random.SeedSequence([seed, index, 0x5E]))
    # The unread border bands are the recording's (the registration), not the frame's: one
    # draw per RECORDING_FRAMES consecutive frames, from a stream of its own.
    recording = index // RECORDING_FRAMES
    r_bands = np.random.default_rng(np.random.SeedSequence([seed, recording, 0xBA4D]))
    intr = intr_full.scaled(scale)
    W, H = intr.width, intr.height
    plan = sample_plan(r_plan, intr)
    R, C, light = plan.R, plan.C, plan.light
    grid = make_grid(intr, R, C, 0.01 if scale >= 0.75 else 0.02)
    terrain = build_terrain(grid, r_world)
    boxes, openings = apply_features(grid, r_world, plan.features)
    grid.finish()
    D, axial = pixel_dirs(intr, R)
    hits = cast(grid, boxes, intr, R, C, D)
    hc = caster_field(grid, boxes)
    sunny = light["sun_strength"] > 0
    horizon = (
        horizon_field(
            hc, np.radians(light["sun_azimuth_deg"]), np.radians(light["sun_elevation_deg"])
        )
        if sunny
        else None
    )
    lin = radiance(grid, boxes, hits, D, light, hc, horizon, r_light).reshape(H, W, 3)
    rgb = develop(r_light, lin, light, intr)

    Z = np.where(np.isfinite(hits.t), hits.t * axial, np.inf).reshape(H, W)
    obj, stain = pixel_objects(grid, boxes, hits)
    mats = np.full(len(D), -1, np.int16)
    top = hits.surf == 1
    mats[top] = grid.nearest(grid.mat_top, hits.pos[top, 0], hits.pos[top, 1])
    bx = hits.surf == 4
    if bx.any():
        mats[bx] = np.array([b.material for b in boxes])[hits.box[bx]]
    no_ret = np.isin(mats, NO_RETURN).reshape(H, W)
    cos_inc = np.abs(np.sum(hits.normal * D, 1)).reshape(H, W)
    if sensor_model == "structured-light":
        bands = draw_bands(r_bands, W)
        depth, rgb, sensor = structured_light(
            r_sl, intr, Z, rgb, no_ret, stain.reshape(H, W), plan.max_range, bands
        )
        sensor["recording"] = recording
    else:
        depth, sensor = xtion_depth(r_sensor, intr, Z, no_ret, cos_inc, plan.max_range)

    beyond = np.isfinite(Z) & (plan.max_range < Z)
    anns, distractors = [], []
    min_px = max(int(60 * scale * scale), 6)
    hole_full = np.zeros(H * W, bool)
    for f in plan.features:
        if f["kind"] not in OPENINGS or f["id"] not in openings:
            continue
        view = opening_view(intr, R, C, D, hits, grid, openings[f["id"]])
        if f["kind"] == "hole":
            hole_full[view["full"]] = True
            a = hole_annotation(f, view, depth, beyond, plan.max_range, scale)
            if a is not None:
                anns.append(a)
        else:
            e = region_entry(f["kind"], f["id"], view["vis"], W, depth, min_px)
            if e is not None:
                e["size_m"] = [_r(v) for v in f["size_m"]]
                e["inscribed_m"] = _r(f["inscribed_m"])
                if f["kind"] == "filled_opening":
                    e["fill_depth_m"] = _r(f["fill_depth"])
                distractors.append(e)
    for f in plan.features:
        k = f["kind"]
        if k in REGION_KINDS or k == "stain":
            pix = np.flatnonzero((stain if k == "stain" else obj) == f["id"])
            e = region_entry(k, f["id"], pix, W, depth, min_px)
            if e is not None:
                distractors.append(e)
        occ = f.get("occluder") if k == "hole" else None
        if occ:
            e = region_entry(
                "occluding_slab", occ["id"], np.flatnonzero(obj == occ["id"]), W, depth, min_px
            )
            if e is not None:
                distractors.append(e)
    if sunny:
        hit = hits.surf != SURF_NONE
        deep = np.zeros(len(D), bool)
        deep[hit] = horizon.bilinear(hits.pos[hit, 0], hits.pos[hit, 1]) - hits.pos[hit, 2] > 0.25
        deep &= ~hole_full & ~no_ret.ravel()
        distractors += shadow_entries(deep.reshape(H, W), depth, int(0.01 * H * W))

    absorbing = sensor.get("absorbing_stains", {})
    for e in distractors:
        if e["kind"] == "stain" and e.get("feature_id") in absorbing:
            e["ir_unread"] = absorbing[e["feature_id"]]  # soot, char, wet: few readings
    cam = {k: (_r(v) if isinstance(v, float) else v) for k, v in plan.camera.items()}
    scene = {
        "seed": seed,
        "index": index,
        **cam,
        "max_range_m": _r(plan.max_range),
        # The world's vertical (up) in the camera frame: horizontal errors are measured
        # perpendicular to it.
        "up_cam": [_r(float(c), 5) for c in R[2, :]],
        "range_limit_in_view": bool(beyond.any()),
        "beyond_range_frac": _r(beyond.mean()),
        "no_reading_frac": _r(np.mean(depth == 0)),
        "lighting": light["kind"],
        "sun_elevation_deg": _r(light["sun_elevation_deg"], 2),
        "sun_azimuth_deg": _r(light["sun_azimuth_deg"], 2),
        "sun_strength": _r(light["sun_strength"]),
        "dark_frame": light["dark_frame"],
        "exposure_target": _r(light["exposure_target"]),
        "colour_gains": [_r(g) for g in light["colour_gains"]],
        "rgb_mean": _r(rgb.mean(), 2),
        "terrain": terrain,
        "sensor": sensor,
        "sensor_model": sensor_model,
        "planned": [f["kind"] + ("+occluder" if f.get("occluder") else "") for f in plan.features],
    }
    return {
        "rgb": rgb,
        "depth": depth,
        "scene": scene,
        "annotations": anns,
        "distractors": distractors,
    }
