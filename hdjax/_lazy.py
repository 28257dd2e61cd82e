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
import threading

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


def prefetch(*loaders) -> threading.Thread:
    """Run `loaders` (functions of this kind, e.g. `pysindy`) in a background thread.

    A command that will need a heavy module later starts its import now, so that it overlaps
    the command's own work on another core (pysindy and matplotlib take about 1.5 s of CPU
    together). Nothing is reported from the thread: a failing import fails again, with its
    message, where the module is used. Python's import locks make the later call wait for an
    import still in progress.
    """

    def work():
        for load in loaders:
            try:
                load()
            except Exception:  # noqa: BLE001 - reported by the call where the module is used
                pass

    thread = threading.Thread(target=work, name="hdjax-prefetch", daemon=True)
    thread.start()
    return thread
