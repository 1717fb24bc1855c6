"""Bad input anywhere gives one clean line on stderr and exit code 2: outputs that cannot be
written, tiny or huge frames, broken cameras, names that are not UTF-8, corrupt PNGs, plan
arguments off the Earth or the calendar."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from holescan import cli
from holescan.detect import PAPER, CameraIntrinsics, detect_holes
from holescan.errors import InputError

REPO = Path(__file__).resolve().parents[1]
AREA = "43.0,-79.0;43.0005,-79.0;43.0005,-78.9995;43.0,-78.9995"
RO = "read-only" if os.geteuid() == 0 else "permission"  # a ro tmpfs as root, else chmod


@pytest.fixture
def readonly_dir(tmp_path: Path) -> Iterator[Path]:
    """A folder nobody can write in: a read-only tmpfs as root, else mode 0555."""
    d = tmp_path / "ro"
    d.mkdir()
    mounted = False
    if os.geteuid() == 0:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(d)])
        mounted = r.returncode == 0
        if not mounted:
            pytest.skip("root without mount: cannot make a read-only folder")
    else:
        d.chmod(0o555)
    try:
        yield d
    finally:
        if mounted:
            subprocess.run(["umount", str(d)], check=False)
        else:
            d.chmod(0o755)


@pytest.fixture(scope="module")
def frame(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("frame")
    depth = np.full((48, 64), 2000, np.uint16)
    depth[15:30, 20:40] = 0
    cv2.imwrite(str(d / "rgb.png"), np.full((48, 64, 3), 90, np.uint8))
    cv2.imwrite(str(d / "depth.png"), depth)
    (d / "cam.json").write_text(json.dumps(CameraIntrinsics.xtion(64, 48).to_dict()))
    return d / "rgb.png", d / "depth.png"


def one_line_error(capfd: pytest.CaptureFixture[str], argv: list[str], *expected: str) -> str:
    """Run the CLI; it must exit 2 with exactly one stderr line holding ``expected``."""
    code = cli.main(argv)
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (argv, err)
    assert len(lines) == 1, (argv, err)
    for text in expected:
        assert text in lines[0], (argv, lines[0])
    return lines[0]


def test_detect_outputs_that_cannot_be_written(
    frame: tuple[Path, Path], tmp_path: Path, readonly_dir: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    rgb, depth = (str(p) for p in frame)
    cases = [
        (["--json", str(tmp_path / "nope" / "d.json")], "does not exist"),
        (["--json", str(readonly_dir / "d.json")], RO),
        (["--json", str(tmp_path / "d.txt")], "unknown extension"),
        (["--json", str(tmp_path)], "is a folder"),
        (["--overlay", str(tmp_path / "nope" / "o.png")], "does not exist"),
        (["--overlay", str(readonly_dir / "o.png")], RO),
        (["--overlay", str(tmp_path / "o.xyz")], "unknown extension"),
        (["--overlay", str(tmp_path)], "is a folder"),
        (["--overlay", rgb], "also an input"),
    ]
    for extra, message in cases:
        one_line_error(capfd, ["detect", rgb, depth, *extra], message)
    assert not list(tmp_path.glob(".*part*"))
    # An existing output is kept unless --force (--overwrite: its old hidden spelling).
    (tmp_path / "d.json").write_text("keep")
    one_line_error(capfd, ["detect", rgb, depth, "--json", str(tmp_path / "d.json")], "exists")
    assert (tmp_path / "d.json").read_text() == "keep"
    assert cli.main(["detect", rgb, depth, "--json", str(tmp_path / "d.json"), "--force"]) == 0
    assert isinstance(json.loads((tmp_path / "d.json").read_text()), list)


def test_eval_dataset_log_and_plan_outputs(
    tmp_path: Path, readonly_dir: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    missing = str(tmp_path / "no-dataset")
    one_line_error(capfd, ["eval", missing, "--plot", str(tmp_path / "x" / "pr.png")], "exist")
    one_line_error(capfd, ["eval", missing, "--plot", str(tmp_path / "pr.gif")], "extension")
    one_line_error(capfd, ["eval", missing, "--detections", str(readonly_dir / "d.json")], RO)
    one_line_error(capfd, ["dataset", "synth", str(readonly_dir / "ds"), "--n", "1"], RO)
    log = tmp_path / "a.mcap"
    log.write_bytes(b"\x89MCAP0\r\n" + bytes(100))
    one_line_error(capfd, ["log", "recover", str(log), "--out", str(readonly_dir / "r.mcap")], RO)
    one_line_error(
        capfd, ["plan", AREA, "--out", str(tmp_path / "nope" / "s.plan")], "does not exist"
    )


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--date", "0001-01-01"], "outside"),
        (["--date", "9999-12-31"], "outside"),
        (["--heading", "nan"], "heading_deg must be a finite number"),
        (["--heading", "inf"], "heading_deg must be a finite number"),
        (["--home", "999,999"], "latitude must be within -90..90"),
        (["--home", "43,999"], "longitude must be within -180..180"),
        (["--altitude", "nan"], "altitude_m must be a finite number"),
    ],
)
def test_plan_arguments_off_the_earth_or_calendar(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    one_line_error(capfd, ["plan", AREA, "--out", str(tmp_path / "s.plan"), *extra], message)
    assert not (tmp_path / "s.plan").exists()


def test_tiny_frames_and_broken_cameras(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    cv2.imwrite(str(tmp_path / "r.png"), np.zeros((3, 3, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "d.png"), np.full((3, 3), 1500, np.uint16))
    one_line_error(
        capfd, ["detect", str(tmp_path / "r.png"), str(tmp_path / "d.png")], "at least 4x4"
    )
    cv2.imwrite(str(tmp_path / "r.png"), np.zeros((48, 64, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "d.png"), np.full((48, 64), 1500, np.uint16))
    good = CameraIntrinsics.xtion(64, 48).to_dict()
    for change, message in (
        ({"fx": "NaN"}, "finite"),
        ({"cy": "Infinity"}, "finite"),
        ({"depth_unit_m": 0}, "depth_unit_m"),
        ({"depth_unit_m": -0.001}, "depth_unit_m"),
        ({"depth_unit_m": "NaN"}, "finite"),
        ({"width": 64.5}, "whole"),
    ):
        raw = json.dumps({**good, **change}).replace('"NaN"', "NaN").replace('"Infinity"', "1e999")
        (tmp_path / "cam.json").write_text(raw)
        argv = ["detect", str(tmp_path / "r.png"), str(tmp_path / "d.png")]
        one_line_error(capfd, [*argv, "--camera", str(tmp_path / "cam.json")], message)
    with pytest.raises(InputError, match="depth_unit_m"):
        CameraIntrinsics(64, 48, 50.0, 50.0, 32.0, 24.0, depth_unit_m=float("nan"))


def test_paper_mode_refuses_frames_it_cannot_hold() -> None:
    cam = CameraIntrinsics(10000, 10000, 9000.0, 9000.0, 5000.0, 5000.0)
    depth = np.ones((10000, 10000), np.uint16)
    rgb = np.zeros((1, 1, 3), np.uint8)  # never looked at: the size check comes first
    with pytest.raises(InputError, match=r"at most 2,073,600 pixels \(1920x1080\)"):
        detect_holes(rgb, depth, cam, PAPER)


def test_corrupt_png_and_non_utf8_name_give_one_line(tmp_path: Path) -> None:
    """In a child process: OpenCV's imread segfaulted on such a name (exit 139), and libpng
    wrote its own complaints to the process's stderr."""
    good = tmp_path / "d.png"
    cv2.imwrite(str(good), np.full((48, 64), 1500, np.uint16))
    data = bytearray(good.read_bytes())
    data[40] ^= 0xFF  # inside IHDR/IDAT: CRC error
    (tmp_path / "bad.png").write_bytes(bytes(data))
    weird = os.fsencode(tmp_path) + b"/\xff\xfe-rgb.png"
    with open(weird, "wb") as f:
        f.write(cv2.imencode(".png", np.zeros((48, 64, 3), np.uint8))[1].tobytes())
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for rgb, depth, message in (
        (weird, os.fsencode(good), None),
        (os.fsencode(tmp_path / "r.png"), os.fsencode(tmp_path / "bad.png"), b"not a readable"),
    ):
        if message is not None:
            cv2.imwrite(str(tmp_path / "r.png"), np.zeros((48, 64, 3), np.uint8))
        res = subprocess.run(
            [sys.executable, "-m", "holescan.cli", "detect", rgb, depth],
            capture_output=True,
            env=env,
            cwd=REPO,
            timeout=120,
        )
        assert res.returncode in (0, 2), res
        if message is None:
            assert res.returncode == 0, res.stderr
        else:
            lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
            assert res.returncode == 2
            assert len(lines) == 1 and message in lines[0], res.stderr
            assert b"libpng" not in res.stderr
