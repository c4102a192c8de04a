#!/usr/bin/env python3
"""Independent reference for the golden bytes in tests/test_protocols_stream.cpp.

Written from the specifications alone (no project code, no protocol library):
bit-by-bit CRCs from their Rocksoft parameters, the MAVLink CRC_EXTRA algorithm
as the MAVLink guide states it, the MIP Fletcher checksum as the 3DM-GX5 DCP
manual section 6.4 states it. Run it to re-derive every constant the C++ test
hard-codes:

    python3 tests/support/protocol_reference.py
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
    a space), folded to 8 bits."""
    crc = crc16_mcrf4xx((name + " ").encode())
    for ftype, fname in wire_fields:
        crc = crc16_mcrf4xx((ftype + " ").encode(), crc)
        crc = crc16_mcrf4xx((fname + " ").encode(), crc)
    return (crc & 0xFF) ^ (crc >> 8)


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


if __name__ == "__main__":
    print(f"CRC-16/MCRF4XX('123456789') = 0x{crc16_mcrf4xx(b'123456789'):04X}")
    print(f"CRC-32C('123456789')        = 0x{crc32c(b'123456789'):08X}")
    for name, fields in (("HEARTBEAT", HEARTBEAT), ("HIGHRES_IMU", HIGHRES_IMU),
                         ("HIL_SENSOR", HIL_SENSOR)):
        print(f"CRC_EXTRA {name} = {crc_extra(name, fields)}")

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
