"""Hardware layer of gonio: client drivers for the goniometer's instruments and an emulator.

``drivers`` talks to three serial instruments (a Newport ESP300-dialect motion controller,
a SCPI CCD camera and a SCPI lamp power supply; see ``docs/protocol.md``).
``drivers.emulator`` simulates the whole lab (stage, lamp, camera and sample) behind the
same serial protocols.  This package never imports ``gonio``; importing it only defines
code (no ports are opened, no threads are started).
"""

# Lazy re-exports of the client drivers (PEP 562): ``from drivers import Rig`` works, yet
# ``import drivers`` imports nothing else (not even numpy or pyserial).
_EXPORTS = {
    "Rig": "drivers.rig",
    "Measurement": "drivers.rig",
    "ESP300": "drivers.esp300",
    "Camera": "drivers.camera",
    "Lamp": "drivers.lamp",
    "SerialLine": "drivers.serial_line",
    "DriverError": "drivers.errors",
    "DeviceError": "drivers.errors",
    "GeometryError": "drivers.errors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'drivers' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module), name)
