#!/usr/bin/python3
"""Peak memory and throughput of `imuemu generate` (issue 13, acceptance 3).

For each duration: `imuemu sample-trajectory` writes the built-in flight (1 Hz
knots) for that long, then `imuemu generate --rate RATE` runs on it as a child
and its peak RSS (wait4's ru_maxrss), wall and CPU time, samples per second of
wall time and the output size are printed. Batch generation streams to its
writers, so the peak stays flat with the duration (the input knots are what
grows: ~0.4 MB of CSV per hour at 1 Hz).

    /usr/bin/python3 bench/generate_memory.py build/release/daemon/imuemu [--rate 1000] [--hours 1 4] [--keep DIR]
"""
import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time


def run_child(argv):
    start = time.monotonic()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - start
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        sys.exit(f"{' '.join(argv)}: exit {code}\n{err}")
    return usage, wall


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("imuemu")
    ap.add_argument("--rate", type=int, default=1000)
    ap.add_argument("--hours", type=float, nargs="+", default=[1.0, 4.0])
    ap.add_argument("--extra", default="", help="more generate options, e.g. '--sensor adis16470'")
    ap.add_argument("--keep", help="directory for the files (default: a temporary one, removed)")
    args = ap.parse_args()
    work = args.keep or tempfile.mkdtemp(prefix="imuemu_generate_memory_")
    os.makedirs(work, exist_ok=True)
    print(f"# imuemu generate at {args.rate} Hz, built-in flight with 1 Hz knots {args.extra}")
    print(f"{'hours':>6} {'samples':>10} {'peak_rss_MiB':>13} {'wall_s':>8} {'cpu_s':>8} "
          f"{'samples_per_s':>14} {'input_MB':>9} {'output_MB':>10}")
    try:
        for hours in args.hours:
            traj = os.path.join(work, f"t{hours:g}h.csv")
            out = os.path.join(work, f"imu{hours:g}h.csv")
            run_child([args.imuemu, "sample-trajectory", "--duration-s", f"{hours * 3600:g}", "--out", traj])
            usage, wall = run_child([args.imuemu, "generate", "--in", traj, "--out", out, "--rate", str(args.rate),
                                     "--quiet"] + args.extra.split())
            samples = int(round(hours * 3600 * args.rate)) + 1
            print(f"{hours:6g} {samples:10d} {usage.ru_maxrss / 1024:13.1f} {wall:8.1f} "
                  f"{usage.ru_utime + usage.ru_stime:8.1f} {samples / wall:14.0f} "
                  f"{os.path.getsize(traj) / 1e6:9.2f} {os.path.getsize(out) / 1e6:10.1f}", flush=True)
            if not args.keep:
                os.remove(out)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
