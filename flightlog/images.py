"""How the flight log stores the pixels of a frame: colour and depth codecs, both ways.

Pure conversions (no files, no clocks). Three ways per image, chosen in
:class:`~flightlog.options.LogOptions` (``color``, ``depth``, ``jpeg_quality``):

================  ===========================  =====================================
image, codec      schema                       ``format`` / ``encoding``
================  ===========================  =====================================
colour ``jpeg``   ``foxglove.CompressedImage`` ``jpeg`` (lossy, quality 1-100)
colour ``png``    ``foxglove.CompressedImage`` ``png`` (8-bit RGB, lossless)
colour ``raw``    ``foxglove.RawImage``        ``rgb8``
depth ``zstd``    ``foxglove.CompressedImage`` ``16UC1; zstd; 640x480`` (lossless)
depth ``png``     ``foxglove.CompressedImage`` ``png`` (16-bit grey, lossless)
depth ``raw``     ``foxglove.RawImage``        ``16UC1`` (the layout of older logs)
================  ===========================  =====================================

Depth is always millimetres, 0 = no reading. Foxglove shows ``jpeg`` and ``png`` images
itself; a ``16UC1; zstd; WxH`` depth image is self-describing (pixel type, codec and size
in the format string; the data is one zstd frame of the little-endian ``uint16`` pixels,
row-major, with its content size) but Foxglove cannot show it (choose ``depth = "png"`` to
look at depth in Foxglove, at 5-10x the encoding time). Readers decide by the message's
schema and format, never by the settings, so any mix of old and new logs reads back.
"""

from __future__ import annotations

import re
from typing import Any, Final, Literal, get_args

import cv2
import numpy as np
import numpy.typing as npt
import zstandard
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.timestamp_pb2 import Timestamp

from holescan.errors import InputError
from holescan.flightlog.errors import FlightLogError

__all__ = [
    "COLOR_CODECS",
    "DEPTH_CODECS",
    "ColorCodec",
    "DepthCodec",
    "ImageEncoder",
    "decode_compressed",
    "image_from_raw",
    "raw_image_message",
]

ColorCodec = Literal["jpeg", "png", "raw"]
DepthCodec = Literal["zstd", "png", "raw"]
COLOR_CODECS: Final[tuple[str, ...]] = get_args(ColorCodec)
DEPTH_CODECS: Final[tuple[str, ...]] = get_args(DepthCodec)

#: zstd level of depth images: level 1 is the fast end (1.6 ms per VGA frame here, 116 KB
#: on simulated frames; level 3 gains 3 % for the same time on x86 and more on a Pi).
ZSTD_DEPTH_LEVEL: Final = 1
_ZSTD_FORMAT: Final = re.compile(r"16UC1; zstd; (\d{1,5})x(\d{1,5})")
_MAX_PIXELS: Final = 1 << 26  # a bound on what a damaged format string can make us allocate
_CAMERA_FRAME: Final = "camera"


def _timestamp(t_ns: int) -> Timestamp:
    return Timestamp(seconds=t_ns // 1_000_000_000, nanos=t_ns % 1_000_000_000)


def raw_image_message(image: npt.NDArray[Any], t_unix_ns: int) -> RawImage:
    """``foxglove.RawImage`` of an (H, W, 3) uint8 RGB (``rgb8``) or an (H, W) uint16
    millimetre depth image (``16UC1``, little-endian, step = 2 W, 0 = no reading)."""
    h, w = image.shape[:2]
    if image.ndim == 3:
        encoding, step, data = "rgb8", 3 * w, np.ascontiguousarray(image).tobytes()
    else:
        encoding, step = "16UC1", 2 * w
        data = np.ascontiguousarray(image, dtype="<u2").tobytes()
    return RawImage(
        timestamp=_timestamp(t_unix_ns),
        frame_id=_CAMERA_FRAME,
        width=w,
        height=h,
        encoding=encoding,
        step=step,
        data=data,
    )


def image_from_raw(msg: RawImage) -> npt.NDArray[Any]:
    """Inverse of :func:`raw_image_message`: a writable (H, W, 3) uint8 or (H, W) uint16."""
    h, w = int(msg.height), int(msg.width)
    try:
        if msg.encoding == "rgb8":
            flat = np.frombuffer(msg.data, np.uint8)
            return flat.reshape(h, msg.step)[:, : 3 * w].reshape(h, w, 3).copy()
        if msg.encoding in ("16UC1", "mono16"):
            flat = np.frombuffer(msg.data, "<u2")
            return flat.reshape(h, msg.step // 2)[:, :w].astype(np.uint16)
    except ValueError as err:  # data length does not match width, height, step
        raise FlightLogError(f"damaged {msg.encoding} image ({w}x{h}): {err}") from err
    raise InputError(f"unsupported image encoding {msg.encoding!r} (expected rgb8 or 16UC1)")


class ImageEncoder:
    """Encodes the frames of one log writer (holds its zstd context: one thread only).

    color : ``jpeg`` (lossy, ``jpeg_quality``), ``png`` or ``raw``.
    depth : ``zstd`` (lossless, fast), ``png`` (lossless, Foxglove shows it) or ``raw``.
    """

    def __init__(self, color: ColorCodec, depth: DepthCodec, jpeg_quality: int) -> None:
        if color not in COLOR_CODECS:
            raise InputError(f"colour codec must be one of {list(COLOR_CODECS)}, got {color!r}")
        if depth not in DEPTH_CODECS:
            raise InputError(f"depth codec must be one of {list(DEPTH_CODECS)}, got {depth!r}")
        if not 1 <= jpeg_quality <= 100:
            raise InputError(f"jpeg_quality must be 1..100, got {jpeg_quality}")
        self.color, self.depth, self.jpeg_quality = color, depth, int(jpeg_quality)
        self._zstd = zstandard.ZstdCompressor(level=ZSTD_DEPTH_LEVEL, write_content_size=True)

    def color_message(
        self, rgb: npt.NDArray[np.uint8], t_unix_ns: int
    ) -> RawImage | CompressedImage:
        """The colour image, (H, W, 3) uint8 RGB, as this encoder stores it."""
        if self.color == "raw":
            return raw_image_message(rgb, t_unix_ns)
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        if self.color == "jpeg":
            ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
        else:
            ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise FlightLogError(f"OpenCV could not encode a {rgb.shape} colour image")
        return CompressedImage(
            timestamp=_timestamp(t_unix_ns),
            frame_id=_CAMERA_FRAME,
            format=self.color,
            data=buf.tobytes(),
        )

    def depth_message(
        self, depth: npt.NDArray[np.uint16], t_unix_ns: int
    ) -> RawImage | CompressedImage:
        """The depth image, (H, W) uint16 millimetres, as this encoder stores it."""
        if self.depth == "raw":
            return raw_image_message(depth, t_unix_ns)
        h, w = depth.shape
        if self.depth == "zstd":
            fmt = f"16UC1; zstd; {w}x{h}"
            data = self._zstd.compress(np.ascontiguousarray(depth, dtype="<u2").tobytes())
        else:
            fmt = "png"
            ok, buf = cv2.imencode(".png", depth, [cv2.IMWRITE_PNG_COMPRESSION, 1])
            if not ok:
                raise FlightLogError(f"OpenCV could not encode a {depth.shape} depth image")
            data = buf.tobytes()
        return CompressedImage(
            timestamp=_timestamp(t_unix_ns), frame_id=_CAMERA_FRAME, format=fmt, data=data
        )


def decode_compressed(msg: CompressedImage, kind: Literal["color", "depth"]) -> npt.NDArray[Any]:
    """The pixels of a ``foxglove.CompressedImage``: (H, W, 3) uint8 RGB for ``color``,
    (H, W) uint16 millimetres for ``depth``.

    Raises :class:`FlightLogError` when the data does not decode to that kind of image
    (damaged bytes, an unknown format, a colour picture on the depth topic).
    """
    fmt = msg.format.strip().lower()
    data = bytes(msg.data)
    if kind == "depth":
        m = _ZSTD_FORMAT.fullmatch(msg.format.strip())
        if m is not None:
            w, h = int(m.group(1)), int(m.group(2))
            if not 0 < w * h <= _MAX_PIXELS:
                raise FlightLogError(f"depth image size {w}x{h} is implausible")
            try:
                raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=2 * w * h)
            except zstandard.ZstdError as err:
                raise FlightLogError(f"damaged zstd depth image: {err}") from err
            if len(raw) != 2 * w * h:
                raise FlightLogError(f"zstd depth image holds {len(raw)} bytes, not {w}x{h}x2")
            return np.frombuffer(raw, "<u2").reshape(h, w).astype(np.uint16)
    if fmt not in ("jpeg", "jpg", "png"):
        raise FlightLogError(f"unsupported {kind} image format {msg.format!r}")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if img is None:
        raise FlightLogError(f"damaged {fmt} {kind} image ({len(data)} bytes)")
    if kind == "depth":
        if img.ndim != 2 or img.dtype != np.uint16:
            raise FlightLogError(f"a {fmt} depth image must be 16-bit grey, got {img.dtype}")
        return np.asarray(img, dtype=np.uint16)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise FlightLogError(f"a {fmt} colour image must be 8-bit RGB, got {img.shape}")
    return np.ascontiguousarray(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
