#!/usr/bin/env python3
"""Independent reference for the golden bytes in tests/drivers/test_protocols_stream.cpp.

Written from the specifications alone (no project code, no protocol library):
bit-by-bit CRCs from their Rocksoft parameters, the MAVLink CRC_EXTRA algorithm
as the MAVLink guide states it, the MIP Fletcher checksum as the 3DM-GX5 DCP
manual section 6.4 states it. Run it to re-derive every constant the C++ test
hard-codes:

    python3 tests/support/protocol_reference.py

and, as a reference receiver of a captured stream (counters as JSON; used by
tests/drivers/test_link_faults.cpp to check link faults):

    python3 tests/support/protocol_reference.py decode native|mavlink2|mip FILE
"""
import struct


def crc16_mcrf4xx(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/MCRF4XX (MAVLink's "X.25" CRC): poly 0x1021 reflected (0x8408),
    init 0xFFFF, reflected in/out, no final xor."""
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


def crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli): poly 0x1EDC6F41 reflected (0x82F63B78), init and
    final xor 0xFFFFFFFF."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x82F63B78 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


def mip_fletcher(data: bytes) -> int:
    """MIP checksum (3DM-GX5 DCP manual 6.4): two running 8-bit sums over every
    byte from SYNC1 to the end of the payload; byte1 is sent first (MSB)."""
    b1 = b2 = 0
    for byte in data:
        b1 = (b1 + byte) & 0xFF
        b2 = (b2 + b1) & 0xFF
    return (b1 << 8) | b2


def crc_extra(name: str, wire_fields) -> int:
    """MAVLink guide, "CRC_EXTRA Calculation": X.25 CRC over the message name
    and each non-extension field's type and name (wire order, each followed by
    a space; an array field's base type, then its length as one byte), folded
    to 8 bits. A field is (type, name) or (type, name, array_length)."""
    crc = crc16_mcrf4xx((name + " ").encode())
    for field in wire_fields:
        ftype, fname = field[0], field[1]
        crc = crc16_mcrf4xx((ftype + " ").encode(), crc)
        crc = crc16_mcrf4xx((fname + " ").encode(), crc)
        if len(field) > 2:
            crc = crc16_mcrf4xx(bytes([field[2]]), crc)
    return (crc & 0xFF) ^ (crc >> 8)


_TYPE_BYTES = {"uint64_t": 8, "int64_t": 8, "double": 8, "uint32_t": 4, "int32_t": 4, "float": 4,
               "uint16_t": 2, "int16_t": 2, "uint8_t": 1, "int8_t": 1, "char": 1}


def wire_order(xml_fields):
    """MAVLink guide, "Field Reordering": stable sort by the base type's size,
    largest first (arrays sort by their element type)."""
    return sorted(xml_fields, key=lambda f: -_TYPE_BYTES[f[0]])


# Wire order = common.xml order stably sorted by type size, extensions last and
# outside CRC_EXTRA (MAVLink guide, "Field Reordering").
HEARTBEAT = [("uint32_t", "custom_mode"), ("uint8_t", "type"), ("uint8_t", "autopilot"),
             ("uint8_t", "base_mode"), ("uint8_t", "system_status"),
             ("uint8_t", "mavlink_version")]
_IMU_FLOATS = ["xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag",
               "abs_pressure", "diff_pressure", "pressure_alt", "temperature"]
HIGHRES_IMU = [("uint64_t", "time_usec")] + [("float", f) for f in _IMU_FLOATS] + \
              [("uint16_t", "fields_updated")]
HIL_SENSOR = [("uint64_t", "time_usec")] + [("float", f) for f in _IMU_FLOATS] + \
             [("uint32_t", "fields_updated")]


# common.xml HIL_STATE_QUATERNION (#115), fields in XML order.
HIL_STATE_QUATERNION_XML = [("uint64_t", "time_usec"), ("float", "attitude_quaternion", 4),
                            ("float", "rollspeed"), ("float", "pitchspeed"), ("float", "yawspeed"),
                            ("int32_t", "lat"), ("int32_t", "lon"), ("int32_t", "alt"),
                            ("int16_t", "vx"), ("int16_t", "vy"), ("int16_t", "vz"),
                            ("uint16_t", "ind_airspeed"), ("uint16_t", "true_airspeed"),
                            ("int16_t", "xacc"), ("int16_t", "yacc"), ("int16_t", "zacc")]
HIL_STATE_QUATERNION = wire_order(HIL_STATE_QUATERNION_XML)


def mavlink2_frame(seq, sysid, compid, msgid, payload: bytes, extra: int) -> bytes:
    """MAVLink 2 packet (MAVLink guide, "MAVLink 2 Packet Format"), payload
    truncated of trailing zeros but never below one byte."""
    trimmed = payload.rstrip(b"\x00") or payload[:1]
    header = bytes([0xFD, len(trimmed), 0, 0, seq, sysid, compid,
                    msgid & 0xFF, (msgid >> 8) & 0xFF, (msgid >> 16) & 0xFF])
    crc = crc16_mcrf4xx(header[1:] + trimmed + bytes([extra]))
    return header + trimmed + struct.pack("<H", crc)


def hexs(b: bytes) -> str:
    return " ".join(f"{x:02X}" for x in b)


# ---------------------------------------------------------------- receiving
#
# A reference receiver for the three byte-stream protocols, to check what
# link faults (docs/faults.md) put on the wire. The resynchronisation rule is
# the one docs/native-protocol.md section 6 states (search the start-of-frame
# pattern, count skipped bytes; a rejected candidate gives up only its first
# byte), applied to all three; the frame checks are each protocol's own:
#  native  (docs/native-protocol.md 1, 2, 6): version 1, no reserved flag,
#          payload_length 68 or 116 else malformed; CRC-32C; sequence gaps
#          modulo 2^64, a step back re-bases without counting;
#  mavlink2 (guide "Packet Serialization"): magic 0xFD, incompat_flags 0 or
#          SIGNED, a message whose CRC_EXTRA is known (derived above) else
#          malformed, X.25 CRC over bytes 1.. plus CRC_EXTRA; seq gaps modulo
#          256 per (sysid, compid), a repeated seq is no gap;
#  mip     (3DM-GX5 DCP 6.3, 6.4): 0x75 0x65, descriptor set, payload length,
#          Fletcher checksum; no counter.
# A sample is a native frame, a MAVLink HIL_SENSOR (or `sample_msgid`), a
# MIP packet of set 0x80 with a scaled accel or gyro field.

_MAVLINK_EXTRA = {0: crc_extra("HEARTBEAT", HEARTBEAT), 105: crc_extra("HIGHRES_IMU", HIGHRES_IMU),
                  107: crc_extra("HIL_SENSOR", HIL_SENSOR)}


def _judge_native(c, state):
    if len(c) < 6:
        return "more", 0
    length = c[4] | c[5] << 8
    if c[2] != 1 or (c[3] & ~1) != 0 or length != (116 if c[3] & 1 else 68):
        return "malformed", 0
    total = 6 + length + 4
    if len(c) < total:
        return "more", 0
    if crc32c(bytes(c[:6 + length])) != struct.unpack_from("<I", c, 6 + length)[0]:
        return "checksum", 0
    seq, t_ns = struct.unpack_from("<Qq", c, 6)
    last = state.get("last")
    if last is not None:
        step = (seq - last) % (1 << 64)
        if 1 <= step < (1 << 63):
            state["counters"]["sequence_gaps"] += step - 1
    state["last"] = seq
    state["samples"].append({"sequence": seq, "t_ns": t_ns})
    return "accepted", total


def _judge_mavlink(c, state):
    if len(c) < 10:
        return "more", 0
    incompat = c[2]
    msgid = c[7] | c[8] << 8 | c[9] << 16
    if incompat & ~1 or msgid not in _MAVLINK_EXTRA:
        return "malformed", 0
    total = 10 + c[1] + 2 + (13 if incompat & 1 else 0)
    if len(c) < total:
        return "more", 0
    if crc16_mcrf4xx(bytes(c[1:10 + c[1]]) + bytes([_MAVLINK_EXTRA[msgid]])) != \
            struct.unpack_from("<H", c, 10 + c[1])[0]:
        return "checksum", 0
    key = (c[5], c[6])
    last = state.setdefault("last", {}).get(key)
    if last is not None:
        step = (c[4] - last) % 256
        if step:
            state["counters"]["sequence_gaps"] += step - 1
    state["last"][key] = c[4]
    if msgid == state.get("sample_msgid", 107):
        payload = bytes(c[10:10 + c[1]]) + bytes(64)  # zero-extend a truncated payload
        state["samples"].append({"sequence": c[4], "t_ns": struct.unpack_from("<Q", payload, 0)[0] * 1000})
    return "accepted", total


def _judge_mip(c, state):
    if len(c) < 4:
        return "more", 0
    total = 4 + c[3] + 2
    if len(c) < total:
        return "more", 0
    if mip_fletcher(bytes(c[:4 + c[3]])) != struct.unpack_from(">H", c, 4 + c[3])[0]:
        return "checksum", 0
    if c[2] == 0x80:
        at, fields = 4, set()
        while at + 1 < 4 + c[3] and c[at] >= 2:
            fields.add(c[at + 1])
            at += c[at]
        if fields & {0x04, 0x05}:
            state["samples"].append({"sequence": None, "t_ns": None})
    return "accepted", total


_RECEIVERS = {"native": (b"\xA5\x5A", _judge_native), "mavlink2": (b"\xFD", _judge_mavlink),
              "mip": (b"\x75\x65", _judge_mip)}


def reference_decode(protocol: str, data: bytes, sample_msgid: int = 107):
    """Counters (frames, samples, checksum_errors, resync_bytes,
    sequence_gaps, other_errors) and the accepted samples of a whole stream;
    bytes of an incomplete frame at the end are left out of every count."""
    sync, judge = _RECEIVERS[protocol]
    counters = dict(frames=0, samples=0, checksum_errors=0, resync_bytes=0, sequence_gaps=0, other_errors=0)
    state = {"counters": counters, "samples": [], "sample_msgid": sample_msgid}
    pos, n = 0, len(data)
    while pos < n:
        start = pos
        while start < n and not sync.startswith(data[start:start + len(sync)]):
            start += 1
        counters["resync_bytes"] += start - pos
        pos = start
        if pos >= n:
            break
        verdict, length = judge(memoryview(data)[pos:], state)
        if verdict == "more":
            break
        if verdict == "accepted":
            counters["frames"] += 1
            pos += length
            continue
        counters["checksum_errors" if verdict == "checksum" else "other_errors"] += 1
        counters["resync_bytes"] += 1
        pos += 1
    counters["samples"] = len(state["samples"])
    return counters, state["samples"]


if __name__ == "__main__" and len(__import__("sys").argv) > 1:
    # protocol_reference.py decode PROTOCOL FILE [SAMPLE_MSGID]: the receiver
    # above over a captured stream, as JSON.
    import json
    import sys
    if len(sys.argv) < 4 or sys.argv[1] != "decode":
        sys.exit("usage: protocol_reference.py [decode native|mavlink2|mip FILE [SAMPLE_MSGID]]")
    with open(sys.argv[3], "rb") as f:
        counters, samples = reference_decode(sys.argv[2], f.read(), int(sys.argv[4]) if len(sys.argv) > 4 else 107)
    print(json.dumps({"counters": counters, "samples": samples}))
    sys.exit(0)

if __name__ == "__main__":
    print(f"CRC-16/MCRF4XX('123456789') = 0x{crc16_mcrf4xx(b'123456789'):04X}")
    print(f"CRC-32C('123456789')        = 0x{crc32c(b'123456789'):08X}")
    for name, fields in (("HEARTBEAT", HEARTBEAT), ("HIGHRES_IMU", HIGHRES_IMU),
                         ("HIL_SENSOR", HIL_SENSOR), ("HIL_STATE_QUATERNION", HIL_STATE_QUATERNION)):
        print(f"CRC_EXTRA {name} = {crc_extra(name, fields)}")

    # HIL_STATE_QUATERNION (wire order above): time_usec 1700000000123456,
    # q = (cos 15 deg, 0, 0, sin 15 deg) as floats (heading 30 deg), body
    # rates (0.01, -0.02, 0.5) rad/s, lat 41.5 deg, lon 2.25 deg, alt 120.5 m,
    # v (1000, -250, 50) cm/s, airspeeds 1020 and 1030 cm/s, acc (10, -20,
    # -1000) mG; seq 9, sys 1, comp 1.
    import math
    c, s15 = math.cos(math.radians(15)), math.sin(math.radians(15))
    hsq = struct.pack("<Q4f3f3i3h2H3h", 1700000000123456, c, 0.0, 0.0, s15, 0.01, -0.02, 0.5,
                      415000000, 22500000, 120500, 1000, -250, 50, 1020, 1030, 10, -20, -1000)
    assert len(hsq) == 64
    extra = crc_extra("HIL_STATE_QUATERNION", HIL_STATE_QUATERNION)
    print("HIL_STATE_QUATERNION seq 9 sys 1 comp 1:", hexs(mavlink2_frame(9, 1, 1, 115, hsq, extra)))

    # Pose datagram v2 (docs/pose-wire-format.md §2.5): sequence 7, time 2.5 s,
    # local NED (10, -3.5, 0.25) m, identity quaternion, rates mask 0x03:
    # velocity (1.5, -0.5, 0.25) m/s, angular rate (0.1, 0, -0.2) rad/s,
    # acceleration absent (zeros).
    body = b"IMUP" + bytes([2, 2, 1, 0x03]) + struct.pack("<Qq3d4d", 7, 2_500_000_000, 10.0, -3.5, 0.25,
                                                         1.0, 0.0, 0.0, 0.0) + \
        struct.pack("<9d", 1.5, -0.5, 0.25, 0.1, 0.0, -0.2, 0.0, 0.0, 0.0)
    assert len(body) == 152
    print("pose datagram v2:", hexs(body + struct.pack("<I", crc32c(body))))

    # MIP published examples (CV7 online manual, "MIP Packet Overview" and "Data
    # Overview"): the checksums the manual prints are 0x84EE and 0xE0C6.
    vec = bytes.fromhex("3E7A63A0BB8E3B297FE5BF7F")
    one = bytes.fromhex("7565800E0E04") + vec
    two = bytes.fromhex("7565801C0E05") + vec + bytes.fromhex("0E06") + vec
    print(f"MIP example 1 checksum = 0x{mip_fletcher(one):04X}")
    print(f"MIP example 2 checksum = 0x{mip_fletcher(two):04X}")

    # HEARTBEAT from an IMU component: sys 1, comp 200 (MAV_COMP_ID_IMU), seq 0,
    # type MAV_TYPE_IMU 40 (minimal.xml: components report their own type),
    # autopilot MAV_AUTOPILOT_INVALID 8 (not a flight controller), base_mode 0,
    # custom_mode 0, system_status MAV_STATE_ACTIVE 4, mavlink_version 3.
    hb = struct.pack("<IBBBBB", 0, 40, 8, 0, 4, 3)
    print("HEARTBEAT seq 0 sys 1 comp 200:", hexs(mavlink2_frame(0, 1, 200, 0, hb, 50)))

    # HIL_SENSOR: time_usec 1234567, acc (0.5, -0.25, -9.75) m/s^2,
    # gyro (0.125, -0.0625, 0) rad/s, fields_updated 0x3F, id 0 -> truncated.
    hs = struct.pack("<Q13fIB", 1234567, 0.5, -0.25, -9.75, 0.125, -0.0625, 0.0,
                     0, 0, 0, 0, 0, 0, 0, 0x3F, 0)
    print("HIL_SENSOR seq 7 sys 1 comp 200:", hexs(mavlink2_frame(7, 1, 200, 107, hs, 108)))

    # MIP 0x80 packet: accel (0.5, -0.25, -1) g, gyro (0.125, -0.0625, 0) rad/s,
    # GPS timestamp tow 345600.25 s week 2300 flags 0x1C.
    fields = struct.pack(">BB3f", 14, 0x04, 0.5, -0.25, -1.0) + \
        struct.pack(">BB3f", 14, 0x05, 0.125, -0.0625, 0.0) + \
        struct.pack(">BBdHH", 14, 0x12, 345600.25, 2300, 0x1C)
    pkt = bytes([0x75, 0x65, 0x80, len(fields)]) + fields
    print("MIP accel+gyro+gps:", hexs(pkt + struct.pack(">H", mip_fletcher(pkt))))

    # imuemu native v1 worked example (docs/native-protocol.md).
    payload = struct.pack("<QqI", 42, 1_500_000_000, 0b001) + \
        struct.pack("<6d", 0.01, -0.02, 0.5, 0.1, -0.2, -9.80665) + \
        struct.pack("<6d", 1e-4, -2e-4, 5e-3, 1e-3, -2e-3, -0.0980665)
    header = bytes([0xA5, 0x5A, 1, 0x01]) + struct.pack("<H", len(payload))
    frame = header + payload
    frame += struct.pack("<I", crc32c(frame))
    print(f"native example ({len(frame)} bytes):", hexs(frame))

    # MIP GPS timestamp field (0x80, 0x12) of a trajectory on a UTC time base:
    # 2024-01-01T00:00:00Z is GPS time 2024-01-01T00:00:18 (GPS - UTC = 18 s
    # since 2017-01-01, IERS Bulletin C), counted from the GPS epoch
    # 1980-01-06, as week and time of week; valid flags initialized | tow |
    # week = 0x1C. Computed with datetime, not with the leap-second table.
    import datetime
    gps_epoch = datetime.datetime(1980, 1, 6, tzinfo=datetime.timezone.utc)
    utc = datetime.datetime(2024, 1, 1, tzinfo=datetime.timezone.utc)
    gps_s = (utc - gps_epoch).total_seconds() + 18
    week, tow = divmod(int(gps_s), 604800)
    field = struct.pack(">BBdHH", 14, 0x12, float(tow), week, 0x1C)
    print(f"MIP GPS timestamp of UTC 2024-01-01T00:00:00Z: week {week} tow {tow} s:", hexs(field))
    # Trajectory time on no known time base (the default): the internal
    # clock, e.g. t = 0, with the valid flags clear.
    print("MIP GPS timestamp, unknown time base, t = 0:", hexs(struct.pack(">BBdHH", 14, 0x12, 0.0, 0, 0)))
