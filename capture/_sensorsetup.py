"""Opening the sensor a fly config names: the Xtion (OpenNI2), an ``.oni`` recording or a
flight log replayed at its recorded pace, as the :class:`SensorSetup` :func:`capture.fly`
flies."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from holescan.capture._flyconfig import FlyConfig
from holescan.capture._mavlink import Telemetry
from holescan.capture.errors import SensorError
from holescan.detect import CameraIntrinsics, Frame, FrameSource
from holescan.errors import InputError

__all__ = ["PacedReplay", "SensorSetup", "open_sensor"]


class PacedReplay:
    """Replay a recording's frames at their recorded pace, stamped with the time they are due.

    A :class:`detect.FrameSource` wrapping another (e.g. :class:`flightlog.McapSource`, which
    reads as fast as it can and keeps the recording's old ``t_mono_ns``): frame ``i`` is
    delivered ``t_mono_ns[i] - t_mono_ns[0]`` after the first and re-stamped with that
    instant, as if the sensor delivered it now. Nothing is skipped.
    """

    def __init__(self, inner: FrameSource) -> None:
        self.inner = inner
        self.camera = inner.camera

    def __enter__(self) -> PacedReplay:
        self.inner.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.inner.__exit__(*exc)

    def __iter__(self) -> Iterator[Frame]:
        origin: tuple[int, int] | None = None
        for frame in self.inner:
            if origin is None:
                origin = (time.monotonic_ns(), frame.t_mono_ns)
            due = origin[0] + frame.t_mono_ns - origin[1]
            now = time.monotonic_ns()
            if now < due:
                time.sleep((due - now) / 1e9)
            yield dataclasses.replace(frame, t_mono_ns=max(due, now))


def _reset_xtions() -> None:
    """USB-reset every Xtion attached (the daemon's answer to a stalled sensor)."""
    from holescan.capture._usb import find_xtion, reset_xtion

    devices = find_xtion()
    if not devices:
        raise SensorError("no Xtion on USB to reset")
    for d in devices:
        reset_xtion(d)


@dataclass(frozen=True)
class SensorSetup:
    """What a flight flies with: where frames and telemetry come from.

    factory : opens the frame source (called again after a sensor failure).
    camera : its intrinsics. mavlink : the autopilot's pymavlink connection (None: fly
    without telemetry). usb_reset : resets the sensor on USB after a failure (or None).
    on_telemetry : called with each telemetry link the flight opens to the autopilot, before
    it is used (a simulated camera rendering from the reported pose listens to it).
    """

    factory: Callable[[], FrameSource]
    camera: CameraIntrinsics
    mavlink: str | None = None
    usb_reset: Callable[[], None] | None = None
    on_telemetry: Callable[[Telemetry], None] | None = None


def open_sensor(cfg: FlyConfig) -> SensorSetup:
    """The configured real or recorded sensor, with the configured autopilot link.

    Raises :class:`InputError` for a missing or unreadable recording (before the flight
    starts); ``sim`` is set up by :func:`sim.fly_sim`, which hands its own
    :class:`SensorSetup` to :func:`capture.fly`.
    """
    spec = cfg.sensor
    if spec.kind == "openni2":
        from holescan.capture.openni.device import OpenNI2Device

        uri = cfg.openni_uri
        timeout = cfg.flight.frame_timeout_s
        camera = OpenNI2Device(uri, timeout_s=timeout).camera
        reset = _reset_xtions if cfg.usb_reset else None
        factory = lambda: OpenNI2Device(uri, timeout_s=timeout)  # noqa: E731
        return SensorSetup(factory, camera, cfg.mavlink, reset)
    if spec.kind == "oni":
        from holescan.capture.openni.device import OniSource

        path = spec.path
        assert path is not None
        oni = OniSource(path)  # checks the file now
        return SensorSetup(lambda: OniSource(path, realtime=cfg.realtime), oni.camera, cfg.mavlink)
    if spec.kind == "mcap":
        from holescan.flightlog.reader import McapSource

        assert spec.path is not None
        if not spec.path.is_file():
            raise InputError(f"flight log not found: {spec.path}")
        mcap = McapSource(spec.path)
        paths = spec.path

        def replay() -> FrameSource:
            src = McapSource(paths)
            return PacedReplay(src) if cfg.realtime else src

        return SensorSetup(replay, mcap.camera, cfg.mavlink)
    raise InputError(f"{spec} is not a recorded or live sensor: the simulator is set up by sim")
