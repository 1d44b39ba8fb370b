"""Type stubs of the compiled core (python/src/lib.rs). Its callers are the package's own
modules: the public names, typed where they are defined, live in lidarsim/__init__.py."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

#: The speed of light in vacuum, m/s (the core's constant).
C: float

def version() -> str: ...
def run(
    path: Optional[str] = None,
    text: Optional[str] = None,
    label: Optional[str] = None,
    out: Optional[str] = None,
    threads: Optional[int] = None,
    resume: bool = False,
    stages: Optional[List[str]] = None,
    shard: Optional[Tuple[int, int]] = None,
    overrides: Optional[str] = None,
) -> Dict[str, Any]: ...
def check(path: str) -> str: ...
def compare(runs: List[str]) -> ArrowStream: ...
def read_run(folder: str, what: str, pulse_ids: Optional[List[int]] = None) -> Any: ...
def read_dsm(folder: str) -> Dict[str, Tuple[bytearray, int, int, List[float], Optional[int]]]: ...
def cli_main(argv: List[str]) -> int: ...

class ArrowStream:
    """A table handed over once through the Arrow C stream interface."""

    def __arrow_c_stream__(self, requested_schema: Optional[object] = None) -> object: ...

class Scene:
    @staticmethod
    def load(path: str, wavelengths_nm: Optional[List[float]] = None) -> "Scene": ...
    @property
    def path(self) -> str: ...
    @property
    def bounds(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]: ...
    def simulate_pulse(
        self,
        instrument: str,
        origin: Sequence[float],
        direction: Sequence[float],
        wavelength_nm: str,
        simulation: str,
        seed: int,
        sun: Optional[str] = None,
        atmosphere: Optional[str] = None,
        record: bool = False,
    ) -> List[Dict[str, Any]]: ...
