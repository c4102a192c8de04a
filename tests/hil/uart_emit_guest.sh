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
marker END
exit $status
