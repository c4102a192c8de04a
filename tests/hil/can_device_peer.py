#!/usr/bin/python3
"""The CAN devices answer their drivers on a real SocketCAN vcan0 (issue 27,
acceptance 3; guest side, called by fault_can_guest.py inside the same
hil_can_faults boot, so it costs no boot of its own).

    can_device_peer.py IMUEMUD OUT_DIR        (also importable: run(imuemud, out))

imuemud runs two devices on vcan0: a DroneCAN node (node id 42, identity from
[imu.device], a saturation fault and a restart fault) and a J1939 node
(source address 0x90, not the default, with Component Identification keys).
This script is the driver side, written here from the documents with the
standard library's AF_CAN socket (no python-can, no project code):

 - DroneCAN specification 4.1 "CAN bus transport layer": 29-bit id of a
   service frame = priority << 24 | service type id << 16 |
   request_not_response << 15 | destination << 8 | 1 << 7 | source; of a
   message frame = priority << 24 | data type id << 8 | source. Tail byte =
   start << 7 | end << 6 | toggle << 5 | transfer id (toggle 0 in the first
   frame). A multi-frame transfer starts with the transfer CRC
   (CRC-16-CCITT-FALSE, initial 0xFFFF, over the data type signature's 8
   bytes little-endian, then the payload), little-endian.
 - DSDL uavcan.protocol: 341.NodeStatus (uint32 uptime_sec, uint2 health,
   uint3 mode, uint3 sub_mode, uint16 vendor code: 7 bytes, sub-byte fields
   from the byte's most significant bit); 1.GetNodeInfo (request empty;
   response NodeStatus, SoftwareVersion {u8 major, u8 minor, u8
   optional_field_flags, u32 vcs_commit, u64 image_crc}, HardwareVersion {u8
   major, u8 minor, u8[16] unique_id, u8[<=255] certificate with an 8-bit
   length}, u8[<=80] name as the tail array, without a length), signature
   0xEE468A8121C46A9E.
 - J1939-21: 29-bit id = priority << 26 | PGN (PF << 8 | PS) << 8 | source
   address; Request PGN 59904 (PF 0xEA, PS destination), 3 data bytes = the
   requested PGN little-endian; BAM: TP.CM (PF 0xEC to 0xFF) control 32,
   total size u16, packets, 0xFF, PGN (3 bytes); TP.DT (PF 0xEB) sequence
   1..n then 7 bytes, 0xFF padding. J1939-81: Address Claimed PGN 60928
   (PF 0xEE to 0xFF) from the claimed address, data = the 64-bit NAME
   little-endian (identity number bits 0-20, manufacturer code 21-31, ECU
   instance 32-34, function instance 35-39, function 40-47, vehicle system
   49-55, vehicle system instance 56-59, industry group 60-62, arbitrary
   address capable 63). J1939-71: Component Identification PGN 65259 =
   "make*model*serial*unit*".

What the peer does, as ArduPilot's DroneCAN node-allocation server and a
J1939 tool do: GetNodeInfo once the node is first seen; again after a WARNING
NodeStatus (the saturation fault) and after an INITIALIZATION one (the
restart fault), each answered, and the node's following NodeStatus back to
OK / OPERATIONAL (what ArduPilot needs to clear "Node 42 unhealthy"). J1939:
a Request for Address Claimed to the node's address and one to global, each
answered with the claim from 0x90; a Request for Component Identification,
answered as a BAM. Functional only (UML's clock is emulated): the checks do
not depend on reply times.
"""
import json
import os
import select
import socket
import struct
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from can_peer import crc16_ccitt_false  # noqa: E402  (the spec's CRC, test code)

EFF = 0x80000000  # SocketCAN CAN_EFF_FLAG (linux/can.h): a 29-bit id
EFF_MASK = 0x1FFFFFFF
FRAME = struct.Struct("=IB3x8s")  # struct can_frame (linux/can.h), classic CAN

NODE_ID = 42
PEER_NODE_ID = 10  # the allocation server's node id (ArduPilot's default)
NODE_STATUS_ID = 341
GET_NODE_INFO = 1
GET_NODE_INFO_SIGNATURE = 0xEE468A8121C46A9E
J1939_SA = 0x90
J1939_PEER_SA = 0x21
PGN_REQUEST, PGN_ADDRESS_CLAIMED, PGN_TP_CM, PGN_TP_DT = 59904, 60928, 60416, 60160
PGN_COMPONENT_ID = 65259

# The configured identity (the scene's [imu.device] keys below), as the
# reply must carry it.
NODE_NAME = "org.imuemu.hil.imu"
SOFTWARE = (3, 7)
VCS_COMMIT = 0x1234ABCD
HARDWARE = (2, 1)
UNIQUE_ID = bytes(range(0x10, 0x20))
J1939_COMPONENT = ("HILIM", "hil-j1939-imu", "SN-0027", "U1")

RATE_HZ = 50
DURATION_S = 5.5  # the last NodeStatus checked is at 4.5 s; one more period of margin
SATURATION_AFTER_S, SATURATION_S = 1.2, 0.2  # NodeStatus at 2 s: WARNING; at 3 s: OK again
RESTART_AFTER_S = 3.5  # NodeStatus INITIALIZATION (uptime 0) at 3.5 s, OPERATIONAL at 4.5 s


def scene():
    return (f'[scene]\nname = "candevice"\nphysics = "flat"\n'
            f'[trajectory]\nsource = "sample:static"\nduration_s = {DURATION_S}\nknot_interval_s = 0.1\n'
            f'[[imu]]\nname = "dronecan0"\nrate_hz = {RATE_HZ}\nprotocol = "dronecan"\n'
            f'[imu.dronecan]\nnode_id = {NODE_ID}\n'
            f'[imu.device]\nnode_name = "{NODE_NAME}"\nsoftware_version = "{SOFTWARE[0]}.{SOFTWARE[1]}"\n'
            f'vcs_commit = {VCS_COMMIT}\nhardware_version = "{HARDWARE[0]}.{HARDWARE[1]}"\n'
            f'unique_id = "{UNIQUE_ID.hex()}"\n'
            f'[imu.transport]\ntype = "can"\ninterface = "vcan0"\n'
            f'[[imu.fault]]\ntype = "saturation"\nafter_s = {SATURATION_AFTER_S}\nduration_s = {SATURATION_S}\n'
            f'[[imu.fault]]\ntype = "restart"\nafter_s = {RESTART_AFTER_S}\nduration_s = {1 / RATE_HZ}\n'
            f'[[imu]]\nname = "j1939_0"\nrate_hz = {RATE_HZ}\nprotocol = "j1939"\n'
            f'[imu.j1939]\nsource_address = {J1939_SA}\n'
            f'[imu.device]\nmake = "{J1939_COMPONENT[0]}"\nmodel = "{J1939_COMPONENT[1]}"\n'
            f'serial_number = "{J1939_COMPONENT[2]}"\nunit_number = "{J1939_COMPONENT[3]}"\n'
            f'[imu.transport]\ntype = "can"\ninterface = "vcan0"\n')


# ------------------------------------------------------------ DroneCAN, from the spec

def service_id(priority, service, request, destination, source):
    return priority << 24 | service << 16 | int(request) << 15 | destination << 8 | 1 << 7 | source


def transfer_crc(signature, payload):
    return crc16_ccitt_false(crc16_ccitt_false(0xFFFF, signature.to_bytes(8, "little")), payload)


def node_status(payload):
    return {"uptime_sec": int.from_bytes(payload[0:4], "little"), "health": payload[4] >> 6,
            "mode": (payload[4] >> 3) & 7, "sub_mode": payload[4] & 7,
            "vendor_code": int.from_bytes(payload[5:7], "little")}


HEALTH = ["OK", "WARNING", "ERROR", "CRITICAL"]
MODE = ["OPERATIONAL", "INITIALIZATION", "MAINTENANCE", "SOFTWARE_UPDATE", "?", "?", "?", "OFFLINE"]


def decode_get_node_info(payload):
    p = payload
    out = {"status": node_status(p[0:7]),
           "software_version": {"major": p[7], "minor": p[8], "optional_field_flags": p[9],
                                "vcs_commit": int.from_bytes(p[10:14], "little"),
                                "image_crc": int.from_bytes(p[14:22], "little")},
           "hardware_version": {"major": p[22], "minor": p[23], "unique_id": p[24:40].hex()}}
    cert_len = p[40]
    out["hardware_version"]["certificate_bytes"] = cert_len
    out["name"] = p[41 + cert_len:].decode("ascii", errors="replace")
    return out


class ServiceReassembler:
    """One service response transfer from the node to us: tail bytes, toggle
    and (multi-frame) the transfer CRC checked as the spec says."""

    def __init__(self, service, signature, tid):
        self.id = service_id(0, service, False, PEER_NODE_ID, NODE_ID) & ~(0x1F << 24)
        self.signature, self.tid = signature, tid
        self.data, self.toggle, self.started = bytearray(), False, False
        self.errors = []
        self.frames = 0

    def matches(self, ident):
        return ident & ~(0x1F << 24) == self.id

    def feed(self, data):
        """Returns the payload when the transfer is complete, else None."""
        tail = data[-1]
        start, end, toggle, tid = bool(tail & 0x80), bool(tail & 0x40), bool(tail & 0x20), tail & 0x1F
        if tid != self.tid:
            self.errors.append(f"transfer id {tid}, expected {self.tid}")
            return None
        if start != (not self.started) or toggle != self.toggle:
            self.errors.append(f"frame {self.frames}: start {start}, toggle {toggle} out of order")
        self.started, self.toggle = True, not toggle
        self.frames += 1
        self.data += data[:-1]
        if not end:
            if len(data) != 8:
                self.errors.append(f"frame {self.frames}: a non-final frame of {len(data)} bytes")
            return None
        if self.frames == 1:
            return bytes(self.data)
        crc, payload = self.data[0] | self.data[1] << 8, bytes(self.data[2:])
        if crc != transfer_crc(self.signature, payload):
            self.errors.append(f"transfer CRC {crc:#06x}, expected {transfer_crc(self.signature, payload):#06x}")
        return payload


# ------------------------------------------------------------ J1939, from the standard

def j1939_id(priority, pf, ps, source):
    return priority << 26 | pf << 16 | ps << 8 | source


def j1939_pgn(ident):
    pf, ps = (ident >> 16) & 0xFF, (ident >> 8) & 0xFF
    return (ident >> 8) & 0x3FF00 if pf < 240 else (ident >> 8) & 0x3FFFF, pf, ps


def decode_name(name):
    return {"identity_number": name & 0x1FFFFF, "manufacturer_code": (name >> 21) & 0x7FF,
            "ecu_instance": (name >> 32) & 7, "function_instance": (name >> 35) & 0x1F,
            "function": (name >> 40) & 0xFF, "vehicle_system": (name >> 49) & 0x7F,
            "vehicle_system_instance": (name >> 56) & 0xF, "industry_group": (name >> 60) & 7,
            "arbitrary_address_capable": name >> 63}


# ------------------------------------------------------------ the bus

class Bus:
    def __init__(self, interface="vcan0"):
        self.s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
        # Kernel filters: the node's NodeStatus and service responses to us,
        # and what the J1939 node sends to global or to us.
        filters = [
            (EFF | NODE_STATUS_ID << 8 | NODE_ID, EFF | 0xFFFF << 8 | 1 << 7 | 0x7F),
            (EFF | 1 << 7 | PEER_NODE_ID << 8 | NODE_ID, EFF | 1 << 15 | 0x7F << 8 | 1 << 7 | 0x7F),
            (EFF | J1939_SA, EFF | 0xFF),
            (EFF | 0xFE << 8, EFF | 0xFF),  # Cannot Claim (source 254)
        ]
        self.s.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER,
                          b"".join(struct.pack("=II", i, m) for i, m in filters))
        self.s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.s.bind((interface,))
        self.log = []  # (monotonic, direction, id, data hex)
        self.t0 = time.monotonic()

    def send(self, ident, data):
        self.s.send(FRAME.pack(ident | EFF, len(data), bytes(data).ljust(8, b"\0")))
        self.log.append((round(time.monotonic() - self.t0, 3), "tx", f"{ident:08X}", bytes(data).hex()))

    def recv(self, timeout):
        r, _, _ = select.select([self.s], [], [], timeout)
        if not r:
            return None
        raw = self.s.recv(16)
        ident, length, data = FRAME.unpack(raw)
        if not ident & EFF:
            return None
        self.log.append((round(time.monotonic() - self.t0, 3), "rx", f"{ident & EFF_MASK:08X}", data[:length].hex()))
        return ident & EFF_MASK, data[:length]


class Peer:
    """The driver side's state machine, fed one frame at a time."""

    def __init__(self, bus):
        self.bus = bus
        self.tid = 0
        self.pending = None  # (label, ServiceReassembler)
        self.node_infos = []  # (label, decoded reply, reassembly errors)
        self.statuses = []  # decoded NodeStatus, in order
        self.phase = "first"  # first -> warning -> recovered_warning -> restart -> recovered_restart
        self.recoveries = []  # (label, the NodeStatus after the reply)
        self.j1939_started = False
        self.claims = []  # (destination asked, id, NAME)
        self.bam = None
        self.component_id = None
        self.component_packets = 0
        self.j1939_errors = []
        self.console = []

    def say(self, line):
        self.console.append(line)
        print(f"can_device_peer: {line}", flush=True)

    def ask_node_info(self, label):
        frame_id = service_id(30, GET_NODE_INFO, True, NODE_ID, PEER_NODE_ID)
        self.pending = (label, ServiceReassembler(GET_NODE_INFO, GET_NODE_INFO_SIGNATURE, self.tid))
        self.bus.send(frame_id, [0xC0 | self.tid])  # empty request: one frame, just the tail byte
        self.say(f"GetNodeInfo ({label}) -> node {NODE_ID}: id {frame_id:08X} data {0xC0 | self.tid:02X}")
        self.tid = (self.tid + 1) % 32

    def on_frame(self, ident, data):
        if ident & 0x7F == NODE_ID and not ident & 0x80 and (ident >> 8) & 0xFFFF == NODE_STATUS_ID and len(data) == 8:
            self.on_node_status(node_status(data[:7]))
        elif ident & 0x80 and ident & 0x7F == NODE_ID:
            self.on_service_frame(ident, data)
        elif ident & 0xFF in (J1939_SA, 0xFE):
            self.on_j1939(ident, data)

    def on_node_status(self, s):
        self.statuses.append(s)
        text = f"NodeStatus uptime {s['uptime_sec']} s, health {HEALTH[s['health']]}, mode {MODE[s['mode']]}"
        if self.pending is not None:
            return
        if self.phase == "first":
            self.say(text)
            self.ask_node_info("node first seen")
            self.phase = "warning"
        elif self.phase == "warning" and s["health"] != 0:
            self.say(text + "  <- unhealthy: the allocation server asks GetNodeInfo")
            self.ask_node_info("after WARNING")
            self.phase = "recovered_warning"
        elif self.phase == "recovered_warning" and self.node_infos and self.node_infos[-1][0] == "after WARNING":
            self.say(text)
            self.recoveries.append(("after WARNING", s))
            if s["health"] == 0 and s["mode"] == 0:
                self.phase = "restart"
        elif self.phase == "restart" and s["mode"] == 1:
            self.say(text + "  <- restarted: GetNodeInfo again")
            self.ask_node_info("after INITIALIZATION (restart)")
            self.phase = "recovered_restart"
        elif self.phase == "recovered_restart" and self.node_infos[-1][0].startswith("after INITIALIZATION"):
            self.say(text)
            self.recoveries.append(("after INITIALIZATION (restart)", s))
            if s["health"] == 0 and s["mode"] == 0:
                self.phase = "done"

    def on_service_frame(self, ident, data):
        if self.pending is None or not self.pending[1].matches(ident):
            return
        label, r = self.pending
        payload = r.feed(data)
        if payload is None:
            return
        info = decode_get_node_info(payload)
        self.node_infos.append((label, info, list(r.errors), r.frames))
        self.pending = None
        st = info["status"]
        self.say(f"GetNodeInfo reply ({label}): {r.frames} frames, transfer CRC "
                 f"{'ok' if not r.errors else r.errors}; status uptime {st['uptime_sec']} s "
                 f"{HEALTH[st['health']]} {MODE[st['mode']]}; name '{info['name']}', software "
                 f"{info['software_version']['major']}.{info['software_version']['minor']} "
                 f"vcs {info['software_version']['vcs_commit']:#010x} (flags {info['software_version']['optional_field_flags']}), "
                 f"hardware {info['hardware_version']['major']}.{info['hardware_version']['minor']}, "
                 f"unique id {info['hardware_version']['unique_id']}")

    def start_j1939(self):
        self.j1939_started = True
        for destination in (J1939_SA, 0xFF):
            ident = j1939_id(6, 0xEA, destination, J1939_PEER_SA)
            data = PGN_ADDRESS_CLAIMED.to_bytes(3, "little")
            self.bus.send(ident, data)
            self.say(f"J1939 Request for Address Claimed to {destination:#04x}: id {ident:08X} data {data.hex()}")
        ident = j1939_id(6, 0xEA, J1939_SA, J1939_PEER_SA)
        data = PGN_COMPONENT_ID.to_bytes(3, "little")
        self.bus.send(ident, data)
        self.say(f"J1939 Request for Component Identification to {J1939_SA:#04x}: id {ident:08X} data {data.hex()}")

    def on_j1939(self, ident, data):
        pgn, pf, ps = j1939_pgn(ident)
        if not self.j1939_started:
            if ident & 0xFF == J1939_SA:
                self.start_j1939()
            return
        if pgn == PGN_ADDRESS_CLAIMED:
            name = int.from_bytes(data, "little")
            self.claims.append((ps, ident, name))
            self.say(f"Address Claimed: id {ident:08X} (priority {ident >> 26}, to {ps:#04x}, from {ident & 0xFF:#04x}) "
                     f"NAME {name:016X} = {decode_name(name)}")
        elif pgn == PGN_TP_CM and data[0] == 32:
            self.bam = {"size": data[1] | data[2] << 8, "packets": data[3], "pgn": int.from_bytes(data[5:8], "little"),
                        "data": bytearray(), "next": 1, "id": ident}
            self.say(f"BAM announce: id {ident:08X} data {data.hex()} (PGN {self.bam['pgn']}, {self.bam['size']} bytes, "
                     f"{self.bam['packets']} packets)")
        elif pgn == PGN_TP_DT and self.bam is not None:
            if data[0] != self.bam["next"]:
                self.j1939_errors.append(f"TP.DT sequence {data[0]}, expected {self.bam['next']}")
            self.bam["next"] += 1
            self.bam["data"] += data[1:8]
            if data[0] == self.bam["packets"]:
                body = bytes(self.bam["data"][:self.bam["size"]])
                padding = bytes(self.bam["data"][self.bam["size"]:])
                if padding.strip(b"\xff"):
                    self.j1939_errors.append(f"TP.DT padding {padding.hex()} is not 0xFF")
                if self.bam["pgn"] == PGN_COMPONENT_ID:
                    self.component_id = body.decode("ascii", errors="replace")
                    self.component_packets = self.bam["packets"]
                    self.say(f"Component Identification (BAM reassembled): '{self.component_id}'")
                self.bam = None
        elif pgn == PGN_COMPONENT_ID:
            self.component_id = bytes(data).decode("ascii", errors="replace")


def run(imuemud, out):
    """Runs imuemud and the peer; returns the list of failures."""
    failures = []
    scene_path = os.path.join(out, "candevice.toml")
    with open(scene_path, "w") as f:
        f.write(scene())
    stats_path = os.path.join(out, "candevice.stats.json")
    bus = Bus()
    peer = Peer(bus)
    t0 = time.monotonic()
    # Not in `out`: $HIL_OUT is a 9p share under the qemu backend, where a
    # unix socket cannot be created.
    sock_dir = tempfile.mkdtemp(prefix="hil_candevice.")
    daemon = subprocess.Popen([imuemud, "--scene", scene_path, "--control-socket", os.path.join(sock_dir, "c.sock"),
                               "--late-ticks", "send", "--stats-json", stats_path],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = t0 + 150  # a hang guard only: the scene lasts DURATION_S of (emulated) time
    while daemon.poll() is None and time.monotonic() < deadline:
        frame = bus.recv(0.1)
        if frame is not None:
            peer.on_frame(*frame)
    # What is still queued on our socket.
    while (frame := bus.recv(0.2)) is not None:
        peer.on_frame(*frame)
    if daemon.poll() is None:
        daemon.kill()
        failures.append("imuemud did not end within 150 s")
    daemon_out = daemon.communicate()[0]
    with open(os.path.join(out, "candevice.imuemud.txt"), "w") as f:
        f.write(daemon_out)
    with open(os.path.join(out, "candevice.peer_frames.txt"), "w") as f:
        f.writelines(f"{t} {d} {i} {x}\n" for t, d, i, x in bus.log)
    if daemon.returncode != 0:
        failures.append(f"imuemud exited {daemon.returncode}: {daemon_out[-2000:]}")

    # DroneCAN: each reply decodes to the configured identity; the checks
    # after WARNING and INITIALIZATION recover.
    labels = [label for label, _, _, _ in peer.node_infos]
    want = ["node first seen", "after WARNING", "after INITIALIZATION (restart)"]
    if labels != want:
        failures.append(f"GetNodeInfo answered for {labels}, expected {want} (phase reached: {peer.phase}; "
                        f"NodeStatus seen: {[(s['uptime_sec'], HEALTH[s['health']], MODE[s['mode']]) for s in peer.statuses]})")
    for label, info, errors, frames in peer.node_infos:
        sw, hw = info["software_version"], info["hardware_version"]
        got = (info["name"], (sw["major"], sw["minor"]), sw["optional_field_flags"] & 1, sw["vcs_commit"],
               (hw["major"], hw["minor"]), hw["unique_id"], hw["certificate_bytes"])
        expected = (NODE_NAME, SOFTWARE, 1, VCS_COMMIT, HARDWARE, UNIQUE_ID.hex(), 0)
        if got != expected:
            failures.append(f"GetNodeInfo ({label}) decodes to {got}, configured {expected}")
        if errors:
            failures.append(f"GetNodeInfo ({label}) reassembly: {errors}")
        if frames < 2:
            failures.append(f"GetNodeInfo ({label}) in {frames} frame(s): the reply is over 7 bytes, multi-frame")
    if len(peer.node_infos) >= 2 and peer.node_infos[1][1]["status"]["health"] == 0 and \
            peer.node_infos[1][1]["status"]["mode"] == 0:
        # The node reports the NodeStatus it last sent; the request follows a
        # WARNING one, so OK here means a NodeStatus went out in between
        # (a peer slower than the 1-s period): then recovery is shown below.
        print("can_device_peer: note: the reply after WARNING already reports OK")
    if len(peer.node_infos) >= 3 and peer.node_infos[2][1]["status"]["uptime_sec"] > 1:
        failures.append(f"GetNodeInfo after the restart reports uptime {peer.node_infos[2][1]['status']['uptime_sec']} s")
    for label in want[1:]:
        after = [s for lab, s in peer.recoveries if lab == label]
        if not any(s["health"] == 0 and s["mode"] == 0 for s in after):
            failures.append(f"no NodeStatus OK/OPERATIONAL after the GetNodeInfo {label}: {after}")
    warnings = [s for s in peer.statuses if s["health"] == 1]
    inits = [s for s in peer.statuses if s["mode"] == 1]
    if not warnings:
        failures.append("the saturation fault produced no WARNING NodeStatus")
    if not inits or inits[0]["uptime_sec"] != 0:
        failures.append(f"the restart fault produced no INITIALIZATION NodeStatus with uptime 0: {inits}")

    # J1939: the claim from the configured address, to both requests.
    if len(peer.claims) < 2:
        failures.append(f"{len(peer.claims)} Address Claimed frames for 2 requests")
    for ps, ident, name in peer.claims:
        if ident != j1939_id(6, 0xEE, 0xFF, J1939_SA) or name == 0:
            failures.append(f"Address Claimed id {ident:08X} NAME {name:016X}: expected {j1939_id(6, 0xEE, 0xFF, J1939_SA):08X} "
                            f"(priority 6, to global, from {J1939_SA:#04x}) and a NAME")
    if len({name for _, _, name in peer.claims}) > 1:
        failures.append("the claims carry different NAMEs")
    want_component = "*".join(J1939_COMPONENT) + "*"
    if peer.component_id != want_component:
        failures.append(f"Component Identification '{peer.component_id}', configured '{want_component}'")
    failures += [f"J1939: {e}" for e in peer.j1939_errors]

    # The devices' own counters (imuemud's stats JSON: the transport's reply
    # frames; its "commands" block is not in imuemud's final stats): every
    # reply frame it sent reached the peer, and none besides.
    try:
        with open(stats_path) as f:
            devices = {d["name"]: d for d in json.load(f)["devices"]}
        sent = {name: d["transport"].get("replies_sent") for name, d in devices.items()}
        got = {"dronecan0": sum(frames for _, _, _, frames in peer.node_infos),
               "j1939_0": len(peer.claims) + (1 + peer.component_packets if peer.component_id is not None else 0)}
        print(f"can_device_peer: reply frames sent by imuemud {sent}, received by the peer {got}")
        if sent != got:
            failures.append(f"imuemud sent {sent} reply frames, the peer received {got}")
    except (OSError, ValueError, KeyError) as e:
        failures.append(f"imuemud's stats: {e}")
    summary = {"node_infos": [{"label": label, **info} for label, info, _, _ in peer.node_infos],
               "node_statuses": peer.statuses, "recoveries": peer.recoveries,
               "claims": [{"to": ps, "id": f"{i:08X}", "name": f"{n:016X}", "fields": decode_name(n)}
                          for ps, i, n in peer.claims],
               "component_id": peer.component_id, "wall_s": round(time.monotonic() - t0, 1)}
    with open(os.path.join(out, "candevice.summary.json"), "w") as f:
        json.dump(summary, f, indent=1)
    for failure in failures:
        print("FAIL:", failure)
    print(f"CAN devices answer their drivers on vcan0: {'FAILED' if failures else 'passed'} "
          f"({summary['wall_s']} s)", flush=True)
    return failures


if __name__ == "__main__":
    sys.exit(1 if run(sys.argv[1], sys.argv[2]) else 0)
