#!/usr/bin/env bash
# Runs the README's two commands as a new user would: in a fresh
# `debootstrap --variant=minbase bookworm` chroot (no compiler, no systemd,
# nothing), on a clean clone of this repository's HEAD, as root, with CI's
# environment (CI=true, no standard input). Prints each command's wall and
# CPU time and exit status; the whole output is kept in DIR/check-*.log.
#   scripts/fresh_chroot_check.sh DIR [demo|test|both] [BASE]
# DIR is created (it must not exist). BASE, if given, is an untouched
# debootstrap tree copied instead of running debootstrap again (it needs the
# network: Debian's mirror). Needs root, debootstrap and the network; it is a
# manual acceptance check (issue 12), not part of CI.
set -euo pipefail
dir=${1:?usage: $0 DIR [demo|test|both] [BASE]}
what=${2:-both}
base=${3:-}
repo=$(cd "$(dirname "$0")/.." && pwd)
[[ -e $dir ]] && { echo "$dir exists; give a new directory" >&2; exit 2; }
if [[ -n $base ]]; then
  cp -a "$base" "$dir"
else
  debootstrap --variant=minbase bookworm "$dir" http://deb.debian.org/debian >"$dir.debootstrap.log" 2>&1
fi
cp /etc/resolv.conf "$dir/etc/resolv.conf"
git clone -q --no-local "$repo" "$dir/root/imuemu"
mounts=(proc sys dev dev/pts dev/shm)
cleanup() {
  for ((i = ${#mounts[@]} - 1; i >= 0; i--)); do umount -l "$dir/${mounts[i]}" 2>/dev/null || true; done
}
trap cleanup EXIT
mount -t proc proc "$dir/proc"
mount --rbind /sys "$dir/sys"
mount --bind /dev "$dir/dev"
mount --bind /dev/pts "$dir/dev/pts"
mount -t tmpfs shm "$dir/dev/shm"
status=0
run_in_chroot() {
  local name=$1 command=$2 log="$dir/check-$1.log" rc=0
  echo "=== $name: $command (log: $log)"
  /usr/bin/time -f "$name: %e s wall, %U s user, %S s system" -o "$dir/check-$name.time" \
    env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root CI=true LANG=C.UTF-8 \
    chroot "$dir" /bin/bash -c "cd /root/imuemu && $command" </dev/null >"$log" 2>&1 || rc=$?
  cat "$dir/check-$name.time"
  echo "$name: exit $rc"
  tail -n 15 "$log"
  ((rc == 0)) || status=1
}
case "$what" in
  demo) run_in_chroot demo "bash scripts/demo.sh" ;;
  test) run_in_chroot test "bash scripts/test.sh" ;;
  both) run_in_chroot demo "bash scripts/demo.sh"; run_in_chroot test "bash scripts/test.sh" ;;
  *) echo "usage: $0 DIR [demo|test|both] [BASE]" >&2; exit 2 ;;
esac
exit $status
