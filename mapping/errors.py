"""The mapping package's errors."""

from __future__ import annotations

from holescan.errors import InputError

__all__ = ["MapError"]


class MapError(InputError):
    """Bad input to the map: a grid, an image or a recall table that cannot be used."""
