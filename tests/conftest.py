"""Test configuration: float64, strict dtype promotion, and shared paths."""

from pathlib import Path

import jax
import pytest

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
LARA8 = SHARED / "data" / "lara8"


@pytest.fixture(scope="session")
def lara8_dir() -> Path:
    if not (LARA8 / "validate.csv").exists():
        pytest.skip(f"real LARA8 logs not found at {LARA8} (../shared beside the repo)")
    return LARA8
