#!/usr/bin/env bash
# Installs everything, builds the Release and the ASan+UBSan (clang) flavours
# and runs the whole test suite in both, plus the fuzz targets (built in the
# ASan tree) for a bounded time. This is what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
status=0
run_flavour() {
  echo "=== $1: build"
  bash scripts/build.sh "$1"
  echo "=== $1: test"
  ctest --test-dir "build/$1" --output-on-failure -j "$(nproc)" "${@:2}" || status=1
}
# The hardware-in-the-loop fixtures (label hil: user-mode Linux and QEMU,
# tests/hil/README.md) run once, on the release binaries: ASan binaries cannot
# run under user-mode Linux, and the fixtures test kernels and wires, not
# memory safety (the same code runs under ASan in the unit tests). So do the
# 30-s loopback runs (label loopback): they test delivery at the exact rate.
# The long numeric runs (label heavy, tests/heavy_tests.cmake) run in Release
# only: under ASan at -O1 they cost 12 of the flavour's 16 test minutes and
# exercise no code path the short tests do not. The peak-memory tests (label
# memory) would measure ASan's own shadow memory, so they too are Release only.
run_flavour release
run_flavour asan -LE "hil|loopback|heavy|memory"
# The libFuzzer targets, bounded in time (FUZZ_SECONDS per target).
echo "=== fuzz"
bash scripts/fuzz.sh "${FUZZ_SECONDS:-30}" || status=1
exit $status
