#!/usr/bin/env bash
# Regenerates docs/thesis_fig2.png .. thesis_fig8.png (thesis Appendix A/B,
# Figures 2-8) from the project's own interpolation and smoothing.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/release/bench/thesis_cases ] || bash scripts/build.sh release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
build/release/bench/thesis_cases "$tmp"
/usr/bin/python3 scripts/thesis_figures.py "$tmp" docs
