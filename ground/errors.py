"""The ground side's errors, under the project's one root :class:`holescan.errors.HolescanError`.

The CLI prints any of them as one line and exits 2. Bad input (a missing or corrupt file, a
wrong option) is an :class:`holescan.errors.InputError`; where ground has its own kind of bad
input it subclasses both (:class:`StationFileError`).
"""

from holescan.errors import HolescanError, InputError

__all__ = ["CotError", "EngineError", "GroundError", "StationFileError"]


class GroundError(HolescanError):
    """Root of the errors ground raises on purpose."""


class EngineError(GroundError):
    """The Dask cluster could not be reached, or a reprocessing task failed for a reason
    retrying cannot fix."""


class CotError(GroundError):
    """The TAK link could not be opened."""


class StationFileError(GroundError, InputError):
    """A station folder's state file that is not a holescan ground station file."""
