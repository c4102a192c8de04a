#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan+UBSan) and runs each for a
# bounded time from the seed corpora in tests/fuzz/corpus (copied, so the
# repository is never modified). Exits non-zero on the first crash.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 30)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-${FUZZ_SECONDS:-30}}
cmake -S . -B build/fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DIMUEMU_FUZZ=ON >/dev/null
cmake --build build/fuzz -j "$(nproc)"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
targets=(trajectory_csv imu_csv decimal_time pose_line pose_datagram live_path)
for target in "${targets[@]}"; do
  mkdir -p "$work/$target"
  cp -r "tests/fuzz/corpus/$target/." "$work/$target/"
  echo "=== fuzz_$target: ${seconds}s"
  status=0
  # pose_line: longer than its 4096-byte line limit, so line_too_long is reachable.
  max_len=4096
  [ "$target" = pose_line ] && max_len=9000
  (cd "$work" && "$OLDPWD/build/fuzz/tests/fuzz/fuzz_$target" -max_total_time="$seconds" -max_len="$max_len" \
     -print_final_stats=1 "$work/$target" >"$work/$target.log" 2>&1) || status=$?
  tail -n 6 "$work/$target.log"
  if [ "$status" -ne 0 ]; then
    echo "fuzz_$target FAILED (exit $status); the crashing input is in the log above:"
    grep -E "ERROR|SUMMARY|crash-|Test unit written" "$work/$target.log" | head -20
    exit 1
  fi
done
echo "fuzz: ${#targets[@]} passed, 0 failed"
