"""lidarsim from Python, in three steps: a campaign run, its points and DSM, and one
GEDI-like waveform fitted by simulating it again and again over one loaded scene.

    python docs/examples/quickstart.py [OUT_DIR]

Run from the repository after `pip install .`; plots need matplotlib (`pip install
matplotlib`) and are skipped, saying so, without it. The run folder and the figures go to
OUT_DIR (default runs/quickstart).
"""

import logging
import sys
from pathlib import Path

import numpy as np

import lidarsim

REPO = Path(__file__).resolve().parents[2]
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "runs" / "quickstart"
logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")

# --- 1. A small airborne campaign over the bundled forest, as a mapping --------------------
campaign = {
    "name": "quickstart",
    "scene": "scenes/small_forest/forest.yaml",  # relative to base_dir
    "seed": 1,
    "wavelength_nm": 1064,
    "instrument": {
        "kind": "discrete_return",
        "pulse_energy_j": 1e-4,
        "pulse_fwhm_ns": 3.0,
        "footprint_half_angle_mrad": 0.25,
        "fov_half_angle_mrad": 0.375,
        "receiver_area_m2": 0.01,
        "bin_ns": 0.5,
    },
    "platform": {
        "kind": "als",
        "altitude_m": 120,
        "speed_m_s": 20,
        "prf_hz": 20000,
        "lines": [{"start": [6, 20], "end": [34, 20]}],
        "scanner": {"pattern": "oscillating", "scan_angle_deg": [-10, 10], "scan_frequency_hz": 50},
    },
    "simulation": {"method": "bdpt", "rays_per_pulse": 16, "max_order": 3},
    "products": {"points": True, "dsm": {"resolution_m": 1.0}},
}
run = lidarsim.run(campaign, out=OUT / "run", base_dir=REPO)
points = run.points()  # a pyarrow.Table
dsm = run.dsm()  # numpy arrays and the geotransform
print(f"{points.num_rows} points from {run.pulses().num_rows} pulses")
diff = dsm["difference"][np.isfinite(dsm["difference"])]
print(f"DSM minus reference: bias {diff.mean():+.3f} m, RMSE {np.sqrt((diff ** 2).mean()):.3f} m")

# --- 2. Plots, where matplotlib is installed -----------------------------------------------
try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    plt = None
    print("matplotlib is not installed: no plots (pip install matplotlib)", file=sys.stderr)
if plt is not None:
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    x, z = points["x"].to_numpy(), points["z"].to_numpy()
    cls = points["classification"].to_numpy()
    for code, name, colour in ((2, "ground", "tab:brown"), (5, "vegetation", "tab:green")):
        m = cls == code
        a.scatter(x[m], z[m], s=1, c=colour, label=name)
    a.set(xlabel="x (m)", ylabel="z (m)", title="points, side view")
    a.legend(markerscale=8)
    w, cell, _, n, _, _ = dsm["transform"]
    h, wd = dsm["dsm"].shape
    im = b.imshow(dsm["dsm"], extent=(w, w + wd * cell, n - h * cell, n), cmap="viridis")
    fig.colorbar(im, ax=b, label="first-return height (m)")
    b.set(xlabel="x (m)", ylabel="y (m)", title="DSM")
    fig.tight_layout()
    fig.savefig(OUT / "points_and_dsm.png", dpi=100)
    print(f"wrote {OUT / 'points_and_dsm.png'}")

# --- 3. Fit one GEDI-like waveform: find the range that explains a noisy record -------------
gedi = {
    "kind": "waveform",
    "pulse_energy_j": 0.0105,
    "pulse_fwhm_ns": 14.0,
    "footprint_half_angle_mrad": 0.02,
    "fov_half_angle_mrad": 0.3,
    "receiver_area_m2": 0.5,
    "bin_ns": 1.0,
    "noise": {"electronic_sd_photons": 3.0},
}
scene = lidarsim.Scene.load(REPO / "scenes/small_forest/forest.yaml")  # BVHs built once
H = 419_000.0
true_offset = 1.3  # metres the platform really flew above where it thinks it is
observed = scene.simulate_pulse(gedi, (20, 20, H + true_offset), (0, 0, -1), rays=2000, record=True)


def misfit(offset):
    """Sum of squares between the record and the mean waveform simulated at `offset`."""
    model = scene.simulate_pulse(gedi, (20, 20, H + offset), (0, 0, -1), rays=2000, seed=2)
    # the gates start at different times: compare on the observed record's time axis
    mean = np.interp(observed.time_ns, model.time_ns, model.photons, left=0, right=0)
    return float(((observed.record - mean) ** 2).sum())


grid = np.arange(-3.0, 3.01, 0.25)
cost = np.array([misfit(o) for o in grid])
k = int(np.clip(cost.argmin(), 1, len(grid) - 2))
# a parabola through the best three points of the grid
c0, c1, c2 = cost[k - 1 : k + 2]
best = grid[k] + 0.25 * 0.5 * (c0 - c2) / (c0 - 2 * c1 + c2)
print(f"fitted range offset {best:+.2f} m (true {true_offset:+.2f} m) from {len(grid) + 1} pulses")
if plt is not None:
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(observed.range_m - H, observed.record, lw=0.8, label="record (noisy)")
    model = scene.simulate_pulse(gedi, (20, 20, H + best), (0, 0, -1), rays=2000, seed=2)
    ax.plot(model.range_m - H, model.photons, label=f"fit: offset {best:+.2f} m")
    ax.set(xlabel="range - 419 km (m)", ylabel="photons per bin", title="one GEDI-like waveform")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "waveform_fit.png", dpi=100)
    print(f"wrote {OUT / 'waveform_fit.png'}")
