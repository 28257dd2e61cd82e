"""JAX's persistent compilation cache for the command line (warm starts).

A command compiles its jitted steps once per shape; the compiled programs are kept on disk in
the user's cache directory (`$XDG_CACHE_HOME/hdjax/jax`, by default `~/.cache/hdjax/jax`), so
a second run of the same shapes loads them instead of compiling. The CLI turns it on unless
`--no-cache` is given (or `HDJAX_NO_CACHE=1` is set).
"""

from __future__ import annotations

import os
from pathlib import Path

MIN_COMPILE_SECONDS = 0.0
"""Compilations at least this long are cached (0: every one; a discover run compiles hundreds
of small programs, and together they are most of its start-up time)."""


def cache_dir() -> Path:
    """`$XDG_CACHE_HOME/hdjax/jax`, with `~/.cache` when `XDG_CACHE_HOME` is unset or empty."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "hdjax" / "jax"


def enable_compilation_cache(path=None) -> Path | None:
    """Point JAX's persistent compilation cache at `path` (default [`cache_dir`][]).

    **Returns:** the directory, or `None` when it cannot be created (then nothing is cached
    and a warning says why; a command never fails for want of a cache).
    """
    import warnings

    import jax

    path = Path(path) if path is not None else cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        warnings.warn(
            f"compilation cache disabled: cannot create {path} ({err.strerror}); pass "
            "--no-cache or set XDG_CACHE_HOME to a writable folder",
            stacklevel=2,
        )
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _reset_if_checked()
    return path


def disable_compilation_cache() -> None:
    """Turn the persistent compilation cache off for this process."""
    import jax

    jax.config.update("jax_compilation_cache_dir", None)
    _reset_if_checked()


def _reset_if_checked() -> None:
    # JAX decides once per process whether the cache is used; when something compiled before
    # the CLI set the directory (an in-process caller), make it decide again.
    try:
        from jax._src import compilation_cache as cc
    except ImportError:  # pragma: no cover - a JAX without the private module
        return
    if getattr(cc, "_cache_checked", False) or getattr(cc, "_cache_initialized", False):
        cc.reset_cache()
