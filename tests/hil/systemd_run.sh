#!/usr/bin/env bash
# Hardware-in-the-loop fixture: boots a Linux kernel with systemd as PID 1
# and checks imuemud@.service there (tests/hil/systemd_guest_check.sh):
# Type=notify readiness, user/groups/capabilities, control socket, watchdog
# pets, reload, a watchdog restart of a stalled emitter, a clean stop.
#
#   tests/hil/systemd_run.sh [--results DIR] [--timeout S] [--unit FILE]
#       [--sysusers FILE] [--tmpfiles FILE] [--scene FILE] [--] IMUEMUD IMUEMU_CLI
#
# IMUEMUD is the daemon binary the unit's ExecStart is pointed at (any
# Type=notify service speaking the same control socket and the test hook
# "stall-emitter", enabled by IMUEMU_TEST_HOOKS=1 in a drop-in);
# IMUEMU_CLI is the imuemu command (`imuemu status`).
# Defaults: systemd/imuemud@.service.in, imuemu.sysusers.conf,
# imuemu.tmpfiles.conf from the source tree, tests/hil/hil_scene.toml.
#
# Backend (IMUEMU_HIL_BACKEND=auto|uml|qemu, hil_backend.sh): user-mode
# Linux with the host's root through hostfs, or Debian's kernel under QEMU
# TCG with the host's root read-only over virtio-9p under a tmpfs overlay
# (qemu_run.sh --host-root), the results directory shared writable.
# Either way the guest's root is the host's, but everything systemd and the test
# write goes to tmpfs inside the guest: /run, /tmp, /var, and a copy of /etc
# (sysusers adds the user imuemu there, never on the host). Only the results
# directory is written on the host, so it must not be under /tmp, /run, /var
# or /etc (default: a fresh directory under $PWD); a tree or results directory
# there is copied to a work directory under /opt (or /srv, /mnt,
# IMUEMU_HIL_WORK_DIR) first and the results copied back.
# Results: checks.txt (PASS/FAIL lines), journal.txt, console.log (the whole
# guest console), rc. A failed boot prints the console lines that show the
# cause and the path of the whole console.
# Exit: 0 all checks passed, 1 a check failed, 125 the fixture failed (no
# boot, no verdict within the timeout).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
# shellcheck source=hil_backend.sh
source "$here/hil_backend.sh"
readonly FIXTURE_FAILURE=$HIL_FIXTURE_FAILURE
fail() { echo "systemd_run: FIXTURE FAILURE: $*" >&2; exit $FIXTURE_FAILURE; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//' >&2; exit 2; }

src=$(cd "$here/../.." && pwd)
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
    -*) echo "systemd_run: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
(($# == 2)) || { echo "systemd_run: need IMUEMUD and IMUEMU_CLI" >&2; usage; }
daemon=$(realpath "$1")
cli=$(realpath "$2")
[[ -x $daemon ]] || fail "daemon $daemon is not executable"
[[ -x $cli ]] || fail "imuemu CLI $cli is not executable"
for f in "$unit_file" "$sysusers_file" "$tmpfiles_file" "$scene_file"; do [[ -f $f ]] || fail "missing $f"; done
[[ -x /lib/systemd/systemd ]] || fail "/lib/systemd/systemd not found (package systemd)"
for tool in systemd-sysusers systemctl journalctl ps; do
  command -v "$tool" >/dev/null || fail "$tool not found (package $([[ $tool == ps ]] && echo procps || echo systemd); scripts/setup.sh)"
done

start_ns=$(date +%s%N)
hil_choose_backend systemd_run
if [[ $hil_backend == uml ]]; then uml=$(command -v linux.uml); fi
# The test's watchdog interval. 3 s was too short on a loaded host (load
# average 10-15 on 2 cores), under UML and QEMU alike: a reload stops and
# rebuilds the engine without petting, took longer, and the watchdog killed
# the daemon mid-reload (3 reload checks failed). 10 s: the checks wait
# WatchdogSec+1 s and one watchdog timeout longer, no more.
watchdog_s=10
if [[ -z $results_dir ]]; then
  results_dir=$(mktemp -d "$PWD/hil_systemd.XXXXXX")
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
  echo "systemd_run: working in $work (the tree is where the guest cannot see it); results go to $final_results" >&2
fi
rm -f "$results_dir"/{rc,checks.txt,exit_status.txt,journal.txt,failures,guest_setup.txt,console.log,masked_units.txt,timeline.txt}
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
WatchdogSec=${watchdog_s}s
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
ExecStart=/bin/bash $guest_check $cli $results_dir $watchdog_s
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
# Under QEMU, qemu_run.sh's initramfs has mounted /dev, /proc and /sys already.
mountpoint -q /proc || mount -t proc proc /proc || setup_failed "mount /proc"
mountpoint -q /sys || mount -t sysfs sysfs /sys || setup_failed "mount /sys"
mount -t tmpfs -o mode=755 tmpfs /run || setup_failed "mount /run"
mount -t tmpfs -o mode=1777 tmpfs /tmp || setup_failed "mount /tmp"
mount -t tmpfs -o mode=755 tmpfs /var || setup_failed "mount /var"
mkdir -p /var/tmp /var/lib /var/log /var/cache && chmod 1777 /var/tmp
# /etc: under UML a writable copy on tmpfs, so nothing reaches the host's
# /etc; under QEMU the tmpfs overlay over the whole root does that already.
if [[ $hil_backend == uml ]]; then
  mkdir /run/hil-etc && cp -a /etc/. /run/hil-etc/ && mount --bind /run/hil-etc /etc || setup_failed "copy of /etc"
fi
cp -a "\$stage/system/." /etc/systemd/system/ || setup_failed "installing units"
# This throwaway guest needs none of the host's early-boot services except
# the journal and tmpfiles (the checks read the journal; tmpfiles sets up
# /run and /var for the unit): the rest (pstore, timesyncd, binfmt, random
# seed, utmp, fuse/debug/tracing mounts, ...) is masked here, in the guest's
# /etc, and the generators (fstab, getty, sysv, whatever the host's packages
# add) are not run (SYSTEMD_GENERATOR_PATH, an empty directory), which keeps
# the boot short under QEMU's TCG. imuemud@.service depends on none of them.
# An empty unit file masks a unit (systemd.unit(5)); written by the shell
# itself, since every process started costs ~0.5 s under TCG. A symlink there
# is removed first: writing through it could reach a host file under UML.
keep=" systemd-journald.service systemd-tmpfiles-setup.service systemd-tmpfiles-setup-dev.service "
for wanted in /lib/systemd/system/sysinit.target.wants/* /etc/systemd/system/sysinit.target.wants/* \\
              /lib/systemd/system/local-fs.target.wants/* /etc/systemd/system/local-fs.target.wants/*; do
  [[ -e \$wanted || -L \$wanted ]] || continue
  u=\${wanted##*/}
  [[ \$keep == *" \$u "* ]] && continue
  echo "\$u" >>"\$results/masked_units.txt"
  if [[ -L /etc/systemd/system/\$u ]]; then rm -f "/etc/systemd/system/\$u"; fi
  : >"/etc/systemd/system/\$u" || setup_failed "masking \$u"
done
mkdir -p /run/hil-no-generators
export SYSTEMD_GENERATOR_PATH=/run/hil-no-generators
mkdir -p /etc/sysusers.d /etc/tmpfiles.d /etc/imuemu
cp $(printf %q "$sysusers_file") /etc/sysusers.d/imuemu.conf
cp $(printf %q "$tmpfiles_file") /etc/tmpfiles.d/imuemu.conf
cp $(printf %q "$scene_file") /etc/imuemu/hil.toml
chmod 644 /etc/imuemu/hil.toml
systemd-sysusers /etc/sysusers.d/imuemu.conf 2>>"\$results/guest_setup.txt" || setup_failed "systemd-sysusers"
# Under QEMU the root is a tmpfs overlay over the host's (read-only 9p): the
# host's container marker (this CI may run in docker) would make systemd run
# in container mode; a whiteout in the overlay hides it from this guest only.
# (Under UML the root is the host's itself, read-write: never delete there.)
if [[ $hil_backend == qemu && \$(stat -f -c %T /) == overlayfs ]]; then rm -f /.dockerenv /run/.containerenv; fi
# A machine id keeps systemd's first-boot logic quiet.
[[ -s /etc/machine-id ]] || systemd-machine-id-setup >/dev/null 2>&1
exec /lib/systemd/systemd --unit=imuemu-hil.target --show-status=0
EOF2
chmod +x "$init"

guest_pid=""
cleanup() {
  [[ -n $guest_pid ]] && kill "$guest_pid" 2>/dev/null
  if [[ -n $final_results ]]; then
    cp -a "$results_dir/." "$final_results/" 2>/dev/null
    rm -rf "$work"
  fi
  true
}
trap cleanup EXIT
trap 'exit 143' TERM INT HUP
boot_rc=0
if [[ $hil_backend == uml ]]; then
  TMPDIR=/dev/shm timeout --kill-after=5 "$timeout_s" \
    "$uml" mem=768M rootfstype=hostfs rw init="$init" quiet systemd.show_status=0 \
    con=null con0=null,fd:1 </dev/null >"$results_dir/console.log" 2>&1 &
  kernel="UML $("$uml" --version 2>/dev/null | head -n1)"
else
  "$here/qemu_run.sh" --results "$results_dir" --timeout "$timeout_s" --mem 768M \
    --share "$results_dir" --host-root "$init" </dev/null >&2 &
  kernel="QEMU (Debian's kernel, TCG)"
fi
guest_pid=$!
wait "$guest_pid" || boot_rc=$?
guest_pid=""
elapsed=$(awk -v a="$start_ns" -v b="$(date +%s%N)" 'BEGIN { printf "%.1f", (b - a) / 1e9 }')

[[ -f $results_dir/checks.txt ]] && cat "$results_dir/checks.txt"
if [[ ! -f $results_dir/rc ]]; then
  {
    ((boot_rc == 124 || boot_rc == 137)) && echo "systemd_run: no verdict within ${timeout_s} s"
    [[ -s $results_dir/guest_setup.txt ]] && sed 's/^/systemd_run: /' "$results_dir/guest_setup.txt"
    echo "systemd_run: $kernel exited with status $boot_rc; the console's lines that show the cause:"
    hil_console_cause "$results_dir/console.log" | sed 's/^/  /'
    [[ -s $results_dir/journal.txt ]] && tail -n 40 "$results_dir/journal.txt"
    echo "systemd_run: whole console: ${final_results:-$results_dir}/console.log"
  } >&2
  fail "the checks did not complete on backend $hil_backend (${elapsed} s); results in ${final_results:-$results_dir}"
fi
rc=$(<"$results_dir/rc")
if [[ $rc != 0 ]]; then
  echo "systemd_run: $(<"$results_dir/failures") check(s) failed; journal of the unit:" >&2
  tail -n 60 "$results_dir/journal.txt" >&2
fi
echo "systemd_run: backend $hil_backend: $kernel boot+checks+poweroff ${elapsed} s, results in ${final_results:-$results_dir}" >&2
exit "$rc"
