"""Experiment files: read, validate and resolve them. Configuration only parses and validates;
it builds no model and reads no data.

- [`hdjax.config.load_experiment`][]: read and validate a TOML experiment file (line and
  column on syntax errors, "did you mean" for unknown tables and keys), defaults filled in.
- [`hdjax.config.resolve`][], [`hdjax.config.apply_setting`][]: a config's defaults filled in,
  one `--set` or sweep member applied.
- `hdjax.config.SCHEMA`: every table and key, with defaults.

The data an experiment describes and its model are built by [`hdjax.pipelines`][]
(`build_dataset`, `preflight`); calibrated models are saved and loaded by
[`hdjax.modelfile`][]. Their old names here (`hdjax.config.build_dataset`,
`hdjax.config.save_model`, ...) still work and warn (`DeprecationWarning`).
"""

import importlib as _importlib
import warnings as _warnings

from .._memory import check_memory as check_memory
from ._load import (
    Experiment as Experiment,
    column_map as column_map,
    dumps_toml as dumps_toml,
    experiment_from_dict as experiment_from_dict,
    load_experiment as load_experiment,
    parse_toml as parse_toml,
    parse_value as parse_value,
    with_absolute_paths as with_absolute_paths,
)
from ._schema import (
    SCHEMA as SCHEMA,
    apply_setting as apply_setting,
    check_sweep_setting as check_sweep_setting,
    resolve as resolve,
    sweepable_settings as sweepable_settings,
)

_MOVED = {
    "Dataset": "hdjax.pipelines",
    "StreamedDataset": "hdjax.pipelines",
    "build_dataset": "hdjax.pipelines",
    "preflight": "hdjax.pipelines",
    "synthetic_recording": "hdjax.pipelines",
    "FORMAT_VERSION": "hdjax.modelfile",
    "SavedModel": "hdjax.modelfile",
    "check_compatible": "hdjax.modelfile",
    "load_model": "hdjax.modelfile",
    "save_model": "hdjax.modelfile",
}


def __getattr__(name: str):
    # the names that build data and models, or save them, before they moved (see above)
    if name not in _MOVED:
        raise AttributeError(f"module 'hdjax.config' has no attribute {name!r}")
    _warnings.warn(
        f"hdjax.config.{name} has moved to {_MOVED[name]}.{name}; import it from there "
        "(configuration only parses and validates)",
        DeprecationWarning,
        stacklevel=2,
    )
    return getattr(_importlib.import_module(_MOVED[name]), name)
