"""What every loopback run checks of a decoded capture, in one place.

Used by pty_loopback.py (imuemu emit -> pty -> imuemu listen) and
daemon_scenes.py (imuemud on the example scenes): the listener's error
counters, the received samples against the batch pipeline's grid (consecutive
ticks, exact sample rate, arrival rate within 1 %), and the values within the
protocol's resolution.
"""
import csv
import os
import time

FLOAT32_REL = 2.0 ** -24  # round-to-nearest float32: half an ulp, relative
IMU_COLUMNS = ["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s", "accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"]
# native: doubles end to end; MAVLink 2: one float32 rounding; MIP sends accel
# in g (float32 of a/g, then x g back): at most 1.5 float32 roundings.
ALLOWED_RELATIVE = {"native": 0.0, "mavlink2": FLOAT32_REL * 1.0001, "mip": 3.0 * FLOAT32_REL,
                    "xsens": FLOAT32_REL * 1.0001, "vectornav": FLOAT32_REL * 1.0001, "sbg": FLOAT32_REL * 1.0001}


def memory_dir():
    """A tmpfs for the work files: the readers write a CSV per sample, and on a
    disk under write-back pressure (a build in parallel) write() can block for
    seconds in dirty-page throttling, long enough to overflow the pty queue."""
    return "/dev/shm" if os.access("/dev/shm", os.W_OK) else None


def read_reference(path):
    """imuemu generate's IMU CSV -> (header, {t_ns: (gyro xyz, accel xyz)})."""
    ref = {}
    with open(path) as f:
        rows = csv.reader(line for line in f if not line.startswith("#"))
        header = next(rows)
        for r in rows:
            ref[int(r[0])] = tuple(float(x) for x in r[1:7])
    return header, ref


def read_listened(path):
    """imuemu listen --out CSV -> list of dict rows."""
    with open(path) as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def compare_with_reference(label, protocol, rate, rows, ref, summary, counted_skips=0):
    """(failures, figures) for a capture `rows` with listen's JSON `summary`
    against the batch reference `ref` ({t_ns: values}) at `rate` Hz.
    `counted_skips`: ticks the sender itself counted as not sent (a live
    scene's producer underruns on a slow host); the capture may miss that many
    ticks, as sequence gaps, and no more."""
    failures = []
    for key in ("checksum_errors", "resync_bytes", "other_errors"):
        if summary.get(key, 0) not in (None, 0):
            failures.append(f"{label}: listen {key} = {summary[key]}")
    for key in ("sequence_gaps", "own_sequence_gaps"):
        if (summary.get(key) or 0) > counted_skips:
            failures.append(f"{label}: listen {key} = {summary[key]}, the sender counted {counted_skips} ticks not sent")
    if len(rows) != summary["samples"]:
        failures.append(f"{label}: CSV has {len(rows)} rows, listen's summary says {summary['samples']}")
    grid = sorted(ref)
    index = {t: i for i, t in enumerate(grid)}
    matched = []
    for r in rows:
        t = int(r["t_ns"])
        k = index.get(t)
        if k is None:  # a protocol whose time field is coarser than 1 ns (MAVLink: us): nearest tick within 1 us
            lo = matched[-1] if matched else 0
            j = min(range(lo, min(len(grid), lo + 4 * rate + 10)), key=lambda i: abs(grid[i] - t), default=None)
            k = j if j is not None and abs(grid[j] - t) <= 1000 else None
        if k is None:
            failures.append(f"{label}: decoded time {t} is not on the {rate} Hz grid of the batch reference")
            return failures, {}
        matched.append(k)
    if not matched:
        failures.append(f"{label}: nothing received")
        return failures, {}
    missing = matched[-1] - matched[0] + 1 - len(matched)
    if any(b <= a for a, b in zip(matched, matched[1:])):
        failures.append(f"{label}: received ticks go backwards or repeat")
    elif missing > counted_skips:
        failures.append(f"{label}: {missing} ticks missing between the first and last received, "
                        f"the sender counted {counted_skips} not sent")
    # Every tick is on the batch grid (matched above); with no tick missing,
    # listen's own sample-time rate must be the rate itself.
    if missing == 0 and abs(summary["rate_from_sample_time_hz"] - rate) > 1e-6 * rate:
        failures.append(f"{label}: sample-time rate {summary['rate_from_sample_time_hz']} != {rate}")
    if abs(summary["rate_from_arrival_hz"] - rate) > 0.01 * rate:
        failures.append(f"{label}: arrival rate {summary['rate_from_arrival_hz']} not within 1% of {rate}")
    worst_rel = 0.0
    worst_abs = 0.0
    for r, k in zip(rows, matched):
        want = ref[grid[k]]
        for i, n in enumerate(IMU_COLUMNS):
            d = abs(float(r[n]) - want[i])
            worst_abs = max(worst_abs, d)
            worst_rel = max(worst_rel, d / max(abs(want[i]), 1e-30))
    allowed = ALLOWED_RELATIVE[protocol]
    if worst_rel > allowed:
        failures.append(f"{label}: worst relative difference {worst_rel:.3e} > {allowed:.3e}")
    figures = {"received": len(rows), "first_tick": matched[0], "last_tick": matched[-1],
               "worst_relative_difference": worst_rel,
               "worst_absolute_difference": worst_abs, "allowed_relative": allowed,
               "checksum_errors": summary["checksum_errors"], "sequence_gaps": summary["sequence_gaps"],
               "rate_sample_time_hz": summary["rate_from_sample_time_hz"],
               "rate_arrival_hz": round(summary["rate_from_arrival_hz"], 3),
               "arrival_jitter_p99_us": summary["arrival_jitter_us"]["p99"]}
    return failures, figures


def _crc32c_table():
    table = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        table.append(c)
    return table


CRC_TABLE = _crc32c_table()


def crc32c(data):
    """CRC-32C (docs/native-protocol.md §2; also of the pose datagrams, docs/pose-wire-format.md)."""
    crc = 0xFFFFFFFF
    for b in data:
        crc = CRC_TABLE[(crc ^ b) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def wait_for_link(proc, link, what, timeout_s=20):
    """Waits until `proc` (imuemu emit or imuemud) publishes its pty link;
    raises RuntimeError naming `what` and the process's stderr if it exits or
    the timeout passes first."""
    deadline = time.monotonic() + timeout_s
    while not os.path.islink(link):
        if proc.poll() is not None or time.monotonic() > deadline:
            _, err = proc.communicate()
            raise RuntimeError(f"{what}: never published {link} (rc {proc.returncode}):\n{err}")
        time.sleep(0.01)
