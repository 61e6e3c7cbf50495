"""The emulator driven by two lab frameworks: QCoDeS (with pyvisa-py) and ophyd + bluesky.

A lab that adopts the virtual rig writes small drivers in the framework it already uses;
these tests are such drivers, written from docs/protocol.md alone, and check that the
unmodified emulator serves them as the hardware would:

- QCoDeS 0.58: a ``VisaInstrument`` per instrument over pyvisa-py (``@py``), through TCP
  sockets and through the pseudo-terminals (``ASRL``); ``*IDN?`` parsed into QCoDeS's IDN
  dict, a ``do1d`` sweep of the lamp's polar angle measuring the camera's ROI mean into a
  database under ``tmp_path`` (nothing is written to the user's ``~/.qcodes`` or
  ``~/experiments.db``), the errors read with ``SYST:ERR?`` / ``TB?``;
- ophyd 1.11 and bluesky 1.15: ophyd Devices on plain pyserial ports (no EPICS), a stage
  axis whose ``set()`` Status is completed by a thread polling ``MD?`` and a camera whose
  ``trigger()`` Status is completed by polling ``*ESR?``: the polling clients the wall
  clock serves (docs/emulator.md, "Time"), run at 20 times the hardware's pace;
  ``scan``, ``rel_scan`` and ``count`` under a ``RunEngine``, every event checked against
  the emulator's ground truth (``rig.control.true_state()``, ``rig.control.expected_dn``);
- a lamp warm-up that sleeps (``time.sleep`` in QCoDeS, ``bps.sleep`` in bluesky) and then
  reads the warm filament's current under the wall clock, and the cold filament's inrush
  under the event clock, where a client's sleep does not count.

The ``test`` extra installs the frameworks; each test skips with the reason when one is
missing.
"""
from __future__ import annotations

import contextlib
import functools
import itertools
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

from client_addresses import visa_resource

from drivers.emulator.rig import EmulatedRig

ALBEDO = 0.8
EXPOSURE_S = 0.025
ROI = (206, 190, 100, 100)  # 100 x 100 pixels about the image centre, inside the sample's image
BAUDRATES = {"stage": 19200, "camera": 115200, "lamp": 9600}
HOT_CURRENT_A = 2.5  # the lamp at its rated 120 V (docs/protocol.md, MEAS:CURR?)
REPEATABILITY_DEG = 0.002  # 1 sigma of a move's end point (docs/protocol.md, defaults table)
ENCODER_DEG = 0.001  # TP resolution
WALL_SPEED = 20.0  # simulated seconds per wall second in the wall-clock tests

_names = itertools.count()


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, ALBEDO / np.pi)


def rig_name(prefix: str) -> str:
    """A rig name unique in this process (the ``gonio-sim://`` registry is per process)."""
    return f"{prefix}-{next(_names)}-{id(_names):x}"


def move_time(distance: float, velocity: float, acceleration: float) -> float:
    """Duration of a trapezoidal (or triangular) move with equal acceleration and
    deceleration (docs/protocol.md, "Moves")."""
    if distance >= velocity ** 2 / acceleration:
        return distance / velocity + velocity / acceleration
    return 2.0 * np.sqrt(distance / acceleration)


# == QCoDeS =====================================================================================
@functools.cache
def qcodes_drivers() -> SimpleNamespace:
    """QCoDeS instrument classes for the three instruments (built once qcodes is importable)."""
    from qcodes.instrument import InstrumentChannel, VisaInstrument
    from qcodes.parameters import create_on_off_val_mapping
    from qcodes.validators import Ints, Numbers, Sequence

    def set_baud_rate(instrument: VisaInstrument, baud_rate: int) -> None:
        # A pty checks the client's rate like a real line: set it before the first byte.
        if instrument.visa_handle.resource_name.startswith("ASRL"):
            instrument.visa_handle.baud_rate = baud_rate

    class Esp300Axis(InstrumentChannel):
        """One axis of the ESP300: a move waits with ``WS`` and then reads the error buffer."""

        def __init__(self, parent: "Esp300", name: str, axis: int, limits: tuple[float, float]) -> None:
            super().__init__(parent, name)
            self.axis = axis
            self.position = self.add_parameter(
                "position", unit="deg", label=f"axis {axis}", get_cmd=f"{axis}TP?", get_parser=float,
                set_cmd=self._move, vals=Numbers(*limits))
            self.encoder = self.add_parameter("encoder", unit="deg", get_cmd=f"{axis}TP?", get_parser=float)
            self.target = self.add_parameter("target", unit="deg", get_cmd=f"{axis}DP?", get_parser=float)
            self.motion_done = self.add_parameter("motion_done", get_cmd=f"{axis}MD?", get_parser=int)
            self.motor = self.add_parameter(
                "motor", get_cmd=f"{axis}MO?", get_parser=lambda reply: reply == "1",
                set_cmd=lambda on: self.write(f"{axis}{'MO' if on else 'MF'}"))

        def _move(self, value: float) -> None:
            code, _, message = self.ask(f"{self.axis}PA{value:.5f};{self.axis}WS;TB?").split(", ", 2)
            if int(code):
                raise RuntimeError(f"{self.full_name}: ESP300 error {code}, {message}")

    class Esp300(VisaInstrument):
        """Newport ESP300: commands end in CR, replies in CR LF. It has no ``*IDN?`` (COMMAND
        DOES NOT EXIST on an ESP300): ``VE?`` identifies it."""

        default_terminator = "\r\n"
        default_timeout = 2.0

        def __init__(self, name: str, address: str, **kwargs) -> None:
            super().__init__(name, address, **kwargs)
            set_baud_rate(self, BAUDRATES["stage"])
            self.visa_handle.write_termination = "\r"
            for axis, limits in ((1, (-90, 90)), (2, (0, 90)), (3, (-180, 180))):
                self.add_submodule(f"axis{axis}", Esp300Axis(self, f"axis{axis}", axis, limits))

        def get_idn(self) -> dict[str, str | None]:
            model, _, firmware = self.ask("VE?").partition(" Version ")
            return {"vendor": "Newport", "model": model, "serial": None, "firmware": firmware}

        def next_error(self) -> tuple[int, str]:
            code, _, message = self.ask("TB?").split(", ", 2)
            return int(code), message

    class ScpiInstrument(VisaInstrument):
        default_terminator = "\n"
        default_timeout = 2.0
        baud_rate = 9600

        def __init__(self, name: str, address: str, **kwargs) -> None:
            super().__init__(name, address, **kwargs)
            set_baud_rate(self, self.baud_rate)

        def next_error(self) -> tuple[int, str]:
            code, message = self.ask("SYST:ERR?").split(",", 1)
            return int(code), message.strip('"')

    class GonioCamera(ScpiInstrument):
        """The SCPI CCD camera: ``roi_mean`` exposes a frame and returns its ROI mean."""

        baud_rate = BAUDRATES["camera"]

        def __init__(self, name: str, address: str, **kwargs) -> None:
            super().__init__(name, address, **kwargs)
            self.exposure = self.add_parameter("exposure", unit="s", get_cmd="EXP?", set_cmd="EXP {:.6g}",
                                               get_parser=float, vals=Numbers(1e-5, 60))
            self.gain = self.add_parameter("gain", get_cmd="GAIN?", set_cmd="GAIN {:.6g}", get_parser=float,
                                           vals=Numbers(1, 16))
            self.shutter = self.add_parameter("shutter", get_cmd="SHUT?", set_cmd="SHUT {}",
                                              val_mapping={"open": "OPEN", "closed": "CLOSE"})
            self.roi = self.add_parameter(
                "roi", get_cmd="ROI?", set_cmd="ROI {}", vals=Sequence(Ints(0), length=4),
                set_parser=lambda roi: ",".join(str(int(v)) for v in roi),
                get_parser=lambda reply: tuple(int(v) for v in reply.split(",")))
            self.roi_mean = self.add_parameter("roi_mean", unit="DN", get_cmd=self._acquire_roi_mean)

        def _acquire_roi_mean(self) -> float:
            if self.ask("ACQ;*OPC?") != "1":
                raise RuntimeError(f"{self.name}: the exposure did not complete")
            mean, _std, _count, saturated = self.ask("ROI:STAT?").split(",")
            if int(saturated):
                raise RuntimeError(f"{self.name}: {saturated} saturated pixels in the ROI")
            return float(mean)

    class GonioLamp(ScpiInstrument):
        """The SCPI lamp power supply."""

        baud_rate = BAUDRATES["lamp"]

        def __init__(self, name: str, address: str, **kwargs) -> None:
            super().__init__(name, address, **kwargs)
            self.output = self.add_parameter("output", get_cmd="OUTP?", set_cmd="OUTP {}",
                                             val_mapping=create_on_off_val_mapping("1", "0"))
            self.voltage = self.add_parameter("voltage", unit="V", get_cmd="VOLT?", set_cmd="VOLT {:.6g}",
                                              get_parser=float, vals=Numbers(0, 132))
            self.measured_voltage = self.add_parameter("measured_voltage", unit="V", get_cmd="MEAS:VOLT?",
                                                       get_parser=float)
            self.current = self.add_parameter("current", unit="A", get_cmd="MEAS:CURR?", get_parser=float)

    return SimpleNamespace(Esp300=Esp300, GonioCamera=GonioCamera, GonioLamp=GonioLamp)


def import_qcodes():
    qcodes = pytest.importorskip("qcodes", reason="qcodes is not installed (pip install '.[test]')")
    pytest.importorskip("pyvisa_py", reason="pyvisa-py is not installed (pip install '.[test]')")
    return qcodes


@pytest.fixture
def qcodes_config(tmp_path, monkeypatch):
    """QCoDeS's configuration pointed into tmp_path for the test (restored afterwards)."""
    qcodes = import_qcodes()
    monkeypatch.setitem(qcodes.config.current_config["core"], "db_location", str(tmp_path / "experiments.db"))
    monkeypatch.setitem(qcodes.config.current_config["dataset"], "export_automatic", False)
    monkeypatch.setitem(qcodes.config.current_config["dataset"], "export_path", str(tmp_path))
    monkeypatch.setenv("QCODES_USER_PATH", str(tmp_path / "qcodes-user"))
    return qcodes


@pytest.fixture
def qcodes_lab(qcodes_config):
    """``start(kind, **rig_options)`` starts a rig and returns it with ``open(cls, device)``,
    which connects a QCoDeS instrument named after the device over ``kind`` (``tcp`` or
    ``pty``). The instruments are closed (and leave QCoDeS's registry of names) before the
    rig."""
    with contextlib.ExitStack() as stack:

        def start(kind: str, **rig_options):
            rig = stack.enter_context(EmulatedRig(lambert, name=rig_name("qcodes"), **rig_options))
            addresses = rig.start(pty=kind == "pty", tcp=kind == "tcp")

            def open_(cls, device: str):
                instrument = cls(device, visa_resource(addresses[device][kind], kind), visalib="@py")
                stack.callback(instrument.close)
                return instrument

            return rig, open_

        yield start


@pytest.mark.parametrize("kind", ["tcp", "pty"])
def test_qcodes_do1d_of_the_lamp_angle_follows_cos_theta_i(qcodes_lab, tmp_path, kind):
    from qcodes.dataset import do1d, initialise_or_create_database_at, load_by_id, load_or_create_experiment

    drivers = qcodes_drivers()
    rig, open_ = qcodes_lab(kind, seed=21, lamp_warm=True)
    stage = open_(drivers.Esp300, "stage")
    camera = open_(drivers.GonioCamera, "camera")
    lamp = open_(drivers.GonioLamp, "lamp")

    assert camera.IDN() == {"vendor": "GONIO", "model": "CCD-512", "serial": "SN0001", "firmware": "1.0"}
    assert lamp.IDN() == {"vendor": "GONIO", "model": "LPS-300", "serial": "SN0001", "firmware": "1.0"}
    assert stage.IDN() == {"vendor": "Newport", "model": "ESP300", "serial": None,
                           "firmware": "3.08 09/09/02"}
    assert lamp.output() is True and lamp.voltage() == 120.0
    assert lamp.measured_voltage() == pytest.approx(120.0, rel=2e-3)

    camera.exposure(EXPOSURE_S)
    camera.gain(1)
    camera.roi(ROI)
    assert (camera.exposure(), camera.gain(), camera.roi()) == (EXPOSURE_S, 1.0, ROI)
    camera.shutter("closed")
    dark = camera.roi_mean()  # the dark offset and dark signal, measured as a client would
    camera.shutter("open")
    assert camera.shutter() == "open" and 99.0 < dark < 102.0

    for axis in (stage.axis1, stage.axis2):
        assert axis.motor() is False  # power-on state
        axis.motor(True)
    stage.axis1.position(-20.0)  # the camera on the far side of the normal: the lamp may sweep freely
    assert stage.axis1.target() == -20.0
    assert stage.axis1.position() == pytest.approx(-20.0, abs=5 * REPEATABILITY_DEG)

    initialise_or_create_database_at(tmp_path / "gonio.db")
    experiment = load_or_create_experiment("lamp sweep", sample_name="lambertian 0.8")
    angles = np.linspace(10.0, 70.0, 7)
    dataset, _, _ = do1d(stage.axis2.position, angles[0], angles[-1], len(angles), 0.0,
                         stage.axis2.encoder, stage.axis2.motion_done, camera.roi_mean,
                         exp=experiment, do_plot=False, measurement_name="theta_i sweep")

    truth = rig.control.true_state()
    data = dataset.get_parameter_data()
    setpoints = data["camera_roi_mean"]["stage_axis2_position"]
    signal = data["camera_roi_mean"]["camera_roi_mean"]
    encoder = data["stage_axis2_encoder"]["stage_axis2_encoder"]
    np.testing.assert_allclose(setpoints, angles)
    assert data["stage_axis2_motion_done"]["stage_axis2_motion_done"].tolist() == [1] * len(angles)
    np.testing.assert_allclose(encoder, angles, atol=5 * REPEATABILITY_DEG)
    assert encoder[-1] == pytest.approx(truth.positions_deg[1], abs=ENCODER_DEG / 2 + 1e-9)
    assert truth.positions_deg[0] == pytest.approx(-20.0, abs=5 * REPEATABILITY_DEG)

    # Lambertian: the signal above the dark level is rho E0 cos(theta_i) / pi, brighter at
    # smaller incidence angles, whatever the view angle.
    assert np.all(np.diff(signal) < 0)
    per_cosine = (signal - dark) / np.cos(np.radians(encoder))
    assert per_cosine.std() / per_cosine.mean() < 0.005
    expected = rig.control.expected_dn(EXPOSURE_S, gain=1.0)  # at the last point, where the stage is
    assert camera.roi_mean() == pytest.approx(expected, rel=0.01)
    assert signal[-1] == pytest.approx(expected, rel=0.01)

    # A move the camera-lamp interlock forbids (end point 0 deg from the lamp) fails loudly.
    with pytest.raises(RuntimeError, match="DIGITAL I/O INTERLOCK DETECTED"):
        stage.axis1.position(float(encoder[-1]))
    assert stage.axis1.position() == pytest.approx(-20.0, abs=5 * REPEATABILITY_DEG)

    assert camera.next_error() == (0, "No error")
    assert lamp.next_error() == (0, "No error")
    assert stage.next_error() == (0, "NO ERROR DETECTED")

    stored = load_by_id(dataset.run_id)  # the dataset is in the database under tmp_path
    stored_signal = stored.get_parameter_data("camera_roi_mean")["camera_roi_mean"]["camera_roi_mean"]
    np.testing.assert_array_equal(stored_signal, signal)
    assert stored.exp_name == "lamp sweep" and stored.sample_name == "lambertian 0.8"
    assert (tmp_path / "gonio.db").is_file()
    stored.conn.close()
    dataset.conn.close()


@pytest.mark.parametrize("clock_mode", ["wall", "event"])
def test_qcodes_lamp_warm_up_with_time_sleep(qcodes_lab, clock_mode):
    """``OUTP ON``, ``time.sleep``, ``MEAS:CURR?``: the wall clock lets the filament warm
    while the client sleeps; on the event clock the sleep does not count (docs/emulator.md)."""
    drivers = qcodes_drivers()
    rig, open_ = qcodes_lab("tcp", seed=22, clock_mode=clock_mode, speed=WALL_SPEED)
    lamp = open_(drivers.GonioLamp, "lamp")
    assert lamp.output() is False and lamp.current() == 0.0  # power-on state
    lamp.voltage(120.0)
    lamp.output(True)
    switched_on = rig.control.now()
    time.sleep(0.5)  # on the wall clock, 10 s of the lamp's time at 20 times the hardware's pace
    current = lamp.current()
    slept = rig.control.now() - switched_on
    if clock_mode == "wall":
        assert slept >= 0.5 * WALL_SPEED
        assert current == pytest.approx(HOT_CURRENT_A, rel=0.005)
        assert current == pytest.approx(rig.lamp.current(rig.control.now()), rel=0.003)
    else:
        assert slept < 0.1  # only the lines' transfer times passed
        assert current > 5 * HOT_CURRENT_A  # the cold filament's inrush
    assert lamp.output() is True
    assert lamp.next_error() == (0, "No error")


# == ophyd + bluesky ============================================================================
class PySerialLine:
    """One instrument's line on a pyserial port: a lock, and the device's terminators."""

    def __init__(self, address: str, baudrate: int, write_termination: str, read_termination: str,
                 timeout: float = 2.0) -> None:
        import serial

        self.port = serial.serial_for_url(address, baudrate=baudrate, timeout=timeout)
        self.write_termination = write_termination.encode("ascii")
        self.read_termination = read_termination.encode("ascii")
        self.lock = threading.Lock()

    def write(self, command: str) -> None:
        with self.lock:
            self.port.write(command.encode("ascii") + self.write_termination)

    def query(self, command: str) -> str:
        with self.lock:
            self.port.write(command.encode("ascii") + self.write_termination)
            reply = self.port.read_until(self.read_termination)
        if not reply.endswith(self.read_termination):
            raise TimeoutError(f"no reply to {command!r} (got {reply!r})")
        return reply[: -len(self.read_termination)].decode("ascii")

    def close(self) -> None:
        self.port.close()


@functools.cache
def ophyd_devices() -> SimpleNamespace:
    """ophyd Device classes on PySerialLine (built once ophyd is importable)."""
    from ophyd import Component as Cpt
    from ophyd import Device, DeviceStatus, Signal
    from ophyd.utils import ReadOnlyError

    class LineSignal(Signal):
        """A value on the parent's line: ``get()`` sends ``query``, ``put()`` sends ``command``
        (``{axis}`` is the parent's axis, ``{value}`` the value)."""

        def __init__(self, *, query: str, command: str | None = None, parse=float, **kwargs) -> None:
            super().__init__(**kwargs)
            self._query, self._command, self._parse = query, command, parse

        def _format(self, text: str, **fields) -> str:
            return text.format(axis=getattr(self.parent, "axis", ""), **fields)

        def get(self, **kwargs):
            value = self._parse(self.parent.line.query(self._format(self._query)))
            super().put(value, force=True)  # cache it (timestamp, subscriptions), nothing sent
            return value

        def put(self, value, **kwargs):
            if self._command is None:
                raise ReadOnlyError(f"{self.name} is read-only")
            self.parent.line.write(self._format(self._command, value=value))
            super().put(value, **kwargs)

    def poll_until(status, done, interval_s: float, then=None) -> None:
        """Complete ``status`` from a thread once ``done()`` is true, polling every interval."""

        def run():
            try:
                while not done():
                    time.sleep(interval_s)
                if then is not None:
                    then()
            except Exception as exc:  # the status carries it to the RunEngine
                status.set_exception(exc)
            else:
                status.set_finished()

        threading.Thread(target=run, daemon=True, name=f"poll-{status.device.name}").start()

    class StageAxis(Device):
        """An ESP300 axis: ``set()`` sends ``PA`` and returns a Status a thread completes when
        ``MD?`` reads 1, polled on the wall clock as a lab program polls the hardware."""

        readback = Cpt(LineSignal, query="{axis}TP?", kind="hinted")
        setpoint = Cpt(LineSignal, query="{axis}DP?", kind="normal")
        velocity = Cpt(LineSignal, query="{axis}VA?", command="{axis}VA{value}", kind="config")

        def __init__(self, *args, line: PySerialLine, axis: int, poll_s: float = 0.02, **kwargs) -> None:
            self.line, self.axis, self.poll_s = line, axis, poll_s
            super().__init__(*args, **kwargs)
            self.readback.name = self.name
            self.polls = 0

        def set(self, value, **kwargs):
            status = DeviceStatus(self)
            code, _, message = self.line.query(f"{self.axis}PA{float(value):.5f};TB?").split(", ", 2)
            if int(code):
                status.set_exception(RuntimeError(f"{self.name}: ESP300 error {code}, {message}"))
                return status

            def done() -> bool:
                self.polls += 1
                return self.line.query(f"{self.axis}MD?") == "1"

            poll_until(status, done, self.poll_s)
            return status

        def locate(self):
            return {"setpoint": self.setpoint.get(), "readback": self.readback.get()}

        @property
        def position(self) -> float:
            return self.readback.get()

        def stop(self, *, success: bool = False) -> None:
            self.line.write(f"{self.axis}ST")

    class Camera(Device):
        """The SCPI camera: ``trigger()`` sends ``ACQ;*OPC`` and returns a Status a thread
        completes when ``*ESR?`` shows OPC, after reading the ROI mean for ``read()``."""

        mean = Cpt(Signal, value=float("nan"), kind="hinted")
        exposure = Cpt(LineSignal, query="EXP?", command="EXP {value}", kind="config")
        gain = Cpt(LineSignal, query="GAIN?", command="GAIN {value}", kind="config")

        def __init__(self, *args, line: PySerialLine, poll_s: float = 0.01, **kwargs) -> None:
            self.line, self.poll_s = line, poll_s
            super().__init__(*args, **kwargs)
            self.mean.name = self.name
            self.polls = 0

        def trigger(self):
            status = DeviceStatus(self)
            self.line.write("ACQ;*OPC")

            def done() -> bool:
                self.polls += 1
                esr = int(self.line.query("*ESR?"))
                if esr & 0b111100:  # QYE, DDE, EXE, CME: a command failed
                    raise RuntimeError(f"{self.name}: {self.line.query('SYST:ERR?')}")
                return bool(esr & 1)

            def read_roi() -> None:
                mean, _std, _count, saturated = self.line.query("ROI:STAT?").split(",")
                if int(saturated):
                    raise RuntimeError(f"{self.name}: {saturated} saturated pixels in the ROI")
                self.mean.put(float(mean))

            poll_until(status, done, self.poll_s, then=read_roi)
            return status

    class LampSupply(Device):
        output = Cpt(LineSignal, query="OUTP?", command="OUTP {value}", parse=int, kind="config")
        voltage = Cpt(LineSignal, query="VOLT?", command="VOLT {value}", kind="config")
        current = Cpt(LineSignal, query="MEAS:CURR?", kind="hinted")

        def __init__(self, *args, line: PySerialLine, **kwargs) -> None:
            self.line = line
            super().__init__(*args, **kwargs)

    return SimpleNamespace(StageAxis=StageAxis, Camera=Camera, LampSupply=LampSupply)


def import_bluesky():
    pytest.importorskip("ophyd", reason="ophyd is not installed (pip install '.[test]')")
    return pytest.importorskip("bluesky", reason="bluesky is not installed (pip install '.[test]')")


@pytest.fixture
def run_engine():
    """A RunEngine on its own event loop, stopped and closed at the end (no signal handlers)."""
    import asyncio

    import_bluesky()
    from bluesky import RunEngine

    loop = asyncio.new_event_loop()
    engine = RunEngine({}, loop=loop, context_managers=[])
    yield engine
    if engine.state not in ("idle", "panicked"):
        engine.halt()
    loop.call_soon_threadsafe(loop.stop)
    engine._th.join(timeout=5)
    loop.close()


@pytest.fixture
def wall_lab(request):
    """A wall-clock rig (20 x the hardware's pace) on ptys, with ophyd devices on pyserial."""
    import_bluesky()
    lamp_warm = getattr(request, "param", True)
    devices = ophyd_devices()
    with EmulatedRig(lambert, seed=31, name=rig_name("bluesky"), clock_mode="wall", speed=WALL_SPEED,
                     lamp_warm=lamp_warm, motors_on=True) as rig:
        addresses = rig.start(pty=True)
        lines = {
            "stage": PySerialLine(addresses["stage"]["pty"], BAUDRATES["stage"], "\r", "\r\n"),
            "camera": PySerialLine(addresses["camera"]["pty"], BAUDRATES["camera"], "\n", "\n"),
            "lamp": PySerialLine(addresses["lamp"]["pty"], BAUDRATES["lamp"], "\n", "\n"),
        }
        try:
            lines["camera"].write("*RST;*CLS;ROI {},{},{},{}".format(*ROI))
            lab = SimpleNamespace(
                rig=rig, lines=lines,
                swing=devices.StageAxis(name="swing", line=lines["stage"], axis=1),
                polar=devices.StageAxis(name="polar", line=lines["stage"], axis=2),
                camera=devices.Camera(name="camera", line=lines["camera"]),
                lamp=devices.LampSupply(name="lamp", line=lines["lamp"]),
            )
            lab.camera.exposure.put(EXPOSURE_S)
            yield lab
        finally:
            for line in lines.values():
                line.close()


def collect_with_truth(rig: EmulatedRig, documents: list):
    """A RunEngine callback keeping every document and, with each event, the emulator's
    ground truth at that moment (the stage is at rest and the lamp steady between events)."""

    def callback(name, doc):
        if name == "event":
            documents.append((name, doc, rig.control.true_state(), rig.control.expected_dn(EXPOSURE_S)))
        else:
            documents.append((name, doc, None, None))

    return callback


def events(documents: list) -> list:
    return [(doc, truth, expected) for name, doc, truth, expected in documents if name == "event"]


def assert_no_errors(lab: SimpleNamespace) -> None:
    assert lab.lines["camera"].query("SYST:ERR?") == '0,"No error"'
    assert lab.lines["lamp"].query("SYST:ERR?") == '0,"No error"'
    assert lab.lines["stage"].query("TB?").endswith(", NO ERROR DETECTED")


def test_bluesky_scan_of_the_lamp_angle_polls_the_stage_and_the_camera(run_engine, wall_lab):
    import bluesky.plans as bp

    rig, polar, swing, camera = wall_lab.rig, wall_lab.polar, wall_lab.swing, wall_lab.camera
    swing.set(-20.0).wait(timeout=10)  # the camera on the far side of the normal
    assert swing.position == pytest.approx(-20.0, abs=5 * REPEATABILITY_DEG)
    documents: list = []
    started_sim, started_wall = rig.control.now(), time.monotonic()
    run_engine(bp.scan([camera], polar, 10.0, 70.0, 7), collect_with_truth(rig, documents))
    wall_s, sim_s = time.monotonic() - started_wall, rig.control.now() - started_sim

    stop = documents[-1][1]
    assert stop["exit_status"] == "success" and stop["num_events"] == {"primary": 7}
    descriptor = next(doc for name, doc, *_ in documents if name == "descriptor")
    assert descriptor["configuration"]["camera"]["data"]["camera_exposure"] == EXPOSURE_S
    scanned = events(documents)
    assert len(scanned) == 7
    angles = np.linspace(10.0, 70.0, 7)
    positions = np.array([doc["data"]["polar"] for doc, _, _ in scanned])
    signal = np.array([doc["data"]["camera"] for doc, _, _ in scanned])
    np.testing.assert_allclose([doc["data"]["polar_setpoint"] for doc, _, _ in scanned], angles)
    np.testing.assert_allclose(positions, angles, atol=5 * REPEATABILITY_DEG)
    for (doc, truth, expected) in scanned:  # the stage is where the event says, the signal as expected
        assert doc["data"]["polar"] == pytest.approx(truth.positions_deg[1], abs=ENCODER_DEG / 2 + 1e-9)
        assert truth.positions_deg[0] == pytest.approx(-20.0, abs=5 * REPEATABILITY_DEG)
        assert not any(truth.moving)
        assert doc["data"]["camera"] == pytest.approx(expected, rel=0.01)
    assert np.all(np.diff(signal) < 0)  # Lambertian: brighter at smaller incidence angles
    assert np.all(np.diff([truth.reflectance_factor for _, truth, _ in scanned]) < 0)

    # The wall clock served the polling clients: the simulated time covers every move
    # (from home, 45 deg, to 10 deg, then six 10-deg steps at VA 15 deg/s, AC 30 deg/s^2),
    # the drivers needed several polls per move and per exposure, and the wall time is modest.
    moves = move_time(35.0, 15.0, 30.0) + 6 * move_time(10.0, 15.0, 30.0)
    assert sim_s >= moves
    assert polar.polls > 2 * 7 and camera.polls >= 7
    assert wall_s < 20.0
    assert_no_errors(wall_lab)


def test_bluesky_count_and_rel_scan_of_the_camera_see_a_lambertian_sample_alike(run_engine, wall_lab):
    import bluesky.plan_stubs as bps
    import bluesky.plans as bp

    rig, polar, swing, camera = wall_lab.rig, wall_lab.polar, wall_lab.swing, wall_lab.camera

    def setup():
        yield from bps.mv(polar, 30.0, swing, -30.0)  # both axes at once

    run_engine(setup())
    truth = rig.control.true_state()
    assert truth.positions_deg[:2] == pytest.approx((-30.0, 30.0), abs=5 * REPEATABILITY_DEG)

    documents: list = []
    run_engine(bp.count([camera], num=5), collect_with_truth(rig, documents))
    counted = events(documents)
    assert [doc["seq_num"] for doc, _, _ in counted] == [1, 2, 3, 4, 5]
    repeated = np.array([doc["data"]["camera"] for doc, _, _ in counted])
    assert repeated.std() / repeated.mean() < 0.003  # shot noise over 10^4 pixels, flicker
    for doc, _, expected in counted:
        assert doc["data"]["camera"] == pytest.approx(expected, rel=0.01)

    documents = []
    run_engine(bp.rel_scan([camera], swing, -10.0, 10.0, 5), collect_with_truth(rig, documents))
    scanned = events(documents)
    assert len(scanned) == 5
    views = np.array([doc["data"]["swing"] for doc, _, _ in scanned])
    np.testing.assert_allclose(views, np.linspace(-40.0, -20.0, 5), atol=5 * REPEATABILITY_DEG)
    for doc, truth, expected in scanned:
        assert doc["data"]["swing"] == pytest.approx(truth.positions_deg[0], abs=ENCODER_DEG / 2 + 1e-9)
        assert doc["data"]["camera"] == pytest.approx(expected, rel=0.01)
    signal = np.array([doc["data"]["camera"] for doc, _, _ in scanned])
    assert np.ptp(signal) / signal.mean() < 0.01  # a Lambertian sample looks alike from every view
    assert signal.mean() == pytest.approx(repeated.mean(), rel=0.01)
    # rel_scan puts the motor back where it started.
    assert swing.setpoint.get() == -30.0
    assert rig.control.true_state().positions_deg[0] == pytest.approx(-30.0, abs=5 * REPEATABILITY_DEG)

    # A refused move (the interlock: the camera onto the lamp) fails the plan with the error.
    from bluesky.utils import FailedStatus

    with pytest.raises(FailedStatus) as failed:
        run_engine(bp.scan([camera], swing, 20.0, 30.0, 2))
    assert "ESP300 error 129, DIGITAL I/O INTERLOCK DETECTED" in str(failed.value.__cause__)
    assert rig.control.true_state().positions_deg[0] == pytest.approx(20.0, abs=5 * REPEATABILITY_DEG)
    assert_no_errors(wall_lab)


@pytest.mark.parametrize("wall_lab", [False], indirect=True, ids=["cold-lamp"])
def test_bluesky_lamp_warm_up_with_bps_sleep(run_engine, wall_lab):
    import bluesky.plan_stubs as bps

    rig, lamp = wall_lab.rig, wall_lab.lamp
    assert lamp.output.get() == 0 and lamp.current.get() == 0.0  # power-on state: off and cold
    readings = []

    def warm_up():
        yield from bps.open_run()
        yield from bps.mv(lamp.voltage, 120.0)
        yield from bps.mv(lamp.output, 1)
        yield from bps.sleep(0.5)  # 10 s of the lamp's time at 20 times the hardware's pace
        readings.append(rig.control.now() - rig.lamp.switched_at)
        yield from bps.trigger_and_read([lamp])
        yield from bps.close_run()

    documents: list = []
    run_engine(warm_up(), lambda name, doc: documents.append((name, doc)))
    (event,) = [doc for name, doc in documents if name == "event"]
    current = event["data"]["lamp_current"]
    assert readings[0] >= 0.5 * WALL_SPEED
    assert current == pytest.approx(HOT_CURRENT_A, rel=0.005)
    assert current == pytest.approx(rig.lamp.current(rig.control.now()), rel=0.003)
    assert wall_lab.lines["lamp"].query("OUTP?;:STAT:LAMP?") == "1;OK"
    assert_no_errors(wall_lab)
