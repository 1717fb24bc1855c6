"""The detector's measured recall by range, view angle and image position: what one look
at a cell is worth.

The table is data, written by ``benchmarks/bench_recall.py`` from the simulator and the
independent generators (``recall_table.json`` beside this module, with its provenance).
A look at a cell from ``range`` metres at ``angle`` degrees between the line of sight and
the terrain's normal, seen ``border`` pixels (at 640 px wide) from the edge of the frame's
read area (the frame without its unread border bands), detects an access hole there with
the recall of that bin; outside the measured ranges and angles, and in the unread bands, a
look is worth nothing (a map does not claim coverage that was never measured).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import numpy as np
import numpy.typing as npt

from holescan.mapping.errors import MapError

__all__ = ["RecallTable", "default_recall_table"]

FloatArray = npt.NDArray[np.float64]

_TABLE_FILE = "recall_table.json"


@dataclass(frozen=True, eq=False)
class RecallTable:
    """Per-look probability of detection by range and view angle.

    range_edges_m : (R + 1,) increasing bin edges, metres (line-of-sight distance).
    angle_edges_deg : (A + 1,) increasing bin edges, degrees between the line of sight and
        the terrain's normal (0 = looking straight at it).
    border_edges_px : (B + 1,) increasing bin edges of the distance from the edge of the
        frame's read area, pixels at 640 px wide (a table without it: one bin, [0, inf)).
    recall : (R, A, B) float64 in [0, 1], the detector's recall of the access holes in each
        bin ((R, A) is read as one border bin).
    holes : same shape, int64, how many hole views each bin was measured on (0 = filled,
        see ``provenance``).
    provenance : what was measured, on which data, with which command and settings.
    """

    range_edges_m: FloatArray
    angle_edges_deg: FloatArray
    recall: FloatArray
    holes: npt.NDArray[np.int64]
    provenance: dict[str, Any] = field(default_factory=dict)
    border_edges_px: FloatArray = field(default_factory=lambda: np.array([0.0, np.inf]))

    def __post_init__(self) -> None:
        r = np.asarray(self.range_edges_m, dtype=np.float64)
        a = np.asarray(self.angle_edges_deg, dtype=np.float64)
        b = np.asarray(self.border_edges_px, dtype=np.float64)
        p = np.asarray(self.recall, dtype=np.float64)
        n = np.asarray(self.holes, dtype=np.int64)
        if r.ndim != 1 or a.ndim != 1 or len(r) < 2 or len(a) < 2:
            raise MapError("recall table needs at least two range and two angle edges")
        if b.ndim != 1 or len(b) < 2 or np.isnan(b).any():
            raise MapError("recall table needs at least two border edges")
        if (
            np.any(np.diff(r) <= 0)
            or np.any(np.diff(a) <= 0)
            or np.any(np.diff(b) <= 0)
            or min(r[0], a[0], b[0]) < 0
        ):
            raise MapError("recall table edges must be increasing and non-negative")
        if p.ndim == 2:
            p = p[..., None]
        if n.ndim == 2:
            n = n[..., None]
        shape = (len(r) - 1, len(a) - 1, len(b) - 1)
        if p.shape != shape or n.shape != p.shape:
            raise MapError(f"recall table must be {' x '.join(map(str, shape))}, got {p.shape}")
        if not np.all(np.isfinite(p)) or p.min() < 0 or p.max() > 1:
            raise MapError("recall table values must be in 0..1")
        for name, v in (
            ("range_edges_m", r),
            ("angle_edges_deg", a),
            ("border_edges_px", b),
            ("recall", p),
            ("holes", n),
        ):
            v.flags.writeable = False
            object.__setattr__(self, name, v)

    @property
    def max_range_m(self) -> float:
        return float(self.range_edges_m[-1])

    def pod(
        self,
        range_m: npt.ArrayLike,
        angle_deg: npt.ArrayLike,
        border_px: npt.ArrayLike | None = None,
    ) -> npt.NDArray[np.float32]:
        """Probability of detection of one look, float32 like the inputs' broadcast shape.

        border_px : distance from the edge of the frame's read area, pixels at 640 px wide
            (None: far from it, the last border bin).

        0 outside the table (nearer than its first range edge, beyond its last, more
        oblique than its last angle edge, in an unread band: ``border_px < 0``) and for
        non-finite inputs.
        """
        r = np.asarray(range_m, dtype=np.float64)
        a = np.asarray(angle_deg, dtype=np.float64)
        nr, na, nb = self.recall.shape
        ri = np.searchsorted(self.range_edges_m, r, side="right") - 1
        ai = np.searchsorted(self.angle_edges_deg, a, side="right") - 1
        if border_px is None:
            bi = np.full(np.broadcast(r, a).shape, nb - 1)
        else:
            b = np.asarray(border_px, dtype=np.float64)
            bi = np.searchsorted(self.border_edges_px, b, side="right") - 1
            bi = np.where(np.isposinf(b) & (bi >= nb), nb - 1, bi)
        ok = (ri >= 0) & (ri < nr) & (ai >= 0) & (ai < na) & (bi >= 0) & (bi < nb)
        value = self.recall[np.clip(ri, 0, nr - 1), np.clip(ai, 0, na - 1), np.clip(bi, 0, nb - 1)]
        return np.where(ok, value, 0.0).astype(np.float32)

    def to_json(self) -> dict[str, Any]:
        """The table as the JSON object :meth:`from_json` reads."""
        return {
            "range_edges_m": [float(v) for v in self.range_edges_m],
            "angle_edges_deg": [float(v) for v in self.angle_edges_deg],
            # JSON has no infinity: an open last edge is written as null.
            "border_edges_px": [None if np.isinf(v) else float(v) for v in self.border_edges_px],
            "recall": [[[round(float(v), 4) for v in c] for c in row] for row in self.recall],
            "holes": [[[int(v) for v in c] for c in row] for row in self.holes],
            "provenance": self.provenance,
        }

    @classmethod
    def from_json(cls, obj: Any) -> RecallTable:
        """A table from its JSON object; a malformed one raises :class:`MapError`."""
        try:
            edges = obj.get("border_edges_px", [0.0, None])
            table = cls(
                np.asarray(obj["range_edges_m"], dtype=np.float64),
                np.asarray(obj["angle_edges_deg"], dtype=np.float64),
                np.asarray(obj["recall"], dtype=np.float64),
                np.asarray(obj["holes"], dtype=np.int64),
                dict(obj.get("provenance", {})),
                np.asarray([np.inf if v is None else v for v in edges], dtype=np.float64),
            )
        except (KeyError, TypeError, ValueError) as err:
            if isinstance(err, MapError):
                raise
            raise MapError(f"recall table is malformed: {err}") from err
        return table

    @classmethod
    def uniform(
        cls, pod: float, max_range_m: float = 4.5, max_angle_deg: float = 60.0
    ) -> RecallTable:
        """One value everywhere up to a range and angle (tests and what-if studies)."""
        if not (math.isfinite(pod) and 0.0 <= pod <= 1.0):
            raise MapError(f"pod must be in 0..1, got {pod}")
        return cls(
            np.array([0.0, max_range_m]),
            np.array([0.0, max_angle_deg]),
            np.array([[pod]]),
            np.array([[0]]),
            {"source": f"uniform {pod}"},
        )


def default_recall_table() -> RecallTable:
    """The measured table shipped with holescan (``mapping/recall_table.json``)."""
    text = resources.files("holescan.mapping").joinpath(_TABLE_FILE).read_text()
    return RecallTable.from_json(json.loads(text))
