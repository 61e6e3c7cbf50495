"""The emulator's clock as lab software meets it: polling and sleeping clients in each mode.

A client of ``gonio emulator`` that waits on its own clock instead of on the rig (polls
``MD?`` until a move is done, polls ``*ESR?`` until an exposure has completed, sleeps
through the lamp's warm-up) sees the instrument at the hardware's pace only if simulated
time follows the wall clock. This script starts ``gonio emulator --clock MODE --speed K``
in its own process, as lab software meets it (pseudo-terminals, pyserial, 50-ms polls),
and measures for each clock:

* ``move``: a 10-deg move of axis 1 at the controller's default 10 deg/s and 20 deg/s^2
  (1.5 s of motion on the hardware), polled with ``1MD?`` every 50 ms: the wall time from
  the ``PA`` to the first ``1`` reply;
* ``exposure``: ``EXP 0.5;ACQ;*OPC`` (0.5 s exposure + 50 ms read-out), polled with
  ``*ESR?`` every 50 ms until the operation-complete bit: the wall time;
* ``warm_up``: ``VOLT 100;OUTP ON``, ``time.sleep(5 / K)`` (5 s of the hardware's time at
  speed K), ``MEAS:CURR?`` against the hot filament's current (read after 10 s more,
  stepped through the control channel): 1 when the filament has heated, several times
  more while the cold filament's inrush still flows.

Each time is given as a ratio to the hardware's time divided by the speed (1 = the
hardware's pace at that speed; the target of docs/emulator.md is at most 1.2 at speed 1
and proportionally less wall time at higher speeds). The ``event`` clock is the
reference measured in the same run: time passes there only with the instruments' events,
so a poll advances it by one line's transfer time and a sleep not at all.

Writes docs/benchmarks/clock.json and clock.png. Run: ``python benchmarks/bench_clock.py``
(about 2 minutes, most of it the event clock's slow polls).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time

import serial

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "tests" / "drivers"))
from _common import OUT, ROOT, machine, write_json  # noqa: E402
from emulator_process import banner  # noqa: E402

POLL_S = 0.05
MOVE_HARDWARE_S = 10 / 10 + 10 / 20  # distance / velocity + velocity / acceleration
EXPOSURE_HARDWARE_S = 0.5 + 0.05  # exposure + read-out
WARM_UP_HARDWARE_S = 5.0
#: Give up on a polled wait after this many wall seconds (the event clock's exposure takes ~40 s).
GIVE_UP_S = 120.0
CLOCKS = [("event", 1.0), ("wall", 1.0), ("wall", 2.0), ("wall", 5.0), ("wall", 10.0), ("realtime", 1.0)]


class Emulator:
    """``gonio emulator`` in its own process, with its ptys and control port open."""

    def __init__(self, mode: str, speed: float) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "gonio", "emulator", "--sample", "lambert:rho=0.5", "--clock", mode,
             "--speed", str(speed), "--control", "0"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        lines = banner(self.process, timeout=60)
        fields = {tuple(line.split()[:2]): line.split()[2] for line in lines if len(line.split()) > 2}
        if ("control", "tcp") not in fields:
            self.close()
            raise RuntimeError(f"gonio emulator did not start: {''.join(lines)}")
        self.ports = {device: fields[(device, "pty")] for device in ("stage", "camera", "lamp")}
        host, port = fields[("control", "tcp")].rsplit(":", 1)
        import socket

        self._control = socket.create_connection((host, int(port)), timeout=60).makefile("rwb")

    def control(self, op: str, **args) -> object:
        import json

        self._control.write(json.dumps({"op": op, "args": args}).encode() + b"\n")
        self._control.flush()
        reply = json.loads(self._control.readline())
        if not reply["ok"]:
            raise RuntimeError(reply["error"])
        return reply["result"]

    def port(self, device: str) -> serial.Serial:
        rates = {"stage": 19200, "camera": 115200, "lamp": 9600}
        return serial.Serial(self.ports[device], rates[device], timeout=5)

    def close(self) -> None:
        if getattr(self, "_control", None) is not None:
            self._control.close()
        self.process.terminate()
        self.process.communicate(timeout=60)


def query(port: serial.Serial, text: str, terminator: bytes = b"\n") -> bytes:
    port.write(text.encode() + terminator)
    return port.readline().strip()


def polled_move(emulator: Emulator) -> dict:
    """Wall time of a polled 10-deg move [s] and the polls it took."""
    with emulator.port("stage") as stage:
        stage.write(b"1MO;1PA0;1WS\r")
        query(stage, "1TP?", b"\r")
        start, polls = time.monotonic(), 0
        stage.write(b"1PA10\r")
        while query(stage, "1MD?", b"\r") != b"1":
            polls += 1
            if time.monotonic() - start > GIVE_UP_S:
                return {"wall_s": float("nan"), "polls": polls, "gave_up": True}
            time.sleep(POLL_S)
        return {"wall_s": time.monotonic() - start, "polls": polls, "gave_up": False}


def polled_exposure(emulator: Emulator) -> dict:
    """Wall time of a polled 0.5-s exposure [s] and the polls it took."""
    with emulator.port("camera") as camera:
        query(camera, "*CLS;*OPC?")
        start, polls = time.monotonic(), 0
        camera.write(b"EXP 0.5;ACQ;*OPC\n")
        while not int(query(camera, "*ESR?")) & 1:
            polls += 1
            if time.monotonic() - start > GIVE_UP_S:
                return {"wall_s": float("nan"), "polls": polls, "gave_up": True}
            time.sleep(POLL_S)
        return {"wall_s": time.monotonic() - start, "polls": polls, "gave_up": False}


def sleeping_warm_up(emulator: Emulator, speed: float) -> dict:
    """Lamp current after a warm-up spent in ``time.sleep`` against the warm lamp's [-]."""
    with emulator.port("lamp") as lamp:
        query(lamp, "OUTP OFF;*OPC?")
        query(lamp, "VOLT 100;OUTP ON;*OPC?")  # the inrush of a cold filament
        before = emulator.control("now")
        time.sleep(WARM_UP_HARDWARE_S / speed)
        current = float(query(lamp, "MEAS:CURR?"))
        simulated = emulator.control("now") - before
        emulator.control("advance", seconds=10.0)  # 70 filament time constants: hot
        warm = float(query(lamp, "MEAS:CURR?"))
        return {"current_ratio": current / warm, "simulated_s": simulated}


def measure(mode: str, speed: float, repeats: int) -> dict:
    emulator = Emulator(mode, speed)
    try:
        runs = {"move": [], "exposure": [], "warm_up": []}
        for _ in range(1 if mode == "event" else repeats):
            runs["move"].append(polled_move(emulator))
            runs["exposure"].append(polled_exposure(emulator))
            runs["warm_up"].append(sleeping_warm_up(emulator, speed))
    finally:
        emulator.close()
    hardware = {"move": MOVE_HARDWARE_S / speed, "exposure": EXPOSURE_HARDWARE_S / speed}
    summary = {"mode": mode, "speed": speed, "runs": runs}
    for case, pace in hardware.items():
        walls = [run["wall_s"] for run in runs[case]]
        summary[f"{case}_wall_s"] = walls
        summary[f"{case}_ratio_to_hardware_pace"] = [wall / pace for wall in walls]
    summary["warm_up_current_ratio"] = [run["current_ratio"] for run in runs["warm_up"]]
    return summary


def chart(results: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [f"{r['mode']}\nx{r['speed']:g}" for r in results]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    width = 0.38
    for k, case in enumerate(("move", "exposure")):
        worst = [max(r[f"{case}_ratio_to_hardware_pace"]) for r in results]
        left.bar([i + (k - 0.5) * width for i in range(len(results))], worst, width,
                 label=f"polled {case} ({'1.5 s' if case == 'move' else '0.55 s'} on the hardware)")
    left.axhline(1.2, color="k", ls="--", lw=1, label="target 1.2")
    left.set_yscale("log")
    left.set_xticks(range(len(results)), labels)
    left.set_ylabel("wall time / (hardware time / speed), worst run")
    left.set_title("Polling clients (50-ms polls over a pty)")
    left.legend(fontsize=8)
    right.bar(labels, [max(r["warm_up_current_ratio"]) for r in results], color="tab:red")
    right.axhline(1.0, color="k", ls="--", lw=1)
    right.set_ylabel("lamp current after a sleep / warm current")
    right.set_title("A warm-up spent in time.sleep (5 s of hardware time)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs per wall/realtime clock (default 3)")
    args = parser.parse_args(argv)
    results = []
    for mode, speed in CLOCKS:
        print(f"clock {mode} x{speed:g} ...", flush=True)
        result = measure(mode, speed, args.repeats)
        print(f"  move {result['move_ratio_to_hardware_pace']}, exposure {result['exposure_ratio_to_hardware_pace']}, "
              f"warm-up current {result['warm_up_current_ratio']}", flush=True)
        results.append(result)
    payload = {
        "description": __doc__.split("\n\n")[0],
        "command": "python benchmarks/bench_clock.py",
        "machine": machine(),
        "poll_s": POLL_S,
        "hardware_s": {"move": MOVE_HARDWARE_S, "exposure": EXPOSURE_HARDWARE_S, "warm_up": WARM_UP_HARDWARE_S},
        "results": results,
    }
    print(write_json("clock", payload))
    chart(results, OUT / "clock.png")


if __name__ == "__main__":
    main()
