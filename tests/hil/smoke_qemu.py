#!/usr/bin/env python3
"""Host side of the hil_smoke_qemu test: boots tests/hil/qemu_run.sh with the
guest's /dev/ttyS1 on a unix socket, plays the far end of that UART, then
checks what the guest's real drivers did:

- UART (8250 driver): the guest's greeting arrives here byte for byte, and a
  random token sent back is echoed, so both directions work;
- GPIO (gpio_recorder through libgpiod's gpioset): the recorder holds exactly
  the levels driven, in order, with kernel timestamps that show gpioset's
  200 ms hold;
- vcan: tests/hil/smoke_vcan.sh passes inside the guest.

Standard library only. Exit status 0 on success, 1 on a failed check, the
fixture's 125 when the fixture itself failed.
"""
import os
import secrets
import socket
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
HOLD_NS = 200_000_000  # gpioset --usec=200000 in smoke_qemu_guest.sh


def fail(message):
    print(f"smoke_qemu: FAILED: {message}", file=sys.stderr)
    return 1


def connect(path, fixture, deadline):
    """QEMU creates the socket once the cached kernel and initramfs are ready
    (minutes on a first run that downloads the kernel) and waits for us."""
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


def recv_until(s, received, stop):
    while not stop(received):
        chunk = s.recv(4096)
        if not chunk:
            return False
        received += chunk
    return True


def main():
    with tempfile.TemporaryDirectory(prefix="hil_smoke_qemu.") as tmp:
        sock_path = os.path.join(tmp, "ttyS1.sock")
        results = os.path.join(tmp, "results")
        guest = os.path.join(HERE, "smoke_qemu_guest.sh")
        start = time.monotonic()
        fixture = subprocess.Popen([
            os.path.join(HERE, "qemu_run.sh"),
            "--serial1", f"socket,path={sock_path},server=on,wait=on",
            "--results", results,
            "--include", guest, "--include", os.path.join(HERE, "smoke_vcan.sh"),
            "--", "sh", guest])
        s = connect(sock_path, fixture, start + 250)
        if s is None:
            fixture.kill()
            rc = fixture.wait()
            return 125 if rc == 125 else fail(f"never connected to {sock_path} (fixture status {rc})")
        token = secrets.token_hex(8)
        received = bytearray()
        with s:
            s.settimeout(240)
            if not recv_until(s, received, lambda r: b"\n" in r):
                fixture.wait()
                return fail(f"/dev/ttyS1 closed before the greeting; got {bytes(received)!r}")
            s.sendall(f"PING {token}\n".encode())
            recv_until(s, received, lambda r: False)  # until QEMU exits
        rc = fixture.wait(timeout=60)
        elapsed = time.monotonic() - start
        if rc == 125:
            return rc  # the fixture said why
        failures = [] if rc == 0 else [f"guest script exited with {rc} (its output is above)"]
        expected_uart = f"HELLO-FROM-GUEST\nECHO PING {token}\n".encode()
        if bytes(received) != expected_uart:
            failures.append(f"ttyS1 bytes {bytes(received)!r}, expected {expected_uart!r}")

        with open(os.path.join(results, "gpio_recorder.txt")) as f:
            lines = f.read().splitlines()
        if not lines or not lines[0].startswith("#") or "dropped 0)" not in lines[0]:
            failures.append(f"recorder header missing or events dropped: {lines[:1]}")
        events = [tuple(int(x) for x in line.split()) for line in lines[1:]]
        levels = [(line, value) for _, line, value in events]
        if levels != [(3, 1), (3, 0), (5, 1), (5, 0)]:
            failures.append(f"recorded (line, level) sequence {levels}, expected [(3,1), (3,0), (5,1), (5,0)]")
        times = [t for t, _, _ in events]
        if times != sorted(times):
            failures.append(f"recorder timestamps not monotonic: {times}")
        if len(events) >= 2:
            held_ns = events[1][0] - events[0][0]
            # gpioset sleeps HOLD_NS between driving 1 and exiting; the next
            # gpioset starts a new process, so the gap is longer, not shorter.
            if not HOLD_NS <= held_ns < 10 * HOLD_NS:
                failures.append(f"line 3 held {held_ns} ns, expected >= {HOLD_NS} ns (and < {10 * HOLD_NS})")
            print(f"smoke_qemu: line 3 high for {held_ns / 1e6:.1f} ms (gpioset asked {HOLD_NS / 1e6:.0f} ms)")

        with open(os.path.join(results, "output.txt")) as f:
            output = f.read()
        if "gpioget line 5 reads 0" not in output:
            failures.append("gpioget did not read back the last level 0 on line 5")
        if output.count("received: ") != 2:
            failures.append("the vcan checks inside the guest did not report two frames")

        for message in failures:
            fail(message)
        if failures:
            return 1
        print(f"smoke_qemu: UART round trip, GPIO edges and vcan OK in {elapsed:.1f} s")
        return 0


if __name__ == "__main__":
    sys.exit(main())
