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

# One JAX compilation cache for the whole test session, in a temporary folder (never the real
# home's): the suite is compile-bound, and its two xdist workers, the CLI commands the tests
# start in subprocesses and the programs rebuilt in-process (new closures of the same HLO) all
# compile the same programs (measured on seven of the slowest files with `-n 2`: 195 s without
# the cache, 169 s with it). The controller creates the folder before it starts the workers
# (they inherit the variable) and removes it when it exits. The CLI finds it as
# $XDG_CACHE_HOME/hdjax/jax; a test of the cache itself points XDG_CACHE_HOME elsewhere.
# A program read while another worker is still writing it fails to load; JAX then warns and
# compiles it (the warning is ignored in pyproject's filterwarnings). HDJAX_TEST_CACHE=0 turns
# the cache off, to compare.
if "HDJAX_TEST_XDG" not in os.environ:
    os.environ["HDJAX_TEST_XDG"] = tempfile.mkdtemp(prefix="hdjax-test-xdg-")
    atexit.register(shutil.rmtree, os.environ["HDJAX_TEST_XDG"], ignore_errors=True)
os.environ["XDG_CACHE_HOME"] = os.environ["HDJAX_TEST_XDG"]
TEST_CACHE_ON = os.environ.get("HDJAX_TEST_CACHE", "1") != "0"
if TEST_CACHE_ON:
    os.environ.pop("HDJAX_NO_CACHE", None)
else:
    os.environ["HDJAX_NO_CACHE"] = "1"

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
# no implicit broadcasting between arrays of different ranks: `x - mean[None, :]`, not `x - mean`
jax.config.update("jax_numpy_rank_promotion", "raise")


def use_session_cache() -> None:
    """Point this process's JAX at the session's compilation cache, $XDG_CACHE_HOME/hdjax/jax,
    with the CLI's own settings (or turn it off with HDJAX_TEST_CACHE=0): what every test
    starts from. (jaxtyping's import hook is installed before this file runs, so hdjax imported
    here is checked as everywhere.)"""
    from hdjax._cache import disable_compilation_cache, enable_compilation_cache

    if TEST_CACHE_ON:
        enable_compilation_cache()
    else:
        disable_compilation_cache()


use_session_cache()

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
    "test_real_log.py": 84,
    "test_discover_trust.py": 74,
    "test_discover_plant.py": 67,
    "test_discover_chunked.py": 41,
    "test_plant_simulate.py": 41,
    "test_discover_families.py": 39,
    "test_cli_broken_inputs.py": 36,
    "test_docs.py": 35,
    "test_fleet.py": 34,
    "test_plant_gradients.py": 32,
    "test_discover_design.py": 31,
    "test_discover_loop.py": 30,
    "test_discover_cli.py": 28,
    "test_discover_start_structure.py": 27,
    "test_cli_run.py": 21,
    "test_fit_hybrid.py": 20,
    "test_discover_selection.py": 19,
    "test_readme.py": 19,
    "test_stream_commands.py": 17,
    "test_cache_discover.py": 17,
    "test_export.py": 16,
    "test_config_data.py": 15,
    "test_discover_partial_swing.py": 15,
    "test_lara8_reference.py": 15,
    "test_fleet_chunked.py": 14,
    "test_discover_trust_units.py": 13,
    "test_cli_signals.py": 13,
    "test_stream.py": 12,
    "test_lstsq.py": 12,
    "test_cache.py": 10,
    "test_strain_compare.py": 10,
    "test_network_model.py": 9,
    "test_network_periodic.py": 9,
    "test_plant_dynamics.py": 9,
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
