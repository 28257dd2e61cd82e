"""The packages of hdjax meet only at public names.

A package (`hdjax/compliance/`, `hdjax/discover/`, ...) may use another package's public API or
what that package lends in its `internal` module, never one of its underscore modules or names:
a private name can then change with the one package that owns it. The top-level shared modules
(`hdjax/_errors.py`, `hdjax/_recording.py`, ...) belong to every package.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "hdjax"


def _target(rel: tuple[str, ...], node: ast.ImportFrom) -> list[str]:
    """The imported module as parts below `hdjax` (`["compliance", "_lstsq"]`)."""
    mod = (node.module or "").split(".") if node.module else []
    if node.level == 0:
        return mod[1:] if mod and mod[0] == "hdjax" else []
    package = list(rel[:-1])
    return package[: len(package) - (node.level - 1)] + mod


def private_crossings(root: Path = ROOT) -> list[str]:
    """Every import, in `root`, of another package's underscore module or name."""
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).parts
        own = rel[0] if len(rel) > 1 else None
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                parts = _target(rel, node)
                names = [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                dotted = [a.name.split(".") for a in node.names if a.name.startswith("hdjax.")]
                if not dotted:
                    continue
                parts, names = dotted[0][1:], []
            else:
                continue
            if not parts or parts[0] == own or parts[0].startswith("_"):
                continue  # its own package, or the shared top-level modules
            private = [p for p in parts[1:] if p.startswith("_")]
            private += [n for n in names if n.startswith("_")]
            if private:
                found.append(
                    f"{path.relative_to(root.parent)}:{node.lineno} {'.'.join(parts)} {private}"
                )
    return found


def test_no_package_imports_another_packages_private_names():
    crossings = private_crossings()
    assert not crossings, "lend these through the provider's `internal` module:\n" + "\n".join(
        crossings
    )


def test_the_check_sees_a_private_import(tmp_path):
    pkg = tmp_path / "hdjax"
    (pkg / "discover").mkdir(parents=True)
    (pkg / "compliance").mkdir()
    (pkg / "discover" / "_a.py").write_text(
        "from ..compliance._lstsq import prepare\n"
        "from ..compliance import _stream\n"
        "from ..compliance.internal import _design\n"
        "from ..compliance.internal import prepare as ok\n"
        "from .._errors import DataError\n"
        "from ._b import _own\n"
        "import hdjax.compliance._shape\n"
    )
    found = private_crossings(pkg)
    assert [f.split(" ", 1)[1] for f in found] == [
        "compliance._lstsq ['_lstsq']",
        "compliance ['_stream']",
        "compliance.internal ['_design']",
        "compliance._shape ['_shape']",
    ]


def imported_packages(package: str, root: Path = ROOT) -> dict[str, list[str]]:
    """The other hdjax packages that `package`'s modules import (at any depth, lazily or not),
    each with where."""
    found: dict[str, list[str]] = {}
    for path in sorted((root / package).rglob("*.py")):
        rel = path.relative_to(root).parts
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                parts = _target(rel, node)
                # `from .. import plant` names the packages themselves
                relative_root = node.level and not node.module and not parts
                tops = [a.name for a in node.names] if relative_root else parts[:1]
            elif isinstance(node, ast.Import):
                tops = [a.name.split(".")[1] for a in node.names if a.name.startswith("hdjax.")]
            else:
                continue
            for top in tops:
                if top != package and not top.startswith("_"):
                    found.setdefault(top, []).append(f"{path.name}:{node.lineno}")
    return found


# the [reference] table's checks belong to the package that reads references
CONFIG_MAY_IMPORT = {"reference"}


def test_configuration_only_parses_and_validates():
    """`hdjax.config` builds no model and reads no data: it imports none of the model
    packages (compliance, network, plant, ...) nor the pipelines that build from them."""
    found = imported_packages("config")
    extra = {k: v for k, v in found.items() if k not in CONFIG_MAY_IMPORT}
    assert not extra, f"hdjax.config imports {extra}; build models in hdjax.pipelines"


def test_the_layering_check_sees_a_lazy_import(tmp_path):
    pkg = tmp_path / "hdjax" / "config"
    pkg.mkdir(parents=True)
    (pkg / "_a.py").write_text(
        "from .._errors import ConfigError\n"
        "from ..reference import check_reference\n"
        "from ._b import x\n"
        "from .. import network, _io\n"
        "def f():\n"
        "    from ..compliance import ComplianceModel\n"
        "    import hdjax.plant\n"
    )
    found = imported_packages("config", tmp_path / "hdjax")
    assert found == {
        "reference": ["_a.py:2"],
        "network": ["_a.py:4"],
        "compliance": ["_a.py:6"],
        "plant": ["_a.py:7"],
    }
