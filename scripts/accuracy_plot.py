"""Speed against error for every method (docs/accuracy_speed_vs_error.png).

usage: /usr/bin/python3 scripts/accuracy_plot.py accuracy.csv out.png
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

rows = list(csv.DictReader(open(sys.argv[1])))
methods = sorted({r["method"] for r in rows}, key=lambda m: [r["method"] for r in rows].index(m))
fig, axes = plt.subplots(2, 2, figsize=(12, 9), sharex=True)
markers = "os^vD<>ph*"
for row_i, scene in enumerate(("flat", "ecef")):
    for col_i, (key, label) in enumerate((("gyro_rms_rad_s", "gyro RMS error (rad/s)"),
                                          ("accel_rms_m_s2", "accel RMS error (m/s²)"))):
        ax = axes[row_i][col_i]
        for k, m in enumerate(methods):
            pts = [r for r in rows if r["method"] == m and r["scene"] == scene]
            xs = [float(r["samples_per_cpu_s"]) for r in pts]
            ys = [max(float(r[key]), 1e-18) for r in pts]
            ax.loglog(xs, ys, marker=markers[k % len(markers)], linestyle="-", label=m)
            for r, x, y in zip(pts, xs, ys):
                ax.annotate(r["rate_hz"], (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.set_title(f"{scene} scene: {label}")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        if row_i == 1:
            ax.set_xlabel("throughput (output samples per CPU second, one core)")
axes[0][0].legend(fontsize=8)
fig.suptitle("imuemu methods: speed vs error against analytic truth\n"
             "(aircraft-like flight, knots at 1 Hz; labels = output rate in Hz; lower right is better)")
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=110)
print("wrote", sys.argv[2])
