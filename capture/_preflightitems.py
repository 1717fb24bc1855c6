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

from holescan.capture._flyconfig import FlyConfig
from holescan.detect import CameraIntrinsics

__all__ = [
    "RAW_LOG_BYTES_PER_S",
    "CheckItem",
    "CheckStatus",
    "PreflightReport",
    "disk_item",
    "mount_item",
    "signing_item",
]

CheckStatus = Literal["GO", "NO-GO", "WARN", "SKIP"]

RAW_LOG_BYTES_PER_S: Final = 34e6
"""What a flight log takes at 30 fps with raw colour and depth (zstd-3 over a rubble scene:
the high end of the 19-34 MB/s measured on simulated and demo sorties)."""

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
    """Room for the flight's log on the file system of ``cfg.log_dir``.

    NO-GO: the folder cannot be written, or the planned ``duration_s`` does not fit at
    :data:`RAW_LOG_BYTES_PER_S`; WARN: less than 10 minutes of log fit; else GO with the
    minutes that fit.
    """
    folder = cfg.log_dir
    existing = next((p for p in (folder, *folder.parents) if p.exists()), Path("/"))
    if not os.access(existing, os.W_OK):
        return CheckItem("disk", "NO-GO", f"{existing} is not writable by this user")
    free = shutil.disk_usage(existing).free
    fits_s = free / RAW_LOG_BYTES_PER_S
    what = f"{free / 1e9:.1f} GB free on {existing}: {fits_s / 60:.0f} min of log at "
    what += f"{RAW_LOG_BYTES_PER_S / 1e6:.0f} MB/s"
    planned = cfg.duration_s
    if planned is not None and fits_s < planned:
        return CheckItem("disk", "NO-GO", f"{what}; the planned {planned / 60:.0f} min do not fit")
    if fits_s < 600:
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
