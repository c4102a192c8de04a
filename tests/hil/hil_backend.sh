# Sourced by the hardware-in-the-loop runners (hil_run.sh, systemd_run.sh):
# which kernel runs a scenario that either backend can host, and how a failed
# boot is reported. Not executable on its own.
#
# IMUEMU_HIL_BACKEND=auto|uml|qemu (default auto)
#   uml   user-mode Linux (Debian's user-mode-linux, /usr/bin/linux.uml): the
#         host's root through hostfs, a few seconds per boot. It does not boot
#         on every host: Debian's 6.1um4 panics at init on CPUs with AMX
#         ("userspace - ptrace set fp regs failed, errno = 14"). Forcing uml
#         where it cannot boot is a fixture failure that says why.
#   qemu  Debian's amd64 kernel under QEMU TCG (qemu_run.sh --host-root): the
#         host's root read-only over virtio-9p under a tmpfs overlay. Boots on
#         any x86-64 host, slower (TCG).
#   auto  uml where a probe boot of it prints its marker, otherwise qemu; the
#         log says which and why.
# The probe's verdict is cached for this boot of this host (boot id, CPU
# flags and the linux.uml binary are in the key) for an hour, under
# ${IMUEMU_HIL_CACHE:-<repo>/build/hil}, so parallel scenarios of one ctest
# run probe once.

# Exit status of a runner whose fixture (not the command under test) failed.
readonly HIL_FIXTURE_FAILURE=125
hil_backend_lib_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
hil_repo=$(cd "$hil_backend_lib_dir/../.." && pwd)

# Boots linux.uml with a trivial init that must print a marker. Prints the
# reason when it does not; status 0 if UML boots here.
hil_uml_probe_boot() {
  local uml=$1 dir init console rc=0
  dir=$(mktemp -d "${TMPDIR:-/tmp}/hil_uml_probe.XXXXXX")
  init=$dir/init.sh console=$dir/console.log
  cat >"$init" <<'EOF'
#!/bin/sh
mount -t proc proc /proc
echo HIL_UML_PROBE_INIT_RAN
echo o >/proc/sysrq-trigger
sleep 10
EOF
  chmod +x "$init"
  TMPDIR=/dev/shm timeout --kill-after=5 60 "$uml" mem=64M rootfstype=hostfs ro init="$init" quiet \
    con=null con0=null,fd:1 </dev/null >"$console" 2>&1 || rc=$?
  if grep -q '^HIL_UML_PROBE_INIT_RAN' "$console"; then
    rm -rf "$dir"; return 0
  fi
  local cause; cause=$(hil_console_cause "$console" 6 | tr '\n' ' ' | sed 's/  */ /g')
  echo "a probe boot of $uml (init printing a marker) failed: linux.uml exit status $rc; console: ${cause:-(empty)}"
  # The probe's console stays for a post-mortem; it is small.
  return 1
}

# Sets hil_uml_reason and returns 0 if UML boots on this host (cached).
hil_uml_usable() {
  hil_uml_reason=""
  local uml
  uml=$(command -v linux.uml) || { hil_uml_reason="linux.uml is not on PATH (Debian package user-mode-linux)"; return 1; }
  local cache_root=${IMUEMU_HIL_CACHE:-$hil_repo/build/hil}
  mkdir -p "$cache_root"
  local key
  key=$( { cat /proc/sys/kernel/random/boot_id; grep -m1 '^flags' /proc/cpuinfo; uname -r;
           stat -L -c '%n %s %Y' "$uml"; } | sha256sum | cut -c1-16)
  local verdict=$cache_root/uml-probe-$key
  exec 8>"$cache_root/.lock-uml-probe"
  flock 8
  if [[ ! -f $verdict || -n $(find "$verdict" -mmin +60 2>/dev/null) ]]; then
    local why
    if why=$(hil_uml_probe_boot "$uml"); then echo "ok" >"$verdict.tmp"; else echo "$why" >"$verdict.tmp"; fi
    mv "$verdict.tmp" "$verdict"
  fi
  flock -u 8
  exec 8>&-
  local result; result=$(<"$verdict")
  [[ $result == ok ]] && return 0
  hil_uml_reason="$result (verdict cached in $verdict)"
  return 1
}

# hil_choose_backend RUNNER: sets hil_backend (uml|qemu) and hil_backend_why.
# Exits with the fixture status when the choice cannot be honoured.
hil_choose_backend() {
  local runner=$1 wanted=${IMUEMU_HIL_BACKEND:-auto}
  case $wanted in
    uml)
      hil_uml_usable || { echo "$runner: FIXTURE FAILURE: IMUEMU_HIL_BACKEND=uml, but user-mode Linux cannot run here: $hil_uml_reason" >&2; exit $HIL_FIXTURE_FAILURE; }
      hil_backend=uml hil_backend_why="IMUEMU_HIL_BACKEND=uml" ;;
    qemu) hil_backend=qemu hil_backend_why="IMUEMU_HIL_BACKEND=qemu" ;;
    auto)
      if hil_uml_usable; then
        hil_backend=uml hil_backend_why="auto: user-mode Linux boots here"
      else
        hil_backend=qemu hil_backend_why="auto: user-mode Linux unusable ($hil_uml_reason), falling back to QEMU"
      fi ;;
    *) echo "$runner: FIXTURE FAILURE: IMUEMU_HIL_BACKEND='$wanted': expected auto, uml or qemu" >&2; exit $HIL_FIXTURE_FAILURE ;;
  esac
  echo "$runner: backend $hil_backend ($hil_backend_why)" >&2
}

# hil_console_cause FILE [MAX]: the lines of a guest console that show why it
# failed (panic, oops, the first errors and failures), at most MAX (20), with
# their line numbers, then the console's last lines if nothing matched.
hil_console_cause() {
  local file=$1 max=${2:-20}
  [[ -s $file ]] || { echo "(console empty)"; return 0; }
  local hits
  hits=$(grep -n -i -E 'panic|oops|BUG:|segfault|Call Trace|errno|error|fail|cannot|not found|No such|Killed|timed out|Attempted to kill' "$file" | head -n "$max")
  if [[ -n $hits ]]; then
    printf '%s\n' "$hits"
  else
    echo "(no panic or error line; the last lines:)"
    tail -n 10 "$file"
  fi
}
