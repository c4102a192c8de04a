#!/usr/bin/env bash
# Installs everything, builds the Release and the ASan+UBSan flavours and runs
# the whole test suite in both. This is what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
status=0
for flavour in release asan; do
  echo "=== $flavour: build"
  bash scripts/build.sh "$flavour"
  echo "=== $flavour: test"
  ctest --test-dir "build/$flavour" --output-on-failure -j "$(nproc)" || status=1
done
exit $status
