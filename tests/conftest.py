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

import os

import pytest

# pymavlink chooses MAVLink 1 or 2 once, when mavutil is first imported, from MAVLINK20;
# missions sets it before that import (the project's one door to pymavlink). Importing it
# here first means no test module's own pymavlink import (mavwp ...) can make it MAVLink 1.
import holescan.missions  # noqa: F401


def _shared_keys(item: pytest.Item) -> list[str]:
    """What ``item`` shares with other tests: one key per non-function fixture of ours."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return []
    module = item.nodeid.split("::", 1)[0]
    keys = []
    for name, defs in info.name2fixturedefs.items():
        fixdef = defs[-1]  # the one this item gets (the closest override)
        if fixdef.scope == "function" or not fixdef.baseid:
            continue  # per test, or a plugin's (tmp_path_factory ...): nothing to share
        if fixdef.scope in ("session", "package"):
            keys.append(f"{fixdef.baseid}::{name}")  # one instance for every user
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

    item_keys = {item.nodeid: _shared_keys(item) for item in items}
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
