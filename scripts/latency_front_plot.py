"""Latency budget against IMU error of the live methods (docs/latency_front.png).

usage: /usr/bin/python3 scripts/latency_front_plot.py docs/latency_front.csv docs/latency_front.png
(the CSV is build/release/bench/latency_front's output)
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

rows = list(csv.DictReader(open(sys.argv[1])))
fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
for ax, key, label in ((axes[0], "gyro_rms_rad_s", "gyro RMS error (rad/s)"),
                       (axes[1], "accel_rms_m_s2", "accelerometer RMS error (m/s²)")):
    for pose_hz, marker in (("100", "o"), ("250", "s"), ("1000", "^")):
        pts = [r for r in rows if r["pose_hz"] == pose_hz]
        xs = [float(r["budget_ms"]) for r in pts]
        ys = [max(float(r[key]), 1e-17) for r in pts]
        ax.loglog(xs, ys, marker=marker, label=f"{pose_hz} Hz poses")
        for r, x, y in zip(pts, xs, ys):
            tag = "S" if r["method"] == "smoothing" else ("C" if float(r["flagged_fraction"]) == 0 else "C*")
            ax.annotate(tag, (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("latency budget (ms)")
    ax.set_ylabel(label)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
fig.suptitle("Live methods at 1 kHz output, maneuvering flight, poses with rates: C causal Hermite, "
             "C* causal with every pose interval ending extrapolated, S smoothing (Eq. 3.68)", fontsize=9)
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=110)
