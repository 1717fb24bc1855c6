"""The flight install is what the flight needs: ``holescan check`` and ``holescan fly`` run
with every package of the ``ground`` extra unimportable (an import blocker in
``sitecustomize``, so the detection worker process has it too), and a ground command on
such an install says in one line what to install."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from packaging.requirements import Requirement

from holescan.capture import write_oni
from holescan.cli import GROUND_ONLY
from holescan.detect import CameraIntrinsics, Frame

ROOT = Path(__file__).resolve().parents[1]

BLOCKER = """
import sys

BLOCKED = {blocked!r}
TRIED = {tried!r}


class GroundOnly:
    def find_spec(self, name, path=None, target=None):
        top = name.split(".")[0]
        if top in BLOCKED:
            with open(TRIED, "a") as f:
                f.write(name + "\\n")
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, GroundOnly())
"""


def ground_extra() -> set[str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return {Requirement(r).name.lower() for r in project["optional-dependencies"]["ground"]}


def test_the_cli_knows_every_package_of_the_ground_extra() -> None:
    # (each of these distributions is imported under its own name)
    assert ground_extra() <= GROUND_ONLY
    base = {Requirement(r).name.lower() for r in tomllib.loads(
        (ROOT / "pyproject.toml").read_text())["project"]["dependencies"]}  # fmt: skip
    assert not base & GROUND_ONLY, base & GROUND_ONLY


@pytest.fixture
def flight_only(tmp_path: Path) -> tuple[dict[str, str], Path]:
    """An environment where the ground extra's packages cannot be imported."""
    site = tmp_path / "site"
    site.mkdir()
    tried = tmp_path / "tried.txt"
    (site / "sitecustomize.py").write_text(
        BLOCKER.format(blocked=sorted(GROUND_ONLY), tried=str(tried))
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    return env, tried


def run(env: dict[str, str], *argv: str, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "holescan.cli", *argv],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
    )


def test_check_and_fly_never_import_the_ground_packages(
    tmp_path: Path, flight_only: tuple[dict[str, str], Path]
) -> None:
    env, tried = flight_only
    check = run(env, "check", "--json", "--log-dir", str(tmp_path / "logs"))
    assert check.returncode in (0, 1), check.stderr[-3000:]  # NO-GO here: no Xtion, no autopilot
    assert json.loads(check.stdout)["items"], check.stdout
    cam = CameraIntrinsics.xtion(320, 240)
    depth = np.full((240, 320), 2500, np.uint16)
    depth[90:150, 130:210] = 0
    rgb = np.full((240, 320, 3), 90, np.uint8)
    write_oni(
        tmp_path / "in.oni",
        [Frame(i, rgb, depth, 0, i * 33_333_333) for i in range(20)],
        cam,
    )
    fly = run(
        env,
        *("fly", "--bench", "--sensor", f"oni:{tmp_path / 'in.oni'}"),
        *("--log-dir", str(tmp_path / "logs")),
    )
    assert fly.returncode == 0, fly.stderr[-3000:]
    assert "frames: captured 20, logged 20, dropped from the log 0" in fly.stdout, fly.stdout
    assert not tried.exists(), tried.read_text()  # not even tried (and caught)
    # the blocker was there: a ground package is unimportable in that environment
    probe = subprocess.run(
        [sys.executable, "-c", "import dask"], env=env, capture_output=True, text=True
    )
    assert probe.returncode == 1 and "No module named 'dask'" in probe.stderr


def test_a_ground_command_on_the_flight_install_names_the_extra(
    tmp_path: Path, flight_only: tuple[dict[str, str], Path]
) -> None:
    env, _ = flight_only
    demo = run(env, "demo", "--out", str(tmp_path / "demo"))
    assert demo.returncode == 2, demo.stderr[-3000:]
    assert demo.stderr.count("\n") == 1 and "Traceback" not in demo.stderr, demo.stderr
    assert demo.stderr.startswith("holescan demo: error: this needs the ground install")
    assert "pip install 'holescan[ground]'" in demo.stderr
