#!/usr/bin/python3
"""Soak of imuemud (issue 13, acceptance 2): two daemons at once, < 60 s.

A. The built-in default scene (config/default.toml: sample flight, ECEF,
   400 Hz native on a pty, loop = true) with the flight shortened from 3600 s
   to 6 s, so that its loop seams (copies 6 + max_gap_s 10 + knot 1 = 17 s
   apart) come at 6 s and 23 s: 40 s of emission cross both and reach the
   third copy.
B. A live UDP scene (flat, 50 Hz poses, 400 Hz native on a pty) bound to
   127.0.0.1 at an ephemeral port chosen at run time, fed by a fault script:
   a 10 m/s circle with garbage datagrams, a stray time jump forward and one
   back, a real forward jump of the sender's clock, a sender restart (time
   and sequence back to 0) and a 179 degree heading glitch.

The emitted streams are decoded from the ptys by this script's own decoder,
written from docs/native-protocol.md (sync, version, length, CRC-32C), not
by imuemu. Checks, all on counts the engine guarantees on any host (a slow
host only skips ticks it is too late for, which the daemon counts):

  * both daemons exit 0 (no crash) and every frame written decodes (no CRC error,
    no resync byte, no non-finite value, no saturated/fault status bit);
  * every frame is on its device's grid: t_ns = T0 + floor(seq * 1e9 / 400)
    (exact rate in the emitted time field), sequence strictly increasing;
    the daemon's emitted counter equals the frames decoded, and its ticks
    add up (emitted + not_sent + underruns + dropped_late);
  * A: the three copies are seen (two seams crossed, each a silent gap);
    every frame is exact (no extrapolated status), and equals bit for bit
    the batch pipeline (`imuemu generate --scene-file`) at the same time;
  * B: no sample beyond the circle's physics: |omega| <= w + 0.05 rad/s,
    |f| <= sqrt((R w^2)^2 + g^2) + 1 m/s^2 for exact frames; flagged ones
    (extrapolated or blended back, only if the sender was late on a busy
    host) within the blend's own bound (see the check);
  * B: every fault counted in `imuemu status`: received = datagrams sent,
    rejected = 5 garbage + 2 strays + 1 glitch, accepted = the rest, no
    duplicate/out_of_order/lost, every accepted pose pushed (none refused
    by the engine), and logged: a line per kind (bad datagram, time jump,
    resync, chart/attitude glitch).

Usage: soak.py IMUEMUD IMUEMU CONFIG_DIR
"""
import argparse
import csv
import json
import math
import multiprocessing
import os
import select
import socket
import struct
import subprocess
import sys
import tempfile
import termios
import time
import tty

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from loopback_checks import crc32c, memory_dir, wait_for_link  # noqa: E402

RATE_HZ = 400
A_SECONDS = 40
B_SECONDS = 36
G = 9.80665
# The live sender's circle (flat NED, level, heading along the track).
RADIUS_M = 50.0
OMEGA_RAD_S = 0.2                  # 10 m/s, 2 m/s^2 centripetal
POSE_PERIOD_S = 0.02
POSES = 1300                       # 26 s of poses


# ---------------------------------------------------------------- native protocol decoder (docs/native-protocol.md)

class NativeDecoder:
    """§6 of docs/native-protocol.md: search A5 5A, check version/flags/length,
    whole frame, CRC; a rejected candidate gives up only its first byte."""

    def __init__(self):
        self.buf = bytearray()
        self.frames = []  # (sequence, t_ns, status, gyro xyz, accel xyz)
        self.resync_bytes = 0
        self.checksum_errors = 0
        self.malformed = 0
        self.non_finite = 0

    def feed(self, data):
        self.buf += data
        b = self.buf
        i = 0
        while True:
            j = b.find(b"\xa5\x5a", i)
            if j < 0:
                keep = len(b) - 1 if b.endswith(b"\xa5") else len(b)
                self.resync_bytes += keep - i
                i = keep
                break
            self.resync_bytes += j - i
            i = j
            if len(b) - i < 6:
                break
            version, flags = b[i + 2], b[i + 3]
            (length,) = struct.unpack_from("<H", b, i + 4)
            if version != 1 or flags & ~1 or length != (116 if flags & 1 else 68):
                self.malformed += 1
                i += 1
                continue
            end = i + 6 + length + 4
            if len(b) < end:
                break
            (crc,) = struct.unpack_from("<I", b, end - 4)
            if crc32c(b[i:end - 4]) != crc:
                self.checksum_errors += 1
                i += 1
                continue
            seq, t_ns, status = struct.unpack_from("<QqI", b, i + 6)
            values = struct.unpack_from("<6d", b, i + 26)
            if not all(math.isfinite(v) for v in values):
                self.non_finite += 1
            self.frames.append((seq, t_ns, status, values[:3], values[3:]))
            i = end
        del b[:i]


def open_pty(path):
    fd = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd, termios.TCSANOW)
    return fd


def capture(opened, stop_at, out_queue):
    """Reads every pty in `opened` ({name: fd}, inherited) until its daemon closes it (or stop_at)."""
    fds = {fd: name for name, fd in opened.items()}
    chunks = {name: [] for name in opened}  # decoded afterwards: reading must keep up with the pty on a busy host
    while fds and time.monotonic() < stop_at:
        ready, _, _ = select.select(list(fds), [], [], 0.5)
        for fd in ready:
            try:
                data = os.read(fd, 65536)
            except BlockingIOError:
                continue
            except OSError:  # EIO: the daemon closed its side
                data = b""
            if not data:
                os.close(fd)
                del fds[fd]
                continue
            chunks[fds[fd]].append(data)
    for fd in fds:
        os.close(fd)
    out = {}
    for name, parts in chunks.items():
        d = NativeDecoder()
        d.feed(b"".join(parts))
        out[name] = (d.frames, d.resync_bytes, d.checksum_errors, d.malformed, d.non_finite)
    out_queue.put(out)


# ---------------------------------------------------------------- the live sender and its faults

def datagram(seq, t_ns, north, east, down, heading_deg, pitch_deg=0.0, roll_deg=0.0):
    """docs/pose-wire-format.md §2: local NED position (kind 2), heading-pitch-roll (kind 0)."""
    body = b"IMUP" + bytes([1, 2, 0, 0]) + struct.pack("<Qq7d", seq & (2**64 - 1), t_ns, north, east, down,
                                                       heading_deg, pitch_deg, roll_deg, 0.0)
    return body + struct.pack("<I", crc32c(body))


def circle(i):
    a = OMEGA_RAD_S * i * POSE_PERIOD_S
    return (RADIUS_M * math.sin(a), RADIUS_M * (1.0 - math.cos(a)), -30.0, math.degrees(a) % 360.0)


# Fault schedule (pose index -> fault), and what each one must count.
GARBAGE_AT, STRAY_FORWARD_AT, STRAY_BACK_AT, JUMP_AT, RESTART_AT, GLITCH_AT = 250, 350, 450, 550, 800, 1000
JUMP_S = 100          # the sender's clock jumps forward for good
STRAY_S = 3600        # a single datagram an hour ahead / behind
GARBAGE = [b"hello", bytes(range(84)), b"\xa5" * 200, b"IMUP\x02" + bytes(79)]


def send_faulty_stream(port, stop, report):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    dest = ("127.0.0.1", port)
    seq = 0
    clock_offset_ns = 1000 * 10**9  # the sender's time of pose 0
    sent = 0
    start = time.monotonic()
    for i in range(POSES):
        if stop.is_set():
            break
        delay = start + i * POSE_PERIOD_S - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        if i == JUMP_AT:
            clock_offset_ns += JUMP_S * 10**9
        if i == RESTART_AT:  # the sender restarts: its time and sequence begin at 0 again
            clock_offset_ns = -i * int(POSE_PERIOD_S * 1e9)
            seq = 0
        t_ns = clock_offset_ns + i * int(POSE_PERIOD_S * 1e9)
        n, e, d, h = circle(i)
        extra = []
        if i == GARBAGE_AT:
            extra = GARBAGE + [datagram(seq, t_ns, n, e, d, h)[:-1] + b"\x00"]  # last: CRC broken
        elif i == STRAY_FORWARD_AT:
            extra = [datagram(seq, t_ns + STRAY_S * 10**9, n, e, d, h)]
        elif i == STRAY_BACK_AT:
            extra = [datagram(seq, t_ns - STRAY_S * 10**9, n, e, d, h)]
        elif i == GLITCH_AT:
            extra = [datagram(seq, t_ns, n, e, d, (h + 179.0) % 360.0)]  # in place of this pose: a 179 deg heading glitch
        for x in extra:
            sock.sendto(x, dest)
            sent += 1
        if i in (STRAY_FORWARD_AT, STRAY_BACK_AT, GLITCH_AT):
            seq += 1  # intact datagrams: they use a sequence number (the broken-CRC one is not intact, reuses it)
        if i == GLITCH_AT:
            continue
        sock.sendto(datagram(seq, t_ns, n, e, d, h), dest)
        seq += 1
        sent += 1
    report.put(sent)


# ---------------------------------------------------------------- checks

def grid_failures(label, frames, stats):
    failures = []
    if not frames:
        return [f"{label}: nothing decoded"]
    seq0, t0 = frames[0][0], frames[0][1]
    base = t0 - (seq0 * 10**9) // RATE_HZ
    previous = None
    for seq, t_ns, status, gyro, accel in frames:
        if t_ns != base + (seq * 10**9) // RATE_HZ:
            failures.append(f"{label}: frame {seq} at {t_ns} ns is not on the {RATE_HZ} Hz grid from {base}")
            break
        if previous is not None and seq <= previous:
            failures.append(f"{label}: sequence {seq} after {previous}")
            break
        previous = seq
        if status & 0b110:
            failures.append(f"{label}: frame {seq} has status {status:#x} (saturated/fault)")
            break
    dev = stats["devices"][0]
    # Frames written before this script opened the pty are not seen; every
    # one after is, so at most the ticks before the first decoded one are
    # missing. A reader too slow for the pty makes the daemon drop frames
    # (counted: transport.dropped_queue_full), never corrupt them.
    # When the daemon exits, Linux hangs up the pty and discards what the
    # reader had not read yet: at most the pty's buffer (64 KiB of tty
    # buffers + 4 KiB line discipline; more would have blocked the writer,
    # counted as dropped_queue_full), and only at the end.
    written = dev["transport"]["frames_sent"]
    tail_allowance = (65536 + 4096) // 78 + 1
    last_written = dev["last_sample_counter"]
    if not (len(frames) <= written <= len(frames) + seq0 + tail_allowance and seq0 <= RATE_HZ
            and frames[-1][0] + tail_allowance >= last_written):
        failures.append(f"{label}: daemon wrote {written} frames to the pty (last {last_written}), decoded "
                        f"{len(frames)} from sequence {seq0} to {frames[-1][0]}")
    if dev["emitted"] != written + dev["transport"]["dropped_queue_full"] + dev["transport"]["dropped_link_down"]:
        failures.append(f"{label}: emitted {dev['emitted']} != written {written} + dropped {dev['transport']}")
    if dev["ticks"] != dev["emitted"] + dev["not_sent"] + dev["underruns"] + dev["dropped_late"]:
        failures.append(f"{label}: ticks {dev['ticks']} != emitted + not_sent + underruns + dropped_late")
    return failures


def norm(v):
    return math.sqrt(sum(x * x for x in v))


def start_daemon(imuemud, scene, work, name, seconds):
    d = os.path.join(work, name)
    os.makedirs(d, exist_ok=True)
    cmd = [imuemud, "--scene", scene, "--pty-link-dir", d, "--control-socket", os.path.join(d, "control.sock"),
           "--seconds", str(seconds), "--stats-json", os.path.join(d, "stats.json"), "--late-ticks", "send"]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True), d


def wait_link(proc, link, name):
    wait_for_link(proc, link, f"{name}: imuemud")


def free_udp_port():
    """An ephemeral port the kernel gives now (never a fixed one)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


LIVE_SCENE = """[scene]
name = "soak-live"
physics = "flat"

[trajectory]
source = "udp:127.0.0.1:{port}"
knot_interval_s = 0.02

[smoothing]
window_s = 0.05
max_gap_s = 1.0

[live]
underrun = "extrapolate"
blend_s = 0.2
margin_s = 0.5

[[imu]]
name = "imu0"
rate_hz = 400
protocol = "native"

[imu.transport]
type = "pty"
link = "/tmp/imuemu/ttySOAK"
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("imuemud")
    ap.add_argument("imuemu")
    ap.add_argument("config_dir")
    a = ap.parse_args()
    failures = []
    wall_start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="imuemu_soak_", dir=memory_dir()) as work:
        with open(os.path.join(a.config_dir, "default.toml")) as f:
            default_text = f.read()
        if "duration_s = 3600" not in default_text:
            print("FAIL: config/default.toml no longer has duration_s = 3600; update this test")
            return 1
        scene_a = os.path.join(work, "default-short.toml")
        with open(scene_a, "w") as f:
            f.write(default_text.replace("duration_s = 3600", "duration_s = 6"))
        daemon_a, dir_a = start_daemon(a.imuemud, scene_a, work, "a", A_SECONDS)
        try:
            wait_link(daemon_a, os.path.join(dir_a, "ttyIMU0"), "default")
        except RuntimeError as e:
            print("FAIL:", e)
            return 1
        # Opened and read at once (frames written before are not seen; a pty
        # nobody reads fills and the daemon drops frames), each by a process
        # of its own: in one with the sender or the decoder it would wait for the GIL.
        frames_q = multiprocessing.Queue()
        stop_reading_at = time.monotonic() + A_SECONDS + 25
        fd_a = open_pty(os.path.join(dir_a, "ttyIMU0"))
        reader_a = multiprocessing.Process(target=capture, args=({"a": fd_a}, stop_reading_at, frames_q), daemon=True)
        reader_a.start()
        os.close(fd_a)

        scene_b = os.path.join(work, "live.toml")
        for attempt in range(3):  # the port chosen may be taken by someone else in between: try another
            port = free_udp_port()
            with open(scene_b, "w") as f:
                f.write(LIVE_SCENE.format(port=port))
            daemon_b, dir_b = start_daemon(a.imuemud, scene_b, work, "b", B_SECONDS)
            try:
                wait_link(daemon_b, os.path.join(dir_b, "ttySOAK"), "live")
                break
            except RuntimeError as e:
                if "cannot bind" not in str(e) or attempt == 2:
                    print("FAIL:", e)
                    daemon_a.kill()
                    return 1
        fd_b = open_pty(os.path.join(dir_b, "ttySOAK"))
        reader_b = multiprocessing.Process(target=capture, args=({"b": fd_b}, stop_reading_at, frames_q), daemon=True)
        reader_b.start()
        os.close(fd_b)

        # The sender too: the GIL would make it late (poses extrapolated).
        stop, sent_q = multiprocessing.Event(), multiprocessing.Queue()
        sender = multiprocessing.Process(target=send_faulty_stream, args=(port, stop, sent_q), daemon=True)
        sender.start()

        # The batch reference of A while the daemons run.
        ref_csv = os.path.join(work, "reference.csv")
        subprocess.run([a.imuemu, "generate", "--scene-file", scene_a, "--imu", "imu0", "--out", ref_csv,
                        "--max-seconds", str(A_SECONDS + 10), "--quiet"], check=True)
        reference = {}
        with open(ref_csv) as f:
            rows = csv.reader(line for line in f if not line.startswith("#"))
            next(rows)
            for r in rows:
                reference[int(r[0])] = tuple(float(x) for x in r[1:7])

        sent = sent_q.get(timeout=60)
        time.sleep(1.0)  # the last poses through the engine
        status = subprocess.run([a.imuemu, "status", "--socket", os.path.join(dir_b, "control.sock"), "--timeout-s", "5"],
                                capture_output=True, text=True)
        if status.returncode != 0:
            failures.append(f"live: imuemu status exited {status.returncode}: {status.stderr.strip()}")
            status_json = None
        else:
            status_json = json.loads(status.stdout).get("engine")  # the daemon's status: the engine's counters

        outs = {}
        for name, proc in (("default", daemon_a), ("live", daemon_b)):
            out, err = proc.communicate(timeout=A_SECONDS + 30)
            outs[name] = err
            if proc.returncode != 0:
                failures.append(f"{name}: imuemud exited {proc.returncode}: {err.strip()[-2000:]}")
        captured = frames_q.get(timeout=30)
        captured.update(frames_q.get(timeout=30))
        reader_a.join(timeout=5)
        reader_b.join(timeout=5)
        stop.set()
        sender.join(timeout=5)
        stats = {}
        for name, d in (("default", dir_a), ("live", dir_b)):
            with open(os.path.join(d, "stats.json")) as f:
                stats[name] = json.load(f)

    for name, key in (("default", "a"), ("live", "b")):
        frames, resync, crc_errors, malformed, non_finite = captured[key]
        if resync or crc_errors or malformed or non_finite:
            failures.append(f"{name}: decoder saw {resync} resync bytes, {crc_errors} CRC errors, "
                            f"{malformed} malformed, {non_finite} non-finite frames")
        failures += grid_failures(name, frames, stats[name])

    # A: three copies (two seams), all exact, equal to the batch pipeline.
    frames_a = captured["a"][0]
    segments = 1 + sum(1 for x, y in zip(frames_a, frames_a[1:]) if y[1] - x[1] > 10 * 10**9)
    if segments < 3:
        failures.append(f"default: {segments} copies of the looped flight seen; expected 3 (two seams crossed)")
    extrapolated_a = sum(1 for fr in frames_a if fr[2] & 1)
    if extrapolated_a:
        failures.append(f"default: {extrapolated_a} frames flagged extrapolated")
    # Copy c of the loop is the flight shifted by c * (6 s + max_gap_s 10 s +
    # knot 1 s): the same knots at shifted times, so the same samples.
    shift_ns = (6 + 10 + 1) * 10**9
    start_a = frames_a[0][1] - (frames_a[0][0] * 10**9) // RATE_HZ if frames_a else 0  # tick 0: the flight's start
    mismatched = [fr for fr in frames_a
                  if reference.get(fr[1] - (fr[1] - start_a) // shift_ns * shift_ns) != tuple(fr[3]) + tuple(fr[4])]
    if mismatched:
        fr = mismatched[0]
        failures.append(f"default: {len(mismatched)} frames differ from the batch pipeline, first at t {fr[1]}: "
                        f"{fr[3]} {fr[4]}")
    live_a = stats["default"]["devices"][0]["live"]
    if live_a["gap_events"] < 2 or live_a["extrapolated"] or live_a["blending"]:
        failures.append(f"default: live counters {live_a}: expected >= 2 gap events, nothing extrapolated or blended")

    # B: physical bounds of the circle, for every frame sent. Exact samples:
    # the circle's own |f| and |omega| plus a margin for the smoother. Flagged
    # ones (status bit 0: extrapolated, or blended back, core/live_emitter.hpp;
    # only when a pose came later than margin_s, i.e. a host too busy for the
    # sender) may also carry the rejoin blend of an extrapolation of length D
    # over T = blend_s: with the circle's |a| = A the extrapolation is off by
    # |e - x| <= A D^2 / 2 and |e' - x'| <= A D, so the blend adds at most
    # A + 2 max(s') A D + max(s'') A D^2 / 2 (max s' = 15/(8T), max s'' =
    # 10/(sqrt(3) T^2) for the quintic smoothstep); D is bounded by the
    # longest run of flagged frames seen.
    frames_b = captured["b"][0]
    accel = RADIUS_M * OMEGA_RAD_S**2
    w_max = OMEGA_RAD_S + 0.05
    f_max = math.hypot(accel, G) + 1.0
    longest, run = 0, 0
    for fr in frames_b:
        run = run + 1 if fr[2] & 1 else 0
        longest = max(longest, run)
    d_s, blend_s = longest / RATE_HZ, 0.2
    f_max_flagged = G + accel * (1 + 2 * 15 / (8 * blend_s) * d_s + 10 / (math.sqrt(3) * blend_s**2) * d_s**2 / 2) + 1.0
    worst_w = max((norm(fr[3]) for fr in frames_b), default=0.0)
    worst_f = max((norm(fr[4]) for fr in frames_b if not fr[2] & 1), default=0.0)
    worst_f_flagged = max((norm(fr[4]) for fr in frames_b if fr[2] & 1), default=0.0)
    if worst_w > w_max or worst_f > f_max or worst_f_flagged > f_max_flagged:
        bad = next(fr for fr in frames_b if norm(fr[3]) > w_max or norm(fr[4]) > (f_max_flagged if fr[2] & 1 else f_max))
        failures.append(f"live: sample beyond the circle's physics: |omega| {worst_w:.4g} (bound {w_max:.4g}) rad/s, "
                        f"|f| {worst_f:.4g} (bound {f_max:.4g}) m/s^2 exact, {worst_f_flagged:.4g} (bound "
                        f"{f_max_flagged:.4g}) flagged after {d_s} s; first at seq {bad[0]} status {bad[2]}")
    if len(frames_b) < RATE_HZ * 10:
        failures.append(f"live: only {len(frames_b)} frames")

    # B: every fault counted (imuemu status) and logged.
    expected_rejected = len(GARBAGE) + 1 + 2 + 1  # garbage + broken CRC, two strays, the glitch
    if status_json is not None:
        ps = status_json.get("pose_source", {})
        want = {"received": sent, "rejected": expected_rejected, "accepted": sent - expected_rejected,
                "duplicate": 0, "out_of_order": 0, "overflow_dropped": 0, "lost": 0,
                "resyncs": 2, "held": 0}  # re-acquired after the clock jump and after the restart
        for k, v in want.items():
            if ps.get(k) != v:
                failures.append(f"live: status pose_source.{k} = {ps.get(k)}, expected {v} (sent {sent})")
        if status_json.get("poses_pushed") != sent - expected_rejected or status_json.get("poses_refused") != 0:
            failures.append(f"live: status poses_pushed {status_json.get('poses_pushed')} poses_refused "
                            f"{status_json.get('poses_refused')}: every accepted pose must reach the engine")
    log_b = outs["live"]
    for what, text in (("bad datagram", "dropped datagram ("), ("stray time jump", "held until 2 consistent poses"),
                       ("resync (jump and restart)", "stream re-acquired"), ("179 deg glitch", "a glitch")):
        if text not in log_b:
            failures.append(f"live: no log line for the {what} ('{text}')")
    resyncs = log_b.count("stream re-acquired")
    if resyncs < 2:
        failures.append(f"live: {resyncs} resync log lines; expected one for the jump and one for the restart")

    dev_b = stats["live"]["devices"][0]
    print(json.dumps({"default": {"frames": len(frames_a), "copies_seen": segments, "live": live_a,
                                  "not_sent": stats["default"]["devices"][0]["not_sent"],
                                  "underruns": stats["default"]["devices"][0]["underruns"]},
                      "live": {"frames": len(frames_b), "datagrams_sent": sent,
                               "pose_source": status_json.get("pose_source") if status_json else None,
                               "samples": dev_b["samples"], "live": dev_b["live"], "not_sent": dev_b["not_sent"],
                               "underruns": dev_b["underruns"], "worst_omega_rad_s": worst_w, "worst_f_m_s2": worst_f,
                               "worst_f_flagged_m_s2": worst_f_flagged, "longest_flagged_s": d_s,
                               "transport": dev_b["transport"]},
                      "wall_s": round(time.monotonic() - wall_start, 1)}))
    for f in failures:
        print("FAIL:", f)
    print("soak:", "FAILED" if failures else "passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
