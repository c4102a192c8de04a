"""The signal chain's two figures in docs/signal-chain.md, made by imuemu itself.

usage:
  /usr/bin/python3 scripts/signal_chain_figures.py [IMUEMU] [OUT_DIR]
      IMUEMU: the imuemu binary (default build/release/daemon/imuemu);
      OUT_DIR: where the PNGs go (default docs).

Writes two scenes into a temporary directory, runs `imuemu generate
--scene-file` on each (what imuemud emits for that device: the same
DeviceChain, tick for tick), and plots:

  signal_chain_vibration_psd.png  random vibration: the PSD configured
      ([imu.error_model.signal_chain.vibration.random], g^2/Hz, log-log
      between points) against the PSD of the emitted accelerometer (z, at
      2 kHz, 120 s, Welch: Hann 4096, 50 % overlap), with the +-1 dB band
      the heavy test SignalChain.RandomVibrationPsdMatchesItsProfileWithinOneDecibel
      holds it to.
  signal_chain_aliasing.png  a 1 kHz device on a body vibrating at 120 Hz
      (1 m/s^2) and 1300 Hz (3 m/s^2): sampled at 8 kHz and decimated to
      1 kHz without a filter, the 1300 Hz tone folds to 300 Hz at its full
      amplitude; through the ICM-42688-P chain preset (anti-alias at 258 Hz
      and the UI low-pass at 250 Hz, both second order) it is attenuated by
      the filters' gain at 1300 Hz, which the plot states from the
      analytic response.

Needs Debian's python3 (numpy, matplotlib), not the pyenv one first on PATH.
"""
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

G = 9.80665
PSD_PROFILE = [(20.0, 0.002), (80.0, 0.04), (350.0, 0.04), (500.0, 0.01)]  # docs/signal-chain.md's example

HEAD = """[scene]
name = "{name}"
physics = "flat"

[trajectory]
source = "sample:static"
duration_s = {duration}

[[imu]]
name = "a"
rate_hz = {rate}
protocol = "native"

[imu.transport]
type = "null"
"""


def generate(imuemu, work, name, body, rate, seconds):
    """Runs imuemu generate on a one-device scene; returns (t_s, accel (n, 3))."""
    scene = os.path.join(work, name + ".toml")
    with open(scene, "w", encoding="utf-8") as f:
        f.write(HEAD.format(name=name, rate=rate, duration=seconds + 20) + body)
    out = os.path.join(work, name + ".csv")
    subprocess.run([imuemu, "generate", "--scene-file", scene, "--max-seconds", str(seconds), "--out", out, "--quiet"],
                   check=True)
    data = np.genfromtxt(out, delimiter=",", names=True, comments="#")
    t = (data["time_ns"] - data["time_ns"][0]) * 1e-9
    accel = np.column_stack([data["accel_x_m_s2"], data["accel_y_m_s2"], data["accel_z_m_s2"]])
    return t, accel


def welch(x, fs, n):
    """One-sided PSD by Welch's method (Hann window of n, 50 % overlap)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    w = np.hanning(n)
    scale = fs * np.sum(w * w)
    step = n // 2
    segments = [x[i:i + n] for i in range(0, len(x) - n + 1, step)]
    p = np.zeros(n // 2 + 1)
    for s in segments:
        p += np.abs(np.fft.rfft((s - np.mean(s)) * w)) ** 2
    p /= len(segments) * scale
    p[1:-1] *= 2.0  # one-sided
    return np.fft.rfftfreq(n, 1.0 / fs), p


def profile_at(f):
    """The configured PSD, log-log between points, 0 outside."""
    out = np.zeros_like(f)
    for (f0, s0), (f1, s1) in zip(PSD_PROFILE[:-1], PSD_PROFILE[1:]):
        m = (f >= f0) & (f <= f1)
        out[m] = s0 * (s1 / s0) ** (np.log(f[m] / f0) / math.log(f1 / f0))
    return out


def vibration_psd(imuemu, work, out_dir):
    rate, seconds = 2000, 120
    points = ", ".join(f"[{f:g}, {s:g}]" for f, s in PSD_PROFILE)
    body = ("[imu.error_model.signal_chain.vibration.random]\n"
            f"psd_g2_per_hz = [{points}]\naxis_scale = [0, 0, 1]\nresolution_hz = 0.5\nseed = 1\n")
    _, accel = generate(imuemu, work, "psd", body, rate, seconds)
    f, p = welch(accel[:, 2] / G, rate, 4096)
    configured = profile_at(f)
    fig, ax = plt.subplots(figsize=(8, 4.8))
    ax.loglog(f[1:], p[1:], color="tab:blue", lw=0.8, label="emitted accel z (Welch, Hann 4096, 50 %)")
    band = configured > 0
    ax.loglog(f[band], configured[band], color="black", lw=1.6, label="configured psd_g2_per_hz")
    ax.fill_between(f[band], configured[band] * 10 ** -0.1, configured[band] * 10 ** 0.1, color="0.6", alpha=0.4,
                    label="configured +-1 dB")
    ax.set_xlim(5, 1000)
    ax.set_ylim(1e-6, 0.2)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("acceleration PSD (g$^2$/Hz)")
    in_band = (f >= 25) & (f <= 450)
    db = 10 * np.log10(np.mean(p[in_band]) / np.mean(configured[in_band]))
    ax.set_title(f"Random vibration: configured vs emitted (2 kHz, {seconds} s; 25-450 Hz mean {db:+.2f} dB)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower center")
    fig.tight_layout()
    path = os.path.join(out_dir, "signal_chain_vibration_psd.png")
    fig.savefig(path, dpi=110)
    print(f"{path}: mean emitted/configured over 25-450 Hz {db:+.2f} dB")


def tone_amplitude(x, fs, f0):
    """Amplitude of the sinusoid at f0 in x (a least-squares fit)."""
    t = np.arange(len(x)) / fs
    a = np.column_stack([np.sin(2 * math.pi * f0 * t), np.cos(2 * math.pi * f0 * t), np.ones_like(t)])
    c = np.linalg.lstsq(a, x, rcond=None)[0]
    return math.hypot(c[0], c[1])


def biquad_lowpass_gain(f, fc, fs, q):
    """|H| of the bilinear, prewarped second-order low-pass (core/signal_chain/filters.cpp)."""
    k = math.tan(math.pi * fc / fs)
    norm = 1.0 / (1.0 + k / q + k * k)
    b = np.array([k * k, 2 * k * k, k * k]) * norm
    a = np.array([1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm])
    z = np.exp(-2j * math.pi * f / fs * np.arange(3))
    return abs(np.dot(b, z) / np.dot(a, z))


def aliasing(imuemu, work, out_dir):
    rate, seconds, internal = 1000, 20, 8000
    tones = ("[[imu.error_model.signal_chain.vibration.sinusoid]]\nfrequency_hz = 120\nlinear_m_s2 = [0, 0, 1]\n"
             "[[imu.error_model.signal_chain.vibration.sinusoid]]\nfrequency_hz = 1300\nlinear_m_s2 = [0, 0, 3]\n")
    runs = [
        ("no filter: 8 kHz decimated to 1 kHz", "raw", "[imu.error_model.signal_chain]\noversampling = 8\n"),
        ("ICM-42688-P chain (AAF 258 Hz + UI low-pass 250 Hz)", "icm",
         "[imu.error_model.signal_chain]\npreset = \"icm42688p\"\n"),
    ]
    fig, ax = plt.subplots(figsize=(8, 4.8))
    lines = []
    for (label, name, chain), color in zip(runs, ["tab:red", "tab:blue"]):
        _, accel = generate(imuemu, work, name, chain + tones, rate, seconds)
        z = accel[:, 2]
        f, p = welch(z, rate, 4000)
        alias = tone_amplitude(z, rate, 300.0)
        kept = tone_amplitude(z, rate, 120.0)
        ax.semilogy(f, p, color=color, lw=1.0,
                    label=f"{label}\n  120 Hz: {kept:.3f} m/s$^2$; 300 Hz (the 1300 Hz alias): {alias:.2g} m/s$^2$")
        lines.append(f"{label}: 120 Hz at {kept:.3f} m/s^2, 300 Hz alias of 1300 Hz at {alias:.2e} m/s^2")
        print(lines[-1])
    # The preset's gain at 1300 Hz, analytic (two second-order sections at 8 kHz).
    gain = biquad_lowpass_gain(1300.0, 258.0, internal, 1 / math.sqrt(2)) * biquad_lowpass_gain(
        1300.0, 250.0, internal, 1 / math.sqrt(2))
    ax.set_xlim(0, 500)
    ax.set_ylim(1e-12, 1e2)  # the Hann window's leakage floor below is not the chain's
    ax.set_xlabel("frequency at the 1 kHz output (Hz)")
    ax.set_ylabel("accel z PSD ((m/s$^2$)$^2$/Hz; Welch, Hann 4000)")
    ax.set_title(f"Aliasing of a 1300 Hz vibration at 1 kHz output; the chain's gain there: {20 * math.log10(gain):.1f} dB")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    path = os.path.join(out_dir, "signal_chain_aliasing.png")
    fig.savefig(path, dpi=110)
    print(f"{path}: analytic gain of the preset at 1300 Hz {20 * math.log10(gain):.1f} dB ({gain * 3:.2e} m/s^2 of 3)")


def main(argv):
    imuemu = argv[1] if len(argv) > 1 else "build/release/daemon/imuemu"
    out_dir = argv[2] if len(argv) > 2 else "docs"
    with tempfile.TemporaryDirectory() as work:
        vibration_psd(imuemu, work, out_dir)
        aliasing(imuemu, work, out_dir)


if __name__ == "__main__":
    main(sys.argv)
