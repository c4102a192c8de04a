"""How late the host wakes a thread from a 1 ms periodic sleep (docs/streaming.md, Latency).

usage: chrt -f 50 /usr/bin/python3 scripts/wakeup_probe.py [PERIODS=20000]

A floor for any real-time pipeline on the host: run under SCHED_FIFO (chrt),
what is left is the kernel's and the hypervisor's (vCPU preemption), not
other processes'. Python adds tens of microseconds to each wake-up, not
milliseconds: the tail above 1 ms is the host's.
"""
import sys
import time

PERIOD_NS = 1_000_000


def main() -> None:
    periods = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    due = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + PERIOD_NS
    late = []
    for _ in range(periods):
        while (now := time.clock_gettime_ns(time.CLOCK_MONOTONIC)) < due:
            time.sleep((due - now) / 1e9)
        late.append(time.clock_gettime_ns(time.CLOCK_MONOTONIC) - due)
        due += PERIOD_NS
    late.sort()
    n = len(late)

    def ms(q: float) -> float:
        return late[min(n - 1, int(q * n))] / 1e6

    print(f"wake-ups {n}: lateness p50 {ms(0.5):.3f} ms, p99 {ms(0.99):.3f} ms, p99.9 {ms(0.999):.3f} ms, "
          f"max {late[-1] / 1e6:.3f} ms; > 1 ms late: {sum(x > 1_000_000 for x in late)}, "
          f"> 5 ms late: {sum(x > 5_000_000 for x in late)}")


if __name__ == "__main__":
    main()
