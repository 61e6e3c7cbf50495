"""The emulated goniometer: a simulated lab world behind real serial protocols.

Nothing here runs at import time.  :class:`drivers.emulator.rig.EmulatedRig` assembles the
world (geometry, lamp, CCD), the three device firmwares and their transports.
"""
