#!/usr/bin/env python3
"""Writes pipelines/town_trajectory.csv, the recorded trajectory that
pipelines/als_town_trajectory.yaml flies over the generated town (100 m x 100 m):

- leg 1 east along y = 30 m from x = -20 to 120 m at 150 m, crabbing 3 deg into a wind from
  the south (heading 87 deg), nose 1.5 deg up;
- a left turn of 180 deg about (120, 50) m, radius 20 m, banked 38 deg (atan v^2 / g r at
  12.5 m/s), rolling in and out over 0.5 s, climbing 5 m;
- leg 2 west along y = 70 m at 155 m, crabbing the other way (heading 273 deg).

Epochs every 0.1 s at GPS times from 1.3e9 s. Run from the repository's root:
    python3 tools/town_trajectory.py
"""
import math

V, R, T0, DT = 12.5, 20.0, 1.3e9, 0.1
LEG = 140.0 / V
TURN = math.pi * R / V
BANK = math.degrees(math.atan(V * V / (9.81 * R)))


def pose(t):
    """x, y, z, roll, pitch, heading at t seconds after the first epoch."""
    if t <= LEG:
        return -20.0 + V * t, 30.0, 150.0, 0.0, 1.5, 87.0
    if t <= LEG + TURN:
        s = t - LEG
        a = -math.pi / 2 + V * s / R  # counter-clockwise about the centre
        ramp = min(1.0, s / 0.5, (TURN - s) / 0.5)
        track = 90.0 - math.degrees(V * s / R)  # the heading turns left from east to west
        return (120.0 + R * math.cos(a), 50.0 + R * math.sin(a), 150.0 + 5.0 * s / TURN,
                -BANK * ramp, 1.5, (track - 3.0 * (1 - 2 * s / TURN)) % 360.0)
    s = t - LEG - TURN
    return 120.0 - V * s, 70.0, 155.0, 0.0, 1.5, 273.0


def main():
    n = int(round((2 * LEG + TURN) / DT))
    rows = ["time_s,x,y,z,roll_deg,pitch_deg,heading_deg"]
    for k in range(n + 1):
        x, y, z, r, p, h = pose(k * DT)
        rows.append(f"{T0 + k * DT:.1f},{x:.4f},{y:.4f},{z:.4f},{r:.5f},{p:.5f},{h:.5f}")
    with open("pipelines/town_trajectory.csv", "w") as f:
        f.write("\n".join(rows) + "\n")
    print(f"{n + 1} epochs; scan legs [{T0:.1f}, {T0 + LEG:.1f}] and "
          f"[{T0 + LEG + TURN:.4f}, {T0 + 2 * LEG + TURN:.4f}]")


if __name__ == "__main__":
    main()
