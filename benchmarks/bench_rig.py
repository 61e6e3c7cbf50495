"""Speed and accuracy of the drivers on the emulated rig.

Measures, in one run, over the in-process pyserial URL (``gonio-sim://``), real
pseudo-terminals and TCP on the loopback interface (``socket://``):

- query round trips per second (camera ``EXP?``, stage ``1TP``);
- a command without a reply followed by a query (``EXP 0.001`` then ``SYST:ERR?``) from a
  plain pyserial client that sets no socket option (the exchange Nagle's algorithm and
  delayed ACKs stall on TCP unless the emulator acknowledges at once);
- ROI measurements per second (``ACQ`` + ``ROI:STAT?`` at a fixed 1 ms exposure) and
  full :meth:`drivers.rig.Rig.measure` calls per second (automatic exposure, dark model,
  lamp readings);
- the wall time of a 200-geometry sweep with the event clock next to the simulated instrument
  time it represents (moves, exposures, line transfers);

and the accuracy of the sweep: a Lambertian sample must read the same radiance at every
geometry up to cos(theta_i); ``relative_error`` is the rms relative deviation of
``radiance / cos(theta_i)`` from its mean (lamp drift and flicker, ~0.1 %).

The TCP figures are reported as ratios to the pty figures of the same run
(``tcp_over_pty``; target: within 1.3).

Writes docs/benchmarks/rig.json and docs/benchmarks/rig.png. Run:
``python benchmarks/bench_rig.py``.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import serial

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivers.emulator.rig import EmulatedRig  # noqa: E402
from drivers.rig import Rig  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from _common import OUT, machine  # noqa: E402


def lambert(ti, pi, tr, pr):
    return np.full(np.broadcast(ti, pi, tr, pr).shape, 0.8 / np.pi)


def rate(fn, n):
    """Seconds per call of ``fn`` over ``n`` calls (after one warm-up call)."""
    fn()
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - start) / n


def sweep_geometries(n=200):
    """``n`` in-plane and out-of-plane geometries, away from the retro-reflection gap."""
    rng = np.random.default_rng(0)
    out = []
    while len(out) < n:
        ti = float(rng.choice([0.0, 15.0, 30.0, 45.0, 60.0, 75.0]))
        pi = float(rng.choice([0.0, 0.0, 45.0, 90.0]))
        view = float(rng.integers(-80, 81))
        out.append((ti, pi, view))
    return out


LABELS = {"url": "in-process URL", "pty": "pty", "tcp": "TCP"}


def plain_client_pair(address, n=200):
    """Seconds per ``EXP 0.001`` + ``SYST:ERR?`` exchange of a plain pyserial client (no socket options)."""
    port = serial.serial_for_url(address, baudrate=115200, timeout=5.0)
    try:
        def pair():
            port.write(b"EXP 0.001\n")
            port.write(b"SYST:ERR?\n")
            if not port.readline().startswith(b"0,"):
                raise RuntimeError(f"{address}: unexpected error queue entry")
        return rate(pair, n)
    finally:
        port.close()


def bench_transport(kind, emu, addresses, records, extra):
    stage_url = addresses["stage"][kind]
    camera_url = addresses["camera"][kind]
    lamp_url = addresses["lamp"][kind]
    with Rig.open(stage_url, camera_url, lamp_url, timeout=5.0) as rig:
        rig.lamp_on(120.0)
        rig.calibrate_dark((0.001, 0.01, 0.1))
        rig.move_to(30.0, 0.0, -20.0)
        label = LABELS[kind]
        t_cam = rate(lambda: rig.camera.query("EXP?", float), 300)
        t_stage = rate(lambda: rig.stage.position(1), 300)
        rig.camera.set_exposure(0.001)
        rig._exposure = 0.001

        def roi_measurement():
            rig.camera.acquire()
            rig.camera.roi_stats()

        t_roi = rate(roi_measurement, 40)
        t_measure = rate(lambda: rig.measure(), 40)
        for family, method, seconds, notes in [
            ("query round trip", f"camera EXP? ({label})", t_cam, "115200 baud line; event clock"),
            ("query round trip", f"stage 1TP ({label})", t_stage, "19200 baud line; event clock"),
            ("ROI measurement", f"ACQ + ROI:STAT? ({label})", t_roi, "1 ms exposure; the emulator renders a full 512x480 frame per ACQ"),
            ("ROI measurement", f"Rig.measure ({label})", t_measure, "auto exposure, dark model, lamp V/I readings"),
        ]:
            records.append({
                "family": family, "method": method, "seconds_per_evaluation": seconds,
                "relative_error": 0.0, "reference_method": {"url": "", "pty": "in-process URL", "tcp": "pty"}[kind],
                "notes": notes + " (speed only: relative_error not applicable, 0)",
            })
        extra[kind] = {
            "commands_per_second_camera": 1.0 / t_cam,
            "commands_per_second_stage": 1.0 / t_stage,
            "roi_measurements_per_second": 1.0 / t_roi,
            "rig_measure_per_second": 1.0 / t_measure,
        }

        # The 200-geometry sweep.
        geometries = sweep_geometries(200)
        sim0 = emu.control.now()
        start = time.perf_counter()
        results = []
        skipped = 0
        for g in geometries:
            if rig.check_geometry(*g):
                skipped += 1
                continue
            results.append(rig.measure(*g))
        wall = time.perf_counter() - start
        sim = emu.control.now() - sim0
        normalised = np.array([m.radiance / np.cos(np.radians(m.theta_i)) for m in results])
        rel_rms = float(np.std(normalised) / np.mean(normalised))
        records.append({
            "family": "200-geometry sweep", "method": f"Rig.measure sweep ({label})",
            "seconds_per_evaluation": wall / len(results), "relative_error": rel_rms,
            "reference_method": "simulated instrument time",
            "notes": f"{len(results)} geometries measured ({skipped} refused by check_geometry); "
                     f"wall {wall:.2f} s vs simulated {sim:.1f} s",
        })
        extra[kind].update({
            "sweep_geometries": len(geometries), "sweep_measured": len(results), "sweep_refused": skipped,
            "sweep_wall_s": wall, "sweep_simulated_s": sim, "sweep_speedup": sim / wall,
            "sweep_radiance_rel_rms": rel_rms,
            "sweep_mean_attempts": float(np.mean([m.attempts for m in results])),
        })


def chart(records, path):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 6))
    ax = fig.add_subplot()
    labels = [r["method"] for r in records]
    values = [r["seconds_per_evaluation"] * 1e3 for r in records]
    colour = {"in-process URL": "C0", "pty": "C1", "TCP": "C2"}
    colors = [colour[r["method"].rsplit("(", 1)[1].rstrip(")")] for r in records]
    ax.barh(range(len(values)), values, color=colors)
    ax.set_yticks(range(len(values)), labels, fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("milliseconds per call (log)")
    ax.set_title("gonio drivers on the emulated rig (blue: in-process URL, orange: pty, green: TCP)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    records, extra = [], {}
    with EmulatedRig(lambert, seed=7, name="bench", lamp_warm=True) as emu:
        addresses = emu.start(pty=True, tcp=True)
        for kind in ("url", "pty", "tcp"):
            bench_transport(kind, emu, addresses, records, extra)
        for kind in ("pty", "tcp"):
            seconds = plain_client_pair(addresses["camera"][kind])
            extra[kind]["plain_pyserial_write_then_query_s"] = seconds
            records.append({
                "family": "plain pyserial client", "method": f"EXP + SYST:ERR? ({LABELS[kind]})",
                "seconds_per_evaluation": seconds, "relative_error": 0.0,
                "reference_method": "pty" if kind == "tcp" else "",
                "notes": "serial_for_url with no socket option set: the Nagle/delayed-ACK case "
                         "(speed only: relative_error not applicable, 0)",
            })
    keys = ("commands_per_second_camera", "commands_per_second_stage", "roi_measurements_per_second",
            "rig_measure_per_second")
    extra["pty_over_url_seconds"] = {key: extra["url"][key] / extra["pty"][key] for key in keys}
    tcp_over_pty = {key: extra["pty"][key] / extra["tcp"][key] for key in keys}
    tcp_over_pty["sweep_wall_s"] = extra["tcp"]["sweep_wall_s"] / extra["pty"]["sweep_wall_s"]
    tcp_over_pty["plain_pyserial_write_then_query_s"] = (extra["tcp"]["plain_pyserial_write_then_query_s"]
                                                         / extra["pty"]["plain_pyserial_write_then_query_s"])
    extra["tcp_over_pty_seconds"] = tcp_over_pty
    extra["ratio_note"] = ("'pty_over_url_seconds' and 'tcp_over_pty_seconds': seconds per call (or sweep wall "
                           "time) of the first transport divided by the second's, same run; target TCP <= 1.3 x pty")
    result = {
        "benchmark": "rig",
        "command": "python benchmarks/bench_rig.py",
        "machine": machine(),
        "records": records,
        "transports": extra,
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "rig.json").write_text(json.dumps(result, indent=2) + "\n")
    chart(records, OUT / "rig.png")
    for r in records:
        print(f"{r['method']:<40s} {r['seconds_per_evaluation'] * 1e3:9.3f} ms  rel.err {r['relative_error']:.2e}  {r['notes']}")
    print(json.dumps(extra, indent=2))


if __name__ == "__main__":
    main()
