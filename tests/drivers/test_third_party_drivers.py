"""The emulator driven by unmodified third-party lab software, over a pty and over TCP.

Clients (the ``test`` extra installs them; each test skips with the reason when its client
is missing, and ``make test`` from a fresh clone installs them all):

- pymeasure 0.16: ``pymeasure.instruments.newport.ESP300`` and a generic
  ``SCPIMixin`` instrument for the camera and the lamp;
- pyvisa 1.16 with the pyvisa-py 0.8 backend: ``ASRL<pty>::INSTR`` and
  ``TCPIP::127.0.0.1::<port>::SOCKET`` resources, ``query_binary_values`` on ``FRAME?``;
- InstrumentKit 0.6: ``instruments.newport.NewportESP301``.  Its 0.6 release pins
  ``ruamel.yaml~=0.15.37``, which does not build on Python 3.11; its Newport driver does
  not use YAML (only ``instruments.config`` imports ``ruamel.yaml``, and any version
  imports), so the Makefile installs it with ``pip install --no-deps instrumentkit==0.6.0``
  and the ``test`` extra lists the dependencies it really needs (quantities, future,
  pyusb, python-usbtmc, python-vxi11, ruamel.yaml).

Every feature the stock drivers offer is exercised, InstrumentKit's motor and servo setup
(``setup_axis``/``read_setup``), stored programs, ``move_to_hardware_limit`` and
``move_indefinitely`` included; docs/protocol.md lists the manual commands not emulated.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from client_addresses import tcp_port, visa_resource

from drivers.emulator.rig import EmulatedRig

TRANSPORTS = ["pty", "tcp"]


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


@pytest.fixture(scope="module")
def lab():
    with EmulatedRig(lambert, seed=11, name="third-party", lamp_warm=True) as rig:
        addresses = rig.start(pty=True, tcp=True)
        yield rig, addresses


def serial_port(address: str, baudrate: int, timeout: float):
    import serial

    return serial.serial_for_url(address, baudrate=baudrate, timeout=timeout)


# -- pymeasure: Newport ESP300 ------------------------------------------------------------------
@pytest.fixture
def pymeasure_esp300(lab, request):
    pytest.importorskip("pymeasure", reason="pymeasure is not installed (pip install '.[test]')")
    from pymeasure.adapters import SerialAdapter
    from pymeasure.instruments.newport import ESP300

    rig, addresses = lab
    rig.channels["stage"].process("RS")  # power-on state for each test
    port = serial_port(addresses["stage"][request.param], 19200, timeout=0.2)
    adapter = SerialAdapter(port, write_termination="\r", read_termination="\r\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # "not known whether this device supports SCPI"
        controller = ESP300(adapter)
    yield rig, controller
    adapter.close()


@pytest.mark.parametrize("pymeasure_esp300", TRANSPORTS, indirect=True)
def test_pymeasure_esp300_axes(pymeasure_esp300):
    rig, esp = pymeasure_esp300
    x = esp.x
    assert not x.enabled
    x.enable()
    assert x.enabled and x.units == "degree"
    x.left_limit, x.right_limit = -60.0, 60.0
    assert (x.left_limit, x.right_limit) == (-60.0, 60.0)
    x.position = 25.0
    x.wait_for_stop()
    assert x.motion_done and x.position == pytest.approx(25.0, abs=0.01)
    x.define_position(3.0)  # DH3: the current position becomes 3
    assert x.position == pytest.approx(3.0, abs=1e-9)
    x.zero()  # DH
    assert x.position == pytest.approx(0.0, abs=1e-9)
    x.home(type=1)  # OR1: the home switch reads the DH value, 0
    x.wait_for_stop()
    assert x.position == pytest.approx(0.0, abs=0.01)
    assert rig.control.true_state().positions_deg[0] == pytest.approx(0.0, abs=0.01)
    x.position = 100.0  # beyond SR = 60: refused, positive software limit
    assert [str(e) for e in esp.errors] == ["Newport ESP300 axis 1 reported the error: POSITIVE SOFTWARE LIMIT DETECTED"]
    x.units = "radian"
    assert x.units == "radian"
    x.units = "millimeter"  # a linear unit on a rotary stage: refused by the controller (x01)
    assert x.units == "radian"
    assert [str(e) for e in esp.errors] == ["Newport ESP300 axis 1 reported the error: PARAMETER OUT OF RANGE"]
    x.units = "degree"
    x.disable()
    assert not x.enabled


@pytest.mark.parametrize("pymeasure_esp300", TRANSPORTS, indirect=True)
def test_pymeasure_esp300_controller_level_calls_meet_the_real_esp300_behaviour(pymeasure_esp300):
    """``axes`` reads every SCPI-mixin property: four queries a real ESP300 does not answer."""
    rig, esp = pymeasure_esp300
    esp.clear_errors()
    esp.enable()
    assert [a.enabled for a in (esp.x, esp.y, esp.phi)] == [True, True, True]
    assert [str(e) for e in esp.errors] == ["Newport ESP300 reported the error: COMMAND DOES NOT EXIST"] * 4
    esp.disable()
    assert [a.enabled for a in (esp.x, esp.y, esp.phi)] == [False, False, False]
    esp.clear_errors()
    assert esp.error == 0


# -- pyvisa + pyvisa-py ---------------------------------------------------------------------------
@pytest.fixture
def visa_camera(lab, request):
    pyvisa = pytest.importorskip("pyvisa", reason="pyvisa is not installed (pip install '.[test]')")
    pytest.importorskip("pyvisa_py", reason="pyvisa-py is not installed (pip install '.[test]')")
    rig, addresses = lab
    manager = pyvisa.ResourceManager("@py")
    options = {"baud_rate": 115200} if request.param == "pty" else {}
    camera = manager.open_resource(visa_resource(addresses["camera"][request.param], request.param),
                                   read_termination="\n", write_termination="\n", timeout=2000, **options)
    camera.write("*RST;*CLS")
    yield rig, camera
    camera.close()
    manager.close()


@pytest.mark.parametrize("visa_camera", TRANSPORTS, indirect=True)
def test_pyvisa_camera_frame_status_and_errors(visa_camera):
    rig, camera = visa_camera
    assert camera.query("*IDN?") == "GONIO,CCD-512,SN0001,1.0"
    camera.write("EXPosure 0.02;:GAIN 2;ROI 206,190,100,100")
    assert camera.query("exp?;GAIN?;ROI?") == "0.02;2;206,190,100,100"
    camera.write("*ESE 1;*SRE 32;ACQ;*OPC")
    assert camera.query("*OPC?") == "1"
    assert int(camera.query("*STB?")) & 0b1100000 == 0b1100000  # ESB and MSS: OPC set by the exposure
    roi = camera.query_binary_values("ROI:DATA?", datatype="H", is_big_endian=False, container=np.array)
    window = roi.reshape(100, 100)
    mean, std, n, saturated = camera.query("ROI:STAT?").split(",")
    assert float(mean) == pytest.approx(window.mean(), abs=1e-3) and int(n) == 10000
    if camera.resource_name.startswith("TCPIP"):  # the 491 kB frame takes seconds through pyvisa-py's ASRL
        frame = camera.query_binary_values("FRAME?", datatype="H", is_big_endian=False, container=np.array)
        np.testing.assert_array_equal(frame.reshape(480, 512)[190:290, 206:306], window)
    camera.write("EXP 100")
    assert camera.query("SYST:ERR?") == '-222,"Data out of range;EXP must be within 1e-05..60, got 100"'
    assert camera.query("*ESR?") == "17"  # EXE, and OPC of the exposure (read once, then cleared)
    assert camera.query("*ESR?") == "0"
    assert camera.query("SYST:VERS?;:STAT:OPER:COND?;:STAT:QUES:COND?") == "1999.0;0;0"


@pytest.mark.parametrize("kind", TRANSPORTS)
def test_pyvisa_stage_moves_and_errors(lab, kind):
    pyvisa = pytest.importorskip("pyvisa", reason="pyvisa is not installed (pip install '.[test]')")
    pytest.importorskip("pyvisa_py", reason="pyvisa-py is not installed (pip install '.[test]')")
    rig, addresses = lab
    manager = pyvisa.ResourceManager("@py")
    options = {"baud_rate": 19200} if kind == "pty" else {}
    stage = manager.open_resource(visa_resource(addresses["stage"][kind], kind), read_termination="\r\n",
                                  write_termination="\r", timeout=500, **options)
    try:
        stage.write("RS;2MO;2PA30;2WS")
        assert float(stage.query("2TP")) == pytest.approx(30.0, abs=0.01)
        assert stage.query("2MD?;2DP?") == "1"  # one reply line per query: read the second
        assert stage.read() == "30.00000"
        stage.write("*IDN?")  # not an ESP300 command: no reply (a real ESP300 answers nothing either)
        with pytest.raises(pyvisa.errors.VisaIOError):
            stage.read()
        assert stage.query("TB?").startswith("6, ")
        assert stage.query("VE?") == "ESP300 Version 3.08 09/09/02"
    finally:
        stage.close()
        manager.close()


# -- pymeasure generic SCPI instrument ---------------------------------------------------------
@pytest.mark.parametrize("kind", TRANSPORTS)
@pytest.mark.parametrize("device, baudrate, identity", [("camera", 115200, "GONIO,CCD-512,SN0001,1.0"),
                                                        ("lamp", 9600, "GONIO,LPS-300,SN0001,1.0")])
def test_pymeasure_scpi_mixin_on_the_scpi_instruments(lab, kind, device, baudrate, identity):
    pytest.importorskip("pymeasure", reason="pymeasure is not installed (pip install '.[test]')")
    from pymeasure.adapters import SerialAdapter
    from pymeasure.instruments import Instrument, SCPIMixin

    class Generic(SCPIMixin, Instrument):
        pass

    rig, addresses = lab
    adapter = SerialAdapter(serial_port(addresses[device][kind], baudrate, timeout=1.0),
                            write_termination="\n", read_termination="\n")
    instrument = Generic(adapter, name=device)
    try:
        instrument.clear()
        instrument.reset()
        assert instrument.id == identity
        assert instrument.complete == "1"
        assert instrument.status == "0"
        assert instrument.options == ("MON" if device == "camera" else "0")
        instrument.write("FOO")
        assert instrument.status == "4"  # error queue not empty
        assert instrument.check_errors() == [[-113, '"Undefined header;FOO"']]  # pymeasure keeps the quotes
        assert instrument.next_error == [0, '"No error"']
    finally:
        adapter.close()


# -- InstrumentKit: Newport ESP301 --------------------------------------------------------------
@pytest.fixture
def instrumentkit_esp(lab, request):
    ik = pytest.importorskip("instruments", reason="InstrumentKit is not installed: pip install --no-deps "
                             "instrumentkit==0.6.0 (see the Makefile; its ruamel.yaml pin does not build on 3.11)")
    rig, addresses = lab
    rig.stage.saved.clear()  # factory settings (an earlier test may have saved others with SM)
    rig.stage.programs.clear()
    rig.channels["stage"].process("RS")
    address = addresses["stage"][request.param]
    if request.param == "pty":
        controller = ik.newport.NewportESP301.open_serial(address, baud=19200, timeout=2)
    else:
        controller = ik.newport.NewportESP301.open_tcpip("127.0.0.1", tcp_port(address))
    yield rig, ik, controller


@pytest.mark.parametrize("instrumentkit_esp", TRANSPORTS, indirect=True)
def test_instrumentkit_esp301_motion(instrumentkit_esp):
    rig, ik, esp = instrumentkit_esp
    axis = esp.axis[0]
    assert str(axis.units.dimensionality) == "deg"
    axis.enable()
    axis.velocity, axis.acceleration, axis.deceleration = 15.0, 40.0, 30.0
    assert [float(v) for v in (axis.velocity, axis.acceleration, axis.deceleration)] == [15.0, 40.0, 30.0]
    assert float(axis.max_velocity) == 20.0 and float(axis.max_acceleration) == 80.0
    axis.estop_deceleration = 60.0
    assert float(axis.estop_deceleration) == 60.0
    axis.left_limit, axis.right_limit = -70.0, 70.0
    assert (float(axis.left_limit), float(axis.right_limit)) == (-70.0, 70.0)
    assert float(axis.encoder_resolution) == 0.001
    axis.move(20.0, absolute=True, wait=True, block=True)  # PA, WP, then MD? polling
    assert axis.is_motion_done and float(axis.position) == pytest.approx(20.0, abs=0.01)
    assert float(axis.desired_position) == 20.0
    axis.move(-5.0, absolute=False)
    axis.wait_for_stop()
    assert float(axis.position) == pytest.approx(15.0, abs=0.01)
    axis.home = 0.0  # DH0
    assert float(axis.home) == 0.0 and float(axis.position) == pytest.approx(0.0, abs=1e-9)
    esp.search_for_home(axis=1)  # OR0: the +0 count, here where DH0 put it
    axis.wait_for_stop()
    assert rig.control.true_state().positions_deg[0] == pytest.approx(15.0, abs=0.01)
    esp.search_for_home(axis=1, search_mode=ik.newport.NewportESP301HomeSearchMode.home_index_signals.value)
    axis.wait_for_stop()  # OR1: the home switch and index, which now reads the DH value 0
    assert rig.control.true_state().positions_deg[0] == pytest.approx(0.0, abs=1e-9)
    assert float(axis.position) == 0.0
    with esp.execute_bulk_command():  # ';'-joined on one line
        axis.move(10.0)
        axis.wait_for_stop()
    assert float(axis.position) == pytest.approx(10.0, abs=0.01)
    axis.move(50.0)
    axis.stop_motion()
    axis.wait_for_stop()
    axis.move(-50.0)
    axis.abort_motion()  # AB: e-stop, motors off
    axis.wait_for_stop()
    with pytest.raises(ik.newport.NewportError, match="MOTOR NOT ENABLED"):
        axis.move(0.0)
    axis.max_velocity = 12.0
    assert float(axis.velocity) == 12.0  # lowered to VU
    with pytest.raises(ik.newport.NewportError, match="MAXIMUM VELOCITY EXCEEDED"):
        axis.velocity = 13.0
    axis.disable()
    esp.reset()
    assert float(esp.axis[0].max_velocity) == 20.0


@pytest.mark.parametrize("instrumentkit_esp", ["pty"], indirect=True)
def test_instrumentkit_relative_move_with_wait_hangs_as_on_the_hardware(instrumentkit_esp):
    """``move(-5, absolute=False, wait=True)`` sends ``PR-5`` then ``WP-5``: a wait for the
    absolute position -5, which an axis going from -20 to -25 never passes. A real ESP301
    waits for ever; the emulator holds the controller the same way, so the client meets its
    read timeout, and the controller answers again after a power cycle."""
    rig, ik, esp = instrumentkit_esp
    axis = esp.axis[0]
    axis.enable()
    axis.move(-20.0, absolute=True, wait=True)
    with pytest.raises(OSError, match="timed out"):
        axis.move(-5.0, absolute=False, wait=True)
    assert rig.stage.waiting_for == (1, -5.0)
    rig.control.advance(5.0)  # the event clock: the client's timeout did not count
    rig.control.power_cycle_stage()
    assert rig.stage.waiting_for is None
    assert float(axis.position) == pytest.approx(-25.0, abs=0.01)


@pytest.mark.parametrize("instrumentkit_esp", TRANSPORTS, indirect=True)
def test_instrumentkit_esp301_status_and_units(instrumentkit_esp):
    rig, ik, esp = instrumentkit_esp
    from instruments.newport.newportesp301 import NewportESP301Units

    axis = esp.axis[2]
    axis.enable()
    axis.move(0.0, wait=True, block=True)
    status = axis.get_status()
    assert status["is_motion_done"] and float(status["position"]) == pytest.approx(0.0, abs=0.01)
    assert float(status["desired_position"]) == 0.0
    axis.units = NewportESP301Units.radian
    assert str(axis.units.dimensionality) == "rad"
    axis.enable()
    axis.move(0.5, wait=True, block=True)
    assert rig.control.true_state().positions_deg[2] == pytest.approx(np.degrees(0.5), abs=0.01)
    assert float(axis.encoder_position) == pytest.approx(np.degrees(0.5) * 1000, abs=10)  # in counts (SN0)
    with pytest.raises(ik.newport.NewportError, match=r"Error: 1\. Axis: 3\."):  # x01, 301
        axis.units = NewportESP301Units.millimeter
    axis.units = NewportESP301Units.degree
    assert float(axis.desired_velocity) == float(axis.desired_position)  # InstrumentKit 0.6 reads DP? for it


@pytest.mark.parametrize("instrumentkit_esp", TRANSPORTS, indirect=True)
def test_instrumentkit_esp301_hardware_limit_and_jog(instrumentkit_esp):
    rig, ik, esp = instrumentkit_esp
    axis = esp.axis[0]
    axis.enable()
    axis.move_to_hardware_limit()  # MT (no direction: +) past SR = 90 onto the limit switch
    axis.wait_for_stop()
    assert float(axis.position) == pytest.approx(95.0, abs=1e-9)
    assert rig.control.true_state().positions_deg[0] == pytest.approx(95.0, abs=1e-9)
    axis.move(0.0)
    axis.wait_for_stop()
    axis.move_indefinitely()  # MV (+): runs until stopped
    assert not axis.is_motion_done
    axis.stop_motion()
    axis.wait_for_stop()
    stopped = float(axis.position)
    assert 0.0 < stopped < 90.0 and axis.is_motion_done
    axis.move_indefinitely()
    with pytest.raises(ik.newport.NewportError, match=r"Error: 6\. Axis: 1\."):
        axis.wait_for_stop()  # not stopped: it runs into the software limit SR = 90 (106)
    assert float(axis.position) == pytest.approx(90.0, abs=1e-9)
    with pytest.raises(ik.newport.NewportError, match=r"Error: 6\. Axis: 1\."):
        axis.move_indefinitely()  # already at the limit: 106


@pytest.mark.parametrize("instrumentkit_esp", TRANSPORTS, indirect=True)
def test_instrumentkit_esp301_setup_axis_and_read_setup(instrumentkit_esp):
    rig, ik, esp = instrumentkit_esp
    axis = esp.axis[1]
    setup = dict(motor_type=1, feedback_configuration=110, full_step_resolution=0.002,
                 position_display_resolution=4, current=1.5, voltage=30.0, units=7,
                 encoder_resolution=0.001, max_acceleration=100.0, max_velocity=25.0,
                 max_base_velocity=2.0, homing_velocity=12.0, jog_high_velocity=20.0,
                 jog_low_velocity=3.0, acceleration=50.0, velocity=18.0, deceleration=40.0,
                 estop_deceleration=90.0, jerk=500.0, error_threshold=0.5, proportional_gain=0.25,
                 derivative_gain=0.125, integral_gain=0.0625, integral_saturation_gain=0.75,
                 home=45.0, microstep_factor=20, acceleration_feed_forward=0.5, trajectory=1,
                 hardware_limit_configuration=24, reduce_motor_torque_time=500,
                 reduce_motor_torque_percentage=50)
    config = axis.setup_axis(**setup)  # every setting, then QR, UF, QD, SM and read_setup
    expected = {key: value for key, value in setup.items() if key in config}
    expected["feedback_configuration"] = 0x11  # "110H": InstrumentKit 0.6 drops the last hex digit
    expected["hardware_limit_configuration"] = 2  # "24H" read as decimal without its last digit
    assert str(config.pop("units").dimensionality) == "deg"
    del expected["units"]
    assert {key: float(value) for key, value in config.items()} == pytest.approx(expected)
    assert esp.query("2ZB?").strip() == "110H" and esp.query("2ZH?").strip() == "24H"
    assert esp.query("2QR?").strip() == "500, 50" and float(axis.error_threshold) == 0.5
    esp.reset()  # RS loads the settings saved by SM
    assert float(axis.jerk) == 500.0 and float(axis.max_velocity) == 25.0
    assert float(axis.proportional_gain) == 0.25
    with pytest.raises(ik.newport.NewportError, match="MAXIMUM VELOCITY EXCEEDED"):
        axis.jog_high_velocity = 26.0  # above VU
    with pytest.raises(ik.newport.NewportError, match=r"Error: 1\. Axis: 2\."):
        axis.motor_type = 2  # a stepper motor on the DC-servo stage: 201
    axis.motor_type = 0  # undefined: no move
    axis.enable()
    with pytest.raises(ik.newport.NewportError, match=r"Error: 0\. Axis: 2\."):  # 200 MOTOR TYPE NOT DEFINED
        axis.move(30.0)
    assert float(axis.max_deceleration) == 100.0  # InstrumentKit reads AU? for it


@pytest.mark.parametrize("instrumentkit_esp", TRANSPORTS, indirect=True)
def test_instrumentkit_esp301_stored_programs(instrumentkit_esp):
    rig, ik, esp = instrumentkit_esp
    axis = esp.axis[0]
    axis.enable()
    axis.move(0.0, wait=True, block=True)
    with esp.execute_bulk_command():  # XX, EP, the moves and QP on one line: stored, not run
        with esp.define_program(15):
            axis.move(12.0)
            axis.wait_for_stop()
            axis.move(-3.0, absolute=False)
    assert float(axis.position) == pytest.approx(0.0, abs=0.01)
    esp.run_program(15)  # EX
    axis.wait_for_stop()
    assert float(axis.position) == pytest.approx(9.0, abs=0.01)
    with pytest.raises(ik.newport.NewportError, match="COMMAND NOT ALLOWED"):
        esp.run_program(16)  # no such program: 27
    with pytest.raises(ValueError):
        esp.run_program(101)  # refused by the driver itself
    # Alone, define_program asks TB? after EP; in program entry mode the controller stores
    # that query as program text and does not answer (manual p. 3-3): the driver times out.
    connection = esp._file._conn  # InstrumentKit 0.6's timeout setter fails on a socket
    connection.settimeout(0.3) if hasattr(connection, "settimeout") else setattr(connection, "timeout", 0.3)
    with pytest.raises((IOError, OSError)):
        with esp.define_program(20):
            axis.move(1.0)
    esp.sendcmd("QP")
    assert esp.query("20LP").strip() == "TB?"
