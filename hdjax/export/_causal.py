"""What the exporter refuses, and what it says it changed: terms without C code and estimates
that read samples ahead of the present one.

A controller has the present sample and earlier ones only. [`hdjax.signals`][] with
`causal=True` derives every velocity that way; the exported step computes the same, so it
equals the JAX estimate with `causal=True`. Of the velocity options:

- `"difference"` (eqs. (13)-(14)) is causal but for its first sample, which copies the
  second's velocity: the causal form (and the exported step) starts at rest. This is exported
  as it is, with a note.
- `"smoothed"` is a centred least-squares line that reads `half_window` samples ahead: it is
  refused, unless the export asks for its causal form (the line over the window that ends at
  the sample, which delays the velocity by `half_window` samples).
"""

from __future__ import annotations

from collections.abc import Iterable

from .._errors import ExportError
from ..effects import AbstractTerm, families


def has_c_code(term: AbstractTerm | type) -> bool:
    """Whether a term (or term class) defines its C code (`c_code`, see
    [`hdjax.effects.CSnippet`][])."""
    cls = term if isinstance(term, type) else type(term)
    return getattr(cls, "c_code", None) is not None


def family_of(cls: type) -> str:
    """The name of the registered effect family a term class belongs to (`"?"` if none)."""
    for family in families():
        if cls in family.terms:
            return family.name
    return "?"


def check_terms(terms: Iterable[AbstractTerm]) -> None:
    """Refuse ([`hdjax.ExportError`][]) a model holding a term without C code, naming the first
    one and its family."""
    for term in terms:
        if not has_c_code(term):
            cls = type(term)
            raise ExportError(
                f"the model's term {cls.__name__} ({term.key}, effect family "
                f"{family_of(cls)!r}) has no C code, so the model cannot be exported; give "
                f"{cls.__name__} a c_code method (see 'Adding an effect family') or calibrate "
                "without it"
            )


def velocity_notes(what: str, velocity: str, causal: bool, half_window: int) -> tuple[str, ...]:
    """The README's note on how the exported step derives velocities, or
    [`hdjax.ExportError`][] for a velocity that reads ahead when `causal` is not given."""
    if velocity == "difference":
        return (
            "Velocities are the backward difference of eqs. (13)-(14). The first sample after "
            "hdjax_init has no earlier one and is at rest (velocity 0), where the estimate of "
            "a whole recording copies the second sample's velocity. Later samples read the same "
            "velocities (only a hysteresis state driven by the estimated torque carries the "
            "first sample's difference on); hdjax estimate --causal equals the step everywhere.",
        )
    if velocity != "smoothed":
        raise ExportError(f"{what} derives velocities by {velocity!r}, which has no C code")
    window = 2 * half_window + 1
    if not causal:
        raise ExportError(
            f'{what} derives velocities with velocity = "smoothed", a centred least-squares '
            f"line that reads {half_window} samples ahead of each estimate, which a per-sample "
            f"step cannot; export its causal form (hdjax export --causal: the line over the "
            f"{window} samples up to each one, {half_window} samples late), or calibrate with "
            'velocity = "difference"'
        )
    return (
        f'Velocities are the causal form of velocity = "smoothed": the least-squares line over '
        f"the {window} samples up to and including each one (the estimate of a recording uses "
        f"the centred window instead, which reads {half_window} samples ahead; the causal "
        f"line's velocity is {half_window} samples late). hdjax estimate --causal computes "
        "this estimate.",
    )
