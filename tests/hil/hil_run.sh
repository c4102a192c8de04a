#!/usr/bin/env bash
# Hardware-in-the-loop fixture: runs one command inside a real Linux kernel
# that has SocketCAN and a virtual CAN interface vcan0, which the machine's
# own kernel may lack, with the host's own root file system as the guest's.
#
#   tests/hil/hil_run.sh [--results DIR] [--timeout SECONDS] [--mem SIZE] [--] CMD [ARG...]
#
# The backend (IMUEMU_HIL_BACKEND=auto|uml|qemu, see hil_backend.sh) is
#   uml   user-mode Linux (Debian's user-mode-linux) with the host's root
#         through hostfs, read-write: files the command writes anywhere land
#         on the host; can, can-raw, can-dev and vcan from
#         /usr/lib/uml/modules/<ver>/;
#   qemu  Debian's amd64 kernel under QEMU TCG (qemu_run.sh --host-root) with
#         the host's root read-only over virtio-9p under a tmpfs overlay: only
#         what the command writes to $HIL_OUT lands on the host; the CAN
#         modules come from Debian's kernel package.
# Either way every host binary, library and build directory is at the same
# absolute path; vcan0 is up with MTU 72 (CAN FD frames fit), lo is up; CMD
# runs as root in the caller's working directory with the caller's
# environment plus HIL_BACKEND (uml|qemu), stdin from /dev/null, stdout+stderr
# captured; HIL_OUT names a host directory (same path in the guest) for extra
# results. Afterwards the captured output is printed here, the results
# directory holds output.txt, rc, console.log (the guest kernel's whole
# console), and this script exits with CMD's exit code. If the fixture itself
# fails (no backend boots, a module does not load, the guest hangs) it prints
# the reason, the console lines that show the cause and the path of the whole
# console, and exits 125, never 0.
#
# Emulated clocks (UML) and TCG (QEMU) are slow and jittery: use this for
# functional tests, not timing. AddressSanitizer binaries cannot run under
# UML: its user address space ends at 0x7fc0000000, below the shadow ASan
# needs on x86_64; they do run under the qemu backend.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=hil_backend.sh
source "$here/hil_backend.sh"
readonly FIXTURE_FAILURE=$HIL_FIXTURE_FAILURE
fail() { echo "hil_run: FIXTURE FAILURE: $*" >&2; exit $FIXTURE_FAILURE; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//' >&2; exit 2; }

results_dir=""
timeout_s=240
mem=512M
while (($#)); do
  case "$1" in
    --results) results_dir=$2; shift 2 ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --mem) mem=$2; shift 2 ;;
    -h|--help) usage ;;
    --) shift; break ;;
    -*) echo "hil_run: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
(($#)) || { echo "hil_run: no command given" >&2; usage; }

start_ns=$(date +%s%N)
hil_choose_backend hil_run
ip_cmd=$(command -v ip || echo /usr/sbin/ip)
[[ -x $ip_cmd ]] || fail "ip not found: install the Debian package iproute2"
insmod=""
can_modules=()
if [[ $hil_backend == uml ]]; then
  uml=$(command -v linux.uml)
  insmod=$(command -v insmod || echo /usr/sbin/insmod)
  [[ -x $insmod ]] || fail "insmod not found: install the Debian package kmod (scripts/setup.sh)"
  # The kernel version is the UML binary's own; its modules must match it exactly.
  uml_version=$("$uml" --version 2>/dev/null | head -n1) || true
  modules_dir=/usr/lib/uml/modules/$uml_version/kernel
  [[ -n $uml_version && -d $modules_dir ]] ||
    fail "no UML modules for kernel '$uml_version' under /usr/lib/uml/modules (have: $(ls /usr/lib/uml/modules 2>/dev/null | tr '\n' ' '))"
  can_modules=(net/can/can.ko net/can/can-raw.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko)
  for m in "${can_modules[@]}"; do [[ -f $modules_dir/$m ]] || fail "missing UML module $modules_dir/$m"; done
  can_modules=("${can_modules[@]/#/$modules_dir/}")
fi

# Scratch for this run. It must be on a host path the guest sees unchanged, so
# no tmpfs is mounted over it inside.
work=$(mktemp -d "${TMPDIR:-/tmp}/hil_run.XXXXXX")
chmod 755 "$work"
guest_pid=""
cleanup() { [[ -n $guest_pid ]] && kill "$guest_pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
trap 'exit 143' TERM INT HUP
if [[ -z $results_dir ]]; then
  results_dir=$work/results
fi
mkdir -p "$results_dir"
results_dir=$(cd "$results_dir" && pwd)
rm -f "$results_dir/rc" "$results_dir/output.txt" "$results_dir/guest_setup.txt"

# The command, working directory and environment, as bash source for the guest.
{
  export -p | grep -v -E '^declare -x (BASHOPTS|SHELLOPTS|BASH_[A-Z_]*|PPID|UID|EUID|SHLVL|OLDPWD|HIL_OUT|HIL_BACKEND)='
  printf 'export HIL_OUT=%q HIL_BACKEND=%q\n' "$results_dir" "$hil_backend"
  printf 'hil_cwd=%q\n' "$PWD"
  printf 'hil_cmd=('; printf '%q ' "$@"; printf ')\n'
} >"$work/command.sh"

# PID 1 of the guest. Mounts here live only in the guest kernel; the host's
# mounts are untouched. UML: devtmpfs is already on /dev
# (CONFIG_DEVTMPFS_MOUNT=y); the CAN modules are loaded here. QEMU:
# qemu_run.sh's initramfs has loaded them, set vcan0 up and moved /dev, /proc
# and /sys into the host root.
cat >"$work/init.sh" <<EOF
#!/bin/bash
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
results=$(printf %q "$results_dir")
power_off() { sync; echo o >/proc/sysrq-trigger; sleep 10; }
setup_failed() { echo "guest setup failed: \$*" >>"\$results/guest_setup.txt"; power_off; }
mountpoint -q /proc || mount -t proc proc /proc || setup_failed "mount /proc"
mountpoint -q /sys || mount -t sysfs sysfs /sys || setup_failed "mount /sys"
mount -t tmpfs tmpfs /run || setup_failed "mount /run"
mountpoint -q /dev/pts || mount -t devpts devpts /dev/pts 2>/dev/null || true
for m in ${can_modules[*]}; do
  $insmod \$m 2>>"\$results/guest_setup.txt" || setup_failed "insmod \$m"
done
if ! $ip_cmd link show dev vcan0 >/dev/null 2>&1; then
  { $ip_cmd link set lo up &&
    $ip_cmd link add dev vcan0 type vcan &&
    $ip_cmd link set vcan0 mtu 72 &&
    $ip_cmd link set vcan0 up; } 2>>"\$results/guest_setup.txt" || setup_failed "creating vcan0"
fi
source $(printf %q "$work/command.sh")
cd "\$hil_cwd" || setup_failed "cd \$hil_cwd"
"\${hil_cmd[@]}" </dev/null >"\$results/output.txt" 2>&1
echo \$? >"\$results/rc.tmp"
mv "\$results/rc.tmp" "\$results/rc"
power_off
EOF
chmod +x "$work/init.sh"

boot_rc=0
if [[ $hil_backend == uml ]]; then
  # UML keeps guest memory in a file under TMPDIR; /dev/shm is a tmpfs that
  # allows exec mappings on Debian.
  TMPDIR=/dev/shm timeout --kill-after=5 "$timeout_s" \
    "$uml" mem="$mem" rootfstype=hostfs rw init="$work/init.sh" quiet \
    con=null con0=null,fd:1 </dev/null >"$results_dir/console.log" 2>&1 &
  kernel="UML $uml_version"
else
  # qemu_run.sh writes console.log into the results and prints its own
  # diagnosis when the guest does not reach init.sh.
  "$here/qemu_run.sh" --results "$results_dir" --timeout "$timeout_s" --mem "$mem" \
    --share "$results_dir" --host-root "$work/init.sh" </dev/null >&2 &
  kernel="QEMU (Debian's kernel, TCG)"
fi
guest_pid=$!
wait "$guest_pid" || boot_rc=$?
guest_pid=""
end_ns=$(date +%s%N)
elapsed=$(awk -v a="$start_ns" -v b="$end_ns" 'BEGIN { printf "%.2f", (b - a) / 1e9 }')

if [[ -s $results_dir/output.txt ]]; then
  cat "$results_dir/output.txt"
fi
if [[ ! -f $results_dir/rc ]]; then
  {
    ((boot_rc == 124 || boot_rc == 137)) && echo "hil_run: the guest did not power off within ${timeout_s} s"
    [[ -s $results_dir/guest_setup.txt ]] && sed 's/^/hil_run: /' "$results_dir/guest_setup.txt"
    echo "hil_run: $kernel exited with status $boot_rc; the console's lines that show the cause:"
    hil_console_cause "$results_dir/console.log" | sed 's/^/  /'
    console=$results_dir/console.log
    if [[ $results_dir == "$work"/* ]]; then  # temporary results: keep the console
      console=$(mktemp "${TMPDIR:-/tmp}/hil_run.console.XXXXXX")
      cp "$results_dir/console.log" "$console" 2>/dev/null || true
    fi
    echo "hil_run: whole console: $console"
  } >&2
  fail "the command did not run to completion on backend $hil_backend (${elapsed} s)"
fi
cmd_rc=$(<"$results_dir/rc")
echo "hil_run: backend $hil_backend: $kernel boot+run+poweroff ${elapsed} s, command exit status $cmd_rc" >&2
exit "$cmd_rc"
