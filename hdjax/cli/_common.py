"""Shared pieces of the command line: the parser, progress lines, overrides."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .._errors import ConfigError, did_you_mean
from .._interrupts import check
from .._io import TOML_HINT, ColumnMap, read_text


class UsageError(Exception):
    """A command-line usage problem (exit code 2, one line on stderr)."""


class ParserExit(Exception):
    """`--help` (or `--version`) was answered; carries the exit status."""

    def __init__(self, status: int = 0):
        super().__init__(status)
        self.status = status


class Parser(argparse.ArgumentParser):
    """An `ArgumentParser` that raises [`UsageError`][] instead of exiting, and answers an
    unknown option with "did you mean"."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise UsageError(f"{self.prog}: {message}")

    def exit(self, status=0, message=None):
        if message:
            print(message, file=sys.stderr, end="")
        raise ParserExit(status)

    def option_names(self) -> list[str]:
        return [s for a in self._actions for s in a.option_strings if s.startswith("--")]

    def parse_strict(self, argv: list[str]) -> argparse.Namespace:
        """Parse, refusing unknown options with a "did you mean" answer."""
        args, extra = self.parse_known_args(argv)
        if extra:
            bad = extra[0]
            name = bad.split("=", 1)[0]
            if name.startswith("-"):
                hint = did_you_mean(name, self.option_names())
                raise UsageError(
                    f"{self.prog}: unknown option {name!r}{hint}; see '{self.prog} --help'"
                )
            raise UsageError(f"{self.prog}: unexpected argument {bad!r}; see '{self.prog} --help'")
        return args


class Progress:
    """Progress lines on stderr (`[  1.2s] message`), silent with `quiet`."""

    def __init__(self, quiet: bool = False, stream=None):
        self.quiet = quiet
        self.stream = stream
        self.t0 = time.perf_counter()

    def __call__(self, message: str) -> None:
        check()  # a signal whose exception was swallowed ends the command here
        if self.quiet:
            return
        stream = self.stream or sys.stderr
        print(f"[{time.perf_counter() - self.t0:6.1f}s] {message}", file=stream, flush=True)

    def warn(self, message: str) -> None:
        stream = self.stream or sys.stderr
        print(f"hdjax: warning: {' '.join(str(message).split())}", file=stream, flush=True)


def parse_overrides(items: list[str] | None) -> dict:
    """`["model.poly_order=4", ...]` -> `{"model.poly_order": 4}` (values read as TOML)."""
    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set expects KEY=VALUE (e.g. model.poly_order=4), got {item!r}")
        from ..config import parse_value  # hdjax.config is heavy: imported on use

        out[key.strip()] = parse_value(value.strip())
    return out


RESULT_OVERWRITE = (
    "replace an earlier hdjax result at --out (never any other folder, an input or the current "
    "directory)"
)
"""The `--overwrite` help of the commands that write a result folder."""


def add_command(sub, name: str, help: str, example: str) -> argparse.ArgumentParser:
    """The parser of subcommand `name`: its one-line `help` is also its description, and
    `example` (the command's usage examples) its epilog."""
    return sub.add_parser(name, help=help, description=help, epilog=example)


def add_flag(p: argparse.ArgumentParser, name: str, help: str, *aliases: str) -> None:
    """An on/off option `name` (and its `aliases`, e.g. `-q`), false unless given."""
    p.add_argument(name, *aliases, action="store_true", help=help)


def add_quiet(p: argparse.ArgumentParser, help: str = "no progress lines on stderr") -> None:
    """`--quiet`/`-q`, which every command takes."""
    add_flag(p, "--quiet", help, "-q")


def add_experiment_command(
    sub,
    name: str,
    help: str,
    example: str,
    *,
    config: str,
    out: str,
    flags: dict,
    options: dict | None = None,
) -> argparse.ArgumentParser:
    """The parser of a command that runs an experiment file (`run`, `sweep`): the file
    (`config` its help), the command's on/off `flags` and valued `options` (option -> help),
    `--out` (`out` its help), `--overwrite`, `--set`, `--force` and `--quiet`."""
    p = add_command(sub, name, help, example)
    p.add_argument("config", help=config)
    for flag, flag_help in flags.items():
        add_flag(p, flag, flag_help)
    for option, option_help in (options or {}).items():
        p.add_argument(option, help=option_help)
    p.add_argument("--out", help=out)
    add_flag(p, "--overwrite", RESULT_OVERWRITE)
    p.add_argument(
        "--set",
        metavar="KEY=VALUE",
        action="append",
        help="change one setting of the config, e.g. --set model.poly_order=4 (repeatable; "
        'values are TOML: 4, 1.5, true, [20, 20], "text")',
    )
    add_flag(
        p,
        "--force",
        "run even when a recording's motor/output angle ratio differs from the joint's "
        "(refused by default: the calibration would be wrong)",
    )
    add_quiet(p)
    return p


def resumable_result(out: Path, *, overwrite: bool, inputs: list, command: str):
    """The result folder (a `hdjax.report.ResultDir`) `out` of a command whose finished
    parts survive a failure: they are written to its staging folder `OUT.partial`, which an
    error or an interrupt leaves in place (when it holds finished work) for the next run to
    resume from."""
    from ..report import ResultDir  # hdjax.report is heavy: imported on use

    return ResultDir(
        out,
        overwrite=overwrite,
        inputs=inputs,
        staging=out.parent / f"{out.name}.partial",
        keep_staging_on_error=True,
        command=command,
    )


def experiment_inputs(exp) -> list:
    """Every file an experiment reads: the config and each existing file its `[data]` table
    names (train, test and any other file setting), for the output rules of
    [`hdjax.report.check_output_dir`][]."""
    from pathlib import Path

    from ..config.internal import resolve_path

    paths = [exp.path] if getattr(exp, "path", None) is not None else []

    def walk(v):
        if isinstance(v, str):
            if not v or len(v) > 4096:
                return
            try:
                p = resolve_path(exp, v)
                if p.exists():
                    paths.append(Path(p))
            except (OSError, ValueError):
                pass
        elif isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list | tuple):
            for x in v:
                walk(x)

    walk(exp.get("data", {}))
    return paths


def add_model_command(sub, name: str, help: str, example: str, use: str) -> argparse.ArgumentParser:
    """The parser of a subcommand that reads a saved model ([`add_command`][]): `--model` (a
    model file or the result folder holding it), `--method` (which of its estimators; `use`
    the verb of its help: "use", "export") and `--quiet`."""
    p = add_command(sub, name, help, example)
    p.add_argument(
        "--model",
        required=True,
        help="a model file written by 'hdjax run' or 'hdjax discover' (model.json), or the "
        "result folder holding it",
    )
    p.add_argument(
        "--method",
        choices=("model", "network"),
        default="model",
        help=f"which estimator of the file to {use} (default: the compliance model)",
    )
    add_quiet(p)
    return p


def model_file(path) -> Path:
    """The model file `path` names: the file itself, or the `model.json` of a result folder
    (`ConfigError` for a folder without one)."""
    path = Path(path)
    if path.is_dir():
        if not (path / "model.json").is_file():
            raise ConfigError(
                f"{path}: a folder without model.json; give the model.json written by "
                "'hdjax discover', or by 'hdjax run' (with [outputs] save_model = true)"
            )
        return path / "model.json"
    return path


def read_column_map(path):
    """The [`hdjax.ColumnMap`][] of a TOML file's `[data]` table (or of its top level):
    `columns`, `extras` and the CSV text `encoding`; other keys of the table are ignored, so an
    experiment config serves as a column map; `None` when no file is given (`path` empty)."""
    if not path:
        return None
    from pathlib import Path

    from ..config import parse_toml  # hdjax.config is heavy: imported on use

    cpath = Path(path)
    if not cpath.exists():
        raise ConfigError(f"{cpath}: no such column-map file")
    doc = parse_toml(read_text(cpath, what="column-map file", hint=TOML_HINT), where=str(cpath))
    table = doc.get("data", doc)
    if not isinstance(table, dict):
        raise ConfigError(f"{cpath}: [data] must be a table")
    table = {k: v for k, v in table.items() if k in ("columns", "extras", "encoding")}
    return ColumnMap.from_dict(table, where=f"{cpath} [data]")
