"""The demo's search map: the flight's frames fused, the searched fraction, each miss explained.

While the demo reads its flight log back (:func:`demo._run._views_and_track`), every
``every``-th posed frame goes into a :class:`mapping.SearchMap` over the simulated world
(placed by the pose logged with it, as reprocessing does). Against the planned area it
gives the searched fraction; for each true access hole the flight did not find, the
coverage over its opening says whether it lay in a gap (the sensor never saw it well
enough) or was seen and not detected. With rasterio (the ``ground`` extra) the map's files
are written too (:func:`ground.searchmap.write_map_outputs`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Polygon, box

from holescan.detect import CameraIntrinsics
from holescan.flightlog import LoggedFrame, LoggedPose, read_flight_log
from holescan.geotag import CameraMount, Hole, VehiclePose, camera_pose_local, crop_view
from holescan.ground.report.searchmap import search_map_section
from holescan.mapping import MapGrid, MapLayers, SearchMap
from holescan.missions import SurveyParams
from holescan.sim import RubbleWorld, SortieParams

__all__ = ["DemoMap", "DemoMapper", "views_and_track"]


@dataclasses.dataclass(frozen=True)
class DemoMap:
    """searched_fraction : of the planned area, coverage >= threshold. hole_coverage : true
    hole id -> median coverage over its opening. files : the map's files (none without
    rasterio: ``note`` says so)."""

    searched_fraction: float
    area_m2: float
    threshold: float
    hole_coverage: dict[int, float]
    frames: int
    files: tuple[tuple[str, Path], ...] = ()
    note: str = ""
    section: str | None = None
    """The report's search-map section."""

    def numbers(self, missed_ids: Sequence[int]) -> dict[str, Any]:
        """``searched_fraction`` and, per true hole not found, ``missed_why`` (demo.json)."""
        why = {str(i): self.why_missed(i) for i in missed_ids}
        return {"searched_fraction": self.searched_fraction, "missed_why": why}

    def why_missed(self, truth_id: int) -> str:
        c = self.hole_coverage.get(truth_id, 0.0)
        if c < self.threshold:
            return f"in a gap (coverage {c:.2f}: not seen well enough to find a hole)"
        return f"seen and not detected (coverage {c:.2f})"


class DemoMapper:
    """Fuses the demo's logged frames; :meth:`finish` gives the :class:`DemoMap`."""

    def __init__(
        self,
        world: RubbleWorld,
        sortie: SortieParams,
        camera: CameraIntrinsics,
        mount: CameraMount,
        *,
        cell_m: float = 0.02,
        every: int = 3,
        threshold: float = 0.5,
    ) -> None:
        sx, sy = world.size_m
        self.world = world
        self.sortie = sortie
        self.frame = sortie.anchor.frame
        self.camera, self.mount, self.every, self.threshold = camera, mount, every, threshold
        self.map = SearchMap(MapGrid.covering(0.0, 0.0, sx, sy, cell_m), self.frame)
        self.frames = 0

    def add(self, rec: LoggedFrame) -> None:
        if rec.pose is None or rec.frame.index % self.every:
            return
        pose = camera_pose_local(self.frame, self.mount, rec.pose)
        self.map.add_frame(rec.frame.depth, rec.frame.rgb, self.camera, pose)
        self.frames += 1

    def area(self) -> Polygon:
        """The planned area in the world's metres (the survey's rectangle)."""
        m = self.sortie.margin_m
        sx, sy = self.world.size_m
        return box(m, m, sx - m, sy - m)

    def finish(
        self,
        out: Path,
        confirmed: Sequence[Hole],
        boot_to_unix_ns: int | None,
        tiers: Mapping[int, str] | None = None,
    ) -> DemoMap:
        layers = self.map.layers()
        area = self.area()
        fraction = _searched(layers, area, self.threshold)
        cov = {}
        for h in self.world.access_holes:
            inside = _inside(layers, Polygon(h.opening))
            cov[h.id] = float(np.median(layers.coverage[inside])) if inside.any() else 0.0
        base = DemoMap(fraction, float(area.area), self.threshold, cov, self.frames)

        def section(searched: float, gaps: Sequence[Polygon]) -> str:
            return search_map_section(
                layers,
                self.frame,
                confirmed,
                searched_fraction=searched,
                area_m2=float(area.area),
                planned=True,
                threshold=self.threshold,
                gaps=gaps,
            )

        try:
            from holescan.ground.searchmap import write_map_outputs
        except ImportError:
            return dataclasses.replace(
                base,
                note="map files not written: GeoTIFFs need rasterio "
                "(pip install 'holescan[ground]')",
                section=section(fraction, ()),
            )
        res = write_map_outputs(
            out,
            "flight",
            layers,
            self.frame,
            confirmed,
            area=area,
            threshold=self.threshold,
            survey=SurveyParams(altitude_m=self.sortie.altitude_m),
            boot_to_unix_ns=boot_to_unix_ns,
            tiers=tiers,
        )
        g = res.gaps
        return dataclasses.replace(
            base,
            files=res.files,
            searched_fraction=g.searched_fraction,
            section=section(g.searched_fraction, g.gaps),
        )


def _inside(layers: MapLayers, poly: Polygon) -> np.ndarray:
    e, n = layers.grid.centres()
    ee, nn = np.meshgrid(e, n)
    return np.asarray(shapely.contains_xy(poly, ee, nn))


def _searched(layers: MapLayers, area: Polygon, threshold: float) -> float:
    inside = _inside(layers, area)
    if not inside.any():
        return 0.0
    return float(np.mean(layers.coverage[inside] >= threshold))


def views_and_track(
    files: Sequence[Path], holes: Sequence[Hole], on_frame: Callable[[LoggedFrame], None]
) -> tuple[
    dict[int, tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], tuple[int, ...]]],
    list[VehiclePose],
    int | None,
]:
    """Read the log once: best views (cropped), track, boot -> Unix; frames to ``on_frame``."""
    wanted: dict[int, list[Hole]] = {}
    for h in holes:
        if h.best_frame_index is not None:
            wanted.setdefault(h.best_frame_index, []).append(h)
    views: dict[int, tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], tuple[int, ...]]] = {}
    track: list[VehiclePose] = []
    boot_to_unix: int | None = None
    for rec in read_flight_log(files, kinds={LoggedFrame, LoggedPose}):
        if isinstance(rec, LoggedPose):
            track.append(rec.pose)
            boot_to_unix = rec.t_unix_ns - rec.pose.t_boot_ns
            continue
        assert isinstance(rec, LoggedFrame)
        on_frame(rec)
        for h in wanted.get(rec.frame.index, ()):
            rgb, box = crop_view(rec.frame.rgb, h.best_box)
            depth, _ = crop_view(rec.frame.depth, h.best_box)
            views[h.id] = (rgb.copy(), depth.copy(), box)
    return views, track, boot_to_unix
