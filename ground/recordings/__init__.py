"""RGB-D recordings made elsewhere, read on the ground as frame sources.

* :mod:`.source` - :func:`open_recording`: recognises a recording by its content and
  returns the :class:`detect.FrameSource` that reads it;
* :mod:`.tum` - :class:`TumSource`: TUM RGB-D benchmark folders;
* :mod:`.rosbag` - :class:`BagSource`: ROS 1 and ROS 2 bags (``rosbags``, no ROS needed);
* OpenNI ``.oni`` files and holescan's own MCAP logs are read by
  :class:`capture.OniSource` and :class:`flightlog.McapSource`;
* :mod:`.tolog` - :func:`recording_to_log` / :func:`flight_logs_of`: a recording as a
  holescan flight log (frames, camera, and the pose from a bag's NavSatFix + Imu, made into
  MAVLink by :mod:`.bagtelemetry`), so that ``holescan reprocess`` takes it;
* :mod:`.asdataset` - :func:`recording_dataset`: a recording and a CSV of its hole boxes
  as an annotated dataset (``holescan eval RECORDING --boxes CSV``);
* :mod:`.detectall` - :func:`detect_recording`: the detector over a recording's frames;
* :mod:`.depthstats` - :func:`unread_stats`: the unread fraction of a depth frame and the
  unread bands along its border (the statistics a sensor model is checked against).
"""

from holescan.ground.recordings.asdataset import frame_name, recording_dataset
from holescan.ground.recordings.depthstats import UnreadStats, border_band_px, unread_stats
from holescan.ground.recordings.detectall import FrameDetections, detect_recording
from holescan.ground.recordings.rosbag import BagSource, BagTopics, decode_image
from holescan.ground.recordings.source import RECORDING_KINDS, open_recording, recording_kind
from holescan.ground.recordings.tolog import (
    ConvertedRecording,
    flight_logs_of,
    recording_to_log,
)
from holescan.ground.recordings.tum import TUM_DEPTH_PER_M, TUM_FR1, TumSource, associate

__all__ = [
    "RECORDING_KINDS",
    "TUM_DEPTH_PER_M",
    "TUM_FR1",
    "BagSource",
    "BagTopics",
    "ConvertedRecording",
    "FrameDetections",
    "TumSource",
    "UnreadStats",
    "associate",
    "border_band_px",
    "decode_image",
    "detect_recording",
    "flight_logs_of",
    "frame_name",
    "open_recording",
    "recording_dataset",
    "recording_kind",
    "recording_to_log",
    "unread_stats",
]
