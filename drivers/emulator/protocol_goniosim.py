"""pyserial URL scheme ``goniosim://`` (alias of ``gonio-sim://``, see :mod:`drivers.emulator.urlhandler`)."""
from .urlhandler import Serial  # noqa: F401
