#!/bin/sh
# Guest side of the hil_smoke_qemu test (run by tests/hil/qemu_run.sh, driven
# from the host by tests/hil/smoke_qemu.py).
set -u
here=$(dirname "$0")

# UART: /dev/ttyS1 is the 8250 driver on an emulated 16550A whose far end is
# the host test. Keep one descriptor open for the whole exchange: opening the
# port resets the UART's receive FIFO.
exec 3<>/dev/ttyS1
stty raw -echo 115200 <&3 || { echo "stty on /dev/ttyS1 failed"; exit 1; }
printf 'HELLO-FROM-GUEST\n' >&3
# shellcheck disable=SC3045 # busybox sh has read -t
read -r -t 60 reply <&3 || { echo "no reply from the host on /dev/ttyS1"; exit 1; }
printf 'ECHO %s\n' "$reply" >&3
exec 3>&- # the last close waits until the UART has sent everything

# GPIO through the character device (libgpiod's gpioset): line 3 held high
# for 200 ms by gpioset itself, then driven low; line 5 high, then low.
gpioset --mode=time --usec=200000 "$HIL_GPIOCHIP" 3=1 || { echo "gpioset 3=1 failed"; exit 1; }
gpioset "$HIL_GPIOCHIP" 3=0 || exit 1
gpioset "$HIL_GPIOCHIP" 5=1 || exit 1
gpioset "$HIL_GPIOCHIP" 5=0 || exit 1
echo "gpioget line 5 reads $(gpioget "$HIL_GPIOCHIP" 5)"

# SocketCAN on vcan0 with the same checks as under user-mode Linux.
sh "$here/smoke_vcan.sh"
