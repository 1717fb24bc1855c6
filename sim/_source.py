"""The simulated Xtion: the synthetic rubble world rendered from the vehicle's true pose.

The world (:func:`sim.make_world`) is a metric height field in a local ENU frame
whose origin (the field's south-west corner, height 0) sits at a WGS84 point. At each frame
time the source asks a pose provider (the simulated autopilot's *truth*) where the vehicle
is, turns it through the camera mount into a camera pose in the world and renders the
frame as the Xtion would deliver it (noise, dropouts, dim light). Frames are paced at
``fps`` on the monotonic clock; when rendering is slower than that, frames come late and
:attr:`SimSource.late_frames` counts them.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from holescan.detect import CameraIntrinsics, Frame
from holescan.geotag import (
    CameraMount,
    LocalFrame,
    VehiclePose,
    camera_pose_local,
)
from holescan.sim._camera_model import CameraPose, Conditions, project_points, random_conditions
from holescan.sim._render import GtBox, render
from holescan.sim._world import RubbleWorld
from holescan.sim.registration_bands import draw_bands
from holescan.sim.structured_light import Motion

PoseAtMono = Callable[[int], VehiclePose]


@dataclass(frozen=True)
class WorldAnchor:
    """Where the world's origin (south-west corner, height 0) is on the Earth."""

    lat_deg: float
    lon_deg: float
    alt_m: float

    def to_world(self, lat_deg: float, lon_deg: float, alt_m: float) -> np.ndarray:
        e, n, u = self.frame.to_enu(lat_deg, lon_deg, alt_m)
        return np.array([float(e), float(n), float(u)])

    def to_geodetic(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        lat, lon, alt = self.frame.to_geodetic_alt(x, y, z)
        return float(lat), float(lon), float(alt)

    @property
    def frame(self) -> LocalFrame:
        """The world frame: ENU metres at the anchor (:class:`geotag.LocalFrame`)."""
        return LocalFrame(self.lat_deg, self.lon_deg, self.alt_m)


def camera_pose_in_world(pose: VehiclePose, mount: CameraMount, anchor: WorldAnchor) -> CameraPose:
    """The camera's pose in the world frame for a vehicle pose (mount offset included)."""
    local = camera_pose_local(anchor.frame, mount, pose)
    return CameraPose(local.position_m, local.rotation)


#: Time step over which the camera's image motion is measured.
_MOTION_DT_NS = 10_000_000
#: Seed-stream tag of a flight's border bands.
_BANDS_STREAM = 0xBA4D
#: Colour exposure at dawn (s): what the motion blurs over.
_EXPOSURE_S = 0.012


def image_motion(
    pose: CameraPose, later: CameraPose, camera: CameraIntrinsics, dt_s: float
) -> Motion:
    """Image motion (px/s) of the scene point on the optical axis, 2.5 m ahead, between two
    camera poses ``dt_s`` apart."""
    point = pose.position + pose.rotation[:, 2] * 2.5
    uv, z = project_points(camera, later, point[None, :])
    if not np.isfinite(uv).all() or z[0] <= 0:
        return Motion((0.0, 0.0), _EXPOSURE_S)
    du = (float(uv[0, 0]) - camera.cx) / dt_s
    dv = (float(uv[0, 1]) - camera.cy) / dt_s
    return Motion((du, dv), _EXPOSURE_S)


class SimSource:
    """A :class:`detect.FrameSource` rendering ``world`` from ``pose_at_mono(t)``.

    Parameters
    ----------
    world, anchor : the rubble field and where it lies on the Earth.
    pose_at_mono : vehicle pose at a companion monotonic time (the simulator's truth).
    camera, mount : intrinsics and how the camera sits on the vehicle.
    fps : frame rate; max_frames : stop after this many (None: run until closed).
    seed : noise of the frames (deterministic for a given pose sequence) and the flight's
        unread border bands (``bands``, drawn once: :mod:`sim.registration_bands`).
    """

    def __init__(
        self,
        world: RubbleWorld,
        anchor: WorldAnchor,
        pose_at_mono: PoseAtMono,
        camera: CameraIntrinsics | None = None,
        mount: CameraMount | None = None,
        *,
        fps: float = 30.0,
        max_frames: int | None = None,
        seed: int = 0,
        conditions: Conditions | None = None,
    ) -> None:
        self.world = world
        self.anchor = anchor
        self.camera = camera or CameraIntrinsics.xtion()
        self.mount = mount or CameraMount()
        self.fps = fps
        self.max_frames = max_frames
        self._pose_at_mono = pose_at_mono
        self._rng = np.random.default_rng(seed)
        self._conditions = conditions or Conditions()
        # The unread border bands are the registration's: one draw for the whole flight, from
        # a stream of their own.
        self.bands = draw_bands(np.random.default_rng([seed, _BANDS_STREAM]), self.camera.width)
        self._closed = False
        self.late_frames = 0
        self.render_ms: list[float] = []
        self.truth: dict[int, tuple[VehiclePose, tuple[GtBox, ...]]] = {}

    def __enter__(self) -> SimSource:
        self._closed = False
        return self

    def __exit__(self, *exc: object) -> None:
        self._closed = True

    def render_at(
        self, t_mono_ns: int
    ) -> tuple[np.ndarray, np.ndarray, VehiclePose, tuple[GtBox, ...]]:
        """Render the frame seen at monotonic time ``t_mono_ns`` (no pacing)."""
        pose = self._pose_at_mono(t_mono_ns)
        cam_pose = camera_pose_in_world(pose, self.mount, self.anchor)
        cond = random_conditions(self._rng, self._conditions)
        later = camera_pose_in_world(
            self._pose_at_mono(t_mono_ns + _MOTION_DT_NS), self.mount, self.anchor
        )
        motion = image_motion(cam_pose, later, self.camera, _MOTION_DT_NS * 1e-9)
        rgb, depth, boxes = render(
            self.world, cam_pose, self.camera, self._rng, cond, motion, self.bands
        )
        return rgb, depth, pose, boxes

    def __iter__(self) -> Iterator[Frame]:
        period_ns = round(1e9 / self.fps)
        t0 = time.monotonic_ns()
        i = 0
        while not self._closed and (self.max_frames is None or i < self.max_frames):
            due = t0 + i * period_ns
            now = time.monotonic_ns()
            if now < due:
                time.sleep((due - now) / 1e9)
            elif now - due > period_ns:
                self.late_frames += 1
            t_frame = max(due, now) if now - due > period_ns else due
            r0 = time.perf_counter()
            rgb, depth, pose, boxes = self.render_at(t_frame)
            self.render_ms.append((time.perf_counter() - r0) * 1000.0)
            self.truth[i] = (pose, boxes)
            yield Frame(i, rgb, depth, t_frame, t_frame)
            i += 1
