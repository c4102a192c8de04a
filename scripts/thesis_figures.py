#!/usr/bin/python3
"""Plot the thesis' Appendix A/B figures (Figures 2-8) from thesis_cases CSVs.

Usage:
    thesis_cases CSV_DIR                       # C++ tool, bench/thesis_cases.cpp
    /usr/bin/python3 scripts/thesis_figures.py CSV_DIR [OUT_DIR]

Writes OUT_DIR/thesis_fig2.png ... thesis_fig8.png (OUT_DIR defaults to the
repository's docs/). Each figure mirrors the thesis: heading, pitch and roll
(deg) against time (s), with the knots of Table 1 / Table 2 as markers; a lower
panel adds the body angular-rate magnitude (finite differences at 100 Hz),
which is where the methods differ most. Uses Debian's python3-matplotlib with
the Agg backend (no display needed).
"""

import csv
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ANGLES = (("heading_deg", "heading ψ", "tab:blue"),
          ("pitch_deg", "pitch θ", "tab:orange"),
          ("roll_deg", "roll γ", "tab:green"))


def read(csv_dir, name):
    with open(csv_dir / f"{name}.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows] for k in rows[0]}


def plot_hpr(ax, curve, knots, title):
    for key, label, color in ANGLES:
        ax.plot(curve["time_s"], curve[key], color=color, label=label, lw=1.4)
        if knots is not None:
            ax.plot(knots["time_s"], knots[key], "o", color=color, ms=5, mfc="none")
    ax.set_ylabel("angle (deg)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)


def plot_rate(ax, curve, log=False):
    ax.plot(curve["time_s"], curve["angular_rate_deg_s"], color="k", lw=1.0)
    ax.set_ylabel("|ω| (deg/s)")
    ax.set_xlabel("time (s)")
    if log:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)


def hpr_figure(out, curve, knots, title, log_rate=False):
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True,
                                      gridspec_kw={"height_ratios": [3, 1]})
    plot_hpr(top, curve, knots, title)
    plot_rate(bottom, curve, log=log_rate)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv):
    if len(argv) not in (2, 3):
        print(__doc__, file=sys.stderr)
        return 2
    csv_dir = pathlib.Path(argv[1])
    out_dir = pathlib.Path(argv[2]) if len(argv) == 3 else pathlib.Path(__file__).resolve().parent.parent / "docs"
    out_dir.mkdir(parents=True, exist_ok=True)

    t1 = read(csv_dir, "table1_knots")
    t2l = read(csv_dir, "table2_left_knots")
    t2r = read(csv_dir, "table2_right_knots")
    geo = read(csv_dir, "fig2_geodesic")

    hpr_figure(out_dir / "thesis_fig2.png", geo, t1,
               "Fig. 2 — Table 1, geodesic (Eq. 3.44), 100 Hz")

    lin = read(csv_dir, "fig3_linear_heading")
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(geo["time_s"], geo["heading_deg"], label="geodesic", lw=1.6)
    ax.plot(lin["time_s"], lin["heading_deg"], "--", label="linear interpolation of heading", lw=1.4)
    ax.plot(t1["time_s"], t1["heading_deg"], "ko", mfc="none", label="knots")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("heading (deg)")
    ax.set_title("Fig. 3 — Table 1, heading: geodesic vs linear", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "thesis_fig3.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for ax, (name, label) in zip(axes, (("fig4_minaccel_1_3", "(σ, μ) = (1, 3)"),
                                        ("fig4_minaccel_10_-5", "(σ, μ) = (10, −5)"))):
        c = read(csv_dir, name)
        plot_hpr(ax, c, t1, f"Fig. 4 — Table 1, minimum acceleration (Lemma 3.22), {label}")
        for key, _, color in ANGLES:
            ax.plot(geo["time_s"], geo[key], ":", color=color, lw=0.9)
    axes[-1].set_xlabel("time (s)")
    fig.text(0.99, 0.005, "dotted: geodesic", ha="right", fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / "thesis_fig4.png", dpi=110)
    plt.close(fig)

    hpr_figure(out_dir / "thesis_fig5.png", read(csv_dir, "fig5_park_ravani_4"), t2l,
               "Fig. 5 — Table 2 (left), Park-Ravani §3.6.1, 100 Hz")
    hpr_figure(out_dir / "thesis_fig6.png", read(csv_dir, "fig6_park_ravani_10"), t2r,
               "Fig. 6 — Table 2 (right), Park-Ravani §3.6.1, 100 Hz (erratic)", log_rate=True)
    hpr_figure(out_dir / "thesis_fig7.png", read(csv_dir, "fig7_smoothed_4"), t2l,
               "Fig. 7 — Table 2 (left), §3.6.2 geodesic + bump smoothing (Δ = 10), 100 Hz")
    hpr_figure(out_dir / "thesis_fig8.png", read(csv_dir, "fig8_smoothed_10"), t2r,
               "Fig. 8 — Table 2 (right), §3.6.2 geodesic + bump smoothing (Δ = 10), 100 Hz")
    print(f"wrote {out_dir}/thesis_fig2.png ... thesis_fig8.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
