"""Exceptions that carry what went wrong, so the CLI, the API and the worker can map them in one place.

InputError and its subclasses mean the user's input is bad: the API answers 4xx, the worker fails the job
at once with the message and does not retry. Anything else is unexpected and may be retried.
"""

from __future__ import annotations


class PdeanimError(Exception):
    """Base class of every error the library raises on purpose."""

    code = "error"


class InputError(PdeanimError):
    """The input (file, array, parameter) is invalid; retrying will not help."""

    code = "invalid_input"
    status = 422


class LimitError(InputError):
    """The input is valid but exceeds a configured limit (size, vertices, faces, frames)."""

    code = "limit_exceeded"
    status = 413

    def __init__(self, what: str, value: int | float, limit: int | float, setting: str | None = None):
        self.what, self.value, self.limit, self.setting = what, value, limit, setting
        hint = f" (setting {setting})" if setting else ""
        super().__init__(f"{what} is {value}, over the limit of {limit}{hint}")


class MeshInputError(InputError):
    """A mesh file cannot be read or is not a valid triangle mesh."""

    code = "invalid_mesh"


class PosesInputError(InputError):
    """Poses are malformed or do not match the mesh they belong to."""

    code = "invalid_poses"


class ParameterError(InputError):
    """A job or command parameter is out of range or inconsistent."""

    code = "invalid_parameter"


class ClipFormatError(InputError):
    """A clip file or coefficient blob cannot be decoded."""

    code = "invalid_clip"


class TetrahedralizationError(InputError):
    """The mesh could not be turned into a usable tetrahedral mesh."""

    code = "tetrahedralization_failed"


class TargetNotMetError(InputError):
    """A fit ended above its error target (the request did not ask for best effort); retrying will not
    help."""

    code = "target_not_met"
    status = 422


class OutOfMemoryError(PdeanimError, MemoryError):
    """The work needed more memory than the process may use (an allocation failed under its limit); retrying
    under the same limit fails the same way. A MemoryError too, so handlers of plain ones catch it.
    ``needed`` is the failed allocation in bytes (None if unknown), ``limit`` the limit in force in bytes
    (None if none was found)."""

    code = "out_of_memory"

    def __init__(self, message: str, needed: int | None = None, limit: int | None = None):
        self.needed, self.limit = needed, limit
        super().__init__(message)
