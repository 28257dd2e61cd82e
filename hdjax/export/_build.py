"""Build an exported estimator with the system C compiler and run it from Python (`ctypes`).

The tests and the benchmark compare and time the generated C this way:
[`build_library`][] compiles `hdjax_estimator.c` with `cc -std=c99 -Wall -Wextra -Werror -O2`
(every warning an error) into a shared library beside a small entry point, and
[`CLibrary.run`][] hands it a recording's samples as one array (the `hdjax_sample` layout: all
doubles, no padding) and returns the torque and flags of every sample.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from .._custom_types import Float, Shaped
from .._errors import ExportError
from .._recording import Recording
from ._assemble import CCode

CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-O2")
"""The flags every exported estimator must compile under."""

_ENTRY = """\
#include "hdjax_estimator.h"
/* one pass over n samples from a fresh state, for ctypes */
void hdjax_run(const hdjax_sample *x, size_t n, double *torque, unsigned *flags)
{
    hdjax_state s;
    hdjax_init(&s);
    hdjax_batch(&s, x, n, torque, flags);
}
"""


def find_compiler() -> str | None:
    """The system C compiler (`$CC`, else `cc`, `gcc` or `clang` on the path), or `None`."""
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


class CLibrary:
    """A compiled estimator: `run(recording)` (or `run_samples(array)`) gives the torque and
    flags of every sample, from a fresh state."""

    def __init__(self, path: Path, code: CCode):
        self.path = path
        self.code = code
        self._lib = ctypes.CDLL(str(path))
        self._run = self._lib.hdjax_run
        self._run.restype = None
        self._run.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p]

    def samples(self, recording: Recording) -> Float[np.ndarray, "n n_fields"]:
        """A recording as the `hdjax_sample` array the library reads."""
        cols = [np.asarray(getattr(recording, k), np.float64) for k in ("t", "theta_m")]
        cols += [np.asarray(getattr(recording, k), np.float64) for k in ("theta_l", "current")]
        for name in self.code.extras:
            if name not in recording.extras:
                raise ExportError(f"{recording.source}: no extra column {name!r}")
            cols.append(np.asarray(recording.extras[name], np.float64))
        return np.ascontiguousarray(np.column_stack(cols))

    def run_samples(
        self, x: Float[np.ndarray, "n n_fields"]
    ) -> tuple[Float[np.ndarray, " n"], Shaped[np.ndarray, " n"], float]:
        """Torque, flags and the seconds the batch call took, for an `hdjax_sample` array."""
        x = np.ascontiguousarray(x, np.float64)
        n = x.shape[0]
        torque = np.empty(n, np.float64)
        flags = np.empty(n, np.uint32)
        t0 = time.perf_counter()
        self._run(x.ctypes.data, n, torque.ctypes.data, flags.ctypes.data)
        return torque, flags, time.perf_counter() - t0

    def run(self, recording: Recording) -> tuple[Float[np.ndarray, " n"], Shaped[np.ndarray, " n"]]:
        """Torque [N·m] and `HDJAX_*` flags of every sample of `recording`."""
        torque, flags, _ = self.run_samples(self.samples(recording))
        return torque, flags


def write_sources(code: CCode, directory: Path) -> None:
    """Write `hdjax_estimator.h` and `hdjax_estimator.c` of `code` into `directory`."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "hdjax_estimator.h").write_text(code.header)
    (directory / "hdjax_estimator.c").write_text(code.source)


def compile_c(
    directory: Path,
    sources: list[str],
    output: str,
    extra: tuple[str, ...] = (),
    cc: str | None = None,
) -> Path:
    """Compile `sources` in `directory` with [`CFLAGS`][] (and `extra`) into `output`;
    [`hdjax.ExportError`][] with the compiler's messages when it fails."""
    cc = cc or find_compiler()
    if cc is None:
        raise ExportError("no C compiler found (set CC, or install cc, gcc or clang)")
    cmd = [cc, *CFLAGS, *extra, *sources, "-o", output, "-lm"]
    done = subprocess.run(cmd, cwd=directory, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise ExportError(f"{' '.join(cmd)} failed:\n{done.stderr.strip()}")
    return directory / output


def build_library(code: CCode, directory: Path, *, name: str = "hdjax_estimator") -> CLibrary:
    """Compile `code` into a shared library in `directory` and load it (see the module)."""
    directory = Path(directory)
    write_sources(code, directory)
    (directory / "hdjax_run.c").write_text(_ENTRY)
    lib = compile_c(
        directory,
        ["hdjax_estimator.c", "hdjax_run.c"],
        f"lib{name}.so",
        extra=("-shared", "-fPIC"),
    )
    return CLibrary(lib, code)
