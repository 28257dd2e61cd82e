"""The `hdjax` command: `run`, `sweep`, `estimate`, `discover` and `bench`.

Every [`hdjax.HdjaxError`][] (and every usage error) becomes one line on stderr and exit code
2; an unknown command or option gets a "did you mean" answer. Warnings are printed as one
`hdjax: warning:` line each.
"""

from __future__ import annotations

import sys
import warnings

from .._errors import HdjaxError
from .._io import did_you_mean
from ._common import Parser, ParserExit, UsageError

COMMANDS = ("run", "sweep", "estimate", "discover", "bench", "convert")

DESCRIPTION = """\
Torque estimation for robotic joints with harmonic drives (Song et al. 2019), in JAX.

'hdjax COMMAND --help' explains every option of a command, with an example.
"""

EXAMPLE = """\
example:
  hdjax run experiments/song2019.toml --out runs/song2019 --overwrite
"""


def _parser() -> Parser:
    from . import _bench, _estimate, _run, _sweep

    p = Parser(prog="hdjax", description=DESCRIPTION, epilog=EXAMPLE)
    p.add_argument("--version", action="store_true", help="print the version and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    _run.add_parser(sub)
    _sweep.add_parser(sub)
    _estimate.add_parser(sub)
    sub.add_parser(
        "discover",
        help="residual loop: find, trace and add missing effects (see 'hdjax discover --help')",
        add_help=False,
    )
    _bench.add_parser(sub)
    from . import _convert

    _convert.add_parser(sub)
    return p


def _discover(argv: list[str]) -> int:
    try:
        from ..discover import cli_main
    except ImportError as err:
        raise UsageError(
            f"hdjax discover: not available in this installation (hdjax.discover.cli_main "
            f"cannot be imported: {err})"
        ) from None
    try:
        return int(cli_main(list(argv)) or 0)
    except SystemExit as done:  # its argparse answers --help and usage errors by exiting
        code = done.code
        return code if isinstance(code, int) else (0 if code is None else 2)


def _dispatch(argv: list[str]) -> int:
    from . import _bench, _estimate, _run, _sweep

    if argv and not argv[0].startswith("-") and argv[0] not in COMMANDS:
        raise UsageError(
            f"hdjax: unknown command {argv[0]!r}{did_you_mean(argv[0], COMMANDS)}; commands: "
            f"{', '.join(COMMANDS)}"
        )
    if argv and argv[0] == "discover":
        return _discover(argv[1:])
    parser = _parser()
    if not argv or argv[0].startswith("-"):
        args = parser.parse_strict(argv)
        if args.version:
            from .. import __version__

            print(f"hdjax {__version__}")
        else:
            parser.print_help()
        return 0
    sub = parser._subparsers._group_actions[0].choices[argv[0]]
    args = sub.parse_strict(argv[1:])
    handlers = {"run": _run, "sweep": _sweep, "estimate": _estimate, "bench": _bench}
    from . import _convert

    handlers["convert"] = _convert
    return handlers[argv[0]].command(args, sub)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"hdjax: warning: {' '.join(str(message).split())}", file=sys.stderr, flush=True)


def main(argv=None) -> int:
    """Entry point of the `hdjax` command (`[project.scripts] hdjax = "hdjax.cli:main"`).

    **Arguments:**

    - `argv`: the arguments after the program name (default `sys.argv[1:]`).

    **Returns:** the exit code: 0 on success, 2 on bad input (one line on stderr), 130 when
    interrupted.
    """
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = _show_warning
        try:
            return _dispatch(argv)
        except (HdjaxError, UsageError) as err:
            text = " ".join(str(err).split())
            prefix = "" if text.startswith("hdjax") else "hdjax: error: "
            print(f"{prefix}{text}", file=sys.stderr, flush=True)
            return 2
        except ParserExit as done:
            return done.status
        except KeyboardInterrupt:
            print("hdjax: interrupted", file=sys.stderr, flush=True)
            return 130
