#!/usr/bin/env bash
# Installs everything, builds the Release and the ASan+UBSan (clang) flavours
# and runs the whole test suite in both, plus the fuzz targets (built in the
# ASan tree) for a bounded time. This is what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
status=0
failed=()  # what failed, for the verdict line
fail() { status=1; failed+=("$1"); }
# Where CI's time goes (issue 25): each stage prints its wall time and the
# CPU the whole machine spent meanwhile (from /proc/stat, all processes: the
# ASan build beside the Release tests counts in both), and a table at the end.
# So a change to the suite is measured before it is argued about.
stage_names=() stage_walls=() stage_cpus=()
machine_cpu_s() {  # busy CPU seconds of all cores since boot
  awk '/^cpu /{printf "%d", ($2+$3+$4+$7+$8)/100}' /proc/stat
}
stage_name="" stage_start=0 stage_cpu0=0 run_start=$SECONDS
stage() {  # stage NAME: ends the current stage (if any), starts NAME
  if [[ -n $stage_name ]]; then
    local wall=$((SECONDS - stage_start)) cpu=$(( $(machine_cpu_s) - stage_cpu0 ))
    stage_names+=("$stage_name") stage_walls+=("$wall") stage_cpus+=("$cpu")
    echo "--- $stage_name: ${wall} s wall, ${cpu} CPU-s"
  fi
  stage_name=$1 stage_start=$SECONDS stage_cpu0=$(machine_cpu_s)
  [[ -n $stage_name ]] && echo "=== $stage_name"
  return 0
}
stage_summary() {
  stage ""
  echo "=== time per stage (wall, CPU of the whole machine; $(nproc) cores)"
  local i
  for i in "${!stage_names[@]}"; do
    printf '  %-58s %5d s %6d CPU-s\n' "${stage_names[$i]}" "${stage_walls[$i]}" "${stage_cpus[$i]}"
  done
  printf '  %-58s %5d s\n' "total (setup included)" "$((SECONDS - run_start))"
}
# The last line says it all: what passed, or what failed and where to look
# (ctest's own log: build/<flavour>/Testing/Temporary/LastTest.log).
verdict() {
  verdict_said=1
  if ((status == 0)); then
    echo "=== VERDICT: PASSED: release tests, loopback runs, package, asan tests, fuzz ($((SECONDS - run_start)) s)"
  else
    local IFS=';'
    echo "=== VERDICT: FAILED: ${failed[*]} (ctest logs: build/release|asan/Testing/Temporary/LastTest.log)"
  fi
}
# A stage that stops the script (set -e: setup, the release build) still
# gets its verdict line.
trap 'rc=$?; ((rc == 0)) || [[ -n ${verdict_said:-} ]] || echo "=== VERDICT: FAILED: ${stage_name:-?} (exit $rc; its output above)"' EXIT
stage "setup"
bash scripts/setup.sh
# The hardware-in-the-loop fixtures (label hil: user-mode Linux and QEMU,
# tests/hil/README.md) run once, on the release binaries: ASan binaries cannot
# run under user-mode Linux, and the fixtures test kernels and wires, not
# memory safety (the same code runs under ASan in the unit tests). So do the
# 30-s loopback runs (label loopback): they test delivery at the exact rate.
# The long numeric runs (label heavy, tests/heavy_tests.cmake) run in Release
# only: under ASan at -O1 they cost 12 of the flavour's 16 test minutes and
# exercise no code path the short tests do not. The peak-memory tests (label
# memory) would measure ASan's own shadow memory, so they too are Release only.
stage "release: build"
bash scripts/build.sh release
# The Release tests leave about half of the two cores idle (measured: 399 s of
# wall time for about 200 s of CPU): most wait on real time (emission at its
# rate, daemons, QEMU and UML boots). The ASan build runs beside them at the
# lowest priority (nice 19, so the tests keep the CPU they ask for) and takes
# the rest; every test asserts only what holds on a loaded host. The loopback
# runs measure delivery at the exact rate, so they wait for an idle machine.
echo "=== asan: build starts (beside the release tests, nice 19; compiler output in build/asan/build.log)"
IMUEMU_BUILD_QUIET=1 nice -n 19 bash scripts/build.sh asan &
asan_build=$!
stage "release: test (all but loopback) + asan build beside"
ctest --test-dir build/release --output-on-failure -j "$(nproc)" -LE "loopback|package" || fail "release tests"
echo "release tests ended $((SECONDS - stage_start)) s into the stage; waiting for the asan build"
asan_built=1
wait "$asan_build" || { asan_built=0; fail "asan build (build/asan/build.log)"; }
stage "release: loopback runs (all at once, idle machine)"
ctest --test-dir build/release --output-on-failure -L loopback -j 10 || fail "loopback runs"
# The Debian package check (label package: dpkg-buildpackage from a clean
# clone with the programs from build/release, lintian, apt install, purge;
# about 1 CPU-minute, one core) runs beside the ASan stage, whose tests leave
# CPU idle while they wait on real time.
echo "=== package: dpkg-buildpackage, lintian, install and purge, beside the asan stage (log: build/release/package.log)"
ctest --test-dir build/release --output-on-failure -L package > build/release/package.log 2>&1 &
package_run=$!
wait_package() {
  local ok=1
  wait "$package_run" || ok=0
  cat build/release/package.log
  ((ok)) || fail "package"
}
if ((asan_built)); then
  # The libFuzzer targets run beside the ASan tests, one at a time, for
  # FUZZ_SECONDS of wall time each (30 s, as issue 25 asks; 11 targets: about
  # 330 s, as long as the ASan tests). Measured at 1597 s: the ASan tests left
  # about 125 of their stage's 644 CPU-s idle (most wait on real time), and the
  # whole run needed about 2960 CPU-s, so on 2 cores no order of the stages
  # fitted 1500 s while fuzz had a stage of its own (190 s). Beside the tests, a
  # target shares a core: it gets its 30 s, but fewer executions in them than
  # alone. Longer campaigns: scripts/fuzz.sh 600.
  stage "asan: test + fuzz beside (${FUZZ_SECONDS:-30} s per target, one at a time)"
  FUZZ_JOBS=1 FUZZ_BUILT=1 bash scripts/fuzz.sh "${FUZZ_SECONDS:-30}" > build/asan/fuzz.log 2>&1 &
  fuzz_run=$!
  ctest --test-dir build/asan --output-on-failure -j "$(nproc)" -LE "hil|loopback|heavy|memory" || fail "asan tests"
  echo "asan tests ended $((SECONDS - stage_start)) s into the stage; waiting for the fuzz targets"
  fuzz_ok=1
  wait "$fuzz_run" || fuzz_ok=0
  cat build/asan/fuzz.log
  ((fuzz_ok)) || fail "fuzz"
  wait_package
else
  wait_package
  echo "=== asan: build failed (above); its tests and the fuzz targets did not run"
  stage_summary
  verdict
  exit 1
fi
stage_summary
verdict
exit $status
