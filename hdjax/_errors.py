"""One exception family for everything a user can get wrong.

Every problem with structure, shape, files, columns, keys and units is raised as a subclass of
[`hdjax.HdjaxError`][] in plain Python, before anything is traced, with a message that says what was
found, what was expected and how to fix it. The command line turns these into one line on stderr
and a non-zero exit; a traceback from hdjax means a bug.
"""


class HdjaxError(Exception):
    """Base class of every error hdjax raises on bad input."""


class DataError(HdjaxError, ValueError):
    """A recording, file or column is missing, malformed or inconsistent."""


class ConfigError(HdjaxError, ValueError):
    """A configuration file, table or key is missing, misspelt or out of range."""


class CalibrationError(HdjaxError, ValueError):
    """A calibration cannot be carried out (rank-deficient design, too few samples...)."""


class InversionError(HdjaxError, ValueError):
    """A calibrated compliance cannot be inverted for torque (not monotone in torque)."""


class ModelMismatchError(HdjaxError, ValueError):
    """A saved or fitted model does not match the data it is applied to."""


class DivergenceError(HdjaxError, RuntimeError):
    """An iterative fit or simulation diverged (non-finite loss or state)."""


class UnitWarning(UserWarning):
    """A signal's magnitude suggests a unit mix-up (degrees for radians, counts for radians)."""
