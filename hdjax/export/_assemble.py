"""The parts every exported estimator shares: the sample and state structs, the signals of one
sample (Song et al. eqs. (5), (13)-(14)), `hdjax_init`, `hdjax_step`, `hdjax_batch`.

A model generator ([`hdjax.export.compliance_c`][], [`hdjax.export.network_c`][]) hands a
[`StepParts`][] (its state members, helper functions and the body of the step that turns the
signals into a torque) to [`assemble`][], which writes the header and the source around it.
"""

from __future__ import annotations

import dataclasses

from .. import __version__
from ._emitter import Emitter, c_double

FLAGS = (
    ("HDJAX_OUT_OF_RANGE", 1, "the torque lies outside the calibrated range"),
    ("HDJAX_AMBIGUOUS", 2, "several torque segments were self-consistent (the deepest is taken)"),
    ("HDJAX_UNRESOLVED", 4, "no torque segment was self-consistent (clipped to a segment edge)"),
    ("HDJAX_INPUT_OUTSIDE", 8, "an input lies over 4 standard deviations from the training mean"),
)
"""The bits of `hdjax_state.flags` after a step: (macro, value, meaning)."""


@dataclasses.dataclass(frozen=True)
class CCode:
    """The generated estimator: `header` (`hdjax_estimator.h`) and `source`
    (`hdjax_estimator.c`) texts, the `extras` the sample carries (in the order of its `extra`
    array), the `precision`, what it estimates (`kind`: `"compliance"` or `"network"`), the
    `flags` its step can set (macro names), `notes` (what differs from the JAX estimate
    without `causal`, for the README) and `counts_per_rev`, the motor and load encoders' counts
    per revolution when it has `hdjax_sample_from_counts` ([`hdjax.export.counts_c`][]), else
    `None`."""

    header: str
    source: str
    extras: tuple[str, ...]
    precision: str
    kind: str
    flags: tuple[str, ...]
    notes: tuple[str, ...]
    counts_per_rev: tuple[int, int] | None = None


HEADER_TAIL = """
#ifdef __cplusplus
}
#endif

#endif /* HDJAX_ESTIMATOR_H */
"""
"""How every estimator header ends: declarations added later ([`hdjax.export.counts_c`][]) go
before it."""


@dataclasses.dataclass(frozen=True)
class StepParts:
    """What a model generator adds to the shared estimator.

    **Fields:**

    - `emitter`: the [`hdjax.export.Emitter`][] the code was written with (which signals it
      reads, its states).
    - `states`: `(declaration, initialisation)` pairs of C lines for the state struct and
      `hdjax_init`.
    - `helpers`: static C functions placed before the step.
    - `body`: the step's statements from the signals to `torque` (double), `flags` (unsigned)
      and `segment` (int), which they must set.
    - `flags`: the flag macros the body can set.
    - `description`: one line for the file comments.
    """

    emitter: Emitter
    states: tuple[tuple[str, str], ...]
    helpers: tuple[str, ...]
    body: tuple[str, ...]
    flags: tuple[str, ...]
    description: str


def _indent(lines, n: int = 4) -> str:
    pad = " " * n
    return "\n".join(pad + line if line else "" for line in lines)


def _signals(parts: StepParts, ratio: float, sign: float, velocity: str, window: int) -> tuple:
    """The declarations of the signals the body reads, the velocity state members and the
    statements that store this sample for the next step."""
    em = parts.emitter
    used = em.used_double | em.used_real
    lines = []
    if "twist" in used:
        # eq. (5); XLA multiplies by the reciprocal of a constant divisor, and so does this
        lines.append(
            f"const double d_twist = {c_double(sign)} * (x->theta_l - x->theta_m * "
            f"{c_double(1.0 / ratio)});"
        )
    for name in ("current", "theta_m", "theta_l"):
        if name in used:
            lines.append(f"const double d_{name} = x->{name};")
    for i, _ in enumerate(em.extras):
        if f"x{i}" in used:
            lines.append(f"const double d_x{i} = x->extra[{i}];")
    omegas = [w for w in ("omega_m", "omega_l") if w in used]
    states, store = [], []
    if velocity == "difference":
        states = [
            ("double t_prev; /* the previous sample, for eqs. (13)-(14) */", "s->t_prev = 0.0;"),
            ("double theta_m_prev;", "s->theta_m_prev = 0.0;"),
            ("double theta_l_prev;", "s->theta_l_prev = 0.0;"),
        ]
        if omegas:
            # eqs. (13)-(14), the backward difference; the first sample is at rest
            lines += [f"double d_{w} = 0.0;" for w in omegas]
            lines.append("if (s->n > 0) {")
            lines.append("    const double dt = x->t - s->t_prev;")
            for w in omegas:
                th = "theta_m" if w == "omega_m" else "theta_l"
                lines.append(f"    d_{w} = (x->{th} - s->{th}_prev) / dt;")
            lines.append("}")
        store = [
            "s->t_prev = x->t;",
            "s->theta_m_prev = x->theta_m;",
            "s->theta_l_prev = x->theta_l;",
        ]
    else:
        states = [
            (
                f"double win_t[{window}]; /* the last {window} samples, for the velocity line */",
                "",
            ),
            (f"double win_m[{window}];", ""),
            (f"double win_l[{window}];", ""),
            ("unsigned win_head; /* where the present sample goes */", "s->win_head = 0u;"),
        ]
        # the trailing least-squares line: its slope over the window ending at this sample
        lines += [
            "s->win_t[s->win_head] = x->t;",
            "s->win_m[s->win_head] = x->theta_m;",
            "s->win_l[s->win_head] = x->theta_l;",
        ]
        for w in omegas:
            buf = "win_m" if w == "omega_m" else "win_l"
            th = "theta_m" if w == "omega_m" else "theta_l"
            lines.append(
                f"const double d_{w} = hdjax_window_slope(s->win_t, s->{buf}, s->win_head, "
                f"s->n + 1u, x->t, x->{th});"
            )
        store = [f"s->win_head = (s->win_head + 1u) % {window}u;"]
    if em.real != "double":
        for name in sorted(em.used_real):
            lines.append(f"const {em.real} {name} = ({em.real})d_{name};")
    return lines, states, store


def _window_slope(window: int) -> str:
    return f"""\
static double hdjax_window_slope(const double *tb, const double *xb, unsigned head, unsigned m,
                                 double t0, double x0)
{{
    /* the least-squares slope of the last m <= {window} samples (hdjax.smoothed_velocity with
       causal=True): oldest first, time and angle relative to the present sample */
    double tm = 0.0, xm = 0.0, num = 0.0, den = 0.0;
    unsigned j;
    if (m > {window}u) m = {window}u;
    for (j = 0; j < m; ++j) {{
        const unsigned i = (head + {window}u + 1u - m + j) % {window}u;
        tm += tb[i] - t0;
        xm += xb[i] - x0;
    }}
    tm /= (double)m;
    xm /= (double)m;
    for (j = 0; j < m; ++j) {{
        const unsigned i = (head + {window}u + 1u - m + j) % {window}u;
        const double tw = tb[i] - t0 - tm;
        num += tw * (xb[i] - x0 - xm);
        den += tw * tw;
    }}
    return den > 0.0 ? num / den : 0.0;
}}
"""


def assemble(
    parts: StepParts,
    *,
    ratio: float,
    twist_sign: float,
    velocity: str,
    half_window: int,
    precision: str,
    kind: str,
    notes: tuple[str, ...],
    helpers: str,
) -> CCode:
    """The header and source of an estimator from a model generator's [`StepParts`][].

    **Arguments:** `parts`; the joint's `ratio` and `twist_sign` (eq. (5)); `velocity` and
    `half_window` (how the velocities are derived, causally); `precision`; `kind` and `notes`
    (see [`CCode`][]); `helpers`, the shared static functions
    ([`hdjax.export.helpers`][]).
    """
    em = parts.emitter
    window = 2 * half_window + 1
    sig_lines, vel_states, store = _signals(parts, ratio, twist_sign, velocity, window)
    n_max = 1 if velocity == "difference" else window
    states = (
        [
            (
                "unsigned n; /* samples since hdjax_init, counted up to the velocity window */",
                "s->n = 0u;",
            )
        ]
        + vel_states
        + list(parts.states)
    )
    states += [
        ("unsigned flags; /* HDJAX_* bits of the last step */", "s->flags = 0u;"),
        (
            "int segment; /* torque segment of the last step (compliance model), else 0 */",
            "s->segment = 0;",
        ),
    ]
    real = em.real
    extra_doc = "".join(
        f"\n                                 [{i}] {name}" for i, name in enumerate(em.extras)
    )
    extra_member = (
        f"    double extra[HDJAX_N_EXTRA]; /* extra columns, in this order:{extra_doc} */\n"
        if em.extras
        else ""
    )
    flag_lines = "".join(
        f"#define {name} {value}u /* {meaning} */\n"
        for name, value, meaning in FLAGS
        if name in parts.flags
    )
    header = f"""\
/* hdjax_estimator.h: {parts.description}.
   Generated by hdjax {__version__} ('hdjax export'); do not edit: export the model again.
   C99, no heap, libm only. Call hdjax_init once, then hdjax_step once per sample, in time
   order; hdjax_init again after a gap in the samples. */
#ifndef HDJAX_ESTIMATOR_H
#define HDJAX_ESTIMATOR_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {{
#endif

/* the type of the model's arithmetic (angles, time stamps and the twist are double) */
typedef {real} hdjax_real;

#define HDJAX_N_EXTRA {len(em.extras)}
{flag_lines}
/* one sample, SI units */
typedef struct {{
    double t;       /* time stamp [s], increasing */
    double theta_m; /* motor (wave-generator input) angle [rad], unwrapped */
    double theta_l; /* load (flexspline output) angle [rad], unwrapped */
    double current; /* motor current [A] */
{extra_member}}} hdjax_sample;

/* everything the estimate remembers from one sample to the next */
typedef struct {{
{_indent([decl for decl, _ in states])}
}} hdjax_state;

/* Start (or restart, after a gap) the estimator. */
void hdjax_init(hdjax_state *s);

/* The output torque [N m] of the next sample; s->flags holds its HDJAX_* bits. */
double hdjax_step(hdjax_state *s, const hdjax_sample *x);

/* hdjax_step over n samples in time order: torque[i] [N m] and, unless flags is NULL,
   flags[i]. */
void hdjax_batch(hdjax_state *s, const hdjax_sample *x, size_t n, double *torque,
                 unsigned *flags);
{HEADER_TAIL}"""
    init = [line for _, line in states if line]
    step_helpers = [helpers] + ([_window_slope(window)] if velocity == "smoothed" else [])
    source = f"""\
/* hdjax_estimator.c: {parts.description}.
   Generated by hdjax {__version__} ('hdjax export'); do not edit: export the model again. */
#include "hdjax_estimator.h"

#include <math.h>

{chr(10).join(step_helpers + list(parts.helpers))}
void hdjax_init(hdjax_state *s)
{{
{_indent(init)}
}}

double hdjax_step(hdjax_state *s, const hdjax_sample *x)
{{
    double torque;
    unsigned flags = 0u;
    int segment = 0;
    /* -- the signals of this sample (eq. (5), causal velocities) */
{_indent(sig_lines)}
{_indent(parts.body)}
    /* -- remember this sample */
{_indent(store)}
    if (s->n < {n_max}u) s->n += 1u;
    s->flags = flags;
    s->segment = segment;
    return torque;
}}

void hdjax_batch(hdjax_state *s, const hdjax_sample *x, size_t n, double *torque,
                 unsigned *flags)
{{
    size_t i;
    for (i = 0; i < n; ++i) {{
        torque[i] = hdjax_step(s, &x[i]);
        if (flags) flags[i] = s->flags;
    }}
}}
"""
    return CCode(
        header=header,
        source=source,
        extras=em.extras,
        precision=precision,
        kind=kind,
        flags=parts.flags,
        notes=notes,
    )
