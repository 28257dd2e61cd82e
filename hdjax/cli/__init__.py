"""The `hdjax` command: `run`, `sweep`, `estimate`, `discover`, `bench`, `convert`, `fleet` and
`export`.

Every [`hdjax.HdjaxError`][], usage error and user-caused `OSError` becomes one line on stderr
(`hdjax: error: <file>: <what went wrong>; <what to do>`) and exit code 2; an unknown command
or option gets a "did you mean" answer. SIGINT and SIGTERM end a command with exit code 130 or
143 and remove its staging folder (a sweep keeps its finished members). Warnings are printed as one
`hdjax: warning:` line each.
"""

from __future__ import annotations

import errno
import importlib
import os
import sys
import warnings

from .. import __version__
from .._cache import disable_compilation_cache, enable_compilation_cache
from .._errors import HdjaxError, did_you_mean
from .._interrupts import Interrupted, handling, pending
from ._common import Parser, ParserExit, UsageError

# Each command's module (`add_parser`, `command`), imported only when that command runs or the
# overview is printed: together they pull in every sub-package (about a second of start-up).
_MODULES = {
    "run": "hdjax.cli._run",
    "sweep": "hdjax.cli._sweep",
    "estimate": "hdjax.cli._estimate",
    "discover": "hdjax.cli._discover",
    "bench": "hdjax.cli._bench",
    "convert": "hdjax.cli._convert",
    "fleet": "hdjax.cli._fleet",
    "export": "hdjax.cli._export",
}
COMMANDS = tuple(_MODULES)

DESCRIPTION = """\
Torque estimation for robotic joints with harmonic drives (Song et al. 2019), in JAX.

'hdjax COMMAND --help' explains every option of a command, with an example.
"""

EXAMPLE = """\
example:
  hdjax run experiments/song2019.toml --out runs/song2019 --overwrite
"""


def _parser(only: str | None = None) -> Parser:
    p = Parser(prog="hdjax", description=DESCRIPTION, epilog=EXAMPLE)
    p.add_argument("--version", action="store_true", help="print the version and exit")
    p.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the compilation cache in $XDG_CACHE_HOME/hdjax (any command takes it)",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for name in COMMANDS if only is None else (only,):
        importlib.import_module(_MODULES[name]).add_parser(sub)
    return p


def _dispatch(argv: list[str]) -> int:
    if argv and not argv[0].startswith("-") and argv[0] not in COMMANDS:
        raise UsageError(
            f"hdjax: unknown command {argv[0]!r}{did_you_mean(argv[0], COMMANDS)}; commands: "
            f"{', '.join(COMMANDS)}"
        )
    if not argv or argv[0].startswith("-"):
        parser = _parser()
        args = parser.parse_strict(argv)
        if args.version:
            print(f"hdjax {__version__}")
        else:
            parser.print_help()
        return 0
    parser = _parser(only=argv[0])
    sub = parser._subparsers._group_actions[0].choices[argv[0]]
    args = sub.parse_strict(argv[1:])
    return importlib.import_module(_MODULES[argv[0]]).command(args, sub)


def _compilation_cache(argv: list[str]) -> list[str]:
    """Turn JAX's persistent compilation cache on (off with `--no-cache`, accepted by every
    command, or `HDJAX_NO_CACHE=1`); returns `argv` without `--no-cache`."""
    end = argv.index("--") if "--" in argv else len(argv)
    off = "--no-cache" in argv[:end] or os.environ.get("HDJAX_NO_CACHE", "") not in ("", "0")
    if off:
        disable_compilation_cache()
    else:
        enable_compilation_cache()
    return [a for i, a in enumerate(argv) if not (a == "--no-cache" and i < end)]


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"hdjax: warning: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


_OS_ADVICE = {
    errno.EACCES: "check its permissions or choose another location",
    errno.EPERM: "check its permissions or choose another location",
    errno.EROFS: "the file system is read-only; choose another location",
    errno.ENOSPC: "the disk is full; free some space or choose another location",
    errno.EDQUOT: "the disk quota is exceeded; free some space or choose another location",
    errno.ENOTDIR: "a part of the path is a file, not a folder; check the path",
    errno.EISDIR: "it is a folder; give a file",
    errno.ENOENT: "check the path",
    errno.EEXIST: "it already exists; choose another name",
    errno.ENAMETOOLONG: "use a shorter name",
    errno.EBUSY: "it is in use; choose another location",
}


def os_error_line(err: OSError) -> str:
    """`<file>: <what went wrong>; <what to do>` for an `OSError` a user caused."""
    where = err.filename if err.filename is not None else "hdjax"
    what = (err.strerror or str(err)).lower()
    advice = _OS_ADVICE.get(err.errno, "check the path and try again")
    return f"{where}: {what}; {advice}"


def main(argv=None) -> int:
    """Entry point of the `hdjax` command (`[project.scripts] hdjax = "hdjax.cli:main"`).

    **Arguments:**

    - `argv`: the arguments after the program name (default `sys.argv[1:]`).

    **Returns:** the exit code: 0 on success, 2 on bad input (one line on stderr,
    `hdjax: error: <file>: <what went wrong>; <what to do>`), 130 after SIGINT (Ctrl-C) and
    143 after SIGTERM, with no partial result left behind.
    """
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]

    def fail(text: str) -> int:
        text = " ".join(str(text).split())
        prefix = "" if text.startswith("hdjax") else "hdjax: error: "
        print(f"{prefix}{text}", file=sys.stderr, flush=True)
        return 2

    def interrupted(signum: int) -> int:
        done = Interrupted(signum)
        print(f"hdjax: interrupted ({done.name})", file=sys.stderr, flush=True)
        return done.exit_code

    with handling(), warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = _show_warning
        try:
            argv = _compilation_cache(argv)
            code = _dispatch(argv)
        except Interrupted as done:
            return interrupted(done.signum)
        except KeyboardInterrupt:
            return interrupted(2)
        except (HdjaxError, UsageError) as err:
            code = fail(str(err))
        except UnicodeDecodeError as err:
            code = fail(
                f"cannot decode a text input ({err}); save the file as UTF-8, or set encoding "
                "in its column map"
            )
        except OSError as err:
            code = fail(os_error_line(err))
        except ParserExit as done:
            code = done.status
        except Exception:
            if pending() is None:
                raise
            # a signal that lands inside C code (numpy's dtype hook, say) can surface as
            # another error ("returned a result with an exception set"): still an interrupt
            return interrupted(pending())
        if pending() is not None:
            return interrupted(pending())
        return code
