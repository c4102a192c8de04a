"""Speed against error for every method (docs/accuracy_speed_vs_error.png).

usage: /usr/bin/python3 scripts/accuracy_plot.py accuracy.csv out.png

Rows 1-2: the aircraft-like flight (flat, ecef), interior RMS errors. Row 3
(issue 14): the 90 deg/s yaw's interior gyro RMS and the circle's all-samples
accel max (ends included). A method that refused a motion has no point there.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

rows = list(csv.DictReader(open(sys.argv[1])))
methods = sorted({r["method"] for r in rows}, key=lambda m: [r["method"] for r in rows].index(m))
panels = [
    [("flight", "flat", "gyro_rms_rad_s", "gyro RMS error, interior (rad/s)"),
     ("flight", "flat", "accel_rms_m_s2", "accel RMS error, interior (m/s²)")],
    [("flight", "ecef", "gyro_rms_rad_s", "gyro RMS error, interior (rad/s)"),
     ("flight", "ecef", "accel_rms_m_s2", "accel RMS error, interior (m/s²)")],
    [("fast-yaw", "flat", "gyro_rms_rad_s", "gyro RMS error, interior (rad/s)"),
     ("circle", "flat", "accel_max_all_m_s2", "accel max error, all samples (m/s²)")],
]
fig, axes = plt.subplots(3, 2, figsize=(12, 13))
markers = "os^vD<>ph*"
for row_i, panel_row in enumerate(panels):
    for col_i, (motion, scene, key, label) in enumerate(panel_row):
        ax = axes[row_i][col_i]
        for k, m in enumerate(methods):
            pts = [r for r in rows if r["method"] == m and r["motion"] == motion and r["scene"] == scene]
            if not pts:
                continue
            xs = [float(r["samples_per_cpu_s"]) for r in pts]
            ys = [max(float(r[key]), 1e-18) for r in pts]
            ax.loglog(xs, ys, marker=markers[k % len(markers)], color=f"C{k % 10}", linestyle="-", label=m)
            for r, x, y in zip(pts, xs, ys):
                ax.annotate(r["rate_hz"], (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_title(f"{motion} ({scene}): {label}", fontsize=10)
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("throughput (output samples per CPU second, one core)")
axes[0][0].legend(fontsize=8)
fig.suptitle("imuemu methods: speed vs error against analytic truth\n"
             "(knots at 1 Hz; labels = output rate in Hz; lower right is better)")
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=110)
print("wrote", sys.argv[2])
