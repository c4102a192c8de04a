#!/usr/bin/env bash
# Hardware-in-the-loop fixture: runs one command inside Debian's own amd64
# kernel under QEMU (TCG), where it meets real drivers: a 16550 UART (the 8250
# driver) on /dev/ttyS1 whose other end is on the host, SocketCAN with vcan0,
# and a GPIO chip (tests/hil/gpio_recorder) that records every level driven on
# its lines with kernel timestamps.
#
#   tests/hil/qemu_run.sh [OPTIONS] [--] CMD [ARG...]
#
#   --include PATH     copy a host file or directory into the guest at the same
#                      absolute path; ELF files bring the shared libraries ldd
#                      lists (repeatable)
#   --fetch PATH       after CMD, copy this guest path back to
#                      RESULTS/fetched/PATH (repeatable)
#   --env NAME=VALUE   set in CMD's environment (repeatable); ASAN_OPTIONS,
#                      UBSAN_OPTIONS and LSAN_OPTIONS pass through when set
#   --serial1 SPEC     QEMU chardev backend for the guest's /dev/ttyS1, e.g.
#                      socket,path=/tmp/x.sock,server=on,wait=on (QEMU waits for
#                      the host test to connect); default: file RESULTS/ttyS1.out
#   --results DIR      keep the results here (default: a temporary directory
#                      removed on exit)
#   --timeout SECONDS  whole boot+run+poweroff (default 240); --mem SIZE (512M)
#   --host-root INIT   after the setup below, switch to the host's own root
#                      file system (read-only over virtio-9p, under a tmpfs
#                      overlay, so writes stay in the guest) and exec INIT (a
#                      host path) there as PID 1 instead of running CMD; /dev,
#                      /proc, /sys come along, vcan0 and the modules stay.
#                      INIT writes its own results (through --share) and
#                      powers off; this script then exits 0, or 125 if the
#                      switch failed or the guest did not power off in time.
#   --share DIR        with --host-root: DIR is writable in the guest at the
#                      same path, its writes land on the host (repeatable)
#   --trace EVENTS     QEMU trace events (a -trace enable= pattern, e.g.
#                      serial_update_parameters: the UART's baud rate as QEMU
#                      computes it from the divisor the guest programs) into
#                      RESULTS/qemu_trace.txt (QEMU's log trace backend)
#
# Inside the guest (busybox, PID 1 script, root; the initramfs itself is the
# writable root file system): /proc, /sys, /dev, /sys/kernel/debug; lo and vcan0 (MTU 72, CAN FD) up;
# gpio_recorder loaded with 8 lines, its chip's device in HIL_GPIOCHIP; tools
# gpioset/gpioget/gpioinfo/gpiodetect/gpiomon (libgpiod), candump/cansend/cangen.
# CMD runs in the caller's working directory (created if absent) with stdin
# from /dev/null; HIL_OUT is a guest directory whose contents come back.
#
# Results (in RESULTS): output.txt (CMD's stdout+stderr, also printed here),
# rc, gpio_recorder.txt (the recorder's log: "<t_ns> <line> <value>" lines,
# CLOCK_MONOTONIC), dmesg.txt, ttyS1.out (default --serial1), console.log,
# fetched/..., and whatever CMD wrote to $HIL_OUT. They travel back over a
# third UART (/dev/ttyS2) as a tar stream. The script exits with CMD's exit
# status, or 125 with the reason when the fixture itself fails.
#
# The kernel is the one linux-image-amd64 depends on now (apt-cache depends),
# downloaded with apt-get download; the kernel, the module and the base
# initramfs are cached in ${IMUEMU_HIL_CACHE:-<repo>/build/hil}/<kernel version>.
# The gpio_recorder module needs linux-headers-<version> installed.
set -euo pipefail

readonly FIXTURE_FAILURE=125
fail() { echo "qemu_run: FIXTURE FAILURE: $*" >&2; exit $FIXTURE_FAILURE; }
usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//' >&2; exit 2; }
log() { echo "qemu_run: $*" >&2; }
now_ns() { date +%s%N; }
seconds_since() { awk -v a="$1" -v b="$(now_ns)" 'BEGIN { printf "%.2f", (b - a) / 1e9 }'; }

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo=$(cd "$here/../.." && pwd)
includes=() fetches=() envs=() shares=()
serial1="" results_dir="" timeout_s=240 mem=512M host_root_init="" trace_events=""

while (($#)); do
  case "$1" in
    --include) includes+=("$2"); shift 2 ;;
    --fetch) fetches+=("$2"); shift 2 ;;
    --env) [[ $2 == [A-Za-z_]*=* ]] || fail "--env wants NAME=VALUE, got '$2'"; envs+=("$2"); shift 2 ;;
    --serial1) serial1=$2; shift 2 ;;
    --results) results_dir=$2; shift 2 ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --mem) mem=$2; shift 2 ;;
    --host-root) host_root_init=$2; shift 2 ;;
    --share) shares+=("$2"); shift 2 ;;
    --trace) trace_events=$2; shift 2 ;;
    -h|--help) usage ;;
    --) shift; break ;;
    -*) echo "qemu_run: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
if [[ -n $host_root_init ]]; then
  [[ $host_root_init == /* && -x $host_root_init ]] || fail "--host-root wants the absolute path of an executable init, got '$host_root_init'"
  (($#)) && fail "--host-root runs INIT, not a command: drop '$*'"
  set -- true
  for d in "${shares[@]}"; do
    [[ $d == /* && -d $d && $d != *,* ]] || fail "--share wants an absolute directory path without commas, got '$d'"
  done
elif ((${#shares[@]})); then
  fail "--share needs --host-root"
fi
(($#)) || { echo "qemu_run: no command given" >&2; usage; }
for v in ASAN_OPTIONS UBSAN_OPTIONS LSAN_OPTIONS; do
  [[ -n ${!v:-} ]] && envs+=("$v=${!v}")
done

# shellcheck source=hil_backend.sh
source "$here/hil_backend.sh"
case ${IMUEMU_HIL_BACKEND:-auto} in
  auto|qemu) [[ -n $host_root_init ]] || log "backend qemu" ;;
  uml) log "backend qemu (this scenario needs what only QEMU's kernel offers: the 8250 UART, the GPIO chip or the host root over 9p; IMUEMU_HIL_BACKEND=uml does not apply)" ;;
  *) fail "IMUEMU_HIL_BACKEND='$IMUEMU_HIL_BACKEND': expected auto, uml or qemu" ;;
esac
start_ns=$(now_ns)
need() { # command, Debian package
  command -v "$1" >/dev/null || fail "'$1' not found: install the Debian package $2 (scripts/setup.sh)"
}
need qemu-system-x86_64 qemu-system-x86
need cpio cpio
need gpioset gpiod
need candump can-utils
need make build-essential
need modinfo kmod
need apt-get apt
if [[ ! -x /bin/busybox ]] || ldd /bin/busybox >/dev/null 2>&1; then
  fail "/bin/busybox is missing or not static: install the Debian package busybox-static"
fi

# --- kernel version: whatever linux-image-amd64 depends on today ---
image_pkg=$(apt-cache depends linux-image-amd64 2>/dev/null | awk '$1 == "Depends:" && $2 ~ /^linux-image-/ { print $2; exit }')
[[ -n $image_pkg ]] || fail "apt-cache depends linux-image-amd64 names no kernel package (apt lists missing? run apt-get update)"
kver=${image_pkg#linux-image-}
headers=/usr/src/linux-headers-$kver
[[ -f $headers/Makefile ]] ||
  fail "kernel headers for $kver are not installed ($headers missing; installed: $(ls -d /usr/src/linux-headers-*-amd64 2>/dev/null | tr '\n' ' ')); run: apt-get install linux-headers-$kver (or scripts/setup.sh after apt-get update)"

cache_root=${IMUEMU_HIL_CACHE:-$repo/build/hil}
cache=$cache_root/$kver
mkdir -p "$cache"

# --- cached pieces, built under a lock (parallel ctest runs share them) ---
build_cache() {
  # The kernel and the CAN modules, straight from Debian's package, and for
  # --host-root virtio-pci, 9p and overlay (all modules in Debian's kernel),
  # listed in load order in host-root.order (each after what it depends on,
  # from modinfo).
  can_modules=(kernel/net/can/can.ko kernel/net/can/can-raw.ko kernel/drivers/net/can/dev/can-dev.ko kernel/drivers/net/can/vcan.ko)
  if [[ ! -f $cache/kernel/vmlinuz || ! -f $cache/kernel/modules/host-root.order ]]; then
    local t0 dl; t0=$(now_ns)
    rm -rf "$cache/download" "$cache/kernel"; mkdir -p "$cache/download"
    (cd "$cache/download" && apt-get download "$image_pkg" >apt.log 2>&1) ||
      fail "apt-get download $image_pkg failed: $(tail -n 3 "$cache/download/apt.log")"
    dl=$(ls "$cache/download"/*.deb)
    mkdir -p "$cache/download/x"
    dpkg-deb --fsys-tarfile "$dl" | tar -x -C "$cache/download/x" --wildcards "./boot/vmlinuz-$kver" \
      "${can_modules[@]/#/./lib/modules/$kver/}" "./lib/modules/$kver/kernel/drivers/virtio/*" \
      "./lib/modules/$kver/kernel/net/9p/*" "./lib/modules/$kver/kernel/fs/*" || fail "extracting the kernel and modules from $dl"
    mkdir -p "$cache/kernel/modules"
    cp "$cache/download/x/lib/modules/$kver/"{kernel/net/can/can.ko,kernel/net/can/can-raw.ko,kernel/drivers/net/can/dev/can-dev.ko,kernel/drivers/net/can/vcan.ko} "$cache/kernel/modules/"
    local -A module_path=() loaded=()
    local ko order=()
    while IFS= read -r ko; do module_path[$(basename "$ko" .ko)]=$ko; done < <(find "$cache/download/x/lib/modules" -name '*.ko')
    add_module() { # $1 = module name (dashes or underscores), after its dependencies
      local name=${1//-/_} dep
      [[ -n ${loaded[$name]:-} ]] && return 0
      [[ -n ${module_path[$name]:-} ]] || fail "module $name (needed for --host-root) is not in $dl"
      for dep in $(modinfo -F depends "${module_path[$name]}" | tr ',' ' '); do add_module "$dep"; done
      loaded[$name]=1; order+=("$name"); cp "${module_path[$name]}" "$cache/kernel/modules/$name.ko"
    }
    for ko in virtio_pci 9pnet_virtio 9p overlay; do add_module "$ko"; done
    printf '%s\n' "${order[@]}" >"$cache/kernel/modules/host-root.order"
    basename "$dl" >"$cache/kernel/package"
    mv "$cache/download/x/boot/vmlinuz-$kver" "$cache/kernel/vmlinuz"
    rm -rf "$cache/download"
    log "kernel $kver from $(<"$cache/kernel/package") cached in $(seconds_since "$t0") s"
  fi
  # Decompressing the bzImage under TCG takes ~5 s of every boot; QEMU boots
  # the uncompressed ELF directly through its PVH entry point (CONFIG_PVH;
  # ELF note XEN_ELFNOTE_PHYS32_ENTRY = 0x12) in ~1 s. Falls back, saying so.
  if [[ ! -f $cache/kernel/vmlinux && ! -f $cache/kernel/no-pvh ]]; then
    need readelf binutils
    extract_pvh_vmlinux "$cache/kernel/vmlinuz" "$cache/kernel/vmlinux" ||
      { log "no PVH-bootable vmlinux in $kver's bzImage: booting the compressed kernel (slower)"; touch "$cache/kernel/no-pvh"; }
  fi

  # The recorder module, rebuilt when its source changes.
  local src_sum; src_sum=$(cat "$here/gpio_recorder/gpio_recorder.c" "$here/gpio_recorder/Makefile" | sha256sum | cut -c1-16)
  if [[ ! -f $cache/gpio_recorder/gpio_recorder.ko || $(cat "$cache/gpio_recorder/source.sum" 2>/dev/null) != "$src_sum" ]]; then
    local t0; t0=$(now_ns)
    rm -rf "$cache/gpio_recorder"; mkdir -p "$cache/gpio_recorder"
    cp "$here/gpio_recorder/gpio_recorder.c" "$here/gpio_recorder/Makefile" "$cache/gpio_recorder/"
    make -C "$headers" M="$cache/gpio_recorder" modules >"$cache/gpio_recorder/build.log" 2>&1 ||
      { cat "$cache/gpio_recorder/build.log" >&2; fail "building gpio_recorder.ko against $headers failed"; }
    echo "$src_sum" >"$cache/gpio_recorder/source.sum"
    log "gpio_recorder.ko built in $(seconds_since "$t0") s"
  fi

  # The base initramfs: busybox, the tools, the modules and /init.
  local base_sum; base_sum=$( { guest_init; sha256sum "$cache/gpio_recorder/gpio_recorder.ko" "$cache/kernel/vmlinuz" "$cache/kernel/modules/"*;
    dpkg-query -W busybox-static gpiod can-utils libc6 libgpiod2; } | sha256sum | cut -c1-16)
  if [[ ! -f $cache/base.cpio.gz || $(cat "$cache/base.sum" 2>/dev/null) != "$base_sum" ]]; then
    local t0 stage; t0=$(now_ns)
    stage=$cache/base-stage; rm -rf "$stage"
    mkdir -p "$stage"/{bin,sbin,usr/bin,usr/sbin,proc,sys,dev,tmp,run,root,etc,hil/out,lib/modules/hil}
    cp /bin/busybox "$stage/bin/busybox"
    for applet in $(/bin/busybox --list-full); do
      [[ -e $stage/$applet ]] || ln -s /bin/busybox "$stage/$applet"
    done
    for tool in gpioset gpioget gpioinfo gpiodetect gpiomon gpiofind candump cansend cangen; do
      stage_with_libs "$stage" "$(command -v "$tool")"
    done
    cp "$cache/kernel/modules/"*.ko "$cache/kernel/modules/host-root.order" "$cache/gpio_recorder/gpio_recorder.ko" "$stage/lib/modules/hil/"
    guest_init >"$stage/init"; chmod 755 "$stage/init"
    (cd "$stage" && find . -mindepth 1 | LC_ALL=C sort | cpio -o -H newc -R 0:0 --quiet | gzip -1) >"$cache/base.cpio.gz.tmp"
    mv "$cache/base.cpio.gz.tmp" "$cache/base.cpio.gz"
    echo "$base_sum" >"$cache/base.sum"
    rm -rf "$stage"
    log "base initramfs built in $(seconds_since "$t0") s"
  fi
}

# Writes the ELF kernel inside bzImage $1 to $2 if it has a PVH entry point.
extract_pvh_vmlinux() {
  local magic_tool magic tool offset
  for magic_tool in $'\xfd7zXZ:xz' $'\x28\xb5\x2f\xfd:zstd' $'\x1f\x8b\x08:gzip'; do
    magic=${magic_tool%:*} tool=${magic_tool##*:}
    command -v "$tool" >/dev/null || continue
    for offset in $(LC_ALL=C grep -abo "$magic" "$1" | cut -d: -f1 | head -n 5); do
      tail -c +$((offset + 1)) "$1" | "$tool" -dc >"$2.tmp" 2>/dev/null
      if [[ $(head -c 4 "$2.tmp" | od -An -c | tr -d ' ') == '177ELF' ]] &&
        readelf -n "$2.tmp" 2>/dev/null | grep -q 'note type: (0x00000012)'; then
        mv "$2.tmp" "$2"; return 0
      fi
    done
  done
  rm -f "$2.tmp"; return 1
}

# Copies FILE to STAGE at the same absolute path, plus (for ELF files) every
# shared library and the loader ldd lists, at the paths ldd names.
stage_with_libs() {
  local stage=$1 file=$2
  [[ -e $file ]] || fail "cannot include '$file': no such file"
  file=$(realpath -s "$file")
  if [[ -d $file ]]; then
    mkdir -p "$stage$(dirname "$file")"; cp -a "$file" "$stage$(dirname "$file")/"; return
  fi
  mkdir -p "$stage$(dirname "$file")"; cp -L "$file" "$stage$file"
  [[ $(head -c 4 "$file" | od -An -c | tr -d ' ') == '177ELF' ]] || return 0
  local lib
  for lib in $(ldd "$file" 2>/dev/null | grep -o '/[^ )]*' || true); do
    [[ -e $stage$lib ]] && continue
    mkdir -p "$stage$(dirname "$lib")"; cp -L "$lib" "$stage$lib"
  done
}

# PID 1 of the guest (busybox sh). Per-run settings come from /hil/run.sh,
# which the second, per-run initramfs archive adds.
guest_init() {
  cat <<'EOF'
#!/bin/sh
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root
export HIL_OUT=/hil/out
mount -t proc proc /proc; mount -t sysfs sysfs /sys; mount -t devtmpfs devtmpfs /dev
mkdir -p /dev/pts; mount -t devpts devpts /dev/pts; mount -t debugfs debugfs /sys/kernel/debug
setup_log=$HIL_OUT/guest_setup.txt
send_results() {
  # Raw mode so the tar stream passes unchanged; closing the tty waits until
  # the UART has sent everything (tty closing_wait), then it is safe to stop.
  stty -F /dev/ttyS2 raw -echo 115200
  tar -C "$HIL_OUT" -cf /dev/ttyS2 .
  poweroff -f
}
setup_failed() { echo "guest setup failed: $*" >>"$setup_log"; dmesg >"$HIL_OUT/dmesg.txt"; send_results; }
for m in can can-raw can-dev vcan gpio_recorder; do
  insmod /lib/modules/hil/$m.ko 2>>"$setup_log" || setup_failed "insmod $m.ko"
done
{ ip link set lo up && ip link add dev vcan0 type vcan && ip link set vcan0 mtu 72 &&
  ip link set vcan0 up; } 2>>"$setup_log" || setup_failed "creating vcan0"
HIL_GPIOCHIP=/dev/$(gpiodetect | awk '/\[gpio-recorder\]/ { print $1; exit }')
[ -c "$HIL_GPIOCHIP" ] || setup_failed "no gpio-recorder chip in: $(gpiodetect 2>&1)"
export HIL_GPIOCHIP
[ -f /hil/run.sh ] || setup_failed "no /hil/run.sh in the initramfs"
. /hil/run.sh
if [ -n "${hil_host_root_init:-}" ]; then
  # The host's root, read-only over virtio-9p (cache=loose: nothing changes
  # it during a run), under a tmpfs overlay so the guest may write anywhere;
  # the --share directories (9p, uncached) on top at their host paths.
  for m in $(cat /lib/modules/hil/host-root.order); do
    insmod /lib/modules/hil/$m.ko 2>>"$setup_log" || setup_failed "insmod $m.ko (for the host root)"
  done
  mkdir -p /hil/lower /hil/rw /hil/root
  mount -t 9p -o ro,trans=virtio,version=9p2000.L,msize=512000,cache=loose hil_root /hil/lower 2>>"$setup_log" ||
    setup_failed "mounting the host root over virtio-9p"
  mount -t tmpfs -o mode=755 tmpfs /hil/rw && mkdir -p /hil/rw/upper /hil/rw/work &&
    mount -t overlay -o lowerdir=/hil/lower,upperdir=/hil/rw/upper,workdir=/hil/rw/work overlay /hil/root 2>>"$setup_log" ||
    setup_failed "the tmpfs overlay over the host root"
  hil_mount_shares /hil/root 2>>"$setup_log" || setup_failed "mounting the --share directories"
  for d in dev proc sys; do mount --move /$d /hil/root/$d 2>>"$setup_log" || setup_failed "moving /$d to the host root"; done
  exec switch_root /hil/root "$hil_host_root_init"
fi
(cd "$hil_cwd" && hil_command) </dev/null >"$HIL_OUT/output.txt" 2>&1
echo $? >"$HIL_OUT/rc"
cat /sys/kernel/debug/gpio_recorder/events >"$HIL_OUT/gpio_recorder.txt"
hil_fetch
dmesg >"$HIL_OUT/dmesg.txt"
send_results
EOF
}

lock_t0=$(now_ns)
exec 9>"$cache_root/.lock-$kver"
flock 9
build_cache
flock -u 9
exec 9>&-

# --- per-run archive: /hil/run.sh and the included files ---
work=$(mktemp -d "${TMPDIR:-/tmp}/qemu_run.XXXXXX")
qemu_pid=""
cleanup() { [[ -n $qemu_pid ]] && kill "$qemu_pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
trap 'exit 143' TERM INT HUP
if [[ -z $results_dir ]]; then results_dir=$work/results; fi
mkdir -p "$results_dir"; results_dir=$(cd "$results_dir" && pwd)
rm -rf "$results_dir/rc" "$results_dir/output.txt" "$results_dir/fetched" "$results_dir/guest_setup.txt"

stage=$work/stage
mkdir -p "$stage/hil" "$stage$PWD"
for f in "${includes[@]}"; do stage_with_libs "$stage" "$f"; done
squote() { local s=${1//\'/\'\\\'\'}; printf "'%s'" "$s"; }
{
  echo "hil_cwd=$(squote "$PWD")"
  for e in "${envs[@]}"; do echo "export $(squote "$e")"; done
  printf 'hil_command() {'; for a in "$@"; do printf ' %s' "$(squote "$a")"; done; printf '; }\n'
  [[ -n $host_root_init ]] && echo "hil_host_root_init=$(squote "$host_root_init")"
  echo 'hil_mount_shares() {'
  echo '  :'
  for i in "${!shares[@]}"; do
    echo "  mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 hil_share$i \"\$1\"$(squote "${shares[i]}") || return 1"
  done
  echo '}'
  echo 'hil_fetch() {'
  echo '  :'
  for p in "${fetches[@]}"; do
    q=$(squote "$p")
    echo "  mkdir -p \"\$HIL_OUT/fetched\$(dirname $q)\" && cp -a $q \"\$HIL_OUT/fetched\"$q 2>>\"\$HIL_OUT/fetch_errors.txt\""
  done
  echo '}'
} >"$stage/hil/run.sh"
(cd "$stage" && find . -mindepth 1 | LC_ALL=C sort | cpio -o -H newc -R 0:0 --quiet) >"$work/run.cpio"
# Linux unpacks concatenated cpio archives in order, later files winning; an
# uncompressed archive is recognised only at a 4-byte aligned offset, and NUL
# bytes between archives are skipped (init/initramfs.c, unpack_to_rootfs).
base_size=$(stat -c %s "$cache/base.cpio.gz")
{ cat "$cache/base.cpio.gz"; head -c $(((4 - base_size % 4) % 4)) /dev/zero; cat "$work/run.cpio"; } >"$work/initrd"

# --- boot ---
kernel_image=$cache/kernel/vmlinux
[[ -f $kernel_image ]] || kernel_image=$cache/kernel/vmlinuz
if [[ -z $serial1 ]]; then serial1="file,path=$results_dir/ttyS1.out"; fi
virtfs=()
trace=()
if [[ -n $trace_events ]]; then
  rm -f "$results_dir/qemu_trace.txt"
  trace=(-trace "enable=$trace_events" -D "$results_dir/qemu_trace.txt")
fi
if [[ -n $host_root_init ]]; then
  # multidevs=remap: the host's root spans several file systems (/dev/shm,
  # /tmp, ...); remapped inode numbers stay unique in the guest.
  virtfs+=(-virtfs "local,path=/,mount_tag=hil_root,security_model=none,readonly=on,multidevs=remap")
  for i in "${!shares[@]}"; do
    virtfs+=(-virtfs "local,path=${shares[i]},mount_tag=hil_share$i,security_model=none,multidevs=remap")
  done
fi
boot_t0=$(now_ns)
qemu_rc=0
# TCG, not KVM: the nested KVM guest hung at boot on these machines. -cpu max
# offers the guest what TCG can emulate (SSE4.2, AVX2), so binaries built for
# the host's CPU run. -nodefaults: no VGA, NIC or drives to probe.
timeout --kill-after=5 "$timeout_s" qemu-system-x86_64 \
  -accel tcg -cpu max -m "$mem" -smp 1 -nodefaults -no-user-config -display none -no-reboot \
  -serial stdio \
  -chardev "$serial1,id=hil_serial1" -serial chardev:hil_serial1 \
  -chardev "file,id=hil_results,path=$work/results.tar" -serial chardev:hil_results \
  "${virtfs[@]}" "${trace[@]}" \
  -kernel "$kernel_image" -initrd "$work/initrd" \
  -append "console=ttyS0 panic=-1 oops=panic edd=off quiet mitigations=off" \
  </dev/null >"$results_dir/console.log" 2>&1 &
qemu_pid=$!
wait "$qemu_pid" || qemu_rc=$?
qemu_pid=""
elapsed=$(seconds_since "$boot_t0")

if [[ -s $work/results.tar ]]; then
  tar -x -f "$work/results.tar" -C "$results_dir" 2>"$work/untar.log" ||
    { log "results archive from the guest is damaged: $(cat "$work/untar.log")"; rm -f "$results_dir/rc"; }
fi
# On a failed run: whatever the guest's setup logged, the console lines that
# show the cause, and where the whole console is (kept even without --results).
report_failure() {
  ((qemu_rc == 124 || qemu_rc == 137)) && log "the guest did not power off within ${timeout_s} s"
  [[ -s $results_dir/guest_setup.txt ]] && sed 's/^/qemu_run: /' "$results_dir/guest_setup.txt"
  local console=$results_dir/console.log
  if [[ $results_dir == "$work"/* ]]; then
    console=$(mktemp "${TMPDIR:-/tmp}/qemu_run.console.XXXXXX")
    cp "$results_dir/console.log" "$console"
  fi
  log "qemu-system-x86_64 exited with status $qemu_rc; the console's lines that show the cause:"
  hil_console_cause "$results_dir/console.log" | sed 's/^/  /'
  log "whole console: $console"
}
if [[ -n $host_root_init ]]; then
  # The initramfs sends results over ttyS2 only when it fails before the
  # switch; after it, INIT reports through its --share directories.
  if [[ -s $work/results.tar ]] || ((qemu_rc != 0)); then
    report_failure >&2
    fail "the guest did not switch to the host root and power off (${elapsed} s)"
  fi
  log "kernel $kver: cache check $(awk -v a="$lock_t0" -v b="$boot_t0" 'BEGIN { printf "%.2f", (b - a) / 1e9 }') s, boot+host root init+poweroff ${elapsed} s"
  exit 0
fi
if [[ -s $results_dir/output.txt ]]; then cat "$results_dir/output.txt"; fi
if [[ ! -f $results_dir/rc ]]; then
  report_failure >&2
  fail "the command did not run to completion inside QEMU (${elapsed} s)"
fi
[[ -s $results_dir/fetch_errors.txt ]] && sed 's/^/qemu_run: fetch: /' "$results_dir/fetch_errors.txt" >&2
cmd_rc=$(<"$results_dir/rc")
log "kernel $kver: cache check $(awk -v a="$lock_t0" -v b="$boot_t0" 'BEGIN { printf "%.2f", (b - a) / 1e9 }') s, boot+run+poweroff ${elapsed} s, total $(seconds_since "$start_ns") s, command exit status $cmd_rc"
exit "$cmd_rc"
