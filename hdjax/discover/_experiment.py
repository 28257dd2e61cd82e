"""The experiment-file lines that reproduce the residual loop's final model with `hdjax run`."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from .._joint import Joint
from ..config import dumps_toml

RUN_DATA_KEYS = ("columns", "extras", "encoding", "reference")
"""The `[data]` settings of a discover config that `hdjax run` reads the same way."""


def experiment_toml(
    joint: Joint, train: Path, test: Path, data: Mapping, *, name: str, out: str
) -> str:
    """An experiment file for `hdjax run`: `joint`, the `train` and `test` logs (absolute
    paths) read with `data`'s column map, and `[model] structure = "model.json"`, the loop's
    final model beside it, whose structure `hdjax run` calibrates on TRAIN by the loop's own
    fit ([`hdjax.discover.calibrate_structure`][]): the same model and the same TEST error.
    `out` is the result folder, for the command in the header."""
    doc = {
        "experiment": {
            "name": name,
            "description": "the final model of hdjax discover, calibrated by hdjax run",
        },
        "joint": joint.to_dict(),
        "data": {
            "kind": "files",
            "train": [os.path.normpath(train)],
            "test": [os.path.normpath(test)],
            **{k: data[k] for k in RUN_DATA_KEYS if k in data},
        },
        "model": {"structure": "model.json"},
        "network": {"enabled": False},
    }
    header = (
        "Written by hdjax discover: the final model's structure (model.json, beside this file)\n"
        "calibrated on TRAIN by hdjax run, scored on TEST:\n"
        f"  hdjax run {out}/experiment.toml --out {out}_run"
    )
    return dumps_toml(doc, header)
