#!/bin/bash
# Guest side of the hil_can_dronecan_j1939 test (run by tests/hil/hil_run.sh,
# which gives it a real SocketCAN stack with vcan0, under user-mode Linux or
# QEMU):
#
#   can_emit_guest.sh IMUEMU [PROTOCOL...]     (default: dronecan j1939)
#
# For each protocol, `imuemu emit` sends the built-in static IMU at RATE_HZ
# for SECONDS_EMITTED on vcan0 while three independent receivers capture the interface at once:
# candump -L (can-utils), a python-can socket (can_peer.py capture) and
# `imuemu listen --json`. Then can_peer.py check compares the three captures
# with each other, with what emit reports and with the protocol, decoded
# from the specification (see can_peer.py). Results land in
# $HIL_OUT/<protocol>/. Exit status 0 only if every protocol passed.
set -u
imuemu=${1:?usage: can_emit_guest.sh IMUEMU [PROTOCOL...]}
shift
protocols=("$@")
((${#protocols[@]})) || protocols=(dronecan j1939)
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
out_root=${HIL_OUT:?run me through tests/hil/hil_run.sh}
python=/usr/bin/python3 # Debian's, which has python3-can
# Under QEMU's TCG each CAN write costs a millisecond or more of guest CPU:
# at 100 Hz (700 DroneCAN frames/s) emit's transmit queue fell behind on a
# loaded host and the frames still queued when it stopped were lost. 50 Hz
# there; the checks do not depend on the rate.
if [[ ${HIL_BACKEND:-} == qemu ]]; then RATE_HZ=50; else RATE_HZ=100; fi
readonly RATE_HZ SECONDS_EMITTED=3
# What emit sends from by default (drivers/protocols/{dronecan,j1939}.hpp
# DroneCanOptions::node_id, J1939Options::source_address): listen filters on
# them, can_peer.py checks every frame's id carries them.
readonly NODE_ID=42 SOURCE_ADDRESS=0x80

log() { echo "can_emit_guest: $*"; }
ms_since() { echo $((($(date +%s%N) - $1) / 1000000)); }
raw_receivers() { grep -c ' raw$' /proc/net/can/rcvlist_all; } # prints 0 when none
# Waits until CONDITION holds. The bound only catches a hang: python-can's
# import takes ~3 s under UML and ~25 s under QEMU's TCG (more on a loaded
# host), so it is generous.
readonly WAIT_LIMIT_S=150
wait_for() {
  local what=$1; shift
  local t0; t0=$(date +%s%N)
  while (($(ms_since "$t0") < WAIT_LIMIT_S * 1000)); do
    "$@" && { log "$what after $(ms_since "$t0") ms"; return 0; }
    sleep 0.1
  done
  log "FAILED: $what did not happen within $WAIT_LIMIT_S s"; return 1
}
# shellcheck disable=SC2317 # called through wait_for
more_receivers_than() { (($(raw_receivers) > $1)); }

run_protocol() {
  local protocol=$1 index=$2 out=$out_root/$1
  local emit_args=(--sample static --duration-s "$((SECONDS_EMITTED + 2))" --seconds "$SECONDS_EMITTED"
                   --rate "$RATE_HZ" --protocol "$protocol" --device can:vcan0 --stats-json "$out/emit.json")
  local listen_args=(--protocol "$protocol" --device can:vcan0 --json)
  local check_args=(--rate "$RATE_HZ" --sample-static)
  case $protocol in
    dronecan) listen_args+=(--dronecan-node-id "$NODE_ID"); check_args+=(--node-id "$NODE_ID") ;;
    j1939) listen_args+=(--j1939-source-address "$SOURCE_ADDRESS"); check_args+=(--source-address "$SOURCE_ADDRESS")
           [[ -s $out_root/dronecan/candump.log ]] && check_args+=(--frd-reference "$out_root/dronecan/candump.log") ;;
    *) log "unknown protocol $protocol"; return 1 ;;
  esac

  # Each receiver's socket must be bound before the first frame is sent.
  # /proc/net/can/rcvlist_all lists one 'raw' entry per bound CAN_RAW
  # receiver, so each is started and awaited in turn; the python-can capture
  # (started once, slow to start in an emulated guest) says itself when it writes here.
  wait_for "python-can capturing into $out/python.log" test -f "$out/python.log.ready" || return 1
  local base; base=$(raw_receivers)
  # Line-buffered, so the log shows how far candump has read (see drain below).
  stdbuf -oL candump -L vcan0 >"$out/candump.log" 2>"$out/candump.err" &
  local candump_pid=$!
  pids+=("$candump_pid")
  wait_for "candump bound" more_receivers_than "$base" || return 1
  base=$(raw_receivers)
  "$imuemu" listen "${listen_args[@]}" >"$out/listen.ndjson" 2>"$out/listen.err" &
  local listen_pid=$!
  pids+=("$listen_pid")
  wait_for "imuemu listen bound" more_receivers_than "$base" || { cat "$out/listen.err"; return 1; }

  local t0; t0=$(date +%s%N)
  # SCHED_FIFO for all of emit's threads (the emission thread and the
  # transmit thread): the receivers, at normal priority, catch up from their
  # socket buffers afterwards instead of competing with the sender.
  chrt -f 10 "$imuemu" emit "${emit_args[@]}" >"$out/emit.out" 2>&1
  local emit_rc=$?
  log "$protocol: imuemu emit ${emit_args[*]} -> exit $emit_rc in $(ms_since "$t0") ms"
  sed 's/^/  emit: /' "$out/emit.out"

  # Let the receivers drain their socket queues, then stop them: listen
  # prints its summary on SIGINT, candump flushes; the python capture closes
  # this run's log and moves on to the next (SIGUSR1) or ends (SIGTERM).
  # A stopped receiver loses what is still queued for it, and under TCG on a
  # loaded host it can be seconds behind: so wait until candump has logged
  # as many frames as emit offered and listen as many samples as emit sent
  # (both flush every line), bounded; a receiver that really lost frames
  # then fails the check below.
  local offered sent
  offered=$(grep -o '"frames": [0-9]*' "$out/emit.json" | head -n1 | grep -o '[0-9]*$')
  sent=$(grep -o '"emitted": [0-9]*' "$out/emit.json" | head -n1 | grep -o '[0-9]*$')
  drained() { (($(wc -l <"$out/candump.log") >= ${offered:-0} && $(grep -c '"type":"sample"' "$out/listen.ndjson") >= ${sent:-0})); }
  wait_for "candump ($offered frames) and listen ($sent samples) drained" drained ||
    log "$protocol: stopping the receivers anyway: candump has $(wc -l <"$out/candump.log") frames, listen $(grep -c '"type":"sample"' "$out/listen.ndjson") samples"
  sleep 0.5
  kill -INT "$listen_pid" "$candump_pid" 2>/dev/null
  wait "$listen_pid"; local listen_rc=$?
  wait "$candump_pid"
  pids=()
  python_move_to $((index + 1)) || return 1
  log "$protocol: listen exit $listen_rc; $(wc -l <"$out/candump.log") candump frames, $(wc -l <"$out/python.log") python-can frames"
  [[ -s $out/listen.err ]] && sed 's/^/  listen: /' "$out/listen.err"
  ((emit_rc == 0)) || { log "FAILED: $protocol: imuemu emit exited with $emit_rc"; return 1; }
  ((listen_rc == 0)) || { log "FAILED: $protocol: imuemu listen exited with $listen_rc"; return 1; }
  "$python" "$here/can_peer.py" check "$protocol" --candump "$out/candump.log" --python "$out/python.log" \
    --listen "$out/listen.ndjson" --emit-stats "$out/emit.json" "${check_args[@]}"
}

# Receivers still running when a protocol's run fails early are stopped
# before the next one starts, so they cannot capture its frames.
stop_receivers() {
  ((${#pids[@]})) && kill "${pids[@]}" 2>/dev/null && wait "${pids[@]}" 2>/dev/null
  pids=()
}

# The python-can capture writes run i's frames to python_logs[i]; it closes
# one and moves to the next on SIGUSR1 and ends on SIGTERM (after the last).
python_move_to() {
  while ((python_at < $1)); do
    python_at=$((python_at + 1))
    if ((python_at < ${#protocols[@]})); then
      kill -USR1 "$python_pid"
      wait_for "python-can capture moved to run $python_at" test -f "${python_logs[python_at]}.ready" || return 1
    else
      kill -TERM "$python_pid"; wait "$python_pid"
      sed 's/^/  /' "$out_root/python.out"
    fi
  done
}

log "backend ${HIL_BACKEND:-unknown}"
if [[ ${HIL_BACKEND:-} == uml ]] && ldd "$imuemu" 2>/dev/null | grep -q libasan; then
  log "FAILED: $imuemu is an AddressSanitizer build, which cannot run under UML (tests/hil/README.md): use a release build"
  exit 1
fi

# UML and TCG run everything slowly: with the default 208 KiB socket buffers a
# receiver that falls behind a burst of DroneCAN frames (7 per sample) loses
# some (listen counts them as can_kernel_drops). Larger buffers, in this guest
# kernel only, let every receiver catch up.
if ! { echo $((8 << 20)) >/proc/sys/net/core/rmem_default && echo $((8 << 20)) >/proc/sys/net/core/rmem_max; }; then
  log "FAILED: cannot raise the socket receive buffers"; exit 1
fi

python_logs=()
for protocol in "${protocols[@]}"; do
  rm -rf "${out_root:?}/$protocol"; mkdir -p "$out_root/$protocol"
  python_logs+=("$out_root/$protocol/python.log")
done
"$python" "$here/can_peer.py" capture --channel vcan0 --out "${python_logs[@]}" >"$out_root/python.out" 2>&1 &
python_pid=$!
python_at=0

status=0
for index in "${!protocols[@]}"; do
  protocol=${protocols[index]}
  pids=()
  ok=0; python_move_to "$index" && run_protocol "$protocol" "$index" || ok=1
  stop_receivers
  if ((ok == 0)); then log "$protocol: PASSED"; else log "$protocol: FAILED"; status=1; fi
done
python_move_to ${#protocols[@]}
exit $status
