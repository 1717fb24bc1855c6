"""A simulated sortie: the synthetic rubble world, a survey over it, the autopilot flying it.

Composition only (each part lives elsewhere):

* the world: :func:`sim.make_world`, anchored on the Earth by a
  :class:`~sim._source.WorldAnchor` (its south-west corner, height 0);
* the path: :func:`missions.plan_survey` over the world's rectangle at ``altitude_m``
  above the rubble, its corners rounded with arcs (a quadrotor turns; a spline through bare
  corners would bulge) and flown as a closed loop by
  :class:`~sim._autopilot.SimAutopilot` (:meth:`SimPath.from_waypoints`);
* the camera: :class:`~sim._source.SimSource`, rendering the world from the
  autopilot's *true* pose at each frame time,
  ``autopilot.truth_pose(autopilot.boot_ns_at_mono(t))``;
* the truth to score a flight against: the world's access holes as WGS84 points.

For benchmarks where rendering at 30 fps would eat the CPU the flight is measured on,
:mod:`sim._lap` renders one lap of the loop into an ``.oni`` file first and plays it back
through OpenNI2, each frame at the instant the autopilot is where the frame was rendered
from.
"""

from __future__ import annotations

import logging
import math
import socket
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from types import TracebackType

import numpy as np

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.geotag import CameraMount
from holescan.missions import Area, SurveyParams, SurveyPlan, Waypoint, plan_survey
from holescan.sim._autopilot import SimAutopilot
from holescan.sim._source import SimSource, WorldAnchor
from holescan.sim._trajectory import SimPath
from holescan.sim._world import RubbleWorld, make_world

__all__ = [
    "DEFAULT_ANCHOR",
    "SimSortie",
    "SortieParams",
    "TrueHole",
    "lap_frames",
    "make_sortie_world",
    "survey_path",
    "true_holes",
    "world_area",
]

_log = logging.getLogger(__name__)

#: Where the synthetic world lies unless told otherwise (a rubble site, 120 m above MSL).
DEFAULT_ANCHOR = WorldAnchor(43.6532, -79.3832, 120.0)


@dataclass(frozen=True)
class SortieParams:
    """Everything that shapes a simulated sortie.

    size_m : (east, north) extent of the surveyed area, metres.
    margin_m : the world reaches this far beyond the area on every side, so that the camera
        never looks past the world's edge (the turns run past the area).
    world_seed, n_access_holes, cell_m : the world (:func:`make_world`), whose access holes
        lie anywhere in it; distractor counts scale with its area from ``make_world``'s
        20 x 20 m defaults (``distractors=False``: none).
    anchor : where the world's south-west corner lies (WGS84, MSL metres).
    altitude_m : flight height above the rubble's mean level (home), metres.
    speed_m_s, heading_deg, side_overlap : survey settings (None: the planner's choice).
    turn_radius_m : radius of the arcs that round the path's corners, metres.
    wobble_deg : roll/pitch oscillation of the airframe, degrees.
    clock_offset_s : the autopilot's boot clock reads this when the simulator starts, s.
    drift_ppm : its clock runs this much fast, parts per million.
    eph_m : GPS horizontal accuracy the autopilot reports, m (the simulated position itself
        is exact; a tiny value switches the GPS term of the error model off).
    fps : simulated camera frame rate; noise_seed : the frames' noise.
    """

    world_seed: int = 7
    size_m: tuple[float, float] = (10.0, 10.0)
    margin_m: float = 3.5
    n_access_holes: int = 3
    distractors: bool = True
    cell_m: float = 0.02
    anchor: WorldAnchor = DEFAULT_ANCHOR
    altitude_m: float = 3.0
    speed_m_s: float | None = None
    heading_deg: float | None = None
    side_overlap: float = 0.3
    turn_radius_m: float = 1.0
    wobble_deg: float = 1.5
    clock_offset_s: float = 1234.5
    drift_ppm: float = 15.0
    eph_m: float = 1.2
    fps: float = 30.0
    noise_seed: int = 0

    def __post_init__(self) -> None:
        if not (self.fps > 0 and math.isfinite(self.fps)):
            raise InputError(f"sim fps must be > 0, got {self.fps}")
        if self.turn_radius_m <= 0:
            raise InputError(f"turn_radius_m must be > 0, got {self.turn_radius_m}")
        if self.eph_m < 0.001:
            raise InputError("eph_m must be >= 0.001 m (MAVLink reports h_acc in mm; 0 = unknown)")


@dataclass(frozen=True)
class TrueHole:
    """One true access hole of the world, on the Earth.

    id : index in :attr:`RubbleWorld.holes`; lat_deg, lon_deg, alt_m : the opening's
    centroid at rim height (WGS84, MSL); x_m, y_m : the same in the world frame (east,
    north from its south-west corner); major_m, minor_m : the opening's size.
    """

    id: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    x_m: float
    y_m: float
    major_m: float
    minor_m: float


def make_sortie_world(p: SortieParams) -> RubbleWorld:
    """The world of a sortie (deterministic for the same parameters)."""
    sx, sy = (v + 2.0 * p.margin_m for v in p.size_m)
    k = (sx * sy) / 400.0 if p.distractors else 0.0
    return make_world(
        p.world_seed,
        (sx, sy),
        cell_m=p.cell_m,
        n_access_holes=p.n_access_holes,
        n_small_holes=round(12 * k),
        n_cracks=round(10 * k),
        n_depressions=round(8 * k),
        n_stains=round(10 * k),
        n_shadows=round(8 * k),
    )


def world_area(world: RubbleWorld, anchor: WorldAnchor, margin_m: float = 0.0) -> Area:
    """The world's rectangle inset by ``margin_m`` as a survey :class:`missions.Area` (WGS84)."""
    sx, sy = world.size_m
    m = margin_m
    if not 0.0 <= 2.0 * m < min(sx, sy):
        raise InputError(f"margin {m} m leaves nothing of the {sx:g} x {sy:g} m world")
    corners = ((m, m), (sx - m, m), (sx - m, sy - m), (m, sy - m))
    return Area(tuple(anchor.to_geodetic(x, y, 0.0)[:2] for x, y in corners))


def true_holes(world: RubbleWorld, anchor: WorldAnchor) -> tuple[TrueHole, ...]:
    """The world's access holes (not the distractors) as WGS84 points."""
    out = []
    for h in world.access_holes:
        x, y = h.centre_xy
        lat, lon, alt = anchor.to_geodetic(x, y, h.rim_z)
        out.append(TrueHole(h.id, lat, lon, alt, float(x), float(y), h.major_m, h.minor_m))
    return tuple(out)


def _loop_corners(
    corners: Sequence[tuple[float, float]], turn_radius_m: float
) -> list[tuple[float, float]]:
    """The survey's corners as a closed loop the simulated vehicle can fly lap after lap.

    An area small enough for one survey line (its width within one camera footprint) plans
    a single straight line, which is no loop: the vehicle then flies it out and comes back
    on a parallel leg two turn radii to its left (a racetrack), so the line is flown in
    both directions and the turns stay as wide as elsewhere.

    >>> _loop_corners([(0.0, 0.0), (3.0, 0.0)], 1.0)
    [(0.0, 0.0), (3.0, 0.0), (3.0, 2.0), (0.0, 2.0)]
    """
    pts: list[tuple[float, float]] = []
    for q in corners:
        if not pts or math.dist(q, pts[-1]) > 1e-3:
            pts.append(q)
    if len(pts) > 1 and math.dist(pts[0], pts[-1]) <= 1e-3:
        pts.pop()
    if len(pts) >= 3:
        return pts
    if len(pts) < 2:
        raise InputError("the survey plan has no line to fly: the area is empty")
    (x0, y0), (x1, y1) = pts
    length = math.dist(pts[0], pts[1])
    ox, oy = -(y1 - y0) / length * 2.0 * turn_radius_m, (x1 - x0) / length * 2.0 * turn_radius_m
    return [(x0, y0), (x1, y1), (x1 + ox, y1 + oy), (x0 + ox, y0 + oy)]


def _rounded(points: Sequence[tuple[float, float]], radius: float, step: float) -> np.ndarray:
    """A closed polyline (N, 2) with each corner replaced by a tangent arc, densified.

    The arc radius shrinks where the neighbouring legs are short (at most half of each).
    Returns (M, 2) points about ``step`` metres apart (closing point not repeated).
    """
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    out: list[np.ndarray] = []
    for i in range(n):
        a, b, c = pts[i - 1], pts[i], pts[(i + 1) % n]
        u, v = b - a, c - b
        lu, lv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        u, v = u / lu, v / lv
        turn = math.atan2(u[0] * v[1] - u[1] * v[0], float(u @ v))  # signed, rad
        if abs(turn) < 1e-6:
            out.append(b)
            continue
        tan_half = math.tan(abs(turn) / 2.0)
        r = min(radius, 0.5 * lu / tan_half, 0.5 * lv / tan_half)
        d = r * tan_half  # from the corner to the arc's ends
        start = b - u * d
        normal = np.array([-u[1], u[0]]) * math.copysign(1.0, turn)  # towards the centre
        centre = start + normal * r
        a0 = math.atan2(*(start - centre)[::-1])
        k = max(2, math.ceil(abs(turn) * r / step))
        for t in np.linspace(0.0, turn, k + 1):
            ang = a0 + t
            out.append(centre + r * np.array([math.cos(ang), math.sin(ang)]))
    ring = np.asarray(out)
    dense: list[np.ndarray] = []
    for i in range(len(ring)):
        p, q = ring[i], ring[(i + 1) % len(ring)]
        m = max(1, math.ceil(float(np.linalg.norm(q - p)) / (2.0 * step)))
        dense.extend(p + (q - p) * (j / m) for j in range(m))
    keep = [dense[0]]
    for q in dense[1:]:
        if float(np.linalg.norm(q - keep[-1])) > 1e-3:
            keep.append(q)
    return np.asarray(keep)


def survey_path(world: RubbleWorld, p: SortieParams) -> tuple[SurveyPlan, SimPath]:
    """Plan a lawnmower over the world and turn it into the loop the autopilot flies.

    Home is the world's anchor (the rubble's mean level), so ``altitude_m`` is the height
    above the rubble. The plan's lines are kept straight; their corners (and the leg back
    to the first line, which closes the loop) are rounded with ``turn_radius_m`` arcs.
    """
    a = p.anchor
    area = world_area(world, a, p.margin_m)
    plan = plan_survey(
        area,
        SurveyParams(
            altitude_m=p.altitude_m,
            speed_m_s=p.speed_m_s,
            heading_deg=p.heading_deg,
            side_overlap=p.side_overlap,
            home=area.outer[0],
            home_amsl_m=a.alt_m,
        ),
    )
    corners = [a.to_world(w.lat_deg, w.lon_deg, a.alt_m)[:2] for w in plan.path]
    xy = _rounded(
        _loop_corners([(float(c[0]), float(c[1])) for c in corners], p.turn_radius_m),
        p.turn_radius_m,
        0.5,
    )
    waypoints = []
    for x, y in xy:
        lat, lon, _ = a.to_geodetic(float(x), float(y), 0.0)
        waypoints.append(Waypoint(lat, lon, p.altitude_m))
    path = SimPath.from_waypoints(
        a.lat_deg,
        a.lon_deg,
        a.alt_m,
        waypoints,
        speed_m_s=plan.speed_m_s,
        wobble_rad=math.radians(p.wobble_deg),
    )
    return plan, path


def loop_length_m(path: SimPath) -> float:
    """Length of the closed polyline through the path's waypoints (its timing basis), m."""
    pts = np.asarray(path.waypoints_enu, dtype=np.float64)
    return float(np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1).sum())


def lap_frames(path: SimPath, fps: float, period_multiple_s: float = 10.0) -> tuple[SimPath, int]:
    """The path slowed so one lap lasts a whole number of frames, and that number.

    A pre-rendered lap can then be replayed lap after lap with every frame where the
    vehicle is. The lap is stretched (never shortened: the planner's speed is the motion
    blur bound) to a multiple of ``period_multiple_s``, the period of the simulated
    airframe's wobble (0.9, 1.3 and 0.4 Hz repeat every 10 s), so the attitude repeats
    too; this is checked on the simulator's truth, and :class:`InputError` raised if not.
    """
    length = loop_length_m(path)
    step = max(1, round(period_multiple_s * fps))
    n = step * max(1, math.ceil(length / path.speed_m_s * fps / step - 1e-9))
    lap = replace(path, speed_m_s=length * fps / n)
    ap = SimAutopilot("udpout:127.0.0.1:9", lap)  # never entered: its truth only
    lap_ns = round(n * 1e9 / fps)
    for t_ns in (0, 1_234_567_891, lap_ns // 3):
        a, b = ap.truth_pose(t_ns), ap.truth_pose(t_ns + lap_ns)
        moved = max(abs(a.lat_deg - b.lat_deg), abs(a.lon_deg - b.lon_deg)) * 1.1e5
        turned = max(
            abs(a.roll - b.roll),
            abs(a.pitch - b.pitch),
            abs(math.remainder(a.yaw - b.yaw, math.tau)),
        )
        if moved > 1e-4 or turned > 1e-6:
            raise InputError(
                f"the simulated vehicle does not repeat its lap ({moved:.2g} m, {turned:.2g} "
                "rad apart one lap later): a pre-rendered lap cannot be replayed"
            )
    return lap, n


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class SimSortie:
    """A running simulated sortie: the autopilot on a loopback UDP link, and its camera.

    Use as a context manager (starts/stops the autopilot). :attr:`mavlink` is the connection
    string the flight daemon listens on; :meth:`source` makes a :class:`SimSource` (use it
    as the daemon's source factory); every source made is kept in :attr:`sources` for its
    truth (:attr:`SimSource.truth`, :attr:`SimSource.render_ms`).

    Parameters
    ----------
    params : the sortie. camera, mount : the simulated Xtion and how it sits on the vehicle.
    mavlink : ``udpin:HOST:PORT`` the daemon will listen on (the autopilot sends there);
        None = a free loopback port.
    world, path : reuse an already built world / path (they take seconds to build).
    signing_key : the simulated autopilot's MAVLink 2 signing key (32 bytes; None: unsigned),
        as a real autopilot holding the flight's key.
    sysid : the simulated autopilot's MAVLink system id (``holescan fly --sysid``).
    """

    params: SortieParams = field(default_factory=SortieParams)
    camera: CameraIntrinsics = field(default_factory=CameraIntrinsics.xtion)
    mount: CameraMount = field(default_factory=CameraMount)
    mavlink: str | None = None
    world: RubbleWorld | None = None
    path: SimPath | None = None
    plan: SurveyPlan | None = None
    sources: list[SimSource] = field(default_factory=list)
    autopilot: SimAutopilot | None = None
    signing_key: bytes | None = field(default=None, repr=False)
    sysid: int = 1

    def __post_init__(self) -> None:
        if self.mavlink is None:
            self.mavlink = f"udpin:127.0.0.1:{_free_udp_port()}"
        if not self.mavlink.startswith("udpin:"):
            raise InputError(
                f"the simulated autopilot needs a udpin:HOST:PORT link to talk to, "
                f"got {self.mavlink!r}"
            )
        if self.world is None:
            self.world = make_sortie_world(self.params)
        if self.path is None:
            self.plan, self.path = survey_path(self.world, self.params)

    @property
    def truth(self) -> tuple[TrueHole, ...]:
        assert self.world is not None
        return true_holes(self.world, self.params.anchor)

    def __enter__(self) -> SimSortie:
        assert self.mavlink is not None and self.path is not None
        p = self.params
        self.autopilot = SimAutopilot(
            "udpout:" + self.mavlink.removeprefix("udpin:"),
            self.path,
            uptime_at_start_s=p.clock_offset_s,
            drift_ppm=p.drift_ppm,
            eph_m=p.eph_m,
            seed=p.noise_seed,
            signing_key=self.signing_key,
            sysid=self.sysid,
        )
        self.autopilot.__enter__()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self.autopilot is not None:
            self.autopilot.close()

    def source(self, max_frames: int | None = None) -> SimSource:
        """A new simulated Xtion rendering from the autopilot's true pose (a source factory)."""
        ap = self.autopilot
        if ap is None or self.world is None:
            raise InputError("the sortie is not running: use it as a context manager")
        src = SimSource(
            self.world,
            self.params.anchor,
            lambda t_mono_ns: ap.truth_pose(ap.boot_ns_at_mono(t_mono_ns)),
            self.camera,
            self.mount,
            fps=self.params.fps,
            max_frames=max_frames,
            seed=self.params.noise_seed + len(self.sources),
        )
        self.sources.append(src)
        return src
