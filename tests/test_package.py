"""Package hygiene: every module compiles without warnings and imports; x64 is on."""

import importlib
import pkgutil
import warnings
from pathlib import Path

import jax

import hdjax

ROOT = Path(hdjax.__file__).parent


def test_every_module_compiles_without_warnings():
    # invalid escape sequences in docstrings only warn at compile time; catch them here
    for path in sorted(ROOT.rglob("*.py")):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            compile(path.read_text(), str(path), "exec")


def test_every_module_imports():
    names = [m.name for m in pkgutil.walk_packages([str(ROOT)], prefix="hdjax.")]
    assert "hdjax.discover._loop" in names and "hdjax.compliance._model" in names
    for name in names:
        importlib.import_module(name)


def test_x64_and_lazy_subpackages():
    assert jax.config.jax_enable_x64
    for sub in ("compliance", "plant", "network", "fit", "discover", "strain", "report"):
        assert getattr(hdjax, sub).__name__ == f"hdjax.{sub}"
    assert isinstance(hdjax.__version__, str)
