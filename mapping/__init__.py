"""The search picture (pure): posed RGB-D frames in, rasters of the rubble out.

A :class:`SearchMap` on a :class:`MapGrid` of local metres (a :class:`geotag.LocalFrame`)
fuses frames one by one (:meth:`SearchMap.add_frame`) into the surface's **height**, its
**colour** from the best look, the **look count** and the **coverage**: per cell, the
probability that an access hole there would have been detected, from the detector's
measured recall by range and view angle (:class:`RecallTable`), combined over independent
looks as POD = 1 - prod(1 - POD_i). :meth:`SearchMap.changed_tiles` says what changed
since a version (for a live downlink); :func:`merge_layers` merges maps of chunks or
flights. No files, clocks or devices.
"""

from holescan.mapping._fuse import FrameFused, FuseParams, SearchMap
from holescan.mapping._grid import MapGrid
from holescan.mapping._layers import MapLayers, merge_layers
from holescan.mapping._recall import RecallTable, default_recall_table
from holescan.mapping.errors import MapError

__all__ = [
    "FrameFused",
    "FuseParams",
    "MapError",
    "MapGrid",
    "MapLayers",
    "RecallTable",
    "SearchMap",
    "default_recall_table",
    "merge_layers",
]
