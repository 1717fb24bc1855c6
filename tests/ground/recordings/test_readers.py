"""TUM folders and ROS 1 / ROS 2 bags written by their own tools, read back frame for frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from holescan.detect import CameraIntrinsics, Frame
from holescan.errors import InputError
from holescan.ground.recordings import (
    TUM_FR1,
    BagSource,
    TumSource,
    open_recording,
    recording_kind,
)
from tests.ground.recordings.conftest import Scene
from tests.ground.recordings.recwrite import Pair, write_bag, write_tum

pytestmark = pytest.mark.xdist_group("recordings")


def _frames(path: Path) -> tuple[list[Frame], CameraIntrinsics]:
    with open_recording(path) as source:
        return list(source), source.camera


def _same(frames: list[Frame], pairs: list[Pair]) -> None:
    assert [f.index for f in frames] == list(range(len(pairs)))
    for f, (rgb, mm) in zip(frames, pairs, strict=True):
        np.testing.assert_array_equal(f.rgb, rgb)
        np.testing.assert_array_equal(f.depth, mm)
        assert f.depth.dtype == np.uint16 and f.rgb.dtype == np.uint8


def test_tum_folder(tmp_path: Path, scene: Scene) -> None:
    pairs = scene[0]
    folder = write_tum(tmp_path / "rgbd_dataset_test", pairs)
    assert recording_kind(folder) == "tum"
    frames, camera = _frames(folder)
    _same(frames, pairs)  # the lone colour image without depth is left out
    assert camera == TUM_FR1
    assert frames[1].t_sensor_ns - frames[0].t_sensor_ns == pytest.approx(33_333_333, abs=1000)


def test_tum_tolerance(tmp_path: Path, scene: Scene) -> None:
    folder = write_tum(tmp_path / "late", scene[0], depth_lag_ns=12_000_000)
    with pytest.raises(InputError, match=r"no colour image has a depth image within 0\.01 s"):
        TumSource(folder, max_dt_s=0.01)
    pairs = TumSource(folder).pairs  # each depth with the colour 12 ms before, not 21 ms after
    assert [p.t_depth_ns - p.t_rgb_ns for p in pairs] == [pytest.approx(12e6, abs=2e3)] * 2


@pytest.mark.parametrize(
    ("version", "encoding", "compressed"),
    [(1, "16UC1", False), (2, "32FC1", True), (2, "16UC1", False), (1, "32FC1", True)],
)
def test_bags(
    tmp_path: Path,
    scene: Scene,
    version: int,
    encoding: str,
    compressed: bool,
) -> None:
    pairs, camera, _ = scene
    bag = write_bag(
        tmp_path / ("test.bag" if version == 1 else "test_bag"),
        pairs,
        camera,
        version,  # type: ignore[arg-type]
        depth_encoding=encoding,  # type: ignore[arg-type]
        compressed_colour=compressed,
    )
    assert recording_kind(bag) == f"ros{version}"
    source = open_recording(bag)
    assert isinstance(source, BagSource)
    assert source.topics.depth == "/camera/depth_registered/image_raw"  # not the raw one
    assert source.topics.colour == "/camera/rgb/image_color"
    frames, cam = _frames(bag)
    _same(frames, pairs)
    assert cam == camera  # from CameraInfo


def test_bag_topic_choice(tmp_path: Path, scene: Scene) -> None:
    pairs, camera, _ = scene
    bag = write_bag(tmp_path / "t.bag", pairs, camera, 1)
    with pytest.raises(InputError, match="no image topic '/nope'"):
        BagSource(bag, depth_topic="/nope")
    raw = BagSource(bag, depth_topic="/camera/depth/image_raw")
    with raw, pytest.raises(InputError, match="registered to colour"):
        next(iter(raw))


def test_not_a_recording(tmp_path: Path) -> None:
    text = tmp_path / "notes.bag"
    text.write_text("hello\n")
    with pytest.raises(InputError, match=r"notes.bag: not a recording holescan reads \(one of"):
        open_recording(text)
    with pytest.raises(InputError, match="no such file or folder"):
        open_recording(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="not a recording"):
        recording_kind(tmp_path / "empty")
    broken = tmp_path / "broken.bag"
    broken.write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 40)
    with pytest.raises(InputError, match="not a readable ROS bag"):
        open_recording(broken)
