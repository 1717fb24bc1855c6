"""``holescan detect RECORDING`` on a TUM folder and ROS 1 / ROS 2 bags of rendered frames
with known holes; bad recordings get one line and exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from holescan.cli import main
from holescan.detect import box_iou
from tests.ground.recordings.conftest import Scene

pytestmark = pytest.mark.xdist_group("recordings")


@pytest.mark.parametrize("kind", ["tum", "ros1", "ros2"])
def test_detect_finds_the_true_holes(
    kind: str,
    recordings: dict[str, Path],
    scene: Scene,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "dets.json"
    assert main(["detect", str(recordings[kind]), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "2 frame(s)" in text and "frame 1:" in text
    frames = json.loads(out.read_text())
    assert [f["frame_index"] for f in frames] == [0, 1]
    for f, truth in zip(frames, scene[2], strict=True):
        boxes = [d["box"] for d in f["detections"] if d["p_hole"] >= 0.5]
        for t in truth:
            assert max(box_iou(tuple(b), t) for b in boxes) > 0.5, (kind, t, boxes)
    # the same output is refused as an input's twin: never written over without --force
    assert main(["detect", str(recordings[kind]), "--json", str(out)]) == 2


def test_detect_every_and_max(
    recordings: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["detect", str(recordings["ros1"]), "--every", "2"]) == 0
    assert "1 frame(s)" in capsys.readouterr().out
    assert main(["detect", str(recordings["tum"]), "--max-frames", "1"]) == 0
    assert "1 frame(s)" in capsys.readouterr().out


def test_bad_recording_one_line(tmp_path: Path, recordings: dict[str, Path]) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("not a recording\n")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(recordings["ros1"].read_bytes()[:3000])
    for args in (
        [str(notes)],
        [str(tmp_path / "missing.bag")],
        [str(cut)],
        [str(recordings["tum"]), "--overlay", str(tmp_path / "o.png")],
    ):
        r = subprocess.run(
            [sys.executable, "-m", "holescan.cli", "detect", *args],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("holescan detect: error: "), r.stderr
