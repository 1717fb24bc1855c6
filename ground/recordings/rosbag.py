"""ROS 1 and ROS 2 bags as a frame source (through ``rosbags``, no ROS needed).

Reads ``sensor_msgs/Image`` colour (rgb8, bgr8, rgba8, bgra8, mono8) and depth (16UC1 or
mono16 in millimetres, 32FC1 in metres), ``sensor_msgs/CompressedImage`` (JPEG/PNG colour,
``compressedDepth`` PNG depth in millimetres) and ``sensor_msgs/CameraInfo`` for the
intrinsics. Depth must be registered to colour (same size): on a ROS driver that is the
``depth_registered`` / ``aligned_depth_to_color`` topic. Each depth image is paired with the
colour image nearest to it by header stamp, within a tolerance.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Literal

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection

__all__ = ["BagSource", "BagTopics", "decode_image", "is_ros1_bag", "is_ros2_bag"]

_log = logging.getLogger(__name__)

IMAGE: Final = "sensor_msgs/msg/Image"
COMPRESSED: Final = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO: Final = "sensor_msgs/msg/CameraInfo"
_COLOUR_ENCODINGS: Final = {"rgb8", "bgr8", "rgba8", "bgra8", "mono8", "8uc3", "8uc1"}
_DEPTH_ENCODINGS: Final = {"16uc1", "mono16", "32fc1"}
Kind = Literal["colour", "depth"]


def is_ros1_bag(path: Path) -> bool:
    """A file that starts as ROS 1 bags do (``#ROSBAG V2.0``)."""
    try:
        with path.open("rb") as f:
            return f.read(13) == b"#ROSBAG V2.0\n"
    except OSError:
        return False


def is_ros2_bag(path: Path) -> bool:
    """A ROS 2 bag folder (``metadata.yaml`` beside its ``.db3`` / ``.mcap`` files)."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def stamp_ns(msg: Any, fallback_ns: int) -> int:
    """A message's header stamp, ns (``fallback_ns`` when it has none or it is zero)."""
    stamp = getattr(getattr(msg, "header", None), "stamp", None)
    if stamp is None:
        return fallback_ns
    sec = getattr(stamp, "sec", getattr(stamp, "secs", 0))
    nsec = getattr(stamp, "nanosec", getattr(stamp, "nsecs", 0))
    t = int(sec) * 1_000_000_000 + int(nsec)
    return t if t > 0 else fallback_ns


def decode_image(msg: Any, kind: Kind) -> npt.NDArray[Any]:
    """A ``sensor_msgs/Image`` or ``CompressedImage`` as (H, W, 3) uint8 RGB (``colour``) or
    (H, W) uint16 millimetres, 0 = no reading (``depth``). Raises :class:`InputError` for an
    encoding that is not of that kind."""
    if hasattr(msg, "format"):  # CompressedImage
        return _decode_compressed(msg, kind)
    enc = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    channels = {"rgb8": 3, "bgr8": 3, "8uc3": 3, "rgba8": 4, "bgra8": 4}.get(enc, 1)
    size = {"16uc1": 2, "mono16": 2, "32fc1": 4}.get(enc, 1) * channels
    if h <= 0 or w <= 0 or step < w * size or data.size < step * h:
        raise InputError(f"image {w}x{h} {enc}: {data.size} bytes do not fill it (step {step})")
    rows = data[: step * h].reshape(h, step)[:, : w * size]
    if kind == "colour":
        if enc not in _COLOUR_ENCODINGS:
            raise InputError(f"colour image encoding {msg.encoding!r} is not an 8-bit colour one")
        img = rows.reshape(h, w, channels) if channels > 1 else rows.reshape(h, w)
        code = {
            "bgr8": cv2.COLOR_BGR2RGB,
            "8uc3": cv2.COLOR_BGR2RGB,
            "rgba8": cv2.COLOR_RGBA2RGB,
            "bgra8": cv2.COLOR_BGRA2RGB,
            "mono8": cv2.COLOR_GRAY2RGB,
            "8uc1": cv2.COLOR_GRAY2RGB,
        }.get(enc)
        out = cv2.cvtColor(img, code) if code is not None else img
        return np.ascontiguousarray(out, dtype=np.uint8)
    if enc not in _DEPTH_ENCODINGS:
        raise InputError(f"depth image encoding {msg.encoding!r}: expected 16UC1 (mm) or 32FC1 (m)")
    order = ">" if msg.is_bigendian else "<"
    if enc == "32fc1":
        metres = rows.copy().view(f"{order}f4").reshape(h, w).astype(np.float64)
        return _metres_to_mm(metres)
    return rows.copy().view(f"{order}u2").reshape(h, w).astype(np.uint16)


def _metres_to_mm(metres: npt.NDArray[np.float64]) -> npt.NDArray[np.uint16]:
    ok = np.isfinite(metres) & (metres > 0) & (metres * 1000.0 < 65535.5)
    mm = np.zeros(metres.shape, np.uint16)
    mm[ok] = np.round(metres[ok] * 1000.0).astype(np.uint16)
    return mm


def _decode_compressed(msg: Any, kind: Kind) -> npt.NDArray[Any]:
    fmt = str(msg.format).lower()
    data = np.asarray(msg.data, dtype=np.uint8)
    if "compresseddepth" in fmt:
        if "32fc1" in fmt:
            raise InputError(f"compressed depth {msg.format!r}: only 16UC1 (mm) is read")
        data = data[12:]  # compressed_depth_image_transport's 12-byte config header
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise InputError(f"compressed image ({msg.format!r}): not a readable image")
    if kind == "depth":
        if img.ndim != 2 or img.dtype != np.uint16:
            raise InputError(f"compressed depth ({msg.format!r}) is not 16-bit single channel")
        return np.asarray(img, dtype=np.uint16)
    if img.dtype != np.uint8:
        raise InputError(f"compressed colour ({msg.format!r}) is not 8-bit")
    if img.ndim == 2:
        return np.asarray(cv2.cvtColor(img, cv2.COLOR_GRAY2RGB))
    code = cv2.COLOR_BGRA2RGB if img.shape[2] == 4 else cv2.COLOR_BGR2RGB
    return np.ascontiguousarray(cv2.cvtColor(img, code), dtype=np.uint8)


@dataclass(frozen=True)
class BagTopics:
    """The topics a :class:`BagSource` reads."""

    colour: str
    depth: str
    camera_info: str | None


def _kind_of(conn: Connection, first: Any) -> Kind | None:
    if conn.msgtype == COMPRESSED:
        fmt = str(first.format).lower()
        return "depth" if ("compresseddepth" in fmt or "16uc1" in fmt) else "colour"
    enc = str(first.encoding).lower()
    if enc in _DEPTH_ENCODINGS:
        return "depth"
    return "colour" if enc in _COLOUR_ENCODINGS else None


def _rank(topic: str, kind: Kind) -> tuple[int, str]:
    """Lower is preferred: registered depth over raw, colour over infrared."""
    t = topic.lower()
    if kind == "depth":
        good = ("depth_registered" in t) or ("aligned" in t) or ("registered" in t)
        return (0 if good else 1, topic)
    return (0 if ("color" in t or "rgb" in t) else 1, topic)


class BagSource:
    """A :class:`detect.FrameSource` over a ROS 1 ``.bag`` file or a ROS 2 bag folder.

    Parameters
    ----------
    path : the bag.
    colour_topic, depth_topic : the image topics (default: found by message type and
        encoding; registered depth and colour topics preferred).
    camera : intrinsics (default: the ``CameraInfo`` beside the colour topic, else any
        ``CameraInfo`` of the colour size, else the Xtion's at that size).
    max_dt_s : largest colour-depth stamp difference of a pair (default 0.02 s).

    Frames: ``index`` = position among the pairs; ``t_sensor_ns`` = ``t_mono_ns`` = the
    depth image's header stamp (ns; the bag's receive time when the stamp is zero).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        colour_topic: str | None = None,
        depth_topic: str | None = None,
        camera: CameraIntrinsics | None = None,
        max_dt_s: float = 0.02,
    ) -> None:
        self.path = Path(path)
        if not (math.isfinite(max_dt_s) and max_dt_s >= 0):
            raise InputError(f"max_dt_s must be seconds >= 0, got {max_dt_s}")
        self._max_dt_ns = round(max_dt_s * 1e9)
        self._reader: AnyReader | None = None
        reader = self._open()
        try:
            self.topics = self._find_topics(reader, colour_topic, depth_topic)
            self.camera = camera or self._find_camera(reader)
        finally:
            reader.close()

    def _open(self) -> AnyReader:
        """An open reader of the bag (close it)."""
        try:
            from rosbags.highlevel import AnyReader
            from rosbags.typesys import Stores, get_typestore
        except ImportError as err:
            raise InputError(
                "reading ROS bags needs the rosbags package: pip install 'holescan[ground]'"
            ) from err
        try:
            reader = AnyReader([self.path], default_typestore=get_typestore(Stores.LATEST))
            reader.open()
        except Exception as err:  # rosbags raises its own error kinds per format
            raise InputError(f"{self.path}: not a readable ROS bag ({err})") from err
        return reader

    def _find_topics(self, reader: AnyReader, colour: str | None, depth: str | None) -> BagTopics:
        found: dict[Kind, list[str]] = {"colour": [], "depth": []}
        images = [c for c in reader.connections if c.msgtype in (IMAGE, COMPRESSED)]
        for conn in images:
            for c, _, raw in reader.messages(connections=[conn]):
                kind = _kind_of(c, reader.deserialize(raw, c.msgtype))
                if kind is not None:
                    found[kind].append(conn.topic)
                break
        names = sorted({c.topic for c in images})
        for given in (colour, depth):
            if given is not None and given not in names:
                raise InputError(f"{self.path}: no image topic {given!r} (image topics: {names})")
        colour = colour or min(found["colour"], key=lambda t: _rank(t, "colour"), default=None)
        depth = depth or min(found["depth"], key=lambda t: _rank(t, "depth"), default=None)
        if colour is None or depth is None:
            missing = "colour" if colour is None else "depth"
            raise InputError(
                f"{self.path}: no {missing} image topic (sensor_msgs/Image or CompressedImage; "
                f"image topics: {names or 'none'})"
            )
        infos = [c.topic for c in reader.connections if c.msgtype == CAMERA_INFO]
        beside = colour.rsplit("/", 1)[0] + "/camera_info"
        info = beside if beside in infos else (infos[0] if infos else None)
        return BagTopics(colour, depth, info)

    def _first_colour_size(self, reader: AnyReader) -> tuple[int, int]:
        conns = [c for c in reader.connections if c.topic == self.topics.colour]
        for c, _, raw in reader.messages(connections=conns):
            img = decode_image(reader.deserialize(raw, c.msgtype), "colour")
            return img.shape[1], img.shape[0]
        raise InputError(f"{self.path}: no message on {self.topics.colour}")

    def _find_camera(self, reader: AnyReader) -> CameraIntrinsics:
        w, h = self._first_colour_size(reader)
        if self.topics.camera_info is not None:
            conns = [c for c in reader.connections if c.topic == self.topics.camera_info]
            for c, _, raw in reader.messages(connections=conns):
                info: Any = reader.deserialize(raw, c.msgtype)  # sensor_msgs/CameraInfo, ROS 1 or 2
                k = [float(v) for v in info.k] if hasattr(info, "k") else [float(v) for v in info.K]
                if (int(info.width), int(info.height)) != (w, h) or not k[0] > 0:
                    break
                return CameraIntrinsics(w, h, k[0], k[4], k[2], k[5])
        _log.warning("%s: no CameraInfo of the colour size: Xtion intrinsics assumed", self.path)
        return CameraIntrinsics.xtion(w, h)

    @property
    def reader(self) -> AnyReader | None:
        """The open bag reader while the source is open (for other topics of the bag)."""
        return self._reader

    def __enter__(self) -> BagSource:
        self._reader = self._open()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def __iter__(self) -> Iterator[Frame]:
        reader = self._reader
        if reader is None:
            raise InputError("use a BagSource as a context manager before iterating it")
        conns = [
            c for c in reader.connections if c.topic in (self.topics.colour, self.topics.depth)
        ]
        colours: deque[tuple[int, Any, Connection]] = deque()
        depths: deque[tuple[int, Any, Connection]] = deque()
        index = 0
        for conn, t_bag, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            item = (stamp_ns(msg, t_bag), msg, conn)
            (colours if conn.topic == self.topics.colour else depths).append(item)
            for frame in self._pairs(colours, depths, index, final=False):
                index += 1
                yield frame
        for frame in self._pairs(colours, depths, index, final=True):
            index += 1
            yield frame

    def _pairs(
        self,
        colours: deque[tuple[int, Any, Connection]],
        depths: deque[tuple[int, Any, Connection]],
        index: int,
        final: bool,
    ) -> Iterator[Frame]:
        """Pair the oldest depth once no colour still to come could be nearer to it."""
        dt = self._max_dt_ns
        while depths:
            t_d = depths[0][0]
            newest = colours[-1][0] if colours else None
            if not final and (newest is None or newest <= t_d + dt):
                return
            near = [c for c in colours if abs(c[0] - t_d) <= dt]
            _, dmsg, _ = depths.popleft()
            if not near:
                continue
            best = min(near, key=lambda c: abs(c[0] - t_d))
            while colours and colours[0] is not best:
                colours.popleft()
            colours.popleft()
            yield self._frame(index, best[1], dmsg, t_d)
            index += 1
        if colours:  # a colour older than every depth still to come by more than dt
            horizon = colours[-1][0]
            while colours and colours[0][0] < horizon - dt:
                colours.popleft()

    def _frame(self, index: int, cmsg: Any, dmsg: Any, t_ns: int) -> Frame:
        rgb = decode_image(cmsg, "colour")
        depth = decode_image(dmsg, "depth")
        shape = (self.camera.height, self.camera.width)
        if rgb.shape[:2] != shape or depth.shape != shape:
            raise InputError(
                f"{self.path}: colour {rgb.shape[1]}x{rgb.shape[0]} and depth "
                f"{depth.shape[1]}x{depth.shape[0]} differ from the camera {shape[1]}x{shape[0]}"
                f": give the depth topic registered to colour"
            )
        return Frame(index, rgb, depth, t_ns, t_ns)
