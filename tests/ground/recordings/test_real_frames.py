"""A real structured-light frame, read, measured and detected on.

``tests/data/real/mrpt-openni2`` is MRPT's ``tests_rgbd.rawlog`` (Debian ``mrpt-common``,
BSD-3-clause; README.md there): one 640 x 480 frame of an office bookshelf taken through
OpenNI2, stored as a TUM RGB-D folder. What is checked is what is true of that frame whatever
the detector does: the reader's pixels against OpenCV's, the sensor's signature (unread
border bands, 1/8-pixel disparity quantisation, the unread fraction of PrimeSense frames),
and that the default detector neither breaks on it nor announces a hole in a scene that has
none a person could enter.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from holescan.cli import main
from holescan.detect import CameraIntrinsics, Frame
from holescan.geotag import AnnounceGate
from holescan.ground import read_camera
from holescan.ground.recordings import open_recording, recording_kind, unread_stats

pytestmark = pytest.mark.xdist_group("recordings")

REAL = Path(__file__).resolve().parents[2] / "data" / "real" / "mrpt-openni2"
STAMP = "1462879443.617188"
# f b of a PrimeSense sensor (Kinect v1 / Xtion: IR focal ~580 px, baseline 7.5 cm), px m;
# FIELD-NOTES.md ("What a real structured-light frame looks like")
FB_PX_M = 43.5


@pytest.fixture(scope="module")
def real() -> tuple[Frame, CameraIntrinsics]:
    with open_recording(REAL, camera=read_camera(REAL / "camera.json")) as source:
        frames = list(source)
        camera = source.camera
    assert len(frames) == 1
    return frames[0], camera


def test_the_tum_reader_reads_the_real_frame(real: tuple[Frame, CameraIntrinsics]) -> None:
    frame, camera = real
    assert recording_kind(REAL) == "tum"
    assert frame.index == 0
    assert abs(frame.t_sensor_ns - 1_462_879_443_617_188_000) < 1_000
    bgr = cv2.imread(str(REAL / "rgb" / f"{STAMP}.png"), cv2.IMREAD_COLOR)
    np.testing.assert_array_equal(frame.rgb, bgr[..., ::-1])
    tum = cv2.imread(str(REAL / "depth" / f"{STAMP}.png"), cv2.IMREAD_UNCHANGED)
    assert tum.dtype == np.uint16 and not (tum % 5).any()  # the rawlog's whole mm, x 5
    np.testing.assert_array_equal(frame.depth, tum // 5)
    assert camera == CameraIntrinsics(640, 480, 521.17923, 493.03303, 322.51599, 259.05597)


def test_the_frame_has_a_structured_light_sensors_signature(
    real: tuple[Frame, CameraIntrinsics],
) -> None:
    depth = real[0].depth
    s = unread_stats(depth)
    # the unread fraction of the PrimeSense frames measured so far (7-19 %)
    assert 0.07 <= s.unread <= 0.19, s
    # depth registered to the colour camera: an unread band along every border, and the
    # bands hold most of what is unread
    assert min(s.left, s.right, s.top, s.bottom) >= 1, s
    assert s.inside < s.unread / 2, s
    # depth through disparity quantised in 1/8 px: neighbouring values Z^2 / (8 f b) apart
    values = np.unique(depth[depth > 0]).astype(np.float64) / 1000.0
    mid = (values[1:] + values[:-1]) / 2.0
    ratio = np.diff(values) / (mid**2 / (8.0 * FB_PX_M))
    assert len(values) > 50
    assert 0.9 < float(np.median(ratio)) < 1.1, np.median(ratio)


def test_holescan_detect_on_the_real_frame(
    real: tuple[Frame, CameraIntrinsics], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "dets.json"
    args = ["detect", str(REAL), "--camera", str(REAL / "camera.json"), "--json", str(out)]
    assert main(args) == 0
    assert "1 frame(s)" in capsys.readouterr().out
    (frame,) = json.loads(out.read_text())
    assert frame["frame_index"] == 0 and not frame["no_depth"]
    s = unread_stats(real[0].depth)
    gate = AnnounceGate()
    for d in frame["detections"]:
        x, y, w, h = d["box"]
        assert x >= 0 and y >= 0 and w > 0 and h > 0, d
        assert x + w <= 640 and y + h <= 480, d
        # a border band is unread frame edge, not an opening: no candidate lies within one
        assert not (x + w <= s.left or x >= 640 - s.right), d
        assert not (y + h <= s.top or y >= 480 - s.bottom), d
        # an office bookshelf against a wall holds no opening a person could enter:
        # nothing is announced to the crew
        assert 0.0 <= d["p_hole"] < gate.min_p_hole, d
