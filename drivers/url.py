"""Parse ``--port`` URLs: the scheme picks the driver, the query gives typed options.

Examples (SPEC §3)::

    serial:///dev/ttyUSB0?baud=921600
    modbus-tcp://127.0.0.1:5020
    modbus-rtu:///dev/ttyUSB0?baud=115200&unit=1
    can://virtual/channel0?node=3
    /dev/ttyUSB0                 (a bare device path means serial)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlsplit

from core.errors import InputError

__all__ = ["PortURL", "parse_port_url"]

#: Schemes whose path is a device on this computer (no host part: scheme:///dev/...).
_DEVICE_SCHEMES = ("serial", "modbus-rtu")
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


@dataclass(frozen=True)
class PortURL:
    scheme: str
    host: str = ""
    port: int | None = None
    path: str = ""
    query: dict[str, str] = field(default_factory=dict)
    raw: str = ""

    def check_options(self, allowed: dict[str, type]) -> None:
        """Reject query keys the driver does not know, by name."""
        unknown = sorted(set(self.query) - set(allowed))
        if unknown:
            known = ", ".join(sorted(allowed)) or "none"
            raise InputError.about("port", f"{self.raw}: unknown option {unknown[0]!r} (known: {known})")

    def option(self, name: str, kind: type, default=None):
        """The query option ``name`` converted to ``kind``; a bad value is a one-line error."""
        if name not in self.query:
            return default
        text = self.query[name]
        try:
            if kind is bool:
                low = text.lower()
                if low in _TRUE:
                    return True
                if low in _FALSE:
                    return False
                raise ValueError(text)
            return kind(text)
        except ValueError:
            raise InputError.about(
                "port", f"{self.raw}: option {name}={text!r} is not a valid {kind.__name__}"
            ) from None


def parse_port_url(text: str) -> PortURL:
    """Split a port URL (``agent capture --port``) into scheme, host, port, path and query options."""
    if not text or not text.strip():
        raise InputError.about("port", "the port URL is empty; give a URL such as modbus-tcp://127.0.0.1:5020")
    text = text.strip()
    if text.startswith("/") or "://" not in text:
        if "://" not in text and not text.startswith("/"):
            raise InputError.about(
                "port", f"{text!r}: not a URL; use scheme://..., e.g. serial:///dev/ttyUSB0 or modbus-tcp://127.0.0.1:5020"
            )
        return PortURL(scheme="serial", path=text, raw=text)
    parts = urlsplit(text)
    query: dict[str, str] = {}
    for key, value in parse_qsl(parts.query, keep_blank_values=True):
        if key in query:
            raise InputError.about("port", f"{text}: option {key!r} given twice")
        query[key] = value
    if parts.scheme.lower() in _DEVICE_SCHEMES and parts.netloc:
        raise InputError.about(
            "port", f"{text}: {parts.netloc!r} would be read as a host name, and {parts.path or '/'} as the device; "
            f"a device path needs three slashes: {parts.scheme}:///{parts.netloc}{parts.path}")
    try:
        port = parts.port
    except ValueError:
        raise InputError.about("port", f"{text}: the port number is not valid") from None
    return PortURL(
        scheme=parts.scheme.lower(),
        host=parts.hostname or "",
        port=port,
        path=parts.path,
        query=query,
        raw=text,
    )
