#!/bin/sh
# Guest side of the hil_smoke_vcan test (tests/hil/hil_run.sh, either backend)
# and part of hil_smoke_qemu_uart_gpio_vcan (qemu_run.sh's busybox guest):
# a classic CAN frame and a 16-byte CAN FD frame sent with cansend on vcan0
# must reach a candump listening on the same interface, unchanged.
set -u
rx=${HIL_OUT:?run me through tests/hil/hil_run.sh}/candump.log
check_frame() { # $1 = cansend frame, $2 = the candump -L text expected for it
  : >"$rx"
  candump -L -n 1 -T 5000 vcan0 >"$rx" &
  dump_pid=$!
  # candump binds its socket asynchronously: resend until it has caught one
  # frame (it exits after -n 1), so a frame sent before it listened is no miss.
  tries=0
  while kill -0 "$dump_pid" 2>/dev/null && [ "$tries" -lt 40 ]; do
    cansend vcan0 "$1" || { echo "cansend vcan0 $1 failed"; return 1; }
    tries=$((tries + 1))
    sleep 0.1
  done
  wait "$dump_pid"
  if ! grep -q " vcan0 $2\$" "$rx"; then
    echo "expected 'vcan0 $2' from candump, got: $(cat "$rx")"
    return 1
  fi
  echo "received: $(cat "$rx")"
}
check_frame 123#DEADBEEF 123#DEADBEEF || exit 1
# CAN FD with bit-rate switch (flags 1 = CANFD_BRS); since Linux 6.0 the kernel
# also marks every FD frame with CANFD_FDF (0x04), so candump reports flags 5.
check_frame 1F334455##100112233445566778899AABBCCDDEEFF 1F334455##500112233445566778899AABBCCDDEEFF || exit 1
echo "vcan0 mtu: $(cat /sys/class/net/vcan0/mtu)"
