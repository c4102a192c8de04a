#!/usr/bin/env bash
# The main job, no hardware needed: installs what building and running needs
# (not the test stack), builds only imuemu and imuemud, then
#  1. starts the daemon imuemud on its built-in scene (config/default.toml:
#     the aircraft-like flight near Barcelona, 1 Hz knots, WGS84 ECEF physics,
#     a 400 Hz IMU in imuemu's native protocol on the virtual serial port
#     /tmp/imuemu/ttyIMU0), and shows live decoded samples for a few seconds
#     with `imuemu listen`, then a summary of the daemon's status and a clean
#     stop;
#  2. runs the batch job on the same flight: 10 minutes of 1 Hz knots to a
#     400 Hz IMU, integrated back to print the closed-loop drift (out/demo/).
# DEMO_SECONDS sets how long samples are shown (default 5).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
bash scripts/setup.sh build
echo "build: imuemu and imuemud only (5-10 minutes of CPU from nothing, 3-6 minutes on 2 idle cores; the compiler's output is in build/app/build.log)"
IMUEMU_BUILD_QUIET=1 bash scripts/build.sh app
bin=build/app/daemon
seconds=${DEMO_SECONDS:-5}
link=/tmp/imuemu/ttyIMU0
socket=/tmp/imuemu/default.sock
echo "ready after $((SECONDS - start)) s"

echo "=== imuemud --check-config - (the built-in scene)"
"$bin/imuemud" --check-config -
"$bin/imuemud" &
daemon=$!
trap 'kill "$daemon" 2>/dev/null || true' EXIT
for _ in $(seq 1 200); do
  [[ -L $link && -S $socket ]] && break
  kill -0 "$daemon" 2>/dev/null || { echo "imuemud exited early" >&2; exit 1; }
  sleep 0.05
done
echo "=== imuemu listen --device $link (every 40th sample: 10 lines per second, for $seconds s)"
"$bin/imuemu" listen --protocol native --device "$link" --expect-rate 400 --every 40 --duration-s "$seconds"
echo "=== imuemu status --summary (control socket $socket; --json for every counter)"
"$bin/imuemu" status --socket "$socket" --summary
echo "=== stopping imuemud (SIGTERM: stops at a packet boundary, exit 0)"
kill -TERM "$daemon"
wait "$daemon"
trap - EXIT
echo "imuemud exited with status 0"

echo "=== batch: 10-minute flight -> 400 Hz IMU -> closed-loop check"
exec "$bin/imuemu" demo --out-dir out/demo "$@"
