"""RGB-D recordings made elsewhere, read on the ground.

* :mod:`.depthstats` - :func:`unread_stats`: the unread fraction of a depth frame and the
  unread bands along its border (the statistics a sensor model is checked against).
"""

from holescan.ground.recordings.depthstats import UnreadStats, border_band_px, unread_stats

__all__ = ["UnreadStats", "border_band_px", "unread_stats"]
