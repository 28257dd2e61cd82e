"""Build an exported estimator with the system C compiler and run it from Python (`ctypes`).

The tests and the benchmark compare and time the generated C this way:
[`build_library`][] compiles `hdjax_estimator.c` with `cc -std=c99 -Wall -Wextra -Werror -O2`
(every warning an error) into a shared library beside a small entry point, and
[`CLibrary.run`][] hands it a recording's samples as one array (the `hdjax_sample` layout: all
doubles, no padding) and returns the torque and flags of every sample; an estimator with
`hdjax_sample_from_counts` ([`hdjax.export.counts_c`][]) is also run from encoder counts
([`CLibrary.run_counts`][]), each sample converted by the C function.
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

_ENTRY_COUNTS = """
/* the same from 64-bit encoder counts: x[i]'s angles (and time stamp and current) written by
   hdjax_sample_from_counts before its step; its extra columns as given */
void hdjax_run_counts(hdjax_sample *x, const long long *counts_m, const long long *counts_l,
                      const hdjax_counts_offset *z, size_t n, double *torque, unsigned *flags)
{
    hdjax_state s;
    size_t i;
    hdjax_init(&s);
    for (i = 0; i < n; ++i) {
        hdjax_sample_from_counts(&x[i], x[i].t, counts_m[i], counts_l[i], x[i].current, z);
        torque[i] = hdjax_step(&s, &x[i]);
        flags[i] = s.flags;
    }
}
"""


class CountsOffset(ctypes.Structure):
    """`hdjax_counts_offset`: the zero counts and the offsets [rad] of the two encoders."""

    _fields_ = [
        ("zero_m", ctypes.c_longlong),
        ("zero_l", ctypes.c_longlong),
        ("offset_m", ctypes.c_double),
        ("offset_l", ctypes.c_double),
    ]


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
        self._run_counts = None
        if code.counts_per_rev is not None:
            self._run_counts = self._lib.hdjax_run_counts
            self._run_counts.restype = None
            self._run_counts.argtypes = (
                [ctypes.c_void_p] * 4 + [ctypes.c_size_t] + [ctypes.c_void_p] * 2
            )

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

    def run_counts(
        self,
        x: Float[np.ndarray, "n n_fields"],
        counts_m: Shaped[np.ndarray, " n"],
        counts_l: Shaped[np.ndarray, " n"],
        *,
        zero: tuple[int, int] | None = (0, 0),
        offset: tuple[float, float] = (0.0, 0.0),
    ) -> tuple[Float[np.ndarray, " n"], Shaped[np.ndarray, " n"], Float[np.ndarray, "n n_fields"]]:
        """Torque, flags and the samples the C code stepped: each row of the `hdjax_sample`
        array `x` (its `t`, `current` and extra columns; its angles are overwritten) filled by
        `hdjax_sample_from_counts` from the int64 `counts_m`, `counts_l` and an
        `hdjax_counts_offset` of `zero` counts and `offset` [rad] (`zero=None`: a NULL offset)."""
        if self._run_counts is None:
            raise ExportError("this estimator has no hdjax_sample_from_counts (see counts_c)")
        x = np.array(x, np.float64, order="C", copy=True)
        counts_m = np.ascontiguousarray(counts_m, np.int64)
        counts_l = np.ascontiguousarray(counts_l, np.int64)
        n = x.shape[0]
        if counts_m.shape != (n,) or counts_l.shape != (n,):
            raise ExportError(f"{n} samples but {counts_m.shape} / {counts_l.shape} counts")
        z = None
        if zero is not None:
            z = CountsOffset(int(zero[0]), int(zero[1]), float(offset[0]), float(offset[1]))
        torque = np.empty(n, np.float64)
        flags = np.empty(n, np.uint32)
        self._run_counts(
            x.ctypes.data,
            counts_m.ctypes.data,
            counts_l.ctypes.data,
            None if z is None else ctypes.addressof(z),
            n,
            torque.ctypes.data,
            flags.ctypes.data,
        )
        return torque, flags, x


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


def build_library(
    code: CCode, directory: Path, *, name: str = "hdjax_estimator", extra: tuple[str, ...] = ()
) -> CLibrary:
    """Compile `code` into a shared library in `directory` (with [`CFLAGS`][] and `extra`,
    e.g. `("-pedantic",)`) and load it (see the module)."""
    directory = Path(directory)
    write_sources(code, directory)
    entry = _ENTRY + (_ENTRY_COUNTS if code.counts_per_rev is not None else "")
    (directory / "hdjax_run.c").write_text(entry)
    lib = compile_c(
        directory,
        ["hdjax_estimator.c", "hdjax_run.c"],
        f"lib{name}.so",
        extra=("-shared", "-fPIC", *extra),
    )
    return CLibrary(lib, code)
