"""holescan's command line: ``holescan <verb>`` parses, calls one library function, and maps
the project's errors to exit codes (:mod:`holescan.cli`).

The library sits in the packages beside this one, lowest first: :mod:`detect` and
:mod:`geotag` (pure), :mod:`missions` (MAVLink missions and plan files), :mod:`capture` (the
flight side), :mod:`ground` (post-flight and ground station), and :mod:`sim` (the simulated
world, Xtion and autopilot, beside the flight side). Errors: :mod:`holescan_errors`.
"""

from importlib.metadata import version as _dist_version

__version__ = _dist_version("holescan")
__all__ = ["__version__"]
