"""The one place hdjax imports its heavy dependencies on first use, so `hdjax --version` and
`import hdjax` stay quick.

- `scipy.signal` (`scipy_signal()`): the filtered hand force of the plant's `fast` scenario.
- `pysindy` (`pysindy()`): the sparse selection of the residual loop.
- `dask.distributed` (`dask_distributed()`): the fleet command's cluster (the `fleet` extra).
- matplotlib: `hdjax._plotting.pyplot()`, which also selects the Agg backend.

`scipy.linalg` is light and imported at module level where it is used.
"""

from __future__ import annotations

import importlib

from ._errors import ConfigError


def _load(module: str, install: str):
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ConfigError(f"this needs {module} ({err}); install it with {install}") from err


def scipy_signal():
    """`scipy.signal`, imported on first use."""
    return _load("scipy.signal", "pip install scipy")


def pysindy():
    """`pysindy`, imported on first use (a core dependency, but a heavy import)."""
    return _load("pysindy", "pip install 'pysindy>=2.0,<2.2'")


def dask_distributed():
    """`dask.distributed`, imported on first use (the `fleet` extra)."""
    return _load("dask.distributed", "pip install 'hdjax[fleet]'")
