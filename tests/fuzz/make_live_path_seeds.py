#!/usr/bin/python3
"""Writes the seed corpus of fuzz_live_path (tests/fuzz/corpus/live_path):
datagram sequences in that target's input format (fuzz_live_path.cpp), each
a plausible 50 Hz stream with one kind of fault: garbage, time jumps forward
and back, a sender restart, a 179 degree heading glitch, reordering.
Run once; the seeds are committed.   make_live_path_seeds.py [OUT_DIR]"""
import math
import os
import struct
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "loopback"))
from loopback_checks import crc32c  # noqa: E402

CRC_FLAG, MAGIC_FLAG, ECEF_FLAG, PAUSE_FLAG, OVERSAMPLE_FLAG, FINISH_FLAG = 1, 2, 4, 8, 16, 32


def datagram(seq, t_ns, pos, att, pos_kind=2, att_kind=0):
    body = b"IMUP" + bytes([1, pos_kind, att_kind, 0]) + struct.pack("<Qq3d4d", seq, t_ns, *pos, *att)
    return body + struct.pack("<I", crc32c(body))


def record(payload, advance_ms=20):
    code = 0x80 if len(payload) == 84 else len(payload)
    assert len(payload) == 84 or len(payload) < 128
    return bytes([code, advance_ms]) + payload


def flight(seq, t_ns):
    """A flat-scene circle at 10 m/s, 50 Hz knots (NED + heading/pitch/roll)."""
    s = t_ns * 1e-9
    a = 0.1 * s
    return datagram(seq, t_ns, (100 * math.sin(a), 100 * (1 - math.cos(a)), -50.0),
                    (math.degrees(a) % 360.0, 2.0, 5.0, 0.0))


def stream(n, t0_ns=0, seq0=0, step_ns=20_000_000):
    return [record(flight(seq0 + i, t0_ns + i * step_ns)) for i in range(n)]


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus", "live_path")
    os.makedirs(out, exist_ok=True)
    seeds = {}
    seeds["clean"] = bytes([0]) + b"".join(stream(40))
    seeds["clean_finish_oversampled"] = bytes([FINISH_FLAG | OVERSAMPLE_FLAG]) + b"".join(stream(20))
    g = stream(15)
    g[5:5] = [record(b"garbage!" * 3), record(b"\x00" * 84), record(b"IMUP\x01" + b"\xff" * 79), record(b"")]
    seeds["garbage"] = bytes([0]) + b"".join(g)
    seeds["jump_forward_back"] = bytes([0]) + b"".join(
        stream(10) + stream(3, t0_ns=3600 * 10**9, seq0=10) + stream(10, t0_ns=10 * 20_000_000, seq0=13))
    seeds["restart"] = bytes([FINISH_FLAG]) + b"".join(stream(20, t0_ns=50 * 10**9) + stream(20))
    glitch = stream(20)
    bad = bytearray(flight(10, 10 * 20_000_000 + 1))
    h = struct.unpack_from("<d", bad, 48)[0]
    struct.pack_into("<d", bad, 48, (h + 179.0) % 360.0)
    struct.pack_into("<I", bad, 80, crc32c(bytes(bad[:80])))
    glitch.insert(11, record(bytes(bad)))
    seeds["heading_glitch_179"] = bytes([0]) + b"".join(glitch)
    r = stream(20)
    r[8], r[9] = r[9], r[8]
    r.insert(12, r[12])
    seeds["reorder_duplicate_late"] = bytes([PAUSE_FLAG]) + b"".join(r[:14]) + bytes([0x80, 250]) + r[14][2:] + b"".join(r[15:])
    # Fields changed under a resealed CRC: the fuzzer mutates past the CRC.
    seeds["resealed_mutations"] = bytes([CRC_FLAG | MAGIC_FLAG]) + b"".join(stream(12))
    seeds["ecef_geodetic"] = bytes([ECEF_FLAG]) + b"".join(
        record(datagram(i, 1_700_000_000 * 10**9 + i * 20_000_000, (41.5, 2.1 + 1e-6 * i, 120.0), (90.0, 1.0, 0.0, 0.0), 0, 0))
        for i in range(30))
    for name, data in seeds.items():
        with open(os.path.join(out, name), "wb") as f:
            f.write(data)
    print(f"{len(seeds)} seeds in {out}")


if __name__ == "__main__":
    main()
