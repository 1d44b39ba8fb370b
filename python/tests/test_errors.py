"""Errors as Python exceptions: the class by kind, the place and the advice as attributes."""

import pytest

import lidarsim
from conftest import FOREST, PLANE, als_campaign, write_campaign


def test_the_exception_classes():
    assert issubclass(lidarsim.LidarsimError, Exception)
    assert issubclass(lidarsim.InputError, lidarsim.LidarsimError)
    assert issubclass(lidarsim.InputError, ValueError)
    assert issubclass(lidarsim.DataError, lidarsim.LidarsimError)
    assert issubclass(lidarsim.IoError, lidarsim.LidarsimError)
    assert issubclass(lidarsim.IoError, OSError)


def test_a_bad_value_names_its_file_line_and_key(tmp_path):
    text = (
        "name: bad\n"
        f"scene: {PLANE}\n"
        "wavelength_nm: 1064\n"
        "instrument:\n"
        "  pulse_energy_j: high\n"
        "  pulse_fwhm_ns: 3\n"
        "  footprint_half_angle_mrad: 0.3\n"
        "  fov_half_angle_mrad: 0.5\n"
        "  receiver_area_m2: 0.01\n"
        "platform: { kind: static, pulses: [ { position: [5, 5, 100] } ] }\n"
    )
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.run(path, out=tmp_path / "out")
    err = e.value
    assert err.file == str(path)
    assert err.line == 5
    assert err.column is not None
    assert err.key == "instrument.pulse_energy_j"
    assert str(err).startswith(f"{path}:5:")
    assert not (tmp_path / "out").exists()
    # a value out of range, found after parsing, is located too
    path.write_text(text.replace("pulse_energy_j: high", "pulse_energy_j: -1"))
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.check(path)
    assert (e.value.line, e.value.key) == (5, "instrument.pulse_energy_j")


def test_an_unknown_key_and_a_bad_override(tmp_path):
    camp = als_campaign()
    camp["platform"]["altitude"] = 100
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.run(camp, out=tmp_path / "a")
    assert "altitude" in str(e.value)
    # a mapping has no file: the key says where, not a place in the package's own text
    assert e.value.key == "platform.altitude", e.value
    assert (e.value.file, e.value.line, e.value.column) == (None, None, None)
    assert str(e.value).startswith("platform.altitude: unknown field"), e.value
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.run(als_campaign(), out=tmp_path / "b", overrides={"platform.altitude_m": -5})
    assert e.value.key == "platform.altitude_m"
    assert "-5" in str(e.value)


def test_bad_arguments_are_input_errors(tmp_path):
    with pytest.raises(lidarsim.InputError):
        lidarsim.run(tmp_path / "missing.yaml")
    with pytest.raises(lidarsim.InputError):
        lidarsim.run(als_campaign(), out=tmp_path / "c", shard=(2, 2))
    with pytest.raises(lidarsim.InputError):
        lidarsim.run(als_campaign(), out=tmp_path / "d", stages=["plan", "nothing"])
    with pytest.raises(lidarsim.InputError):
        lidarsim.open_run(tmp_path)
    plane = lidarsim.Scene.load(PLANE)
    with pytest.raises(lidarsim.InputError) as e:
        plane.simulate_pulse({"pulse_energy_j": 1.0}, (0, 0, 10), (0, 0, -1))
    assert e.value.key is not None and e.value.key.startswith("instrument")
    with pytest.raises(lidarsim.InputError):
        plane.simulate_pulse(
            {"pulse_energy_j": 1e-3, "pulse_fwhm_ns": 2, "footprint_half_angle_mrad": 0.3,
             "fov_half_angle_mrad": 0.4, "receiver_area_m2": 0.1},
            (50, 50, 10), (0, 0, -1), wavelength_nm=905,
        )
    # a file the system cannot read is an I/O error, an OSError as Python's own are
    with pytest.raises(lidarsim.IoError) as e:
        lidarsim.Scene.load(tmp_path / "none.yaml")
    assert e.value.file.endswith("none.yaml")


def test_damaged_files_are_data_errors(tmp_path):
    run = lidarsim.run(
        dict(als_campaign(), products={"points": True}),
        out=tmp_path / "r",
        stages=["plan", "simulate", "products"],
    )
    (run.folder / "pulses.parquet").write_bytes(b"not parquet")
    with pytest.raises(lidarsim.DataError) as e:
        run.pulses()
    assert e.value.file.endswith("pulses.parquet")
    assert e.value.advice
    with pytest.raises(lidarsim.InputError):
        run.photons()  # a discrete-return run writes none: the message says which stage would
    # a waveform part whose bytes are not those its checksum records is not handed over
    part = run.folder / "waveforms" / "part-00000.parquet"
    data = bytearray(part.read_bytes())
    data[1000:1200] = bytes(b ^ 0xFF for b in data[1000:1200])
    part.write_bytes(bytes(data))
    with pytest.raises(lidarsim.DataError) as e:
        run.waveforms()
    assert e.value.file.endswith("part-00000.parquet") and "part-00000.fnv" in str(e.value)
    # a manifest that is JSON but no lidarsim manifest
    (run.folder / "manifest.json").write_text("{}")
    with pytest.raises(lidarsim.DataError):
        lidarsim.open_run(run.folder)


def test_the_stubs_name_every_public_name():
    """lidarsim/__init__.pyi (stubgen's, with the attributes of Waveform) declares every name
    the package exports, and every attribute a Waveform has."""
    import ast
    from pathlib import Path

    stub = ast.parse((Path(lidarsim.__file__).parent / "__init__.pyi").read_text())
    declared = set()
    for node in ast.walk(stub):
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            declared.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            declared.add(node.target.id)
    missing = [n for n in lidarsim.__all__ if n not in declared and n not in dir(lidarsim.errors)]
    assert not missing, missing
    assert not [a for a in lidarsim.Waveform.__slots__ if a not in declared]


def test_arguments_of_the_wrong_kind_are_input_errors(tmp_path):
    camp = als_campaign()
    for kwargs, key in [
        (dict(threads=-1), "threads"),
        (dict(threads="2"), "threads"),
        (dict(shard=(-1, 2)), "shard"),
        (dict(shard=(0.5, 2)), "shard"),
        (dict(shard=3), "shard"),
        (dict(threads=0), "threads"),
        (dict(threads=10**9), "threads"),
        (dict(shard=(3, 2)), "shard"),
        (dict(stages=["bogus"]), "stages"),
        (dict(stages=5), "stages"),
        (dict(overrides=[1, 2]), "overrides"),
        (dict(overrides={"": 1}), "overrides"),
        (dict(out=5), "out"),
    ]:
        args = dict(out=tmp_path / "x")
        args.update(kwargs)
        with pytest.raises(lidarsim.InputError) as e:
            lidarsim.run(camp, **args)
        assert e.value.key == key, (kwargs, e.value)
    # a path of the wrong kind, wherever one is asked for
    for call, key in [
        (lambda: lidarsim.run(5), "campaign"),
        (lambda: lidarsim.run(None), "campaign"),
        (lambda: lidarsim.open_run(3), "folder"),
        (lambda: lidarsim.check(7), "campaign"),
        (lambda: lidarsim.compare([3]), "runs"),
        (lambda: lidarsim.compare(None), "runs"),
        (lambda: lidarsim.compare(b"runs"), "runs"),
        (lambda: lidarsim.Scene.load(3), "path"),
        (lambda: lidarsim.Scene.load(PLANE, wavelength_nm="x"), "wavelength_nm"),
    ]:
        with pytest.raises(lidarsim.InputError) as e:
            call()
        assert e.value.key == key, (key, e.value)
    bad = als_campaign()
    bad["platform"]["altitude_m"] = float("nan")
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.run(bad, out=tmp_path / "nan")
    assert e.value.key == "campaign"
    # a path and numpy numbers are values a mapping may hold; "plan" is one stage
    import numpy as np

    ok = als_campaign()
    ok["scene"] = FOREST
    ok["seed"] = np.int64(3)
    ok["instrument"]["bin_ns"] = np.float32(0.5)
    r = lidarsim.run(ok, out=tmp_path / "np", stages="plan")
    assert r.pulses().num_rows > 0 and "simulate" not in r.manifest["stages"]
    plane = lidarsim.Scene.load(PLANE)
    inst = {"pulse_energy_j": 1e-3, "pulse_fwhm_ns": 2, "footprint_half_angle_mrad": 0.3,
            "fov_half_angle_mrad": 0.4, "receiver_area_m2": 0.1}
    for kwargs, key in [
        (dict(seed=-1), "seed"),
        (dict(rays=2**70), "rays"),
        (dict(origin=(1, 2)), "origin"),
        (dict(wavelength_nm="1064"), "wavelength_nm"),
    ]:
        args = dict(origin=(50, 50, 10), direction=(0, 0, -1))
        args.update(kwargs)
        with pytest.raises(lidarsim.InputError) as e:
            plane.simulate_pulse(inst, **args)
        assert e.value.key == key, (kwargs, e.value)
    for call, key in [
        (lambda: plane.simulate_pulse(5, (50, 50, 10), (0, 0, -1)), "instrument"),
        (lambda: plane.simulate_pulse(inst, (50, 50, 10), (0, 0, -1), sun=[1]), "sun"),
        (lambda: plane.simulate_pulse(inst, (50, 50, 10), (0, 0, -1), simulation=5), "simulation"),
        (lambda: plane.simulate_pulse(inst, (50, 50, 10), (0, 0, -1), record="yes"), "record"),
        # the one-pulse campaign's keys, said as the arguments that gave them
        (lambda: plane.simulate_pulse(inst, (50, 50, 10), (0, 0, 0)), "direction"),
        (lambda: plane.simulate_pulse(inst, (50, 50, 10), (0, 0, -1), rays=0), "rays"),
        (lambda: plane.simulate_pulse(inst, (50, 50, 10), (0, 0, -1), method=5), "method"),
        (lambda: lidarsim.run(camp, out=tmp_path / "r", resume="no"), "resume"),
        (lambda: lidarsim.run(camp, out=tmp_path / "r", stages={}), "stages"),
    ]:
        with pytest.raises(lidarsim.InputError) as e:
            call()
        assert e.value.key == key, (key, e.value)
        assert "simulate_pulse:" not in str(e.value), e.value
    with pytest.raises(lidarsim.InputError):
        r.waveforms([-1])
    with pytest.raises(lidarsim.InputError) as e:
        r.waveforms(3)
    assert e.value.key == "pulse_ids"
    # one run folder given alone is that run, not the characters of its name
    assert lidarsim.compare(r.folder).num_rows == 1
    # a gate no memory holds is refused, as a run of the same campaign is, not attempted
    with pytest.raises(lidarsim.InputError) as e:
        plane.simulate_pulse(dict(inst, bin_ns=1e-30), (50, 50, 10), (0, 0, -1), rays=20)
    assert e.value.key == "instrument.bin_ns"


def test_numbers_past_64_bits_and_arguments_given_twice(tmp_path):
    # a whole number no 64-bit integer holds, in an override, a mapping or a section
    # (read as a YAML reader reads 10**20, a number: a key that wants a whole one says so)
    for call in (
        lambda: lidarsim.run(als_campaign(), out=tmp_path / "x", overrides={"seed": 2**64}),
        lambda: lidarsim.run(dict(als_campaign(), seed=2**64), out=tmp_path / "y"),
    ):
        with pytest.raises(lidarsim.InputError) as e:
            call()
        assert e.value.key == "seed" and "whole number" in str(e.value), e.value
    plane = lidarsim.Scene.load(PLANE)
    inst = {"pulse_energy_j": 1e-3, "pulse_fwhm_ns": 3, "footprint_half_angle_mrad": 0.2,
            "fov_half_angle_mrad": 0.4, "receiver_area_m2": 0.1}
    with pytest.raises(lidarsim.InputError) as e:
        plane.simulate_pulse(dict(inst, max_returns=2**64), (0, 0, 10), (0, 0, -1))
    assert e.value.key == "instrument.max_returns", e.value
    # a number-valued key takes one past 64 bits as the number it is
    plane.simulate_pulse(dict(inst, receiver_area_m2=10**20), (0, 0, 10), (0, 0, -1), rays=10)
    # method, rays and max_order are simulate_pulse's own arguments, not also simulation keys
    with pytest.raises(lidarsim.InputError) as e:
        plane.simulate_pulse(inst, (0, 0, 10), (0, 0, -1), simulation={"method": "forward"})
    assert e.value.key == "simulation" and "method=" in str(e.value)
    for bad in ([], -1, True):
        with pytest.raises(lidarsim.InputError) as e:
            lidarsim.Scene.load(PLANE, wavelength_nm=bad)
        assert e.value.key == "wavelength_nm", (bad, e.value)
    with pytest.raises(lidarsim.InputError) as e:
        plane.simulate_pulse(inst, (0, 0, 10), (0, 0, -1), wavelength_nm=None)
    assert e.value.key == "wavelength_nm"
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.run(als_campaign(), out="")
    assert e.value.key == "out"


def test_an_override_of_the_wrong_type_names_its_key(tmp_path):
    with pytest.raises(lidarsim.InputError) as e:
        lidarsim.run(als_campaign(), out=tmp_path / "o", overrides={"platform.altitude_m": "high"})
    assert e.value.key == "platform.altitude_m"
    assert "expected a number" in str(e.value)


def test_a_damaged_manifest_is_a_data_error(tmp_path):
    r = lidarsim.run(als_campaign(), out=tmp_path / "m", stages=["plan"])
    (r.folder / "manifest.json").write_text("[1, 2]")
    with pytest.raises(lidarsim.DataError):
        r.manifest
    (r.folder / "manifest.json").write_text("{ not json")
    with pytest.raises(lidarsim.DataError):
        lidarsim.open_run(r.folder).manifest
