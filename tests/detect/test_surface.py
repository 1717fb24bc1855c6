"""An unread patch that is a surface (soot, char, wet) against a void: the rim-plane test.

Seeded synthetic frames through the structured-light model: a rough plane of rubble 2.5 m
away holding either a black stain that swallows 55-76 % of the pattern in clumps, or a
real hole of the same outline and darkness whose floor is partly read (wet, dropouts).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from holescan.detect import DEFAULT, CameraIntrinsics, Detection, detect_holes
from holescan.detect._geometry import fit_plane, rays_of
from holescan.detect._regions import block_depth
from holescan.detect._surface import PlaneEvidence, plane_evidence, surface_factor
from holescan.sim.structured_light import (
    SensorCamera,
    StructuredLight,
    Surface,
    structured_light_frame,
)

CAM = CameraIntrinsics.xtion()
SENSOR = SensorCamera(CAM.fx, CAM.cx, CAM.cy)
OFF = replace(DEFAULT, options=replace(DEFAULT.options, surface_plane=False))
ANNOUNCE = 0.9
CLUMP_PX = (24.0, 32.0)


def _frame(
    kind: str, seed: int
) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """(rgb, depth, true box) of a stain or a hole (1.2 x 0.9 m) in rough rubble."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    z0 = float(rng.uniform(2.2, 2.8))
    bumps = cv2.GaussianBlur(rng.normal(0, 1, (480, 640)).astype(np.float32), (0, 0), 12)
    z = z0 + 0.0004 * (v - 240) + 0.02 * bumps / float(bumps.std())
    cu, cv_ = rng.uniform(260, 380), rng.uniform(200, 280)
    a, b = 0.6 * CAM.fx / z0, 0.45 * CAM.fx / z0
    inside = ((u - cu) / a) ** 2 + ((v - cv_) / b) ** 2 < 1.0
    texture = cv2.GaussianBlur(rng.normal(0, 1, (480, 640)).astype(np.float32), (0, 0), 2)
    grey = np.clip(120 + 25 * texture / float(texture.std()), 0, 255)
    unread = np.zeros((480, 640), np.float32)
    if kind == "stain":
        grey = np.where(inside, grey * rng.uniform(0.3, 0.55), grey)
        unread[inside] = rng.uniform(0.55, 0.76)
    else:  # a void: walls, a floor 1.2-1.5 m below, partly wet, dark inside
        z = np.where(inside, z + rng.uniform(1.2, 1.5), z)
        grey = np.where(inside, grey * 0.25, grey)
        unread[inside] = 0.6
    rgb = np.repeat(grey[..., None], 3, axis=2).astype(np.uint8)
    params = StructuredLight(max_range_m=4.5, fade_range_m=4.2, dropout_clump_px=CLUMP_PX)
    fr = structured_light_frame(
        z, rgb, SENSOR, seed=seed, surface=Surface(ir_unread=unread), params=params
    )
    assert fr.rgb is not None
    return fr.rgb, fr.depth_mm, (cu - a, cv_ - b, 2 * a, 2 * b)


def _on(dets: list[Detection], box: tuple[float, float, float, float]) -> list[Detection]:
    x, y, w, h = box
    out = []
    for d in dets:
        dx, dy, dw, dh = d.box
        ix = max(0.0, min(x + w, dx + dw) - max(x, dx))
        iy = max(0.0, min(y + h, dy + dh) - max(y, dy))
        if ix * iy > 0.3 * dw * dh:
            out.append(d)
    return out


def _evidence(kind: str, seed: int) -> PlaneEvidence:
    """The plane test on the unread region inside the true outline (4x4 work
    grid, as the detector sees it)."""
    _, depth, box = _frame(kind, seed)
    z, _ = block_depth(depth, 4, CAM.depth_unit_m)
    cam = CAM.scaled(0.25)
    read = ~np.isnan(z)
    x, y, w, h = (round(c / 4) for c in box)
    outline = np.zeros(z.shape, np.uint8)
    cv2.ellipse(outline, (x + w // 2, y + h // 2), (w // 2, h // 2), 0, 0, 360, 1, -1)
    region = (outline > 0) & ~read
    ring = (cv2.dilate(outline, np.ones((5, 5), np.uint8)) > 0) & (outline == 0) & read
    rv, ru = np.nonzero(ring)
    rim = rays_of(ru.astype(float), rv.astype(float), cam) * z[ring].astype(float)[:, None]
    normal, centre = fit_plane(rim)
    if normal @ centre > 0:
        normal = -normal
    return plane_evidence(region, z, read, (0, 0), cam, (normal, centre), rim)


def test_stain_islands_lie_on_the_rim_plane_a_voids_readings_behind() -> None:
    stains = [_evidence("stain", seed) for seed in range(8)]
    holes = [_evidence("hole", seed) for seed in range(8)]
    # Each stain's readings inside lie on its rim plane, none behind; a hole's behind.
    assert all(ev.on_plane > 0.15 and ev.behind < 0.02 for ev in stains), stains
    assert all(ev.on_plane < 0.02 and ev.behind > 0.1 for ev in holes), holes
    # The score of a hole is never touched; most stains' fall well down.
    assert all(surface_factor(ev) == 1.0 for ev in holes)
    factors = sorted(surface_factor(ev) for ev in stains)
    assert factors[len(factors) // 2] < 0.7 and factors[0] <= 0.4


@pytest.mark.parametrize("seed", range(6))
def test_black_stain_on_a_plane_is_not_announced(seed: int) -> None:
    rgb, depth, box = _frame("stain", seed)
    unread = depth[int(box[1]) : int(box[1] + box[3]), int(box[0]) : int(box[0] + box[2])] == 0
    assert 0.4 < unread.mean() < 0.8  # the stain really does look unread
    on = _on(detect_holes(rgb, depth, CAM, DEFAULT), box)
    assert all((d.p_hole or 0.0) < ANNOUNCE for d in on), [(d.box, d.p_hole) for d in on]
    # The plane test only ever lowers a candidate's score.
    without = _on(detect_holes(rgb, depth, CAM, OFF), box)
    best_with = max((d.score for d in on), default=0.0)
    assert best_with <= max((d.score for d in without), default=0.0)


@pytest.mark.parametrize("seed", range(6))
def test_real_hole_with_dropouts_keeps_its_score(seed: int) -> None:
    rgb, depth, box = _frame("hole", seed)
    dets = detect_holes(rgb, depth, CAM, DEFAULT)
    hit = [d for d in _on(dets, box) if d.p_hole is not None and d.p_hole >= ANNOUNCE]
    assert hit, [(d.box, d.p_hole) for d in dets]
    without = _on(detect_holes(rgb, depth, CAM, OFF), box)
    assert max(d.score for d in hit) == pytest.approx(max(d.score for d in without))


def test_a_candidate_the_plane_test_lowers_stays_a_detection() -> None:
    """The hole-level vote counts the views the frame-level test lowered: the lowest score
    the test can leave (the gate times the floor) is above the detector's score cut; and a
    void's detections carry their reading, behind the plane."""
    from holescan.detect import plane_verdict
    from holescan.detect._measure import SURFACE_GATE
    from holescan.detect._surface import SURFACE_FLOOR

    assert DEFAULT.min_score < SURFACE_GATE * SURFACE_FLOOR
    for seed in range(3):
        rgb, depth, box = _frame("hole", seed)
        (d,) = _on(detect_holes(rgb, depth, CAM, DEFAULT), box)
        assert d.beyond_range and d.inside_on_plane is not None
        assert plane_verdict(d.inside_on_plane, d.inside_behind) == "behind"
