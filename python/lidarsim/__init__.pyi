"""Type stubs of the package (written by mypy's stubgen from lidarsim/__init__.py, with
its docstrings; regenerate with `stubgen -p lidarsim --include-docstrings` after changing a
signature there)."""

from .errors import DataError as DataError, InputError as InputError, IoError as IoError, LidarsimError as LidarsimError
import os
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence, Union

import numpy
import pyarrow

PathLike = Union[str, os.PathLike[str]]

__all__ = ['__version__', 'run', 'open_run', 'check', 'compare', 'Run', 'Scene', 'Waveform', 'LidarsimError', 'InputError', 'DataError', 'IoError']

__version__: str

def run(campaign: PathLike | Mapping[str, Any], out: PathLike | None = None, threads: int | None = None, resume: bool = False, stages: Sequence[str] | None = None, shard: tuple[int, int] | None = None, overrides: Mapping[str, Any] | None = None, base_dir: PathLike | None = None) -> Run:
    '''Runs a campaign into its run folder, as ``lidarsim run`` does, and returns the run.

    Args:
        campaign: a campaign file, or a mapping holding the campaign\'s YAML (its relative
            paths resolve against ``base_dir``, else the current directory).
        out: the run folder; default ``runs/<name>``, as the command line.
        threads: worker threads; default all cores. The files do not depend on it.
        resume: keep completed stages and the waveform parts whose inputs are unchanged.
        stages: the stages to run (``"plan"``, ``"simulate"``, ``"products"``,
            ``"report"``); default all.
        shard: ``(k, n)``: simulate only the parts whose index is k modulo n.
        overrides: dotted keys and values applied before validation, as in a sweep:
            ``{"platform.altitude_m": 500}``.
        base_dir: where a mapping\'s relative paths resolve.

    The interpreter is released while the run works, and its progress goes to the
    ``lidarsim`` logger. Ctrl-C stops it at the next part boundary, with every finished part
    kept, and then raises ``KeyboardInterrupt``: run again with ``resume=True`` to finish.

    Raises:
        InputError: the campaign or an argument is wrong (``err.file``, ``err.line``,
            ``err.key`` say where).
        IoError, DataError: a file could not be written, or one read back is damaged.
    '''
def open_run(folder: PathLike) -> Run:
    """An existing run folder (one ``lidarsim run`` or :func:`run` wrote), or a sweep's
    folder (its runs in :attr:`Run.sweep`)."""
def check(campaign: PathLike) -> dict[str, Any]:
    """What ``lidarsim check`` prints, as a dict: the campaign validated, its scene loaded
    and measured, the run's memory and time estimated. Keys include ``pulses``,
    ``instances``, ``triangles`` (instanced), ``distinct_triangles``, ``memory_bound_mib``,
    ``estimated_time_s`` and ``warnings``."""
def compare(runs: Iterable[PathLike]) -> pyarrow.Table:
    """The table of ``lidarsim compare`` (the columns of its ``--csv``), one row per run; a
    sweep's folder stands for its sub-runs."""

class Run:
    """A run folder: its files as tables, dicts and text.

    Tables are ``pyarrow.Table``; every read goes to the files, so a run resumed elsewhere
    is seen as it is now.
    """
    folder: Path
    summary: dict[str, Any] | None
    def __init__(self, folder: PathLike) -> None: ...
    @property
    def sweep(self) -> list['Run']:
        """A sweep's runs, one per combination, in order (a sweep's folder holds them in
        sub-folders, listed in its ``sweep.json``); empty for a single run."""
    @property
    def campaign(self) -> dict[str, Any]:
        """``campaign.resolved.yaml``: the campaign with every default filled in."""
    @property
    def manifest(self) -> dict[str, Any]:
        """``manifest.json``: per stage, its status, inputs' fingerprint, outputs, times."""
    @property
    def report(self) -> str:
        """``report.md``: the human summary."""
    def pulses(self) -> pyarrow.Table:
        """``pulses.parquet``: the planned pulses."""
    def waveforms(self, pulse_ids: Iterable[int] | None = None) -> pyarrow.Table:
        """The waveform parts' rows, in pulse order: all of them, or those of ``pulse_ids``
        (one row per pulse and band)."""
    def points(self) -> pyarrow.Table:
        """The discrete returns of ``points.las`` or ``points.laz``: x, y, z (in the frame's
        CRS when the campaign has one), gps_time, return_number, number_of_returns,
        classification, intensity, apparent_reflectance, pulse_id, scan_angle_deg,
        point_source_id (+ wavelength_nm with several bands)."""
    def photons(self) -> pyarrow.Table:
        """``photons.parquet``: the photon-counting events."""
    def dsm(self) -> dict[str, Any]:
        '''The DSM rasters: ``dsm``, ``reference`` and ``difference`` (2-D float32 numpy
        arrays, north row first, NaN where there is no data), ``transform`` (GDAL\'s
        geotransform) and ``crs`` (``"EPSG:N"``, or None in local metres).'''

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
    t0_ns: float
    bin_ns: float
    wavelength_nm: float
    energy_j: numpy.ndarray
    energy_se_j: numpy.ndarray
    photons: numpy.ndarray
    order_energy_j: numpy.ndarray
    order_energy_se_j: numpy.ndarray
    received_energy_j: float
    received_energy_se_j: float
    outside_gate_energy_j: float
    solar_photons_per_bin: float
    rays: int
    record: numpy.ndarray | None
    record_background: float | None
    def __init__(self, raw: dict[str, Any]) -> None: ...
    @property
    def time_ns(self) -> numpy.ndarray:
        """The centre of each bin after emission, ns."""
    @property
    def range_m(self) -> numpy.ndarray:
        """The range of each bin's centre, c t / 2, m (vacuum)."""

class Scene:
    """A scene loaded once (its BVHs built) and reused for many single pulses."""
    def __init__(self, native: Any) -> None: ...
    @classmethod
    def load(cls, path: PathLike, wavelength_nm: None | float | Sequence[float] = None) -> Scene:
        """Loads a scene file (the ``scene:`` of a campaign).

        Materials are resolved at ``wavelength_nm`` (one or several bands); by default at a
        wavelength every material of the file gives. A pulse at another band loads the
        scene again for it, once, and keeps it.
        """
    @property
    def path(self) -> str:
        """The scene file."""
    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """((xmin, ymin, zmin), (xmax, ymax, zmax)), scene coordinates, metres."""
    def simulate_pulse(self, instrument: Mapping[str, Any], origin: Sequence[float], direction: Sequence[float], wavelength_nm: float | Sequence[float] = 1064, rays: int = 1000, method: str = 'bdpt', max_order: int = 5, seed: int = 1, sun: Mapping[str, Any] | None = None, atmosphere: Mapping[str, Any] | None = None, record: bool = False, simulation: Mapping[str, Any] | None = None) -> Waveform | list[Waveform]:
        '''Simulates one pulse in memory and returns its waveform.

        The pulse is pulse 0 of a one-pulse static campaign over this scene with these
        settings: the same numbers as that campaign\'s waveform file (to float32).

        Args:
            instrument: the campaign\'s ``instrument:`` mapping, same keys.
            origin: the laser\'s position, scene coordinates, m.
            direction: the beam\'s direction (normalised here).
            wavelength_nm: the band; a list of bands returns a list of waveforms.
            rays: ray samples (``simulation.rays_per_pulse``).
            method: ``"bdpt"``, ``"forward"``, ``"backward"`` or ``"auto"``.
            max_order: the highest scattering order traced.
            seed: every random draw derives from it.
            sun, atmosphere: the campaign\'s ``sun:`` and ``atmosphere:`` mappings.
            record: also draw the instrument\'s noisy record (``Waveform.record``).
            simulation: further keys of the campaign\'s ``simulation:`` section
                (``sampler``, ``mis``, ``receiver_depth``).

        Raises:
            InputError: a key or value is wrong (``err.key`` names it).
        '''
