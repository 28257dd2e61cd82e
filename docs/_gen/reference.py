"""Pages generated from the code at build time, so that they cannot drift from it.

- `commands_page()`: the `hdjax` command reference, from the argparse parsers of `hdjax.cli`.
- `config_page()`: the experiment-file reference, from the schema of `hdjax.config` (tables,
  keys, defaults and the checks' limits), the `hdjax.Joint` docstring and the meanings in
  `settings.toml` next to this file. A schema key without a meaning there, or a meaning for a key
  the schema no longer has, is an error (the strict docs build fails).
- `api_pages()`: one API page per public package, listing every name its `__init__.py`
  re-exports (`from ._x import A as A`), rendered by mkdocstrings from the docstrings.

Each function returns Markdown; `hooks.py` adds the pages to the site.
"""

from __future__ import annotations

import argparse
import ast
import inspect
import re
import tomllib
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
PACKAGE = REPO / "hdjax"

GENERATED_NOTE = (
    "<!-- Generated at build time by docs/_gen/reference.py from {source}; edit the code, "
    "not this page. -->\n\n"
)


class DocsError(Exception):
    """The code and its documentation disagree (the build must fail)."""


# ---------------------------------------------------------------------------------------------
# Command reference


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _full_parser(name: str, sub: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """A subcommand whose options live in another module (registered without options)."""
    if any(a.option_strings for a in sub._actions):
        return sub
    import importlib

    for module in (f"hdjax.cli._{name}",):
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        build = getattr(mod, "build_parser", None)
        if build is not None:
            full = build()
            full.prog = f"hdjax {name}"
            return full
    return sub


def _option_rows(parser: argparse.ArgumentParser) -> list[str]:
    formatter = parser._get_formatter()
    rows = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
            continue
        if action.help == argparse.SUPPRESS:
            continue
        if action.option_strings:
            names = ", ".join(f"`{s}`" for s in action.option_strings)
            if action.nargs != 0:
                metavar = formatter._format_args(action, action.dest.upper())
                names += f" `{metavar}`"
        else:
            names = f"`{formatter._format_args(action, action.dest)}`"
        default = action.default
        if default in (None, False, argparse.SUPPRESS) or default == []:
            shown = ""
        else:
            shown = f"`{default}`"
        required = (
            " (required)" if getattr(action, "required", False) and action.option_strings else ""
        )
        text = formatter._expand_help(action) if action.help else ""
        rows.append(f"| {names}{required} | {_cell(shown)} | {_cell(text)} |")
    return rows


def commands_page() -> str:
    from hdjax.cli import _parser

    main = _parser()
    subs = _subcommands(main)
    out = [
        GENERATED_NOTE.format(source="the argument parsers of hdjax.cli"),
        "# Command reference\n\n",
        "Every command prints this with `hdjax COMMAND --help` (or `python -m hdjax COMMAND "
        "--help`).\n\n",
        "```text\n" + main.format_help().rstrip() + "\n```\n\n",
        "| command | what it does |\n|---|---|\n",
    ]
    helps = {}
    for action in main._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {c.dest: c.help for c in action._choices_actions}
    for name in subs:
        out.append(f"| [`hdjax {name}`](#hdjax-{name}) | {_cell(helps.get(name, ''))} |\n")
    for name, sub in subs.items():
        parser = _full_parser(name, sub)
        parser.prog = f"hdjax {name}"
        out.append(f"\n## hdjax {name}\n\n")
        if parser.description:
            out.append(_as_paragraphs(parser.description) + "\n\n")
        out.append("```text\n" + parser.format_usage().strip() + "\n```\n\n")
        rows = _option_rows(parser)
        if rows:
            out.append("| argument | default | meaning |\n|---|---|---|\n")
            out.append("\n".join(rows) + "\n\n")
        if parser.epilog:
            out.append("```text\n" + parser.epilog.strip("\n") + "\n```\n")
    return "".join(out)


def _as_paragraphs(text: str) -> str:
    """argparse descriptions are plain text: keep their line breaks as Markdown paragraphs."""
    blocks = [b for b in re.split(r"\n\s*\n", text.strip()) if b.strip()]
    rendered = []
    for block in blocks:
        lines = block.splitlines()
        if any(line.startswith("  ") for line in lines):
            rendered.append("```text\n" + block + "\n```")
        else:
            rendered.append(" ".join(line.strip() for line in lines))
    return "\n\n".join(rendered)


# ---------------------------------------------------------------------------------------------
# Config reference


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _describe_check(check) -> str:
    """What a schema check accepts, read from the check itself (its kind and its limits)."""
    check = inspect.unwrap(check)  # under pytest, jaxtyping's import hook wraps every function
    name = getattr(check, "__qualname__", "")
    outer = name.split(".<locals>")[0].lstrip("_")
    free = {}
    if getattr(check, "__closure__", None):
        free = dict(zip(check.__code__.co_freevars, (c.cell_contents for c in check.__closure__)))
    if outer == "optional":
        inner = _describe_check(free["check"])
        return f"{inner}, or {_toml_value(free['none_value'])} for not set"
    if outer == "int":
        lo, hi = free.get("minimum"), free.get("maximum")
        limits = [f">= {lo}" for _ in [0] if lo is not None] + [
            f"<= {hi}" for _ in [0] if hi is not None
        ]
        return "integer" + (f" {' and '.join(limits)}" if limits else "")
    if outer == "num":
        parts = []
        if free.get("positive"):
            parts.append("> 0")
        if free.get("lo") is not None:
            parts.append(f">= {free['lo']}")
        if free.get("hi") is not None:
            parts.append(f"<= {free['hi']}")
        return "number" + (f" {' and '.join(parts)}" if parts else "")
    if outer == "choice":
        return "one of " + ", ".join(f'"{o}"' for o in free["options"])
    if outer == "list":
        inner = _describe_check(free["item"])
        return f"{'non-empty ' if free.get('nonempty') else ''}list of {inner}"
    simple = {
        "encoding": 'a text encoding name ("utf-8", "latin-1", "cp1252", ...)',
        "bool": "true or false",
        "str": "string",
        "table": "table",
        "current_scale": '"auto" or a number > 0',
        "test_files": "list of files, or a table name = file",
        "check_reference": 'table: kind = "column" (default) or "wrench" (see hdjax.reference)',
    }
    if outer in simple:
        return simple[outer]
    if name.startswith("_list.") or name == "<lambda>":
        return "any value"
    # a check of its own: its docstring's first sentence, if any (the meaning is what matters)
    doc = inspect.getdoc(check) or ""
    return doc.split(". ")[0].split("\n\n")[0].replace("\n", " ") if doc else "checked value"


def _argument_docs(docstring: str) -> dict[str, str]:
    """The `**Arguments:**` bullets of a docstring: `- `a`, `b`: text` -> {a: text, b: text}."""
    docs: dict[str, str] = {}
    current: list[str] = []
    text: list[str] = []

    def flush():
        for key in current:
            docs[key] = " ".join(text)

    for line in inspect.cleandoc(docstring).splitlines():
        m = re.match(r"- ((?:`\w+`(?:, )?)+): (.*)", line)
        if m:
            flush()
            current = re.findall(r"`(\w+)`", m.group(1))
            text = [m.group(2).strip()]
        elif current and line.startswith("  "):
            text.append(line.strip())
        else:
            flush()
            current, text = [], []
    flush()
    return docs


def _schema_comments() -> dict[tuple[str, str], str]:
    """Comments written directly above a key in the SCHEMA literal of hdjax/config/_schema.py:
    (table, key) -> text. They describe a key when settings.toml does not."""
    lines = (PACKAGE / "config" / "_schema.py").read_text().splitlines()
    out: dict[tuple[str, str], str] = {}
    table = None
    comment: list[str] = []
    for line in lines:
        stripped = line.strip()
        m_table = re.match(r'"(\w+)": \{$', stripped)
        m_key = re.match(r'"(\w+)": \(', stripped)
        if m_table and line.startswith("    ") and not line.startswith("        "):
            table, comment = m_table.group(1), []
        elif m_key and table:
            text = " ".join(comment).strip()
            if text:
                out[(table, m_key.group(1))] = text
            comment = []
        elif stripped.startswith("#"):
            comment.append(stripped.lstrip("#").strip())
        else:
            comment = []
    return out


def _meanings() -> dict:
    return tomllib.loads((HERE / "settings.toml").read_text())


def config_page() -> str:
    import dataclasses

    from hdjax import Joint
    from hdjax.config import _schema

    meanings = _meanings()
    schema_meanings = meanings.get("experiment_file", {})
    comments = _schema_comments()
    problems = []
    out = [
        GENERATED_NOTE.format(source="hdjax/config/_schema.py and docs/_gen/settings.toml"),
        "# Experiment files\n\n",
        meanings["intro"]["text"].strip() + "\n\n",
    ]
    # [experiment] first, then [joint], then the rest in schema order.
    tables = list(_schema.TABLES)
    for table in tables:
        out.append(f"## `[{table}]`\n\n")
        intro = meanings.get("tables", {}).get(table)
        if intro:
            out.append(intro.strip() + "\n\n")
        out.append("| key | default | accepts | meaning |\n|---|---|---|---|\n")
        if table == "joint":
            docs = _argument_docs(Joint.__doc__ or "")
            for f in dataclasses.fields(Joint):
                default = (
                    "required"
                    if f.default is dataclasses.MISSING
                    else ("not set" if f.default is None else f"`{_toml_value(f.default)}`")
                )
                if f.name not in docs:
                    problems.append(f"hdjax.Joint's docstring does not describe {f.name!r}")
                kind = str(f.type).replace(" | None", "")
                kind = {"float": "number", "int": "integer", "str": "string"}.get(kind, kind)
                out.append(
                    f"| `{f.name}` | {default} | {_cell(kind)} | {_cell(docs.get(f.name, ''))} |\n"
                )
            out.append("\n")
            continue
        given = schema_meanings.get(table, {})
        for key, (default, check) in _schema.SCHEMA[table].items():
            meaning = given.get(key, comments.get((table, key)))
            if meaning is None:
                problems.append(
                    f"[{table}] {key} has no meaning: add a comment above it in "
                    f"hdjax/config/_schema.py or a line to docs/_gen/settings.toml "
                    f"[experiment_file.{table}]"
                )
            out.append(
                f"| `{key}` | `{_toml_value(default)}` | {_cell(_describe_check(check))} | "
                f"{_cell(meaning or '')} |\n"
            )
        for key in given:
            if key not in _schema.SCHEMA[table]:
                problems.append(
                    f"docs/_gen/settings.toml describes [{table}] {key}, which the schema no "
                    "longer has"
                )
        out.append("\n")
    for table in schema_meanings:
        if table not in _schema.SCHEMA:
            problems.append(f"docs/_gen/settings.toml describes a table [{table}] the schema lacks")
    out.append(
        meanings["sweeps"]["text"]
        .strip()
        .format(sweepable=", ".join(f"`{s}`" for s in _schema.sweepable_settings()))
        + "\n\n"
    )
    out.append(_discover_section(meanings, problems))
    if problems:
        raise DocsError("; ".join(problems))
    return "".join(out)


def _discover_section(meanings: dict, problems: list[str]) -> str:
    from hdjax.discover import _config

    given = meanings.get("discover_file", {})
    out = [
        "## Discover experiment files\n\n",
        given.get("intro", "").strip() + "\n\n",
    ]
    for table, keys in (("data", _config._DATA_KEYS), ("discover", _config._DISCOVER_KEYS)):
        out.append(f"### `[{table}]`\n\n| key | meaning |\n|---|---|\n")
        described = given.get(table, {})
        for key in keys:
            if key not in described:
                problems.append(
                    f"discover [{table}] {key} has no meaning in docs/_gen/settings.toml "
                    f"[discover_file.{table}]"
                )
            out.append(f"| `{key}` | {_cell(described.get(key, ''))} |\n")
        for key in described:
            if key not in keys:
                problems.append(
                    f"docs/_gen/settings.toml describes discover [{table}] {key}, which the "
                    "discover file no longer has"
                )
        out.append("\n")
    return "".join(out)


# ---------------------------------------------------------------------------------------------
# API reference


def public_packages() -> list[str]:
    """`hdjax` and its public sub-packages, in the order of the data flow where known."""
    order = [
        "compliance",
        "plant",
        "network",
        "fit",
        "discover",
        "strain",
        "effects",
        "reference",
        "pipelines",
        "modelfile",
        "report",
        "config",
        "cli",
    ]
    found = [
        p.name
        for p in PACKAGE.iterdir()
        if p.is_dir() and not p.name.startswith("_") and (p / "__init__.py").exists()
    ]
    found.sort(key=lambda n: (order.index(n) if n in order else len(order), n))
    return ["hdjax"] + [f"hdjax.{n}" for n in found]


def exported_names(package: str) -> list[str]:
    """The names a package's `__init__.py` exports: `__all__` if given, else every
    `from .x import A as A`, public function, class and upper-case constant it defines."""
    path = PACKAGE.joinpath(*package.split(".")[1:], "__init__.py")
    tree = ast.parse(path.read_text())
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return [ast.literal_eval(e) for e in node.value.elts]
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level >= 1:
            names += [a.asname for a in node.names if a.asname and a.asname == a.name]
        elif isinstance(node, ast.FunctionDef | ast.ClassDef) and not node.name.startswith("_"):
            names.append(node.name)
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Name) and t.id.isupper() and not t.id.startswith("_"):
                    names.append(t.id)
    seen: set[str] = set()
    return [n for n in names if not (n in seen or seen.add(n))]


def api_page(package: str) -> str:
    names = exported_names(package)
    out = [
        GENERATED_NOTE.format(source=f"the docstrings of {package}"),
        f"# `{package}`\n\n",
        f"::: {package}\n    options:\n      show_root_heading: false\n      members: false\n\n",
    ]
    for name in names:
        out.append(f"::: {package}.{name}\n    options:\n      heading_level: 2\n\n")
    return "".join(out)


def api_pages() -> dict[str, str]:
    """`reference/api/<package>.md` -> page text, for every public package."""
    return {f"reference/api/{p}.md": api_page(p) for p in public_packages()}


# ---------------------------------------------------------------------------------------------
# Effect families (a table substituted into pages at a marker)

FAMILIES_MARKER = "<!-- generated: effect families -->"


def effect_families_table() -> str:
    """The registered effect families of `hdjax.effects`: report keys, plant effects, summary."""
    from hdjax import effects

    rows = [
        "| family | keys in a discover report | plant effects | what it is |",
        "|---|---|---|---|",
    ]
    for family in effects.families():
        doc = (inspect.getdoc(type(family)) or "").split("\n\n")[0].replace("\n", " ")
        keys = ", ".join(f"`{k.strip()}`" for k in family.vocabulary_text().split(",") if k.strip())
        plant = ", ".join(f"`{p.name}`" for p in family.plant_effects)
        rows.append(f"| `{family.name}` | {keys or 'not proposed'} | {plant} | {_cell(doc)} |")
    return "\n".join(rows) + "\n"
