"""The architecture docs/architecture.md describes is the one the code has."""

from __future__ import annotations

import ast
import contextlib
import graphlib
import subprocess
import sys
import warnings
import zipfile
from collections.abc import Iterator
from pathlib import Path

import grimp
import pytest

from holescan.errors import InputError
from holescan.sim import sortie_params

ROOT = Path(__file__).resolve().parents[1]
# The folders of the repository's root that are holescan's subpackages, and the namespace itself.
PACKAGES = (
    *("capture", "detect", "geotag", "mapping", "missions", "flightlog", "link"),
    *("ground", "sim", "demo", "holescan"),
)
# Python code outside the installed package that follows the same rules.
OTHER_CODE = ("benchmarks", "tests")
# A module this long is worth a look: is it one concept? (a warning, never a gate: rooms
# are cut by concept, and documentation is never trimmed to pass a count)
LONG_MODULE_LINES = 700


def _sources(*folders: str) -> Iterator[Path]:
    for folder in folders:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "node_modules" not in path.parts and not path.is_symlink():
                yield path


def _package_sources() -> Iterator[Path]:
    # holescan/capture etc. are links to the root folders: walk each file once.
    for path in _sources(*PACKAGES):
        if path.resolve() == path:
            yield path


def test_the_flight_side_loads_neither_the_simulator_nor_numba() -> None:
    code = (
        "import sys, holescan.capture, holescan.missions, holescan.detect, holescan.geotag, "
        "holescan.flightlog, holescan.link, holescan.outputs, holescan.mapping; "
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'dask', "
        "'distributed', 'starlette', 'uvicorn') "
        "or m.split('.')[:2] in (['holescan', 'sim'], ['holescan', 'ground'], "
        "['holescan', 'demo'], ['holescan', 'cli'])); "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr


def test_an_install_adds_no_import_name_but_holescan(tmp_path: Path) -> None:
    # A real wheel from the build backend, the way `pip install holescan` would get it.
    done = subprocess.run(
        [
            *(sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"),
            *("--disable-pip-version-check", "-q", "-w", str(tmp_path), str(ROOT)),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (wheel,) = tmp_path.glob("holescan-*.whl")
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        (top_level,) = [n for n in names if n.endswith(".dist-info/top_level.txt")]
        declared = zf.read(top_level).decode().split()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"holescan"} and declared == ["holescan"], (tops, declared)
    # Every subpackage is inside, with its data files.
    for sub in (*PACKAGES[:-1], "cli"):
        assert f"holescan/{sub}/__init__.py" in names, sub
    for name in (
        "station.html",
        "station.js",
        "station.css",
        "review.js",
        "maplayers.js",
        "mapview.js",
    ):
        assert f"holescan/ground/station/static/{name}" in names, name
    assert "holescan/ground/report/report.css" in names
    assert "holescan/mapping/recall_table.json" in names


def _private_imports(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    yield f"{node.lineno}: from {node.module} import {alias.name}"


def test_no_private_name_is_imported_from_another_module() -> None:
    # What crosses a module boundary is public (no leading underscore) where it is defined.
    offenders = [
        f"{path.relative_to(ROOT)}:{line}"
        for path in (*_package_sources(), *_sources(*OTHER_CODE))
        for line in _private_imports(path)
    ]
    assert offenders == [], "\n".join(offenders)


def test_no_module_outside_a_package_imports_its_private_modules() -> None:
    offenders = []
    for path in (*_package_sources(), *_sources(*OTHER_CODE)):
        rel = path.relative_to(ROOT)
        own = rel.parts[0] if rel.parts[0] in PACKAGES else None
        if own == "holescan" and len(rel.parts) > 2:
            own = rel.parts[1]  # holescan/cli/...
        if rel.parts[0] == "tests" and len(rel.parts) > 2:
            own = rel.parts[1]  # tests/detect/... tests its own package's modules (white box)
        for node in ast.walk(ast.parse(path.read_text())):
            modules = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            for module in modules:
                parts = module.split(".")
                if parts[0] != "holescan" or len(parts) < 3:
                    continue
                if parts[1] != own and any(p.startswith("_") for p in parts[2:]):
                    offenders.append(f"{rel}:{node.lineno}: {module}")
    # benchmarks/ablation.py turns the detector's private switches on purpose
    assert [o for o in offenders if not o.startswith("benchmarks/ablation.py:")] == [], offenders


def test_no_import_circle() -> None:
    graph = grimp.build_graph("holescan", cache_dir=None)
    order = graphlib.TopologicalSorter(
        {m: graph.find_modules_directly_imported_by(m) for m in graph.modules}
    )
    try:
        order.prepare()
    except graphlib.CycleError as err:
        pytest.fail(f"import circle: {' -> '.join(err.args[1])}")


def test_long_modules_are_named() -> None:
    long = {
        str(p.relative_to(ROOT)): n
        for p in _package_sources()
        if (n := len(p.read_text().splitlines())) > LONG_MODULE_LINES
    }
    if long:
        warnings.warn(f"modules over {LONG_MODULE_LINES} lines: {long}", stacklevel=1)


def test_a_typo_in_the_sim_table_is_named() -> None:
    with pytest.raises(InputError, match=r"unknown setting sim\.world_sed"):
        sortie_params({"world_sed": 3})
    params, record = sortie_params({"world_seed": 3})
    assert params.world_seed == 3 and record["sim.world_seed"] == 3


def _imported_modules(path: Path) -> Iterator[tuple[int, str]]:
    """Every module an import names in ``path``: its code and its docstring examples."""
    text = path.read_text()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.stmt):
            yield from _imported_modules_of(node)
    for lineno, line in enumerate(text.splitlines(), 1):
        example = line.strip()
        if example.startswith((">>> import ", ">>> from ")):
            with contextlib.suppress(SyntaxError):
                for node in ast.parse(example[4:]).body:
                    for _, name in _imported_modules_of(node):
                        yield lineno, name


def _imported_modules_of(node: ast.stmt) -> Iterator[tuple[int, str]]:
    if isinstance(node, ast.Import):
        yield from ((node.lineno, a.name) for a in node.names)
    elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
        yield node.lineno, node.module


def test_subpackages_are_imported_by_one_name_only() -> None:
    # capture/, detect/, ... are holescan.capture, holescan.detect, ...; the root folders
    # are also importable as top-level names when the clone's root is on sys.path (pytest
    # puts it there to collect the doctests): a module imported by both names is two
    # modules (two copies of its state, isinstance failing across them).
    bare = set(PACKAGES) - {"holescan"}
    offenders = [
        f"{path.relative_to(ROOT)}:{lineno}: {module}"
        for path in (*_package_sources(), *_sources(*OTHER_CODE))
        for lineno, module in _imported_modules(path)
        if module.split(".")[0] in bare
    ]
    assert offenders == [], "\n".join(offenders)
