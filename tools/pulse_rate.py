#!/usr/bin/env python3
"""Single pulses from Python against the same pulses as one-pulse campaigns.

    python tools/pulse_rate.py [--out docs/benchmarks/python_pulses.md] [--seconds 2]

Needs the package installed (`pip install .`). For the plane and the bundled small forest, at
1, 10 and 1000 rays: calls per second of `Scene.load(...).simulate_pulse(...)` over one
loaded scene (the median of three timed stretches), with the campaign defaults and with
`receiver_depth: full` (which skips the pilot that `auto` runs for each pulse), and runs per
second of the same pulse as a one-pulse campaign, by `lidarsim.run` in this process and by
the `lidarsim` command as a process of its own (scene loading and file writing included).
Writes a markdown table whose first line names the command, the commit and the machine.
"""

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import lidarsim

REPO = Path(__file__).resolve().parents[1]
INSTRUMENT = {
    "kind": "waveform",
    "pulse_energy_j": 0.0105,
    "pulse_fwhm_ns": 14.0,
    "footprint_half_angle_mrad": 0.03,
    "fov_half_angle_mrad": 0.3,
    "receiver_area_m2": 0.5,
    "bin_ns": 1.0,
}
SCENES = {
    "plane": (REPO / "scenes/plane.yaml", (50.0, 50.0, 419_000.0)),
    "small forest": (REPO / "scenes/small_forest/forest.yaml", (20.0, 20.0, 419_000.0)),
}


def rate(call, seconds):
    """Calls per second: the median of three stretches of about `seconds` / 3 each."""
    call()
    rates = []
    for _ in range(3):
        n, t0 = 0, time.perf_counter()
        while True:
            call()
            n += 1
            dt = time.perf_counter() - t0
            if dt >= seconds / 3:
                break
        rates.append(n / dt)
    return statistics.median(rates)


def campaign(scene, origin, rays):
    return {
        "name": "one_pulse",
        "scene": str(scene),
        "seed": 1,
        "wavelength_nm": 1064,
        "instrument": INSTRUMENT,
        "platform": {"kind": "static", "pulses": [{"position": list(origin), "direction": [0, 0, -1]}]},
        "simulation": {"method": "bdpt", "rays_per_pulse": rays, "max_order": 5},
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "docs/benchmarks/python_pulses.md"))
    ap.add_argument("--seconds", type=float, default=2.0, help="time per measured figure")
    args = ap.parse_args()
    commit = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip() or "unknown"
    exe = shutil.which("lidarsim") or "lidarsim"
    rows = []
    with tempfile.TemporaryDirectory(prefix="lidarsim-pulse-rate-") as tmp:
        tmp = Path(tmp)
        for name, (path, origin) in SCENES.items():
            scene = lidarsim.Scene.load(path)
            for rays in (1, 10, 1000):
                kw = dict(rays=rays, method="bdpt", max_order=5, seed=1)
                default = rate(lambda: scene.simulate_pulse(INSTRUMENT, origin, (0, 0, -1), **kw), args.seconds)
                full = rate(
                    lambda: scene.simulate_pulse(
                        INSTRUMENT, origin, (0, 0, -1), simulation={"receiver_depth": "full"}, **kw
                    ),
                    args.seconds,
                )
                file = tmp / f"{name.replace(' ', '_')}_{rays}.yaml"
                file.write_text(json.dumps(campaign(path, origin, rays)))
                out = tmp / "run"
                in_process = rate(lambda: lidarsim.run(file, out=out), args.seconds)
                process = rate(
                    lambda: subprocess.run(
                        [exe, "run", str(file), "--out", str(out)], check=True, capture_output=True
                    ),
                    args.seconds,
                )
                rows.append((name, rays, default, full, in_process, process))
                print(rows[-1], file=sys.stderr)
    cpu = platform.processor() or platform.machine()
    lines = [
        f"<!-- `python tools/pulse_rate.py --seconds {args.seconds}` at {commit} on {os.cpu_count()} "
        f"cores ({cpu}), Python {platform.python_version()}, lidarsim {lidarsim.__version__} -->",
        "",
        "| scene | rays | simulate_pulse calls/s | with receiver_depth full | one-pulse campaigns/s, lidarsim.run | one-pulse campaigns/s, lidarsim command | simulate_pulse / lidarsim.run |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for name, rays, default, full, in_process, process in rows:
        lines.append(
            f"| {name} | {rays} | {default:,.0f} | {full:,.0f} | {in_process:,.1f} | {process:,.1f} | {default / in_process:,.0f} |"
        )
    text = "\n".join(lines) + "\n"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
