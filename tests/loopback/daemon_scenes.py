#!/usr/bin/python3
"""imuemud runs every example scene that needs no hardware (issue 6, acceptance 1).

For each scene, in parallel, for SECONDS:

    imuemud --scene SCENE --pty-link-dir W   (the scene's own devices: virtual serial ports)
    imuemu listen --device W/LINK             (the project's own decoder)

and, for the live-UDP scene, a sender replaying a 50 Hz flight as pose
datagrams v1 (docs/pose-wire-format.md §2) to the scene's port in real time.
Checks per scene:

  * zero checksum errors, zero resync bytes, zero sequence gaps;
  * the received samples are consecutive ticks of the device's grid, at
    exactly the scene's rate in sample time and within 1 % in wall time;
  * values equal the batch pipeline for the same trajectory
    (`imuemu generate --scene-file SCENE --imu NAME`: the scene's smoothing,
    physics, rate and mounting; for the live scene `imuemu generate --in`
    on the poses sent, with the scene's window) within the protocol's
    resolution: native bit-identical, MAVLink 2 and MIP float32;
  * the daemon stops cleanly (exit 0) and counted every tick.

A wake-up later than a sample period (the VM descheduled the emission thread)
is sent late instead of dropped (--late-ticks send) and printed: this test
checks the chain scene -> engine -> encoder -> pty -> decoder; the timing
benchmark (`imuemu bench timing`) measures lateness.

Usage: daemon_scenes.py IMUEMUD IMUEMU CONFIG_DIR [--seconds S] [--scenes a,b]
"""
import argparse
import csv
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import multiprocessing
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from loopback_checks import compare_with_reference, crc32c, memory_dir, read_listened, read_reference  # noqa: E402

# scene name -> (scene file or None for the built-in, imu name, protocol, rate, pty link name, listen extra args)
SCENES = {
    "default": (None, "imu0", "native", 400, "ttyIMU0", []),
    "bench-static": ("bench-static.toml", "bench", "native", 1000, "ttyBENCH0", []),
    "car-urban": ("car-urban.toml", "car-imu", "mavlink2", 250, "ttyCAR0", ["--mavlink-sample-message", "hil_sensor"]),
    "live-udp": ("live-udp.toml", "imu0", "native", 400, "ttyIMU0", []),
}
LIVE_PORT = 5005     # config/live-udp.toml
LIVE_PERIOD_S = 0.02
LIVE_WINDOW_S = 0.05



def decimal_ns(text):
    whole, _, frac = text.partition(".")
    sign = -1 if whole.startswith("-") else 1
    return sign * (abs(int(whole or "0")) * 1_000_000_000 + int((frac + "000000000")[:9]))


def send_poses(csv_path, stop):
    """Replays geodetic + heading/pitch/roll rows as datagrams, paced in real time."""
    with open(csv_path) as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))[1:]
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    t0 = decimal_ns(rows[0][0])
    start = time.monotonic_ns()
    for seq, r in enumerate(rows):
        if stop.is_set():
            break
        t = decimal_ns(r[0])
        due = start + (t - t0)
        delay = (due - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)
        body = b"IMUP" + bytes([1, 0, 0, 0]) + struct.pack("<Qq7d", seq, t, *(float(x) for x in r[1:7]), 0.0)
        sock.sendto(body + struct.pack("<I", crc32c(body)), ("127.0.0.1", LIVE_PORT))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("imuemud")
    ap.add_argument("imuemu")
    ap.add_argument("config_dir")
    ap.add_argument("--seconds", type=int, default=60)
    ap.add_argument("--scenes", default=",".join(SCENES))
    a = ap.parse_args()
    names = a.scenes.split(",")
    failures = []
    with tempfile.TemporaryDirectory(prefix="imuemu_scenes_", dir=memory_dir()) as work:
        runs = {}
        for name in names:
            scene_file, imu, protocol, rate, link_name, _ = SCENES[name]
            d = os.path.join(work, name)
            os.makedirs(d)
            cmd = [a.imuemud, "--pty-link-dir", d, "--control-socket", os.path.join(d, "control.sock"),
                   "--seconds", str(a.seconds + 8), "--stats-json", os.path.join(d, "stats.json"), "--late-ticks", "send"]
            if scene_file:
                cmd += ["--scene", os.path.join(a.config_dir, scene_file)]
            runs[name] = {"daemon": subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
                          "link": os.path.join(d, link_name), "dir": d}
        # A process of its own: in a thread it would wait for the GIL while
        # this script parses CSVs, and poses would arrive late (extrapolated).
        stop = multiprocessing.Event()
        sender = None
        if "live-udp" in runs:
            flight = os.path.join(work, "flight50.csv")
            subprocess.run([a.imuemu, "sample-trajectory", "--out", flight, "--kind", "flight",
                            "--duration-s", str(a.seconds + 20), "--period-s", str(LIVE_PERIOD_S)], check=True)
            sender = multiprocessing.Process(target=send_poses, args=(flight, stop), daemon=True)
        deadline = time.monotonic() + 30
        for name, run in runs.items():
            while not os.path.islink(run["link"]):
                if run["daemon"].poll() is not None or time.monotonic() > deadline:
                    out, err = run["daemon"].communicate()
                    print(f"FAIL: {name}: imuemud never published {run['link']} (rc {run['daemon'].returncode}):\n{err}")
                    return 1
                time.sleep(0.01)
        for name, run in runs.items():
            _, _, protocol, rate, _, extra = SCENES[name]
            run["csv"] = os.path.join(run["dir"], "listen.csv")
            run["listen"] = subprocess.Popen(
                [a.imuemu, "listen", "--protocol", protocol, "--device", run["link"], "--json", "--quiet",
                 "--out", run["csv"], "--expect-rate", str(rate), "--duration-s", str(a.seconds)] + extra,
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if sender:
            sender.start()
        # Batch references while the daemons run.
        for name, run in runs.items():
            scene_file, imu, protocol, rate, _, _ = SCENES[name]
            ref_csv = os.path.join(run["dir"], "reference.csv")
            if name == "live-udp":
                cmd = [a.imuemu, "generate", "--in", flight, "--out", ref_csv, "--rate", str(rate), "--scene", "ecef",
                       "--delta", str(round(LIVE_WINDOW_S * rate)), "--gap-policy", "split", "--max-gap-s", "1", "--quiet"]
            else:
                cmd = [a.imuemu, "generate", "--scene-file", os.path.join(a.config_dir, scene_file or "default.toml"),
                       "--imu", imu, "--out", ref_csv, "--max-seconds", str(a.seconds + 30), "--quiet"]
            subprocess.run(cmd, check=True)
            run["ref"] = read_reference(ref_csv)[1]
        for name, run in runs.items():
            _, imu, protocol, rate, _, _ = SCENES[name]
            l_out, l_err = run["listen"].communicate(timeout=a.seconds + 60)
            d_out, d_err = run["daemon"].communicate(timeout=a.seconds + 60)
            if run["listen"].returncode != 0:
                failures.append(f"{name}: listen exited {run['listen'].returncode}: {l_err.strip()}")
                continue
            if run["daemon"].returncode != 0:
                failures.append(f"{name}: imuemud exited {run['daemon'].returncode}: {d_err.strip()[-2000:]}")
                continue
            summary = json.loads(l_out.strip().splitlines()[-1])
            with open(os.path.join(run["dir"], "stats.json")) as f:
                dev = json.load(f)["devices"][0]
            # A live scene's producer can be late for a tick on a slow host
            # (an underrun: nothing ready at the deadline, so nothing sent,
            # counted); a file or sample scene must have none (checked below).
            counted_skips = dev["underruns"] + dev["not_sent"] if name == "live-udp" else 0
            f, figures = compare_with_reference(name, protocol, rate, read_listened(run["csv"]), run["ref"], summary,
                                                counted_skips)
            failures += f
            if summary["samples"] < 0.95 * rate * a.seconds:
                failures.append(f"{name}: listen saw {summary['samples']} samples in {a.seconds} s at {rate} Hz")
            if dev["underruns"] != 0 and name != "live-udp":
                failures.append(f"{name}: {dev['underruns']} producer underruns on a file/sample trajectory")
            figures["transport"] = dev["transport"]
            # Why a tick was not sent, when one was not: the emitter's own
            # counters (gap, paused, waiting, underrun events) and the
            # producer's lateness (underruns: no sample ready at the deadline).
            figures["live"] = dev.get("live")
            figures["underruns"] = dev["underruns"]
            figures["not_sent"] = dev["not_sent"]
            figures.update({"scene": name, "protocol": protocol, "rate_hz": rate, "daemon_emitted": dev["emitted"],
                            "deadline_misses_sent_late": dev["deadline_misses"], "extrapolated": dev["samples"]["extrapolated"],
                            "lateness_p99_us": dev["lateness"]["p99_ns"] / 1000})
            print(json.dumps(figures))
        stop.set()
        if sender:
            sender.join(timeout=5)
    for f in failures:
        print("FAIL:", f)
    print("imuemud scenes:", "FAILED" if failures else "passed", f"({len(names)} scenes, {a.seconds} s each, in parallel)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
