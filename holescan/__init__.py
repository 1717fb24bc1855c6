"""holescan: access-hole detection from a UAV's RGB-D camera.

The domain packages sit beside this one: :mod:`detect` and :mod:`geotag` are pure,
:mod:`capture` is the flight side and :mod:`missions` talks MAVLink missions and plan
files. This package holds the project's exception root, dataset/evaluation I/O and the
thin command line (:mod:`holescan.cli`).
"""

from holescan_errors import HolescanError, InputError

__version__ = "0.1.0"
__all__ = ["HolescanError", "InputError", "__version__"]
