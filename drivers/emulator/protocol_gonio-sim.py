"""pyserial URL scheme ``gonio-sim://`` (see :mod:`drivers.emulator.urlhandler`)."""
from .urlhandler import Serial  # noqa: F401
