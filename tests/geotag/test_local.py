"""The one local frame (LocalFrame): east/north/up and north/east/down against pymap3d's
own functions, and round trips through WGS84."""

from __future__ import annotations

import numpy as np
import pymap3d
import pytest

from holescan.geotag import LocalFrame

ORIGINS = [(47.0, 8.0, 420.0), (-33.9, 151.2, 5.0), (64.1, -21.9, 30.0), (0.0, 179.9999, 0.0)]


@pytest.mark.parametrize("origin", ORIGINS)
def test_ned_is_pymap3d_ned(origin: tuple[float, float, float]) -> None:
    rng = np.random.default_rng(7)
    lat0, lon0, alt0 = origin
    frame = LocalFrame(*origin)
    lat = lat0 + rng.uniform(-0.01, 0.01, 20)
    lon = lon0 + rng.uniform(-0.01, 0.01, 20)
    alt = alt0 + rng.uniform(-50, 50, 20)
    n, e, d = frame.to_ned(lat, lon, alt)
    n_ref, e_ref, d_ref = pymap3d.geodetic2ned(lat, lon, alt, lat0, lon0, alt0)
    np.testing.assert_allclose(n, n_ref, atol=1e-9)
    np.testing.assert_allclose(e, e_ref, atol=1e-9)
    np.testing.assert_allclose(d, d_ref, atol=1e-9)


@pytest.mark.parametrize("origin", ORIGINS)
def test_ned_and_enu_round_trips(origin: tuple[float, float, float]) -> None:
    frame = LocalFrame(*origin)
    n = np.array([0.0, 12.5, -300.0, 1500.0])
    e = np.array([0.0, -7.25, 80.0, -2200.0])
    d = np.array([0.0, 3.0, -40.0, 120.0])
    lat, lon, alt = frame.ned_to_geodetic(n, e, d)
    assert np.all((lon >= -180.0) & (lon < 180.0))
    back = frame.to_ned(lat, lon, alt)
    np.testing.assert_allclose(back, (n, e, d), atol=1e-6)
    enu = frame.to_enu(lat, lon, alt)
    np.testing.assert_allclose(enu, (e, n, -d), atol=1e-6)
    np.testing.assert_allclose(frame.to_geodetic_alt(e, n, -d), (lat, lon, alt), atol=1e-9)
