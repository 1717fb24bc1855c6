"""The pre-flight checklist's records and the items read from the configuration and this
machine alone: the mount and camera, the disk, the signing key (:mod:`capture._preflight`
checks the sensor and the links)."""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np

from holescan.capture._diskbudget import disk_budget
from holescan.capture._flyconfig import FlyConfig
from holescan.detect import CameraIntrinsics

__all__ = [
    "CheckItem",
    "CheckStatus",
    "PreflightReport",
    "disk_item",
    "mount_item",
    "signing_item",
]

CheckStatus = Literal["GO", "NO-GO", "WARN", "SKIP"]

_MAX_OFF_NADIR_DEG: Final = 60.0


@dataclass(frozen=True)
class CheckItem:
    """One line of the checklist: ``name`` (one of :data:`ITEMS`), its status, and why."""

    name: str
    status: CheckStatus
    detail: str


@dataclass(frozen=True)
class PreflightReport:
    """The checklist. ``go``: no item is NO-GO (WARN and SKIP fly)."""

    items: tuple[CheckItem, ...]

    @property
    def go(self) -> bool:
        return all(i.status != "NO-GO" for i in self.items)

    def item(self, name: str) -> CheckItem:
        for i in self.items:
            if i.name == name:
                return i
        raise KeyError(name)

    def as_dict(self) -> dict[str, Any]:
        """``{"go": bool, "items": [{"name", "status", "detail"}, ...]}`` (the JSON output)."""
        return {
            "go": self.go,
            "items": [{"name": i.name, "status": i.status, "detail": i.detail} for i in self.items],
        }

    def no_go_line(self) -> str:
        """The NO-GO items on one line (empty when GO)."""
        return "; ".join(f"{i.name}: {i.detail}" for i in self.items if i.status == "NO-GO")


def disk_item(cfg: FlyConfig) -> CheckItem:
    """Room for the flight's log on the file system of ``cfg.log_dir``, by the flight's own
    disk budget (:func:`capture.disk_budget`: the rate measured on the last finished log or
    expected for the image settings, the image reserve, the planned flight). Removes
    nothing (the retention rule is ``fly``'s, when configured).

    NO-GO: the folder cannot be written, or the planned flight does not fit; WARN: under
    10 minutes of log fit; else GO.
    """
    folder = cfg.log_dir
    existing = next((p for p in (folder, *folder.parents) if p.exists()), Path("/"))
    if not os.access(existing, os.W_OK):
        return CheckItem("disk", "NO-GO", f"{existing} is not writable by this user")
    budget = disk_budget(cfg, shutil.disk_usage(existing).free)
    what = budget.describe().removeprefix("disk: ")
    if budget.fits is False:
        return CheckItem("disk", "NO-GO", what)
    if budget.lasts_s < 600:
        return CheckItem("disk", "WARN", what)
    return CheckItem("disk", "GO", what)


def mount_item(cfg: FlyConfig, camera: CameraIntrinsics | None) -> CheckItem:
    mount = cfg.flight.mount
    r = np.asarray(mount.rotation, dtype=np.float64)
    off_nadir = math.degrees(math.acos(max(-1.0, min(1.0, float(r[2, 2])))))
    parts = [f"camera axis {off_nadir:.0f} deg from straight down"]
    if camera is not None:
        c = camera
        plausible = (
            c.width > 0
            and c.height > 0
            and 0.3 * c.width < c.fx < 3.0 * c.width
            and 0.3 * c.width < c.fy < 3.0 * c.width
            and 0 <= c.cx < c.width
            and 0 <= c.cy < c.height
        )
        parts.append(f"{c.width}x{c.height} f {c.fx:.0f} px, centre ({c.cx:.1f}, {c.cy:.1f})")
        if not plausible:
            return CheckItem("mount and camera", "NO-GO", "implausible intrinsics: " + parts[-1])
    if off_nadir > _MAX_OFF_NADIR_DEG:
        return CheckItem(
            "mount and camera",
            "NO-GO",
            f"{parts[0]} (more than {_MAX_OFF_NADIR_DEG:.0f}: check [mount] in fly.toml)",
        )
    return CheckItem("mount and camera", "GO", "; ".join(parts))


def signing_item(cfg: FlyConfig) -> CheckItem:
    if cfg.signing is None:
        return CheckItem("signing", "SKIP", "not configured: links unsigned")
    where = "the ground-station link" if cfg.gcs else "the autopilot link"
    return CheckItem("signing", "GO", f"key {cfg.signing.fingerprint} signs {where}")
