"""Saved models: a calibrated compliance model and, optionally, a trained network in one file.

- [`hdjax.modelfile.save_model`][] / [`hdjax.modelfile.load_model`][]: write and read the file
  (JSON, float64 values exact, a checksum over the rest).
- [`hdjax.modelfile.check_compatible`][]: refuse data a saved model cannot be applied to (another
  joint ratio, a missing column).
- [`hdjax.modelfile.SavedModel`][]: what a file holds; `FORMAT_VERSION`: the format it writes.
"""

from ._saved_model import (
    FORMAT_VERSION as FORMAT_VERSION,
    SavedModel as SavedModel,
    check_compatible as check_compatible,
    load_model as load_model,
    save_model as save_model,
)
