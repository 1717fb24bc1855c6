"""The architecture the README describes is the one the code has."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from holescan_errors import InputError
from sim import sortie_params

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("capture", "detect", "geotag", "missions", "ground", "sim", "holescan")


def test_the_flight_side_loads_neither_the_simulator_nor_numba() -> None:
    code = (
        "import sys, capture, missions, detect, geotag; "
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('sim', 'numba', 'ground')); "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr


def test_no_module_outside_a_package_imports_its_private_modules() -> None:
    offenders = []
    for pkg in (*PACKAGES, "benchmarks"):
        for path in (ROOT / pkg).rglob("*.py"):
            for n, line in enumerate(path.read_text().splitlines(), 1):
                words = line.split()
                if len(words) >= 2 and words[0] in ("from", "import"):
                    top, _, rest = words[1].partition(".")
                    if top in PACKAGES and top != pkg and rest.startswith("_"):
                        offenders.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    # benchmarks/ablation.py turns the detector's private switches on purpose
    assert [o for o in offenders if not o.startswith("benchmarks/ablation.py:")] == [], offenders


def test_modules_stay_small() -> None:
    big = {
        str(p.relative_to(ROOT)): n
        for pkg in (*PACKAGES, "holescan_errors")
        for p in (ROOT / pkg).rglob("*.py")
        if (n := len(p.read_text().splitlines())) > 550
    }
    assert not big, big


def test_a_typo_in_the_sim_table_is_named() -> None:
    with pytest.raises(InputError, match=r"unknown setting sim\.world_sed"):
        sortie_params({"world_sed": 3})
    params, record = sortie_params({"world_seed": 3})
    assert params.world_seed == 3 and record["sim.world_seed"] == 3
