"""The simulated Xtion flown by any autopilot: frames rendered from the pose it reports.

``holescan fly --sensor sim --mavlink CONN``: the autopilot at ``CONN`` (ArduPilot SITL, a
real vehicle on the bench with its props off, the pymavlink autopilot) flies; the flight's
own telemetry link (:class:`capture.Telemetry`, handed over by
:attr:`capture.SensorSetup.on_telemetry`) says where the vehicle is, and
:class:`ReportedPoseCamera` renders the simulated world from that pose. The world is placed
at the autopilot's home: the first valid pose's position and its home altitude
(``alt_m - rel_alt_m``) become the survey area's south-west corner, ``margin_m`` inside the
world (where :func:`sim.survey_path` puts home). Until the autopilot has a valid position
(booting, no GPS fix) the camera is not ready: opening it raises :class:`SensorError` and the
daemon retries with its back-off, as for an Xtion that is not plugged in yet. Once placed,
a frame whose time has no valid pose is rendered from the last pose that had one.

Everything after the frame source is the one flight path (:func:`capture.fly`).
"""

from __future__ import annotations

import logging
import threading
import time

from holescan.capture import SensorError, Telemetry
from holescan.detect import CameraIntrinsics
from holescan.geotag import CameraMount, LocalFrame, VehiclePose
from holescan.link import PoseUnavailable
from holescan.sim._sortie import SortieParams, TrueHole, make_sortie_world, true_holes
from holescan.sim._source import SimSource, WorldAnchor
from holescan.sim._world import RubbleWorld

__all__ = ["ReportedPoseCamera", "anchor_at_home"]

_log = logging.getLogger(__name__)


def anchor_at_home(home: tuple[float, float, float], margin_m: float) -> WorldAnchor:
    """The world's anchor (south-west corner, height 0) for a vehicle home (lat, lon, MSL):
    home is ``margin_m`` east and north of it, at the rubble's mean level."""
    lat, lon = LocalFrame(home[0], home[1], home[2]).to_geodetic(-margin_m, -margin_m)
    return WorldAnchor(float(lat), float(lon), home[2])


class ReportedPoseCamera:
    """Simulated Xtions rendering the world from the flight's telemetry (a source factory).

    Parameters
    ----------
    params : the sortie (world, margin, fps, noise seed).
    camera, mount : the simulated Xtion and how it sits on the vehicle.
    world : an already built world (default: built from ``params``).
    home : place the world at this home now (lat, lon, MSL) instead of the autopilot's.
    """

    def __init__(
        self,
        params: SortieParams,
        camera: CameraIntrinsics,
        mount: CameraMount,
        *,
        world: RubbleWorld | None = None,
        home: tuple[float, float, float] | None = None,
    ) -> None:
        self.params = params
        self.camera = camera
        self.mount = mount
        self.world = world if world is not None else make_sortie_world(params)
        self.anchor = anchor_at_home(home, params.margin_m) if home is not None else None
        self.sources: list[SimSource] = []
        self.fallbacks = 0
        self._telemetry: Telemetry | None = None
        self._last: VehiclePose | None = None
        self._lock = threading.Lock()

    def attach(self, telemetry: Telemetry) -> None:
        """The flight's telemetry link (:attr:`capture.SensorSetup.on_telemetry`)."""
        self._telemetry = telemetry

    @property
    def truth(self) -> tuple[TrueHole, ...]:
        """The world's access holes on the Earth (empty until the world is placed)."""
        return () if self.anchor is None else true_holes(self.world, self.anchor)

    def _pose_now(self, t_mono_ns: int) -> VehiclePose | None:
        tel = self._telemetry
        if tel is None:
            return None
        try:
            return tel.pose_at_mono(t_mono_ns)
        except PoseUnavailable:
            return None

    def pose_at_mono(self, t_mono_ns: int) -> VehiclePose:
        """The pose a frame at ``t_mono_ns`` is rendered from (the last valid one if none)."""
        pose = self._pose_now(t_mono_ns)
        with self._lock:
            if pose is None:
                self.fallbacks += 1
                assert self._last is not None  # the camera opens only after a valid pose
                return self._last
            self._last = pose
            return pose

    def source(self) -> SimSource:
        """A new simulated Xtion; :class:`SensorError` while the autopilot has no position."""
        pose = self._pose_now(time.monotonic_ns())
        with self._lock:
            if pose is not None:
                self._last = pose
            if self.anchor is None:
                if pose is None:
                    raise SensorError(
                        "simulated Xtion: waiting for the autopilot's first valid position "
                        "(its home places the simulated world)"
                    )
                home = (pose.lat_deg, pose.lon_deg, pose.alt_m - pose.rel_alt_m)
                self.anchor = anchor_at_home(home, self.params.margin_m)
                _log.info("simulated world placed at the autopilot's home %.7f, %.7f", *home[:2])
            if self._last is None:
                raise SensorError("simulated Xtion: no valid pose from the autopilot yet")
        src = SimSource(
            self.world,
            self.anchor,
            self.pose_at_mono,
            self.camera,
            self.mount,
            fps=self.params.fps,
            seed=self.params.noise_seed + len(self.sources),
        )
        self.sources.append(src)
        return src
