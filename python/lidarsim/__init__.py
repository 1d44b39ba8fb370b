"""lidarsim: physically based LiDAR simulation, from Python.

Two ways in:

* campaigns, as the ``lidarsim`` command runs them: :func:`run` writes a run folder and
  returns a :class:`Run`, whose tables come back as ``pyarrow.Table`` (:func:`open_run` opens
  an existing folder; :func:`check` and :func:`compare` are the commands of the same names);
* single pulses in memory, for retrieval loops: :meth:`Scene.load` builds a scene once and
  :meth:`Scene.simulate_pulse` returns a :class:`Waveform` of numpy arrays.

Every name here is a thin layer over the compiled core (``lidarsim._lidarsim``), which is
the same library the command line runs: the same campaigns give the same files. Progress goes
to the ``lidarsim`` logger of :mod:`logging`; errors are :class:`LidarsimError` subclasses.
"""

from __future__ import annotations

import json
import logging
import math
import numbers
import operator
import os
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from . import _lidarsim
from .errors import DataError, InputError, IoError, LidarsimError

__all__ = [
    "__version__",
    "run",
    "open_run",
    "check",
    "compare",
    "Run",
    "Scene",
    "Waveform",
    "LidarsimError",
    "InputError",
    "DataError",
    "IoError",
]

#: The version of the compiled core (the Rust crate's).
__version__: str = _lidarsim.version()

# a library's logger stays quiet until the application configures logging
logging.getLogger("lidarsim").addHandler(logging.NullHandler())

PathLike = Union[str, "os.PathLike[str]"]


def _bad(key: str, message: str) -> InputError:
    """An :class:`InputError` for a bad argument, named by ``key``."""
    err = InputError(f"{key}: {message}")
    err.key = key
    return err


def _whole(value: Any, key: str, least: int = 0, most: int = 2**64 - 1) -> int:
    """A whole number (a Python or numpy integer, not a bool or a float) from ``least`` to
    ``most``, or an :class:`InputError` naming ``key``."""
    top = "2^64 - 1" if most == 2**64 - 1 else str(most)
    try:
        if isinstance(value, bool):
            raise TypeError
        n = operator.index(value)
    except TypeError:
        raise _bad(key, f"expected a whole number from {least} to {top}, found {value!r}") from None
    if not least <= n <= most:
        raise _bad(key, f"expected a whole number from {least} to {top}, found {n}")
    return n


def _path(value: Any, key: str) -> str:
    """A file or folder path (a ``str`` or an ``os.PathLike``), or an :class:`InputError`
    naming ``key``."""
    if isinstance(value, (str, os.PathLike)):
        p = os.fspath(value)
        if isinstance(p, str):
            return p
    raise _bad(key, f"expected a path (a str or a pathlib.Path), found {value!r}")


def _folder(value: Any, key: str) -> str:
    """A folder path, not empty (an empty one would be the current folder, unasked)."""
    p = _path(value, key)
    if not p:
        raise _bad(key, "expected a folder path, found an empty one")
    return p


def _mapping(value: Any, key: str) -> Dict[str, Any]:
    """A mapping's items as a dict, or an :class:`InputError` naming ``key``."""
    if isinstance(value, Mapping):
        return dict(value)
    raise _bad(key, f"expected a mapping of keys to values, found {value!r}")


def _flag(value: Any, key: str) -> bool:
    """``True`` or ``False`` (a numpy bool too), or an :class:`InputError` naming ``key``:
    ``bool("no")`` is true."""
    # numpy's bool is `bool_` in numpy 1 and `bool` in numpy 2
    if isinstance(value, bool) or (
        type(value).__module__ == "numpy" and type(value).__name__ in ("bool_", "bool")
    ):
        return bool(value)
    raise _bad(key, f"expected True or False, found {value!r}")


def _overrides(value: Any) -> Dict[str, Any]:
    """``run``'s overrides: a mapping of dotted campaign keys (none empty) to values."""
    items = _mapping(value, "overrides")
    bad = [k for k in items if not isinstance(k, str) or not k.strip()]
    if bad:
        raise _bad("overrides", f"expected dotted campaign keys (platform.altitude_m), found {bad[0]!r}")
    return items


def _point(value: Any, key: str) -> Tuple[float, float, float]:
    """Three finite numbers, or an :class:`InputError` naming ``key``."""
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise _bad(key, f"expected three finite numbers (x, y, z), found {value!r}")
    return v  # type: ignore[return-value]


def _plain(value: Any) -> Any:
    """What ``json`` cannot write itself but a campaign value can be: a path, a numpy
    scalar or array."""
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if getattr(value, "shape", None) == () and callable(getattr(value, "item", None)):
        return value.item()
    if callable(getattr(value, "tolist", None)):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a number, a string, a list or a mapping")


def _in_64_bits(value: Any) -> Any:
    """``value`` with every whole number no 64-bit integer holds made a float, as a YAML
    reader takes 10**20: a key that wants a number takes it, one that wants a whole number
    says so at its own name (the core's reader has no integers past 64 bits)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return value if -(2**63) <= value < 2**64 else float(value)
    if isinstance(value, Mapping):
        return {k: _in_64_bits(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_in_64_bits(v) for v in value]
    return value


def _json(value: Any, key: str, indent: Optional[int] = None) -> str:
    """``value`` as the JSON the core reads, or an :class:`InputError` naming ``key``."""
    value = _in_64_bits(value)
    try:
        return json.dumps(value, default=_plain, allow_nan=False, indent=indent)
    except ValueError:
        raise _bad(key, "NaN and infinity are not values a campaign can hold") from None
    except TypeError as e:
        raise _bad(key, str(e)) from None


def _table(stream: Any) -> "pyarrow.Table":  # noqa: F821
    """A ``pyarrow.Table`` from the core's Arrow C stream (no copy of the columns)."""
    import pyarrow as pa

    return pa.RecordBatchReader.from_stream(stream).read_all()


def _array(data: bytearray, dtype: str = "<f8") -> "numpy.ndarray":  # noqa: F821
    """A writable numpy array over the bytes the core made (no copy)."""
    import numpy as np

    return np.frombuffer(data, dtype=dtype)


def run(
    campaign: Union[PathLike, Mapping[str, Any]],
    out: Optional[PathLike] = None,
    threads: Optional[int] = None,
    resume: bool = False,
    stages: Optional[Sequence[str]] = None,
    shard: Optional[Tuple[int, int]] = None,
    overrides: Optional[Mapping[str, Any]] = None,
    base_dir: Optional[PathLike] = None,
) -> "Run":
    """Runs a campaign into its run folder, as ``lidarsim run`` does, and returns the run.

    Args:
        campaign: a campaign file, or a mapping holding the campaign's YAML (its relative
            paths resolve against ``base_dir``, else the current directory).
        out: the run folder; default ``runs/<name>``, as the command line.
        threads: worker threads; default all cores. The files do not depend on it.
        resume: keep completed stages and the waveform parts whose inputs are unchanged.
        stages: the stages to run (``"plan"``, ``"simulate"``, ``"products"``,
            ``"report"``), as a list or as the command line's ``"plan,simulate"``; default
            all.
        shard: ``(k, n)``: simulate only the parts whose index is k modulo n.
        overrides: dotted keys and values applied before validation, as in a sweep:
            ``{"platform.altitude_m": 500}``.
        base_dir: where a mapping's relative paths resolve.

    The interpreter is released while the run works, and its progress goes to the
    ``lidarsim`` logger. Ctrl-C stops it at the next part boundary, with every finished part
    kept, and then raises ``KeyboardInterrupt``: run again with ``resume=True`` to finish.

    Raises:
        InputError: the campaign or an argument is wrong (``err.file``, ``err.line``,
            ``err.key`` say where).
        IoError, DataError: a file could not be written, or one read back is damaged.
    """
    if isinstance(stages, str):
        # "plan,simulate", as the command line takes it
        stages = [s.strip() for s in stages.split(",") if s.strip()]
    if stages is not None:
        names = list(stages) if isinstance(stages, Iterable) else None
        if names is None or isinstance(stages, Mapping) or not all(isinstance(s, str) for s in names):
            raise _bad("stages", f"expected stage names (plan, simulate, products, report), found {stages!r}")
        stages = names
    if shard is not None:
        if isinstance(shard, (str, bytes)) or not isinstance(shard, Sequence) or len(shard) != 2:
            raise _bad("shard", f"expected (k, n), two whole numbers, found {shard!r}")
        shard = (_whole(shard[0], "shard"), _whole(shard[1], "shard"))
    kwargs: Dict[str, Any] = dict(
        out=None if out is None else _folder(out, "out"),
        threads=None if threads is None else _whole(threads, "threads", least=1),
        resume=_flag(resume, "resume"),
        stages=None if stages is None else list(stages),
        shard=shard,
        overrides=None if overrides is None else _json(_overrides(overrides), "overrides"),
    )
    if isinstance(campaign, Mapping):
        base = Path(_path(base_dir, "base_dir")) if base_dir is not None else Path.cwd()
        summary = _lidarsim.run(
            text=_json(campaign, "campaign", indent=2),
            label=os.fspath(base / "<campaign>"),
            **kwargs,
        )
    else:
        summary = _lidarsim.run(path=_path(campaign, "campaign"), **kwargs)
    r = Run(summary["out"])
    r.summary = summary
    return r


def open_run(folder: PathLike) -> "Run":
    """An existing run folder (one ``lidarsim run`` or :func:`run` wrote), or a sweep's
    folder (its runs in :attr:`Run.sweep`)."""
    r = Run(_path(folder, "folder"))
    if not r.sweep:
        _lidarsim.read_run(os.fspath(r.folder), "manifest")  # checks that it is a run folder
    return r


def check(campaign: PathLike) -> Dict[str, Any]:
    """What ``lidarsim check`` prints, as a dict: the campaign validated, its scene loaded
    and measured, the run's memory and time estimated. Keys include ``pulses``,
    ``instances``, ``triangles`` (instanced), ``distinct_triangles``, ``memory_bound_mib``,
    ``estimated_time_s`` and ``warnings``."""
    return json.loads(_lidarsim.check(_path(campaign, "campaign")))


def compare(runs: Iterable[PathLike]) -> "pyarrow.Table":  # noqa: F821
    """The table of ``lidarsim compare`` (the columns of its ``--csv``), one row per run; a
    sweep's folder stands for its sub-runs."""
    if isinstance(runs, (str, os.PathLike)):
        # one run folder, not the characters of its name
        runs = [runs]
    if not isinstance(runs, Iterable) or isinstance(runs, (bytes, Mapping)):
        raise _bad("runs", f"expected run folders (a list of paths), found {runs!r}")
    return _table(_lidarsim.compare([_path(r, "runs") for r in runs]))


#: The keys of the one-pulse campaign ``Scene.simulate_pulse`` makes, by the argument that
#: gives each.
_PULSE_ARGUMENTS = {
    "simulation.rays_per_pulse": "rays",
    "simulation.method": "method",
    "simulation.max_order": "max_order",
    "platform.pulses[0].position": "origin",
    "platform.pulses[0].direction": "direction",
    "seed": "seed",
}


def _argument_error(e: InputError) -> InputError:
    """An error in the one-pulse campaign ``simulate_pulse`` makes, said of its arguments: the
    key as the argument that gave it, without the place in a text the caller never saw. An
    error in a file of the caller's (the scene's materials) is theirs as it stands."""
    if e.file is not None and e.file != "simulate_pulse":
        return e
    key = e.key
    text = str(e)
    if key and f"{key}: " in text:
        text = text.split(f"{key}: ", 1)[1]
    if not key:
        # no key: the place in the internal text is all there was to drop
        err = InputError(text.split(": ", 1)[-1] if str(e).startswith("simulate_pulse") else text)
    else:
        err = _bad(_PULSE_ARGUMENTS.get(key, key), text)
    err.advice = e.advice
    return err


class Run:
    """A run folder: its files as tables, dicts and text.

    Tables are ``pyarrow.Table``; every read goes to the files, so a run resumed elsewhere
    is seen as it is now.
    """

    def __init__(self, folder: PathLike) -> None:
        #: The run folder.
        self.folder: Path = Path(_path(folder, "folder"))
        #: What :func:`run` returned for this run (None for :func:`open_run`): ``pulses``,
        #: ``rays``, ``seconds``, ``parts_done``, ``complete``.
        self.summary: Optional[Dict[str, Any]] = None

    def __repr__(self) -> str:
        return f"lidarsim.Run({str(self.folder)!r})"

    @property
    def sweep(self) -> List["Run"]:
        """A sweep's runs, one per combination, in order (a sweep's folder holds them in
        sub-folders, listed in its ``sweep.json``); empty for a single run."""
        index = self.folder / "sweep.json"
        if not index.is_file():
            return []
        try:
            names = json.loads(index.read_text())["sweep"]
            ok = isinstance(names, list) and all(
                isinstance(n, str) and n not in ("", ".", "..") and not any(c in n for c in "/\\\0")
                for n in names
            )
        except (ValueError, KeyError, TypeError):
            ok = False
        if not ok:
            err = DataError(
                f"{index}: not a sweep's index (cut short, edited, or naming folders outside "
                "the sweep's); run the sweep's campaign again with resume=True"
            )
            err.file = str(index)
            raise err
        return [Run(self.folder / name) for name in names]

    def _not_a_sweep(self, what: str) -> None:
        """An :class:`InputError` when this folder is a sweep's, which holds no run itself."""
        if (self.folder / "sweep.json").is_file() and not (self.folder / "manifest.json").exists():
            raise _bad(
                "folder",
                f"{self.folder} is a sweep's folder, with no run of its own: ask one of its runs "
                f"for its {what} (Run.sweep, one per combination: run.sweep[0])",
            )

    def _read(self, what: str, pulse_ids: Optional[List[int]] = None) -> Any:
        self._not_a_sweep(what)
        return _lidarsim.read_run(os.fspath(self.folder), what, pulse_ids)

    @property
    def campaign(self) -> Dict[str, Any]:
        """``campaign.resolved.yaml``: the campaign with every default filled in, as a YAML
        reader gives it (a table's wavelength keys stay numbers)."""
        return self._read("campaign")

    @property
    def manifest(self) -> Dict[str, Any]:
        """``manifest.json``: per stage, its status, inputs' fingerprint, outputs, times."""
        return json.loads(self._read("manifest"))

    @property
    def report(self) -> str:
        """``report.md``: the human summary."""
        return self._read("report")

    def pulses(self) -> "pyarrow.Table":  # noqa: F821
        """``pulses.parquet``: the planned pulses."""
        return _table(self._read("pulses"))

    def waveforms(self, pulse_ids: Optional[Iterable[int]] = None) -> "pyarrow.Table":  # noqa: F821
        """The waveform parts' rows, in pulse order: all of them, or those of ``pulse_ids``
        (one row per pulse and band)."""
        if pulse_ids is not None and not isinstance(pulse_ids, Iterable):
            raise _bad("pulse_ids", f"expected a list of pulse ids, found {pulse_ids!r}")
        ids = None if pulse_ids is None else [_whole(i, "pulse_ids") for i in pulse_ids]
        return _table(self._read("waveforms", ids))

    def points(self) -> "pyarrow.Table":  # noqa: F821
        """The discrete returns of ``points.las`` or ``points.laz``: x, y, z (in the frame's
        CRS when the campaign has one), gps_time, return_number, number_of_returns,
        classification, intensity, apparent_reflectance, pulse_id, scan_angle_deg,
        point_source_id (+ wavelength_nm with several bands)."""
        return _table(self._read("points"))

    def photons(self) -> "pyarrow.Table":  # noqa: F821
        """``photons.parquet``: the photon-counting events."""
        return _table(self._read("photons"))

    def dsm(self) -> Dict[str, Any]:
        """The DSM rasters: ``dsm``, ``reference`` and ``difference`` (2-D float32 numpy
        arrays, north row first, NaN where there is no data), ``transform`` (GDAL's
        geotransform) and ``crs`` (``"EPSG:N"``, or None in local metres)."""
        self._not_a_sweep("dsm")
        rasters = _lidarsim.read_dsm(os.fspath(self.folder))
        out: Dict[str, Any] = {}
        for name, (cells, height, width, transform, epsg) in rasters.items():
            out[name] = _array(cells, "<f4").reshape(height, width)
            if name == "dsm":
                out["transform"] = tuple(transform)
                out["crs"] = None if epsg is None else f"EPSG:{epsg}"
        return out


class Waveform:
    """One pulse's waveform, simulated in memory (:meth:`Scene.simulate_pulse`).

    Attributes:
        t0_ns: time of the start of bin 0 after emission, ns.
        bin_ns: bin width, ns.
        wavelength_nm: the band.
        energy_j: received laser energy per bin before pulse convolution (the impulse
            response), J.
        energy_se_j: its standard error per bin, J.
        photons: mean laser photons per bin at the detector, pulse-convolved, no noise.
        order_energy_j: received energy by scattering order (index 0 = order 1), J; and
            ``order_energy_se_j`` its standard errors.
        received_energy_j: total received laser energy, all orders, in or out of the gate;
            ``received_energy_se_j`` its standard error; ``outside_gate_energy_j`` the part
            outside the gate.
        solar_photons_per_bin: mean solar photons per bin (0 without a sun).
        rays: ray samples traced.
        record: with ``record=True``, what the detector records: the instrument's shot and
            electronic noise, detector response and digitiser applied (counts with a
            digitiser, photoelectrons without); ``record_background`` the mean of a sample
            with no laser signal, in the same units. None otherwise.
    """

    __slots__ = (
        "t0_ns",
        "bin_ns",
        "wavelength_nm",
        "energy_j",
        "energy_se_j",
        "photons",
        "order_energy_j",
        "order_energy_se_j",
        "received_energy_j",
        "received_energy_se_j",
        "outside_gate_energy_j",
        "solar_photons_per_bin",
        "rays",
        "record",
        "record_background",
    )

    def __init__(self, raw: Dict[str, Any]) -> None:
        arrays = ("energy_j", "energy_se_j", "photons", "order_energy_j", "order_energy_se_j")
        for name in self.__slots__:
            v = raw.get(name)
            if name in arrays or (name == "record" and v is not None):
                v = _array(v)
            setattr(self, name, v)

    @property
    def time_ns(self) -> "numpy.ndarray":  # noqa: F821
        """The centre of each bin after emission, ns."""
        import numpy as np

        return self.t0_ns + (np.arange(len(self.photons)) + 0.5) * self.bin_ns

    @property
    def range_m(self) -> "numpy.ndarray":  # noqa: F821
        """The range of each bin's centre, c t / 2, m (vacuum)."""
        return self.time_ns * 1e-9 * _lidarsim.C / 2.0

    def __repr__(self) -> str:
        return (
            f"lidarsim.Waveform({len(self.photons)} bins of {self.bin_ns} ns from "
            f"{self.t0_ns:.3f} ns, {self.wavelength_nm} nm, {self.rays} rays, "
            f"received {self.received_energy_j:.4e} J)"
        )


class Scene:
    """A scene loaded once (its BVHs built) and reused for many single pulses."""

    def __init__(self, native: Any) -> None:
        self._native = native

    @classmethod
    def load(
        cls, path: PathLike, wavelength_nm: Union[None, float, Sequence[float]] = None
    ) -> "Scene":
        """Loads a scene file (the ``scene:`` of a campaign).

        Materials are resolved at ``wavelength_nm`` (one or several bands); by default at a
        wavelength every material of the file gives. A pulse at another band loads the
        scene again for it, once, and keeps it.
        """
        bands = None
        if wavelength_nm is not None:
            several = not isinstance(wavelength_nm, (str, bytes)) and isinstance(wavelength_nm, Iterable)
            # a numpy scalar or 0-d array is a number
            if getattr(wavelength_nm, "shape", None) == () and callable(getattr(wavelength_nm, "item", None)):
                wavelength_nm, several = wavelength_nm.item(), False
            values = list(wavelength_nm) if several else [wavelength_nm]
            try:
                if any(isinstance(w, (bool, str, bytes)) for w in values):
                    raise TypeError
                bands = [float(w) for w in values]
            except (TypeError, ValueError):
                bands = []
            if not bands or not all(math.isfinite(w) and w > 0 for w in bands):
                raise _bad(
                    "wavelength_nm",
                    f"expected a wavelength in nm above 0, or a list of them, found {wavelength_nm!r}",
                )
        return cls(_lidarsim.Scene.load(_path(path, "path"), bands))

    @property
    def path(self) -> str:
        """The scene file."""
        return self._native.path

    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """((xmin, ymin, zmin), (xmax, ymax, zmax)), scene coordinates, metres."""
        return self._native.bounds

    def simulate_pulse(
        self,
        instrument: Mapping[str, Any],
        origin: Sequence[float],
        direction: Sequence[float],
        wavelength_nm: Union[float, Sequence[float]] = 1064,
        rays: int = 1000,
        method: str = "bdpt",
        max_order: int = 5,
        seed: int = 1,
        sun: Optional[Mapping[str, Any]] = None,
        atmosphere: Optional[Mapping[str, Any]] = None,
        record: bool = False,
        simulation: Optional[Mapping[str, Any]] = None,
    ) -> Union[Waveform, List[Waveform]]:
        """Simulates one pulse in memory and returns its waveform.

        The pulse is pulse 0 of a one-pulse static campaign over this scene with these
        settings: the same numbers as that campaign's waveform file (to float32).

        Args:
            instrument: the campaign's ``instrument:`` mapping, same keys.
            origin: the laser's position, scene coordinates, m.
            direction: the beam's direction (normalised here).
            wavelength_nm: the band; a list of bands returns a list of waveforms.
            rays: ray samples (``simulation.rays_per_pulse``).
            method: ``"bdpt"``, ``"forward"``, ``"backward"`` or ``"auto"``.
            max_order: the highest scattering order traced.
            seed: every random draw derives from it.
            sun, atmosphere: the campaign's ``sun:`` and ``atmosphere:`` mappings.
            record: also draw the instrument's noisy record (``Waveform.record``).
            simulation: further keys of the campaign's ``simulation:`` section
                (``sampler``, ``mis``, ``receiver_depth``).

        Raises:
            InputError: a key or value is wrong (``err.key`` names it).
            KeyboardInterrupt: Ctrl-C during the pulse, which drops it at its next chunk
                of rays (a pulse of many rays need not be waited for).
        """
        sim = {} if simulation is None else _mapping(simulation, "simulation")
        given = [k for k in ("method", "rays_per_pulse", "max_order") if k in sim]
        if given:
            raise _bad(
                "simulation",
                f"{given[0]} is an argument of simulate_pulse of its own (method=, rays=, max_order=): give it there",
            )
        sim.update(
            method=method,
            rays_per_pulse=_whole(rays, "rays", least=1, most=2**32 - 1),
            max_order=_whole(max_order, "max_order", least=1, most=100_000),
        )
        if getattr(wavelength_nm, "shape", None) == () and callable(getattr(wavelength_nm, "item", None)):
            wavelength_nm = wavelength_nm.item()
        if (
            wavelength_nm is None
            or isinstance(wavelength_nm, (str, bytes, bool))
            or not isinstance(wavelength_nm, (numbers.Real, Iterable))
        ):
            raise _bad("wavelength_nm", f"expected a number or a list of numbers, found {wavelength_nm!r}")
        several = not isinstance(wavelength_nm, numbers.Real)
        args = (
            _json(_mapping(instrument, "instrument"), "instrument"),
            _point(origin, "origin"),
            _point(direction, "direction"),
            _json(list(wavelength_nm) if several else wavelength_nm, "wavelength_nm"),
            _json(sim, "simulation"),
            _whole(seed, "seed"),
            None if sun is None else _json(_mapping(sun, "sun"), "sun"),
            None if atmosphere is None else _json(_mapping(atmosphere, "atmosphere"), "atmosphere"),
            _flag(record, "record"),
        )
        try:
            rows = self._native.simulate_pulse(*args)
        except InputError as e:
            raise _argument_error(e) from None
        waveforms = [Waveform(r) for r in rows]
        return waveforms if several else waveforms[0]

    def __repr__(self) -> str:
        return f"lidarsim.Scene({self.path!r})"
