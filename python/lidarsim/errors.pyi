"""Type stubs of lidarsim.errors (stubgen, as __init__.pyi)."""

__all__ = ['LidarsimError', 'InputError', 'DataError', 'IoError']

class LidarsimError(Exception):
    file: str | None
    line: int | None
    column: int | None
    key: str | None
    advice: str | None

class InputError(LidarsimError, ValueError): ...
class DataError(LidarsimError): ...
class IoError(LidarsimError, OSError): ...
