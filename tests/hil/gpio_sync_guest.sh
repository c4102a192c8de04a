#!/bin/sh
# Guest side of the hil_gpio_sync_qemu test (run by tests/hil/qemu_run.sh,
# driven from the host by tests/hil/uart_peer.py gpio):
#
#   gpio_sync_guest.sh IMUEMU TOKEN RATE_HZ EVERY WIDTH_US
#
# `imuemu emit` sends a static IMU at RATE_HZ as native frames (which carry
# the sample counter) on /dev/ttyS1 for the host to decode, with a WIDTH_US
# sync pulse every EVERY samples on the gpio_recorder chip ($HIL_GPIOCHIP),
# which timestamps every level driven: first active high on line 0, then
# active low on line 1.
set -u
usage="usage: gpio_sync_guest.sh IMUEMU TOKEN RATE_HZ EVERY WIDTH_US"
imuemu=${1:?$usage} token=${2:?$usage} rate_hz=${3:?$usage} every=${4:?$usage} width_us=${5:?$usage}
readonly SECONDS_EMITTED=3
status=0
[ -c "${HIL_GPIOCHIP:-}" ] || { echo "gpio_sync_guest: no gpio_recorder chip (HIL_GPIOCHIP='${HIL_GPIOCHIP:-}')"; exit 1; }

marker() {
  stty -F /dev/ttyS1 raw -echo 115200 || { echo "stty on /dev/ttyS1 failed"; exit 1; }
  printf 'HILSEP:%s:%s;' "$token" "$1" >/dev/ttyS1
}

run() { # name line [--sync-active-low]
  name=$1 line=$2
  shift 2
  marker "BEGIN:$name:native"
  "$imuemu" emit --sample static --duration-s $((SECONDS_EMITTED + 2)) --seconds $SECONDS_EMITTED \
    --rate "$rate_hz" --protocol native --device serial:/dev/ttyS1,baud=921600 \
    --gpio "$HIL_GPIOCHIP:$line" --sync-every "$every" --sync-width-us "$width_us" "$@" \
    --stats-json "$HIL_OUT/$name.emit.json"
  rc=$?
  echo "gpio_sync_guest: $name: imuemu emit exit status $rc"
  [ $rc -eq 0 ] || status=1
}

run sync_high 0
run sync_low 1 --sync-active-low

# Issue 29: a VectorNav whose saved register 32 drives its SyncOut pin (line
# 3, the scene's sync line, requested active high): SyncOutMode ImuReady,
# negative polarity, skip factor 39 (every 40th IMU sample of its 800 Hz: 20
# Hz, every 5th sample of this 100 Hz scene), 2000 us wide. Binary output 1
# carries the samples' time for the host (register 75; ASCII off).
marker "BEGIN:sync_vectornav:vectornav"
"$imuemu" emit --sample static --duration-s $((SECONDS_EMITTED + 2)) --seconds $SECONDS_EMITTED \
  --rate "$rate_hz" --protocol vectornav --device serial:/dev/ttyS1,baud=921600 --gpio "$HIL_GPIOCHIP:3" \
  --vectornav-saved-registers '6,0;75,1,4,01,0121;32,3,0,0,0,2,0,39,2000000,0' \
  --stats-json "$HIL_OUT/sync_vectornav.emit.json"
rc=$?
echo "gpio_sync_guest: sync_vectornav: imuemu emit exit status $rc"
[ $rc -eq 0 ] || status=1

# A line another process holds (gpioset keeps it requested until signalled):
# emit must refuse before sending anything, naming the chip, the line and the
# owner. gpioset drives line 2 to 0 once; the host allows that line's events.
gpioset --mode=signal "$HIL_GPIOCHIP" 2=0 &
holder=$!
sleep 0.5
out=$("$imuemu" emit --sample static --duration-s 3 --seconds 1 --rate 100 --protocol native \
  --device serial:/dev/ttyS1,baud=921600 --gpio "$HIL_GPIOCHIP:2" 2>&1)
rc=$?
kill "$holder"
wait "$holder" 2>/dev/null
echo "gpio_sync_guest: claimed line: emit exit status $rc: $out"
if [ $rc -ne 0 ] && echo "$out" | grep -q "line 2 is already claimed by 'gpioset'"; then
  echo "gpio_sync_guest: claimed line: refused with a clear error: PASS"
else
  echo "gpio_sync_guest: claimed line: FAIL (expected a non-zero exit naming line 2 and its owner gpioset)"
  status=1
fi
marker END
exit $status
