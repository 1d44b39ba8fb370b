"""Type stubs of lidarsim.errors (stubgen, as __init__.pyi)."""

__all__ = ['LidarsimError', 'InputError', 'DataError', 'IoError']

class LidarsimError(Exception):
    """Base class of every lidarsim error."""
    file: str | None
    line: int | None
    column: int | None
    key: str | None
    advice: str | None

class InputError(LidarsimError, ValueError):
    """A campaign, scene, table or argument is wrong: the message says what to change."""
class DataError(LidarsimError):
    """A file lidarsim reads back (a run folder's parts, manifest, products) is damaged or
    not its own: run the stage that writes it again (``resume=True`` redoes what it cannot
    trust)."""
class IoError(LidarsimError, OSError):
    """The system refused a read or a write (a missing file, permissions, a full disk)."""
