"""Records the detector takes and returns: camera intrinsics, parameters, detections."""

from __future__ import annotations

import enum
import math
import numbers
from dataclasses import dataclass, field, replace

import numpy as np

from holescan.detect._options import DefaultOptions
from holescan.errors import InputError


def _is_int(v: object) -> bool:
    return isinstance(v, int | np.integer) and not isinstance(v, bool)


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the (depth-registered) camera.

    Pixel ``(u, v)`` with depth ``Z`` metres back-projects to
    ``X = (u - cx) Z / fx``, ``Y = (v - cy) Z / fy`` in the optical frame
    (x right, y down, z forward).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    depth_unit_m: float = 0.001

    def __post_init__(self) -> None:
        if (
            not (_is_int(self.width) and _is_int(self.height))
            or self.width <= 0
            or self.height <= 0
        ):
            raise InputError(
                f"camera size must be positive whole pixels, got {self.width}x{self.height}"
            )
        values = (self.fx, self.fy, self.cx, self.cy, self.depth_unit_m)
        if not all(isinstance(v, numbers.Real) and math.isfinite(v) for v in values):
            raise InputError(
                f"camera fx, fy, cx, cy, depth_unit_m must be finite numbers, got "
                f"{self.fx}, {self.fy}, {self.cx}, {self.cy}, {self.depth_unit_m}"
            )
        if self.fx <= 0 or self.fy <= 0:
            raise InputError(f"camera focal lengths must be positive, got {self.fx}, {self.fy}")
        if not 0 < self.depth_unit_m <= 1.0:
            raise InputError(
                f"camera depth_unit_m must be in (0, 1] metres per depth unit "
                f"(0.001 = millimetres), got {self.depth_unit_m}"
            )

    @classmethod
    def xtion(cls, width: int = 640, height: int = 480) -> CameraIntrinsics:
        """Asus Xtion Pro at ``width`` x ``height``: 58 x 45 deg FOV, f = 570.3 px at 640x480."""
        s = width / 640.0
        return cls(width, height, 570.3 * s, 570.3 * s, (width - 1) / 2, (height - 1) / 2)

    def scaled(self, factor: float) -> CameraIntrinsics:
        """Intrinsics of the image resized by ``factor`` (0.25 = quarter resolution)."""
        return CameraIntrinsics(
            round(self.width * factor),
            round(self.height * factor),
            self.fx * factor,
            self.fy * factor,
            (self.cx + 0.5) * factor - 0.5,
            (self.cy + 0.5) * factor - 0.5,
            self.depth_unit_m,
        )

    def to_dict(self) -> dict[str, float]:
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "depth_unit_m": self.depth_unit_m,
        }


class Mode(enum.Enum):
    """Which detector runs: the method as published, or holescan's default."""

    PAPER = "paper"
    DEFAULT = "default"


@dataclass(frozen=True)
class Searcher:
    """Who has to fit through the hole: sizes in metres (ALGORITHM.md, Panero & Zelnik 1979).

    A region scores 1 on width when its major/minor axes reach ``major_m``/``minor_m`` and 0
    at ``min_fraction`` of those; its depth scores 0 at ``depth_low_m`` and 1 at
    ``depth_high_m`` below the rim.
    """

    name: str
    major_m: float
    minor_m: float
    depth_low_m: float
    depth_high_m: float
    min_fraction: float = 0.5


HUMAN = Searcher("human", major_m=0.655, minor_m=0.368, depth_low_m=0.200, depth_high_m=1.951)
DOG = Searcher("dog", major_m=0.45, minor_m=0.25, depth_low_m=0.15, depth_high_m=1.2)
ROBOT = Searcher("robot", major_m=0.35, minor_m=0.20, depth_low_m=0.10, depth_high_m=0.8)
SEARCHERS: dict[str, Searcher] = {s.name: s for s in (HUMAN, DOG, ROBOT)}


@dataclass(frozen=True)
class DetectParams:
    """Everything that changes what the detector finds.

    ``PAPER`` is the method as published (Kong et al. 2015); ``DEFAULT`` is holescan's.
    Use :func:`dataclasses.replace` (or :meth:`with_searcher`) to derive variants.
    """

    mode: Mode = Mode.DEFAULT
    searcher: Searcher = HUMAN
    superpixels: int = 9
    # Paper mode: ERS settings (prototype defaults) and score thresholds.
    ers_lambda: float = 0.5
    ers_sigma: float = 5.0
    dark_threshold: float = 0.274
    contrast_threshold: float = 0.267
    weights: tuple[float, float, float, float, float] = (0.2, 0.2, 0.2, 0.2, 0.2)
    bias: float = 0.0
    # Default mode.
    work_scale: float = 0.25
    max_range_m: float = 4.0
    min_score: float = 0.05
    nms_iou: float = 0.3
    #: The default detector's design choices (the ablation study switches them off).
    options: DefaultOptions = DefaultOptions()  # noqa: RUF009 (frozen: one shared instance)
    extra: dict[str, float] = field(default_factory=dict, compare=False, hash=False)

    def with_searcher(self, searcher: Searcher | str) -> DetectParams:
        s = SEARCHERS[searcher] if isinstance(searcher, str) else searcher
        return replace(self, searcher=s)


PAPER = DetectParams(mode=Mode.PAPER)
DEFAULT = DetectParams(mode=Mode.DEFAULT)


@dataclass(frozen=True)
class FeatureScores:
    """The paper's five attribute scores, each in [0, 1] (1 = more hole-like).

    depth (Sd), width (Sw), fill (Sr, aspect/fill ratio), darkness (Sb, absolute
    brightness), contrast (Sc, darker than the neighbours).
    """

    depth: float
    width: float
    fill: float
    darkness: float
    contrast: float

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        return (self.depth, self.width, self.fill, self.darkness, self.contrast)


@dataclass(frozen=True)
class Detection:
    """One candidate access hole in one image.

    box : (x, y, w, h) pixels, x/y of the top-left corner.
    score : confidence in [0, 1].
    features : the five attribute scores that explain the score.
    depth_rel_m : how far the region lies below its rim (a lower bound when
        ``beyond_range``).
    major_m, minor_m : metric axes of the opening.
    rim_depth_m : camera depth of the opening's rim (the surrounding terrain), used to
        geotag the hole; the floor is deeper or unread.
    beyond_range : the floor gave no depth reading (deeper than the sensor's range).
    relative_brightness : for a region without readings, the median luminance of its
        no-reading pixels over that of the readable rubble around it (a void at dawn is
        darker, ~0.1-0.5; a surface the sensor does not return from, ~1 or more);
        None when the region has readings.
    p_hole : probability that this is a true access hole (default mode, calibrated on
        independent scene sets, see :mod:`detect._calibration`); None in paper mode,
        whose score is the published method's own.
    opening_m : centre of the opening on the plane of its rim, metres in the camera's
        optical frame (x right, y down, z forward): where the hole is, whatever the view
        (the box centre is not: seen obliquely, the box spans the visible far wall and the
        near rim). None when not measured (paper mode, the baseline, older logs).
    rim_normal : unit normal of the rim plane in the optical frame, toward the camera;
        None when not measured.
    rim_seen : fraction of the opening's outline bordered by rim the sensor saw (not the
        image border, no unread pixels, no nearer edge in front): 1 = the whole rim seen;
        None when not measured.
    border_cut : the opening is cut by the frame's border or an unread band along it: its
        rim there is unknown (not open), its box runs to the frame's edge.
    inside_on_plane, inside_behind : for a region without readings (``beyond_range``),
        the fractions of its interior (well inside the outline) read *on* the rim's plane
        (what an absorbing surface's islands of readings do) and *behind* it (a void's
        walls and floor): the rim-plane test's evidence (:func:`detect.plane_verdict`
        turns it into a verdict the tracker counts over views). Both 0: nothing read
        inside. None when not measured (a region with readings, too small a region, a
        low score, paper mode, older logs).
    """

    box: tuple[int, int, int, int]
    score: float
    features: FeatureScores
    depth_rel_m: float
    major_m: float
    minor_m: float
    rim_depth_m: float
    beyond_range: bool = False
    relative_brightness: float | None = None
    p_hole: float | None = None
    opening_m: tuple[float, float, float] | None = None
    rim_normal: tuple[float, float, float] | None = None
    rim_seen: float | None = None
    border_cut: bool = False
    inside_on_plane: float | None = None
    inside_behind: float | None = None

    @property
    def centre_px(self) -> tuple[float, float]:
        x, y, w, h = self.box
        return (x + w / 2.0 - 0.5, y + h / 2.0 - 0.5)

    def explain(self) -> str:
        """One line a rescuer can read: why this is (or is not) a hole."""
        f = self.features
        depth = (
            f">{self.depth_rel_m:.1f} m (no floor reading)"
            if self.beyond_range
            else (f"{self.depth_rel_m:.2f} m")
        )
        prob = "" if self.p_hole is None else f"this frame's p_hole {self.p_hole:.2f}, "
        light = (
            ""
            if self.relative_brightness is None
            else f"; inside {self.relative_brightness:.2f}x as bright as the rubble around"
        )
        if self.inside_on_plane is not None and self.inside_behind is not None:
            light += (
                f"; inside read {100 * self.inside_on_plane:.0f} % on the rim's plane, "
                f"{100 * self.inside_behind:.0f} % behind it"
            )
        return (
            f"{prob}score {self.score:.2f}: {self.major_m:.2f} x {self.minor_m:.2f} m opening, "
            f"{depth} deep; depth {f.depth:.2f} width {f.width:.2f} fill {f.fill:.2f} "
            f"dark {f.darkness:.2f} contrast {f.contrast:.2f}{light}"
        )
