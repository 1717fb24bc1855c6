"""The detector's measured recall by range and view angle: what one look at a cell is worth.

The table is data, written by ``benchmarks/bench_recall.py`` from the simulator and the
independent generators (``recall_table.json`` beside this module, with its provenance).
A look at a cell from ``range`` metres at ``angle`` degrees between the line of sight and
the terrain's normal detects an access hole there with the recall of that bin; outside the
measured ranges and angles a look is worth nothing (a map does not claim coverage that was
never measured).
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
    recall : (R, A) float64 in [0, 1], the detector's recall of the access holes in each bin.
    holes : (R, A) int64, how many hole views each bin was measured on (0 = filled, see
        ``provenance``).
    provenance : what was measured, on which data, with which command and settings.
    """

    range_edges_m: FloatArray
    angle_edges_deg: FloatArray
    recall: FloatArray
    holes: npt.NDArray[np.int64]
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        r = np.asarray(self.range_edges_m, dtype=np.float64)
        a = np.asarray(self.angle_edges_deg, dtype=np.float64)
        p = np.asarray(self.recall, dtype=np.float64)
        n = np.asarray(self.holes, dtype=np.int64)
        if r.ndim != 1 or a.ndim != 1 or len(r) < 2 or len(a) < 2:
            raise MapError("recall table needs at least two range and two angle edges")
        if np.any(np.diff(r) <= 0) or np.any(np.diff(a) <= 0) or r[0] < 0 or a[0] < 0:
            raise MapError("recall table edges must be increasing and non-negative")
        if p.shape != (len(r) - 1, len(a) - 1) or n.shape != p.shape:
            raise MapError(f"recall table must be {len(r) - 1} x {len(a) - 1}, got {p.shape}")
        if not np.all(np.isfinite(p)) or p.min() < 0 or p.max() > 1:
            raise MapError("recall table values must be in 0..1")
        for name, v in (("range_edges_m", r), ("angle_edges_deg", a), ("recall", p), ("holes", n)):
            v.flags.writeable = False
            object.__setattr__(self, name, v)

    @property
    def max_range_m(self) -> float:
        return float(self.range_edges_m[-1])

    def pod(self, range_m: npt.ArrayLike, angle_deg: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """Probability of detection of one look, float32 like the inputs' broadcast shape.

        0 outside the table (nearer than its first range edge, beyond its last, more
        oblique than its last angle edge) and for non-finite inputs.
        """
        r = np.asarray(range_m, dtype=np.float64)
        a = np.asarray(angle_deg, dtype=np.float64)
        ri = np.searchsorted(self.range_edges_m, r, side="right") - 1
        ai = np.searchsorted(self.angle_edges_deg, a, side="right") - 1
        nr, na = self.recall.shape
        ok = (ri >= 0) & (ri < nr) & (ai >= 0) & (ai < na)
        value = self.recall[np.clip(ri, 0, nr - 1), np.clip(ai, 0, na - 1)]
        return np.where(ok, value, 0.0).astype(np.float32)

    def to_json(self) -> dict[str, Any]:
        """The table as the JSON object :meth:`from_json` reads."""
        return {
            "range_edges_m": [float(v) for v in self.range_edges_m],
            "angle_edges_deg": [float(v) for v in self.angle_edges_deg],
            "recall": [[round(float(v), 4) for v in row] for row in self.recall],
            "holes": [[int(v) for v in row] for row in self.holes],
            "provenance": self.provenance,
        }

    @classmethod
    def from_json(cls, obj: Any) -> RecallTable:
        """A table from its JSON object; a malformed one raises :class:`MapError`."""
        try:
            table = cls(
                np.asarray(obj["range_edges_m"], dtype=np.float64),
                np.asarray(obj["angle_edges_deg"], dtype=np.float64),
                np.asarray(obj["recall"], dtype=np.float64),
                np.asarray(obj["holes"], dtype=np.int64),
                dict(obj.get("provenance", {})),
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
