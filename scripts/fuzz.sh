#!/usr/bin/env bash
# Builds the libFuzzer targets (in the clang ASan+UBSan tree, build/asan) and
# runs each for a bounded time from the seed corpora in tests/fuzz/corpus
# (copied, so the repository is never modified), FUZZ_JOBS at a time (default
# 2, one per core; scripts/test.sh runs them one at a time beside the ASan tests).
# Runs every target; exits non-zero if any crashed, naming each and its input.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 30)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-${FUZZ_SECONDS:-30}}
targets=(trajectory_csv imu_csv decimal_time pose_line pose_datagram live_path mavlink_senders error_model fault_table scene control_request)
# FUZZ_BUILT=1: the caller built them (scripts/test.sh: the whole ASan tree),
# so no cmake runs in build/asan while its tests read it.
if [[ ${FUZZ_BUILT:-0} != 1 ]]; then
  IMUEMU_BUILD_QUIET=${IMUEMU_BUILD_QUIET:-1} bash scripts/build.sh asan "${targets[@]/#/fuzz_}"
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
root=$PWD
run_target() {
  local target=$1 max_len=4096
  mkdir -p "$work/$target"
  cp -r "tests/fuzz/corpus/$target/." "$work/$target/"
  # pose_line: longer than its 4096-byte line limit, so line_too_long is reachable.
  [ "$target" = pose_line ] && max_len=9000
  (cd "$work" && "$root/build/asan/tests/fuzz/fuzz_$target" -max_total_time="$seconds" -max_len="$max_len" \
     -print_final_stats=1 "$work/$target" >"$work/$target.log" 2>&1)
}
pids=() failed=()
for target in "${targets[@]}"; do
  run_target "$target" & pids+=("$!:$target")
  if ((${#pids[@]} >= ${FUZZ_JOBS:-2})); then
    entry=${pids[0]}; pids=("${pids[@]:1}")
    wait "${entry%%:*}" || failed+=("${entry#*:}")
  fi
done
for entry in "${pids[@]}"; do wait "${entry%%:*}" || failed+=("${entry#*:}"); done
for target in "${targets[@]}"; do
  echo "=== fuzz_$target: ${seconds}s"
  tail -n 6 "$work/$target.log"
done
if ((${#failed[@]})); then
  mkdir -p build/asan/fuzz_crashes
  cp "$work"/crash-* "$work"/timeout-* "$work"/oom-* build/asan/fuzz_crashes/ 2>/dev/null || true
fi
for target in "${failed[@]}"; do
  echo "fuzz_$target FAILED; its log (inputs kept in build/asan/fuzz_crashes):"
  grep -E "ERROR|SUMMARY|crash-|Test unit written" "$work/$target.log" | head -20
done
echo "fuzz: $((${#targets[@]} - ${#failed[@]})) passed, ${#failed[@]} failed"
((${#failed[@]} == 0))
