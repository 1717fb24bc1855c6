"""What a frame contains: camera pose and range, light, and where each feature goes.

Every feature is placed by picking a pixel, following its ray to the rubble datum (z = 0)
and refusing spots whose footprint (a circle) overlaps an earlier feature's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from camera import Intrinsics, axial_depth, ground_at, make_pose
from shapes import blob, inscribed_diameter, rect, strip

N_HOLES_P = (0.12, 0.36, 0.32, 0.20)
N_DISTRACTORS_P = (0.06, 0.20, 0.30, 0.24, 0.14, 0.06)
DISTRACTORS = {
    "no_return_metal": 1.0,
    "no_return_puddle": 1.0,
    "no_return_plastic": 0.8,
    "mound": 0.9,
    "ledge": 0.7,
    "steep_slab": 1.0,
    "slit": 1.0,
    "filled_opening": 1.0,
    "stain": 1.1,
}
STAIN_TINTS = ((1.0, 1.0, 1.0), (0.9, 0.8, 0.7), (0.7, 0.75, 0.9), (0.85, 0.9, 0.8))


@dataclass
class Plan:
    camera: dict
    R: np.ndarray
    C: np.ndarray
    max_range: float
    light: dict
    features: list


def sample_camera(rng: np.random.Generator, intr: Intrinsics):
    """Pose and range cut-off; a quarter of the frames see the range limit in the far part."""
    range_scene = bool(rng.random() < 0.25)
    for _ in range(200):
        tilt_dir, yaw = rng.uniform(0, 2 * np.pi, 2)
        if range_scene:
            h, tilt = rng.uniform(2.9, 3.5), np.radians(rng.uniform(14, 20))
        else:
            tilt = np.radians(rng.uniform(0, 4) if rng.random() < 0.3 else rng.uniform(4, 20))
            c = rng.uniform(3.5, 4.5)
            top = min(3.5, (c - 0.95) * np.cos(tilt))
            if top < 2.0:
                continue
            h = rng.uniform(2.0, top)
        R, C = make_pose(h, tilt, tilt_dir, yaw)
        if range_scene:
            # axial depth of the datum along the line from the image centre to its far edge
            d = np.array([np.cos(tilt_dir), np.sin(tilt_dir)])
            reach = min(
                abs(intr.width / 2 / d[0]) if d[0] else 1e9,
                abs(intr.height / 2 / d[1]) if d[1] else 1e9,
            )
            frac = rng.uniform(0.55, 0.92)
            u, v = intr.cx + d[0] * reach * frac, intr.cy + d[1] * reach * frac
            c = float(axial_depth(R, C, ground_at(intr, R, C, u, v))[0])
            if not 3.5 <= c <= 4.5:
                continue
        cam = {
            "height_m": h,
            "tilt_deg": np.degrees(tilt),
            "tilt_dir_deg": np.degrees(tilt_dir),
            "yaw_deg": np.degrees(yaw),
            "range_limit_scene": range_scene,
        }
        return cam, R, C, float(c)
    raise RuntimeError("no camera pose found")  # pragma: no cover - 200 tries always suffice


def sample_light(rng: np.random.Generator) -> dict:
    overcast = bool(rng.random() < 0.3)
    el = float(np.radians(rng.uniform(2, 16)))
    sun = 0.0 if overcast else float(rng.uniform(1.5, 4.5) * np.clip(np.sin(el) / 0.17, 0.35, 1.2))
    pink = rng.uniform(0, 0.5)
    zenith = (1 - pink) * np.array((0.42, 0.52, 0.85)) + pink * np.array((0.8, 0.55, 0.65))
    horizon = np.array((1.0, rng.uniform(0.5, 0.75), rng.uniform(0.3, 0.55)))
    if overcast:
        zenith = zenith * 0.4 + 0.6 * np.array((0.62, 0.63, 0.68))
        horizon = horizon * 0.4 + 0.6 * np.array((0.75, 0.70, 0.66))
    dark = bool(rng.random() < 0.25)
    cast = np.exp(rng.normal(0, 0.08, 3))
    if rng.random() < 0.3:
        cast = cast * np.array(
            ((1.25, 1.0, 0.75), (0.8, 0.95, 1.25), (0.9, 1.15, 0.9))[rng.integers(3)]
        )
    return {
        "kind": "overcast" if overcast else "low_sun",
        "sun_elevation_deg": float(np.degrees(el)),
        "sun_azimuth_deg": float(rng.uniform(0, 360)),
        "sun_strength": sun,
        "sun_rgb": [1.0, float(rng.uniform(0.55, 0.8)), float(rng.uniform(0.3, 0.55))],
        "zenith_rgb": zenith.tolist(),
        "horizon_rgb": horizon.tolist(),
        "dark_frame": dark,
        "exposure_target": float(rng.uniform(0.07, 0.16) if dark else rng.uniform(0.2, 0.45)),
        "colour_gains": cast.tolist(),
    }


class Placer:
    def __init__(self, rng, intr: Intrinsics, R, C, max_range: float):
        self.rng, self.intr, self.R, self.C, self.max_range = rng, intr, R, C, max_range
        self.taken: list[tuple[float, float, float]] = []

    def free(self, x, y, r, skip: int = 0) -> bool:
        """No overlap with the footprints placed so far (but the last ``skip`` ones)."""
        taken = self.taken[: len(self.taken) - skip]
        return all(np.hypot(x - a, y - b) > r + q + 0.1 for a, b, q in taken)

    def z(self, x, y, z=0.0) -> float:
        return float(axial_depth(self.R, self.C, np.array([x, y, z]))[0])

    def spot(self, r: float, margin_px: float = 0.0, ok=None, uv=None, tries: int = 60):
        """A free ground point for a footprint of radius r (and pixel margin), or None."""
        W, H = self.intr.width, self.intr.height
        if uv:
            u, v = np.array([uv() for _ in range(tries)]).T
        else:
            u = self.rng.uniform(margin_px, W - margin_px, tries)
            v = self.rng.uniform(margin_px, H - margin_px, tries)
        for x, y, _ in ground_at(self.intr, self.R, self.C, u, v):
            if self.free(x, y, r) and (ok is None or ok(x, y)):
                self.taken.append((x, y, r))
                return float(x), float(y)
        return None

    def r_px(self, r: float) -> float:
        return self.intr.fx * r / (-self.C[2] / self.R[2, 2])


def hole_shape(rng, a_max: float = 1.6, min_in: float = 0.42):
    """An access-hole outline: about a x b m (0.6-1.6 x 0.45-1.3), inscribed disk >= 0.42 m."""
    for _ in range(50):
        a = rng.uniform(0.6, a_max)
        b = rng.uniform(max(0.45, 0.45 * a), min(a, 1.3))
        poly = blob(rng, (0, 0), a, b, rng.uniform(0, np.pi), rough=rng.uniform(0.03, 0.12))
        d = inscribed_diameter(poly)
        if d >= min_in:
            return a, b, poly, d
    return a, b, poly, d  # pragma: no cover


def plan_hole(rng, pl: Placer, fid: int, special: str) -> list[dict]:
    """An access hole: no floor in range (void) or a debris floor 0.45-0.8 m down."""
    floor = "void" if special == "range_limit" or rng.random() < 0.55 else "debris"
    depth = float(rng.uniform(0.45, 0.8)) if floor == "debris" else None
    c = pl.max_range
    W, H = pl.intr.width, pl.intr.height
    side = int(rng.integers(4))
    for attempt in range(4):
        a, b, poly0, d_in = hole_shape(rng, 1.6 if attempt < 2 else 1.0)
        r = float(np.max(np.linalg.norm(poly0, axis=1)))

        def ok(x, y, r=r):
            if special != "range_limit":
                return pl.z(x, y) < c - 0.2 and (depth is None or pl.z(x, y, -depth) < c - 0.12)
            away = np.array([x - pl.C[0], y - pl.C[1]])
            far = np.array([x, y]) + away / max(np.linalg.norm(away), 1e-6) * (r + 0.05)
            return pl.z(x, y) < c - 0.08 and pl.z(far[0], far[1]) > c + 0.04

        rp = pl.r_px(r)

        def border_uv(rp=rp):
            e = rng.uniform(-0.3, 0.6) * rp
            return (
                (e, rng.uniform(0.2, 0.8) * H),
                (W - e, rng.uniform(0.2, 0.8) * H),
                (rng.uniform(0.2, 0.8) * W, e),
                (rng.uniform(0.2, 0.8) * W, H - e),
            )[side]

        margin = 0.0 if special == "border" else min(rp + 4, 0.4 * H)
        uv = border_uv if special == "border" else None
        pos = pl.spot(r + 0.2, margin, ok, uv, tries=150)
        if pos is not None:
            break
    else:
        return []
    poly = poly0 + np.array(pos)
    cav = float(rng.uniform(0.15, 0.5)) if rng.random() < (0.6 if floor == "void" else 0.4) else 0.0
    thick = float(rng.uniform(0.12, 0.35 if depth is None else min(0.35, depth - 0.2)))
    f = {
        "kind": "hole",
        "id": fid,
        "floor": floor,
        "poly": poly,
        "size_m": [a, b],
        "inscribed_m": d_in,
        "depth": depth,
        "cavity": cav,
        "thickness": thick,
        "lip": float(rng.uniform(0.15, 0.45)) if rng.random() < 0.5 else 0.0,
        "placement": special,
        "occluder": None,
    }
    if special == "normal" and rng.random() < 0.3:
        # the slab lies mostly on the camera's side of the hole: a nearer slab edge
        to_cam = np.arctan2(pl.C[1] - pos[1], pl.C[0] - pos[0])
        u_ang = float(
            to_cam + rng.uniform(-1.2, 1.2) if rng.random() < 0.75 else rng.uniform(0, 2 * np.pi)
        )
        u = np.array([np.cos(u_ang), np.sin(u_ang)])
        perp = float(np.ptp(poly0 @ np.array([-u[1], u[0]])))
        occ = {
            "id": fid + 1,
            "dir": u_ang,
            "cover": float(rng.uniform(0.2, 0.85)),
            "clearance": float(rng.uniform(0.03, 0.35)),
            "L": float(rng.uniform(0.9, 1.8)),
            "W": float(perp + rng.uniform(0.3, 0.8)),
            "thk": float(rng.uniform(0.12, 0.25)),
            "shade": float(rng.uniform(0.8, 1.2)),
        }
        sc = np.array(pos) + u * (r * (1 - occ["cover"]) + occ["L"] / 2)
        rs = float(np.hypot(occ["L"], occ["W"]) / 2)
        if pl.free(sc[0], sc[1], rs - 0.3, skip=1):
            pl.taken.append((float(sc[0]), float(sc[1]), rs - 0.3))
            f["occluder"] = occ
    return [f]


def plan_distractor(rng, pl: Placer, kind: str, fid: int) -> dict | None:
    f: dict = {"kind": kind, "id": fid}
    c = pl.max_range

    def in_range(x, y):
        return pl.z(x, y) < c - 0.1

    if kind in ("slit", "filled_opening", "no_return_puddle", "no_return_plastic", "stain"):
        if kind == "slit":
            length, width = rng.uniform(0.6, 1.8), rng.uniform(0.08, 0.26)
            poly0 = strip(rng, (0, 0), length, width, rng.uniform(0, np.pi))
            f.update(
                size_m=[length, width],
                floor="void",
                inscribed_m=inscribed_diameter(poly0),
                cavity=float(rng.uniform(0.1, 0.3)) if rng.random() < 0.5 else 0.0,
                thickness=float(rng.uniform(0.1, 0.3)),
                lip=0.0,
            )
        elif kind == "filled_opening":
            a, b, poly0, d_in = hole_shape(rng)
            f.update(
                size_m=[a, b],
                inscribed_m=d_in,
                floor="fill",
                fill_depth=float(rng.uniform(0.08, 0.16)),
                cavity=0.0,
                lip=float(rng.uniform(0.15, 0.4)) if rng.random() < 0.5 else 0.0,
            )
        else:
            lo, hi = (0.4, 1.5) if kind == "stain" else (0.6, 1.6)
            a = rng.uniform(lo, hi)
            b = rng.uniform(max(lo * 0.75, 0.45 * a), a)
            poly0 = blob(rng, (0, 0), a, b, rng.uniform(0, np.pi), rough=rng.uniform(0.05, 0.15))
            f["size_m"] = [a, b]
            if kind == "stain":
                f.update(
                    strength=float(rng.uniform(0.55, 0.97)),
                    tint=STAIN_TINTS[rng.integers(len(STAIN_TINTS))],
                )
            if kind == "no_return_plastic":
                f["colour"] = int(rng.integers(5))
        r = float(np.max(np.linalg.norm(poly0, axis=1)))
        need = in_range if kind in ("slit", "filled_opening") else None
        pos = pl.spot(r + 0.15, 0.0, need)
        if pos is None:
            return None
        f["poly"] = poly0 + np.array(pos)
        return f
    if kind == "no_return_metal":
        L = rng.uniform(0.6, 1.6)
        f.update(
            L=L,
            W=rng.uniform(0.5, min(L, 1.2)),
            yaw=rng.uniform(0, np.pi),
            slope=rng.normal(0, 0.12, 2).tolist(),
            corrugation=float(rng.uniform(0.05, 0.12)) if rng.random() < 0.6 else 0.0,
        )
        r = np.hypot(f["L"], f["W"]) / 2
    elif kind == "mound":
        f.update(
            R=rng.uniform(0.5, 1.3),
            H=rng.uniform(0.35, min(1.0, pl.C[2] - 1.1)),
            aniso=rng.uniform(0.6, 1.0),
            angle=rng.uniform(0, np.pi),
            p=rng.uniform(2, 5),
        )
        r = 1.3 * f["R"]
    elif kind == "ledge":
        L, W = rng.uniform(1.0, 2.2), rng.uniform(0.8, 1.6)
        f.update(L=L, W=W, H=rng.uniform(0.35, min(0.9, pl.C[2] - 1.1)), yaw=rng.uniform(0, np.pi))
        r = np.hypot(L, W) / 2
    else:  # steep_slab
        pitch = np.radians(rng.uniform(35, 75))
        L = min(rng.uniform(0.8, 1.7), (pl.C[2] - 1.0) / np.sin(pitch))
        f.update(
            L=L,
            W=rng.uniform(0.5, 1.2),
            thk=rng.uniform(0.1, 0.22),
            yaw=rng.uniform(0, 2 * np.pi),
            pitch=pitch,
            shade=rng.uniform(0.8, 1.2),
        )
        r = L * np.cos(pitch) + 0.3
    pos = pl.spot(float(r), 0.0)
    if pos is None:
        return None
    f["x"], f["y"] = pos
    if kind == "ledge":
        f["poly"] = rect(pos, f["L"], f["W"], f["yaw"], jitter=0.03, rng=rng)
    return f


def sample_plan(rng: np.random.Generator, intr: Intrinsics) -> Plan:
    cam, R, C, max_range = sample_camera(rng, intr)
    light = sample_light(rng)
    pl = Placer(rng, intr, R, C, max_range)
    feats: list[dict] = []
    fid = 1
    n_holes = int(rng.choice(4, p=N_HOLES_P))
    for i in range(n_holes):
        special = "normal"
        if i == 0 and cam["range_limit_scene"] and rng.random() < 0.7:
            special = "range_limit"
        elif rng.random() < 0.15:
            special = "border"
        got = plan_hole(rng, pl, fid, special)
        if not got and special != "normal":  # no room where it was meant to go
            got = plan_hole(rng, pl, fid, "normal")
        feats += got
        fid += 2
    kinds = list(DISTRACTORS)
    w = np.array([DISTRACTORS[k] for k in kinds])
    n_d = int(rng.choice(len(N_DISTRACTORS_P), p=N_DISTRACTORS_P))
    for _ in range(n_d):
        for _attempt in range(3):  # no room for this kind: try another
            f = plan_distractor(rng, pl, kinds[rng.choice(len(kinds), p=w / w.sum())], fid)
            fid += 1
            if f is not None:
                feats.append(f)
                break
    return Plan(cam, R, C, max_range, light, feats)
