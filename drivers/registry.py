"""Map ``--port`` URL schemes to driver classes, imported only when used.

Adding a transport = one module with a :class:`drivers.base.Driver` subclass plus one
line here; no other transport is touched.
"""

from __future__ import annotations

import importlib

from core.errors import InputError, TransportError
from drivers.base import Driver
from drivers.url import PortURL, parse_port_url

__all__ = ["DRIVERS", "driver_class", "open_driver"]

#: scheme -> (module, class)
DRIVERS: dict[str, tuple[str, str]] = {
    "serial": ("drivers.transports.serial_port", "SerialDriver"),
    "modbus-tcp": ("drivers.transports.modbus", "ModbusDriver"),
    "modbus-rtu": ("drivers.transports.modbus", "ModbusDriver"),
    "can": ("drivers.transports.can_bus", "CanDriver"),
    "linuxcnc": ("drivers.transports.linuxcnc_hal", "LinuxCNCDriver"),
}


def driver_class(scheme: str) -> type[Driver]:
    try:
        module_name, class_name = DRIVERS[scheme]
    except KeyError:
        known = ", ".join(sorted(DRIVERS))
        raise InputError.about("port", f"URL scheme {scheme!r} is not supported (known: {known})") from None
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise TransportError(f"the {scheme} driver cannot be loaded: {exc}") from exc
    return getattr(module, class_name)


def open_driver(port: str | PortURL, axes: list[str] | None = None) -> Driver:
    """Build (not yet open) the driver for a ``--port`` URL."""
    url = port if isinstance(port, PortURL) else parse_port_url(port)
    return driver_class(url.scheme)(url, axes)
