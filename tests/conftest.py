"""Test configuration: float64, strict dtype and rank promotion, and shared paths.

hdjax's jaxtyping annotations are checked by beartype in every test: pyproject's pytest
`addopts` passes `--jaxtyping-packages=hdjax,beartype.beartype`, whose import hook is installed
before this file runs, so nothing here may import hdjax at module level before it.
"""

import atexit
import os
import shutil
import tempfile
from pathlib import Path

# `pytest -n 2` on two cores: each worker computes on one thread. XLA's and BLAS's own thread
# pools in two workers would otherwise share two cores (measured on the two slowest files: 161 s
# -> 141 s). Set before JAX starts its backend; subprocesses the tests start inherit it.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false"
    ).strip()
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

# The suite is compile-bound (most of its time is XLA compiling small programs), so its programs
# are compiled at LLVM optimisation level 0: the same HLO, the same HLO passes, less time making
# machine code (measured alone: test_discover_trust 84 -> 68 s, test_real_log 108 -> 94 s). The
# package, the CLI and the benchmarks keep XLA's default. A level already in XLA_FLAGS is kept.
if "--xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0"
    ).strip()

import jax  # noqa: E402
import pytest

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
# no implicit broadcasting between arrays of different ranks: `x - mean[None, :]`, not `x - mean`
jax.config.update("jax_numpy_rank_promotion", "raise")

# The CLI keeps JAX's compilation cache in $XDG_CACHE_HOME/hdjax: never the real home's in
# tests, and off unless a test turns it on (tests/test_cache.py does, in a subprocess).
_CACHE_HOME = tempfile.mkdtemp(prefix="hdjax-test-xdg-")
atexit.register(shutil.rmtree, _CACHE_HOME, ignore_errors=True)
os.environ["XDG_CACHE_HOME"] = _CACHE_HOME
os.environ["HDJAX_NO_CACHE"] = "1"

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
LARA8 = SHARED / "data" / "lara8"


@pytest.fixture(scope="session")
def lara8_dir() -> Path:
    if not (LARA8 / "validate.csv").exists():
        pytest.skip(f"real LARA8 logs not found at {LARA8} (../shared beside the repo)")
    return LARA8


# -- xdist: whole files per worker, the slowest first -------------------------------------------
# `pytest -n 2` hands tests out one by one by default, so the two workers both run part of a
# file and both pay for its module fixtures and its compilations (most of this suite's time is
# XLA compiling programs that the tests of one file share). Here a worker takes whole files, the
# known slow ones first (longest-processing-time order keeps the two workers' totals level; the
# small files at the end fill the gaps). `HDJAX_TEST_DIST=load` restores xdist's default, to
# compare. The weights are seconds measured on a 2-core machine (`--durations`, summed per
# file); an unlisted file counts as 1 s per test.
SLOW_FILES = {
    "test_real_log.py": 104,
    "test_discover_trust.py": 91,
    "test_discover_plant.py": 82,
    "test_fleet.py": 51,
    "test_cli_broken_inputs.py": 45,
    "test_plant_simulate.py": 42,
    "test_plant_gradients.py": 41,
    "test_discover_design.py": 40,
    "test_docs.py": 38,
    "test_discover_families.py": 38,
    "test_discover_chunked.py": 36,
    "test_discover_cli.py": 34,
    "test_discover_loop.py": 32,
    "test_cli_run.py": 26,
    "test_fit_hybrid.py": 25,
    "test_stream_commands.py": 23,
    "test_config_data.py": 22,
    "test_stream.py": 20,
    "test_lara8_reference.py": 20,
    "test_cache_discover.py": 20,
    "test_export.py": 18,
    "test_lstsq.py": 17,
    "test_discover_partial_swing.py": 17,
    "test_cli_signals.py": 17,
    "test_readme.py": 15,
    "test_network_model.py": 15,
    "test_fleet_chunked.py": 15,
    "test_export_cli.py": 15,
    "test_discover_trust_units.py": 14,
    "test_cache.py": 14,
    "test_strain_compare.py": 13,
    "test_effects_family.py": 13,
    "test_plant_dynamics.py": 12,
}


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    if os.environ.get("HDJAX_TEST_DIST", "file") != "file":
        return None
    from xdist.scheduler import LoadFileScheduling

    class SlowFilesFirst(LoadFileScheduling):
        def _assign_work_unit(self, node):
            if not getattr(self, "_ordered", False):
                self._ordered = True

                def cost(item):
                    scope, tests = item
                    return SLOW_FILES.get(Path(scope).name, len(tests))

                ordered = sorted(self.workqueue.items(), key=cost, reverse=True)
                self.workqueue.clear()
                self.workqueue.update(ordered)
            super()._assign_work_unit(node)

    return SlowFilesFirst(config, log)
