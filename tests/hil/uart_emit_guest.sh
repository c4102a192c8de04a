#!/bin/sh
# Guest side of the hil_uart_mavlink_mip_qemu test (run by tests/hil/qemu_run.sh,
# driven from the host by tests/hil/uart_peer.py uart):
#
#   uart_emit_guest.sh IMUEMU TOKEN RATE_HZ
#
# `imuemu emit` sends a static IMU at RATE_HZ through libserialport into the
# 8250 driver on /dev/ttyS1 (921600 baud asked), first as MAVLink 2, then as
# MIP; the host decodes the UART's far end. Before each run an ASCII marker
# with the host's TOKEN tells the host which protocol follows; emit's stats
# go to $HIL_OUT/<run>.emit.json.
#
# Then the px4 run (issue 27): `imuemu emit --protocol mip` at 115200 baud
# and 1000 Hz, a device that answers its driver; the host replays PX4's
# microstrain start-up sequence, whose Comm Port Speed command moves the
# device to 921600 baud. For that run the port's baud_base is raised to
# 921600 (setserial: an 8250 clocked at 14.7456 MHz, as UARTs that run a
# 3DM device at 921600 are), so 115200 is divisor 8 and 921600 divisor 1:
# the emulated 16550A's own 1.8432 MHz clock stops at 115200, where the
# kernel would keep the old rate (uart_get_baud_rate) and the change would
# prove nothing. While emit runs, the port's termios speed is sampled into
# $HIL_OUT/px4.speed.txt ("<uptime s> <speed>"): the 8250 driver writes back
# the rate it programmed the divisor for.
set -u
usage="usage: uart_emit_guest.sh IMUEMU TOKEN RATE_HZ"
imuemu=${1:?$usage} token=${2:?$usage} rate_hz=${3:?$usage}
readonly SECONDS_EMITTED=2
status=0

# A marker, in raw mode at 115200 baud (the most the emulated 16550A's
# 1.8432 MHz clock gives through termios; the marker's rate does not matter).
# Closing the port waits until the UART has sent it (tty closing_wait), so it
# precedes the run.
marker() {
  stty -F /dev/ttyS1 raw -echo 115200 || { echo "stty on /dev/ttyS1 failed"; exit 1; }
  printf 'HILSEP:%s:%s;' "$token" "$1" >/dev/ttyS1
}

for protocol in mavlink2 mip; do
  marker "BEGIN:$protocol:$protocol"
  "$imuemu" emit --sample static --duration-s $((SECONDS_EMITTED + 2)) --seconds $SECONDS_EMITTED \
    --rate "$rate_hz" --protocol $protocol --device serial:/dev/ttyS1,baud=921600 \
    --stats-json "$HIL_OUT/$protocol.emit.json"
  rc=$?
  echo "uart_emit_guest: $protocol: imuemu emit exit status $rc"
  [ $rc -eq 0 ] || status=1
done
# PX4 start-up replay, driven by the host (uart_peer.py Px4Run).
# 4 s of emission: the replay and the stream check take ~1 s of it on an idle
# host (the host logs how long); the rest is margin for a loaded one.
readonly PX4_SECONDS=4 PX4_RATE_HZ=1000
if setserial /dev/ttyS1 baud_base 921600 && setserial -a /dev/ttyS1 >"$HIL_OUT/px4.setserial.txt" 2>&1; then
  marker "BEGIN:px4:mip-px4"
  grep '^1:' /proc/tty/driver/serial >"$HIL_OUT/px4.serial_counters.txt"
  "$imuemu" emit --sample static --duration-s $((PX4_SECONDS + 2)) --seconds $PX4_SECONDS \
    --rate $PX4_RATE_HZ --protocol mip --device serial:/dev/ttyS1,baud=115200 \
    --stats-json "$HIL_OUT/px4.emit.json" 2>"$HIL_OUT/px4.emit.err" &
  pid=$!
  while kill -0 $pid 2>/dev/null; do
    speed=$(stty -F /dev/ttyS1 -a 2>&1 | head -n 1)
    echo "$(cut -d' ' -f1 /proc/uptime) $speed"
    sleep 0.3
  done >"$HIL_OUT/px4.speed.txt"
  wait $pid
  rc=$?
  grep '^1:' /proc/tty/driver/serial >>"$HIL_OUT/px4.serial_counters.txt"

  echo "uart_emit_guest: px4: imuemu emit exit status $rc"
  cat "$HIL_OUT/px4.emit.err"
  [ $rc -eq 0 ] || status=1
else
  echo "uart_emit_guest: setserial /dev/ttyS1 baud_base 921600 failed"
  status=1
fi
# Issue 29: the VectorNav, SBG and Xsens devices through the 8250 driver at
# 921600 baud (the port's baud_base was raised for the px4 run: 921600 is
# divisor 1), each as a unit whose saved settings stream one IMU packet per
# sample (the pty loopback's, tests/loopback/pty_loopback.py): VectorNav
# binary output 1 at 800 / 4 Hz with its ASCII output off, SBG IMU_DATA on
# every 5 ms main-loop tick, Xsens MTData2 at its default 100 Hz. The host
# checks every frame's CRC / checksum and counts them against emit's samples.
device_run() {  # device_run PROTOCOL RATE_HZ [emit options...]
  protocol=$1 device_rate_hz=$2
  shift 2
  marker "BEGIN:$protocol:$protocol"
  "$imuemu" emit --sample static --duration-s $((SECONDS_EMITTED + 2)) --seconds $SECONDS_EMITTED \
    --rate "$device_rate_hz" --protocol "$protocol" --device serial:/dev/ttyS1,baud=921600 \
    --stats-json "$HIL_OUT/$protocol.emit.json" "$@"
  rc=$?
  echo "uart_emit_guest: $protocol: imuemu emit exit status $rc"
  [ $rc -eq 0 ] || status=1
}
device_run vectornav "$rate_hz" --vectornav-saved-registers '6,0;75,1,4,01,0121'
device_run sbg "$rate_hz" --sbg-saved-outputs 'imuData=5ms,imuShort=disabled'
device_run xsens 100
marker END
exit $status
