#!/usr/bin/env bash
# Hardware-in-the-loop fixture: runs one command inside a real Linux kernel
# (user-mode Linux, Debian package user-mode-linux) that has SocketCAN and a
# virtual CAN interface vcan0, which the machine's own kernel may lack.
#
#   tests/hil/uml_run.sh [--results DIR] [--timeout SECONDS] [--mem SIZE] [--] CMD [ARG...]
#
# The guest's root file system is the host's own root (hostfs), so every host
# binary, library and build directory is reachable at the same absolute path
# and files the command writes land on the host. Inside the guest:
#   - can, can-raw, can-dev and vcan are loaded from /usr/lib/uml/modules/<ver>/
#     and vcan0 is up with MTU 72 (CAN FD frames fit); lo is up;
#   - CMD runs as root in the caller's working directory with the caller's
#     environment, stdin from /dev/null, stdout+stderr captured;
#   - HIL_OUT names a host directory (same path in the guest) for extra results.
# Afterwards the captured output is printed here, the results directory holds
# output.txt, rc, console.log (the guest kernel's console), and this script
# exits with CMD's exit code. If the fixture itself fails (UML cannot boot,
# a module does not load, the guest hangs) it prints the reason with the
# console log and exits 125, never 0.
#
# UML's clocks are emulated: use it for functional tests, not timing.
# AddressSanitizer binaries cannot run here: UML's user address space ends at
# 0x7fc0000000, below the shadow ASan needs on x86_64 ("Shadow memory range
# interleaves with an existing memory mapping"); run them under qemu_run.sh.
set -euo pipefail

readonly FIXTURE_FAILURE=125
fail() { echo "uml_run: FIXTURE FAILURE: $*" >&2; exit $FIXTURE_FAILURE; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//' >&2; exit 2; }

results_dir=""
timeout_s=120
mem=512M
while (($#)); do
  case "$1" in
    --results) results_dir=$2; shift 2 ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --mem) mem=$2; shift 2 ;;
    -h|--help) usage ;;
    --) shift; break ;;
    -*) echo "uml_run: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
(($#)) || { echo "uml_run: no command given" >&2; usage; }

start_ns=$(date +%s%N)
uml=$(command -v linux.uml) || fail "linux.uml not found: install the Debian package user-mode-linux (scripts/setup.sh)"
insmod=$(command -v insmod || echo /usr/sbin/insmod)
[[ -x $insmod ]] || fail "insmod not found: install the Debian package kmod (scripts/setup.sh)"
ip_cmd=$(command -v ip || echo /usr/sbin/ip)
[[ -x $ip_cmd ]] || fail "ip not found: install the Debian package iproute2"
# The kernel version is the UML binary's own; its modules must match it exactly.
uml_version=$("$uml" --version 2>/dev/null | head -n1) || true
modules_dir=/usr/lib/uml/modules/$uml_version/kernel
[[ -n $uml_version && -d $modules_dir ]] ||
  fail "no UML modules for kernel '$uml_version' under /usr/lib/uml/modules (have: $(ls /usr/lib/uml/modules 2>/dev/null | tr '\n' ' '))"
can_modules=(net/can/can.ko net/can/can-raw.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko)
for m in "${can_modules[@]}"; do [[ -f $modules_dir/$m ]] || fail "missing UML module $modules_dir/$m"; done

# Scratch for this run. It must be on a host path the guest sees unchanged, so
# no tmpfs is mounted over it inside.
work=$(mktemp -d "${TMPDIR:-/tmp}/uml_run.XXXXXX")
uml_pid=""
cleanup() { [[ -n $uml_pid ]] && kill "$uml_pid" 2>/dev/null; rm -rf "$work"; }
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
  export -p | grep -v -E '^declare -x (BASHOPTS|SHELLOPTS|BASH_[A-Z_]*|PPID|UID|EUID|SHLVL|OLDPWD)='
  printf 'export HIL_OUT=%q\n' "$results_dir"
  printf 'hil_cwd=%q\n' "$PWD"
  printf 'hil_cmd=('; printf '%q ' "$@"; printf ')\n'
} >"$work/command.sh"

# PID 1 of the guest. devtmpfs is already on /dev (CONFIG_DEVTMPFS_MOUNT=y).
# Mounts here live only in the UML kernel; the host's mounts are untouched.
cat >"$work/init.sh" <<EOF
#!/bin/bash
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
results=$(printf %q "$results_dir")
power_off() { sync; echo o >/proc/sysrq-trigger; sleep 10; }
setup_failed() { echo "guest setup failed: \$*" >>"\$results/guest_setup.txt"; power_off; }
mount -t proc proc /proc || setup_failed "mount /proc"
mount -t sysfs sysfs /sys || setup_failed "mount /sys"
mount -t tmpfs tmpfs /run || setup_failed "mount /run"
mount -t devpts devpts /dev/pts 2>/dev/null || true
for m in ${can_modules[*]}; do
  $insmod $modules_dir/\$m 2>>"\$results/guest_setup.txt" || setup_failed "insmod \$m"
done
{ $ip_cmd link set lo up &&
  $ip_cmd link add dev vcan0 type vcan &&
  $ip_cmd link set vcan0 mtu 72 &&
  $ip_cmd link set vcan0 up; } 2>>"\$results/guest_setup.txt" || setup_failed "creating vcan0"
source $(printf %q "$work/command.sh")
cd "\$hil_cwd" || setup_failed "cd \$hil_cwd"
"\${hil_cmd[@]}" </dev/null >"\$results/output.txt" 2>&1
echo \$? >"\$results/rc.tmp"
mv "\$results/rc.tmp" "\$results/rc"
power_off
EOF
chmod +x "$work/init.sh"

# UML keeps guest memory in a file under TMPDIR; /dev/shm is a tmpfs that
# allows exec mappings on Debian.
boot_rc=0
TMPDIR=/dev/shm timeout --kill-after=5 "$timeout_s" \
  "$uml" mem="$mem" rootfstype=hostfs rw init="$work/init.sh" quiet \
  con=null con0=null,fd:1 </dev/null >"$results_dir/console.log" 2>&1 &
uml_pid=$!
wait "$uml_pid" || boot_rc=$?
uml_pid=""
end_ns=$(date +%s%N)
elapsed=$(awk -v a="$start_ns" -v b="$end_ns" 'BEGIN { printf "%.2f", (b - a) / 1e9 }')

if [[ -s $results_dir/output.txt ]]; then
  cat "$results_dir/output.txt"
fi
if [[ ! -f $results_dir/rc ]]; then
  {
    ((boot_rc == 124 || boot_rc == 137)) && echo "uml_run: the guest did not power off within ${timeout_s} s"
    [[ -s $results_dir/guest_setup.txt ]] && sed 's/^/uml_run: /' "$results_dir/guest_setup.txt"
    echo "uml_run: linux.uml exited with status $boot_rc; last console lines:"
    tail -n 40 "$results_dir/console.log"; echo
  } >&2
  fail "the command did not run to completion inside UML (${elapsed} s)"
fi
cmd_rc=$(<"$results_dir/rc")
echo "uml_run: UML $uml_version boot+run+poweroff ${elapsed} s, command exit status $cmd_rc" >&2
exit "$cmd_rc"
