"""The search map of one partition (on the worker), and of a flight (on the client).

A task fuses every ``map_every``-th posed frame of its partition into a
:class:`mapping.SearchMap` on the run's frame (the first logged pose of the run's first
flight: every partition's cells are the same cells) and returns only the window it saw;
the client merges the windows (:func:`mapping.merge_layers`: looks and independent looks
add, the best look wins), so the map is built in parallel with the detection. Frames are
placed by the pose logged with them (the pose the flight geotagged its holes with, at most
a frame's age from the re-interpolated one the merge uses; the difference is measured per
flight, :attr:`FlightMerger.pose_gap_m`, in the report and the summary).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics
from holescan.geotag import CameraMount, LocalFrame, VehiclePose, camera_pose_local
from holescan.mapping import MapGrid, MapLayers, SearchMap, merge_layers

__all__ = [
    "REACH_M",
    "MapFrame",
    "fuse_frames",
    "horizontal_gap_m",
    "merge_flight_maps",
]

REACH_M = 6.0
"""How far from the camera (horizontally) a frame's cells may lie: past the Xtion's range."""


@dataclasses.dataclass(frozen=True)
class MapFrame:
    """One frame to fuse: its images and the pose logged with it."""

    depth: npt.NDArray[np.uint16]
    rgb: npt.NDArray[np.uint8]
    pose: VehiclePose


def fuse_frames(
    frames: Sequence[MapFrame],
    camera: CameraIntrinsics,
    mount: CameraMount,
    anchor: tuple[float, float, float],
    cell_m: float,
) -> MapLayers | None:
    """The window of the map these frames saw (None: no frame, or nothing seen)."""
    if not frames:
        return None
    frame = LocalFrame(*anchor)
    poses = [camera_pose_local(frame, mount, f.pose) for f in frames]
    xy = np.array([p.position_m[:2] for p in poses])
    grid = MapGrid.covering(
        float(xy[:, 0].min()) - REACH_M,
        float(xy[:, 1].min()) - REACH_M,
        float(xy[:, 0].max()) + REACH_M,
        float(xy[:, 1].max()) + REACH_M,
        cell_m,
    )
    m = SearchMap(grid, frame)
    for f, p in zip(frames, poses, strict=True):
        m.add_frame(f.depth, f.rgb, camera, p)
    return m.seen_window()


def merge_flight_maps(parts: Sequence[MapLayers], cell_m: float) -> MapLayers | None:
    """Merge partition windows into one map over all of them (None: nothing seen)."""
    if not parts:
        return None
    west = min(p.grid.west_m for p in parts)
    east = max(p.grid.east_m for p in parts)
    south = min(p.grid.south_m for p in parts)
    north = max(p.grid.north_m for p in parts)
    # The windows' corners are whole cells of the same frame: so is the union's.
    nx = round((east - west) / cell_m)
    ny = round((north - south) / cell_m)
    grid = MapGrid(west, north, cell_m, max(1, nx), max(1, ny))
    return merge_layers(grid, parts)


def horizontal_gap_m(a: VehiclePose, b: VehiclePose) -> float:
    """Horizontal distance between two poses, metres."""
    e, n = LocalFrame(a.lat_deg, a.lon_deg).to_en(b.lat_deg, b.lon_deg)
    return math.hypot(float(e), float(n))
