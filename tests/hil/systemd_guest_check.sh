#!/bin/bash
# Guest side of systemd_run.sh: runs as a oneshot service under systemd
# (PID 1) inside user-mode Linux or QEMU. Checks imuemud@hil.service end to end:
#   1. start -> active only after READY=1 (Type=notify), runs as user imuemu,
#      control socket /run/imuemu/hil.sock mode 0660 imuemu:imuemu;
#   2. `imuemu status` answers; SCHED_FIFO emission thread and mlockall as
#      the scene asks (CAP_SYS_NICE, CAP_IPC_LOCK through the unit);
#   3. the watchdog is petted (WatchdogTimestamp advances);
#   4. reload (SIGHUP) keeps the same process active;
#   5. stall-emitter test hook -> no more pets -> systemd's watchdog kills
#      it and Restart=on-failure restarts it (NRestarts +1, new MainPID);
#   6. systemctl stop -> clean exit (EXIT_CODE=exited, EXIT_STATUS=0 as
#      ExecStopPost sees them), socket removed.
# Writes RESULTS/checks.txt (PASS/FAIL per check), journal.txt, rc, and
# timeline.txt (the guest's uptime at each step: boot time, slow steps).
#   systemd_guest_check.sh IMUEMU_CLI RESULTS_DIR [WATCHDOG_S (3)]
set -u
cli=$1
results=$2
watchdog_s=${3:-3}  # the unit's WatchdogSec= in this test (systemd_run.sh's drop-in)
unit=imuemud@hil.service
socket=/run/imuemu/hil.sock
failures=0
: >"$results/checks.txt"
mark() { echo "$(cut -d' ' -f1 /proc/uptime) s $*" >>"$results/timeline.txt"; }
: >"$results/timeline.txt"
mark "checks start (boot to here)"
pass() { echo "PASS $*" >>"$results/checks.txt"; }
fail() { echo "FAIL $*" >>"$results/checks.txt"; failures=$((failures + 1)); }
check() { local what=$1; shift; if "$@"; then pass "$what"; else fail "$what"; fi; }
prop() { systemctl show -P "$1" "$unit"; }
finish() {
  mark "checks done"
  journalctl -b --no-pager -o short-monotonic -u "$unit" >"$results/journal.txt" 2>&1
  journalctl -b --no-pager -o short-monotonic >"$results/boot_journal.txt" 2>&1
  systemctl status --no-pager "$unit" >>"$results/journal.txt" 2>&1
  echo "$failures" >"$results/failures"
  echo $((failures == 0 ? 0 : 1)) >"$results/rc"
  sync
  exit 0  # the verdict is in rc; SuccessAction powers off
}

# 1. Start: systemctl start returns once the service sent READY=1.
if timeout 60 systemctl start "$unit"; then pass "start returned (READY=1 received)"; else fail "start"; finish; fi
check "ActiveState=active" test "$(prop ActiveState)" = active
pid=$(prop MainPID)
echo "MainPID $pid" >>"$results/checks.txt"
uid=$(awk '/^Uid:/ { print $2 }' "/proc/$pid/status")
check "runs as user imuemu (uid $uid)" test "$uid" = "$(id -u imuemu)"
check "supplementary group dialout" grep -qE "^Groups:.*\b$(getent group dialout | cut -d: -f3)\b" "/proc/$pid/status"
check "control socket 0660 imuemu:imuemu ($(stat -c '%a %U:%G' $socket 2>&1))" \
  test "$(stat -c '%a %U:%G' $socket)" = "660 imuemu:imuemu"

mark "started"
# 2. Status over the control socket; real-time settings took effect.
status=$("$cli" status --scene hil --compact 2>&1)
echo "status: $status" >>"$results/checks.txt"
check "imuemu status: samples are being emitted" grep -qE '"samples_emitted":[1-9]' <<<"$status"
check "imuemu status: watchdog interval $watchdog_s s" grep -qE "\"interval_s\":$watchdog_s(\\.0)?[,}]" <<<"$status"
check "emission thread is SCHED_FIFO (CAP_SYS_NICE)" bash -c "ps -L -o cls= -p $pid | grep -q FF"
check "memory locked (CAP_IPC_LOCK): $(grep VmLck /proc/$pid/status)" bash -c "awk '/^VmLck:/ { exit !(\$2 > 0) }' /proc/$pid/status"

mark "status checked"
# 3. Watchdog pets: systemd stamps every WATCHDOG=1 it accepts.
w0=$(prop WatchdogTimestampMonotonic)
sleep $((watchdog_s + 1))
w1=$(prop WatchdogTimestampMonotonic)
check "watchdog petted (WatchdogTimestampMonotonic $w0 -> $w1)" test "$w1" -gt "$w0"
check "still active after > WatchdogSec" test "$(prop ActiveState)" = active

mark "watchdog checked"
# 4. Reload: same process, active again.
check "systemctl reload" timeout 30 systemctl reload "$unit"
sleep 1
check "reload kept the process (MainPID $(prop MainPID))" test "$(prop MainPID)" = "$pid"
check "active after reload" test "$(prop ActiveState)" = active

mark "reload checked"
# 5. Stall the emitter: systemd must kill and restart it. The bound (120 s of
# this guest's clock, not a number of polls: one systemctl call takes seconds
# under QEMU's TCG) only catches a restart that never comes.
restarts0=$(prop NRestarts)
check "stall-emitter test hook accepted" "$cli" status --scene hil --command stall-emitter --compact
restarted=no
deadline=$((SECONDS + 120))
while ((SECONDS < deadline)); do
  sleep 0.5
  # One call for the three properties (key=value lines).
  state=$(systemctl show -p NRestarts -p ActiveState -p MainPID "$unit")
  n=$(sed -n 's/^NRestarts=//p' <<<"$state") a=$(sed -n 's/^ActiveState=//p' <<<"$state") m=$(sed -n 's/^MainPID=//p' <<<"$state")
  if [[ $n -gt $restarts0 && $a == active && $m != "$pid" && $m != 0 ]]; then
    restarted=yes
    break
  fi
done
mark "restart seen: $restarted"
check "watchdog restart: NRestarts $restarts0 -> $(prop NRestarts), MainPID $pid -> $(prop MainPID)" test $restarted = yes
check "journal shows the watchdog timeout" bash -c "journalctl -b --no-pager -u $unit | grep -q 'Watchdog timeout'"
check "restarted daemon answers" "$cli" status --scene hil --compact

# 6. Clean stop.
check "systemctl stop" timeout 30 systemctl stop "$unit"
# exit_status.txt: one "SERVICE_RESULT EXIT_CODE EXIT_STATUS" line per run
# of the main process, written by the test drop-in's ExecStopPost.
runs=$(cat "$results/exit_status.txt" 2>/dev/null | tr '\n' ';')
check "first run ended by the watchdog (SIGABRT): $runs" test "$(sed -n 1p "$results/exit_status.txt")" = "watchdog killed ABRT"
check "last run exited cleanly (success exited 0): $runs" test "$(tail -n 1 "$results/exit_status.txt")" = "success exited 0"
check "Result=success" test "$(prop Result)" = success
check "control socket removed" test ! -e $socket
finish
