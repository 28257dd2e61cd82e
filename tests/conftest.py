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

import jax
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
