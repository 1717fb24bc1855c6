"""The structured-light sensor model: each effect on small seeded frames, exact properties."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from holescan.ground.recordings import unread_stats
from holescan.sim.registration_bands import (
    BAND_PROFILES,
    KINECT_HOST_REGISTERED,
    OPENNI2_REGISTERED,
    BandProfile,
    Bands,
    draw_bands,
)
from holescan.sim.structured_light import (
    Motion,
    SensorCamera,
    StructuredLight,
    Surface,
    predicted_shadow_px,
    structured_light_frame,
)

CAM = SensorCamera(fx=580.0, cx=319.5, cy=239.5)
# Only the effect under test: no bands, no misregistration, no fattening.
BARE = StructuredLight(
    bands=False,
    misregistration_px=(0.0, 0.0),
    misregistration_scale=0.0,
    max_time_offset_s=0.0,
    fattening_px=(0, 0),
    flying_fraction=(0.0, 0.0),
)


def _step(near_right: bool = True) -> np.ndarray:
    z = np.full((480, 640), 2.0, np.float32)
    if near_right:
        z[:, 320:] = 1.0
    else:
        z[:, :320] = 1.0
    return z


def test_same_seed_same_frame_other_seed_other_frame() -> None:
    z = _step()
    a = structured_light_frame(z, None, CAM, seed=4)
    b = structured_light_frame(z, None, CAM, seed=4)
    c = structured_light_frame(z, None, CAM, seed=5)
    assert np.array_equal(a.depth_mm, b.depth_mm) and a.draws == b.draws
    assert not np.array_equal(a.depth_mm, c.depth_mm)


def test_projector_shadow_lies_left_of_the_nearer_surface_at_the_predicted_width() -> None:
    out = structured_light_frame(_step(near_right=True), None, CAM, seed=1, params=BARE)
    gap = (out.depth_mm[100:380] == 0).mean(axis=0)
    cols = np.flatnonzero(gap > 0.9)
    predicted = predicted_shadow_px(1.0, 2.0, CAM.fx, BARE)  # 21.75 px, registered
    assert cols.max() == 319  # ends at the near edge, on its left
    assert abs(cols.size - predicted) <= 1.5
    # A nearer surface on the LEFT casts no shadow on its right.
    out = structured_light_frame(_step(near_right=False), None, CAM, seed=1, params=BARE)
    assert (out.depth_mm[100:380] == 0).mean() < 0.001


def test_registration_narrows_the_shadow_below_the_raw_width() -> None:
    raw = predicted_shadow_px(1.0, 2.0, 580.0, BARE, registered=False)
    assert raw == pytest.approx(1.2 * 43.5 * 0.5)
    assert predicted_shadow_px(1.0, 2.0, 580.0, BARE) == pytest.approx(raw - 580 * 0.025 * 0.5)


@pytest.mark.parametrize(("z_m", "step_mm"), [(2.0, 11.5), (2.5, 18.0), (3.0, 25.9)])
def test_depth_is_quantised_in_eighth_pixel_disparity_steps(z_m: float, step_mm: float) -> None:
    z = np.full((120, 160), z_m, np.float32)
    cam = SensorCamera(580.0, 79.5, 59.5)
    out = structured_light_frame(z, None, cam, seed=2, params=BARE)
    values = np.unique(out.depth_mm[out.depth_mm > 0]).astype(float)
    steps = np.diff(values)
    central = steps[np.abs(values[1:] - 1000 * z_m) < 40]
    assert central.size >= 2
    assert np.all(np.abs(central - step_mm) <= 1.0)


def test_flat_surface_noise_is_0_8_to_1_times_the_kinect_model() -> None:
    z = np.full((240, 320), 2.5, np.float32)
    cam = SensorCamera(580.0, 159.5, 119.5)
    out = structured_light_frame(z, None, cam, seed=3, params=BARE)
    read = out.depth_mm[out.depth_mm > 0].astype(float) / 1000.0
    model = 1.425e-3 * 2.5**2
    assert 0.75 * model < float(read.std()) < 1.05 * model
    assert out.draws.noise_fraction * model == pytest.approx(float(read.std()), rel=0.1)


def test_border_bands_are_unread_and_within_the_measured_widths() -> None:
    z = np.full((480, 640), 2.0, np.float32)
    profiles = {p.name: p for p in BAND_PROFILES}
    seen = set()
    for seed in range(8):
        out = structured_light_frame(z, None, CAM, seed=seed)
        d = out.draws
        prof = profiles[d.band_profile]
        seen.add(d.band_profile)
        assert prof.left_px[0] <= d.band_left <= prof.left_px[1]
        assert prof.right_px[0] <= d.band_right <= prof.right_px[1]
        assert prof.top_px[0] <= d.band_top <= prof.top_px[1]
        assert prof.bottom_px[0] <= d.band_bottom <= prof.bottom_px[1]
        dm = out.depth_mm
        assert not dm[:, 640 - d.band_right :].any() and not dm[: d.band_top].any()
        assert not dm[480 - d.band_bottom :].any() and not dm[:, : d.band_left].any()
        inner = dm[d.band_top + 5 : 475 - d.band_bottom, d.band_left + 5 : 635 - d.band_right]
        assert (inner > 0).mean() > 0.99
    assert seen == set(profiles)  # both ways of registering come up


def test_a_recordings_bands_are_the_same_in_every_frame() -> None:
    z = np.full((240, 320), 2.0, np.float32)
    cam = SensorCamera(290.0, 159.5, 119.5)
    bands = draw_bands(np.random.default_rng(5), 320)
    assert bands == draw_bands(np.random.default_rng(5), 320)
    for seed in range(4):  # other frames of the recording: other noise, the same bands
        d = structured_light_frame(z, None, cam, seed=seed, bands=bands).draws
        assert (d.band_left, d.band_top, d.band_right, d.band_bottom) == bands.ltrb
        assert d.band_profile == bands.profile
    # widths scale with the frame: half of 640 px, half the range
    for seed in range(20):
        b = draw_bands(np.random.default_rng(seed), 320, (OPENNI2_REGISTERED,))
        assert 9 <= b.left <= 14 and 6 <= b.right <= 10 and 7 <= b.top <= 9 and 2 <= b.bottom <= 4
    with pytest.raises(ValueError, match="profile"):
        draw_bands(np.random.default_rng(0), 640, ())
    with pytest.raises(ValueError, match="lo <= hi"):
        BandProfile("bad", (3, 2), (0, 1), (0, 1), (0, 1))


REAL_OPENNI2 = Path(__file__).resolve().parents[1] / "data" / "real" / "mrpt-openni2"
# FIELD-NOTES.md and docs/real-recordings.md: registered Kinect v1 frames (TUM, SUN RGB-D),
# (left, right, top, bottom) px as unread_stats measures them, and FIELD-NOTES' ranges.
REAL_KINECT_REGISTERED = [(14, 33, 14, 13), (2, 45, 15, 10), (2, 28, 12, 8), (11, 43, 13, 10)]


def _covers(prof: BandProfile, ltrb: tuple[int, int, int, int]) -> bool:
    ranges = (prof.left_px, prof.right_px, prof.top_px, prof.bottom_px)
    return all(lo <= v <= hi for v, (lo, hi) in zip(ltrb, ranges, strict=True))


def test_the_band_profiles_cover_the_real_frames() -> None:
    depth = cv2.imread(str(next((REAL_OPENNI2 / "depth").glob("*.png"))), cv2.IMREAD_UNCHANGED)
    s = unread_stats(depth // 5)  # TUM convention, 5000 per metre
    openni2 = (s.left, s.right, s.top, s.bottom)
    assert openni2 == (23, 16, 16, 6)  # docs/real-recordings.md
    assert _covers(OPENNI2_REGISTERED, openni2)
    assert all(_covers(KINECT_HOST_REGISTERED, b) for b in REAL_KINECT_REGISTERED)
    assert set(BAND_PROFILES) == {OPENNI2_REGISTERED, KINECT_HOST_REGISTERED}


def test_a_simulated_openni2_frame_measures_like_the_real_one() -> None:
    # the real frame's scene: a wall with shelves at 1.6-2.6 m; the bands measured with the
    # function that measured the real frame, misregistration (1-4 px) included
    z = np.full((480, 640), 2.2, np.float32)
    z[150:330, 100:560] = 1.9
    bands = Bands(23, 16, 16, 6, OPENNI2_REGISTERED.name)
    out = structured_light_frame(z, None, CAM, seed=11, bands=bands)
    s = unread_stats(out.depth_mm)
    for measured, drawn in zip((s.left, s.top, s.right, s.bottom), bands.ltrb, strict=True):
        assert drawn <= measured <= drawn + 5
    assert 0.08 < s.unread < 0.2  # real frame: 11.1 %


def test_absorbing_patch_loses_its_fraction_of_readings_in_blobs() -> None:
    z = np.full((240, 320), 2.0, np.float32)
    unread = np.zeros(z.shape, np.float32)
    unread[60:180, 80:240] = 0.65
    cam = SensorCamera(580.0, 159.5, 119.5)
    out = structured_light_frame(z, None, cam, seed=7, surface=Surface(unread), params=BARE)
    patch = out.depth_mm[60:180, 80:240] == 0
    assert 0.6 < patch.mean() < 0.7
    assert (out.depth_mm[:50] == 0).mean() < 0.01
    # Ragged blobs, not salt: an unread pixel's right neighbour is unread more often than
    # the patch's fraction (0.65 for independent pixels).
    assert (patch[:, :-1] & patch[:, 1:]).sum() > 0.72 * patch[:, :-1].sum()


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("frac", [0.55, 0.76])
def test_absorbing_dropouts_are_connected_clumps_with_read_islands(seed: int, frac: float) -> None:
    """A black stain on a plane (640 px frame): each patch loses its own fraction, the
    unread pixels form clumps tens of pixels across (most of them in one or a few
    components, as on real frames), and what is read stays in islands on the plane."""
    z = np.full((480, 640), 2.0, np.float32)
    unread = np.zeros(z.shape, np.float32)
    unread[150:270, 200:360] = frac  # a 120 x 160 px stain
    unread[350:390, 60:120] = 0.7  # a small second patch
    out = structured_light_frame(z, None, CAM, seed=seed, surface=Surface(unread), params=BARE)
    assert 10 <= out.draws.dropout_clump_px <= 18
    dm = out.depth_mm
    patch = dm[150:270, 200:360] == 0
    assert abs(patch.mean() - frac) < 0.02
    assert abs((dm[350:390, 60:120] == 0).mean() - 0.7) < 0.03
    _, _, stats, _ = cv2.connectedComponentsWithStats(patch.astype(np.uint8), connectivity=8)
    areas = np.sort(stats[1:, cv2.CC_STAT_AREA])[::-1]
    # Clumps, not specks: the three largest hold most of the unread pixels.
    assert areas[:3].sum() > 0.8 * patch.sum()
    # 4x4 blocks (the detector's work grid) wholly unread: a large share of the patch.
    blocks = patch.reshape(30, 4, 40, 4).all(axis=(1, 3))
    assert blocks.mean() > 0.3
    # The read islands lie on the plane (2 m, within quantisation and noise).
    read = dm[150:270, 200:360][~patch]
    assert read.size > 0 and np.abs(read.astype(np.float64) - 2000.0).max() < 40
    assert (dm[:100] == 0).mean() < 0.01


def test_grazing_surfaces_return_nothing() -> None:
    z = np.full((120, 160), 2.0, np.float32)
    cos = np.ones(z.shape, np.float32)
    cos[:, :80] = 0.05  # seen almost edge-on
    cam = SensorCamera(580.0, 79.5, 59.5)
    out = structured_light_frame(z, None, cam, seed=1, surface=Surface(None, cos), params=BARE)
    assert not out.depth_mm[:, :80].any() and (out.depth_mm[:, 80:] > 0).all()


def test_edges_fatten_the_near_surface_and_some_crossings_fly() -> None:
    z = _step(near_right=False)  # near on the left: no shadow at this edge
    params = StructuredLight(
        bands=False,
        misregistration_px=(0.0, 0.0),
        misregistration_scale=0.0,
        max_time_offset_s=0.0,
        fattening_px=(2, 2),
        flying_fraction=(0.1, 0.1),
    )
    out = structured_light_frame(z, None, CAM, seed=3, params=params)
    near = (out.depth_mm > 0) & (out.depth_mm < 1100)
    # The near surface reaches two pixels past its true edge (column 319).
    assert near[:, 321].mean() > 0.97 and near[:, 322].mean() < 0.03
    # Flying pixels (between the plateaus) at ~10 % of the rows' edge crossings.
    assert 0.06 < out.flying.any(axis=1).mean() < 0.14
    between = (out.depth_mm > 1100) & (out.depth_mm < 1900)
    assert np.array_equal(between, out.flying)


def test_misregistration_and_time_offset_shift_the_depth_against_the_colour() -> None:
    z = _step(near_right=False)
    still = StructuredLight(bands=False, fattening_px=(0, 0), flying_fraction=(0.0, 0.0))
    out = structured_light_frame(z, None, CAM, seed=9, params=still, motion=Motion((400.0, 0.0)))
    d = out.draws
    assert 1.0 <= float(np.hypot(*d.shift_px)) <= 4.0 and abs(d.time_offset_s) <= 0.016
    row = out.depth_mm[240]
    edge = int(np.flatnonzero((row > 0) & (row < 1100)).max()) + 1  # first far column
    expected = 320 - (d.shift_px[0] + 400.0 * d.time_offset_s) * d.scale
    assert abs(edge - expected) <= 2.0


def test_motion_blurs_the_colour_along_the_motion() -> None:
    rgb = np.zeros((60, 80, 3), np.uint8)
    rgb[:, 40:] = 200
    z = np.full((60, 80), 2.0, np.float32)
    cam = SensorCamera(580.0, 39.5, 29.5)
    out = structured_light_frame(z, rgb, cam, seed=1, motion=Motion((1000.0, 0.0), 0.01))
    assert out.rgb is not None
    row = out.rgb[30, :, 0].astype(int)
    ramp = np.flatnonzero((row > 10) & (row < 190))
    assert 6 <= ramp.size <= 12  # 10 px of blur: a ramp, not a step
    still = structured_light_frame(z, rgb, cam, seed=1)
    assert still.rgb is not None and np.array_equal(still.rgb, rgb)
