"""Finding the Xtion on USB (real pyusb + libusb), and the live source without a sensor."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from holescan.capture import OpenNI2Device, SensorError, UsbDeviceInfo, find_xtion, reset_xtion
from holescan.errors import HolescanError

REPO = Path(__file__).resolve().parents[2]


def sysfs_xtions() -> list[tuple[int, int]]:
    """(bus, address) of PrimeSense devices according to the kernel, independent of libusb."""
    found = []
    for dev in Path("/sys/bus/usb/devices").glob("*"):
        vendor = dev / "idVendor"
        if vendor.is_file() and vendor.read_text().strip().lower() == "1d27":
            bus = int((dev / "busnum").read_text())
            address = int((dev / "devnum").read_text())
            found.append((bus, address))
    return sorted(found)


def test_find_xtion_agrees_with_the_kernel() -> None:
    found = find_xtion()
    assert all(isinstance(d, UsbDeviceInfo) for d in found)
    assert sorted((d.bus, d.address) for d in found) == sysfs_xtions()


def test_no_xtion_attached_gives_empty_list_and_a_clear_sensor_error() -> None:
    if sysfs_xtions():
        pytest.skip("an Xtion is attached to this machine")
    assert find_xtion() == []
    with pytest.raises(SensorError, match=r"no Xtion found on USB \(vendor 0x1d27\)"):
        OpenNI2Device().open()
    assert issubclass(SensorError, HolescanError)


def test_reset_of_a_device_no_longer_on_usb_raises_sensor_error() -> None:
    ghost = UsbDeviceInfo(0x1D27, 0x0601, 250, 127, (9, 9, 9), "Asus Xtion Pro Live")
    if (ghost.bus, ghost.address) in sysfs_xtions():
        pytest.skip("an Xtion really sits at the ghost's address")
    with pytest.raises(SensorError, match="no longer on USB"):
        reset_xtion(ghost)
    assert "1d27:0601 on bus 250 port 9.9.9" in str(ghost)


def test_opening_an_absent_uri_raises_sensor_error_from_openni2() -> None:
    """The real library is asked (in a child process: it initialises OpenNI2)."""
    child = textwrap.dedent(
        """
        import json
        from holescan.capture import OpenNI2Device, SensorError
        try:
            with OpenNI2Device(uri="1d27/0601@250/127"):
                result = "opened"
        except SensorError as err:
            result = str(err)
        print(json.dumps(result))
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", child], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    message = json.loads(proc.stdout.strip().splitlines()[-1])
    assert message.startswith("OpenNI2 cannot open Xtion 1d27/0601@250/127")
