"""One exception family for everything a user can get wrong.

Every problem with structure, shape, files, columns, keys and units is raised as a subclass of
[`hdjax.HdjaxError`][] in plain Python, before anything is traced, with a message that says what was
found, what was expected and how to fix it. The command line turns these into one line on stderr
and a non-zero exit; a traceback from hdjax means a bug.
"""

import difflib


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


class ExportError(HdjaxError, ValueError):
    """A model cannot be exported to C (a term without C code, an estimate that reads ahead)."""


class DivergenceError(HdjaxError, RuntimeError):
    """An iterative fit or simulation diverged (non-finite loss or state)."""


class UnitWarning(UserWarning):
    """A signal's magnitude suggests a unit mix-up (degrees for radians, counts for radians)."""


def did_you_mean(name: str, options) -> str:
    """A ` (did you mean 'x'?)` hint, or an empty string when nothing is close."""
    options = list(options)
    same_but_case = [o for o in options if o.lower() == name.lower() and o != name]
    if same_but_case:  # 'theta_L' for 'theta_l' beats the equally close 'theta_m'
        return f" (did you mean {same_but_case[0]!r}?)"
    close = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_keys(table, known, where: str = "", *, inside: str = "", noun: str = "key") -> None:
    """Raise `ConfigError` for the first key of `table` not in `known`, with a "did you mean"
    hint and the known keys: `"{where}: unknown key 'x'{inside} (did you mean 'y'?); known keys:
    ..."` (`noun` renames "key", e.g. "plant parameter"; an empty `where` drops the prefix)."""
    known = list(known)
    prefix = f"{where}: " if where else ""
    for key in table:
        if key not in known:
            raise ConfigError(
                f"{prefix}unknown {noun} {key!r}{inside}{did_you_mean(str(key), known)}; known "
                f"{noun}s: {', '.join(map(str, known))}"
            )
