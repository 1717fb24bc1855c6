"""The flight side: frame sources, telemetry, the MCAP flight log and the capture daemon."""

from capture._frame import Frame, FrameSource

__all__ = ["Frame", "FrameSource"]
