"""MAVLink missions and plan files: survey planning, sun windows, waypoint files, upload."""

__all__: list[str] = []
