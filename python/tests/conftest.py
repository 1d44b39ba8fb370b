"""Shared pieces of the Python package's tests: the repository, campaigns, run folders.

The suite runs from a fresh virtual environment into which `pip install .` installed the
package (tests/python.rs does that); run by hand: `pip install .[test]`, then
`pytest python/tests`.
"""

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import pytest

import lidarsim

REPO = Path(__file__).resolve().parents[2]
FOREST = REPO / "scenes" / "small_forest" / "forest.yaml"
PLANE = REPO / "scenes" / "plane.yaml"
C = lidarsim._lidarsim.C


def als_campaign(name="py_als"):
    """A discrete-return strip over the bundled forest in a UTM frame: points, DSM, report."""
    return {
        "name": name,
        "scene": str(FOREST),
        "seed": 3,
        "wavelength_nm": 1064,
        "instrument": {
            "kind": "discrete_return",
            "pulse_energy_j": 0.0001,
            "pulse_fwhm_ns": 3.0,
            "footprint_half_angle_mrad": 0.25,
            "fov_half_angle_mrad": 0.375,
            "receiver_area_m2": 0.01,
            "bin_ns": 0.5,
            "max_returns": 4,
        },
        "platform": {
            "kind": "als",
            "altitude_m": 120,
            "speed_m_s": 20,
            "prf_hz": 10000,
            "lines": [{"start": [12, 20], "end": [28, 20]}],
            "scanner": {"pattern": "oscillating", "scan_angle_deg": [-10, 10], "scan_frequency_hz": 50},
        },
        "simulation": {"method": "bdpt", "rays_per_pulse": 8, "max_order": 3},
        "products": {"points": True, "dsm": {"resolution_m": 1.0}},
        "frame": {"crs": "EPSG:32635", "origin": [694000.0, 6461000.0, 35.0]},
    }


def track_campaign(rays=1500):
    """A profiling track over a plane: 4000 pulses, so four waveform parts of 1000."""
    return {
        "name": "py_track",
        "scene": str(PLANE),
        "seed": 9,
        "wavelength_nm": 1064,
        "instrument": {
            "pulse_energy_j": 0.001,
            "pulse_fwhm_ns": 2,
            "footprint_half_angle_mrad": 0.5,
            "fov_half_angle_mrad": 0.6,
            "receiver_area_m2": 0.1,
        },
        "platform": {
            "kind": "track",
            "altitude_m": 300,
            "track": {"start": [10, 50], "end": [90, 50]},
            "along_track_step_m": 0.02,
        },
        "simulation": {"method": "bdpt", "rays_per_pulse": rays, "max_order": 5},
    }


def write_campaign(folder: Path, campaign: dict, name="campaign.yaml") -> Path:
    """A campaign file (JSON is YAML)."""
    path = folder / name
    path.write_text(json.dumps(campaign, indent=2) + "\n")
    return path


def cli():
    """The command line to compare with: the Rust binary the test harness names, else the
    `lidarsim` command this package installed."""
    exe = os.environ.get("LIDARSIM_BIN") or shutil.which("lidarsim")
    if exe is None:
        pytest.fail("no lidarsim command: set LIDARSIM_BIN or install the package")
    return exe


def same_run_files(a: Path, b: Path) -> str:
    """tools/compare_runs.sh's verdict on two run folders ("" when identical, timings
    aside), else what it printed."""
    p = subprocess.run(
        ["bash", str(REPO / "tools" / "compare_runs.sh"), str(a), str(b)],
        capture_output=True,
        text=True,
    )
    return "" if p.returncode == 0 else p.stdout + p.stderr


def plane_closed_form(energy, rho, area, h):
    """Closed form 1 (physics.md) when the field of view holds the whole footprint: the
    integral over the footprint is 1, so Q_r = Q_e rho A_tel / (pi H^2)."""
    return energy * rho * area / (math.pi * h * h)


@pytest.fixture(scope="session")
def session_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("lidarsim-py")
