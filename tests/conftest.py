"""Test-session set-up shared by every test package.

Under pytest-xdist (``.ci/run``: ``-n 2 --dist loadgroup``) each worker is its own session,
so a module- or session-scoped fixture is built once *per worker* that runs a test using
it. To build each expensive fixture once (a simulated flight, the demo run, a generated
dataset), :func:`pytest_collection_modifyitems` puts every test that shares a non-function
fixture defined in this tree (``tests/**/conftest.py`` or a test module) into one
``xdist_group``: the tests of one module fixture, and all the users of one session fixture,
run on the same worker. It also moves the work units holding a ``slow`` test to the front,
so the long ones start first and the short ones fill in at the end. A plain ``pytest``
run (no worker) is left exactly as collected.
"""

from __future__ import annotations

import ast
import os
from pathlib import Path

import pytest

# pymavlink chooses MAVLink 1 or 2 once, when mavutil is first imported, from MAVLINK20;
# missions sets it before that import (the project's one door to pymavlink). Importing it
# here first means no test module's own pymavlink import (mavwp ...) can make it MAVLink 1.
import holescan.missions  # noqa: F401

_TESTS = Path(__file__).resolve().parent


def _fixture_scopes(path: Path) -> dict[str, str]:
    """Fixture name -> scope of the fixtures ``path`` defines (``@pytest.fixture`` with a
    literal ``scope=``, as every fixture here is written; read from the source, so no
    pytest internals are needed)."""
    scopes: dict[str, str] = {}
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.FunctionDef):
            continue
        for dec in node.decorator_list:
            call = dec if isinstance(dec, ast.Call) else None
            target = call.func if call is not None else dec
            if not (isinstance(target, ast.Attribute) and target.attr == "fixture"):
                continue
            scope = "function"
            for kw in call.keywords if call is not None else ():
                if kw.arg == "scope" and isinstance(kw.value, ast.Constant):
                    scope = str(kw.value.value)
            scopes[node.name] = scope
    return scopes


class _Definitions:
    """Where each fixture an item uses is defined (its module, else the closest conftest
    up to this folder) and with which scope; files read once."""

    def __init__(self) -> None:
        self._files: dict[Path, dict[str, str]] = {}

    def _scopes(self, path: Path) -> dict[str, str]:
        if path not in self._files:
            self._files[path] = _fixture_scopes(path) if path.is_file() else {}
        return self._files[path]

    def find(self, module: Path, name: str) -> tuple[Path, str] | None:
        """(defining file, scope) of fixture ``name`` as a test in ``module`` gets it."""
        if name in self._scopes(module):
            return module, self._scopes(module)[name]
        folder = module.parent
        while True:
            conftest = folder / "conftest.py"
            if name in self._scopes(conftest):
                return conftest, self._scopes(conftest)[name]
            if folder == _TESTS or folder == folder.parent:
                return None  # a plugin's (tmp_path_factory ...): nothing of ours to share
            folder = folder.parent


def _shared_keys(item: pytest.Item, defs: _Definitions) -> list[str]:
    """What ``item`` shares with other tests: one key per non-function fixture of ours."""
    if not isinstance(item, pytest.Function):
        return []  # a doctest: no fixtures of ours
    module = item.nodeid.split("::", 1)[0]
    keys = []
    for name in item.fixturenames:
        found = defs.find(item.path, name)
        if found is None or found[1] == "function":
            continue  # per test, or not ours
        where, scope = found
        if scope in ("session", "package"):
            keys.append(f"{where.relative_to(_TESTS)}::{name}")  # one instance for every user
        else:
            keys.append(module)  # module / class: one instance per module
    return keys


def _groups(items: list[pytest.Item]) -> dict[str, str]:
    """nodeid -> group name, for the items that share an expensive fixture (union-find)."""
    parent: dict[str, str] = {}

    def root(k: str) -> str:
        while parent.setdefault(k, k) != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    defs = _Definitions()
    item_keys = {item.nodeid: _shared_keys(item, defs) for item in items}
    for keys in item_keys.values():
        for k in keys[1:]:
            parent[root(k)] = root(keys[0])
    return {nodeid: root(keys[0]) for nodeid, keys in item_keys.items() if keys}


@pytest.hookimpl(tryfirst=True)  # before xdist reads the xdist_group marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    groups = _groups(items)
    for item in items:
        if item.nodeid in groups:
            item.add_marker(pytest.mark.xdist_group(groups[item.nodeid]))
    # Slow work units first (a stable sort: the same order on every worker, as xdist needs;
    # a group's tests stay together and in order, so its module fixtures are built once).
    unit = {item.nodeid: groups.get(item.nodeid, item.nodeid) for item in items}
    slow_units = {unit[item.nodeid] for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: unit[item.nodeid] not in slow_units)
