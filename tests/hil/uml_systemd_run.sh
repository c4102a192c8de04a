#!/usr/bin/env bash
# Hardware-in-the-loop fixture: boots user-mode Linux with systemd as PID 1
# and checks imuemud@.service there (tests/hil/systemd_guest_check.sh):
# Type=notify readiness, user/groups/capabilities, control socket, watchdog
# pets, reload, a watchdog restart of a stalled emitter, a clean stop.
#
#   tests/hil/uml_systemd_run.sh [--results DIR] [--timeout S] [--unit FILE]
#       [--sysusers FILE] [--tmpfiles FILE] [--scene FILE] [--] IMUEMUD IMUEMU_CLI
#
# IMUEMUD is the daemon binary the unit's ExecStart is pointed at (any
# Type=notify service speaking the same control socket and the test hook
# "stall-emitter", enabled by IMUEMU_TEST_HOOKS=1 in a drop-in);
# IMUEMU_CLI is the imuemu command (`imuemu status`).
# Defaults: systemd/imuemud@.service.in, imuemu.sysusers.conf,
# imuemu.tmpfiles.conf from the source tree, tests/hil/hil_scene.toml.
#
# The guest's root is the host's (hostfs), but everything systemd and the test
# write goes to tmpfs inside the guest: /run, /tmp, /var, and a copy of /etc
# (sysusers adds the user imuemu there, never on the host). Only the results
# directory is written on the host, so it must not be under /tmp, /run, /var
# or /etc (default: a fresh directory under $PWD); a tree or results directory
# there is copied to a work directory under /opt (or /srv, /mnt,
# IMUEMU_HIL_WORK_DIR) first and the results copied back.
# Results: checks.txt (PASS/FAIL lines), journal.txt, console.log, rc.
# Exit: 0 all checks passed, 1 a check failed, 125 the fixture failed (no
# boot, no verdict within the timeout).
set -euo pipefail

readonly FIXTURE_FAILURE=125
fail() { echo "uml_systemd_run: FIXTURE FAILURE: $*" >&2; exit $FIXTURE_FAILURE; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//' >&2; exit 2; }

src=$(cd "$(dirname "$0")/../.." && pwd)
results_dir=""
timeout_s=240
unit_file=$src/systemd/imuemud@.service.in
sysusers_file=$src/systemd/imuemu.sysusers.conf
tmpfiles_file=$src/systemd/imuemu.tmpfiles.conf
scene_file=$src/tests/hil/hil_scene.toml
while (($#)); do
  case "$1" in
    --results) results_dir=$2; shift 2 ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --unit) unit_file=$2; shift 2 ;;
    --sysusers) sysusers_file=$2; shift 2 ;;
    --tmpfiles) tmpfiles_file=$2; shift 2 ;;
    --scene) scene_file=$2; shift 2 ;;
    -h|--help) usage ;;
    --) shift; break ;;
    -*) echo "uml_systemd_run: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
(($# == 2)) || { echo "uml_systemd_run: need IMUEMUD and IMUEMU_CLI" >&2; usage; }
daemon=$(realpath "$1")
cli=$(realpath "$2")
[[ -x $daemon ]] || fail "daemon $daemon is not executable"
[[ -x $cli ]] || fail "imuemu CLI $cli is not executable"
for f in "$unit_file" "$sysusers_file" "$tmpfiles_file" "$scene_file"; do [[ -f $f ]] || fail "missing $f"; done
uml=$(command -v linux.uml) || fail "linux.uml not found: install the Debian package user-mode-linux (scripts/setup.sh)"
[[ -x /lib/systemd/systemd ]] || fail "/lib/systemd/systemd not found (package systemd)"

start_ns=$(date +%s%N)
if [[ -z $results_dir ]]; then
  results_dir=$(mktemp -d "$PWD/uml_systemd.XXXXXX")
fi
mkdir -p "$results_dir"
results_dir=$(cd "$results_dir" && pwd)
guest_check=$src/tests/hil/systemd_guest_check.sh

# Paths the guest cannot use: under tmpfs inside the guest (/tmp, /run, /var,
# the /etc copy), or hidden from the hardened service (ProtectHome= hides
# /home and /root, so a daemon binary there cannot be executed). A checkout
# or build tree there (a CI clone in /tmp, say) is copied to a work
# directory the guest sees, and the results copied back at the end.
hidden_from_guest() { case "$1/" in /tmp/*|/run/*|/var/*|/etc/*|/dev/*|/proc/*|/sys/*|/home/*|/root/*) return 0 ;; esac; return 1; }
final_results=""
relocate=no
for p in "$results_dir" "$daemon" "$cli" "$guest_check" "$unit_file" "$sysusers_file" "$tmpfiles_file" "$scene_file"; do
  hidden_from_guest "$p" && relocate=yes
done
if [[ $relocate == yes ]]; then
  base=""
  for cand in "${IMUEMU_HIL_WORK_DIR:-}" /opt /srv /mnt; do
    [[ -n $cand && -d $cand && -w $cand ]] || continue
    cand=$(cd "$cand" && pwd)
    hidden_from_guest "$cand" || { base=$cand; break; }
  done
  [[ -n $base ]] || fail "the tree is under a path the guest hides (/tmp, /run, /var, /etc, /home, /root) and none of IMUEMU_HIL_WORK_DIR, /opt, /srv, /mnt is writable to copy it to"
  work=$(mktemp -d "$base/imuemu-hil-systemd.XXXXXX")
  chmod 755 "$work"  # mktemp makes it 0700: the service runs as user imuemu
  mkdir -p "$work/bin" "$work/files" "$work/results"
  cp "$daemon" "$work/bin/imuemud" && daemon=$work/bin/imuemud
  cp "$cli" "$work/bin/imuemu" && cli=$work/bin/imuemu
  cp "$guest_check" "$work/files/" && guest_check=$work/files/$(basename "$guest_check")
  for v in unit_file sysusers_file tmpfiles_file scene_file; do
    cp "${!v}" "$work/files/"
    printf -v "$v" '%s' "$work/files/$(basename "${!v}")"
  done
  final_results=$results_dir
  results_dir=$work/results
  echo "uml_systemd_run: working in $work (the tree is where the guest cannot see it); results go to $final_results" >&2
fi
rm -f "$results_dir"/{rc,checks.txt,exit_status.txt,journal.txt,failures,guest_setup.txt,console.log}
# Staging (unit, drop-in, target, scene) next to the results: the guest reads it.
stage=$results_dir/stage
rm -rf "$stage"; mkdir -p "$stage/system/imuemud@hil.service.d"

# A unit straight from the source tree still has configure_file's @VARS@.
sed -E -e "s|^ExecStart=[^ ]+|ExecStart=$daemon|" -e "s|@IMUEMU_DOC_DIR@|$src|" \
    -e "s|@IMUEMU_CONFIG_EXAMPLES_DIR@|$src/config|" "$unit_file" >"$stage/system/imuemud@.service"
grep -q "^ExecStart=$daemon " "$stage/system/imuemud@.service" || fail "no ExecStart= line in $unit_file"
cat >"$stage/system/imuemud@hil.service.d/hil.conf" <<EOF2
# Test only: the stall hook, a short watchdog so the test is quick.
[Service]
Environment=IMUEMU_TEST_HOOKS=1
WatchdogSec=3s
RestartSec=1s
# How each run of the main process ended (systemd.exec(5) ExecStopPost
# environment); "+": outside the sandbox, so it may write the results.
ExecStopPost=+/bin/sh -c 'echo "\$SERVICE_RESULT \$EXIT_CODE \$EXIT_STATUS" >>$results_dir/exit_status.txt'
EOF2
cat >"$stage/system/imuemu-hil.target" <<EOF2
[Unit]
Description=imuemu systemd HIL test
Wants=imuemu-hil-check.service
AllowIsolate=yes
EOF2
cat >"$stage/system/imuemu-hil-check.service" <<EOF2
[Unit]
Description=imuemu systemd HIL checks
After=basic.target
# Keeps imuemud@hil loaded after it stops, so its exit status can be read.
Wants=imuemud@hil.service
After=imuemud@hil.service
SuccessAction=poweroff-force
FailureAction=poweroff-force
[Service]
Type=oneshot
ExecStart=/bin/bash $guest_check $cli $results_dir
StandardOutput=file:$results_dir/check_output.txt
StandardError=inherit
EOF2
# Wants= above would start imuemud@hil before the check; the check starts it itself.
sed -i -e '/^Wants=imuemud@hil.service/d' -e '/^After=imuemud@hil.service/d' "$stage/system/imuemu-hil-check.service"

init=$stage/init.sh
cat >"$init" <<EOF2
#!/bin/bash
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
results=$(printf %q "$results_dir")
stage=$(printf %q "$stage")
power_off() { sync; echo o >/proc/sysrq-trigger; sleep 10; }
setup_failed() { echo "guest setup failed: \$*" >>"\$results/guest_setup.txt"; power_off; }
mount -t proc proc /proc || setup_failed "mount /proc"
mount -t sysfs sysfs /sys || setup_failed "mount /sys"
mount -t tmpfs -o mode=755 tmpfs /run || setup_failed "mount /run"
mount -t tmpfs -o mode=1777 tmpfs /tmp || setup_failed "mount /tmp"
mount -t tmpfs -o mode=755 tmpfs /var || setup_failed "mount /var"
mkdir -p /var/tmp /var/lib /var/log /var/cache && chmod 1777 /var/tmp
# /etc: a writable copy on tmpfs, so nothing reaches the host's /etc.
mkdir /run/hil-etc && cp -a /etc/. /run/hil-etc/ && mount --bind /run/hil-etc /etc || setup_failed "copy of /etc"
cp -a "\$stage/system/." /etc/systemd/system/ || setup_failed "installing units"
mkdir -p /etc/sysusers.d /etc/tmpfiles.d /etc/imuemu
cp $(printf %q "$sysusers_file") /etc/sysusers.d/imuemu.conf
cp $(printf %q "$tmpfiles_file") /etc/tmpfiles.d/imuemu.conf
cp $(printf %q "$scene_file") /etc/imuemu/hil.toml
chmod 644 /etc/imuemu/hil.toml
systemd-sysusers /etc/sysusers.d/imuemu.conf 2>>"\$results/guest_setup.txt" || setup_failed "systemd-sysusers"
# A machine id keeps systemd's first-boot logic quiet.
[[ -s /etc/machine-id ]] || systemd-machine-id-setup >/dev/null 2>&1
exec /lib/systemd/systemd systemd.unit=imuemu-hil.target
EOF2
chmod +x "$init"

uml_pid=""
cleanup() {
  [[ -n $uml_pid ]] && kill "$uml_pid" 2>/dev/null
  if [[ -n $final_results ]]; then
    cp -a "$results_dir/." "$final_results/" 2>/dev/null
    rm -rf "$work"
  fi
  true
}
trap cleanup EXIT
trap 'exit 143' TERM INT HUP
boot_rc=0
TMPDIR=/dev/shm timeout --kill-after=5 "$timeout_s" \
  "$uml" mem=768M rootfstype=hostfs rw init="$init" quiet systemd.show_status=0 \
  con=null con0=null,fd:1 </dev/null >"$results_dir/console.log" 2>&1 &
uml_pid=$!
wait "$uml_pid" || boot_rc=$?
uml_pid=""
elapsed=$(awk -v a="$start_ns" -v b="$(date +%s%N)" 'BEGIN { printf "%.1f", (b - a) / 1e9 }')

[[ -f $results_dir/checks.txt ]] && cat "$results_dir/checks.txt"
if [[ ! -f $results_dir/rc ]]; then
  {
    ((boot_rc == 124 || boot_rc == 137)) && echo "uml_systemd_run: no verdict within ${timeout_s} s"
    [[ -s $results_dir/guest_setup.txt ]] && sed 's/^/uml_systemd_run: /' "$results_dir/guest_setup.txt"
    echo "uml_systemd_run: linux.uml exited with status $boot_rc; last console lines:"
    tail -n 40 "$results_dir/console.log"
    [[ -s $results_dir/journal.txt ]] && tail -n 40 "$results_dir/journal.txt"
  } >&2
  fail "the checks did not complete inside UML (${elapsed} s); results in $results_dir"
fi
rc=$(<"$results_dir/rc")
if [[ $rc != 0 ]]; then
  echo "uml_systemd_run: $(<"$results_dir/failures") check(s) failed; journal of the unit:" >&2
  tail -n 60 "$results_dir/journal.txt" >&2
fi
echo "uml_systemd_run: boot+checks+poweroff ${elapsed} s, results in ${final_results:-$results_dir}" >&2
exit "$rc"
