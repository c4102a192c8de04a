#!/usr/bin/python3
"""Third-party CAN peer of the hil_can_dronecan_j1939 test (guest side,
under tests/hil/hil_run.sh; run with /usr/bin/python3, which has python3-can).

  can_peer.py capture --channel vcan0 --out FILE [FILE...]
      Receives every frame on the interface with python-can's SocketCAN
      backend (its own socket, independent of candump and of imuemu) until
      SIGTERM/SIGINT, and writes them in candump's -L log format; SIGUSR1
      moves on to the next FILE, and FILE.ready appears once FILE is in use.

  can_peer.py check dronecan|j1939 --candump LOG --python LOG --listen NDJSON
                    --emit-stats JSON [--rate HZ] [--sample-static] [--node-id N]
                    [--source-address SA] [--frd-reference DRONECAN_LOG]
      Checks the three captures against each other and against the protocol,
      decoding the frames here from the specifications (not with imuemu's
      decoders):
       - DroneCAN (UAVCAN v0 spec 4.1 "CAN bus transport layer"): the 29-bit id
         fields priority(5) | data type id(16) | service(1)=0 | source node(7);
         the tail byte start/end/toggle/transfer id sequence of every
         multi-frame RawIMU (1003) transfer (toggle 0 in the first frame), the
         transfer CRC (CRC-16-CCITT-FALSE seeded with the data type signature
         0x8280632C40E574B5, LSB first), transfer ids consecutive mod 32, the
         RawIMU payload (47 bytes: uint56 usec, float32 integration interval,
         float16[3] gyro, float32[3], float16[3] accel, float32[3]) with its
         timestamps on the output grid (increasing, within the ticks emit
         counted, equal to listen's); NodeStatus (341) single-frame, once per
         second of the samples' time (+-1), uptime not decreasing.
       - J1939 (SAE J1939-21 29-bit id: priority(3) | PGN(18) | source
         address(8)): only PGNs 61482 ARI, 61485 ACCS (and 61481 SSI2 when
         sent), with the configured priority and source address, in the
         per-sample order ARI, ACCS[, SSI2], every frame 8 bytes, no value in
         the reserved range.
       - Counts: candump, python-can and imuemu listen saw the same frames (the
         two logs frame for frame), listen decoded as many samples as the
         emitter reports sending and python found, with zero checksum errors,
         sequence gaps and malformed frames.
      With --sample-static, the static IMU's physics is checked too (specific
      force ~1 g pointing up, rates ~0); with --frd-reference, J1939's ISO 8855
      accelerations against the same IMU's DroneCAN (body FRD) values.
Exit status 0 when every check passed, 1 otherwise (each failure printed).
"""
import argparse
import json
import math
import signal
import struct
import sys

# ---------------------------------------------------------------- capture


def capture(args):
    """Captures into args.out[0]; SIGUSR1 moves on to the next file (so that one
    process, whose start in an emulated guest takes seconds, serves several runs). Each
    file gets a sibling FILE.ready once frames go into it."""
    import can  # python3-can (Debian), only needed here

    stop = False
    rotations = 0

    def on_stop(signum, frame):
        nonlocal stop
        stop = True

    def on_next(signum, frame):
        nonlocal rotations
        rotations += 1

    signal.signal(signal.SIGTERM, on_stop)
    signal.signal(signal.SIGINT, on_stop)
    signal.signal(signal.SIGUSR1, on_next)
    bus = can.interface.Bus(channel=args.channel, interface="socketcan", fd=True)
    # The socket is bound once Bus() returns: from here on no frame is missed.
    index, counts = 0, []
    out = None

    def write(msg):
        width = 8 if msg.is_extended_id else 3
        sep = "##%X" % ((1 if msg.bitrate_switch else 0) | 4) if msg.is_fd else "#"
        out.write("(%.6f) %s %0*X%s%s\n" % (msg.timestamp, args.channel, width,
                                            msg.arbitration_id, sep, msg.data.hex().upper()))
        counts[-1] += 1

    def drain():
        """Everything sent before the signal is already in the socket's
        queue (vcan delivers synchronously): it belongs to this file."""
        while (msg := bus.recv(timeout=0)) is not None:
            if not msg.is_error_frame:
                write(msg)

    while not stop:
        if out is None or (rotations > index and index + 1 < len(args.out)):
            if out is not None:
                drain()
                out.close()
                index += 1
            out = open(args.out[index], "w")
            counts.append(0)
            with open(args.out[index] + ".ready", "w") as ready:
                ready.write("ready\n")
        msg = bus.recv(timeout=0.05)
        if msg is not None and not msg.is_error_frame:
            write(msg)
    drain()
    out.close()
    bus.shutdown()
    print(f"can_peer capture: frames per file on {args.channel}: {counts}")
    return 0


# ---------------------------------------------------------------- parsing


def parse_candump_log(path):
    """candump -L lines: '(sec.usec) IFACE ID#DATA' (classic) or 'ID##F DATA'
    (FD). Returns [(id, extended, fd, bytes)] in order."""
    frames = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            parts = line.split()
            if len(parts) != 3:
                raise ValueError(f"{path}:{number}: not a candump -L line: {line!r}")
            ident, _, rest = parts[2].partition("#")
            fd = rest.startswith("#")
            data = rest[2:] if fd else rest
            frames.append((int(ident, 16), len(ident) == 8, fd, bytes.fromhex(data)))
    return frames


def read_listen(path):
    """imuemu listen --json: NDJSON sample lines, then one summary object."""
    samples, summary = [], None
    with open(path) as f:
        for number, line in enumerate(f, 1):
            if not line.strip():
                continue
            obj = json.loads(line)
            if obj.get("type") == "summary":
                summary = obj
            else:
                samples.append(obj)
    return samples, summary


# ---------------------------------------------------------------- DroneCAN

RAW_IMU_ID = 1003
RAW_IMU_SIGNATURE = 0x8280632C40E574B5
RAW_IMU_PAYLOAD_BYTES = 47
NODE_STATUS_ID = 341


def crc16_ccitt_false(crc, data):
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def half_to_float(bits):
    return struct.unpack("<e", struct.pack("<H", bits))[0]


class Checks:
    def __init__(self, name):
        self.name, self.failures, self.notes = name, [], []
        self.timestamp_ticks = None  # tick indices of the samples, from the python decoding of their times
        self.first_accel_frd = None  # the first RawIMU's specific force (m/s^2, body FRD)

    def expect(self, ok, message):
        if not ok:
            self.failures.append(message)
        return ok

    def note(self, message):
        self.notes.append(message)


def check_dronecan(frames, args, c):
    """Independent DroneCAN checks; returns the number of RawIMU transfers."""
    transfers = []  # (transfer id, payload)
    node_status = []  # (transfer id, payload)
    current = None  # [tid, expected toggle, bytes]
    for index, (ident, extended, fd, data) in enumerate(frames):
        where = f"frame {index} id {ident:08X}"
        if not c.expect(extended and not fd and 1 <= len(data) <= 8,
                        f"{where}: not a classic 29-bit frame of 1..8 bytes (extended={extended}, fd={fd}, len={len(data)})"):
            continue
        priority, type_id = (ident >> 24) & 0x1F, (ident >> 8) & 0xFFFF
        service, source = (ident >> 7) & 1, ident & 0x7F
        c.expect(service == 0, f"{where}: service bit set in a message broadcast")
        c.expect(source == args.node_id, f"{where}: source node {source}, configured {args.node_id}")
        tail = data[-1]
        start, end, toggle, tid = bool(tail & 0x80), bool(tail & 0x40), bool(tail & 0x20), tail & 0x1F
        if type_id == NODE_STATUS_ID:
            c.expect(priority == args.node_status_priority,
                     f"{where}: NodeStatus priority {priority}, expected {args.node_status_priority}")
            c.expect(start and end and not toggle and len(data) == 8,
                     f"{where}: NodeStatus is not a single 8-byte frame (tail {tail:02X}, len {len(data)})")
            node_status.append((tid, data[:-1]))
            continue
        if not c.expect(type_id == RAW_IMU_ID, f"{where}: data type id {type_id}, expected 1003 or 341"):
            continue
        c.expect(priority == args.raw_imu_priority,
                 f"{where}: RawIMU priority {priority}, expected {args.raw_imu_priority}")
        if start:
            c.expect(current is None, f"{where}: new transfer while transfer {current and current[0]} is incomplete")
            c.expect(not toggle, f"{where}: toggle bit set in the first frame")
            current = [tid, True, bytearray(data[:-1])]
        else:
            if not c.expect(current is not None, f"{where}: continuation frame with no transfer in progress"):
                continue
            c.expect(tid == current[0], f"{where}: transfer id {tid} inside transfer {current[0]}")
            c.expect(toggle == current[1], f"{where}: toggle {int(toggle)}, expected {int(current[1])}")
            current[1] = not current[1]
            current[2] += data[:-1]
        if end and current is not None:
            stream = bytes(current[2])
            crc, payload = stream[0] | stream[1] << 8, stream[2:]
            expected_crc = crc16_ccitt_false(crc16_ccitt_false(0xFFFF, RAW_IMU_SIGNATURE.to_bytes(8, "little")), payload)
            c.expect(crc == expected_crc, f"{where}: transfer CRC {crc:04X}, computed {expected_crc:04X}")
            c.expect(len(payload) == RAW_IMU_PAYLOAD_BYTES, f"{where}: RawIMU payload {len(payload)} bytes, expected 47")
            transfers.append((current[0], payload))
            current = None
    c.expect(current is None, "the capture ends inside a RawIMU transfer")

    for name, sequence in (("RawIMU", transfers), ("NodeStatus", node_status)):
        for (a, _), (b, _) in zip(sequence, sequence[1:]):
            if not c.expect(b == (a + 1) % 32, f"{name} transfer id {b} after {a}: not consecutive mod 32"):
                break
        if sequence:
            c.expect(sequence[0][0] == 0, f"{name}: first transfer id {sequence[0][0]}, a fresh node starts at 0")

    # RawIMU payload: little-endian, byte-aligned fields (DSDL bit order).
    usecs = []
    for tid, p in transfers:
        if len(p) != RAW_IMU_PAYLOAD_BYTES:
            continue
        usec = int.from_bytes(p[0:7], "little")
        interval = struct.unpack_from("<f", p, 7)[0]
        gyro = [half_to_float(int.from_bytes(p[11 + 2 * i:13 + 2 * i], "little")) for i in range(3)]
        accel = [half_to_float(int.from_bytes(p[29 + 2 * i:31 + 2 * i], "little")) for i in range(3)]
        usecs.append(usec)
        if c.first_accel_frd is None:
            c.first_accel_frd = accel
        c.expect(all(math.isfinite(v) for v in gyro + accel + [interval]), f"RawIMU {tid}: non-finite value")
        if args.rate:
            c.expect(abs(interval - 1.0 / args.rate) < 1e-6,
                     f"RawIMU {tid}: integration interval {interval} s, expected 1/{args.rate} s")
        if args.sample_static:
            norm = math.sqrt(sum(a * a for a in accel))
            c.expect(9.7 < norm < 9.9 and accel[2] < -9.6,
                     f"RawIMU {tid}: static specific force {accel} m/s^2, expected ~(0, 0, -9.8) in FRD")
            c.expect(max(abs(g) for g in gyro) < 1e-3, f"RawIMU {tid}: static rates {gyro} rad/s, expected ~0")
    if args.rate:
        # Sample k of the trajectory is at k periods (the grid starts at
        # trajectory time 0): the timestamps name which ticks were sent.
        period_us = 1e6 / args.rate
        ticks = [u / period_us for u in usecs]
        c.expect(all(abs(k - round(k)) * period_us <= 1 for k in ticks),
                 f"RawIMU timestamps not on the {period_us} us grid: {[k for k in ticks if abs(k - round(k)) * period_us > 1][:5]}")
        c.timestamp_ticks = [round(k) for k in ticks]
    if usecs:
        span_s = (usecs[-1] - usecs[0]) / 1e6
        expected = math.floor(span_s) + 1  # at the first sample, then every whole second
        c.expect(abs(len(node_status) - expected) <= 1,
                 f"{len(node_status)} NodeStatus over {span_s:.3f} s of samples, expected {expected} (+-1)")
        uptimes = [int.from_bytes(p[0:4], "little") for _, p in node_status]
        c.expect(uptimes == sorted(uptimes) and (not uptimes or uptimes[0] <= 1),
                 f"NodeStatus uptimes {uptimes}: should start at 0 and not decrease")
        c.note(f"{len(transfers)} RawIMU transfers of {len(transfers) * 7} frames, "
               f"{len(node_status)} NodeStatus (uptimes {uptimes}), {span_s:.3f} s of sample time")
    return len(transfers)


# ---------------------------------------------------------------- J1939

PGN_ARI, PGN_ACCS, PGN_SSI2 = 61482, 61485, 61481


def check_j1939(frames, args, c):
    """Independent J1939 checks; returns the number of samples (ARI frames)."""
    pgns = []
    ari, accs = [], []
    for index, (ident, extended, fd, data) in enumerate(frames):
        where = f"frame {index} id {ident:08X}"
        if not c.expect(extended and not fd and len(data) == 8,
                        f"{where}: not a classic 29-bit 8-byte frame (extended={extended}, fd={fd}, len={len(data)})"):
            continue
        priority, pgn, source = (ident >> 26) & 7, (ident >> 8) & 0x3FFFF, ident & 0xFF
        c.expect(priority == args.priority, f"{where}: priority {priority}, expected {args.priority}")
        c.expect(source == args.source_address, f"{where}: source address {source}, configured {args.source_address}")
        c.expect((ident >> 24) & 3 == 0, f"{where}: EDP/DP set: not in PGN page 0")
        if not c.expect(pgn in (PGN_ARI, PGN_ACCS, PGN_SSI2), f"{where}: PGN {pgn}, expected 61482/61485/61481"):
            continue
        pgns.append(pgn)
        if pgn in (PGN_ARI, PGN_ACCS):
            raw = [int.from_bytes(data[2 * i:2 * i + 2], "little") for i in range(3)]
            c.expect(all(r <= 0xFAFF for r in raw), f"{where}: value outside the valid range 0..0xFAFF: {raw}")
            (ari if pgn == PGN_ARI else accs).append(raw)
    # The per-sample order ARI, ACCS[, SSI2] (whatever subset is sent).
    if pgns:
        per_sample = pgns[:pgns.index(PGN_ARI, 1)] if pgns.count(PGN_ARI) > 1 else pgns
        c.expect(per_sample[0] == PGN_ARI and PGN_ACCS in per_sample,
                 f"per-sample PGN order {per_sample}: expected ARI (61482) first, then ACCS (61485)")
        n = len(pgns) // len(per_sample)
        c.expect(pgns == per_sample * n, f"PGN sequence does not repeat {per_sample}: {pgns[:12]}...")
        c.note(f"{len(pgns)} frames, {n} samples of PGNs {per_sample}")
    if args.sample_static:
        # ISO 8855 vehicle axes (z up): a sensor at rest reads ~+1 g vertical
        # (the built-in static trajectory is tilted by about a degree).
        for raw in accs:
            lateral, longitudinal, vertical = (r * 0.01 - 320.0 for r in raw)
            norm = math.sqrt(lateral ** 2 + longitudinal ** 2 + vertical ** 2)
            if not c.expect(9.7 < norm < 9.9 and vertical > 9.6,
                            f"static ACCS {lateral, longitudinal, vertical} m/s^2, expected ~1 g up"):
                break
        if accs and args.frd_reference:
            # The same static IMU sent as DroneCAN RawIMU (body FRD, the
            # reference run's capture, decoded here): ISO 8855 has
            # longitudinal = f_x, lateral = -f_y, vertical = -f_z.
            scratch = Checks("reference")
            check_dronecan(parse_candump_log(args.frd_reference), args, scratch)
            f = scratch.first_accel_frd
            if c.expect(f is not None, f"no RawIMU in the reference capture {args.frd_reference}"):
                lateral, longitudinal, vertical = (r * 0.01 - 320.0 for r in accs[0])
                expected = (-f[1], f[0], -f[2])
                c.expect(all(abs(a - b) <= 0.006 + 0.01 * abs(b) / 100 for a, b in
                             zip((lateral, longitudinal, vertical), expected)),
                         f"ACCS (lateral, longitudinal, vertical) {lateral, longitudinal, vertical} m/s^2 does not "
                         f"match the RawIMU FRD {f} in ISO 8855 axes: expected {expected}")
                c.note(f"ACCS {lateral:.2f}, {longitudinal:.2f}, {vertical:.2f} m/s^2 = RawIMU FRD {f} in ISO 8855 axes")
        for raw in ari:
            rates = [r / 128.0 - 250.0 for r in raw]
            if not c.expect(max(abs(r) for r in rates) < 0.02, f"static ARI {rates} deg/s, expected ~0"):
                break
    return len(ari)


# ---------------------------------------------------------------- check


def check(args):
    c = Checks(args.protocol)
    candump = parse_candump_log(args.candump)
    python = parse_candump_log(args.python)
    c.expect(len(candump) > 0, "candump captured no frames")
    c.expect(candump == python,
             f"candump ({len(candump)} frames) and python-can ({len(python)} frames) captures differ"
             + (f" from frame {next((i for i, (a, b) in enumerate(zip(candump, python)) if a != b), min(len(candump), len(python)))}"
                if candump != python else ""))
    samples = (check_dronecan if args.protocol == "dronecan" else check_j1939)(candump, args, c)

    with open(args.emit_stats) as f:
        device = emit_device(json.load(f))
    emitted = device.get("emitted")
    # Ticks emit itself skipped (late wake-ups under UML or TCG are
    # dropped, not sent late): the sample times then jump, counters do not.
    skipped = device.get("ticks", 0) - (emitted or 0)
    listen_samples, summary = read_listen(args.listen)
    c.expect(summary is not None, f"{args.listen}: no summary object from imuemu listen")
    summary = summary or {}
    c.expect(isinstance(emitted, int) and emitted > 0, f"emit stats give no positive 'emitted' count: {device}")
    c.expect(samples == emitted, f"python decoded {samples} samples, emit reports {emitted}")
    c.expect(summary.get("samples") == emitted, f"listen decoded {summary.get('samples')} samples, emit reports {emitted}")
    c.expect(len(listen_samples) == summary.get("samples"),
             f"listen printed {len(listen_samples)} sample lines, its summary says {summary.get('samples')}")
    c.expect(summary.get("can_frames_received") == len(candump),
             f"listen received {summary.get('can_frames_received')} CAN frames, candump {len(candump)}")
    for counter in ("checksum_errors", "sequence_gaps", "other_errors", "can_kernel_drops", "can_frames_other_source",
                    "sequence_backward_steps"):
        c.expect(summary.get(counter) == 0, f"listen {counter} = {summary.get(counter)}, expected 0")
    if args.protocol == "dronecan":
        c.expect(summary.get("own_sequence_gaps") == 0, f"listen own_sequence_gaps = {summary.get('own_sequence_gaps')}")
        sequences = [x.get("sequence") for x in listen_samples]
        c.expect(sequences == list(range(len(sequences))),
                 f"listen's RawIMU sequence (widened transfer ids) is not 0..{len(sequences) - 1}: {sequences[:8]}...")
        # RawIMU timestamp 0 means "unknown" (DSDL): the first sample, at
        # trajectory time 0, comes without a time.
        untimed = [x.get("index") for x in listen_samples if x.get("t_ns") is None]
        c.expect(untimed in ([], [0]), f"listen gave no time for samples {untimed[:5]}")
        if args.rate and untimed in ([], [0]):
            listen_ticks = [0 if x.get("t_ns") is None else round(x["t_ns"] * args.rate / 1e9) for x in listen_samples]
            c.expect(listen_ticks == c.timestamp_ticks, "listen's sample times differ from the RawIMU timestamps decoded here")
    if c.timestamp_ticks is not None:
        # Every tick emit counted was sent (emitted) or skipped (late), so the
        # samples' ticks are distinct, increasing and within 0..ticks-1.
        t = c.timestamp_ticks
        c.expect(all(a < b for a, b in zip(t, t[1:])) and (not t or (t[0] >= 0 and t[-1] < device.get("ticks", 0))),
                 f"sample ticks {t[:3]}...{t[-3:]} not increasing within emit's {device.get('ticks')} ticks")
        c.note(f"sample ticks {t[0] if t else None}..{t[-1] if t else None}: {len(t)} sent, "
               f"{(t[-1] - t[0] + 1 - len(t)) if t else 0} skipped between them")
    transport = device.get("transport", {})
    # emit writes its statistics when the engine has stopped; frames its
    # transport still held then ("queued") are sent as it closes, after the
    # snapshot (seen under QEMU's TCG on a loaded host). Every frame emit
    # offered must have reached candump either way.
    queued = transport.get("queued", 0) or 0
    c.expect(transport.get("frames") == len(candump) and (transport.get("frames_sent") or 0) + queued == len(candump),
             f"emit offered {transport.get('frames')} and sent {transport.get('frames_sent')} frames"
             f" ({queued} still queued when its statistics were written), candump saw {len(candump)}")
    if queued:
        c.note(f"emit's statistics were written with {queued} frames still queued in its transport"
               f" (sent as it closed: candump saw all {len(candump)})")
    if skipped:
        c.note(f"emit skipped {skipped} late ticks of {device.get('ticks')} (dropped_late {device.get('dropped_late')},"
               f" underruns {device.get('underruns')}, not_sent {device.get('not_sent')})")

    for note in c.notes:
        print(f"can_peer {args.protocol}: {note}")
    print(f"can_peer {args.protocol}: candump {len(candump)} frames, python-can {len(python)}, "
          f"listen {summary.get('can_frames_received')} frames / {summary.get('samples')} samples, "
          f"emit {emitted} samples, {transport.get('frames_sent')} frames")
    for failure in c.failures[:20]:
        print(f"can_peer {args.protocol}: FAILED: {failure}")
    if len(c.failures) > 20:
        print(f"can_peer {args.protocol}: ... and {len(c.failures) - 20} more failures")
    return 1 if c.failures else 0


def emit_device(stats):
    """The one device of `imuemu emit --stats-json` (daemon/engine/engine_stats.cpp to_json)."""
    devices = stats.get("devices")
    return devices[0] if isinstance(devices, list) and len(devices) == 1 and isinstance(devices[0], dict) else {}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    cap = sub.add_parser("capture")
    cap.add_argument("--channel", required=True)
    cap.add_argument("--out", required=True, nargs="+", help="one log per run; SIGUSR1 moves to the next")
    chk = sub.add_parser("check")
    chk.add_argument("protocol", choices=["dronecan", "j1939"])
    chk.add_argument("--candump", required=True)
    chk.add_argument("--python", required=True)
    chk.add_argument("--listen", required=True)
    chk.add_argument("--emit-stats", required=True)
    chk.add_argument("--rate", type=float, default=0.0)
    chk.add_argument("--sample-static", action="store_true")
    chk.add_argument("--frd-reference", help="j1939: candump log of a DroneCAN run of the same static IMU")
    chk.add_argument("--node-id", type=int, default=42)
    chk.add_argument("--raw-imu-priority", type=int, default=8)
    chk.add_argument("--node-status-priority", type=int, default=24)
    chk.add_argument("--source-address", type=lambda s: int(s, 0), default=0x80)
    chk.add_argument("--priority", type=int, default=3)
    args = parser.parse_args()
    return capture(args) if args.command == "capture" else check(args)


if __name__ == "__main__":
    sys.exit(main())
