"""Local metres: the tangent plane at a reference point (WGS84, through pymap3d).

The project's one east/north/up (and north/east/down) helper: survey planning, the report
map, the simulator's world anchor, the flight log's ``/tf``, the geotag projection, the
merging and matching of holes all use it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pymap3d

__all__ = ["LocalFrame", "local_en_m"]

FloatArray = npt.NDArray[np.float64]


class LocalFrame:
    """East-north-up metres in the tangent plane at ``(lat0_deg, lon0_deg, alt0_m)``.

    Examples
    --------
    >>> f = LocalFrame(47.0, 8.0)
    >>> e, n = f.to_en(47.0, 8.0 + 1e-5)
    >>> round(float(e), 3), round(float(n), 3)
    (0.761, 0.0)
    >>> [round(float(v), 9) for v in f.to_geodetic(e, n)]
    [47.0, 8.00001]
    """

    def __init__(self, lat0_deg: float, lon0_deg: float, alt0_m: float = 0.0) -> None:
        self.lat0_deg = float(lat0_deg)
        self.lon0_deg = float(lon0_deg)
        self.alt0_m = float(alt0_m)

    def __repr__(self) -> str:
        return f"LocalFrame({self.lat0_deg!r}, {self.lon0_deg!r}, {self.alt0_m!r})"

    def to_en(
        self, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Geodetic degrees at the frame's height -> (east, north) metres (arrays alike)."""
        e, n, _ = self.to_enu(lat_deg, lon_deg, self.alt0_m)
        return e, n

    def to_enu(
        self, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike, alt_m: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Geodetic degrees and ellipsoid height -> (east, north, up) metres."""
        lat = np.asarray(lat_deg, dtype=np.float64)
        lon = np.asarray(lon_deg, dtype=np.float64)
        alt = np.asarray(alt_m, dtype=np.float64)
        e, n, u = pymap3d.geodetic2enu(lat, lon, alt, self.lat0_deg, self.lon0_deg, self.alt0_m)
        f = np.float64
        return np.asarray(e, dtype=f), np.asarray(n, dtype=f), np.asarray(u, dtype=f)

    def to_ned(
        self, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike, alt_m: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Geodetic degrees and ellipsoid height -> (north, east, down) metres, the
        autopilot's and the camera mount's axes.

        >>> f = LocalFrame(47.0, 8.0, 400.0)
        >>> [round(float(v), 3) + 0.0 for v in f.to_ned(47.0001, 8.0, 390.0)]
        [11.118, 0.0, 10.0]
        """
        e, n, u = self.to_enu(lat_deg, lon_deg, alt_m)
        return n, e, -u

    def ned_to_geodetic(
        self, north_m: npt.ArrayLike, east_m: npt.ArrayLike, down_m: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(north, east, down) metres -> geodetic (lat, lon, ellipsoid height)."""
        return self.to_geodetic_alt(east_m, north_m, -np.asarray(down_m, dtype=np.float64))

    def to_geodetic(
        self, east_m: npt.ArrayLike, north_m: npt.ArrayLike, up_m: npt.ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray]:
        """(east, north[, up]) metres -> geodetic (lat, lon) degrees, lon in -180..180."""
        lat, lon, _ = self.to_geodetic_alt(east_m, north_m, up_m)
        return lat, lon

    def to_geodetic_alt(
        self, east_m: npt.ArrayLike, north_m: npt.ArrayLike, up_m: npt.ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(east, north, up) metres -> geodetic (lat, lon, ellipsoid height)."""
        e = np.asarray(east_m, dtype=np.float64)
        n = np.asarray(north_m, dtype=np.float64)
        u = np.asarray(up_m, dtype=np.float64)
        lat, lon, alt = pymap3d.enu2geodetic(e, n, u, self.lat0_deg, self.lon0_deg, self.alt0_m)
        lon = (np.asarray(lon, dtype=np.float64) + 180.0) % 360.0 - 180.0
        return np.asarray(lat, dtype=np.float64), lon, np.asarray(alt, dtype=np.float64)


def local_en_m(
    lat_deg: float, lon_deg: float, lat0_deg: float, lon0_deg: float
) -> tuple[float, float]:
    """(east, north) metres of one point from a reference point, both on the ellipsoid.

    >>> [round(v, 2) + 0.0 for v in local_en_m(47.0001, 8.0, 47.0, 8.0)]  # + 0.0: no -0.0
    [0.0, 11.12]
    """
    e, n = LocalFrame(lat0_deg, lon0_deg).to_en(lat_deg, lon_deg)
    return float(e), float(n)
