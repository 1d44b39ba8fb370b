"""The exceptions lidarsim raises: one base class, one class per kind of problem.

Every error carries the CLI's one-line message as ``str(err)`` and, where known, where the
problem is (``file``, ``line``, ``column``, ``key``) and what to do about it (``advice``).
"""

from __future__ import annotations

from typing import Optional

__all__ = ["LidarsimError", "InputError", "DataError", "IoError"]


class LidarsimError(Exception):
    """Base class of every lidarsim error."""

    #: The file the problem is in, when there is one.
    file: Optional[str] = None
    #: 1-based line and column in that file, when the place is known.
    line: Optional[int] = None
    column: Optional[int] = None
    #: The dotted key path (``platform.altitude_m``), when one key's value is wrong.
    key: Optional[str] = None
    #: What to do about it, when the message alone does not say.
    advice: Optional[str] = None


class InputError(LidarsimError, ValueError):
    """A campaign, scene, table or argument is wrong: the message says what to change."""


class DataError(LidarsimError):
    """A file lidarsim reads back (a run folder's parts, manifest, products) is damaged or
    not its own: run the stage that writes it again (``resume=True`` redoes what it cannot
    trust)."""


class IoError(LidarsimError, OSError):
    """The system refused a read or a write (a missing file, permissions, a full disk)."""
