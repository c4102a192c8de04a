#!/usr/bin/env bash
# Installs everything, builds, and runs the main job on the built-in sample
# trajectory: a 10-minute aircraft-like flight given at 1 Hz becomes a 400 Hz
# ideal IMU in the ecef scene, which is then integrated back and compared.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh release
exec build/release/daemon/imuemu demo --out-dir out/demo "$@"
