"""The README's two commands in either order in the clone's root: the demo writes to the
user's data folder (printed), never into the folder it runs in, and no output folder can
become part of the package (setuptools finds only real ``holescan`` packages)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests import test_layout

ROOT = Path(__file__).resolve().parents[1]


def wheel_names(src: Path, out: Path) -> list[str]:
    done = subprocess.run(
        [
            *(sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"),
            *("--disable-pip-version-check", "-q", "-w", str(out), str(src)),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (wheel,) = out.glob("holescan-*.whl")
    with zipfile.ZipFile(wheel) as zf:
        return zf.namelist()


@pytest.mark.slow
def test_the_demo_run_in_the_clone_root_leaves_it_as_it_was(tmp_path: Path) -> None:
    before = sorted(p.name for p in ROOT.iterdir())
    env = {**os.environ, "XDG_DATA_HOME": str(tmp_path / "data")}
    done = subprocess.run(
        [sys.executable, "-m", "holescan.cli", "demo", "--duration", "2"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    (out,) = (tmp_path / "data" / "holescan" / "demo").iterdir()
    assert done.stderr.startswith(f"holescan demo: writing to {out}\n"), done.stderr[:300]
    assert list(out.glob("flight_*.mcap")) and (out / "demo.json").is_file()
    assert sorted(p.name for p in ROOT.iterdir()) == before
    (tmp_path / "wheel").mkdir()
    test_layout.test_an_install_adds_no_import_name_but_holescan(tmp_path / "wheel")


def test_an_output_folder_in_the_clone_root_is_never_packaged(tmp_path: Path) -> None:
    """A demo output folder as older versions left it (with subfolders, as a namespace
    package would be found) in a copy of the clone: the wheel still holds holescan only."""
    src = tmp_path / "clone"
    skip = shutil.ignore_patterns(".git", "node_modules", "build", "*.egg-info", "__pycache__")
    shutil.copytree(ROOT, src, symlinks=True, ignore=skip)
    left = src / "holescan-demo-20261206-101500"
    (left / "ground").mkdir(parents=True)
    (left / "flight_0000.mcap").write_bytes(b"\x89MCAP0\r\n")
    (left / "ground" / "holes.kml").write_text("<kml/>")
    names = wheel_names(src, tmp_path / "wheel")
    assert {n.split("/")[0] for n in names if ".dist-info" not in n} == {"holescan"}
    assert "holescan/capture/_preflight.py" in names
