#!/usr/bin/env python3
"""End-to-end fault injection (issue 18) over a pty, native protocol.

    fault_injection.py IMUEMUD IMUEMU [--keep DIR]

Three runs of imuemud on a flat `sample:flight` scene, 200 Hz native with
deltas on a pty whose raw bytes this script captures:

 1. scene faults: one [[imu.fault]] of every byte-stream type (26: all but
    the two CAN-only ones, tested with the DroneCAN decoder in
    tests/engine/test_fault_injection.cpp) on its own 20-sample window (after_s
    since the device's first sample). The decoded samples are walked in wire
    order against the expected order (absent, once, twice for duplicate,
    three times for babble). The capture is decoded
    twice, by an independent reference decoder written here from
    docs/native-protocol.md (CRC-32C from tests/support/protocol_reference.py,
    no project code) and by `imuemu listen` (drivers' decoder); both must
    agree sample for sample, and each sample must be exactly what the fault
    makes of the fault-free batch reference (`imuemu generate` of the same
    scene without its faults): the configured effect on exactly the
    configured samples, bit-identical elsewhere (analytic for the ramps and
    scale, 1e-12). The fault log names exactly those samples. noise_gain on
    this ideal sensor adds nothing (its noise is k-fold the model's, and the
    model has none): the check is that it changes nothing.
 2. run time: `imuemu fault inject` (a gyro bias step), `fault list`, then
    `fault clear --all`; the log names the first and last affected sample,
    the samples between carry the bias, and every other sample is
    bit-identical with the fault-free reference.
 3. random faults ([imu.random_faults], one seed): two runs write identical
    fault logs, and identical samples where both runs captured them.

Prints one JSON line of figures per run and FAIL lines; exit 1 on failure.
"""
import argparse
import csv
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
import tty

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
import protocol_reference  # noqa: E402
from protocol_reference import crc32c  # noqa: E402  (bitwise, from the CRC's Rocksoft parameters)

RATE = 200
PERIOD_NS = 1_000_000_000 // RATE
G0 = 9.80665
WINDOW = 20  # samples per scene fault (0.1 s at 200 Hz)

# (type, after_s, extra TOML lines): one window each, 0.4 s apart; the
# sequence jump last (the counter stays shifted after it).
SCENE_FAULTS = [
    ("dead", 1.0, 'sensor = "gyro"\nflag_status = true'),
    ("bias_step", 1.4, 'sensor = "accel"\naxes = "z"\nbias_mg = 100'),
    ("stuck", 1.8, 'sensor = "gyro"'),
    ("scale_step", 2.2, "scale_ppm = 10000"),
    ("delayed", 2.6, 'sensor = "gyro"\ndelay_ms = 50'),
    ("bias_ramp", 3.0, 'sensor = "gyro"\nramp_deg_s_per_s = 10'),
    ("slow", 3.4, "divisor = 4"),
    ("saturation", 3.8, 'sensor = "accel"'),
    ("garbage", 4.2, 'sensor = "gyro"'),
    ("intermittent", 4.6, 'sensor = "gyro"\non_ms = 25\noff_ms = 25'),
    ("plausible_drift", 5.0, 'sensor = "gyro"'),
    ("spikes", 5.4, 'sensor = "gyro"\nspike_deg_s = 100\nspike_rate_hz = 50'),
    ("noise_gain", 5.8, "noise_factor = 10"),
    ("drop", 6.2, ""),
    ("duplicate", 6.6, ""),
    ("babble", 7.0, "babble_factor = 3"),
    ("bad_checksum", 7.4, ""),
    ("truncate", 7.8, "truncate_bytes = 10"),
    ("bad_length", 8.2, ""),
    ("bit_errors", 8.6, "bit_error_rate = 0.01"),
    ("time_jump", 9.0, "time_step_ms = 10"),
    ("time_freeze", 9.4, ""),
    ("silence", 9.8, ""),
    ("sequence_jump", 10.2, "sequence_step = 1000"),
    ("sequence_reset", 10.6, ""),
    ("restart", 11.0, ""),
]
DURATION_S = 11.6  # 2321 samples
GYRO_RANGE = 2000.0 * 3.141592653589793 / 180.0  # core/fault/timeline.hpp defaults (no sensor model)
ACCEL_RANGE = 16.0 * G0


def scene_text(name, link, duration_s, speed, faults="", random=""):
    return (f'[scene]\nname = "{name}"\nphysics = "flat"\n'
            f'[trajectory]\nsource = "sample:flight"\nduration_s = {duration_s}\nknot_interval_s = 0.1\nspeed = {speed}\n'
            f'[[imu]]\nname = "imu0"\nrate_hz = {RATE}\nprotocol = "native"\nnative.include_deltas = true\n'
            f'[imu.transport]\ntype = "pty"\nlink = "{link}"\n' + faults + random)


def fault_tables(faults):
    out = ""
    for kind, after, extra in faults:
        out += f'[[imu.fault]]\ntype = "{kind}"\nafter_s = {after}\nduration_s = {WINDOW / RATE}\n'
        out += (extra + "\n") if extra else ""
    return out


# ---- independent reference decoder (docs/native-protocol.md §1, §2) ----

def reference_decode(data):
    """Native v1 frames in `data` -> (samples, counters). A frame: A5 5A, version
    1, flags (bit 0 deltas), u16 payload length (68, or 116 with deltas),
    payload, CRC-32C LE over everything before it. A bad CRC or a length that
    disagrees with the flags is counted and the search resumes one byte on."""
    samples, counters = [], {"crc_errors": 0, "bad_length": 0, "skipped_bytes": 0}
    i, n = 0, len(data)
    while i + 6 <= n:
        if data[i] != 0xA5 or data[i + 1] != 0x5A or data[i + 2] != 1:
            i += 1
            counters["skipped_bytes"] += 1
            continue
        flags = data[i + 3]
        (length,) = struct.unpack_from("<H", data, i + 4)
        if length != (116 if flags & 1 else 68):
            counters["bad_length"] += 1
            i += 1
            continue
        end = i + 6 + length + 4
        if end > n:
            break
        (crc,) = struct.unpack_from("<I", data, i + 6 + length)
        if crc != crc32c(data[i:i + 6 + length]):
            counters["crc_errors"] += 1
            i += 1
            continue
        seq, t_ns, status = struct.unpack_from("<QqI", data, i + 6)
        values = struct.unpack_from("<12d" if flags & 1 else "<6d", data, i + 26)
        samples.append({"seq": seq, "t_ns": t_ns, "status": status, "gyro": values[0:3], "accel": values[3:6],
                        "dtheta": values[6:9] if flags & 1 else None, "dv": values[9:12] if flags & 1 else None})
        i = end
    return samples, counters


def listen_decode(imuemu, capture, work):
    """imuemu listen on the captured bytes -> (samples, summary)."""
    out_csv = os.path.join(work, "listen.csv")
    r = subprocess.run([imuemu, "listen", "--protocol", "native", "--device", capture, "--json", "--quiet",
                        "--out", out_csv], capture_output=True, text=True, timeout=60)
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    samples = []
    with open(out_csv) as f:
        for row in csv.DictReader(line for line in f if not line.startswith("#")):
            samples.append(row)
    return samples, summary


def same_as_listen(ref_samples, listen_rows):
    """The two decoders agree on every sample (sequence, time, values, status)."""
    if len(ref_samples) != len(listen_rows):
        return f"reference decoder {len(ref_samples)} samples, imuemu listen {len(listen_rows)}"
    keys = list(listen_rows[0].keys()) if listen_rows else []
    seq_key = "sequence" if "sequence" in keys else keys[0]
    for a, b in zip(ref_samples, listen_rows):
        if int(b[seq_key]) != a["seq"] or int(b["t_ns"]) != a["t_ns"]:
            return f"sample {a['seq']}/{a['t_ns']}: listen has {b[seq_key]}/{b['t_ns']}"
        got = [float(b[k]) for k in ("gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s",
                                     "accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2")]
        if got != list(a["gyro"]) + list(a["accel"]):
            return f"sample {a['seq']}: values differ: reference {a['gyro']} {a['accel']}, listen {got}"
    return None


# ---- running imuemud and capturing its pty ----

class Daemon:
    def __init__(self, imuemud, work, scene, extra=()):
        self.work = work
        self.link = os.path.join(work, "ttyF0")
        self.socket = os.path.join(work, "control.sock")
        self.log = os.path.join(work, "faults.jsonl")
        self.capture = os.path.join(work, "capture.bin")
        scene_path = os.path.join(work, "scene.toml")
        with open(scene_path, "w") as f:
            f.write(scene)
        self.proc = subprocess.Popen([imuemud, "--scene", scene_path, "--pty-link-dir", work, "--control-socket",
                                      self.socket, "--fault-log", self.log, "--late-ticks", "send",
                                      "--stats-json", os.path.join(work, "stats.json"), *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 30
        while not os.path.islink(self.link):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"imuemud never published {self.link}: {self.proc.communicate()[0]}")
            time.sleep(0.002)
        self.fd = os.open(self.link, os.O_RDONLY | os.O_NOCTTY)
        tty.setraw(self.fd)  # no line discipline: the bytes as sent

    def read_until_exit(self, timeout_s, during=None):
        """Reads until the daemon ends (the pty then reports EIO); `during(elapsed)`
        is called between reads. Returns the bytes."""
        data = bytearray()
        os.set_blocking(self.fd, False)
        start = time.monotonic()
        while time.monotonic() - start < timeout_s:
            try:
                chunk = os.read(self.fd, 65536)
                if chunk:
                    data += chunk
                    continue
            except BlockingIOError:
                pass
            except OSError:  # EIO: the master side closed
                break
            if during:
                during(time.monotonic() - start)
            if self.proc.poll() is not None:
                try:
                    while True:
                        chunk = os.read(self.fd, 65536)
                        if not chunk:
                            break
                        data += chunk
                except OSError:
                    pass
                break
            time.sleep(0.002)
        os.close(self.fd)
        out = self.proc.communicate(timeout=30)[0]
        with open(self.capture, "wb") as f:
            f.write(data)
        self.output = out
        return bytes(data)

    def events(self):
        with open(self.log) as f:
            return [json.loads(line) for line in f if line.strip()]


def reference(imuemu, work, duration_s):
    """The fault-free batch reference: {k: (t_ns, gyro, accel)} from imuemu generate."""
    clean = os.path.join(work, "clean.toml")
    with open(clean, "w") as f:
        f.write(scene_text("clean", os.path.join(work, "unused"), duration_s, 1))
    out = os.path.join(work, "reference.csv")
    subprocess.run([imuemu, "generate", "--scene-file", clean, "--imu", "imu0", "--out", out, "--quiet"], check=True)
    ref = []
    with open(out) as f:
        rows = csv.reader(line for line in f if not line.startswith("#"))
        next(rows)
        for r in rows:
            ref.append((int(r[0]), tuple(float(x) for x in r[1:4]), tuple(float(x) for x in r[4:7])))
    return ref


def check_scene_faults(a, work, failures):
    ref = reference(a.imuemu, work, DURATION_S)
    d = Daemon(a.imuemud, work, scene_text("faults", os.path.join(work, "ttyF0"), DURATION_S, 2,
                                            fault_tables(SCENE_FAULTS)))
    data = d.read_until_exit(60)
    if d.proc.returncode != 0:
        failures.append(f"scene faults: imuemud exited {d.proc.returncode}: {d.output[-2000:]}")
        return
    samples, counters = reference_decode(data)
    rows, summary = listen_decode(a.imuemu, d.capture, work)
    if (why := same_as_listen(samples, rows)):
        failures.append("scene faults: the decoders disagree: " + why)
    # The project's reference receiver (protocol_reference.reference_decode,
    # from the link-fault work, when present): the same samples, and the
    # same error counters as imuemu listen.
    shared_reference = getattr(protocol_reference, "reference_decode", None)
    if shared_reference is not None:
        shared_counters, shared_samples = shared_reference("native", data)
        if [(x["sequence"], x["t_ns"]) for x in shared_samples] != [(x["seq"], x["t_ns"]) for x in samples]:
            failures.append("scene faults: protocol_reference.reference_decode decodes other samples")
        for key in ("checksum_errors", "other_errors", "resync_bytes"):
            if shared_counters[key] != summary.get(key):
                failures.append(f"scene faults: {key}: protocol_reference {shared_counters[key]}, listen {summary.get(key)}")
    windows = {kind: range(round(after * RATE), round(after * RATE) + WINDOW) for kind, after, _ in SCENE_FAULTS}
    w0 = {kind: w[0] for kind, w in windows.items()}
    # Ground truth: ids 1.. in file order, start/end exactly at the window.
    events = d.events()
    for i, (kind, after, _) in enumerate(SCENE_FAULTS):
        mine = [e for e in events if e["fault_id"] == i + 1]
        want = [("start", windows[kind][0]), ("end", windows[kind][-1])]
        got = [(e["phase"], e["sample_counter"]) for e in mine]
        if got != want or any(e["type"] != kind or e["source"] != "scene" for e in mine):
            failures.append(f"scene faults: fault log for {kind}: {got}, expected {want}")
    param = {e["type"]: e["parameters"] for e in events if e["phase"] == "start"}
    if not samples:
        failures.append("scene faults: nothing decoded")
        return
    first = samples[0]["seq"]  # no sequence fault before the first windows: seq = k
    if first > 150:
        failures.append(f"scene faults: the capture starts at sample {first} (the reader was late)")
    absent = set()
    for kind in ("drop", "bad_checksum", "truncate", "bad_length", "bit_errors", "silence", "restart"):
        absent |= set(windows[kind])

    def seq_of(k):
        if k >= windows["restart"][-1] + 1:
            return k - (windows["restart"][-1] + 1)  # restarted: the counter from 0 again
        if k >= w0["sequence_reset"]:
            return k - w0["sequence_reset"]
        if k >= w0["sequence_jump"]:
            return k + 1000
        return k

    # The expected wire order: (k, copies) for every sample from the first.
    expected = [(k, 3 if k in windows["babble"] else 2 if k in windows["duplicate"] else 1)
                for k in range(first, len(ref)) if k not in absent]
    flat = [k for k, n in expected for _ in range(n)]
    if len(flat) != len(samples):
        failures.append(f"scene faults: {len(samples)} samples decoded, {len(flat)} expected")
    spikes = 0
    h = 1.0 / RATE
    start_of = {k: w[0] for w in windows.values() for k in w}
    checked = 0
    for k, s in zip(flat, samples):
        t, gyro, accel = ref[k]
        want_t = t + (10_000_000 if k in windows["time_jump"] else 0)
        if k in windows["time_freeze"]:
            want_t = ref[w0["time_freeze"]][0]
        want_status = 4 if k in windows["dead"] else 2 if k in windows["saturation"] else 0
        gyro_w, accel_w, tolerance = list(gyro), list(accel), 0.0
        tau = (k - start_of.get(k, k)) * h  # time since the fault's first sample
        problems = []
        if k in windows["dead"]:
            gyro_w = [0.0, 0.0, 0.0]
            if list(s["dtheta"]) != [0.0, 0.0, 0.0]:
                problems.append(f"dead: delta theta {s['dtheta']}")
        elif k in windows["bias_step"]:
            accel_w[2] += param["bias_step"]["accel_bias_m_s2"]
        elif k in windows["stuck"]:
            gyro_w = list(next(x for x in samples if x["seq"] == w0["stuck"] - 1)["gyro"])
        elif k in windows["scale_step"]:
            gyro_w = [v * 1.01 for v in gyro_w]
            accel_w = [v * 1.01 for v in accel_w]
            tolerance = 1e-12
        elif k in windows["delayed"]:
            gyro_w = list(ref[k - 10][1])  # 50 ms at 200 Hz
        elif k in windows["bias_ramp"]:
            gyro_w = [v + param["bias_ramp"]["gyro_ramp_rad_s2"] * tau for v in gyro_w]
            tolerance = 1e-12
        elif k in windows["slow"]:
            held = w0["slow"] + 4 * ((k - w0["slow"]) // 4)
            gyro_w, accel_w = list(ref[held][1]), list(ref[held][2])
        elif k in windows["saturation"]:
            accel_w = [-ACCEL_RANGE if v < 0 else ACCEL_RANGE for v in accel_w]
        elif k in windows["garbage"]:
            if not all(abs(g) <= GYRO_RANGE and g != r for g, r in zip(s["gyro"], gyro)):
                problems.append(f"garbage: gyro {s['gyro']} not a draw within +-{GYRO_RANGE}")
            gyro_w = list(s["gyro"])
        elif k in windows["intermittent"]:
            if (k - w0["intermittent"]) * 5 % 50 < 25:  # on 25 ms of every 50 ms
                gyro_w = [0.0, 0.0, 0.0]
        elif k in windows["plausible_drift"]:
            p = param["plausible_drift"]
            gyro_w = [v + min(p["gyro_bias_rad_s"], p["gyro_ramp_rad_s2"] * tau) for v in gyro_w]
            tolerance = 1e-12
        elif k in windows["spikes"]:
            spiked = [v + param["spikes"]["gyro_bias_rad_s"] for v in gyro_w]
            if list(s["gyro"]) == spiked:
                spikes += 1
                gyro_w = spiked
        if s["seq"] != seq_of(k):
            problems.append(f"sequence {s['seq']} != {seq_of(k)}")
        if s["t_ns"] != want_t:
            problems.append(f"t_ns {s['t_ns']} != {want_t}")
        if s["status"] != want_status:
            problems.append(f"status {s['status']} != {want_status}")
        values, wanted = list(s["gyro"]) + list(s["accel"]), gyro_w + accel_w
        if any(abs(x - y) > tolerance * max(1.0, abs(y)) for x, y in zip(values, wanted)):
            problems.append(f"values {values} != {wanted}")
        if problems:
            failures.append(f"scene faults: sample {k} ({', '.join(problems)})")
        checked += 1
    if spikes == 0:
        failures.append("scene faults: no spike in the spikes window (50 /s over 0.1 s)")
    # Each corrupting fault shows once per affected frame in the reference decoder.
    if counters["crc_errors"] < 2 * WINDOW or counters["bad_length"] < WINDOW:
        failures.append(f"scene faults: reference decoder counters {counters}")
    if summary.get("checksum_errors", 0) < WINDOW:
        failures.append(f"scene faults: imuemu listen counted {summary.get('checksum_errors')} checksum errors")
    print(json.dumps({"run": "scene faults", "bytes": len(data), "samples_decoded": len(samples),
                      "samples_checked": checked, "first_sample": first, "spikes": spikes,
                      "reference_decoder": counters,
                      "listen": {k: summary.get(k) for k in ("samples", "checksum_errors", "resync_bytes",
                                                             "sequence_gaps", "other_errors")},
                      "fault_events": len(events), "protocol_reference_receiver": shared_reference is not None}))


def run_cli(imuemu, args):
    r = subprocess.run([imuemu, "fault", *args], capture_output=True, text=True, timeout=30)
    return r.returncode, r.stdout, r.stderr


def check_run_time(a, work, failures):
    duration = 8
    ref = reference(a.imuemu, work, duration)
    d = Daemon(a.imuemud, work, scene_text("runtime", os.path.join(work, "ttyF0"), duration, 1))
    state = {"step": 0}
    replies = {}
    sock = ["--socket", d.socket]

    def client():  # a thread: the main loop keeps reading the pty meanwhile
        time.sleep(2.0)
        replies["inject"] = run_cli(a.imuemu, ["inject", *sock, "--imu", "imu0", "--type", "bias_step",
                                               "--after-s", "0.5", "--param", "sensor=gyro", "--param",
                                               "bias_deg_s=10", "--compact"])
        replies["bad_type"] = run_cli(a.imuemu, ["inject", *sock, "--imu", "imu0", "--type", "no_such_type"])
        replies["bad_imu"] = run_cli(a.imuemu, ["inject", *sock, "--imu", "imu9", "--type", "dead"])
        state["step"] = 1
        time.sleep(1.5)
        replies["list"] = run_cli(a.imuemu, ["list", *sock, "--compact"])
        replies["clear"] = run_cli(a.imuemu, ["clear", *sock, "--imu", "imu0", "--all", "--compact"])
        replies["clear_again"] = run_cli(a.imuemu, ["clear", *sock, "--imu", "imu0", "--id", "1"])
        state["step"] = 2

    thread = threading.Thread(target=client, daemon=True)
    thread.start()
    data = d.read_until_exit(60)
    thread.join(timeout=30)
    if d.proc.returncode != 0:
        failures.append(f"run time: imuemud exited {d.proc.returncode}: {d.output[-2000:]}")
        return
    if state["step"] != 2:
        failures.append("run time: the daemon ended before the injection sequence ran")
        return
    rc, out, err = replies["inject"]
    if rc != 0:
        failures.append(f"run time: inject exited {rc}: {err}")
        return
    injected = json.loads(out)
    for key, why in (("bad_type", "not a fault type"), ("bad_imu", "no imu 'imu9'")):
        rc, out, err = replies[key]
        if rc != 4 or why not in err:
            failures.append(f"run time: {key}: exit {rc}, stderr {err.strip()}")
    rc, out, err = replies["list"]
    listed = json.loads(out)["faults"] if rc == 0 else []
    if [(f["id"], f["type"], f["state"], f["first_sample"]) for f in listed] != \
            [(injected["id"], "bias_step", "active", injected["first_sample"])]:
        failures.append(f"run time: list {listed}")
    rc, out, err = replies["clear"]
    if rc != 0 or json.loads(out)["cleared"] != [injected["id"]]:
        failures.append(f"run time: clear: exit {rc}: {out} {err}")
    rc, out, err = replies["clear_again"]
    if rc != 4 or "no fault 1" not in err:
        failures.append(f"run time: a second clear: exit {rc}, {err.strip()}")
    events = d.events()
    if [(e["phase"], e["fault_id"], e["source"]) for e in events] != \
            [("start", injected["id"], "control"), ("end", injected["id"], "control")]:
        failures.append(f"run time: fault log {events}")
        return
    k0, k1 = events[0]["sample_counter"], events[1]["sample_counter"]
    if k0 != injected["first_sample"]:
        failures.append(f"run time: the log starts at {k0}, inject said {injected['first_sample']}")
    bias = events[0]["parameters"]["gyro_bias_rad_s"]
    samples, counters = reference_decode(data)
    rows, summary = listen_decode(a.imuemu, d.capture, work)
    if (why := same_as_listen(samples, rows)):
        failures.append("run time: the decoders disagree: " + why)
    biased = identical = 0
    seen = set()
    for s in samples:
        k = s["seq"]
        seen.add(k)
        t, gyro, accel = ref[k]
        want = [g + bias for g in gyro] if k0 <= k <= k1 else list(gyro)
        if s["t_ns"] != t or list(s["accel"]) != list(accel) or list(s["gyro"]) != want:
            failures.append(f"run time: sample {k}: {s['gyro']} {s['accel']} != {want} {accel}")
            break
        if k0 <= k <= k1:
            biased += 1
        elif k > k1:
            identical += 1
    missing = [k for k in range(min(seen), len(ref)) if k not in seen]
    if missing or counters["crc_errors"] or counters["skipped_bytes"]:
        failures.append(f"run time: missing samples {missing[:10]}, decoder counters {counters}")
    if biased != k1 - k0 + 1 or identical < RATE:
        failures.append(f"run time: {biased} biased samples for {k0}..{k1}, {identical} after the clear")
    with open(os.path.join(work, "stats.json")) as f:
        faults = json.load(f)["devices"][0]["faults"]
    if (faults["started"], faults["ended"], faults["injected"], faults["cleared"], faults["dropped_events"]) != (1, 1, 1, 1, 0):
        failures.append(f"run time: status counters {faults}")
    print(json.dumps({"run": "run time", "inject": injected, "first_sample": k0, "last_sample": k1,
                      "biased_samples": biased, "bit_identical_after_clear": identical, "status_faults": faults}))


def check_random(a, work, failures):
    logs, captures = [], []
    random = ('[imu.random_faults]\nper_hour = 1800\ntypes = ["dead", "bias_step", "drop", "duplicate", "time_jump"]\n'
              'duration_s = 0.2\nseed = 42\n')
    for run in range(2):
        w = os.path.join(work, f"random{run}")
        os.makedirs(w)
        d = Daemon(a.imuemud, w, scene_text("random", os.path.join(w, "ttyF0"), 20, 5, random=random))
        data = d.read_until_exit(60)
        if d.proc.returncode != 0:
            failures.append(f"random: imuemud exited {d.proc.returncode}: {d.output[-2000:]}")
            return
        logs.append(d.events())
        captures.append({(s["seq"], s["t_ns"]): s for s in reference_decode(data)[0]})
    if not logs[0] or len(logs[0]) % 2:
        failures.append(f"random: {len(logs[0])} fault events in 20 s at 1800/h")
    if logs[0] != logs[1]:
        failures.append("random: the fault logs of two runs with one seed differ")
    common = set(captures[0]) & set(captures[1])
    differ = [key for key in common if captures[0][key] != captures[1][key]]
    # Both captures miss the samples sent before their reader opened (a
    # slower start under the sanitizers): most of the run must be common.
    if differ or len(common) < 0.75 * 20 * RATE:
        failures.append(f"random: {len(differ)} of {len(common)} common samples differ between the runs")
    print(json.dumps({"run": "random", "events": len(logs[0]),
                      "faults": sorted({(e['type'], e['sample_counter']) for e in logs[0] if e['phase'] == 'start'}),
                      "common_samples": len(common)}))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("imuemud")
    ap.add_argument("imuemu")
    ap.add_argument("--keep", help="keep the work files here")
    ap.add_argument("--only", default="scene,runtime,random")
    a = ap.parse_args()
    failures = []
    work = tempfile.mkdtemp(prefix="imuemu_faults_", dir="/dev/shm" if os.access("/dev/shm", os.W_OK) else None)
    try:
        for name, check in (("scene", check_scene_faults), ("runtime", check_run_time), ("random", check_random)):
            if name not in a.only.split(","):
                continue
            w = os.path.join(work, name)
            os.makedirs(w)
            try:
                check(a, w, failures)
            except Exception as e:  # a crash of the check is a failure, with what it was doing
                failures.append(f"{name}: {type(e).__name__}: {e}")
    finally:
        if a.keep:
            shutil.copytree(work, a.keep, dirs_exist_ok=True)
        shutil.rmtree(work, ignore_errors=True)
    for f in failures[:50]:
        print("FAIL:", f)
    print("fault injection:", "FAILED" if failures else "passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
