"""holescan: find access holes in disaster rubble from a UAV's RGB-D camera.

Every import name of the project lives under this one package. The folders of the
repository's root are its subpackages (``holescan/capture`` is a link to ``capture/``, and so
on), lowest layer first:

- :mod:`holescan.errors`: the exception root (a leaf);
- :mod:`holescan.detect` and :mod:`holescan.geotag`: the pure core;
- :mod:`holescan.missions`: MAVLink missions and the crew's plan and hole files;
- :mod:`holescan.capture`: the flight side;
- :mod:`holescan.ground`: after the flight and the ground station;
- :mod:`holescan.sim`: the simulated world, Xtion and autopilot (beside the flight side);
- :mod:`holescan.cli`: ``holescan <verb>``, on top.
"""

from importlib.metadata import version as _dist_version

__version__ = _dist_version("holescan")
__all__ = ["__version__"]
