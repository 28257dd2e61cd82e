"""Package hygiene: every module compiles without warnings and imports; x64 is on."""

import ast
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


def test_every_package_all_lists_what_it_imports():
    # a package that orders its API page by __all__ must list every name it re-exports, or the
    # page silently loses one (and an unknown name breaks the docs build)
    for init in sorted(ROOT.glob("*/__init__.py")):
        tree = ast.parse(init.read_text())
        alls = [n for n in tree.body if isinstance(n, ast.Assign) and "__all__" in ast.dump(n)]
        if not alls or init.parent.name.startswith("_"):
            continue
        imported = {
            a.asname
            for n in tree.body
            if isinstance(n, ast.ImportFrom) and n.level >= 1
            for a in n.names
            if a.asname == a.name
        }
        module = importlib.import_module(f"hdjax.{init.parent.name}")
        assert set(module.__all__) == imported, (init, set(module.__all__) ^ imported)


def test_discover_api_page_opens_with_the_loop(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT.parent / "docs" / "_gen"))
    from reference import exported_names

    assert exported_names("hdjax.discover")[:2] == ["discover", "DiscoverOptions"]
