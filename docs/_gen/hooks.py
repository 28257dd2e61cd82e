"""mkdocs hooks: add the generated reference pages and keep the navigation in step with docs/.

- The command, experiment-file and API reference pages are generated from the code on every
  build (`reference.py`), so they cannot drift from it; they are never committed.
- The table of effect families replaces its marker in a page (`reference.FAMILIES_MARKER`), and
  the export page's tables theirs (`export_tables`, from the benchmark snapshot).
- Navigation entries whose page does not exist are dropped (with a note in the build log), and
  every page under docs/ that the navigation does not list is appended under "More", so a page
  added to docs/ is always reachable.
- MathJax comes with the site (`MATHJAX`, from the django-static-mathjax package of the docs
  extra, which ships MathJax 3 and nothing else), so the maths renders without internet.
"""

from __future__ import annotations

import importlib.util
import logging
import sys
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

sys.path.insert(0, str(Path(__file__).resolve().parent))

import export_tables  # noqa: E402
import reference  # noqa: E402

log = logging.getLogger("mkdocs.hooks.hdjax")

GENERATED: dict[str, str] = {}

# MathJax 3 with every TeX extension and SVG output in one file: it loads no fonts and nothing
# else, so it works from disk too; its Apache-2.0 licence travels with it
MATHJAX = {
    "js/mathjax/tex-svg-full.js": "static/mathjax/es5/tex-svg-full.js",
    "js/mathjax/LICENSE": "static/mathjax/LICENSE",
}


def _mathjax_files(config) -> list[File]:
    spec = importlib.util.find_spec("mathjax")
    root = Path(spec.origin).parent if spec and spec.origin else None
    if root is None or not all((root / src).is_file() for src in MATHJAX.values()):
        raise PluginError(
            "MathJax not found: the site bundles it from the django-static-mathjax package; "
            "install the docs extra (pip install -e '.[dev,docs]')"
        )
    return [
        File.generated(config, uri, abs_src_path=str(root / src)) for uri, src in MATHJAX.items()
    ]


def _generated_pages() -> dict[str, str]:
    pages = {
        "reference/commands.md": reference.commands_page(),
        "reference/config.md": reference.config_page(),
    }
    pages.update(reference.api_pages())
    return pages


def _nav_pages(nav) -> list[str]:
    found = []
    for item in nav or []:
        if isinstance(item, str):
            found.append(item)
        elif isinstance(item, dict):
            for value in item.values():
                if isinstance(value, str):
                    found.append(value)
                else:
                    found += _nav_pages(value)
    return found


def _prune(nav, exists):
    out = []
    for item in nav or []:
        if isinstance(item, str):
            if exists(item):
                out.append(item)
            else:
                log.info("nav: %s is not in docs/ (yet); left out", item)
        elif isinstance(item, dict):
            ((title, value),) = item.items()
            if isinstance(value, str):
                if exists(value) or value.startswith(("http://", "https://")):
                    out.append(item)
                else:
                    log.info("nav: %s is not in docs/ (yet); left out", value)
            else:
                inner = _prune(value, exists)
                if inner:
                    out.append({title: inner})
    return out


def on_config(config):
    GENERATED.clear()
    GENERATED.update(_generated_pages())
    docs = Path(config["docs_dir"])
    api = sorted(p for p in GENERATED if p.startswith("reference/api/"))

    def exists(page: str) -> bool:
        return page in GENERATED or (docs / page).is_file()

    nav = config["nav"]
    for item in nav:  # the API section lists every generated package page
        if isinstance(item, dict) and "Reference" in item:
            section = [e for e in item["Reference"] if not (isinstance(e, dict) and "API" in e)]
            section.append({"API": [{Path(p).stem: p} for p in api]})
            item["Reference"] = section
    nav = _prune(nav, exists)
    listed = set(_nav_pages(nav))
    excluded = {"_gen"}
    extra = sorted(
        str(p.relative_to(docs))
        for p in docs.rglob("*.md")
        if not excluded.intersection(p.relative_to(docs).parts)
        and str(p.relative_to(docs)) not in listed
    )
    if extra:
        nav.append({"More": extra})
    config["nav"] = nav
    return config


def on_page_markdown(markdown, page, config, files):
    if reference.FAMILIES_MARKER in markdown:
        markdown = markdown.replace(reference.FAMILIES_MARKER, reference.effect_families_table())
    if export_tables.STEP_MARKER in markdown:
        markdown = markdown.replace(export_tables.STEP_MARKER, export_tables.step_table())
    if export_tables.CAUSALITY_MARKER in markdown:
        markdown = markdown.replace(export_tables.CAUSALITY_MARKER, export_tables.causality_table())
    return markdown


def on_files(files, config):
    for path, text in GENERATED.items():
        files.append(File.generated(config, path, content=text))
    for file in _mathjax_files(config):
        files.append(file)
    return files
