#!/usr/bin/env bash
# Configures and builds one flavour: scripts/build.sh release|asan|app
# Build trees live in build/<flavour>.
#   release  Release with the tests and benchmarks (scripts/test.sh)
#   asan     ASan+UBSan with the tests (scripts/test.sh)
#   app      Release, only the two programs imuemu and imuemud, no test stack
#            needed (scripts/demo.sh; `cmake --install build/app` installs them)
# IMUEMU_BUILD_QUIET=1 sends the compiler's output to build/<flavour>/build.log
# and prints one line (the log's tail if the build fails).
set -euo pipefail
cd "$(dirname "$0")/.."
flavour=${1:-release}
targets=()
case "$flavour" in
  release) extra=(-DCMAKE_BUILD_TYPE=Release -DIMUEMU_SANITIZE=OFF -DIMUEMU_BUILD_BENCH=ON) ;;
  # -O1 -g1: half the compile time of -O2 -g (the sanitizers' instrumentation
  # dominates), still line numbers in every report; keeps CI under 30 minutes.
  asan) extra=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DIMUEMU_SANITIZE=ON -DIMUEMU_BUILD_BENCH=OFF) ;;
  app) extra=(-DCMAKE_BUILD_TYPE=Release -DIMUEMU_SANITIZE=OFF -DIMUEMU_BUILD_TESTS=OFF -DIMUEMU_BUILD_BENCH=OFF)
       targets=(--target imuemu imuemud) ;;
  *) echo "usage: $0 release|asan|app" >&2; exit 2 ;;
esac
dir=build/$flavour
cmake -S . -B "$dir" -G Ninja "${extra[@]}" >/dev/null
if [[ ${IMUEMU_BUILD_QUIET:-0} == 1 ]]; then
  log=$dir/build.log
  start=$SECONDS
  if ! cmake --build "$dir" -j "$(nproc)" "${targets[@]}" >"$log" 2>&1; then
    echo "build ($flavour): failed; the last lines of $log:" >&2
    tail -n 40 "$log" >&2
    exit 1
  fi
  echo "build ($flavour): done in $((SECONDS - start)) s ($dir)"
else
  cmake --build "$dir" -j "$(nproc)" "${targets[@]}"
fi
