#!/usr/bin/env bash
# The Debian package end to end (issue 32, acceptance 1):
#   tests/package/package_check.sh SRC WORK [PREBUILT_TREE]
# 1. a clean clone of SRC's HEAD is packaged with `dpkg-buildpackage -us -uc -b`
#    (with PREBUILT_TREE: IMUEMU_DEB_PREBUILT, the programs installed from
#    that Release tree instead of compiled again; debian/rules says why);
# 2. `lintian --fail-on error,warning` on the result (overrides, if any, are
#    in debian/imuemu.lintian-overrides with their reasons);
# 3. the package is installed with apt into a scratch root: an overlay of this
#    system (writes go to WORK, never to the host), since CI has no network for
#    debootstrap and this system already has the package's dependencies;
# 4. checked there: the user and group from sysusers (and dialout), the runtime
#    directory from tmpfiles, the unit (systemd/verify_unit.sh: systemd-analyze
#    verify and the hardening list), each man page rendered by `man -l` without
#    a warning, `--version` of both programs, `imuemud --check-config` and
#    `imuemu generate` on an example copied to /etc/imuemu, `imuemu allan --png`
#    with the installed plotting script;
# 5. `apt-get purge`, then nothing is left: none of the package's files, no
#    /etc/imuemu, no user or group, no /run/imuemu, and /etc/passwd, group,
#    shadow and gshadow byte-identical to the system's.
# Exit 0: all passed; 1: a check failed; 77: cannot run here (not root, or no
# overlay mounts); ctest counts 77 as skipped.
set -euo pipefail
src=$(cd "${1:?usage: $0 SRC WORK [PREBUILT_TREE]}" && pwd)
work=${2:?usage: $0 SRC WORK [PREBUILT_TREE]}
prebuilt=${3:-}
[[ -n $prebuilt ]] && prebuilt=$(cd "$prebuilt" && pwd)

failures=0
pass() { echo "PASS: $*"; }
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
die() { echo "package_check: $*" >&2; exit 1; }

((EUID == 0)) || { echo "package_check: needs root (overlay mount, chroot); skipped"; exit 77; }
# In a mount namespace of its own: the overlay and the binds under WORK vanish
# with this process however it ends (a ctest timeout's SIGKILL too), so no
# later `rm -rf WORK` can reach the host's /dev through a stale bind.
if [[ -z ${IMUEMU_PACKAGE_CHECK_NS:-} ]]; then
  if unshare --mount --propagation private true 2>/dev/null; then
    exec unshare --mount --propagation private env IMUEMU_PACKAGE_CHECK_NS=1 bash "$0" "$@"
  fi
  echo "package_check: cannot make a mount namespace (unshare --mount); skipped"
  exit 77
fi
for tool in dpkg-buildpackage lintian git; do
  command -v "$tool" >/dev/null || die "$tool not found (scripts/setup.sh installs it)"
done

rm -rf --one-file-system "$work"
mkdir -p "$work"
work=$(cd "$work" && pwd)

# 1. Build from a clean clone.
git clone -q --no-local "$src" "$work/imuemu"
start=$SECONDS
build_log=$work/dpkg-buildpackage.log
if ! (cd "$work/imuemu" && IMUEMU_DEB_PREBUILT=$prebuilt dpkg-buildpackage -us -uc -b) >"$build_log" 2>&1; then
  tail -n 40 "$build_log"
  die "dpkg-buildpackage failed (log: $build_log)"
fi
deb=$(ls "$work"/imuemu_*_*.deb)
pass "dpkg-buildpackage: $(basename "$deb") in $((SECONDS - start)) s${prebuilt:+ (programs from $prebuilt)}"
dpkg-deb --contents "$deb" | awk '{print $6}' > "$work/contents.txt"

# 2. lintian.
start=$SECONDS
if lintian --fail-on error,warning --display-info "$work"/imuemu_*.changes >"$work/lintian.txt" 2>&1; then
  pass "lintian --fail-on error,warning: clean in $((SECONDS - start)) s ($(grep -c '^[IP]:' "$work/lintian.txt" || true) information tags: $work/lintian.txt)"
else
  cat "$work/lintian.txt"
  fail "lintian reported errors or warnings"
fi

# 3. A scratch root: this system under an overlay.
root=$work/root
mkdir -p "$root" "$work/upper" "$work/overlay-work"
if ! mount -t overlay imuemu-package-check -o "lowerdir=/,upperdir=$work/upper,workdir=$work/overlay-work" "$root" 2>"$work/mount.err"; then
  echo "package_check: cannot mount an overlay ($(cat "$work/mount.err")); skipped"
  exit 77
fi
mounts=()
cleanup() {
  for ((i = ${#mounts[@]} - 1; i >= 0; i--)); do umount -l "${mounts[i]}" 2>/dev/null || true; done
  umount -l "$root" 2>/dev/null || true
}
trap cleanup EXIT
mount -t proc proc "$root/proc" && mounts+=("$root/proc")
mount --bind /dev "$root/dev" && mounts+=("$root/dev")
# /run and /tmp start empty in the scratch root, as on a booted system (the
# host's may hold anything); no /run/systemd/system: postinst does not try to
# talk to a systemd that is not there.
mount -t tmpfs tmpfs "$root/run" && mounts+=("$root/run")
mount -t tmpfs tmpfs "$root/tmp" && mounts+=("$root/tmp")
in_root() { chroot "$root" env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 "$@"; }

for f in passwd group shadow gshadow; do cp "/etc/$f" "$work/host-$f"; done
in_root dpkg -s imuemu >/dev/null 2>&1 && die "imuemu is already installed on this system; the check needs it absent"
cp "$deb" "$root/tmp/"
if in_root apt-get install -y -q --no-install-recommends "/tmp/$(basename "$deb")" >"$work/apt-install.log" 2>&1; then
  pass "apt-get install ./$(basename "$deb")"
else
  tail -n 30 "$work/apt-install.log"
  die "apt-get install failed (log: $work/apt-install.log)"
fi

# 4. What the package made and holds.
if in_root getent passwd imuemu | grep -q '^imuemu:x:[0-9]*:[0-9]*:.*:/nonexistent:/usr/sbin/nologin$'; then
  pass "system user imuemu: $(in_root getent passwd imuemu)"
else
  fail "no system user imuemu with home /nonexistent and shell nologin ($(in_root getent passwd imuemu || echo absent))"
fi
in_root getent group imuemu >/dev/null && pass "group imuemu" || fail "no group imuemu"
in_root id -nG imuemu | tr ' ' '\n' | grep -qx dialout && pass "imuemu is in dialout" || fail "imuemu not in dialout"
if [[ $(in_root stat -c '%U:%G %a' /run/imuemu 2>/dev/null) == "imuemu:imuemu 750" ]]; then
  pass "/run/imuemu 0750 imuemu:imuemu (tmpfiles)"
else
  fail "/run/imuemu is not 0750 imuemu:imuemu ($(in_root stat -c '%U:%G %a' /run/imuemu 2>&1))"
fi
cp "$src/systemd/verify_unit.sh" "$root/tmp/verify_unit.sh"
if out=$(in_root bash /tmp/verify_unit.sh /lib/systemd/system/imuemud@.service /usr/sbin/imuemud \
           /usr/lib/sysusers.d/imuemu.conf /usr/lib/tmpfiles.d/imuemu.conf 2>&1); then
  pass "the installed unit: $(echo "$out" | grep -c . ) lines of verify_unit.sh, all clean"
else
  echo "$out"
  fail "systemd/verify_unit.sh on the installed unit"
fi
grep -q '^ExecStart=/usr/sbin/imuemud --scene /etc/imuemu/%i.toml$' "$root/lib/systemd/system/imuemud@.service" &&
  grep -q '^Documentation=.* file:///usr/share/doc/imuemu/README.md$' "$root/lib/systemd/system/imuemud@.service" &&
  pass "unit: ExecStart and Documentation name installed files" || fail "unit's ExecStart/Documentation do not name /usr/sbin/imuemud and /usr/share/doc/imuemu"
[[ -f $root/usr/share/doc/imuemu/README.md && -f $root/usr/share/doc/imuemu/docs/scene-format.md ]] &&
  pass "docs in /usr/share/doc/imuemu" || fail "README.md or docs/scene-format.md missing in /usr/share/doc/imuemu"
for page in /usr/share/man/man1/imuemu.1.gz /usr/share/man/man8/imuemud.8.gz /usr/share/man/man5/imuemu-scene.5.gz; do
  if [[ ! -f $root$page ]]; then fail "man page $page missing"; continue; fi
  warnings=$(in_root env MANWIDTH=80 man --warnings -E UTF-8 -l "$page" 2>&1 >/dev/null) || true
  lines=$(in_root env MANWIDTH=80 man -E UTF-8 -l "$page" 2>/dev/null | wc -l)
  if [[ -z $warnings && $lines -gt 20 ]]; then pass "man -l $page: $lines lines, no warnings"; else
    echo "$warnings" | head -20; fail "man -l $page: $lines lines, warnings above"; fi
done
version=$(in_root imuemu --version 2>&1) || true
dversion=$(in_root imuemud --version 2>&1) || true
want=$(sed -n 's/^project(imuemu VERSION \([0-9.]*\).*/\1/p' "$src/CMakeLists.txt")
[[ $version == "imuemu $want (git "* && $dversion == "imuemud $want (git "* ]] &&
  pass "--version: '$version', '$dversion'" || fail "--version: '$version', '$dversion' (want $want)"
# An example copied to /etc/imuemu, as the README says, finds its data in
# /usr/share/imuemu/config; the shipped one is a conffile already there.
grep -qx /etc/imuemu/bench-static.toml <(in_root dpkg-query -W -f='${Conffiles}\n' imuemu | awk '{print $1}') &&
  pass "/etc/imuemu/bench-static.toml is a conffile" || fail "/etc/imuemu/bench-static.toml is not a conffile"
in_root cp /usr/share/imuemu/config/car-urban.toml /etc/imuemu/car-urban.toml
if in_root imuemud --check-config /etc/imuemu/car-urban.toml >"$work/check-config.txt" 2>&1 &&
   in_root imuemud --check-config /etc/imuemu/bench-static.toml >>"$work/check-config.txt" 2>&1; then
  pass "imuemud --check-config on /etc/imuemu/car-urban.toml (copied) and bench-static.toml"
else
  cat "$work/check-config.txt"; fail "imuemud --check-config on the /etc/imuemu scenes"
fi
if in_root imuemu generate --scene-file /etc/imuemu/car-urban.toml --max-seconds 5 --out /tmp/car.csv >"$work/generate.txt" 2>&1; then
  rows=$(($(wc -l <"$root/tmp/car.csv") - 1))
  # car-urban emits at its [[imu]] rate_hz for 5 s: rate x 5 (+1 for both ends).
  rate=$(sed -n 's/^rate_hz *= *\([0-9]*\).*/\1/p' "$root/usr/share/imuemu/config/car-urban.toml" | head -1)
  ((rows >= rate * 5 && rows <= rate * 5 + 1)) && pass "imuemu generate on /etc/imuemu/car-urban.toml: $rows samples at $rate Hz" ||
    fail "imuemu generate wrote $rows samples, expected $((rate * 5)) at $rate Hz"
else
  cat "$work/generate.txt"; fail "imuemu generate --scene-file /etc/imuemu/car-urban.toml"
fi
if [[ -x $root/usr/bin/python3 ]] && in_root /usr/bin/python3 -c 'import matplotlib' 2>/dev/null; then
  in_root imuemu generate --scene-file /etc/imuemu/bench-static.toml --max-seconds 60 --out /tmp/static.csv >/dev/null 2>&1 || true
  if in_root imuemu allan /tmp/static.csv --png /tmp/allan.png >"$work/allan.txt" 2>&1 && [[ -s $root/tmp/allan.png ]]; then
    pass "imuemu allan --png with /usr/share/imuemu/plot_allan.py: $(stat -c %s "$root/tmp/allan.png") bytes"
  else
    cat "$work/allan.txt"; fail "imuemu allan --png with the installed plotting script"
  fi
fi
in_root rm -f /etc/imuemu/car-urban.toml

# 5. Purge, then nothing is left.
if in_root apt-get purge -y -q imuemu >"$work/apt-purge.log" 2>&1; then pass "apt-get purge imuemu"; else
  tail -n 30 "$work/apt-purge.log"; fail "apt-get purge imuemu"; fi
left=()
while read -r path; do
  path=${path#.}
  [[ -z $path || $path == / || -d $root$path && ! -L $root$path && $path != /etc/imuemu* && $path != /usr/share/imuemu* && $path != /usr/share/doc/imuemu* ]] && continue
  [[ -e $root$path || -L $root$path ]] && left+=("$path")
done <"$work/contents.txt"
[[ -e $root/etc/imuemu ]] && left+=(/etc/imuemu)
[[ -e $root/run/imuemu ]] && left+=(/run/imuemu)
((${#left[@]} == 0)) && pass "purge: none of the package's $(wc -l <"$work/contents.txt") paths is left" ||
  fail "purge left: ${left[*]}"
in_root getent passwd imuemu >/dev/null && fail "purge left the user imuemu" || pass "purge removed the user imuemu"
in_root getent group imuemu >/dev/null && fail "purge left the group imuemu" || pass "purge removed the group imuemu"
for f in passwd group shadow gshadow; do
  cmp -s "$work/host-$f" "$root/etc/$f" && pass "/etc/$f as before the install" || fail "/etc/$f differs from before the install"
done

# 6. The package's unit, daemon, sysusers and tmpfiles entries under systemd
#    as PID 1 (tests/hil/systemd_run.sh: user-mode Linux or QEMU; the suite's
#    only run of that fixture, so a fixture that cannot boot fails): imuemud@hil
#    starts from /etc/imuemu/hil.toml, reports READY, its status socket
#    answers, and the fixture's other checks (watchdog, reload, stop) pass.
cleanup
mounts=()
trap - EXIT
if [[ ${IMUEMU_PACKAGE_SYSTEMD:-1} == 1 ]]; then
  files=$work/files
  dpkg-deb -x "$deb" "$files"
  # Both entries are called imuemu.conf in the package; the fixture may copy
  # its files into one directory, so they get names of their own first.
  cp "$files/usr/lib/sysusers.d/imuemu.conf" "$work/imuemu.sysusers.conf"
  cp "$files/usr/lib/tmpfiles.d/imuemu.conf" "$work/imuemu.tmpfiles.conf"
  rc=0
  bash "$src/tests/hil/systemd_run.sh" --results "$work/systemd" \
    --unit "$files/lib/systemd/system/imuemud@.service" \
    --sysusers "$work/imuemu.sysusers.conf" --tmpfiles "$work/imuemu.tmpfiles.conf" \
    --scene "$src/tests/hil/hil_scene.toml" "$files/usr/sbin/imuemud" "$files/usr/bin/imuemu" >"$work/systemd.log" 2>&1 || rc=$?
  if ((rc == 0)); then
    pass "the package's imuemud@hil under systemd: $(grep -c '^PASS' "$work/systemd/checks.txt") checks passed ($(grep -o 'backend [a-z]*' "$work/systemd.log" | head -1))"
  else
    cat "$work/systemd.log"; grep -v '^PASS' "$work/systemd/checks.txt" 2>/dev/null || true
    fail "the package's imuemud@hil under systemd (log: $work/systemd.log)"
  fi
fi

echo "package_check: $failures failed (work directory: $work)"
((failures == 0))
