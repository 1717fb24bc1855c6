"""Detections in the flight log: the ``/detections`` JSON records and the
``/detections/annotations`` boxes Foxglove draws on the colour image."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation

from holescan.detect import Detection, FeatureScores
from holescan.errors import InputError
from holescan.flightlog.schemas import float_or_nan, float_or_none, jsonable, timestamp

__all__ = ["annotations_message", "decode_detection", "detection_json"]


def detection_json(det: Detection) -> dict[str, Any]:
    out: dict[str, Any] = jsonable(det)
    return out


def decode_detection(obj: Mapping[str, Any]) -> Detection:
    """Inverse of :func:`detection_json`; logs written before ``p_hole``,
    ``relative_brightness``, ``opening_m``, ``rim_normal``, ``rim_seen``,
    ``inside_on_plane`` and ``inside_behind`` existed (or in paper mode) give None for
    them, and False for ``border_cut``."""
    f = obj["features"]
    x, y, w, h = (int(v) for v in obj["box"])
    return Detection(
        box=(x, y, w, h),
        score=float_or_nan(obj["score"]),
        features=FeatureScores(
            **{k: float_or_nan(f[k]) for k in FeatureScores.__dataclass_fields__}
        ),
        depth_rel_m=float_or_nan(obj["depth_rel_m"]),
        major_m=float_or_nan(obj["major_m"]),
        minor_m=float_or_nan(obj["minor_m"]),
        rim_depth_m=float_or_nan(obj["rim_depth_m"]),
        beyond_range=bool(obj.get("beyond_range", False)),
        relative_brightness=float_or_none(obj.get("relative_brightness")),
        p_hole=float_or_none(obj.get("p_hole")),
        opening_m=_opt_xyz(obj.get("opening_m")),
        rim_normal=_opt_xyz(obj.get("rim_normal")),
        rim_seen=float_or_none(obj.get("rim_seen")),
        border_cut=bool(obj.get("border_cut", False)),
        inside_on_plane=_opt_fraction(obj.get("inside_on_plane")),
        inside_behind=_opt_fraction(obj.get("inside_behind")),
    )


def _opt_fraction(value: Any) -> float | None:
    """A logged fraction in [0, 1], or None (not measured)."""
    v = float_or_none(value)
    if v is not None and not 0.0 <= v <= 1.0:
        raise InputError(f"expected a fraction in [0, 1] or null, got {value!r}")
    return v


def _opt_xyz(value: Any) -> tuple[float, float, float] | None:
    if value is None:
        return None
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise InputError(f"expected 3 numbers or null, got {value!r}")
    x, y, z = (float_or_nan(v) for v in value)
    return (x, y, z)


def _score_color(score: float) -> Color:
    s = min(max(score, 0.0), 1.0)
    return Color(r=1.0, g=1.0 - s, b=0.0, a=1.0)


def annotations_message(detections: Sequence[Detection], t_unix_ns: int) -> ImageAnnotations:
    """Boxes as LINE_LOOP outlines (yellow -> red with the score) and the score as text."""
    stamp = timestamp(t_unix_ns)
    msg = ImageAnnotations()
    for det in detections:
        x, y, w, h = det.box
        color = _score_color(det.score)
        corners = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)]
        msg.points.append(
            PointsAnnotation(
                timestamp=stamp,
                type=PointsAnnotation.Type.LINE_LOOP,
                points=[Point2(x=float(u) - 0.5, y=float(v) - 0.5) for u, v in corners],
                outline_color=color,
                thickness=2.0,
            )
        )
        msg.texts.append(
            TextAnnotation(
                timestamp=stamp,
                position=Point2(x=float(x), y=float(max(y - 4, 0))),
                text=f"{det.score:.2f}",
                font_size=14.0,
                text_color=color,
                background_color=Color(r=0.0, g=0.0, b=0.0, a=0.6),
            )
        )
    return msg
