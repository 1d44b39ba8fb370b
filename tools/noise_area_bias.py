#!/usr/bin/env python3
"""Apparent reflectance of discrete returns under electronic noise, against the plane's.

    python tools/noise_area_bias.py [--pulses 10000] [--photons 82]

Needs the package installed (`pip install .`). A nadir track of pulses at 500 m over a
rho = 0.3 plane at 1064 nm (4 ns pulse, 1 ns bins, no mixing: every aperture point sees the
whole footprint, so the noise-free apparent reflectance is the plane's), recorded with
Poisson noise alone and with electronic noise of 2 and 4 photoelectrons a bin. For each, the
mean apparent reflectance of the pulses' single returns on the plane, its standard error, and
its bias in per cent and in standard errors. Prints a markdown table whose first line names
the command, the commit and the machine.
"""

import argparse
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import lidarsim

REPO = Path(__file__).resolve().parents[1]
RHO = 0.3


def campaign(scene: Path, pulses: int, energy_j: float, electronic: float) -> dict:
    noise = {"electronic_sd_photons": electronic} if electronic > 0 else {}
    return {
        "name": "noise_area_bias",
        "scene": str(scene),
        "seed": 23,
        "wavelength_nm": 1064,
        "instrument": {
            "kind": "discrete_return",
            "pulse_energy_j": energy_j,
            "pulse_fwhm_ns": 4.0,
            "footprint_half_angle_mrad": 0.2,
            "fov_half_angle_mrad": 0.4,
            "receiver_area_m2": 0.01,
            "bin_ns": 1.0,
            "bandwidth_nm": 1.0,
            "max_returns": 4,
            "quantum_efficiency": 1.0,
            "noise": noise,
        },
        "platform": {
            "kind": "track",
            "altitude_m": 500,
            "track": {"start": [0, 0], "end": [pulses * 0.01, 0]},
            "along_track_step_m": 0.01,
        },
        "simulation": {"method": "forward", "rays_per_pulse": 16, "max_order": 1},
        "products": {"points": True},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pulses", type=int, default=10_000)
    ap.add_argument(
        "--photons", type=float, default=82.0, help="mean photons of a return (about)"
    )
    args = ap.parse_args()
    # 4e-9 J gives about 82 photons a return in this geometry
    energy = 4e-9 * args.photons / 82.0
    commit = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
    ).stdout.strip()
    print(
        f"`python tools/noise_area_bias.py --pulses {args.pulses} --photons {args.photons:g}`"
        f" at {commit or 'unknown'} on {platform.node()}\n"
    )
    print("| electronic noise (sd a bin) | single returns on the plane | apparent reflectance | bias |")
    print("|---|---|---|---|")
    work = Path(tempfile.mkdtemp(prefix="noise_area_bias-"))
    try:
        scene = work / "plane.yaml"
        scene.write_text(
            "name: plane\nmaterials:\n  soil: { reflectance: { 1064: %g } }\n"
            "objects:\n  - plane: { z: 0, extent: [[-5000, -5000], [5000, 5000]], material: soil }\n"
            % RHO
        )
        for electronic in (0.0, 2.0, 4.0):
            run = lidarsim.run(
                campaign(scene, args.pulses, energy, electronic), out=work / "run"
            )
            t = run.points().to_pydict()
            rho = [
                r
                for r, z, n in zip(
                    t["apparent_reflectance"], t["z"], t["number_of_returns"]
                )
                if abs(z) < 0.3 and n == 1
            ]
            mean = statistics.fmean(rho)
            se = statistics.stdev(rho) / len(rho) ** 0.5
            print(
                f"| {electronic:g} | {len(rho)} of {args.pulses} | {mean:.5f} ± {se:.5f} |"
                f" {100 * (mean / RHO - 1):+.2f} % ({(mean - RHO) / se:+.1f} SE) |"
            )
            shutil.rmtree(work / "run")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
