#!/usr/bin/env bash
# Installs every Debian bookworm package imuemu needs to build, test, benchmark
# and plot. Run as root on a fresh machine; safe to run again.
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive

packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config git ca-certificates
  # core maths and geodesy
  libeigen3-dev libgeographiclib-dev
  # transports
  libserialport-dev libgpiod-dev linux-libc-dev libboost-dev libsystemd-dev
  # configuration and command line
  libtomlplusplus-dev libcli11-dev nlohmann-json3-dev
  # tests, benchmarks, and libFuzzer (clang's runtime) for the parsers
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev
  # plots (run under Debian's /usr/bin/python3)
  python3 python3-numpy python3-matplotlib
  # hardware-in-the-loop fixtures (tests/hil): user-mode Linux with vcan; QEMU
  # booting Debian's kernel (fetched by apt-get download) with a busybox
  # initramfs, the UART, vcan and the gpio_recorder module built against the
  # headers; the CAN and GPIO tools run inside both; systemd as PID 1 in the
  # guest and systemd-analyze (a minbase system has no systemd), ps for its checks
  user-mode-linux kmod iproute2 qemu-system-x86 busybox-static cpio xz-utils
  linux-headers-amd64 can-utils gpiod python3-can systemd procps
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all ${#packages[@]} packages already installed"
fi
