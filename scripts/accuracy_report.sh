#!/usr/bin/env bash
# Regenerates docs/accuracy.md, docs/accuracy.csv and
# docs/accuracy_speed_vs_error.png: every method over the reference set
# against analytic truth (bench/accuracy_report.cpp). Takes a few minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/release/bench/accuracy_report ] || bash scripts/build.sh release
build/release/bench/accuracy_report docs "$@"
/usr/bin/python3 scripts/accuracy_plot.py docs/accuracy.csv docs/accuracy_speed_vs_error.png
