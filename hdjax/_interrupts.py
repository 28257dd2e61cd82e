"""Interruptions of the `hdjax` command: SIGINT (Ctrl-C) and SIGTERM (`kill`, a scheduler's time
limit) end a command with exit code 130 or 143 and no partial result.

While a command runs, both signals raise [`Interrupted`][] so that every staging folder is
removed on the way out (a sweep keeps its finished members for resuming). The exception can be
swallowed when it lands inside a callback Python runs on its own (JAX's garbage-collection
callback is one), so the signal is also remembered: [`check`][] raises it again at the next
progress line and before a result is moved into place, and the command's exit code reports it.
When it lands inside C code it can surface as another error (a `SystemError`, "returned a result
with an exception set"); with a signal remembered, the command line reports that as the interrupt.
Before the command starts (while Python imports JAX) there is nothing to clean up, and a signal
ends the process at once with the same exit codes.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_NAMES = {signal.SIGINT: "SIGINT", signal.SIGTERM: "SIGTERM"}

_pending: int | None = None
_critical = 0


class Interrupted(BaseException):
    """A command was interrupted by SIGINT or SIGTERM (not an error: a `BaseException`)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    @property
    def name(self) -> str:
        return _NAMES.get(self.signum, f"signal {self.signum}")


def _handler(signum, frame):
    global _pending
    _pending = signum
    if not _critical:
        raise Interrupted(signum)


def pending() -> int | None:
    """The signal received while the current command runs, if any."""
    return _pending


def check() -> None:
    """Raise [`Interrupted`][] if a signal arrived (even one whose exception was swallowed)."""
    if _pending is not None and not _critical:
        raise Interrupted(_pending)


@contextlib.contextmanager
def critical():
    """A section that a signal does not cut short (it is remembered and reported after)."""
    global _critical
    _critical += 1
    try:
        yield
    finally:
        _critical -= 1


@contextlib.contextmanager
def handling():
    """Turn SIGINT and SIGTERM into [`Interrupted`][] while the block runs (main thread only);
    one that is ignored (the process was started so) stays ignored."""
    global _pending
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    # a signal the process was started with ignored (a background job of a shell, `nohup`)
    # stays ignored, as the convention of such jobs wants
    old = {s: h for s in _SIGNALS if (h := signal.getsignal(s)) is not signal.SIG_IGN}
    old_hook = sys.unraisablehook
    _pending = None
    for s in old:
        signal.signal(s, _handler)
    sys.unraisablehook = _quiet_unraisable(old_hook)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        sys.unraisablehook = old_hook
        _pending = None  # reported by the command; the next one starts clean


def _quiet_unraisable(fallback):
    """An `sys.unraisablehook` that drops an [`Interrupted`][] raised inside a callback Python
    runs on its own (it would print "Exception ignored in ..." and a traceback): the signal is
    remembered and [`check`][] raises it again. Anything else goes to `fallback`."""

    def hook(unraisable):
        if isinstance(unraisable.exc_value, Interrupted):
            return
        fallback(unraisable)

    return hook


def _exit_now(signum, frame):
    os.write(2, f"hdjax: interrupted ({_NAMES.get(signum, signum)})\n".encode())
    os._exit(128 + signum)


def guard_startup() -> None:
    """When this process is the `hdjax` command, a signal during start-up exits at once."""
    argv0 = sys.argv[0] if sys.argv else ""
    if not (argv0 == "-m" or os.path.basename(argv0) in ("hdjax", "hdjax.exe")):
        return
    if threading.current_thread() is not threading.main_thread():
        return
    for s in _SIGNALS:
        if signal.getsignal(s) in (signal.default_int_handler, signal.SIG_DFL):
            signal.signal(s, _exit_now)
