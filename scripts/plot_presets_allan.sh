#!/usr/bin/env bash
# The Allan deviation plot of each sensor preset (issue 15, acceptance 1):
# a static body (`imuemu sample-trajectory --kind static`), its IMU output
# through `imuemu generate --sensor PRESET --seed 1`, analysed by
# `imuemu allan --png`. Same rates, durations and seed as
# tests/cli/test_allan_presets.cpp; docs/allan.md shows the results.
#   scripts/plot_presets_allan.sh [BUILD_DIR] [OUT_DIR]
# Needs about 3 GB of free space in $TMPDIR (the STIM300's 13.8 M-row CSV,
# deleted afterwards).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$here/build/release}"
out="${2:-$here/docs}"
imuemu="$build/daemon/imuemu"
work="$(mktemp -d "${TMPDIR:-/tmp}/imuemu-presets-XXXXXX")"
trap 'rm -rf "$work"' EXIT

# preset rate_hz hours [extra allan options for the accelerometer]
run() {
  local preset="$1" rate="$2" hours="$3" accel_opts="${4:-}"
  local seconds=$((hours * 3600 + 10))
  "$imuemu" sample-trajectory --kind static --duration-s "$seconds" --period-s 10 --out "$work/static.csv"
  "$imuemu" generate --in "$work/static.csv" --out "$work/$preset.csv" --rate "$rate" --sensor "$preset" --seed 1 --quiet
  if [[ -z "$accel_opts" ]]; then
    "$imuemu" allan "$work/$preset.csv" --png "$out/allan_$preset.png" > "$out/allan_$preset.txt"
  else
    "$imuemu" allan "$work/$preset.csv" --axes gyro --png "$out/allan_${preset}_gyro.png" > "$out/allan_$preset.txt"
    # shellcheck disable=SC2086
    "$imuemu" allan "$work/$preset.csv" --axes accel $accel_opts --png "$out/allan_${preset}_accel.png" >> "$out/allan_$preset.txt"
  fi
  rm -f "$work/$preset.csv"
  echo "$preset: $out/allan_$preset*.png"
}

run icm42688p 1000 1
run adis16470 25 24
run stim300 20 192
# HG9900's accelerometer has bias instability only (no VRW in the brochure):
# fit above the flicker's configured tau_min (docs/allan.md "The presets").
run hg9900 1 700 "--fit-min-tau-s 100"
