"""Campaigns run from Python: the same files as the command line, and the tables they hold."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import lidarsim
from conftest import REPO, als_campaign, cli, same_run_files, track_campaign, write_campaign


@pytest.fixture(scope="module")
def runs(session_dir):
    """The ALS strip run three ways: the command line on a file, Python on the same file,
    Python on the mapping; and once more from Python writing LAZ."""
    camp = als_campaign()
    path = write_campaign(session_dir, camp)
    out = {
        "cli": session_dir / "cli",
        "file": session_dir / "file",
        "dict": session_dir / "dict",
        "laz": session_dir / "laz",
    }
    p = subprocess.run(
        [cli(), "run", str(path), "--out", str(out["cli"])], capture_output=True, text=True
    )
    assert p.returncode == 0, p.stderr
    r = {
        "file": lidarsim.run(path, out=out["file"]),
        "dict": lidarsim.run(camp, out=out["dict"], base_dir=session_dir),
        "laz": lidarsim.run(
            path, out=out["laz"], overrides={"products.points_format": "laz"}
        ),
    }
    r["cli"] = lidarsim.open_run(out["cli"])
    return r


def test_a_run_from_python_writes_the_cli_s_files(runs):
    for way in ("file", "dict"):
        assert runs[way].summary["complete"]
        diff = same_run_files(runs["cli"].folder, runs[way].folder)
        assert diff == "", f"{way}: {diff}"


def test_points_are_what_laspy_reads_from_las_and_laz(runs):
    laspy = pytest.importorskip("laspy")
    for way, name in (("file", "points.las"), ("laz", "points.laz")):
        t = runs[way].points()
        las = laspy.read(runs[way].folder / name)
        assert t.num_rows == len(las.points) > 1000
        for col in ("x", "y", "z", "gps_time"):
            np.testing.assert_array_equal(t[col].to_numpy(), np.asarray(las[col], dtype=np.float64))
        for col in ("return_number", "number_of_returns", "classification", "intensity"):
            np.testing.assert_array_equal(t[col].to_numpy(), np.asarray(las[col]))
        np.testing.assert_array_equal(
            t["apparent_reflectance"].to_numpy(), np.asarray(las["apparent_reflectance"])
        )
        np.testing.assert_array_equal(t["pulse_id"].to_numpy(), np.asarray(las["pulse_id"]))
        assert t.schema.field("x").type == pa.float64()
        assert t.schema.field("classification").type == pa.uint8()
        assert t.schema.field("intensity").type == pa.uint16()
        assert t.schema.field("apparent_reflectance").type == pa.float32()
        assert t.schema.field("pulse_id").type == pa.uint64()
    # in the frame's CRS: eastings and northings near the frame's origin
    x = runs["file"].points()["x"].to_numpy()
    assert 694000 < x.min() and x.max() < 694050


def test_waveforms_of_given_pulses_are_those_rows_of_the_parts(runs):
    run = runs["file"]
    parts = sorted((run.folder / "waveforms").glob("part-*.parquet"))
    whole = pa.concat_tables([pq.read_table(p) for p in parts])
    assert run.waveforms().equals(whole)
    ids = [0, 7, 1234, 1235, whole.num_rows - 1]
    got = run.waveforms(pulse_ids=ids)
    want = whole.filter(pa.compute.is_in(whole["pulse_id"], pa.array(ids, pa.uint64())))
    assert got.num_rows == len(ids)
    assert got.equals(want)
    assert run.waveforms(pulse_ids=[]).num_rows == 0


def test_the_campaign_keeps_its_number_keys(tmp_path):
    # a table by wavelength reads back with number keys, as a YAML reader gives it
    layers = [{"scale_height_m": 8000, "optical_depth": {1064: 0.1}}]
    run = lidarsim.run(
        dict(als_campaign(), atmosphere={"layers": layers}), out=tmp_path / "a", stages=["plan"]
    )
    depth = run.campaign["atmosphere"]["layers"][0]["optical_depth"]
    assert depth == {1064: 0.1} and all(isinstance(k, (int, float)) for k in depth), depth


def test_pulses_campaign_manifest_report_and_dsm(runs):
    run = runs["file"]
    pulses = run.pulses()
    assert pulses.equals(pq.read_table(run.folder / "pulses.parquet"))
    assert run.campaign["name"] == "py_als"
    assert run.campaign["instrument"]["kind"] == "discrete_return"
    assert run.manifest["stages"]["report"]["status"] == "done"
    assert run.report.startswith("#")
    d = run.dsm()
    assert d["crs"] == "EPSG:32635"
    assert d["dsm"].dtype == np.float32 and d["dsm"].ndim == 2
    assert d["dsm"].shape == d["reference"].shape == d["difference"].shape
    west, cell, _, north, _, minus_cell = d["transform"]
    assert cell == 1.0 and minus_cell == -1.0 and 694000 <= west < 694040
    both = np.isfinite(d["dsm"]) & np.isfinite(d["reference"])
    assert both.sum() > 10
    np.testing.assert_allclose(
        (d["dsm"] - d["reference"])[both], d["difference"][both], atol=1e-3
    )
    assert np.isnan(d["difference"][~np.isfinite(d["dsm"])]).all()


def test_check_and_compare(runs, session_dir):
    c = lidarsim.check(write_campaign(session_dir, als_campaign(), "check.yaml"))
    for key in ("pulses", "instances", "triangles", "distinct_triangles", "memory_bound_mib"):
        assert key in c, key
    assert c["pulses"] == runs["file"].pulses().num_rows
    assert c["triangles"] >= c["distinct_triangles"] > 0
    assert c["memory_bound_mib"] > 0
    # the bound is of the process as it is, not of what the session held before the call
    import numpy as np

    held = np.ones(50_000_000)  # 400 MB, given back below
    held[::4096] = 2.0
    del held
    again = lidarsim.check(write_campaign(session_dir, als_campaign(), "check.yaml"))
    assert again["memory_bound_mib"] < c["memory_bound_mib"] + 100, (again, c)
    t = lidarsim.compare([runs["file"].folder, runs["laz"].folder])
    assert t.num_rows == 2
    assert t.column_names[:4] == ["run", "altitude_m", "prf_hz", "pulses"]
    csv = runs["file"].folder.parent / "compare.csv"
    p = subprocess.run(
        [cli(), "compare", str(runs["file"].folder), str(runs["laz"].folder), "--csv", str(csv)],
        capture_output=True,
        text=True,
    )
    assert p.returncode == 0, p.stderr
    header = csv.read_text().splitlines()[0].split(",")
    assert t.column_names == header
    assert t["altitude_m"].to_pylist() == [120.0, 120.0]


def test_the_lidarsim_command_is_installed():
    exe = os.path.join(os.path.dirname(sys.executable), "lidarsim")
    if not os.path.exists(exe):
        pytest.skip("not run from an environment pip installed the package into")
    p = subprocess.run([exe, "--version"], capture_output=True, text=True)
    assert p.returncode == 0 and lidarsim.__version__ in p.stdout


SCRIPT = """
import logging, sys
import lidarsim
logging.basicConfig(level=logging.INFO, stream=sys.stderr)
lidarsim.run(sys.argv[1], out=sys.argv[2])
"""


def interrupted(command, out):
    """Starts `command`, a run into `out`, sends it SIGINT once its first part is written,
    and returns the finished process and its stderr (skips when the run ended first)."""
    child = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    t = time.monotonic()
    while not (out / "waveforms" / "part-00000.parquet").is_file():
        assert time.monotonic() - t < 120, "no part appeared"
        assert child.poll() is None, child.stderr.read()
        time.sleep(0.005)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=120)
    if child.returncode == 0:
        pytest.skip("the run ended before the signal arrived")
    return child, err


def test_ctrl_c_stops_at_a_part_and_resume_finishes_the_same_bytes(session_dir):
    camp = write_campaign(session_dir, track_campaign(), "track.yaml")
    reference = lidarsim.run(camp, out=session_dir / "track_reference")
    out = session_dir / "track_stopped"
    child, err = interrupted([sys.executable, "-c", SCRIPT, str(camp), str(out)], out)
    assert "KeyboardInterrupt" in err, err
    # the logger said how far it got, and nothing after the simulate stage counts as done
    assert "simulate" in err, err
    m = json.loads((out / "manifest.json").read_text())
    assert m["stages"]["simulate"]["status"] in ("partial", "done"), m
    assert "products" not in m["stages"], m
    assert not (out / "report.md").exists()
    assert not list(out.rglob("*.tmp-*"))
    done = lidarsim.run(camp, out=out, resume=True)
    assert done.summary["complete"]
    diff = same_run_files(reference.folder, out)
    assert diff == "", diff


def test_a_sweep_returns_its_runs(session_dir):
    camp = track_campaign(rays=4)
    camp["platform"]["along_track_step_m"] = 1.0
    camp["sweep"] = {"platform.altitude_m": [200, 400]}
    run = lidarsim.run(camp, out=session_dir / "sweep")
    assert [r.folder.name for r in run.sweep] == ["altitude_m=200", "altitude_m=400"]
    assert [r.campaign["platform"]["altitude_m"] for r in run.sweep] == [200, 400]
    assert lidarsim.open_run(run.folder).sweep[1].pulses().num_rows == 80
    assert lidarsim.compare([run.folder]).num_rows == 2
    # the sweep's folder has no run of its own: asked for one, it says where its runs are
    for ask in (lambda: run.campaign, lambda: run.points(), lambda: run.manifest, lambda: run.dsm()):
        with pytest.raises(lidarsim.InputError) as e:
            ask()
        assert "sweep" in str(e.value) and e.value.key == "folder", e.value


def test_ctrl_c_ends_the_lidarsim_command_as_the_binary_does(session_dir):
    # the console script pip installed (cli() may name the Rust binary instead)
    exe = os.path.join(os.path.dirname(sys.executable), "lidarsim")
    if not os.path.exists(exe):
        pytest.skip("not run from an environment pip installed the package into")
    camp = write_campaign(session_dir, track_campaign(), "track_cli.yaml")
    out = session_dir / "track_cli_stopped"
    child, err = interrupted([exe, "run", str(camp), "--out", str(out)], out)
    # what the command kept, one line, and a failed run's exit code: no traceback on top
    assert child.returncode == 1, (child.returncode, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert "SIGINT" in err, err
