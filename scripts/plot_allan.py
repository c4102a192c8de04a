"""Allan deviation plots of `imuemu allan --json`, and a synthetic IMU record.

usage (installed as /usr/share/imuemu/plot_allan.py):
  /usr/bin/python3 scripts/plot_allan.py ALLAN.json OUT.png
      (what `imuemu allan FILE --png OUT.png` runs) one log-log panel per axis:
      the overlapping Allan deviation, its confidence band, the fitted model
      and each fitted term (IEEE Std 952-1997 Annex C).
  /usr/bin/python3 scripts/plot_allan.py synth OUT.csv [--hours H] [--rate HZ] [--seed S]
      writes an IMU CSV (io/sample_writers.hpp format) of a static sensor whose
      noise is known exactly: white rate (ARW/VRW), true flicker (1/f, shaped
      in the frequency domain) for bias instability, a random walk of rate,
      and angle/velocity quantisation (the integrated signal rounded to an
      LSB). The configured coefficients go to OUT.csv.truth.json.
  bash: see docs/allan.md ("Example") for the command that makes
      docs/allan_example.png.

Needs Debian's python3 (numpy, matplotlib), not the pyenv one first on PATH.
"""
import json
import math
import os
import sys

DEG = math.pi / 180.0
G = 9.80665

# Datasheet units shown in the legend, per sensor and term: (unit key of
# imuemu's JSON, label).
LEGEND_UNITS = {
    "gyro": {
        "quantization": ("arcsec", "arcsec"),
        "white": ("deg/sqrt(h)", "°/√h"),
        "bias_instability": ("deg/h", "°/h"),
        "rate_random_walk": ("deg/h/sqrt(h)", "°/h/√h"),
        "rate_ramp": ("deg/h^2", "°/h²"),
    },
    "accel": {
        "quantization": ("mm/s", "mm/s"),
        "white": ("m/s/sqrt(h)", "m/s/√h"),
        "bias_instability": ("ug", "µg"),
        "rate_random_walk": ("ug/sqrt(h)", "µg/√h"),
        "rate_ramp": ("ug/h", "µg/h"),
    },
}
TERM_STYLE = {
    "quantization": "tab:purple",
    "white": "tab:blue",
    "bias_instability": "tab:green",
    "rate_random_walk": "tab:orange",
    "rate_ramp": "tab:brown",
}


def plot(json_path, png_path):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        # One line a user can act on instead of a traceback: the plot is the
        # only part of `imuemu allan` that needs more than imuemu itself.
        sys.exit(f"imuemu allan --png: the plot needs Python's matplotlib ({e}); "
                 "install it with `apt install python3-matplotlib`, or leave out --png")

    with open(json_path) as f:
        data = json.load(f)
    axes_data = data["axes"]
    cols = 3 if len(axes_data) >= 3 else len(axes_data)
    rows = (len(axes_data) + cols - 1) // cols
    fig, axs = plt.subplots(rows, cols, figsize=(6.0 * cols, 4.8 * rows), squeeze=False)
    for i, ax_data in enumerate(axes_data):
        ax = axs[i // cols][i % cols]
        tau = ax_data["tau_s"]
        adev = ax_data["adev"]
        positive = [j for j, v in enumerate(adev) if v > 0]
        if not positive:
            ax.set_title(f"{ax_data['name']}: zero (constant signal)")
            continue
        t = [tau[j] for j in positive]
        ax.fill_between(t, [ax_data["ci_low"][j] for j in positive], [ax_data["ci_high"][j] for j in positive],
                        color="0.8", label=f"{data['confidence'] * 100:.0f} % interval (EDF, χ²)")
        ax.loglog(t, [adev[j] for j in positive], "k.", ms=4, label="overlapping ADEV")
        ax.loglog(t, [ax_data["model_adev"][j] for j in positive], "r-", lw=1.5, label="fitted model")
        sensor = ax_data["sensor"]
        for name, term in ax_data["terms"].items():
            if term["value"] <= 0:
                continue
            key, label = LEGEND_UNITS[sensor][name]
            value = term["units"][key]["value"]
            sigma = term["units"][key]["sigma"]
            ax.loglog(t, [term["adev"][j] for j in positive], "--", color=TERM_STYLE[name], lw=1,
                      label=f"{term['symbol']} {term['label']}: {value:.3g} ± {sigma:.2g} {label}")
        lo = min(ax_data["ci_low"][j] for j in positive if ax_data["ci_low"][j] > 0)
        hi = max(ax_data["ci_high"][j] for j in positive)
        ax.set_ylim(lo / 2, hi * 2)
        ax.set_xlabel("τ (s)")
        ax.set_ylabel(f"σ(τ) ({ax_data['unit']})")
        ax.set_title(ax_data["name"])
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for j in range(len(axes_data), rows * cols):
        axs[j // cols][j % cols].axis("off")
    hours = data["duration_s"] / 3600.0
    fig.suptitle(f"{os.path.basename(data['file'])}: {data['samples']} samples at {1.0 / data['tau0_s']:.6g} Hz ({hours:.3g} h)", fontsize=10)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


def flicker(rng, n, tau0, b):
    """Rate noise with two-sided PSD B^2 / (2 pi |f|) (IEEE Std 952-1997 C.1.4;
    Annex C's PSDs are two-sided: its white term S = N^2 gives sigma^2 = N^2/tau),
    i.e. one-sided B^2 / (pi f), whose Allan variance is 2 ln2 h_-1 = (2 ln2/pi) B^2,
    flat at 0.664 B; white noise shaped in the frequency domain over
    [1/(2 n tau0), 1/(2 tau0)]."""
    import numpy as np

    m = 2 * n  # twice the length: the periodic FFT noise is cut to its first half
    f = np.fft.rfftfreq(m, tau0)
    spectrum = np.zeros(f.size, dtype=complex)
    psd = np.zeros(f.size)
    psd[1:] = b * b / (math.pi * f[1:])  # one-sided
    # One-sided PSD S: a real series x = irfft(X) with E|X_k|^2 = S_k m / (2 tau0)
    # has that PSD (Parseval with numpy's unnormalised forward transform).
    amplitude = np.sqrt(psd * m / (2.0 * tau0) / 2.0)
    spectrum.real = rng.standard_normal(f.size) * amplitude
    spectrum.imag = rng.standard_normal(f.size) * amplitude
    spectrum[0] = 0.0
    spectrum[-1] = spectrum[-1].real * math.sqrt(2.0)
    return np.fft.irfft(spectrum, m)[:n]


def synth(out_path, hours, rate_hz, seed):
    import numpy as np

    rng = np.random.default_rng(seed)
    n = int(round(hours * 3600.0 * rate_hz))
    tau0 = 1.0 / rate_hz
    # An industrial-MEMS-like gyro and accelerometer (coefficients in SI;
    # comments in datasheet units), each term dominant over part of 0.01 s .. 1 h.
    truth = {
        "gyro": {"white": 0.3 * DEG / 60.0,                  # 0.3 deg/sqrt(h)
                 "bias_instability": 5.0 * DEG / 3600.0,     # 5 deg/h
                 "rate_random_walk": 10.0 * DEG / 3600.0 / 60.0,  # 10 deg/h/sqrt(h)
                 "quantization_lsb": 2.5e-5},                # angle LSB (rad): Q = LSB / sqrt(12)
        "accel": {"white": 0.06 / 60.0,                      # 0.06 m/s/sqrt(h)
                  "bias_instability": 50e-6 * G,             # 50 ug
                  "rate_random_walk": 100e-6 * G / 60.0,     # 100 ug/sqrt(h)
                  "quantization_lsb": 2e-4},                 # velocity LSB (m/s)
    }
    columns = []
    for sensor, gravity in (("gyro", 0.0), ("accel", -G)):
        c = truth[sensor]
        for _ in range(3):
            y = c["white"] / math.sqrt(tau0) * rng.standard_normal(n)
            y += flicker(rng, n, tau0, c["bias_instability"])
            y += np.cumsum(c["rate_random_walk"] * math.sqrt(tau0) * rng.standard_normal(n))
            # Quantise the integrated signal (what an IMU's delta-theta/-v
            # counters do) and difference it back into a rate.
            lsb = c["quantization_lsb"]
            theta = np.concatenate(([0.0], np.cumsum(y * tau0)))
            theta = np.round(theta / lsb) * lsb
            columns.append(np.diff(theta) / tau0 + gravity * (sensor == "accel"))
        c["quantization"] = c.pop("quantization_lsb") / math.sqrt(12.0)
    t_ns = (np.arange(n, dtype=np.int64) * int(round(1e9 / rate_hz))).astype(np.int64)
    with open(out_path, "w") as f:
        f.write("time_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2\n")
        block = 200000
        for s in range(0, n, block):
            e = min(n, s + block)
            rows = np.column_stack([t_ns[s:e].astype(np.float64)] + [col[s:e] for col in columns])
            lines = ["%d,%s" % (int(r[0]), ",".join(repr(float(v)) for v in r[1:])) for r in rows]
            f.write("\n".join(lines))
            f.write("\n")
    with open(out_path + ".truth.json", "w") as f:
        json.dump({"samples": n, "rate_hz": rate_hz, "seed": seed, "si": truth}, f, indent=1)


def main(argv):
    if len(argv) >= 2 and argv[1] == "synth":
        import argparse

        p = argparse.ArgumentParser(prog="plot_allan.py synth")
        p.add_argument("out")
        p.add_argument("--hours", type=float, default=2.0)
        p.add_argument("--rate", type=float, default=200.0)
        p.add_argument("--seed", type=int, default=1)
        a = p.parse_args(argv[2:])
        synth(a.out, a.hours, a.rate, a.seed)
        return 0
    if len(argv) != 3:
        sys.stderr.write(__doc__)
        return 2
    plot(argv[1], argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
