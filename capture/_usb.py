"""Find the Asus Xtion (PrimeSense PS1080) on USB and reset it, through pyusb/libusb.

OpenNI2 says little when a sensor is missing or wedged; asking USB first gives a clear
error, and a USB port reset is what brings a stuck Xtion back without unplugging it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Final

from holescan.capture.errors import SensorError

__all__ = ["XTION_PRODUCTS", "XTION_VENDOR_ID", "UsbDeviceInfo", "find_xtion", "reset_xtion"]

_log = logging.getLogger(__name__)

XTION_VENDOR_ID: Final = 0x1D27
"""PrimeSense's USB vendor id (Asus Xtion Pro / Pro Live, PrimeSense Carmine)."""

XTION_PRODUCTS: Final = {
    0x0500: "PrimeSense PS1080",
    0x0600: "Asus Xtion Pro",
    0x0601: "Asus Xtion Pro Live",
    0x0609: "PrimeSense Carmine",
}
"""Product ids the PS1080 driver handles; other 0x1d27 products are listed as 'PrimeSense'."""


@dataclass(frozen=True)
class UsbDeviceInfo:
    """Where a sensor sits on USB.

    bus, address : libusb bus number and device address (the address changes on reset).
    port_path : port numbers from the root hub (stable across resets), empty if unknown.
    """

    vendor_id: int
    product_id: int
    bus: int
    address: int
    port_path: tuple[int, ...]
    name: str

    def __str__(self) -> str:
        port = ".".join(map(str, self.port_path)) or "?"
        return (
            f"{self.name} {self.vendor_id:04x}:{self.product_id:04x} "
            f"on bus {self.bus} port {port} (address {self.address})"
        )


def _usb_core() -> Any:
    try:
        import usb.core
    except ImportError as err:  # pragma: no cover - pyusb is a dependency
        raise SensorError("pyusb is not installed: pip install pyusb") from err
    return usb.core


def _find_devices(**match: int) -> list[Any]:
    core = _usb_core()
    try:
        return list(core.find(find_all=True, **match))
    except core.NoBackendError as err:
        raise SensorError(
            "no libusb backend for pyusb: install libusb-1.0-0 (apt-get install libusb-1.0-0)"
        ) from err
    except core.USBError as err:
        raise SensorError(f"cannot enumerate USB devices: {err}") from err


def _info(dev: Any) -> UsbDeviceInfo:
    ports = getattr(dev, "port_numbers", None) or ()
    product = int(dev.idProduct)
    return UsbDeviceInfo(
        vendor_id=int(dev.idVendor),
        product_id=product,
        bus=int(dev.bus),
        address=int(dev.address),
        port_path=tuple(int(p) for p in ports),
        name=XTION_PRODUCTS.get(product, "PrimeSense device"),
    )


def find_xtion() -> list[UsbDeviceInfo]:
    """Every PrimeSense/Xtion sensor on USB (vendor 0x1d27), sorted by bus and port.

    Returns an empty list when none is attached.

    Raises
    ------
    SensorError
        pyusb has no libusb backend or USB cannot be enumerated.
    """
    found = [_info(d) for d in _find_devices(idVendor=XTION_VENDOR_ID)]
    return sorted(found, key=lambda d: (d.bus, d.port_path, d.address))


def reset_xtion(device: UsbDeviceInfo) -> None:
    """Reset the sensor's USB port (like unplugging it); it re-enumerates in ~1-3 s.

    Close every OpenNI2 stream and device on it first. The sensor is found again by bus
    and port path (its address may have changed since ``device`` was listed).

    Raises
    ------
    SensorError
        The sensor is no longer on USB, or the reset was refused (permissions: install
        the udev rules of Debian's libopenni2-0, or run as root).
    """
    candidates = _find_devices(idVendor=device.vendor_id, idProduct=device.product_id)
    same_port = [
        d
        for d in candidates
        if int(d.bus) == device.bus
        and (
            tuple(getattr(d, "port_numbers", None) or ()) == device.port_path
            if device.port_path
            else int(d.address) == device.address
        )
    ]
    if not same_port:
        raise SensorError(f"cannot reset {device}: it is no longer on USB")
    core = _usb_core()
    try:
        same_port[0].reset()
    except core.USBError as err:
        raise SensorError(f"USB reset of {device} failed: {err}") from err
    _log.warning("reset %s", device)
