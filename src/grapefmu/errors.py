"""grapefmu's own error types, so callers can tell bad input from a solver failure."""
from __future__ import annotations


class GrapefmuError(Exception):
    """Base class of every error grapefmu raises on purpose."""


class SceneError(GrapefmuError, ValueError):
    """A scene value is missing, of the wrong type or outside its allowed range.

    `key` names the offending entry (for example ``berries[1].mass``) so that a
    user can find it in the TOML file without reading a traceback.
    """

    def __init__(self, key: str, message: str):
        self.key = key
        self.why = message
        super().__init__(f"{key}: {message}")


class SolverError(GrapefmuError, RuntimeError):
    """The integrator could not finish the requested interval.

    The solver state is left as it was before the failing call.
    """


class StateError(GrapefmuError, ValueError):
    """A solver state handed to set_state does not belong to this solver or is corrupt; the solver keeps its own."""


class RecordingError(GrapefmuError):
    """A recording cannot be written or read as asked (an unknown message field, a topic of another type,
    a file that is not a grapefmu MCAP recording)."""


class DataError(GrapefmuError, ValueError):
    """A measured time series (the CSV `grapefmu fit` reads) cannot be used as given; the message names the
    file, the column and the row."""
