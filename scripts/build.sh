#!/usr/bin/env bash
# Configures and builds one flavour: scripts/build.sh release|asan
# Build trees live in build/<flavour>.
set -euo pipefail
cd "$(dirname "$0")/.."
flavour=${1:-release}
case "$flavour" in
  release) extra=(-DCMAKE_BUILD_TYPE=Release -DIMUEMU_SANITIZE=OFF -DIMUEMU_BUILD_BENCH=ON) ;;
  # -O1 -g1: half the compile time of -O2 -g (the sanitizers' instrumentation
  # dominates), still line numbers in every report; keeps CI under 30 minutes.
  asan) extra=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DIMUEMU_SANITIZE=ON -DIMUEMU_BUILD_BENCH=OFF) ;;
  *) echo "usage: $0 release|asan" >&2; exit 2 ;;
esac
cmake -S . -B "build/$flavour" -G Ninja "${extra[@]}" >/dev/null
cmake --build "build/$flavour" -j "$(nproc)"
