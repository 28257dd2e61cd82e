"""Regenerate the figures the README and the docs show, each from a run of `hdjax discover`.

    python docs/make_figures.py            # the README's before/after figure (example logs)
    python docs/make_figures.py --lara8    # also the LARA8 pages' figures (needs the logs)

- `docs/img/discover_before_after.png`: `hdjax discover --config
  docs/examples/bench_discover.toml` (the Getting-started example), its `figures/torque.png`.
- `docs/lara8/report.md` and `docs/lara8/figures/`: the report of `hdjax discover --config
  experiments/lara8_discover.toml`; the logs live outside the repository, where that file's
  `[data] path` points.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _discover(config: str, out: Path) -> Path:
    from hdjax.cli import main

    code = main(["discover", "--config", str(REPO / config), "--out", str(out)])
    if code != 0:
        sys.exit(f"hdjax discover --config {config} failed (exit code {code})")
    return out / "figures"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lara8", action="store_true", help="also the LARA8 figures")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        figures = _discover("docs/examples/bench_discover.toml", Path(tmp) / "bench")
        (REPO / "docs" / "img").mkdir(exist_ok=True)
        shutil.copyfile(figures / "torque.png", REPO / "docs" / "img" / "discover_before_after.png")
        if args.lara8:
            figures = _discover("experiments/lara8_discover.toml", Path(tmp) / "lara8")
            target = REPO / "docs" / "lara8"
            shutil.rmtree(target, ignore_errors=True)
            (target / "figures").mkdir(parents=True)
            for png in figures.glob("*.png"):
                shutil.copyfile(png, target / "figures" / png.name)
            report = (figures.parent / "report.md").read_text()
            title = "# LARA8 joint 3: the report of `hdjax discover`"
            note = (
                "Written by `hdjax discover --config experiments/lara8_discover.toml` and copied "
                "here by `python docs/make_figures.py --lara8`; not edited by hand."
            )
            report = report.replace("# hdjax discover", f"{title}\n\n{note}", 1)
            # the commands it prints name the repository's files and a folder of the user's
            out = figures.parent
            report = report.replace(str(out), "runs/lara8").replace(f"{REPO}/", "")
            (target / "report.md").write_text(report)


if __name__ == "__main__":
    main()
