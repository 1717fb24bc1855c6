"""``holescan reprocess`` on recordings: a TUM folder (frames only) and ROS 1 / ROS 2 bags
with MAVROS's NavSatFix + Imu (holes placed from the bag's pose, search map written); the
converted log is reused when the recording is unchanged and never written over otherwise;
``holescan detect`` plays an ``.oni`` made of the same frames through libOpenNI2."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pymap3d
import pytest

from holescan.capture import write_oni
from holescan.cli import main
from holescan.detect import Frame
from tests.ground.recordings.conftest import Scene
from tests.ground.recordings.recwrite import write_bag

pytestmark = [pytest.mark.xdist_group("recordings"), pytest.mark.slow]

FIX = (-33.8568, 151.2153, 40.0)


def _summary(out: Path, name: str) -> dict[str, object]:
    doc = json.loads((out / f"{name}_reprocess.json").read_text())
    assert isinstance(doc, dict)
    return doc


def test_tum_frames_only(
    recordings: dict[str, Path], scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert main(["reprocess", str(recordings["tum"]), "-o", str(out), "--workers", "0"]) == 0
    text = capsys.readouterr().out
    assert "2 frames, no poses" in text
    s = _summary(out, "rgbd_dataset_scene")
    # a candidate at least per true hole (a TUM folder is read with the benchmark's own
    # freiburg1 camera, not the renderer's, so weak candidates may differ)
    assert s["frames_detected"] == 2 and s["detections"] >= sum(map(len, scene[2])) == 2
    assert s["frames_unposed"] == 2  # no pose: nothing placed on a map
    assert s["holes_found"] == 0 and s["holes"] == []
    # again: the converted log is kept and the partitions come from the cache
    assert main(["reprocess", str(recordings["tum"]), "-o", str(out), "--workers", "0"]) == 0
    assert "kept (made from it before)" in capsys.readouterr().out


@pytest.mark.parametrize("version", [1, 2])
def test_bag_with_mavros_pose(
    version: int, scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pairs, camera, _ = scene
    bag = write_bag(
        tmp_path / ("flight.bag" if version == 1 else "flight"),
        pairs,
        camera,
        version,  # type: ignore[arg-type]
        fix=FIX,
    )
    out = tmp_path / "out"
    args = ["reprocess", str(bag), "-o", str(out), "--workers", "0", "--min-sightings", "1"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "poses from /mavros/global_position/global + /mavros/imu/data" in text
    s = _summary(out, "flight")
    holes = s["holes"]
    # the two frames are two different scenes flown at one fix: where their openings fall
    # within the tracker's gate of each other they are one hole, so 1 or 2
    assert s["frames_unposed"] == 0 and s["holes_found"] == len(holes) and 1 <= len(holes) <= 2
    for h in holes:
        # nadir camera 2-3 m above the rubble: each hole within a few metres of the fix,
        # below it by about the depth of the scene
        e, n, u = pymap3d.geodetic2enu(h["lat_deg"], h["lon_deg"], h["alt_m"], *FIX)
        assert (e**2 + n**2) ** 0.5 < 3.0 and -5.0 < u < -1.0, (e, n, u)
    assert (out / "flight_coverage.tif").is_file() and (out / "flight_holes.kml").is_file()


def test_changed_recording_is_not_written_over(
    scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pairs, camera, _ = scene
    bag = write_bag(tmp_path / "b.bag", pairs, camera, 1)
    out = tmp_path / "out"
    assert main(["reprocess", str(bag), "-o", str(out), "--workers", "0"]) == 0
    log = out / "recordings" / "b_0000.mcap"
    before = log.read_bytes()
    st = bag.stat()
    os.utime(bag, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # another recording now
    assert main(["reprocess", str(bag), "-o", str(out), "--workers", "0"]) == 2
    assert "was not made from" in capsys.readouterr().err
    assert log.read_bytes() == before


def test_detect_oni(
    scene: Scene, scene_candidates: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pairs, camera, _ = scene
    oni = tmp_path / "scene.oni"
    frames = [
        Frame(i, rgb, mm, i * 33_333_333, i * 33_333_333) for i, (rgb, mm) in enumerate(pairs)
    ]
    assert write_oni(oni, frames, camera) == 2
    assert main(["detect", str(oni)]) == 0
    text = capsys.readouterr().out
    assert f"2 frame(s), {scene_candidates} candidate(s)" in text and "p_hole 0.9" in text
