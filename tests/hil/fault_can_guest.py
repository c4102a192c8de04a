#!/usr/bin/python3
"""CAN faults end to end on vcan0 (issue 18; guest side, under tests/hil/hil_run.sh).

    fault_can_guest.py IMUEMUD IMUEMU

imuemud runs a 100 Hz DroneCAN device on vcan0 with one [[imu.fault]] per CAN
fault on its own 10 samples (can_wrong_id, can_missing_frame, silence,
bad_checksum, sequence_jump). candump -L captures the bus; the capture is
decoded here from the specification (UAVCAN v0 transport: 29-bit id, tail
byte start/end/toggle/transfer id, transfer CRC seeded with the RawIMU data
type signature; CRC and float16 helpers from can_peer.py), and imuemu listen
decodes the same bus. Both must see exactly the samples outside the fault
windows, with the transfer ids the faults leave (silence and the others keep
the encoder running: consecutive ids jump by the window; sequence_jump adds
5), and the fault log must name exactly the windows. Functional only (UML's
clock is emulated): no timing is checked.
"""
import json
import os
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from can_peer import RAW_IMU_ID, RAW_IMU_SIGNATURE, crc16_ccitt_false, parse_candump_log  # noqa: E402

RATE = 100
NODE_ID = 42
FAULTS = [  # (type, first sample, extra keys); 10 samples each
    ("can_wrong_id", 100, "can_id = 0x123"),
    ("can_missing_frame", 150, ""),
    ("silence", 200, ""),
    ("bad_checksum", 250, ""),
    ("sequence_jump", 300, "sequence_step = 5"),
]
DURATION_S = 4


def scene(faults=True):
    text = (f'[scene]\nname = "canfaults"\nphysics = "flat"\n[trajectory]\nsource = "sample:flight"\n'
            f'duration_s = {DURATION_S}\nknot_interval_s = 0.1\n'
            f'[[imu]]\nname = "imu0"\nrate_hz = {RATE}\nprotocol = "dronecan"\n'
            f'[imu.dronecan]\nnode_id = {NODE_ID}\n[imu.transport]\ntype = "can"\ninterface = "vcan0"\n')
    if faults:
        for kind, first, extra in FAULTS:
            text += f'[[imu.fault]]\ntype = "{kind}"\nafter_s = {first / RATE}\nduration_s = {10 / RATE}\n'
            text += (extra + "\n") if extra else ""
    return text


def reference_decode(frames):
    """RawIMU transfers of node NODE_ID -> [(transfer id, usec)] and counters.
    A transfer that breaks the rules (a frame missing: toggle or start out of
    order; a bad CRC) is counted and dropped; a frame that is not a 29-bit
    frame of this node is counted and skipped."""
    out, counters = [], {"foreign_frames": 0, "broken_transfers": 0, "crc_errors": 0}
    current = None
    for ident, extended, fd, data in frames:
        if not extended or fd or not 1 <= len(data) <= 8 or ident & 0x7F != NODE_ID:
            counters["foreign_frames"] += 1
            continue
        if (ident >> 8) & 0xFFFF != RAW_IMU_ID:
            continue  # NodeStatus
        tail = data[-1]
        start, end, toggle, tid = bool(tail & 0x80), bool(tail & 0x40), bool(tail & 0x20), tail & 0x1F
        if start:
            if current is not None:
                counters["broken_transfers"] += 1
            current = [tid, True, bytearray(data[:-1])] if not toggle else None
        elif current is None or tid != current[0] or toggle != current[1]:
            if current is not None:
                counters["broken_transfers"] += 1
            current = None
            continue
        else:
            current[1] = not current[1]
            current[2] += data[:-1]
        if end and current is not None:
            stream = bytes(current[2])
            crc, payload = stream[0] | stream[1] << 8, stream[2:]
            if crc != crc16_ccitt_false(crc16_ccitt_false(0xFFFF, RAW_IMU_SIGNATURE.to_bytes(8, "little")), payload):
                counters["crc_errors"] += 1
            else:
                out.append((current[0], int.from_bytes(payload[0:7], "little")))
            current = None
    return out, counters


def receivers():
    with open("/proc/net/can/rcvlist_all") as f:
        return sum(1 for line in f if line.rstrip().endswith(" raw"))


def main():
    imuemud, imuemu = sys.argv[1], sys.argv[2]
    out = os.environ.get("HIL_OUT") or tempfile.mkdtemp()
    failures = []
    scene_path = os.path.join(out, "scene.toml")
    with open(scene_path, "w") as f:
        f.write(scene())
    clean_path = os.path.join(out, "clean.toml")
    with open(clean_path, "w") as f:
        f.write(scene(False))
    ref_csv = os.path.join(out, "reference.csv")
    subprocess.run([imuemu, "generate", "--scene-file", clean_path, "--imu", "imu0", "--out", ref_csv, "--quiet"],
                   check=True)
    with open(ref_csv) as f:
        grid = [int(line.split(",")[0]) for line in f if line[:1].isdigit() or line[:1] == "-"]
    # UML's emulated host is slow: receivers that fall behind would lose frames
    # from a default-sized socket buffer (a receiver's loss, not the
    # emulator's). 8 MiB holds the whole run; the daemon runs niced.
    for knob in ("rmem_default", "rmem_max"):
        with open(f"/proc/sys/net/core/{knob}", "w") as f:
            f.write("8388608")
    base = receivers()
    candump = subprocess.Popen(["candump", "-L", "vcan0"], stdout=open(os.path.join(out, "candump.log"), "w"))
    listen = subprocess.Popen([imuemu, "listen", "--protocol", "dronecan", "--device", "can:vcan0", "--json",
                               "--dronecan-node-id", str(NODE_ID)], stdout=open(os.path.join(out, "listen.ndjson"), "w"),
                              stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while receivers() < base + 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    log = os.path.join(out, "faults.jsonl")
    if os.path.exists(log):
        os.remove(log)  # imuemud appends: a results directory used before holds an older run's
    daemon = subprocess.run(["nice", "-n", "10", imuemud, "--scene", scene_path, "--control-socket", os.path.join(out, "c.sock"),
                             "--fault-log", log, "--late-ticks", "send", "--stats-json", os.path.join(out, "stats.json")],
                            capture_output=True, text=True, timeout=200)
    if daemon.returncode != 0:
        failures.append(f"imuemud exited {daemon.returncode}: {daemon.stderr[-2000:]}")
    time.sleep(2.0)  # the receivers drain their socket queues
    for p in (listen, candump):
        p.send_signal(signal.SIGINT)
        p.wait(timeout=30)

    transfers, counters = reference_decode(parse_candump_log(os.path.join(out, "candump.log")))
    usec_to_k = {max(t // 1000, 1): k for k, t in enumerate(grid)}
    got = [(usec_to_k.get(usec), tid) for tid, usec in transfers]
    if any(k is None for k, _ in got):
        failures.append("a RawIMU timestamp is not on the output grid")
    windows = {kind: range(first, first + 10) for kind, first, _ in FAULTS}
    absent = set(windows["can_wrong_id"]) | set(windows["can_missing_frame"]) | set(windows["silence"]) | \
        set(windows["bad_checksum"])
    first_k = got[0][0] if got else 0
    want = [(k, (k + (5 if k >= 300 else 0)) % 32) for k in range(first_k, len(grid)) if k not in absent]
    if got != want:
        diff = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), min(len(got), len(want)))
        failures.append(f"reference decoder: {len(got)} samples, expected {len(want)}; first difference at "
                        f"{diff}: {got[diff:diff + 3]} vs {want[diff:diff + 3]}")
    if first_k > 50:
        failures.append(f"the capture starts at sample {first_k}")
    wrong_id = sum(1 for ident, extended, _, _ in parse_candump_log(os.path.join(out, "candump.log"))
                   if ident == 0x123 and not extended)
    if wrong_id == 0 or wrong_id % 10 or counters["crc_errors"] != 10 or counters["broken_transfers"] < 10:
        failures.append(f"reference decoder counters {counters}, {wrong_id} frames under 0x123")
    listened = []
    with open(os.path.join(out, "listen.ndjson")) as f:
        for line in f:
            obj = json.loads(line)
            if obj.get("type") != "summary":
                listened.append(max(obj["t_ns"] // 1000, 1))
    if listened != [usec for _, usec in transfers]:
        failures.append(f"imuemu listen decoded {len(listened)} samples, the reference {len(transfers)}; they differ")
    with open(log) as f:
        events = [json.loads(line) for line in f if line.strip()]
    got_events = [(e["type"], e["phase"], e["sample_counter"]) for e in events]
    want_events = [(kind, phase, first + (0 if phase == "start" else 9)) for kind, first, _ in FAULTS
                   for phase in ("start", "end")]
    if got_events != want_events:
        failures.append(f"fault log {got_events}, expected {want_events}")
    print(json.dumps({"samples_reference": len(transfers), "samples_listen": len(listened), "first_sample": first_k,
                      "counters": counters, "frames_under_0x123": wrong_id, "fault_events": len(events)}))
    for f in failures:
        print("FAIL:", f)
    print("CAN faults on vcan0:", "FAILED" if failures else "passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
