"""Where a result may be written: the rules that keep a user's own files safe.

Every command that writes goes through these checks before any work starts:

- An output is never an input, never holds an input and never lies inside one, whatever the
  flags (inputs are the config, the data files, the model, the joint and the column map).
- The current directory (or a folder holding it) is never replaced.
- `--overwrite` replaces only a result folder hdjax wrote itself: one stamped with the marker
  file [`MARKER`][] that lists the files of the result, and holding no other file. Any other
  non-empty folder is refused, saying what is in it; an empty folder is used as if absent.
- The folder that would receive the output must exist as a folder (not a file) and be writable.

Each refusal is a [`hdjax.ConfigError`][] of the form `<path>: <what is wrong>; <what to do>`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from .. import __version__
from .._custom_types import PathLike
from .._errors import ConfigError

MARKER = ".hdjax-result"
"""The marker file hdjax writes into every result folder (JSON: format, command, files)."""

_FORMAT = "hdjax-result"


def _real(p) -> Path:
    return Path(os.path.realpath(os.path.expanduser(os.fspath(p))))


def _within(inner: Path, outer: Path) -> bool:
    return inner == outer or outer in inner.parents


def check_not_input(out: PathLike, inputs: Iterable, *, flag: str = "--out") -> None:
    """Refuse an output that is an input, holds an input or lies inside one.

    **Arguments:**

    - `out`: the output path (file or folder).
    - `inputs`: every path the command reads (`None` entries are skipped).
    - `flag`: the option name for the message.

    **Raises:** [`hdjax.ConfigError`][], whatever `--overwrite` says.
    """
    o = _real(out)
    for p in inputs:
        if p is None:
            continue
        r = _real(p)
        if o == r:
            raise ConfigError(
                f"{out}: {flag} is also an input of this command ({p}); hdjax never writes over "
                f"its inputs; choose another {flag}"
            )
        if _within(r, o):
            raise ConfigError(
                f"{out}: {flag} holds the input {p}; hdjax never replaces a folder holding its "
                f"inputs; choose another {flag}"
            )
        if _within(o, r):
            raise ConfigError(
                f"{out}: {flag} lies inside the input {p}; choose another {flag} outside it"
            )


def check_location(out, *, flag: str = "--out") -> None:
    """Refuse an output whose parent is a file, or a folder hdjax cannot write in."""
    parent = Path(os.path.abspath(os.path.expanduser(os.fspath(out)))).parent
    while not parent.exists() and parent != parent.parent:
        if parent.is_symlink():  # a dangling link
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise ConfigError(
            f"{out}: {parent} is a file, not a folder, so it cannot hold {flag}; choose another "
            f"{flag}"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(
            f"{out}: cannot write in {parent} (permission denied or read-only file system); "
            f"choose another {flag} or fix the folder's permissions"
        )


def _describe(folder: Path) -> str:
    names = sorted(p.name + ("/" if p.is_dir() else "") for p in folder.iterdir())
    shown = ", ".join(names[:4])
    return shown + (f" and {len(names) - 4} more" if len(names) > 4 else "")


def read_marker(folder: PathLike) -> dict | None:
    """The marker of an hdjax result folder, or `None` when `folder` holds none."""
    p = Path(folder) / MARKER
    if not p.is_file() or p.is_symlink():
        return None
    try:
        doc = json.loads(p.read_bytes()[:1_000_000].decode("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != _FORMAT:
        return None
    if not isinstance(doc.get("files"), list):
        return None
    return doc


def marker_bytes(command: str, files: Iterable[str], **extra) -> bytes:
    """The content of a result folder's [`MARKER`][] file."""
    doc = {
        "format": _FORMAT,
        "command": command,
        "hdjax_version": __version__,
        "files": sorted(set(files)),
        **extra,
    }
    return (json.dumps(doc, indent=2) + "\n").encode()


def _files_under(folder: Path) -> set[str]:
    out = set()
    for root, _dirs, files in os.walk(folder):
        for f in files:
            out.add(Path(root, f).relative_to(folder).as_posix())
    return out


def check_output_dir(
    out: PathLike, *, inputs: Iterable = (), overwrite: bool = False, flag: str = "--out"
) -> str:
    """Check that `out` may receive a result folder; returns `"new"`, `"empty"` or `"result"`.

    **Raises:** [`hdjax.ConfigError`][] when `out` is (or holds, or lies in) an input, is or holds
    the current directory, is a file, is a non-empty folder hdjax did not write (even with
    `overwrite`), holds files its marker does not list, or is a result and `overwrite` is false.
    """
    out = Path(out)
    check_not_input(out, inputs, flag=flag)
    if _within(_real(Path.cwd()), _real(out)):
        raise ConfigError(
            f"{out}: {flag} is the current directory or holds it, which hdjax never replaces; "
            f"choose a new folder, e.g. {flag} runs/NAME"
        )
    check_location(out, flag=flag)
    if not out.exists():
        if out.is_symlink():
            raise ConfigError(
                f"{out}: a dangling symbolic link; remove it or choose another {flag}"
            )
        return "new"
    if not out.is_dir():
        raise ConfigError(
            f"{out}: exists and is a file, not a result folder; choose another {flag}"
        )
    if not any(out.iterdir()):
        return "empty"
    marker = read_marker(out)
    if marker is None:
        older = any((out / n).is_file() for n in ("metrics.json", "report.json"))
        hint = (
            " (a result of an hdjax version without the marker file? remove it yourself)"
            if older
            else ""
        )
        raise ConfigError(
            f"{out}: not an hdjax result folder (it holds {_describe(out)}); hdjax replaces only "
            f"a folder it wrote itself and stamped with {MARKER}, even with --overwrite{hint}; "
            f"choose another {flag}"
        )
    if not overwrite:
        raise ConfigError(
            f"{out}: a result folder already exists here; choose another {flag} or pass "
            "--overwrite to replace it"
        )
    foreign = sorted(_files_under(out) - set(marker["files"]) - {MARKER})
    if foreign:
        more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        raise ConfigError(
            f"{out}: holds files hdjax did not write ({', '.join(foreign[:3])}{more}); move them "
            f"out of the folder or choose another {flag}"
        )
    return "result"


def check_output_file(
    out: PathLike,
    *,
    inputs: Iterable = (),
    overwrite: bool = False,
    flag: str = "--out",
    ours: Callable[[Path], bool] | None = None,
    example: str = "result.csv",
) -> None:
    """Check that the file `out` may be written.

    **Arguments:**

    - `out`, `inputs`, `overwrite`, `flag`: as for [`check_output_dir`][].
    - `ours`: tells whether an existing file is one hdjax wrote (only such a file is replaced).
    - `example`: a file name for the message when `out` is a folder.

    **Raises:** [`hdjax.ConfigError`][].
    """
    out = Path(out)
    check_not_input(out, inputs, flag=flag)
    check_location(out, flag=flag)
    if out.is_dir():
        raise ConfigError(
            f"{out}: is a folder; {flag} takes a file name, e.g. {flag} {out / example}"
        )
    if out.exists():
        if not overwrite:
            raise ConfigError(
                f"{out}: the file already exists; choose another {flag} or pass --overwrite to "
                "replace it"
            )
        if ours is not None and not ours(out):
            raise ConfigError(
                f"{out}: not a file hdjax wrote, so it is not replaced, even with --overwrite; "
                f"choose another {flag}"
            )
