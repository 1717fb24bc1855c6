"""A simulated autopilot: a pymavlink peer that flies a path and streams telemetry.

No autopilot simulator installs on this machine (no ArduPilot/PX4 SITL), so tests and demos
use :class:`SimAutopilot`: system 1, component 1, flying a closed loop of local ENU waypoints
around a home position at a cruise speed. It behaves like an autopilot on the wire:

* HEARTBEAT at 1 Hz (a quadrotor running ArduPilot, armed, in AUTO: :attr:`SimAutopilot.mode`
  and ``armed`` change that; the path flown stays the same);
* GLOBAL_POSITION_INT, ATTITUDE, ATTITUDE_QUATERNION, GPS_RAW_INT, EKF_STATUS_REPORT,
  SYSTEM_TIME only when asked, at the asked rate: MAV_CMD_SET_MESSAGE_INTERVAL (ACKed;
  ``message_interval=False`` makes it answer UNSUPPORTED like an old firmware),
  REQUEST_DATA_STREAM (ArduPilot's stream groups), MAV_CMD_REQUEST_MESSAGE; any other
  command is ACKed UNSUPPORTED;
* TIMESYNC requests answered with its boot clock in ns;
* the mission protocol (upload, download, clear) through an embedded
  :class:`missions._protocol.MissionReceiver` (:attr:`SimAutopilot.mission`). The uploaded
  mission is stored, not flown: build a :class:`SimPath` from it to fly it.

The GPS fix can be switched off and on (:attr:`SimAutopilot.gps_fix`), as ArduPilot
behaves: before its first fix it sends GLOBAL_POSITION_INT with lat = lon = 0 (its EKF
has no origin), GPS_RAW_INT with ``fix_type`` 1 and an EKF_STATUS_REPORT in
constant-position mode; a fix lost in flight leaves the EKF dead-reckoning, its position
drifting away from the truth (``lost_drift_m_s``) without POS_HORIZ_ABS.

A SiK radio on the link can be played too (:attr:`SimAutopilot.radio_txbuf`): RADIO_STATUS
once a second from system 51, component 68 (as SiK firmware sends it), reporting that much
of its transmit buffer free, as ArduPilot forwards it to its other links.

It reboots as ArduPilot SITL does (:meth:`SimAutopilot.reboot`, or MAV_CMD_PREFLIGHT_REBOOT_
SHUTDOWN): boot clock and TIMESYNC from 0, streams forgotten, mission kept.

Its boot clock is the host's monotonic clock shifted by a realistic offset (it booted
``uptime_at_start_s`` before the simulator started), running ``drift_ppm`` fast, read with
``jitter_ns`` of Gaussian noise. Motion: a periodic cubic spline through the waypoints (times
from distance / speed); yaw along the track; roll and pitch tilt the thrust against the
acceleration, plus a small oscillation. Messages carry the exact state at their
``time_boot_ms``; :meth:`SimAutopilot.truth_pose` and :meth:`SimAutopilot.boot_ns_at_mono`
give that truth to tests.

MAVLink 2, through :func:`link.open_link`.
"""

from __future__ import annotations

import logging
import math
import random
import threading
import time
from dataclasses import dataclass, replace
from types import TracebackType
from typing import Any

from scipy.spatial.transform import Rotation

from holescan.geotag import LocalFrame, VehiclePose
from holescan.link import SigningKey, mavlink, open_link
from holescan.missions import MissionReceiver
from holescan.sim._simcommands import STREAMED, command_result, is_reboot, param_value, set_streams
from holescan.sim._trajectory import SimPath, Trajectory

__all__ = ["SimAutopilot"]

_log = logging.getLogger(__name__)

_NS = 1_000_000_000
_BACKLOG_NS = 500_000_000  # messages due longer ago than this are dropped, not sent late

# EKF_STATUS_REPORT flags: using GPS; no fix ever (constant position); dead reckoning.
_EKF_AIDED = (
    mavlink.EKF_ATTITUDE
    | mavlink.EKF_VELOCITY_HORIZ
    | mavlink.EKF_VELOCITY_VERT
    | mavlink.EKF_POS_VERT_ABS
)
_EKF_GOOD = (
    _EKF_AIDED
    | mavlink.EKF_POS_HORIZ_REL
    | mavlink.EKF_POS_HORIZ_ABS
    | mavlink.EKF_PRED_POS_HORIZ_REL
    | mavlink.EKF_PRED_POS_HORIZ_ABS
)
_EKF_NO_ORIGIN = (
    mavlink.EKF_ATTITUDE
    | mavlink.EKF_VELOCITY_VERT
    | mavlink.EKF_POS_VERT_ABS
    | mavlink.EKF_CONST_POS_MODE
)
_EKF_DEAD_RECKONING = _EKF_AIDED | mavlink.EKF_POS_HORIZ_REL


@dataclass(frozen=True)
class _State:
    t_boot_ns: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    rel_alt_m: float
    vel_ned: tuple[float, float, float]
    rot: Rotation
    rates: tuple[float, float, float]


class SimAutopilot:
    """A simulated autopilot on a pymavlink connection; a context manager running a thread.

    Parameters
    ----------
    connection : pymavlink connection string (e.g. ``udpout:127.0.0.1:14560`` towards
        MAVProxy's ``--master=udpin:...``, or ``udpin:`` to be found by a peer).
    path : where it flies.
    sysid, compid : its MAVLink identity.
    uptime_at_start_s : its boot clock reads this when the simulator starts, s.
    drift_ppm : its boot clock runs this much fast (negative: slow), parts per million.
    jitter_ns : standard deviation of the noise on each boot-clock reading, ns.
    message_interval : honour MAV_CMD_SET_MESSAGE_INTERVAL (False: ACK UNSUPPORTED).
    eph_m : GPS horizontal accuracy reported (h_acc), m.
    gps_fix : whether the GPS has a 3-D fix at start (switch with :attr:`gps_fix`).
    lost_drift_m_s : how fast the position drifts east of the truth while a fix once had is
        lost (the EKF dead-reckoning), m/s.
    seed : for the clock jitter.
    mission : the mission-protocol state machine (default: a fresh
        :class:`~missions._protocol.MissionReceiver` for ``sysid``/``compid``).
    signing_key : MAVLink 2 signing key (32 bytes): sign everything sent, drop every
        unsigned or wrongly signed packet (``received_signed`` counts the good ones).
    :attr:`params` answer PARAM_REQUEST_READ (None: still initialising, no answer).
    """

    def __init__(
        self,
        connection: str,
        path: SimPath | None = None,
        *,
        sysid: int = 1,
        compid: int = mavlink.MAV_COMP_ID_AUTOPILOT1,
        uptime_at_start_s: float = 37.25,
        drift_ppm: float = 15.0,
        jitter_ns: int = 20_000,
        message_interval: bool = True,
        eph_m: float = 1.2,
        gps_fix: bool = True,
        lost_drift_m_s: float = 1.5,
        seed: int = 0,
        mission: MissionReceiver | None = None,
        signing_key: bytes | None = None,
    ) -> None:
        self._signing_key = signing_key
        self.path = path if path is not None else SimPath()
        self._traj = Trajectory(self.path)
        self.connection = connection
        self.sysid = sysid
        self.compid = compid
        self._drift = drift_ppm * 1e-6
        self._jitter_ns = jitter_ns
        self._message_interval = message_interval
        self.eph_m = eph_m
        self._rng = random.Random(seed)
        self._mono0 = time.monotonic_ns()
        self._boot0 = round(uptime_at_start_s * _NS)
        self._tau_shift_ns = 0  # keeps the flight path continuous across a reboot
        self._down_until_mono_ns = 0  # rebooting: silent, deaf
        self.reboots = 0
        self._unix_minus_boot = time.time_ns() - self.boot_ns_at_mono(time.monotonic_ns())
        self.lost_drift_m_s = lost_drift_m_s
        self._had_fix = gps_fix
        self._lost_at_boot_ns: int | None = None if gps_fix else -1
        self._lock = threading.Lock()  # rates
        self._send_lock = threading.Lock()  # the connection's writer
        self._intervals_ns: dict[str, int] = {"HEARTBEAT": _NS}
        self._next_due: dict[str, int] = {}
        self.sent: dict[str, int] = {}
        self.received: dict[str, int] = {}
        self.received_signed: dict[str, int] = {}  # of those, correctly signed (signing_key)
        self.silent = False
        self.mode = mavlink.COPTER_MODE_AUTO  # ArduCopter's custom mode in the heartbeat
        self.armed = True
        self.radio_txbuf: int | None = None
        self.params: dict[str, float] | None = {"SYSID_THISMAV": sysid, "MIS_TOTAL": 0}
        self.mission = (
            mission
            if mission is not None
            else MissionReceiver(system_id=sysid, component_id=compid)
        )
        self._conn: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- truth ----------------------------------------------------------------------------

    def boot_ns_at_mono(self, t_mono_ns: int) -> int:
        """The autopilot's true boot-clock reading at host monotonic time ``t_mono_ns``."""
        return self._boot0 + round((t_mono_ns - self._mono0) * (1.0 + self._drift))

    def unix_ns_at_boot(self, t_boot_ns: int) -> int:
        """The UTC time (ns since the epoch) the autopilot reports for boot time ``t_boot_ns``."""
        return t_boot_ns + self._unix_minus_boot

    @property
    def gps_fix(self) -> bool:
        """Whether the GPS has a 3-D fix now; set it to lose or regain the fix."""
        return self._lost_at_boot_ns is None

    @gps_fix.setter
    def gps_fix(self, value: bool) -> None:
        now = self.boot_ns_at_mono(time.monotonic_ns())
        if value:
            self._had_fix = True
            self._lost_at_boot_ns = None
        elif self._lost_at_boot_ns is None:
            self._lost_at_boot_ns = now

    def truth_pose(self, t_boot_ns: int) -> VehiclePose:
        """The simulated vehicle's exact pose at its boot time ``t_boot_ns``."""
        s = self._state(t_boot_ns)
        yaw, pitch, roll = s.rot.as_euler("ZYX")
        return VehiclePose(
            t_boot_ns=t_boot_ns,
            lat_deg=s.lat_deg,
            lon_deg=s.lon_deg,
            alt_m=s.alt_m,
            rel_alt_m=s.rel_alt_m,
            roll=float(roll),
            pitch=float(pitch),
            yaw=float(yaw),
            vn=s.vel_ned[0],
            ve=s.vel_ned[1],
            vd=s.vel_ned[2],
            eph_m=self.eph_m,
        )

    def truth_rotation(self, t_boot_ns: int) -> Rotation:
        """Body (FRD) -> NED rotation at boot time ``t_boot_ns`` (for angle comparisons)."""
        return self._traj.rotation(self._tau(t_boot_ns))

    def rates_hz(self) -> dict[str, float]:
        """Message name -> the rate the simulator currently streams it at, Hz."""
        with self._lock:
            return {k: _NS / v for k, v in self._intervals_ns.items()}

    def _tau(self, t_boot_ns: int) -> float:
        return (t_boot_ns - self._boot0 + self._tau_shift_ns) / _NS

    def reboot(self, down_s: float = 1.5) -> None:
        """Reboot as ArduPilot does: deaf and silent for ``down_s``, then the boot clock and
        TIMESYNC from 0, only the heartbeat streaming; the path flown and the mission go on
        (``truth_pose(boot_ns_at_mono(t))`` stays right on both sides)."""
        with self._lock:
            back = time.monotonic_ns() + round(down_s * _NS)
            old_boot_at_back = self.boot_ns_at_mono(back)
            self._tau_shift_ns += round((back - self._mono0) * (1.0 + self._drift))  # continuous
            self._mono0, self._boot0 = back, 0
            self._unix_minus_boot += old_boot_at_back
            lost = self._lost_at_boot_ns
            if lost is not None and lost >= 0:
                self._lost_at_boot_ns = lost - old_boot_at_back
            self._intervals_ns = {"HEARTBEAT": _NS}
            self._next_due = {}
            self._down_until_mono_ns = back
            self.reboots += 1

    def _state(self, t_boot_ns: int) -> _State:
        tau = self._tau(t_boot_ns)
        p, v, _ = self._traj.kinematics(tau)
        home = self.path
        lat, lon, alt = LocalFrame(
            home.home_lat_deg, home.home_lon_deg, home.home_alt_m
        ).to_geodetic_alt(p[0], p[1], p[2])
        rates = self._traj.body_rates(tau)
        return _State(
            t_boot_ns=t_boot_ns,
            lat_deg=float(lat),
            lon_deg=float(lon),
            alt_m=float(alt),
            rel_alt_m=float(alt) - home.home_alt_m,
            vel_ned=(float(v[1]), float(v[0]), float(-v[2])),
            rot=self._traj.rotation(tau),
            rates=(float(rates[0]), float(rates[1]), float(rates[2])),
        )

    # -- lifecycle ------------------------------------------------------------------------

    def __enter__(self) -> SimAutopilot:
        self._conn = open_link(
            self.connection, source_system=self.sysid, source_component=self.compid
        )
        if self._signing_key is not None:  # as ArduPilot with a key: signs, drops unsigned
            SigningKey(self._signing_key).apply(self._conn)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="sim-autopilot", daemon=True)
        self._thread.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def inject_garbage(self, data: bytes) -> None:
        """Write raw bytes into the link (to test a receiver's robustness)."""
        with self._send_lock:
            self._conn.write(data)

    def set_rate(self, name: str, hz: float) -> None:
        """Stream ``name`` at ``hz`` (<= 0 stops it), as if a GCS had asked."""
        if name not in STREAMED:
            raise ValueError(f"the simulator does not stream {name!r}; it streams {STREAMED}")
        with self._lock:
            if hz > 0:
                self._intervals_ns[name] = round(_NS / hz)
            else:
                self._intervals_ns.pop(name, None)
                self._next_due.pop(name, None)

    # -- thread ---------------------------------------------------------------------------

    def _run(self) -> None:
        conn = self._conn
        while not self._stop.is_set():
            now = time.monotonic_ns()
            if now < self._down_until_mono_ns:  # rebooting: deaf and silent
                while conn.recv_msg() is not None:
                    pass
                conn.select(0.02)
                continue
            batch: list[tuple[int, str]] = []  # (sample time, message) due now
            with self._lock:
                for name, interval in self._intervals_ns.items():
                    due = self._next_due.get(name, now)
                    if due < now - _BACKLOG_NS:  # hopelessly behind (host stalled): skip
                        due = now
                    while due <= now:
                        batch.append((due, name))
                        due += interval
                    self._next_due[name] = due
                next_wake = min(self._next_due.values(), default=now + 20_000_000)
            for t_sample, name in sorted(batch):
                if t_sample < self._down_until_mono_ns:
                    continue  # due before a reboot that came since: lost with it
                if not self.silent:
                    try:
                        self._send(name, t_sample)
                    except Exception:
                        _log.exception("simulator failed to send %s", name)
            while True:
                msg = conn.recv_msg()
                if msg is None:
                    break
                try:
                    self._handle(msg)
                except Exception:
                    _log.exception("simulator failed to handle %s", msg.get_type())
            self._send_all(self.mission.poll(time.monotonic_ns()))
            wait_s = (next_wake - time.monotonic_ns()) / 1e9
            if wait_s > 0:
                conn.select(min(wait_s, 0.02))

    def _read_boot_ns(self, t_mono_ns: int | None = None) -> int:
        """The boot clock read (with jitter) at ``t_mono_ns`` (default: now)."""
        noise = self._rng.gauss(0.0, self._jitter_ns) if self._jitter_ns else 0.0
        t = time.monotonic_ns() if t_mono_ns is None else t_mono_ns
        return self.boot_ns_at_mono(t) + round(noise)

    def _send(self, name: str, t_sample_mono_ns: int | None = None) -> None:
        """Send ``name`` carrying the state sampled at ``t_sample_mono_ns`` (default: now).

        Like an autopilot, a message sent late (the host was busy) still carries the state
        and stamp of the moment it was due; only its delivery is late.
        """
        with self._send_lock:
            self._send_locked(name, t_sample_mono_ns)

    def _send_locked(self, name: str, t_sample_mono_ns: int | None) -> None:
        mav = self._conn.mav
        t_boot_now_ns = self._read_boot_ns(t_sample_mono_ns)
        t_boot_ms = t_boot_now_ns // 1_000_000
        if name == "HEARTBEAT":
            mav.heartbeat_send(
                mavlink.MAV_TYPE_QUADROTOR,
                mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0),
                self.mode,  # ArduCopter's custom mode number (3 = AUTO)
                mavlink.MAV_STATE_ACTIVE,
            )
            txbuf = self.radio_txbuf
            if txbuf is not None:  # the SiK radio's own report, routed to this link
                ids = (mav.srcSystem, mav.srcComponent)
                mav.srcSystem, mav.srcComponent = 51, mavlink.MAV_COMP_ID_TELEMETRY_RADIO
                try:
                    mav.radio_status_send(180, 170, txbuf, 30, 28, 0, 0)
                finally:
                    mav.srcSystem, mav.srcComponent = ids
        elif name == "SYSTEM_TIME":
            # both clocks read at the same instant, each truncated to its field's unit
            mav.system_time_send(self.unix_ns_at_boot(t_boot_now_ns) // 1000, t_boot_ms)
        else:
            s = self._reported(self._state(t_boot_ms * 1_000_000))
            if name == "GLOBAL_POSITION_INT":
                yaw_deg = math.degrees(s.rot.as_euler("ZYX")[0]) % 360.0
                mav.global_position_int_send(
                    t_boot_ms,
                    round(s.lat_deg * 1e7),
                    round(s.lon_deg * 1e7),
                    round(s.alt_m * 1000),
                    round(s.rel_alt_m * 1000),
                    round(s.vel_ned[0] * 100),
                    round(s.vel_ned[1] * 100),
                    round(s.vel_ned[2] * 100),
                    round(yaw_deg * 100) % 36000,
                )
            elif name == "ATTITUDE":
                yaw, pitch, roll = s.rot.as_euler("ZYX")
                mav.attitude_send(t_boot_ms, roll, pitch, yaw, *s.rates)
            elif name == "ATTITUDE_QUATERNION":
                x, y, z, w = s.rot.as_quat()
                mav.attitude_quaternion_send(t_boot_ms, w, x, y, z, *s.rates)
            elif name == "EKF_STATUS_REPORT":
                flags = (
                    _EKF_GOOD
                    if self.gps_fix
                    else _EKF_DEAD_RECKONING
                    if self._had_fix
                    else _EKF_NO_ORIGIN
                )
                mav.ekf_status_report_send(flags, 0.1, 0.1, 0.1, 0.1, 0.0)
            elif name == "GPS_RAW_INT" and not self.gps_fix:
                mav.gps_raw_int_send(
                    t_boot_ms * 1000, mavlink.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 9999, 9999, 0, 0, 3
                )
            elif name == "GPS_RAW_INT":
                vn, ve, _ = s.vel_ned
                cog = math.degrees(math.atan2(ve, vn)) % 360.0
                mav.gps_raw_int_send(
                    t_boot_ms * 1000,
                    mavlink.GPS_FIX_TYPE_3D_FIX,
                    round(s.lat_deg * 1e7),
                    round(s.lon_deg * 1e7),
                    round(s.alt_m * 1000),
                    80,  # HDOP 0.8
                    120,
                    round(math.hypot(vn, ve) * 100),
                    round(cog * 100) % 36000,
                    14,
                    h_acc=round(self.eph_m * 1000),
                    v_acc=round(1.5 * self.eph_m * 1000),
                    vel_acc=300,
                )
        self.sent[name] = self.sent.get(name, 0) + 1

    def _reported(self, s: _State) -> _State:
        """The state as the autopilot's estimator has it: the truth with a fix; zeros before
        the first fix; drifting east of the truth after a fix is lost."""
        lost = self._lost_at_boot_ns
        if lost is None:
            return s
        if not self._had_fix:
            return replace(s, lat_deg=0.0, lon_deg=0.0, alt_m=0.0, rel_alt_m=0.0, vel_ned=(0, 0, 0))
        drift = self.lost_drift_m_s * max(0, s.t_boot_ns - lost) / _NS
        lat, lon = LocalFrame(s.lat_deg, s.lon_deg, s.alt_m).to_geodetic(drift, 0.0)
        return replace(s, lat_deg=float(lat), lon_deg=float(lon))

    def _handle(self, msg: Any) -> None:
        mtype = msg.get_type()
        self.received[mtype] = self.received.get(mtype, 0) + 1
        if getattr(msg, "_signed", False):
            self.received_signed[mtype] = self.received_signed.get(mtype, 0) + 1
        if mtype == "TIMESYNC" and msg.tc1 == 0:
            if not self.silent:
                with self._send_lock:
                    self._conn.mav.timesync_send(self._read_boot_ns(), msg.ts1)
        elif mtype.startswith("MISSION_"):
            self._send_all(self.mission.handle(msg, time.monotonic_ns()))
        elif mtype == "PARAM_REQUEST_READ" and self._for_me(msg):
            self._send_all(param_value(self.params, msg))
        elif mtype == "COMMAND_LONG" and self._for_me(msg):
            self._command(msg)
        elif mtype == "REQUEST_DATA_STREAM" and self._for_me(msg):
            set_streams(msg, self.set_rate)

    def _send_all(self, msgs: list[Any]) -> None:
        if self.silent or not msgs:
            return
        with self._send_lock:
            for out in msgs:
                self._conn.mav.send(out)

    def _for_me(self, msg: Any) -> bool:
        return msg.target_system in (0, self.sysid) and msg.target_component in (0, self.compid)

    def _command(self, msg: Any) -> None:
        result = command_result(
            msg, message_interval=self._message_interval, set_rate=self.set_rate, send=self._send
        )
        if not self.silent:
            with self._send_lock:
                self._conn.mav.command_ack_send(
                    msg.command,
                    result,
                    target_system=msg.get_srcSystem(),
                    target_component=msg.get_srcComponent(),
                )
        if is_reboot(msg):
            self.reboot()
