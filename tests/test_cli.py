"""The command line: results on good input; one clear line and exit 2 on bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from holescan.cli import main
from holescan.detect import CameraIntrinsics
from holescan.ground import Sample, write_dataset

CAM = CameraIntrinsics.xtion()


def _frame() -> tuple[np.ndarray, np.ndarray]:
    depth = np.full((480, 640), 2600, np.uint16)
    depth[180:300, 250:420] = 0  # a 0.8 m x 0.55 m opening, floor beyond range
    rgb = np.full((480, 640, 3), 110, np.uint8)
    rgb[180:300, 250:420] = 15
    return rgb, depth


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    rgb, depth = _frame()
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb)
    cv2.imwrite(str(tmp_path / "depth.png"), depth)
    return tmp_path / "rgb.png", tmp_path / "depth.png"


def test_detect_prints_writes_json_and_overlay(
    pair: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_json, overlay = tmp_path / "d.json", tmp_path / "o.png"
    assert (
        main(
            [
                "detect",
                str(pair[0]),
                str(pair[1]),
                "--json",
                str(out_json),
                "--overlay",
                str(overlay),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "1 candidate hole" in text and "no floor reading" in text
    dets = json.loads(out_json.read_text())
    x, y, w, h = dets[0]["box"]
    assert abs(x - 250) <= 4 and abs(y - 180) <= 4 and abs(w - 170) <= 8 and abs(h - 120) <= 8
    img = cv2.imread(str(overlay))
    assert img.shape == (480, 1280, 3)


def _run(args: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "holescan.cli", *args], capture_output=True, text=True, timeout=120
    )


def test_bad_inputs_exit_2_with_one_line(pair: tuple[Path, Path], tmp_path: Path) -> None:
    rgb_path, depth_path = pair
    rgb, depth = _frame()
    cv2.imwrite(str(tmp_path / "d8.png"), (depth // 20).astype(np.uint8))
    np.save(tmp_path / "f.npy", depth.astype(np.float32))
    cv2.imwrite(str(tmp_path / "zero.png"), np.zeros_like(depth))
    cv2.imwrite(str(tmp_path / "small.png"), depth[:240, :320])
    (tmp_path / "junk.png").write_bytes(b"not a png at all")
    (tmp_path / "noann").mkdir()
    write_dataset(tmp_path / "nohole", CAM, [Sample("a", rgb, depth, [], [])])
    cases = {
        "8-bit": ["detect", str(rgb_path), str(tmp_path / "d8.png")],
        "zero": ["detect", str(rgb_path), str(tmp_path / "zero.png")],
        "size": ["detect", str(rgb_path), str(tmp_path / "small.png")],
        "missing": ["detect", str(rgb_path), str(tmp_path / "nope.png")],
        "junk": ["detect", str(rgb_path), str(tmp_path / "junk.png")],
        "camera": ["detect", str(rgb_path), str(depth_path), "--camera", str(tmp_path / "x.json")],
        "no annotations": ["eval", str(tmp_path / "noann")],
        "no hole": ["eval", str(tmp_path / "nohole")],
        "bad K": ["eval", str(tmp_path / "nohole"), "--superpixels", "a,b"],
    }
    for name, args in cases.items():
        r = _run(args)
        assert r.returncode == 2, (name, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "error:" in lines[0], (name, r.stderr)
        assert "Traceback" not in r.stderr


def test_eval_on_a_tiny_dataset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rgb, depth = _frame()
    write_dataset(
        tmp_path / "ds",
        CAM,
        [
            Sample("a", rgb, depth, [(250, 180, 170, 120)], [False]),
            Sample("b", rgb, np.full_like(depth, 2600), [], []),
        ],
    )
    assert (
        main(
            [
                "eval",
                str(tmp_path / "ds"),
                "--workers",
                "1",
                "--plot",
                str(tmp_path / "pr.png"),
                "--detections",
                str(tmp_path / "r.json"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "| default | 1.000 | 1.000 | 1.000 | 1.000 |" in out
    rows = json.loads((tmp_path / "r.json").read_text())
    assert rows[0]["image_id"] == 1 and rows[0]["category_id"] == 1
    assert (tmp_path / "pr.png").stat().st_size > 10_000


def test_a_verb_loads_only_its_own_modules() -> None:
    """`holescan log ...` registers the log verb alone: neither the detector nor the ground
    station is imported (seconds of CPU on a companion computer); `--help` and an unknown
    verb still see every verb."""
    probe = (
        "import sys; from holescan.cli import build_parser, COMMANDS\n"
        "p = build_parser(['-v', 'log', 'info', 'x.mcap'])\n"
        "print(sorted(m for m in ('holescan.detect', 'holescan.ground') if m in sys.modules))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True
    )
    assert r.stdout.strip() == "[]", r.stdout
    listing = _run(["--help"])
    assert listing.returncode == 0
    from holescan.cli import COMMANDS

    assert all(verb in listing.stdout for verb in COMMANDS)
    typo = _run(["detcet"])
    assert typo.returncode == 2 and "invalid choice" in typo.stderr
    assert all(repr(verb) in typo.stderr for verb in COMMANDS), typo.stderr
