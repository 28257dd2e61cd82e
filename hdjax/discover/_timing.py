"""Wall and process time per phase of the residual loop (its last progress line).

The loop runs its phases inside `phase(name)`; [`Phases.line`][] sums them up, e.g.
`phases [s wall / s cpu]: baseline 1.2/2.0, score 3.1/5.4, ...`. Process time counts every
thread of the process, so on a shared machine it says how much work a phase did, where wall
time also says how busy the machine was.
"""

from __future__ import annotations

import contextlib
import time


class Phases:
    """Accumulated `(wall, cpu)` seconds per phase name, in first-use order."""

    def __init__(self) -> None:
        self.seconds: dict[str, list[float]] = {}

    @contextlib.contextmanager
    def __call__(self, name: str):
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            acc = self.seconds.setdefault(name, [0.0, 0.0])
            acc[0] += time.perf_counter() - w0
            acc[1] += time.process_time() - c0

    def line(self) -> str:
        parts = ", ".join(f"{k} {w:.1f}/{c:.1f}" for k, (w, c) in self.seconds.items())
        return f"phases [s wall / s cpu]: {parts}"


_NULL = Phases()


def null_phases() -> Phases:
    """A `Phases` whose totals nobody reads (the default of helpers called outside a loop)."""
    return _NULL
