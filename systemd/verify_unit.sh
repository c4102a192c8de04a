#!/usr/bin/env bash
# Checks imuemud@.service the way systemd reads it:
#   verify_unit.sh UNIT DAEMON_BINARY [SYSUSERS_CONF [TMPFILES_CONF]]
# - systemd-analyze verify on an instance of the template (imuemud@bench),
#   ExecStart pointed at DAEMON_BINARY (verify insists the binary exists);
#   any diagnostic about the unit fails the test, not only errors;
# - the directives issue 6 requires are present, the forbidden ones absent;
# - systemd-sysusers / systemd-tmpfiles parse the two config files (dry run
#   into a scratch root: nothing on this machine changes);
# - prints the exposure score of `systemd-analyze security --offline=true`
#   and fails if it rises above IMUEMU_MAX_EXPOSURE (default 3.0).
set -euo pipefail
unit=${1:?unit file}
daemon=${2:?daemon binary}
sysusers=${3:-}
tmpfiles=${4:-}
max_exposure=${IMUEMU_MAX_EXPOSURE:-3.0}

command -v systemd-analyze >/dev/null || { echo "verify_unit: systemd-analyze not found (package systemd)"; exit 1; }
[[ -x $daemon ]] || { echo "verify_unit: $daemon is not an executable"; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

instance=$work/imuemud@bench.service
sed -E "s|^ExecStart=[^ ]+|ExecStart=$daemon|" "$unit" >"$instance"
grep -q "^ExecStart=$daemon --scene /etc/imuemu/%i.toml\$" "$instance" ||
  { echo "verify_unit: ExecStart is not '<binary> --scene /etc/imuemu/%i.toml'"; exit 1; }

status=0
# SYSTEMD_LOG_LEVEL=notice keeps systemd's own debug chatter out; every line
# that remains is about our unit.
out=$(SYSTEMD_LOG_LEVEL=notice systemd-analyze verify --man=no "$instance" 2>&1) || status=$?
if [[ $status -ne 0 || -n $out ]]; then
  echo "verify_unit: systemd-analyze verify reported (exit $status):"
  echo "$out"
  exit 1
fi
echo "verify_unit: systemd-analyze verify: clean"

# Issue 6's list, one directive per line as written in the unit.
required=(
  "Type=notify" "NotifyAccess=main" "Restart=on-failure" "User=imuemu" "Group=imuemu"
  "SupplementaryGroups=dialout" "RuntimeDirectory=imuemu" "UMask=0007" "NoNewPrivileges=yes"
  "ProtectSystem=strict" "ProtectHome=yes" "PrivateTmp=yes"
  "RestrictAddressFamilies=AF_UNIX AF_INET AF_INET6 AF_CAN AF_NETLINK"
  "DevicePolicy=closed" "DeviceAllow=char-ttyS rw" "DeviceAllow=char-ttyUSB rw" "DeviceAllow=char-ttyACM rw"
  "DeviceAllow=/dev/ptmx rw" "DeviceAllow=char-pts rw" "DeviceAllow=char-gpiochip rw"
  "CapabilityBoundingSet=CAP_SYS_NICE CAP_IPC_LOCK" "AmbientCapabilities=CAP_SYS_NICE CAP_IPC_LOCK"
  "ProtectKernelTunables=yes" "ProtectKernelModules=yes" "ProtectKernelLogs=yes" "ProtectControlGroups=yes"
  "ProtectClock=yes" "ProtectHostname=yes" "RestrictNamespaces=yes" "LockPersonality=yes"
  "MemoryDenyWriteExecute=yes" "RestrictSUIDSGID=yes" "SystemCallArchitectures=native"
  "SystemCallFilter=@system-service" "ExecReload=kill -HUP \$MAINPID"
)
for line in "${required[@]}"; do
  grep -qxF "$line" "$unit" || { echo "verify_unit: missing directive: $line"; status=1; }
done
grep -qE '^WatchdogSec=[1-9]' "$unit" || { echo "verify_unit: missing WatchdogSec="; status=1; }
for forbidden in PrivateDevices PrivateNetwork RestrictRealtime; do
  grep -qE "^$forbidden=" "$unit" && { echo "verify_unit: $forbidden= must not be set (real devices, networks, SCHED_FIFO)"; status=1; }
done
((status == 0)) || exit 1
echo "verify_unit: required directives present, PrivateDevices/PrivateNetwork/RestrictRealtime absent"

if [[ -n $sysusers ]]; then
  mkdir -p "$work/root/etc"
  printf 'root:x:0:\ndialout:x:20:\n' >"$work/root/etc/group"
  printf 'root:x:0:0::/root:/bin/sh\n' >"$work/root/etc/passwd"
  : >"$work/root/etc/shadow"; : >"$work/root/etc/gshadow"
  systemd-sysusers --root="$work/root" "$sysusers" ||
    { echo "verify_unit: systemd-sysusers rejected $sysusers"; exit 1; }
  grep -q '^imuemu:x:[0-9]*:[0-9]*:' "$work/root/etc/passwd" || { echo "verify_unit: no user imuemu created"; exit 1; }
  grep -qE '^imuemu:x:[0-9]+:$' "$work/root/etc/group" || { echo "verify_unit: no group imuemu created"; exit 1; }
  grep -qE '^dialout:x:20:(.*,)?imuemu(,.*)?$' "$work/root/etc/group" || { echo "verify_unit: imuemu not in dialout"; exit 1; }
  echo "verify_unit: systemd-sysusers (scratch root): user+group imuemu, member of dialout"
fi
if [[ -n $tmpfiles ]]; then
  mkdir -p "$work/root/run"
  systemd-tmpfiles --root="$work/root" --create "$tmpfiles" ||
    { echo "verify_unit: systemd-tmpfiles rejected $tmpfiles"; exit 1; }
  mode=$(stat -c %a "$work/root/run/imuemu")
  [[ $mode == 750 ]] || { echo "verify_unit: /run/imuemu mode $mode, expected 750"; exit 1; }
  echo "verify_unit: systemd-tmpfiles (scratch root): /run/imuemu 0750"
fi

exposure=$(systemd-analyze security --offline=true --no-pager "$instance" 2>/dev/null |
           sed -nE 's/.*Overall exposure level for .*: ([0-9.]+).*/\1/p')
[[ -n $exposure ]] || { echo "verify_unit: no exposure score from systemd-analyze security"; exit 1; }
echo "verify_unit: systemd-analyze security exposure: $exposure (limit $max_exposure)"
awk -v e="$exposure" -v m="$max_exposure" 'BEGIN { exit !(e <= m) }' ||
  { echo "verify_unit: exposure $exposure above $max_exposure"; exit 1; }
