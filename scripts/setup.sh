#!/usr/bin/env bash
# Installs the Debian bookworm packages imuemu needs. Run as root; safe to run
# again (only what is missing is installed).
#   scripts/setup.sh build   what building and running imuemu and imuemud needs
#                            (toolchain, libraries): scripts/demo.sh
#   scripts/setup.sh test    that plus the test stack (GoogleTest, Benchmark,
#                            libFuzzer, plotting, the hardware-in-the-loop
#                            fixtures' QEMU, user-mode Linux, kernel headers,
#                            systemd): scripts/test.sh. The default.
# apt's own output goes to a log (IMUEMU_SETUP_LOG, default
# /tmp/imuemu-setup.log); its last lines are shown if it fails.
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
what=${1:-test}

build_packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config
  # core maths and geodesy
  libeigen3-dev libgeographiclib-dev
  # transports
  libserialport-dev libgpiod-dev linux-libc-dev libboost-dev libsystemd-dev
  # configuration and command line
  libtomlplusplus-dev libcli11-dev nlohmann-json3-dev
)
test_packages=(
  git ca-certificates
  # tests, benchmarks, and libFuzzer (clang's runtime) for the parsers
  libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev
  # lld links the ASan tree (scripts/build.sh asan)
  lld
  # plots and the Python test peers (run under Debian's /usr/bin/python3)
  python3 python3-numpy python3-matplotlib
  # hardware-in-the-loop fixtures (tests/hil): user-mode Linux with vcan; QEMU
  # booting Debian's kernel (fetched by apt-get download) with a busybox
  # initramfs, the UART, vcan and the gpio_recorder module built against the
  # headers; the CAN and GPIO tools run inside both; systemd as PID 1 in the
  # guest and systemd-analyze (a minbase system has no systemd), ps for its checks;
  # setserial raises the guest UART's baud_base for the 921600-baud change
  user-mode-linux kmod iproute2 qemu-system-x86 busybox-static cpio xz-utils
  linux-headers-amd64 can-utils gpiod python3-can systemd procps setserial
  # the Debian package (debian/, tests/package/package_check.sh): built with
  # debhelper (imuemu-scene(5) by pandoc), checked by lintian, man pages
  # rendered by man-db, installed with apt into an overlay of this system
  debhelper dpkg-dev pandoc lintian man-db apt
  # GNSS receiver acceptance (tests/cli/test_gnss_gpsd.cpp): Debian's gpsd reads
  # imuemu's NMEA and UBX ptys
  gpsd gpsd-clients
)

case "$what" in
  build) packages=("${build_packages[@]}") ;;
  test) packages=("${build_packages[@]}" "${test_packages[@]}") ;;
  *) echo "usage: $0 [build|test]" >&2; exit 2 ;;
esac

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
  echo "setup ($what): all ${#packages[@]} packages already installed"
  exit 0
fi
log=${IMUEMU_SETUP_LOG:-/tmp/imuemu-setup.log}
echo "setup ($what): installing ${#missing[@]} Debian packages (apt's output: $log; a few minutes on a fresh system)"
start=$SECONDS
if ! { apt-get update -q && apt-get install -y -q --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
  echo "setup ($what): apt-get failed; the last lines of $log:" >&2
  tail -n 30 "$log" >&2
  exit 1
fi
echo "setup ($what): done in $((SECONDS - start)) s"
