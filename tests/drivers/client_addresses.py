"""Addresses of the emulator's instruments as third-party clients spell them."""
from __future__ import annotations


def tcp_port(address: str) -> int:
    """The port of a ``socket://127.0.0.1:PORT`` address."""
    return int(address.rsplit(":", 1)[1])


def visa_resource(address: str, kind: str) -> str:
    """The VISA resource name of an instrument's pty (``ASRL...::INSTR``) or TCP address
    (``TCPIP::127.0.0.1::PORT::SOCKET``)."""
    if kind == "pty":
        return f"ASRL{address}::INSTR"
    return f"TCPIP::127.0.0.1::{tcp_port(address)}::SOCKET"
