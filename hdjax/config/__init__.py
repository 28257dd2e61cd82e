"""Experiment files, the data they describe, the steps they run, and saved models.

- [`hdjax.config.load_experiment`][]: read and validate a TOML experiment file (line and
  column on syntax errors, "did you mean" for unknown tables and keys), defaults filled in.
- [`hdjax.config.build_dataset`][]: the calibration and test recordings of an experiment
  (plant scenarios, files through a column map, or synthetic); with `[fit] chunk` on files a
  [`hdjax.config.StreamedDataset`][] that reads them chunk by chunk.
- [`hdjax.config.save_model`][] / [`hdjax.config.load_model`][]: a calibrated model in one file.
- [`hdjax.config.preflight`][]: the checks of a resolved config (or one `--set` or sweep member)
  before any work: the model can be built, the data fits in memory.
- `hdjax.config.SCHEMA`: every table and key, with defaults.
"""

from ._dataset import (
    Dataset as Dataset,
    build_dataset as build_dataset,
    column_map as column_map,
    synthetic_recording as synthetic_recording,
)
from ._load import (
    Experiment as Experiment,
    dumps_toml as dumps_toml,
    experiment_from_dict as experiment_from_dict,
    load_experiment as load_experiment,
    parse_toml as parse_toml,
    parse_value as parse_value,
    with_absolute_paths as with_absolute_paths,
)
from ._preflight import check_memory as check_memory, preflight as preflight
from ._saved_model import (
    FORMAT_VERSION as FORMAT_VERSION,
    SavedModel as SavedModel,
    check_compatible as check_compatible,
    load_model as load_model,
    save_model as save_model,
)
from ._schema import (
    SCHEMA as SCHEMA,
    apply_setting as apply_setting,
    check_sweep_setting as check_sweep_setting,
    resolve as resolve,
    sweepable_settings as sweepable_settings,
)
from ._streamed import StreamedDataset as StreamedDataset
