"""The documentation site builds strictly (every cross-reference resolves), its generated pages
follow the code, the README stays short and its commands are the ones CI runs, and the user docs
name no tracker issue and no path outside the repository."""

import re
import sys
import warnings

import numpy as np
import pytest

from .conftest import REPO

README = REPO / "README.md"
DOCS = REPO / "docs"


def _user_texts():
    yield README
    for path in DOCS.rglob("*.md"):
        if "_gen" not in path.parts:
            yield path


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    mkdocs_config = pytest.importorskip("mkdocs.config", reason="install the docs extra")
    from mkdocs.commands.build import build

    out = tmp_path_factory.mktemp("site")
    cfg = mkdocs_config.load_config(str(REPO / "mkdocs.yml"), site_dir=str(out), strict=True)
    build(cfg)  # raises mkdocs.exceptions.Abort on any warning (strict)
    return out


def test_strict_build_renders_every_page(site):
    # page.md becomes page.html (the offline plugin turns directory URLs off, so that links
    # resolve when the site is opened from disk)
    for page in ("index", "getting-started", "residual-loop", "compliance-model", "benchmarks"):
        assert (site / f"{page}.html").is_file(), page
    commands = (site / "reference" / "commands.html").read_text()
    assert "hdjax run" in commands and "--overwrite" in commands
    api = (site / "reference" / "api" / "hdjax.compliance.html").read_text()
    assert 'id="hdjax.compliance.calibrate_lstsq"' in api
    loop = (site / "residual-loop.html").read_text()
    assert "generated: effect families" not in loop and "<code>hysteresis:torque</code>" in loop
    for page in site.rglob("*.html"):  # the rendered docstrings too
        text = re.sub(r"<[^>]+>", " ", page.read_text())
        assert not re.search(r"\b[Ii]ssues? #?\d+", text), page


# a script or stylesheet from another host: `<script src=...>`, `<link href=...>` (stylesheets,
# preconnects, preloads); plain links to papers and repositories are fine
_EXTERNAL = re.compile(
    r"<(?:script|link)\b[^>]*?\b(?:src|href)=[\"']?((?:https?:)?//[^\"'\s>]+)", re.I
)


def test_site_works_offline(site):
    # the site is read on machines without internet, also opened straight from disk: nothing it
    # loads comes from another host, MathJax is in it, and search has its index as a script
    # (material's offline plugin) and its worker a shim, which a page opened as file:// can load
    import json

    external = {url for page in site.rglob("*.html") for url in _EXTERNAL.findall(page.read_text())}
    assert not external, sorted(external)
    page = (site / "residual-loop.html").read_text()
    for script in ("js/mathjax/tex-svg-full.js", "js/iframe-worker/shim.js"):
        assert f'<script src="{script}">' in page, script
        assert (site / script).is_file(), script
    assert (site / "js" / "mathjax" / "tex-svg-full.js").stat().st_size > 1_000_000
    assert (site / "js" / "mathjax" / "LICENSE").is_file()
    index = (site / "search" / "search_index.js").read_text()
    assert index.startswith("var __index = ")
    docs = json.loads(index.removeprefix("var __index = "))["docs"]
    assert any(doc["location"].startswith("residual-loop.html") for doc in docs)


def test_config_reference_lists_every_schema_key():
    sys.path.insert(0, str(DOCS / "_gen"))
    import reference

    from hdjax.config import _schema

    page = reference.config_page()
    for table, keys in _schema.SCHEMA.items():
        assert f"## `[{table}]`" in page
        for key in keys:
            assert f"| `{key}` |" in page, (table, key)


def test_readme_is_short_and_ci_runs_its_test_command():
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    commands = re.findall(r"^python3 -m venv .*$", text, re.M)
    assert len(commands) == 2, commands
    assert "'.[dev,docs]'" in commands[1] and "pytest" in commands[1]
    assert commands[1] in (REPO / ".ci" / "run").read_text().splitlines()


def test_readme_command_table_lists_every_command():
    from hdjax.cli import COMMANDS

    section = README.read_text().split("## Commands", 1)[1].split("\n## ", 1)[0]
    listed = re.findall(r"^\| `hdjax (\w+)", section, re.M)
    assert sorted(listed) == sorted(COMMANDS)


def test_readme_links_exist():
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README.read_text()):
        if not target.startswith(("http://", "https://")):
            assert (REPO / target).exists(), target


def test_user_docs_name_no_issue_and_no_outside_path():
    for path in _user_texts():
        text = path.read_text()
        assert not re.search(r"\bissues? \d+|#\d{1,3}\b", text), path
        assert "../shared" not in text and "/work/" not in text and "/tmp/" not in text, path


def _blocks(page: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", (DOCS / page).read_text(), re.S)


def test_getting_started_python_runs_as_written(monkeypatch):
    (code,) = _blocks("getting-started.md", "python")
    monkeypatch.chdir(REPO)
    namespace: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a sparse torque segment is left out
        exec(compile(code, "docs/getting-started.md", "exec"), namespace)
    result = namespace["result"]
    # the example logs carry an order-2 kinematic error of the motor angle, and nothing else
    # that the starting model lacks: the loop must name it first and lower the TEST error
    assert result.aux.effects[0].startswith("harmonic:theta_m:2")
    assert result.stats["final_test_rms"] < 0.5 * result.stats["baseline_test_rms"]
    assert namespace["est"].torque.shape == namespace["test"].torque.shape


def test_worked_example_test_log_is_another_recording():
    # TEST is another motion and load path than TRAIN (not the same motion with a new noise
    # draw): its encoder counts differ from TRAIN's (the two swings cross, so a row may agree
    # by chance: at most 1 %), its output angle spans less, and its torque stays inside the
    # range TRAIN calibrates
    logs = {
        name: np.loadtxt(DOCS / "examples" / f"bench_{name}.csv", delimiter=",", skiprows=1)
        for name in ("train", "test")
    }
    train, test = logs["train"], logs["test"]
    assert train.shape == test.shape
    for col in (1, 2):  # motor_counts, output_counts
        assert np.mean(train[:, col] == test[:, col]) <= 0.01
    assert np.ptp(test[:, 2]) < 0.9 * np.ptp(train[:, 2])
    assert train[:, 4].min() < test[:, 4].min() and test[:, 4].max() < train[:, 4].max()


def test_getting_started_commands_run_as_written(monkeypatch, tmp_path):
    import shlex

    import hdjax.cli

    (script,) = _blocks("getting-started.md", "bash")
    monkeypatch.chdir(REPO)
    for line in script.strip().splitlines():
        argv = shlex.split(line.replace("runs/", f"{tmp_path}/"))
        assert argv[0] == "hdjax"
        assert hdjax.cli.main(argv[1:]) == 0, line
    estimate = (tmp_path / "bench_torque.csv").read_text().splitlines()
    assert estimate[0].startswith("t,torque_estimate")
    assert len(estimate) == len((DOCS / "examples" / "bench_test.csv").read_text().splitlines())
    assert (tmp_path / "bench_discover" / "report.json").is_file()
    # the discovered model, used as the report prints: the TEST error the report states
    import json

    import numpy as np

    rep = json.loads((tmp_path / "bench_discover" / "report.json").read_text())
    est = np.genfromtxt(tmp_path / "bench_discovered_torque.csv", delimiter=",", names=True)
    ref = np.genfromtxt(DOCS / "examples" / "bench_test.csv", delimiter=",", names=True)
    col = [n for n in ref.dtype.names if "torque" in n][0]
    rms = float(np.sqrt(np.mean((est["torque_estimate"] - ref[col]) ** 2)))
    assert rep["effects"], rep["notes"]
    assert rms == pytest.approx(rep["final"]["rms"], rel=1e-9), (rms, rep["final"])


def test_benchmarks_page_is_rendered_from_the_snapshot():
    import json

    sys.path.insert(0, str(REPO / "benchmarks"))
    import _page

    snapshot = json.loads((REPO / _page.SNAPSHOT).read_text())
    assert (REPO / _page.PAGE).read_text() == _page.render(snapshot), (
        "docs/benchmarks.md differs from docs/benchmarks/results.json: run "
        "python benchmarks/run_all.py instead of editing the page"
    )


@pytest.mark.parametrize("page", ["simulated-joint.md", "network-and-fits.md", "strain-gauge.md"])
def test_physics_page_code_runs(page):
    for code in _blocks(page, "python"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # short runs: sparse torque segments
            exec(compile(code, f"docs/{page}", "exec"), {})
