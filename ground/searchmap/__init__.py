"""The search map's files: GeoTIFFs, the KMZ overlay, gap polygons, the re-fly mission.

* :mod:`.geotiff` - ``NAME_ortho.tif``, ``NAME_dsm.tif``, ``NAME_coverage.tif`` (UTM,
  tiled, overviews; rasterio);
* :mod:`.kmz` - ``NAME_map.kmz``: the orthophoto as a KML GroundOverlay with the holes;
* :mod:`.gaps` - gaps (coverage below a threshold) as polygons, the searched fraction,
  ``NAME_gaps.geojson``, a re-fly over the gaps through :func:`missions.plan_survey`;
* :mod:`.outputs` - all of them at once (:func:`write_map_outputs`).
"""

from holescan.ground.searchmap.gaps import (
    GapReport,
    Refly,
    find_gaps,
    gaps_document,
    plan_refly,
    write_gaps_geojson,
)
from holescan.ground.searchmap.geotiff import (
    DSM_NODATA,
    local_crs,
    utm_crs,
    write_map_geotiffs,
)
from holescan.ground.searchmap.kmz import write_map_kmz
from holescan.ground.searchmap.outputs import MapOutputs, write_map_outputs

__all__ = [
    "DSM_NODATA",
    "GapReport",
    "MapOutputs",
    "Refly",
    "find_gaps",
    "gaps_document",
    "local_crs",
    "plan_refly",
    "utm_crs",
    "write_gaps_geojson",
    "write_map_geotiffs",
    "write_map_kmz",
    "write_map_outputs",
]
