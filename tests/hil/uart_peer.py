#!/usr/bin/python3
"""Host side of the QEMU UART tests: boots tests/hil/qemu_run.sh with the
guest's /dev/ttyS1 (Debian's kernel, the real 8250 driver on an emulated
16550A) on a unix socket, plays the far end of that UART, and decodes what
the guest's `imuemu emit --device serial:/dev/ttyS1,...` sent with the
host's own `imuemu listen`, fed live through a FIFO.

  uart_peer.py uart --imuemu PATH [--results DIR]
      hil_uart_mavlink_mip_qemu: guest tests/hil/uart_emit_guest.sh emits
      mavlink2, then mip (static IMU, 200 Hz, 921600 baud). Per run:
      listen's checksum errors, resync bytes, malformed frames, sequence gaps
      (MAVLink's seq) all 0; listen's samples = the samples emit reports;
      bytes listen read = bytes the host received between the run's markers =
      bytes emit's transport reports sent; the decoded sample times on the
      output grid (mavlink2's time_usec; mip's GPS time) and the static IMU's
      specific force ~1 g. The bytes are also decoded here, from the protocol
      documents (every byte in a packet, MAVLink X.25 CRCs with CRC_EXTRA and
      consecutive packet sequence, MIP Fletcher checksums, IMU packets = emit's
      samples, accelerometer ~1 g in m/s^2 resp. g). Then PX4's microstrain
      start-up (Px4Run), then the VectorNav, SBG and Xsens devices at 921600
      baud with the same checks (their frames' CRCs and checksums decoded
      here from the manuals, one IMU packet per sample).

  uart_peer.py gpio --imuemu PATH [--results DIR]
      hil_gpio_sync_qemu: guest tests/hil/gpio_sync_guest.sh emits native
      samples on ttyS1 with a sync pulse every N samples on the gpio_recorder
      chip, active high on line 0, then active low on line 1. From the
      recorder's kernel-timestamped log: the idle level and polarity; one
      pulse per sent sample whose native counter (decoded by listen; the
      counters are the samples' tick indices) is a multiple of N, i.e.
      ceil(samples / N) when emit skipped no tick, and the pulse count emit
      reports; each width >= the configured width and below half the pulse
      period; the k-th leading edge lines up with its sample's counter x
      period (within the emission lateness); the mean spacing.

The guest separates its runs on the UART with ASCII markers carrying a
random token of this run ("HILSEP:<token>:BEGIN:<name>:<protocol>;" and
"HILSEP:<token>:END;"), so one boot serves several runs; bytes outside a run
fail the test. Standard library only. Exit 0 on success, 1 on a failed
check, the fixture's 125 when the fixture itself failed (never skipped).
"""
import argparse
import json
import math
import os
import secrets
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
FIXTURE_FAILURE = 125


def log(message):
    print(f"uart_peer: {message}", flush=True)


class Run:
    """One emit run as the host saw it: its bytes go live into a FIFO that
    `imuemu listen` reads."""

    def __init__(self, name, protocol, imuemu, results):
        self.name, self.protocol = name, protocol
        self.bytes = 0
        self.wire = bytearray()  # the run's bytes, for the independent decoding here
        self.listen_path = os.path.join(results, f"{name}.listen.ndjson")
        self.fifo = os.path.join(results, f"{name}.fifo")
        if os.path.exists(self.fifo):
            os.unlink(self.fifo)
        os.mkfifo(self.fifo)
        with open(self.listen_path, "w") as out, open(os.path.join(results, f"{name}.listen.err"), "w") as err:
            self.listen = subprocess.Popen(
                [imuemu, "listen", "--protocol", protocol, "--device", self.fifo, "--json"],
                stdout=out, stderr=err)
        self.fd = self._open_writer()
        self.write_error = None

    def _open_writer(self):
        # listen opens the FIFO for reading (non-blocking); until it has, an
        # O_NONBLOCK writer's open fails with ENXIO.
        deadline = time.monotonic() + 30
        while True:
            try:
                fd = os.open(self.fifo, os.O_WRONLY | os.O_NONBLOCK)
                os.set_blocking(fd, True)
                return fd
            except OSError:
                if self.listen.poll() is not None or time.monotonic() > deadline:
                    self.listen.kill()
                    raise RuntimeError(f"imuemu listen never opened {self.fifo} (status {self.listen.poll()})")
                time.sleep(0.02)

    def write(self, data):
        self.bytes += len(data)
        self.wire += data
        if self.fd is None or not data:
            return
        try:
            os.write(self.fd, data)  # blocking: a slow listen holds the UART back, nothing is lost
        except OSError as e:
            self.write_error = f"writing to imuemu listen: {e}"
            os.close(self.fd)
            self.fd = None

    def finish(self):
        with open(os.path.join(os.path.dirname(self.fifo), f"{self.name}.wire.bin"), "wb") as f:
            f.write(self.wire)
        if self.fd is not None:
            os.close(self.fd)  # end of stream for listen
            self.fd = None
        try:
            rc = self.listen.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.listen.kill()
            rc = self.listen.wait()
        os.unlink(self.fifo)
        samples, summary = [], None
        with open(self.listen_path) as f:
            for line in f:
                if not line.strip():
                    continue
                obj = json.loads(line)
                if obj.get("type") == "sample":
                    samples.append(obj)
                elif obj.get("type") == "summary":
                    summary = obj
        self.listen_rc, self.samples, self.summary = rc, samples, summary or {}


# ---------------------------------------------------------------- PX4 replay
# MIP packets written here from the 3DM-GX5 / 3DM-CV7 DCP manuals ("MIP
# packet overview", "Command and data packets"): 0x75 0x65, descriptor set,
# payload length, fields (length, descriptor, data), Fletcher-16 over header
# and payload (two 8-bit running sums, sum1 sent first). A reply's first field
# is the ACK/NACK (0x04, 0xF1, the echoed command descriptor, error code: 0
# ACK, 3 invalid parameter).


def mip_packet(descriptor_set, *fields):
    body = bytes([0x75, 0x65, descriptor_set, sum(len(f) for f in fields)]) + b"".join(bytes(f) for f in fields)
    sum1 = sum2 = 0
    for byte in body:
        sum1 = (sum1 + byte) & 0xFF
        sum2 = (sum2 + sum1) & 0xFF
    return body + bytes([sum1, sum2])


def mip_ack(command, code=0):
    return bytes([0x04, 0xF1, command, code])


def mip_fields(packet):
    """[(descriptor, data)] of a whole packet."""
    out, at = [], 4
    while at + 2 <= len(packet) - 2 and packet[at] >= 2:
        out.append((packet[at + 1], bytes(packet[at + 2:at + packet[at]])))
        at += packet[at]
    return out


PX4_IMU_RATE_HZ = 500  # PX4 module.yaml MS_IMU_RATE_HZ default
# The 16-bit descriptors (set << 8 | field) PX4's initializeIns() looks up in
# the Get Device Descriptors reply before it uses them.
PX4_NEEDED_DESCRIPTORS = [0x0109, 0x0C0E, 0x0C0F, 0x0D01, 0x0C11, 0x0106, 0x8004, 0x8005]
PX4_STREAM_PACKETS = 200  # 0x80 packets decoded after Resume before the replay ends


class Px4Run:
    """The host as PX4's microstrain driver (PX4-Autopilot 00c59fa5080c,
    src/drivers/ins/microstrain/MicroStrain.cpp initializeIns(), module.yaml
    defaults; the same sequence as tests/device/test_mip_device.cpp
    Px4MicrostrainStartUpReplayGetsEveryAckItWaitsFor): each command is sent
    when the previous one's reply arrived, and each reply must be the one the
    driver waits for. After the Comm Port Speed ACK the driver reopens its
    port at 921600; here the far end is QEMU's socket chardev, which carries
    bytes at any rate, so "switching" is bookkeeping: every byte after the
    ACK must still be part of a valid MIP packet, and the guest's side
    (px4.speed.txt, the QEMU trace) shows the rate the 8250 was set to.
    PX4's 250-ms reply timeout is not kept under TCG (REPLY_TIMEOUT_S)."""

    REPLY_TIMEOUT_S = 15.0

    def __init__(self, name, send, results):
        self.name, self.protocol, self.send, self.results = name, "mip-px4", send, results
        self.bytes = 0
        self.wire = bytearray()
        self.buffer = bytearray()
        self.garbage = 0
        self.steps = self._steps()
        self.step = -1  # -1: waiting for the device's first packet
        self.sent_at = None
        self.replies = []  # (label, command bytes, reply bytes, verdict or None)
        self.failures = []
        self.base_rate = None
        self.switched_at_byte = None  # wire offset after the Comm Port Speed ACK
        self.data_packets = []  # (wire offset, step index when it arrived, field descriptors, accel g)
        self.stream_after_resume = 0
        self.done = False
        self.first_sent = self.last_reply = None

    def _steps(self):
        idle = ("Set To Idle (0x01,0x02)", 0x01, [0x02, 0x02], self._exact(0x01, mip_ack(0x02)))
        return [
            # connectAtBaud(115200) -> forceIdle
            idle,
            # getSupportedDescriptors: both lists
            ("Get Device Descriptors (0x01,0x04)", 0x01, [0x02, 0x04], self._descriptors),
            ("Get Extended Descriptors (0x01,0x07)", 0x01, [0x02, 0x07], self._ack_then(0x01, 0x07, 0x86)),
            # writeBaudRate(921600, port 1): Comm Port Speed, function 1 (write), port 1, u32 BE
            ("Comm Port Speed 921600 (0x01,0x09)", 0x01, [0x08, 0x09, 0x01, 0x01, *921600 .to_bytes(4, "big")],
             self._exact(0x01, mip_ack(0x09))),
            # connectAtBaud(921600) -> forceIdle
            ("at 921600: " + idle[0], *idle[1:]),
            # configureImuMessageFormat: base rate of 0x80, then accel + gyro
            ("Get Base Rate 0x80 (0x0C,0x0E)", 0x0C, [0x03, 0x0E, 0x80], self._base_rate(0x80)),
            ("Message Format 0x80 accel+gyro (0x0C,0x0F)", 0x0C, None, self._exact(0x0C, mip_ack(0x0F))),
            # configureFilterMessageFormat: base rate of 0x82, then no field
            ("Get Base Rate 0x82 (0x0C,0x0E)", 0x0C, [0x03, 0x0E, 0x82], self._base_rate(0x82)),
            ("Message Format 0x82, no field (0x0C,0x0F)", 0x0C, [0x05, 0x0F, 0x01, 0x82, 0x00],
             self._exact(0x0C, mip_ack(0x0F))),
            # configureGnssMessageFormat(0x91 / 0x92): NACK invalid parameter, which PX4 tolerates
            ("Get Base Rate 0x91 (0x0C,0x0E)", 0x0C, [0x03, 0x0E, 0x91], self._exact(0x0C, mip_ack(0x0E, 0x03))),
            ("Get Base Rate 0x92 (0x0C,0x0E)", 0x0C, [0x03, 0x0E, 0x92], self._exact(0x0C, mip_ack(0x0E, 0x03))),
            ("Reset Filter (0x0D,0x01)", 0x0D, [0x02, 0x01], self._exact(0x0D, mip_ack(0x01))),
            ("Datastream Control all on (0x0C,0x11)", 0x0C, [0x05, 0x11, 0x01, 0x00, 0x01],
             self._exact(0x0C, mip_ack(0x11))),
            ("Resume (0x01,0x06)", 0x01, [0x02, 0x06], self._exact(0x01, mip_ack(0x06))),
            # Not PX4's: after the stream check, the device's own word on its rate.
            ("(check) read Comm Port Speed port 1 (0x01,0x09)", 0x01, [0x04, 0x09, 0x02, 0x01],
             self._exact(0x01, mip_ack(0x09), bytes([0x07, 0x89, 0x01, *921600 .to_bytes(4, "big")]))),
        ]

    # -- reply checks: return None when the reply is the one expected, else why not
    @staticmethod
    def _exact(descriptor_set, *fields):
        want = mip_packet(descriptor_set, *fields)
        return lambda reply: None if reply == want else f"expected {want.hex(' ')}"

    @staticmethod
    def _ack_then(descriptor_set, command, reply_field):
        def check(reply):
            fields = mip_fields(reply)
            if reply[2] != descriptor_set or not fields or fields[0] != (0xF1, bytes([command, 0])):
                return f"no ACK of {command:#04x}"
            return None if any(d == reply_field for d, _ in fields[1:]) else f"no reply field {reply_field:#04x}"
        return check

    def _descriptors(self, reply):
        why = self._ack_then(0x01, 0x04, 0x82)(reply)
        if why:
            return why
        data = b"".join(d for f, d in mip_fields(reply) if f == 0x82)
        listed = {int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data) - 1, 2)}
        missing = [f"{d:#06x}" for d in PX4_NEEDED_DESCRIPTORS if d not in listed]
        return f"descriptors PX4 needs are not listed: {missing}" if missing else None

    def _base_rate(self, data_set):
        def check(reply):
            fields = mip_fields(reply)
            if reply[2] != 0x0C or len(fields) != 2 or fields[0] != (0xF1, bytes([0x0E, 0])) or \
                    fields[1][0] != 0x8E or len(fields[1][1]) != 3 or fields[1][1][0] != data_set:
                return "expected ACK and field 0x8E (set, u16 rate)"
            rate = int.from_bytes(fields[1][1][1:3], "big")
            if data_set == 0x80:
                self.base_rate = rate
            return None if rate > 0 else "base rate 0"
        return check

    def _command(self, index):
        label, descriptor_set, field, _ = self.steps[index]
        if field is None:  # Message Format 0x80: write, set 0x80, 2 descriptors at base_rate / MS_IMU_RATE_HZ
            decimation = (self.base_rate or 0) // PX4_IMU_RATE_HZ
            field = [0x0B, 0x0F, 0x01, 0x80, 0x02, 0x04, *decimation.to_bytes(2, "big"), 0x05,
                     *decimation.to_bytes(2, "big")]
        return mip_packet(descriptor_set, field)

    def _send_step(self, index):
        self.step = index
        command = self._command(index)
        self.replies.append([self.steps[index][0], command, None, None])
        self.sent_at = time.monotonic()
        self.first_sent = self.first_sent or self.sent_at
        try:
            self.send(command)
        except OSError as e:  # QEMU gone: the guest's side ended (its output says why)
            self.failures.append(f"{self.steps[index][0]}: cannot send: {e}")
            self.done = True

    # -- the byte stream
    def write(self, data):
        self.bytes += len(data)
        self.wire += data
        self.buffer += data
        offset = len(self.wire) - len(self.buffer)
        while len(self.buffer) >= 6:
            if self.buffer[0] != 0x75 or self.buffer[1] != 0x65:
                self.garbage += 1
                del self.buffer[0]
                offset += 1
                continue
            total = 4 + self.buffer[3] + 2
            if len(self.buffer) < total:
                break
            packet = bytes(self.buffer[:total])
            if mip_packet(packet[2], packet[4:-2]) != packet:
                self.garbage += 1  # not a packet: resync one byte on
                del self.buffer[0]
                offset += 1
                continue
            del self.buffer[:total]
            self.on_packet(packet, offset)
            offset += total

    def on_packet(self, packet, offset):
        if packet[2] == 0x80:
            fields = mip_fields(packet)
            accel = next((struct.unpack(">3f", d) for f, d in fields if f == 0x04 and len(d) == 12), None)
            self.data_packets.append((offset, self.step, [f for f, _ in fields], accel))
            if self.step == -1:
                self._send_step(0)  # the device is up: the driver starts
            elif self.steps[self.step][0].startswith("Resume") and self.replies[-1][3] is None \
                    and self.replies[-1][2] is not None:
                self.stream_after_resume += 1
                if self.stream_after_resume == PX4_STREAM_PACKETS:
                    self._send_step(self.step + 1)
            return
        if self.step < 0 or self.replies[-1][2] is not None:
            self.failures.append(f"an unasked packet {packet.hex(' ')}")
            return
        record = self.replies[-1]
        record[2] = packet
        self.last_reply = time.monotonic()
        why = self.steps[self.step][3](packet)
        record[3] = why
        log(f"px4: {record[0]}: sent {record[1].hex(' ')} -> {packet.hex(' ')}"
            f"{'' if why is None else '  FAILED: ' + why}")
        if why is not None:
            self.failures.append(f"{record[0]}: reply {packet.hex(' ')}: {why}")
            self.done = True
            return
        if self.steps[self.step][0].startswith("Comm Port Speed"):
            self.switched_at_byte = offset + len(packet)
            log("px4: the driver switches its side to 921600 baud now (bookkeeping on the socket chardev)")
        if self.steps[self.step][0].startswith("Resume"):
            return  # the stream check sends the next one
        if self.step + 1 < len(self.steps):
            self._send_step(self.step + 1)
        else:
            self.done = True

    def tick(self):
        if self.done or self.sent_at is None or self.replies[-1][2] is not None:
            return
        if time.monotonic() - self.sent_at > self.REPLY_TIMEOUT_S:
            self.failures.append(f"{self.replies[-1][0]}: no reply within {self.REPLY_TIMEOUT_S} s")
            log(f"px4: FAILED: {self.failures[-1]}")
            self.done = True

    def finish(self):
        with open(os.path.join(self.results, f"{self.name}.wire.bin"), "wb") as f:
            f.write(self.wire)


class Splitter:
    """Cuts the UART byte stream at the guest's markers."""

    def __init__(self, token, imuemu, results):
        self.prefix = b"HILSEP:" + token.encode() + b":"
        self.imuemu, self.results = imuemu, results
        self.send = None  # writes to the guest's ttyS1 (set once connected)
        self.buffer = b""
        self.current = None
        self.runs = []
        self.stray_bytes = 0
        self.ended = False

    def _data(self, data):
        if self.current is not None:
            self.current.write(data)
        else:
            self.stray_bytes += len(data)

    def feed(self, chunk):
        self.buffer += chunk
        while True:
            at = self.buffer.find(self.prefix)
            if at < 0:
                # Hold back only a tail that could be the start of a marker
                # cut by the chunking: an interactive run (Px4Run) must see a
                # reply's last bytes at once, not when more bytes follow.
                keep = next((n for n in range(min(len(self.prefix) - 1, len(self.buffer)), 0, -1)
                             if self.prefix.startswith(self.buffer[-n:])), 0)
                self._data(self.buffer[:len(self.buffer) - keep])
                self.buffer = self.buffer[len(self.buffer) - keep:]
                return
            self._data(self.buffer[:at])
            end = self.buffer.find(b";", at)
            if end < 0:
                self.buffer = self.buffer[at:]
                return
            marker = self.buffer[at + len(self.prefix):end].decode(errors="replace").split(":")
            self.buffer = self.buffer[end + 1:]
            if self.current is not None:
                self.current.finish()
                self.current = None
            if marker[0] == "BEGIN" and len(marker) == 3:
                log(f"run {marker[1]}: {marker[2]} begins")
                if marker[2] == "mip-px4":
                    self.current = Px4Run(marker[1], self.send, self.results)
                else:
                    self.current = Run(marker[1], marker[2], self.imuemu, self.results)
                self.runs.append(self.current)
            elif marker == ["END"]:
                self.ended = True
            else:
                raise RuntimeError(f"unknown marker {marker}")

    def tick(self):
        """Lets an interactive run (a driver replay) send and time out."""
        if self.current is not None and hasattr(self.current, "tick"):
            self.current.tick()

    def close(self):
        self._data(self.buffer)
        self.buffer = b""
        if self.current is not None:
            self.current.finish()
            self.current = None


def connect(path, fixture, deadline):
    """QEMU creates the socket once the cached kernel and initramfs are
    ready (minutes on a first run that downloads the kernel) and waits."""
    while time.monotonic() < deadline:
        if fixture.poll() is not None:
            return None
        if os.path.exists(path):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                s.connect(path)
                return s
            except OSError:
                s.close()
        time.sleep(0.05)
    return None


def boot_and_capture(guest, imuemu, results, token, guest_args=(), extra_includes=(), fixture_args=()):
    """Runs the guest script under qemu_run.sh; returns (fixture status, splitter)."""
    with tempfile.TemporaryDirectory(prefix="hil_uart.") as tmp:
        sock_path = os.path.join(tmp, "ttyS1.sock")
        includes = [imuemu, guest, *extra_includes]
        command = [os.path.join(HERE, "qemu_run.sh"), "--serial1", f"socket,path={sock_path},server=on,wait=on",
                   "--results", results, "--timeout", "200", *fixture_args]
        for path in includes:
            command += ["--include", path]
        command += ["--", "sh", guest, imuemu, token, *map(str, guest_args)]
        fixture = subprocess.Popen(command)
        s = connect(sock_path, fixture, time.monotonic() + 250)
        splitter = Splitter(token, imuemu, results)
        if s is None:
            fixture.kill()
            rc = fixture.wait()
            log(f"never connected to {sock_path} (fixture status {rc})")
            return FIXTURE_FAILURE, splitter
        splitter.send = s.sendall
        try:
            with s:
                # Short reads, so an interactive run (Px4Run) can time out.
                s.settimeout(0.05)
                last = time.monotonic()
                while True:
                    try:
                        chunk = s.recv(65536)
                    except ConnectionResetError:
                        # QEMU exited with bytes of ours it never read (a
                        # command the guest did not take): the results say why.
                        log("ttyS1: connection reset by QEMU (it exited with unread bytes from the host)")
                        break
                    except socket.timeout:
                        splitter.tick()
                        if time.monotonic() - last > 200:
                            log("no bytes on ttyS1 for 200 s")
                            break
                        continue
                    if not chunk:
                        break  # QEMU exited
                    last = time.monotonic()
                    splitter.feed(chunk)
                    splitter.tick()
            splitter.close()
            return fixture.wait(timeout=60), splitter
        finally:
            if fixture.poll() is None:  # a failure here must not leave QEMU running
                fixture.terminate()
                fixture.wait()


# ---------------------------------------------------------------- checks


class Checks:
    def __init__(self):
        self.failures = []

    def expect(self, ok, message):
        if not ok:
            self.failures.append(message)
            log(f"FAILED: {message}")
        return ok


def emit_stats(results, name):
    path = os.path.join(results, f"{name}.emit.json")
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        return {"_error": f"{path}: {e}"}


def emit_device(stats):
    """The one device of `imuemu emit --stats-json` (daemon/engine/engine_stats.cpp to_json)."""
    devices = stats.get("devices")
    return devices[0] if isinstance(devices, list) and len(devices) == 1 and isinstance(devices[0], dict) else {}


def check_stream_run(run, results, rate_hz, c, static=True):
    """What every byte-stream run must show; returns emit's device stats."""
    stats = emit_stats(results, run.name)
    device = emit_device(stats)
    s = run.summary
    emitted = device.get("emitted")
    # Ticks emit itself skipped (a wake-up more than a period late is dropped,
    # not sent late): sample times and native counters jump by them.
    skipped = device.get("ticks", 0) - (emitted or 0)
    tag = f"{run.name} ({run.protocol})"
    c.expect(run.write_error is None, f"{tag}: {run.write_error}")
    c.expect(run.listen_rc == 0, f"{tag}: imuemu listen exited with {run.listen_rc}")
    c.expect(s.get("end_reason") == "end of stream", f"{tag}: listen ended with '{s.get('end_reason')}'")
    c.expect(isinstance(emitted, int) and emitted > 0, f"{tag}: emit stats give no positive 'emitted' count: {stats}")
    c.expect(s.get("samples") == emitted, f"{tag}: listen decoded {s.get('samples')} samples, emit reports {emitted}")
    c.expect(len(run.samples) == s.get("samples"),
             f"{tag}: {len(run.samples)} sample lines, listen's summary says {s.get('samples')}")
    c.expect(s.get("bytes_received") == run.bytes,
             f"{tag}: listen read {s.get('bytes_received')} bytes, the host received {run.bytes}")
    transport = device.get("transport", {})
    c.expect(transport.get("frames") == transport.get("frames_sent") and device.get("bytes") == run.bytes,
             f"{tag}: emit offered {transport.get('frames')} frames ({device.get('bytes')} bytes) and sent "
             f"{transport.get('frames_sent')}; the host received {run.bytes} bytes through ttyS1")
    for counter in ("checksum_errors", "resync_bytes", "other_errors", "sequence_backward_steps"):
        c.expect(s.get(counter) == 0, f"{tag}: listen {counter} = {s.get(counter)}, expected 0")
    if run.protocol != "native":  # native: checked against the skipped ticks below
        c.expect(s.get("sequence_gaps") == 0, f"{tag}: listen sequence_gaps = {s.get('sequence_gaps')}, expected 0")
    if s.get("own_sequence_gaps") is not None and run.protocol != "native":
        # MAVLink's seq counts packets, which skipped ticks do not interrupt.
        c.expect(s["own_sequence_gaps"] == 0, f"{tag}: listen own_sequence_gaps = {s['own_sequence_gaps']}, expected 0")
    times = [x["t_ns"] for x in run.samples if x.get("t_ns") is not None]
    period_ns = 1e9 / rate_hz
    if c.expect(len(times) == len(run.samples), f"{tag}: {len(run.samples) - len(times)} samples without a time"):
        # Tick k of the output grid is at k periods of trajectory time (the
        # grid starts at 0), to the wire's time resolution (1 us MAVLink, GPS
        # time for MIP): the times name which ticks were sent, and every tick
        # emit counted was either sent or skipped.
        off_grid = [t for t in times if abs(t / period_ns - round(t / period_ns)) * period_ns > 1000]
        c.expect(not off_grid, f"{tag}: sample times off the {period_ns:.0f} ns grid: {off_grid[:5]}")
        ticks = [round(t / period_ns) for t in times]
        c.expect(all(a < b for a, b in zip(ticks, ticks[1:])) and
                 (not ticks or (ticks[0] >= 0 and ticks[-1] < device.get("ticks", 0))),
                 f"{tag}: sample ticks {ticks[:3]}...{ticks[-3:]} not increasing within emit's {device.get('ticks')} ticks")
        if run.protocol == "native":
            # The native frame's counter is the sample counter: the tick index
            # (so skipped ticks show as gaps, and as nothing else).
            sequences = [x.get("sequence") for x in run.samples]
            c.expect(sequences == ticks, f"{tag}: native sample counters are not the samples' tick indices")
            inner_skipped = ticks[-1] - ticks[0] + 1 - len(ticks) if ticks else 0
            for counter in ("sequence_gaps", "own_sequence_gaps"):
                c.expect(s.get(counter) == inner_skipped,
                         f"{tag}: listen {counter} = {s.get(counter)}, {inner_skipped} ticks skipped between samples")
    if static:
        for x in run.samples:
            a = x["accel_m_s2"]
            norm = math.sqrt(sum(v * v for v in a))
            if not c.expect(9.7 < norm < 9.9 and a[2] < -9.6,
                            f"{tag}: sample {x['index']}: static specific force {a} m/s^2, expected ~1 g up (FRD z < -9.6)"):
                break
    log(f"{tag}: host received {run.bytes} bytes, listen {s.get('samples')} samples "
        f"({s.get('frames')} frames, checksum errors {s.get('checksum_errors')}, sequence gaps "
        f"{s.get('sequence_gaps')}), emit {emitted} samples, {device.get('bytes')} bytes, {skipped} ticks skipped")
    return device


# ---------------------------------------------------------------- wire decoding
# Independent of imuemu's decoders: written from the protocol documents.

# MAVLink 2 (mavlink.io "Serialization"): 0xFD, len, incompat, compat, seq,
# sysid, compid, msgid (3 LE), payload (trailing zeros truncated), CRC-16/
# MCRF4XX (X.25) over len..payload then CRC_EXTRA, little-endian. CRC_EXTRA
# from common.xml as pymavlink generates it.
MAVLINK_CRC_EXTRA = {0: 50, 105: 93, 107: 108}  # HEARTBEAT, HIGHRES_IMU, HIL_SENSOR


def x25_crc(data, crc=0xFFFF):
    for byte in data:
        tmp = (byte ^ crc) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def check_mavlink_wire(run, emitted, c):
    tag = f"{run.name} (mavlink2, decoded here)"
    wire, at, seqs, msgids, accels = bytes(run.wire), 0, [], [], []
    while at < len(wire):
        if not c.expect(wire[at] == 0xFD and at + 12 <= len(wire), f"{tag}: no MAVLink 2 packet at byte {at}"):
            return
        length, incompat = wire[at + 1], wire[at + 2]
        end = at + 10 + length + 2 + (13 if incompat & 1 else 0)
        if not c.expect(end <= len(wire), f"{tag}: packet at byte {at} runs past the end"):
            return
        msgid = int.from_bytes(wire[at + 7:at + 10], "little")
        payload = wire[at + 10:at + 10 + length]
        crc = int.from_bytes(wire[at + 10 + length:at + 12 + length], "little")
        if not c.expect(msgid in MAVLINK_CRC_EXTRA, f"{tag}: unexpected message id {msgid} at byte {at}"):
            return
        c.expect(x25_crc(bytes([MAVLINK_CRC_EXTRA[msgid]]), x25_crc(wire[at + 1:at + 10 + length])) == crc,
                 f"{tag}: CRC mismatch in message {msgid} at byte {at}")
        seqs.append(wire[at + 4])
        msgids.append(msgid)
        if msgid in (105, 107):  # time_usec u64, then xacc, yacc, zacc float32 (m/s^2)
            full = payload + bytes(max(0, 20 - len(payload)))
            accels.append(struct.unpack_from("<3f", full, 8))
        at = end
    c.expect(all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:])), f"{tag}: packet sequence numbers not consecutive")
    samples = sum(1 for m in msgids if m != 0)
    c.expect(samples == emitted, f"{tag}: {samples} IMU messages, emit reports {emitted}")
    c.expect(0 in msgids, f"{tag}: no HEARTBEAT")
    bad = [a for a in accels if not 9.7 < math.sqrt(sum(v * v for v in a)) < 9.9]
    c.expect(not bad, f"{tag}: static specific force not ~1 g: {bad[:3]}")
    log(f"{tag}: {len(msgids)} packets, {samples} IMU messages "
        f"({sorted(set(msgids))}), {msgids.count(0)} HEARTBEAT")


# MIP (3DM-GX5 DCP manual, "MIP packet overview"): 0x75 0x65, descriptor set,
# payload length, fields (length, descriptor, data), Fletcher-16 over header
# and payload (two 8-bit running sums, sent MSB first). Data set 0x80 field
# 0x04 is the scaled accelerometer, 3 big-endian float32 in g.
def check_mip_wire(run, emitted, c):
    tag = f"{run.name} (mip, decoded here)"
    wire, at, samples, accels = bytes(run.wire), 0, 0, []
    while at < len(wire):
        if not c.expect(wire[at:at + 2] == b"\x75\x65" and at + 6 <= len(wire), f"{tag}: no MIP packet at byte {at}"):
            return
        end = at + 4 + wire[at + 3] + 2
        if not c.expect(end <= len(wire), f"{tag}: packet at byte {at} runs past the end"):
            return
        sum1 = sum2 = 0
        for byte in wire[at:end - 2]:
            sum1 = (sum1 + byte) & 0xFF
            sum2 = (sum2 + sum1) & 0xFF
        c.expect(wire[end - 2] == sum1 and wire[end - 1] == sum2, f"{tag}: Fletcher checksum mismatch at byte {at}")
        if c.expect(wire[at + 2] == 0x80, f"{tag}: descriptor set {wire[at + 2]:#x}, expected 0x80 at byte {at}"):
            samples += 1
            field = at + 4
            while field < end - 2:
                if wire[field + 1] == 0x04 and wire[field] == 14:
                    accels.append(struct.unpack_from(">3f", wire, field + 2))
                field += max(wire[field], 2)
        at = end
    c.expect(samples == emitted, f"{tag}: {samples} 0x80 packets, emit reports {emitted}")
    c.expect(len(accels) == samples, f"{tag}: {samples - len(accels)} packets without the scaled accelerometer (0x04)")
    bad = [a for a in accels if not 0.985 < math.sqrt(sum(v * v for v in a)) < 1.01]
    c.expect(not bad, f"{tag}: static scaled accelerometer not ~1 g: {bad[:3]}")
    log(f"{tag}: {samples} packets, first scaled accelerometer {accels[0] if accels else None} g")


# VectorNav binary output (VN-100 / VN-200 / VN-300 user manuals, "Binary
# output", written from them): 0xFA, the groups byte, one little-endian uint16
# field mask per group present, the fields in bit order, CRC-16/CCITT (poly
# 0x1021, init 0) over everything after 0xFA, sent big-endian, so the CRC of
# the packet after 0xFA including it is 0. Sizes of the common group (group
# 1) fields by bit: TimeStartup, TimeGps, TimeSyncIn 8; YawPitchRoll 12;
# Quaternion 16; AngularRate 12; Position 24; Velocity 12; Accel 12; Imu 24;
# MagPres 20; DeltaTheta 28; InsStatus 2; SyncInCnt 4; TimeGpsPps 8.
VN_COMMON_FIELD_BYTES = [8, 8, 8, 12, 16, 12, 24, 12, 12, 24, 20, 28, 2, 4, 8]


def crc_ccitt(data, crc=0):
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
    return crc


def check_vectornav_wire(run, emitted, c):
    tag = f"{run.name} (vectornav binary output, decoded here)"
    wire, at, packets, accels = bytes(run.wire), 0, 0, []
    while at < len(wire):
        if not c.expect(wire[at] == 0xFA and at + 4 <= len(wire) and wire[at + 1] == 0x01,
                        f"{tag}: no common-group-only binary packet at byte {at}"):
            return
        mask = int.from_bytes(wire[at + 2:at + 4], "little")
        bits = [b for b in range(16) if mask >> b & 1]
        if not c.expect(all(b < len(VN_COMMON_FIELD_BYTES) for b in bits), f"{tag}: field mask {mask:#06x} at byte {at}"):
            return
        end = at + 4 + sum(VN_COMMON_FIELD_BYTES[b] for b in bits) + 2
        if not c.expect(end <= len(wire), f"{tag}: packet at byte {at} runs past the end"):
            return
        c.expect(crc_ccitt(wire[at + 1:end]) == 0, f"{tag}: CRC mismatch in the packet at byte {at}")
        field = at + 4
        for b in bits:
            if b == 8:  # Accel: 3 float32, m/s^2
                accels.append(struct.unpack_from("<3f", wire, field))
            field += VN_COMMON_FIELD_BYTES[b]
        packets += 1
        at = end
    c.expect(packets == emitted, f"{tag}: {packets} packets, emit reports {emitted}")
    c.expect(len(accels) == packets, f"{tag}: {packets - len(accels)} packets without Accel")
    bad = [a for a in accels if not 9.7 < math.sqrt(sum(v * v for v in a)) < 9.9]
    c.expect(not bad, f"{tag}: static acceleration not ~1 g: {bad[:3]}")
    log(f"{tag}: {packets} packets, first Accel {accels[0] if accels else None} m/s^2")


# sbgECom frames (sbgECom reference manual, "Frame format"): 0xFF 0x5A, message
# id, class, payload length (uint16 LE), payload, CRC-16 (reflected 0x8408,
# init 0: CRC-16/KERMIT) over id..payload sent LE, 0x33. IMU_DATA is class 0
# message 3: time stamp uint32, status uint16, accelerometers 3 float32 m/s^2.
def crc_kermit(data):
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def check_sbg_wire(run, emitted, c):
    tag = f"{run.name} (sbg, decoded here)"
    wire, at, frames, accels = bytes(run.wire), 0, 0, []
    while at < len(wire):
        if not c.expect(wire[at:at + 2] == b"\xff\x5a" and at + 9 <= len(wire), f"{tag}: no sbgECom frame at byte {at}"):
            return
        length = int.from_bytes(wire[at + 4:at + 6], "little")
        end = at + 6 + length + 3
        if not c.expect(end <= len(wire) and wire[end - 1] == 0x33, f"{tag}: frame at byte {at} has no ETX where its length ends"):
            return
        c.expect(crc_kermit(wire[at + 2:at + 6 + length]) == int.from_bytes(wire[end - 3:end - 1], "little"),
                 f"{tag}: CRC mismatch in the frame at byte {at}")
        if wire[at + 3] == 0 and wire[at + 2] == 3:
            accels.append(struct.unpack_from("<3f", wire, at + 6 + 6))
        frames += 1
        at = end
    c.expect(len(accels) == emitted, f"{tag}: {len(accels)} IMU_DATA logs, emit reports {emitted}")
    bad = [a for a in accels if not 9.7 < math.sqrt(sum(v * v for v in a)) < 9.9]
    c.expect(not bad, f"{tag}: static accelerometers not ~1 g: {bad[:3]}")
    log(f"{tag}: {frames} frames, {len(accels)} IMU_DATA, first accelerometers {accels[0] if accels else None} m/s^2")


# Xsens Xbus (MT Low-Level Communication Protocol, as xspublic's headers
# give it): 0xFA, bus id 0xFF, message id, length (0xFF: a 2-byte big-endian
# extended length follows), data, checksum: the bytes after 0xFA sum to 0
# mod 256. MTData2 (0x36): items of data id (uint16 BE), size, data;
# Acceleration 0x4020 (float32, big-endian, m/s^2).
def check_xsens_wire(run, emitted, c):
    tag = f"{run.name} (xsens, decoded here)"
    wire, at, packets, accels = bytes(run.wire), 0, 0, []
    while at < len(wire):
        if not c.expect(wire[at:at + 2] == b"\xfa\xff" and at + 5 <= len(wire), f"{tag}: no Xbus message at byte {at}"):
            return
        length, head = wire[at + 3], 4
        if length == 0xFF:
            length, head = int.from_bytes(wire[at + 4:at + 6], "big"), 6
        end = at + head + length + 1
        if not c.expect(end <= len(wire), f"{tag}: message at byte {at} runs past the end"):
            return
        c.expect(sum(wire[at + 1:end]) & 0xFF == 0, f"{tag}: checksum mismatch in the message at byte {at}")
        if c.expect(wire[at + 2] == 0x36, f"{tag}: message id {wire[at + 2]:#x} at byte {at}, expected MTData2"):
            packets += 1
            item = at + head
            while item + 3 <= end - 1:
                data_id, size = int.from_bytes(wire[item:item + 2], "big"), wire[item + 2]
                if data_id == 0x4020 and size == 12:
                    accels.append(struct.unpack_from(">3f", wire, item + 3))
                item += 3 + size
        at = end
    c.expect(packets == emitted, f"{tag}: {packets} MTData2 messages, emit reports {emitted}")
    c.expect(len(accels) == packets, f"{tag}: {packets - len(accels)} MTData2 without Acceleration (0x4020)")
    bad = [a for a in accels if not 9.7 < math.sqrt(sum(v * v for v in a)) < 9.9]
    c.expect(not bad, f"{tag}: static acceleration not ~1 g: {bad[:3]}")
    log(f"{tag}: {packets} MTData2, first Acceleration {accels[0] if accels else None} m/s^2")


def check_common(rc, splitter, expected_runs, c):
    if rc != 0:
        c.expect(False, f"the guest script exited with {rc} (its output is above)")
    c.expect(splitter.ended, "the guest's end marker never arrived")
    c.expect(splitter.stray_bytes == 0, f"{splitter.stray_bytes} bytes on ttyS1 outside any run")
    names = [r.name for r in splitter.runs]
    c.expect(names == expected_runs, f"runs {names}, expected {expected_runs}")


UART_RATE_HZ = 200  # passed to tests/hil/uart_emit_guest.sh
# The runs at another rate (uart_emit_guest.sh device_run): the Xsens MTi's
# default output configuration sends every item at 100 Hz.
RUN_RATE_HZ = {"xsens": 100}


def check_px4_run(run, results, c):
    """The PX4 replay (Px4Run) and what the guest saw of the baud change."""
    tag = "px4 (PX4 microstrain start-up, mip)"
    for failure in run.failures:
        c.expect(False, f"{tag}: {failure}")
    unanswered = [label for label, _, reply, _ in run.replies if reply is None]
    c.expect(len(run.replies) == len(run.steps) and not unanswered,
             f"{tag}: {len(run.replies)} of {len(run.steps)} commands sent, unanswered: {unanswered}"
             f"{' (the device never streamed: no first packet)' if run.step == -1 else ''}")
    c.expect(run.garbage == 0, f"{tag}: {run.garbage} bytes outside valid MIP packets")
    c.expect(len(run.buffer) == 0, f"{tag}: {len(run.buffer)} bytes of a cut packet at the end")
    c.expect(run.switched_at_byte is not None, f"{tag}: no Comm Port Speed ACK")
    after = [p for p in run.data_packets if run.switched_at_byte is not None and p[0] >= run.switched_at_byte]
    resume_step = next(i for i, step in enumerate(run.steps) if step[0].startswith("Resume"))
    # Set to idle at 921600 .. Resume's ACK: the device is idle, it sends nothing.
    idle_step = 4
    idle_leak = [p for p in run.data_packets if idle_step < p[1] <= resume_step - 1 or
                 (p[1] == resume_step and run.replies[resume_step][2] is None)]
    c.expect(not idle_leak, f"{tag}: {len(idle_leak)} data packets while the device was idle")
    streamed = [p for p in run.data_packets if p[1] >= resume_step and p not in idle_leak]
    c.expect(len(streamed) >= PX4_STREAM_PACKETS, f"{tag}: {len(streamed)} 0x80 packets after Resume")
    wrong = [p for p in streamed if p[2] != [0x04, 0x05]]
    c.expect(not wrong, f"{tag}: {len(wrong)} packets after Resume with fields other than accel+gyro "
             f"(0x04, 0x05): {wrong[:2]}")
    bad = [p[3] for p in streamed if p[3] is None or not 0.985 < math.sqrt(sum(v * v for v in p[3])) < 1.01]
    c.expect(not bad, f"{tag}: static scaled accelerometer not ~1 g: {bad[:3]}")
    # The emulated device's own counters (emit --stats-json).
    device = emit_device(emit_stats(results, run.name))
    commands = device.get("commands") or {}
    transport = device.get("transport") or {}
    log(f"{tag}: emit: commands {json.dumps(commands)}; transport replies_sent {transport.get('replies_sent')}, "
        f"frames {transport.get('frames')}, sent {transport.get('frames_sent')}, dropped_queue_full "
        f"{transport.get('dropped_queue_full')}, input_bytes {transport.get('input_bytes')}")
    c.expect(commands.get("baud") == 921600, f"{tag}: emit reports the device at {commands.get('baud')} baud")
    c.expect(commands.get("received") == len(run.steps) and commands.get("nacked") == 2,
             f"{tag}: emit counted {commands.get('received')} commands ({commands.get('nacked')} NACKed); "
             f"the driver sent {len(run.steps)}, 2 to be NACKed (GNSS base rates)")
    # The guest's 8250: the termios speed, which the driver writes back as
    # the rate it programmed the divisor for (uart_get_baud_rate).
    speeds = []
    try:
        with open(os.path.join(results, f"{run.name}.speed.txt")) as f:
            for line in f:
                parts = line.split()
                if len(parts) >= 3 and parts[1] == "speed":
                    speeds.append((float(parts[0]), int(parts[2])))
    except (OSError, ValueError) as e:
        c.expect(False, f"{tag}: the guest's speed log: {e}")
    changes = [b for (_, a), (_, b) in zip(speeds, speeds[1:]) if a != b]
    c.expect(bool(speeds) and speeds[0][1] == 115200 and speeds[-1][1] == 921600 and changes == [921600],
             f"{tag}: /dev/ttyS1's speed in the guest went {[v for _, v in speeds[:1]] + changes}, expected "
             f"115200 then 921600")
    log(f"{tag}: guest stty -F /dev/ttyS1: {speeds[0] if speeds else None} ... {speeds[-1] if speeds else None} "
        f"({len(speeds)} samples, {'first 921600 at %.1f s' % next((t for t, v in speeds if v == 921600), -1)})")
    # QEMU's view (trace serial_update_parameters: 115200 / divisor, since
    # QEMU's 16550A has a 1.8432 MHz clock): the guest's divisor 8 (115200 at
    # baud_base 921600) shows as 14400, divisor 1 as 115200.
    try:
        with open(os.path.join(results, "qemu_trace.txt")) as f:
            rates = [int(line.split("baudrate=")[1].split()[0]) for line in f if "serial_update_parameters" in line]
        runs = []
        for rate in rates:
            if runs and runs[-1][0] == rate:
                runs[-1][1] += 1
            else:
                runs.append([rate, 1])
        log(f"{tag}: QEMU serial_update_parameters baud rates in order (all three UARTs; rate x calls): "
            f"{', '.join(f'{r} x{n}' for r, n in runs)}")
        c.expect(any(a == 14400 and b == 115200 for a, b in zip(rates, rates[1:])),
                 f"{tag}: QEMU never saw ttyS1's divisor go from 8 to 1 (14400 -> 115200 at its clock)")
    except (OSError, IndexError, ValueError) as e:
        c.expect(False, f"{tag}: QEMU's trace: {e}")
    # The guest's 8250 received exactly the driver's bytes (/proc/tty/driver/serial rx, before and after).
    try:
        with open(os.path.join(results, f"{run.name}.serial_counters.txt")) as f:
            rx = [int(line.split(" rx:")[1].split()[0]) for line in f if " rx:" in line]
        sent = sum(len(command) for _, command, _, _ in run.replies)
        c.expect(len(rx) == 2 and rx[1] - rx[0] == sent,
                 f"{tag}: the guest's 8250 counted {rx} received bytes, the driver sent {sent}")
        log(f"{tag}: the guest's 8250 received {rx[1] - rx[0] if len(rx) == 2 else rx} bytes, the driver sent {sent}")
    except (OSError, IndexError, ValueError) as e:
        c.expect(False, f"{tag}: the guest's serial counters: {e}")
    if run.first_sent is not None and run.last_reply is not None:
        log(f"{tag}: the replay took {run.last_reply - run.first_sent:.2f} s from the first command to the last reply")
    log(f"{tag}: {len(run.replies)} commands answered, {len(streamed)} 0x80 packets after Resume, "
        f"{len(after)} data packets after the switch, {run.garbage} garbage bytes, {run.bytes} bytes in all")


def test_uart(args, results):
    token = secrets.token_hex(8)
    guest = os.path.join(HERE, "uart_emit_guest.sh")
    setserial = shutil.which("setserial") or "/bin/setserial"
    if not os.path.exists(setserial):
        log("FIXTURE FAILURE: setserial not found: install the Debian package setserial (scripts/setup.sh)")
        return FIXTURE_FAILURE
    rc, splitter = boot_and_capture(guest, args.imuemu, results, token, (UART_RATE_HZ,), (setserial,),
                                    ("--trace", "serial_update_parameters"))
    if rc == FIXTURE_FAILURE:
        return rc
    c = Checks()
    check_common(rc, splitter, ["mavlink2", "mip", "px4", "vectornav", "sbg", "xsens"], c)
    for run in splitter.runs:
        if isinstance(run, Px4Run):
            check_px4_run(run, results, c)
            continue
        device = check_stream_run(run, results, RUN_RATE_HZ.get(run.protocol, UART_RATE_HZ), c)
        {"mavlink2": check_mavlink_wire, "mip": check_mip_wire, "vectornav": check_vectornav_wire,
         "sbg": check_sbg_wire, "xsens": check_xsens_wire}[run.protocol](run, device.get("emitted"), c)
    return 1 if c.failures else 0


# Passed to tests/hil/gpio_sync_guest.sh.
GPIO_RATE_HZ = 100
GPIO_EVERY = 20
GPIO_WIDTH_US = 2000
GPIO_RUNS = {"sync_high": (0, False), "sync_low": (1, True)}  # run: (line, active low)


def read_recorder(path, c):
    with open(path) as f:
        lines = f.read().splitlines()
    c.expect(bool(lines) and lines[0].startswith("#") and "dropped 0)" in lines[0],
             f"recorder header missing or events dropped: {lines[:1]}")
    return [tuple(int(x) for x in line.split()) for line in lines[1:] if line.strip()]


def check_gpio_run(run, device, events, line, active_low, c):
    tag = f"{run.name} (line {line}, active {'low' if active_low else 'high'})"
    samples = run.summary.get("samples") or 0
    sequences = [x.get("sequence") for x in run.samples]  # = tick indices (check_stream_run)
    idle, active = (1, 0) if active_low else (0, 1)
    levels = [(t, v) for t, ln, v in events if ln == line]
    if not c.expect(bool(levels), f"{tag}: the recorder saw nothing on line {line}"):
        return
    # Requesting the line as an output drives its idle level first.
    c.expect(levels[0][1] == idle, f"{tag}: first level driven {levels[0][1]}, expected idle {idle}")
    c.expect(levels[-1][1] == idle, f"{tag}: line left at {levels[-1][1]}, expected idle {idle}")
    pulses = []  # (leading edge t, trailing edge t)
    level, lead = levels[0][1], None
    for t, v in levels[1:]:
        if v == level:
            continue  # a write of the same level is no edge
        if v == active:
            lead = t
        elif lead is not None:
            pulses.append((lead, t))
            lead = None
        level = v
    # A pulse goes with every sample whose counter is a multiple of N
    # (ceil(samples / N) when emit skipped no tick).
    expected = sum(1 for q in sequences if q is not None and q % GPIO_EVERY == 0)
    c.expect(samples > 0, f"{tag}: listen decoded no samples")
    c.expect(len(pulses) == expected,
             f"{tag}: {len(pulses)} pulses on the recorder, {expected} samples with a counter multiple of "
             f"{GPIO_EVERY} (of {samples}; ceil = {math.ceil(samples / GPIO_EVERY)})")
    gpio = device.get("gpio") or {}
    c.expect(gpio.get("pulses") == len(pulses), f"{tag}: emit reports {gpio.get('pulses')} pulses, recorder {len(pulses)}")
    for key in ("skipped_pulses", "set_errors"):
        c.expect(gpio.get(key) == 0, f"{tag}: emit reports {key} = {gpio.get(key)}")
    period_ns = 1e9 / GPIO_RATE_HZ
    width_ns = GPIO_WIDTH_US * 1000
    widths = [b - a for a, b in pulses]
    if widths:
        # TCG timing is loose: the trailing edge comes from a timer thread,
        # so only a lower bound and "well inside the pulse period" hold.
        c.expect(min(widths) >= width_ns,
                 f"{tag}: narrowest pulse {min(widths)} ns < configured {width_ns} ns (measured between the kernel's "
                 f"timestamps of the two line writes: a trailing edge timed from before the leading edge's write "
                 f"cuts the pulse short by that write's latency)")
        c.expect(max(widths) < 0.5 * GPIO_EVERY * period_ns,
                 f"{tag}: widest pulse {max(widths)} ns, not well below N x period = {GPIO_EVERY * period_ns:.0f} ns")
    sent_multiples = [q for q in sequences if q is not None and q % GPIO_EVERY == 0]
    if len(pulses) == len(sent_multiples) and pulses:
        # The k-th pulse belongs to the k-th sent sample whose counter is a
        # multiple of N: its leading edge is that sample's tick time on the
        # guest's clock plus the emission thread's lateness, so edge time
        # minus counter x period stays within the lateness spread (a pulse
        # assigned to the wrong multiple of N would be N periods off).
        offsets = [lead - q * period_ns for (lead, _), q in zip(pulses, sent_multiples)]
        spread = max(offsets) - min(offsets)
        c.expect(spread < 0.5 * GPIO_EVERY * period_ns,
                 f"{tag}: leading edge minus counter x period varies by {spread / 1e6:.1f} ms: pulses do not line "
                 f"up with samples {sent_multiples[:4]}...")
        log(f"{tag}: pulses line up with samples {sent_multiples[0]}, {sent_multiples[1] if len(sent_multiples) > 1 else ''}"
            f"... {sent_multiples[-1]} within {spread / 1e6:.1f} ms")
    if len(pulses) > 2 and len(pulses) == len(sent_multiples):
        # emit paces the samples on CLOCK_MONOTONIC, so over the run the
        # pulses keep the samples' spacing (a skipped multiple of N leaves a
        # double gap, accounted for by the counters).
        expected_spacing = (sent_multiples[-1] - sent_multiples[0]) / (len(pulses) - 1) * period_ns
        mean_spacing = (pulses[-1][0] - pulses[0][0]) / (len(pulses) - 1)
        c.expect(abs(mean_spacing - expected_spacing) < 0.25 * expected_spacing,
                 f"{tag}: pulses {mean_spacing:.0f} ns apart on average, expected {expected_spacing:.0f} ns (+-25%)")
        log(f"{tag}: {len(pulses)} pulses for {samples} samples, widths {min(widths) / 1e3:.0f}.."
            f"{max(widths) / 1e3:.0f} us (configured {GPIO_WIDTH_US} us), mean spacing {mean_spacing / 1e6:.2f} ms "
            f"(expected {expected_spacing / 1e6:.2f} ms)")


# Issue 29: the device's own sync-out setting on a recorder line
# (gpio_sync_guest.sh sync_vectornav): line, pulse every N samples of the
# scene, width, negative polarity.
DEVICE_SYNC_RUNS = {"sync_vectornav": (3, 5, 2000)}


def check_device_sync_run(run, device, events, line, every, width_us, c):
    """VectorNav register 32 (SyncOutMode ImuReady, negative, skip 39 of its
    800 Hz IMU samples): the line requested active high idles high from the
    first sample on and pulses low on each sample whose tick is a multiple of
    `every`, at least width_us wide."""
    tag = f"{run.name} (line {line}, the device's SyncOut: negative pulses every {every} samples)"
    levels = [(t, v) for t, ln, v in events if ln == line]
    if not c.expect(len(levels) >= 2, f"{tag}: the recorder saw {len(levels)} levels on line {line}"):
        return
    # Requested as an output, inactive (low); the device's negative polarity
    # then moves it to its idle level, high, before any pulse.
    c.expect(levels[0][1] == 0 and levels[1][1] == 1, f"{tag}: first levels {levels[:2]}, expected 0 (request) then 1")
    pulses, lead, level = [], None, 1
    for t, v in levels[2:]:
        if v == level:
            continue
        if v == 0:
            lead = t
        elif lead is not None:
            pulses.append((lead, t))
            lead = None
        level = v
    period_ns = 1e9 / GPIO_RATE_HZ
    ticks = [round(x["t_ns"] / period_ns) for x in run.samples if x.get("t_ns") is not None]
    expected = [k for k in ticks if k % every == 0]
    c.expect(ticks and len(pulses) == len(expected),
             f"{tag}: {len(pulses)} low pulses, {len(expected)} sent samples with a tick multiple of {every}")
    gpio = device.get("gpio") or {}
    c.expect(gpio.get("pulses") == len(pulses), f"{tag}: emit reports {gpio.get('pulses')} pulses, recorder {len(pulses)}")
    widths = [b - a for a, b in pulses]
    if widths:
        c.expect(min(widths) >= width_us * 1000, f"{tag}: narrowest pulse {min(widths)} ns < the register's {width_us} us")
        c.expect(max(widths) < 0.5 * every * period_ns, f"{tag}: widest pulse {max(widths)} ns")
    if len(pulses) == len(expected) and len(pulses) > 2:
        offsets = [lead - k * period_ns for (lead, _), k in zip(pulses, expected)]
        spread = max(offsets) - min(offsets)
        c.expect(spread < 0.5 * every * period_ns,
                 f"{tag}: leading edge minus tick x period varies by {spread / 1e6:.1f} ms: pulses off their samples")
        log(f"{tag}: {len(pulses)} pulses for {len(ticks)} samples, widths {min(widths) / 1e3:.0f}.."
            f"{max(widths) / 1e3:.0f} us (register {width_us} us), lined up with their samples within "
            f"{spread / 1e6:.1f} ms")


def test_gpio(args, results):
    token = secrets.token_hex(8)
    guest = os.path.join(HERE, "gpio_sync_guest.sh")
    rc, splitter = boot_and_capture(guest, args.imuemu, results, token, (GPIO_RATE_HZ, GPIO_EVERY, GPIO_WIDTH_US))
    if rc == FIXTURE_FAILURE:
        return rc
    c = Checks()
    check_common(rc, splitter, list(GPIO_RUNS) + list(DEVICE_SYNC_RUNS), c)
    events = read_recorder(os.path.join(results, "gpio_recorder.txt"), c)
    for run in splitter.runs:
        device = check_stream_run(run, results, GPIO_RATE_HZ, c)
        if run.name in GPIO_RUNS:
            check_gpio_run(run, device, events, *GPIO_RUNS[run.name], c)
        if run.name in DEVICE_SYNC_RUNS:
            check_device_sync_run(run, device, events, *DEVICE_SYNC_RUNS[run.name], c)
    # Line 2: driven once by gpioset, which holds it while the guest checks
    # that emit refuses a claimed line (gpio_sync_guest.sh).
    lines_used = {ln for _, ln, _ in events} - {2}
    used = {line for line, _ in GPIO_RUNS.values()} | {run[0] for run in DEVICE_SYNC_RUNS.values()}
    c.expect(lines_used <= used, f"the recorder saw lines {sorted(lines_used)}, only {sorted(used)} were used")
    return 1 if c.failures else 0


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("test", choices=["uart", "gpio"])
    parser.add_argument("--imuemu", required=True, help="the imuemu binary (release build)")
    parser.add_argument("--results", help="keep the results here, emptied first (default: a temporary directory, "
                        "removed when the test passes)")
    args = parser.parse_args()
    start = time.monotonic()
    results = args.results or tempfile.mkdtemp(prefix=f"hil_{args.test}_results.")
    # Emptied first: a stale emit.json or recorder log must not pass for this run's.
    shutil.rmtree(results, ignore_errors=True)
    os.makedirs(results)
    try:
        rc = (test_uart if args.test == "uart" else test_gpio)(args, results)
    except (RuntimeError, OSError) as e:
        log(f"FAILED: {e}")
        rc = 1
    log(f"{'PASSED' if rc == 0 else 'FAILED'} in {time.monotonic() - start:.1f} s (results: {results})")
    if not args.results and rc == 0:
        shutil.rmtree(results, ignore_errors=True)
    return rc


if __name__ == "__main__":
    sys.exit(main())
