"""Single pulses in memory: closed form 1, and the one-pulse campaign they are defined as."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest

import lidarsim
from conftest import FOREST, PLANE, C, plane_closed_form, write_campaign

GEDI = {
    "kind": "waveform",
    "pulse_energy_j": 0.0105,
    "pulse_fwhm_ns": 14.0,
    "footprint_half_angle_mrad": 0.03,
    "fov_half_angle_mrad": 0.3,
    "receiver_area_m2": 0.5,
    "bin_ns": 1.0,
}


@pytest.fixture(scope="module")
def plane():
    return lidarsim.Scene.load(PLANE)


def test_a_pulse_over_the_plane_meets_closed_form_1(plane):
    h = 419_000.0
    for method in ("bdpt", "forward"):
        w = plane.simulate_pulse(
            GEDI, (50, 50, h), (0, 0, -1), rays=20_000, method=method, max_order=5, seed=4
        )
        expect = plane_closed_form(GEDI["pulse_energy_j"], 0.30, GEDI["receiver_area_m2"], h)
        se = w.received_energy_se_j
        # the test must be able to tell a 1 % error from the noise
        assert 3 * se < 0.01 * expect, (method, se / expect)
        assert abs(w.received_energy_j - expect) < 3 * se + 1e-9 * expect, (
            method,
            w.received_energy_j / expect - 1,
            se / expect,
        )
        # single scattering, all of it in the bin of 2H/c
        assert (w.order_energy_j[1:] == 0).all()
        b = int((2 * h / C - w.t0_ns * 1e-9) / (w.bin_ns * 1e-9))
        assert w.energy_j[b] / w.energy_j.sum() > 1 - 1e-6
        assert abs(w.energy_j.sum() - w.received_energy_j) < 1e-5 * w.received_energy_j
        hv = 6.62607015e-34 * C / 1064e-9
        assert abs(w.photons.sum() * hv / w.received_energy_j - 1) < 1e-4


def _one_pulse_campaign(scene, instrument, origin, direction, method, rays, max_order, seed):
    return {
        "name": "one_pulse",
        "scene": str(scene),
        "seed": seed,
        "wavelength_nm": 1064,
        "instrument": instrument,
        "platform": {"kind": "static", "pulses": [{"position": list(origin), "direction": list(direction)}]},
        "simulation": {"method": method, "rays_per_pulse": rays, "max_order": max_order},
    }


@pytest.mark.parametrize(
    "scene,origin,direction,method,rays",
    [
        (PLANE, (50, 50, 419_000.0), (0, 0, -1), "bdpt", 3000),
        (FOREST, (20, 21, 500.0), (0.02, 0, -1), "bdpt", 700),
        (FOREST, (18, 20, 300.0), (0, 0, -1), "forward", 1000),
    ],
)
def test_a_pulse_equals_pulse_0_of_a_one_pulse_campaign(tmp_path, scene, origin, direction, method, rays):
    inst = dict(GEDI, footprint_half_angle_mrad=5.0, fov_half_angle_mrad=6.0)
    seed = 11
    w = lidarsim.Scene.load(scene).simulate_pulse(
        inst, origin, direction, rays=rays, method=method, max_order=4, seed=seed, record=True
    )
    camp = _one_pulse_campaign(scene, inst, origin, direction, method, rays, 4, seed)
    run = lidarsim.run(write_campaign(tmp_path, camp), out=tmp_path / "run", stages=["plan", "simulate"])
    parts = sorted((run.folder / "waveforms").glob("part-*.parquet"))
    row = pq.read_table(parts[0]).to_pylist()[0]
    assert row["pulse_id"] == 0 and row["rays"] == w.rays == rays
    assert row["t0_ns"] == w.t0_ns and row["bin_ns"] == np.float32(w.bin_ns)
    assert w.received_energy_j > 0
    assert row["received_energy_j"] == w.received_energy_j
    assert row["outside_gate_energy_j"] == w.outside_gate_energy_j
    assert row["order_energy_j"] == list(w.order_energy_j)
    f32 = lambda a: list(np.asarray(a, dtype=np.float32))  # noqa: E731
    assert row["laser_photons"] == f32(w.photons)
    assert row["impulse_energy_j"] == f32(w.energy_j)
    # the record is drawn from the waveform with the campaign's seed: noise-free here
    np.testing.assert_allclose(w.record, w.photons, rtol=1e-6, atol=0)


def test_record_carries_the_instrument_s_noise(plane):
    inst = dict(GEDI, noise={"electronic_sd_photons": 2.0}, quantum_efficiency=0.5)
    kw = dict(rays=500, method="bdpt", max_order=1)
    a = plane.simulate_pulse(inst, (50, 50, 419_000.0), (0, 0, -1), seed=1, record=True, **kw)
    b = plane.simulate_pulse(inst, (50, 50, 419_000.0), (0, 0, -1), seed=2, record=True, **kw)
    assert a.record.shape == a.photons.shape
    assert not np.array_equal(a.record, b.record)
    # the record is q L photoelectrons plus shot noise (Poisson) and electronic noise of sd 2
    q = 0.5
    z = (a.record - q * a.photons) / np.sqrt(4.0 + q * a.photons)
    assert len(z) > 20
    assert abs(z.mean()) < 4 / np.sqrt(len(z)), z.mean()
    assert 0.6 < z.std() < 1.4, z.std()
    plain = plane.simulate_pulse(inst, (50, 50, 419_000.0), (0, 0, -1), seed=1, **kw)
    assert plain.record is None


def test_scene_bounds_and_bands(plane):
    assert plane.bounds == ((0.0, 0.0, 0.0), (100.0, 100.0, 0.0))
    both = plane.simulate_pulse(
        GEDI, (50, 50, 1000.0), (0, 0, -1), wavelength_nm=[532, 1064], rays=4000, max_order=1
    )
    assert [w.wavelength_nm for w in both] == [532.0, 1064.0]
    # the plane's reflectance is 0.10 at 532 nm and 0.30 at 1064 nm: one path, two bands
    ratio = both[0].received_energy_j / both[1].received_energy_j
    assert abs(ratio - 1 / 3) < 1e-9


PULSE_SCRIPT = """
import json, sys
import lidarsim
scene = lidarsim.Scene.load(sys.argv[1])
instrument = json.loads(sys.argv[2])
print("tracing", flush=True)
try:
    # hours of rays: only Ctrl-C ends this call within the test's time
    scene.simulate_pulse(instrument, (50, 50, 1000), (0, 0, -1), rays=4_000_000_000,
                         method="bdpt", max_order=5, seed=1)
    print("returned", flush=True)
except KeyboardInterrupt:
    print("stopped", flush=True)
w = scene.simulate_pulse(instrument, (50, 50, 1000), (0, 0, -1), rays=3000, method="bdpt",
                         max_order=5, seed=2)
print(repr(w.received_energy_j), flush=True)
"""


def test_ctrl_c_stops_a_long_pulse_and_the_next_one_is_whole(plane):
    child = subprocess.Popen(
        [sys.executable, "-c", PULSE_SCRIPT, str(PLANE), json.dumps(GEDI)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stdout.readline().strip() == "tracing", child.stderr.read()
    time.sleep(0.5)
    child.send_signal(signal.SIGINT)
    try:
        out, err = child.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        child.kill()
        child.communicate()
        pytest.fail("the pulse went on after Ctrl-C")
    assert child.returncode == 0, err
    lines = out.split()
    assert lines[0] == "stopped", out
    # the pulse after the stop is traced whole: the same as in a process never interrupted
    w = plane.simulate_pulse(GEDI, (50, 50, 1000), (0, 0, -1), rays=3000, method="bdpt",
                             max_order=5, seed=2)
    assert float(lines[1]) == w.received_energy_j, (lines, w.received_energy_j)
