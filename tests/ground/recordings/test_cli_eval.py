"""``holescan eval RECORDING --boxes CSV``: the true boxes of the rendered frames, named by
frame index or by TUM colour file, give AP 1; rows naming no frame are one clear line."""

from __future__ import annotations

from pathlib import Path

import pytest

from holescan.cli import main
from holescan.ground.recordings import TumSource
from tests.ground.recordings.conftest import Scene

pytestmark = pytest.mark.xdist_group("recordings")


def _csv(path: Path, names: list[str], scene: Scene) -> Path:
    rows = ["file,x,y,w,h"]
    for name, boxes in zip(names, scene[2], strict=True):
        rows += [f"{name},{x + 1:.0f},{y + 1:.0f},{w:.0f},{h:.0f}" for x, y, w, h in boxes]
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("kind", ["tum", "ros2"])
def test_eval_recording(
    kind: str,
    recordings: dict[str, Path],
    scene: Scene,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    rec = recordings[kind]
    if kind == "tum":  # by colour file, as a TUM user names frames
        names = [p.rgb.relative_to(rec).as_posix() for p in TumSource(rec).pairs]
    else:
        names = ["0", "frame_000001"]
    boxes = _csv(tmp_path / "boxes.csv", names, scene)
    args = ["eval", str(rec), "--boxes", str(boxes), "--workers", "1"]
    assert main([*args, "--detections", str(tmp_path / "d.json")]) == 0
    text = capsys.readouterr().out
    assert f"{rec}: 2 images, 2 access holes" in text
    default = next(line for line in text.splitlines() if line.startswith("| default"))
    assert default.split("|")[2].strip() == "1.000", text  # AP (IoU > 0.5)
    assert (tmp_path / "d.json").is_file()


def test_eval_recording_errors(
    recordings: dict[str, Path], scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = recordings["ros1"]
    bad = _csv(tmp_path / "bad.csv", ["0", "7"], scene)
    assert main(["eval", str(rec), "--boxes", str(bad), "--workers", "1"]) == 2
    assert "frame(s) [7] are not in" in capsys.readouterr().err
    named = _csv(tmp_path / "named.csv", ["0", "left.png"], scene)
    assert main(["eval", str(rec), "--boxes", str(named), "--workers", "1"]) == 2
    assert "'left.png' names no frame" in capsys.readouterr().err
