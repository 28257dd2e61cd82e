"""Encoder counts in: `hdjax_sample_from_counts`, the angles of a sample from 64-bit counts,
converted as hdjax converts a log's count column.

hdjax reads a count column through a [`hdjax.ColumnMap`][] entry `{ source = "...",
counts_per_rev = N, offset = ... }` (its `ColumnSpec`): the cell read as a double (exact
below 2^53), `scale = 2 pi / N` rounded to double once, then

- `offset = "first"`: `(counts - first) * scale`, the subtraction in double;
- `offset = <number>` (radians, default 0): `counts * scale + offset`.

[`counts_c`][] adds a function to an exported estimator that does the same operations in the
same order, in double, so that its angles equal the reader's to the bit:
`theta = ((double)counts - (double)zero) * HDJAX_RAD_PER_COUNT + offset`, with `zero` the first
count (or 0) and `offset` the number (or 0.0); subtracting an exact 0.0 and adding 0.0 change
nothing. The product is stored through a `volatile double` before the offset is added, so that
no compiler fuses the multiply and the add into one fused multiply-add (ISO C contracts within
one expression at most, but GCC's default `gnu` modes contract across statements on targets
with FMA, aarch64 among them); whatever the flags, the angles are the reader's.

The counts per revolution are the joint's (`encoder_bits_motor`, `encoder_bits_load`: 2^bits)
unless given (`hdjax export --counts-per-rev-m N --counts-per-rev-l N`); without both the
function is not generated (see [`hdjax.export.counts_per_rev`][]).
"""

from __future__ import annotations

import dataclasses
import math
import re

from .._errors import ConfigError
from .._joint import Joint
from ._assemble import HEADER_TAIL, CCode
from ._emitter import c_double

MAX_COUNTS_PER_REV = 2**53
"""The largest counts per revolution: a double holds every count up to it exactly."""

ENCODERS = (("m", "motor", "encoder_bits_motor"), ("l", "load", "encoder_bits_load"))
"""(suffix, encoder, joint field) of the two encoders."""


def check_counts_per_rev(value: int | float | str, option: str) -> int:
    """A counts-per-revolution option's value (a string on the command line, or an int) as a
    positive whole number up to 2^53, else a one-line [`hdjax.ConfigError`][]."""
    text = value.strip() if isinstance(value, str) else value
    if isinstance(text, str) and re.fullmatch("[0-9]+", text):
        text = int(text)
    if isinstance(text, bool) or not isinstance(text, int) or not 1 <= text <= MAX_COUNTS_PER_REV:
        raise ConfigError(
            f"{option} must be a whole number of encoder counts per revolution, 1 to 2^53 "
            f"(e.g. 2097152 for a 21-bit encoder), got {value!r}"
        )
    return text


def counts_per_rev(
    joint: Joint, motor: int | None = None, load: int | None = None
) -> tuple[tuple[int, str] | None, tuple[int, str] | None]:
    """The counts per revolution of the motor and the load encoder, each with where it comes
    from: `motor` / `load` when given (`--counts-per-rev-m`, `--counts-per-rev-l`), else 2^bits
    of the joint's `encoder_bits_motor` / `encoder_bits_load`, else `None` (unknown)."""
    out = []
    for given, (suffix, _, field) in zip((motor, load), ENCODERS):
        bits = getattr(joint, field)
        if given is not None:
            cpr = check_counts_per_rev(given, f"--counts-per-rev-{suffix}")
            out.append((cpr, f"--counts-per-rev-{suffix} {cpr}"))
        elif bits is not None:
            out.append((2**bits, f"the joint's {field} = {bits}"))
        else:
            out.append(None)
    return out[0], out[1]


def rad_per_count(cpr: int) -> float:
    """`2 pi / cpr` rounded to double once, as [`hdjax.ColumnMap`][] computes its scale."""
    return 2.0 * math.pi / float(cpr)


def counts_c(code: CCode, motor: int, load: int, origin: tuple[str, str] = ("", "")) -> CCode:
    """`code` with `hdjax_sample_from_counts` (declared in the header, defined in the source)
    for encoders of `motor` and `load` counts per revolution; `origin` says where each comes
    from (header comments)."""
    motor = check_counts_per_rev(motor, "motor counts per revolution")
    load = check_counts_per_rev(load, "load counts per revolution")
    if code.counts_per_rev is not None:
        raise ValueError("the estimator already converts counts")
    if code.header.count(HEADER_TAIL) != 1:
        raise ValueError("not an estimator header written by hdjax.export")
    why = [f" ({o})" if o else "" for o in origin]
    declarations = f"""
/* -- encoder counts: hdjax_sample_from_counts converts them as hdjax reads a log's count
   column {{ source = "...", counts_per_rev = N, offset = ... }} (hdjax.ColumnMap):
     theta = ((double)counts - (double)zero) * HDJAX_RAD_PER_COUNT + offset
   in double, step by step as the reader does, so the angles equal hdjax's to the bit. */
#define HDJAX_COUNTS_PER_REV_M {motor}LL /* motor encoder counts per revolution{why[0]} */
#define HDJAX_COUNTS_PER_REV_L {load}LL /* load encoder counts per revolution{why[1]} */
/* 2 pi / HDJAX_COUNTS_PER_REV_x, rounded to double once (as the reader's scale) [rad] */
#define HDJAX_RAD_PER_COUNT_M {c_double(rad_per_count(motor))}
#define HDJAX_RAD_PER_COUNT_L {c_double(rad_per_count(load))}

/* where the angles start: the column map's offset, per encoder */
typedef struct {{
    long long zero_m; /* [counts] offset = "first": the stream's first motor count; else 0 */
    long long zero_l; /* [counts] offset = "first": the stream's first load count; else 0 */
    double offset_m;  /* [rad] offset = a number: that number; else 0.0 */
    double offset_l;  /* [rad] offset = a number: that number; else 0.0 */
}} hdjax_counts_offset;

/* Fill x->t, x->theta_m, x->theta_l and x->current from the time stamp [s], the multi-turn
   motor and load counts (64-bit, not wrapping; exact up to 2^53) and the current [A]; z NULL
   for no offset. The extra columns (x->extra) are left to the caller. */
void hdjax_sample_from_counts(hdjax_sample *x, double t, long long counts_m,
                              long long counts_l, double current,
                              const hdjax_counts_offset *z);
"""
    definition = """
void hdjax_sample_from_counts(hdjax_sample *x, double t, long long counts_m,
                              long long counts_l, double current,
                              const hdjax_counts_offset *z)
{
    /* as hdjax's reader: each count a double, less the zero (in double), times the scale,
       plus the offset, each rounded on its own (the products stored through volatile, so no
       compiler fuses them with the add into a multiply-add, whatever its flags) */
    double m = (double)counts_m;
    double l = (double)counts_l;
    if (z) {
        m -= (double)z->zero_m;
        l -= (double)z->zero_l;
    }
    volatile double pm = m * HDJAX_RAD_PER_COUNT_M;
    volatile double pl = l * HDJAX_RAD_PER_COUNT_L;
    m = pm;
    l = pl;
    if (z) {
        m += z->offset_m;
        l += z->offset_l;
    }
    x->t = t;
    x->theta_m = m;
    x->theta_l = l;
    x->current = current;
}
"""
    return dataclasses.replace(
        code,
        header=code.header.replace(HEADER_TAIL, declarations + HEADER_TAIL),
        source=code.source + definition,
        counts_per_rev=(motor, load),
    )
