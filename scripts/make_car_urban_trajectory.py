#!/usr/bin/env python3
"""Writes config/data/car-urban.csv: a 165-second urban drive for the
car-urban.toml example scene (flat scene, local NED, knots at 10 Hz).

The route is a loop around city blocks: straights joined by 90-degree
corners of constant radius, so the heading is continuous and the curvature
piecewise constant. Speed follows v(s) = min(50 km/h, corner and stop limits)
with a constant braking/acceleration bound (a car's ~2 m/s^2), the car halts
at two traffic lights, the road rises and falls by a few metres (pitch is the
road grade) and the body leans a little into the corners (roll proportional to
lateral acceleration, with a first-order lag). Only the Python standard
library is used, so the result is reproducible anywhere:

    python3 scripts/make_car_urban_trajectory.py config/data/car-urban.csv
"""
import math
import sys

V_MAX = 50.0 / 3.6      # m/s, urban limit
V_CORNER = 4.5          # m/s through a 90-degree corner of radius 9 m (lateral ~2.2 m/s^2)
A_BOUND = 1.8           # m/s^2, acceleration and braking bound
CORNER_RADIUS = 9.0     # m
STOP_S = 20.0           # s at each traffic light
KNOT_PERIOD = 0.1       # s
ROLL_PER_LATERAL = math.radians(0.6)  # rad of lean per m/s^2 of lateral acceleration
ROLL_TIME_CONSTANT = 0.4  # s, the body's first-order roll response (suspension)
HILL_AMPLITUDE = 3.0    # m
HILL_WAVELENGTH = 600.0  # m

# (kind, value): ("line", length m) | ("turn", +90 right / -90 left) | ("stop", None)
ROUTE = [
    ("line", 180.0), ("turn", 90.0), ("line", 120.0), ("stop", None), ("line", 60.0),
    ("turn", 90.0), ("line", 150.0), ("turn", -90.0), ("line", 90.0), ("turn", 90.0),
    ("line", 140.0), ("stop", None), ("line", 100.0), ("turn", 90.0), ("line", 120.0),
]


def build_path():
    """Geometry sampled every DS metres: s, north, east, heading, curvature."""
    ds = 0.05
    n = e = psi = 0.0
    s = 0.0
    points = [(s, n, e, psi, 0.0)]
    corners, stops = [], []
    for kind, value in ROUTE:
        if kind == "stop":
            stops.append((s, len(points) - 1))  # position and the path point where the car halts
            continue
        if kind == "line":
            length, kappa = value, 0.0
        else:
            length = abs(math.radians(value)) * CORNER_RADIUS
            kappa = math.copysign(1.0 / CORNER_RADIUS, value)
            corners.append((s, s + length))
        steps = max(1, int(round(length / ds)))
        h = length / steps
        for _ in range(steps):
            # Midpoint rule for the heading: exact for piecewise-constant curvature.
            psi_mid = psi + 0.5 * kappa * h
            n += math.cos(psi_mid) * h
            e += math.sin(psi_mid) * h
            psi += kappa * h
            s += h
            points.append((s, n, e, psi, kappa))
    return points, corners, stops


def speed_limit(s, total, corners, stops):
    v = V_MAX
    # Start and end at rest.
    v = min(v, math.sqrt(2.0 * A_BOUND * s), math.sqrt(2.0 * A_BOUND * max(0.0, total - s)))
    for a, b in corners:
        d = 0.0 if a <= s <= b else min(abs(s - a), abs(s - b))
        v = min(v, math.sqrt(V_CORNER ** 2 + 2.0 * A_BOUND * d))
    for c, _ in stops:
        v = min(v, math.sqrt(2.0 * A_BOUND * abs(s - c)))
    return v


def main(out_path):
    points, corners, stops = build_path()
    total = points[-1][0]
    # Time along the path: dt = ds / v (midpoint speed keeps it finite where v
    # reaches zero at a stop), plus the dwell at each light.
    # A halt is a repeated path point STOP_S later.
    stop_points = {index for _, index in stops}
    times = [0.0]
    expanded = [points[0]]
    t = 0.0
    for i in range(1, len(points)):
        s0, s1 = points[i - 1][0], points[i][0]
        v_mid = speed_limit(0.5 * (s0 + s1), total, corners, stops)
        t += (s1 - s0) / max(v_mid, 1e-3)
        times.append(t)
        expanded.append(points[i])
        if i in stop_points:
            t += STOP_S
            times.append(t)
            expanded.append(points[i])
    points = expanded
    t_end = times[-1]

    rows = []
    roll = 0.0
    roll_gain = 1.0 - math.exp(-KNOT_PERIOD / ROLL_TIME_CONSTANT)
    j = 0
    k = 0
    while True:
        tk = k * KNOT_PERIOD
        if tk > t_end:
            break
        while j + 1 < len(times) - 1 and times[j + 1] <= tk:
            j += 1
        t0, t1 = times[j], times[j + 1]
        u = 0.0 if t1 == t0 else min(1.0, max(0.0, (tk - t0) / (t1 - t0)))
        p0, p1 = points[j], points[j + 1]
        s = p0[0] + u * (p1[0] - p0[0])
        north = p0[1] + u * (p1[1] - p0[1])
        east = p0[2] + u * (p1[2] - p0[2])
        psi = p0[3] + u * (p1[3] - p0[3])
        kappa = p1[4]
        v = speed_limit(s, total, corners, stops)
        down = -HILL_AMPLITUDE * math.sin(2.0 * math.pi * s / HILL_WAVELENGTH)
        grade = -HILL_AMPLITUDE * 2.0 * math.pi / HILL_WAVELENGTH * math.cos(2.0 * math.pi * s / HILL_WAVELENGTH)
        pitch = math.atan(-grade)  # nose up while climbing (down decreasing)
        # The lean follows the lateral acceleration through the suspension's lag
        # (no step in roll where the curvature steps at a corner's start).
        roll += roll_gain * (ROLL_PER_LATERAL * v * v * kappa - roll)
        heading = math.degrees(math.atan2(math.sin(psi), math.cos(psi)))
        rows.append("%d.%d,%.4f,%.4f,%.4f,%.5f,%.5f,%.5f" % (k // 10, k % 10, north, east, down, heading,
                                                            math.degrees(pitch), math.degrees(roll)))
        k += 1

    with open(out_path, "w") as f:
        f.write("# imuemu example: %.0f-second urban drive, %.0f m, local NED frame (flat scene), knots at 10 Hz\n"
                % (t_end, total))
        f.write("# written by scripts/make_car_urban_trajectory.py\n")
        f.write("time_s,north_m,east_m,down_m,heading_deg,pitch_deg,roll_deg\n")
        f.write("\n".join(rows) + "\n")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "config/data/car-urban.csv")
