r"""A term's numeric hyperparameters handed to a compiled program as values, not as constants.

A term's hyperparameters are static fields (`hyper`), so each value is
part of the cache key of every program compiled over the term. The residual loop builds terms
whose values come from the data: a spectrum peak at order 1.98, a skew refined to 0.49 ms, a
smoothing speed or a column scale from a velocity's RMS, a hysteresis width from the rated
torque. With the values as constants, every new joint (and every refinement) compiles each
column program again: on a 2-core machine about 0.2 s each, most of a warm `hdjax discover`.

[`split_hypers`][] keeps the term's structure static (its class, its strings and integers,
and the sign of each float, so that values of either sign compile apart) and hands the float
values apart, as
float64 arrays; [`join_hypers`][] puts them back inside the compiled program. The columns are
the same numbers, bit for bit: in these elementwise programs XLA folds no constant operand into
another rounding (the tests compare the residual loop's design, built this way, with the
model's own single program, built with the constants).

One rounding differs: XLA folds a constant into a neighbouring constant (an order $K$ times the
angle, then times $2/\pi$ in the sine's reduction, becomes the angle times $2K/\pi$), which a
traced value cannot share. A term whose value meets such a constant passes it through
[`opaque`][] first, so both forms round alike.

A family keeps a float hyperparameter constant by naming it in its `static_hypers`: one that
its columns branch on in Python (the hysteresis state's `initial`, say): inside the program
the value is traced, sign included, so the columns select with `jnp.where`. A term whose
columns cannot compute with a traced value at all (a family written elsewhere that calls
`float()` on one) still works: [`run_split`][] runs it with its constants, as before, and
remembers its class.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Scalar
from ._fields import is_finite_number, is_zero


def opaque(x: Scalar) -> jax.Array:
    """`x` as a value XLA does not fold into neighbouring constants (an optimization barrier):
    a constant hyperparameter then rounds as a traced one does (module docstring)."""
    return jax.lax.optimization_barrier(jnp.asarray(x, jnp.float64))


def _sign(x: float) -> float:
    # what the static skeleton keeps of a float: 0, or its sign (the program's key only: inside
    # it the term holds the traced value)
    return 0.0 if x == 0 else math.copysign(1.0, x)


def _is_float_tuple(v) -> bool:
    return isinstance(v, tuple) and bool(v) and all(is_finite_number(x) for x in v)


_NEEDS_CONSTANTS: set[type] = set()
"""Term classes whose compiled programs failed with their hyperparameters as values."""


TRACER_ERRORS = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerArrayConversionError,
    jax.errors.TracerIntegerConversionError,
)
"""What a program raises when it reads a traced value as a Python number (`float()`, an `if`
on it; `TracerBoolConversionError` is a `ConcretizationTypeError`)."""


def run_split(program, split, obj, *args):
    """`program(skeleton, values, *args)` with `split(obj) -> (skeleton, values)`.

    Where that fails to trace because a term reads a value as a Python number, the same
    program runs with `obj` itself and no values (its constants, as before); a single term's
    class is then remembered, so that [`split_hypers`][] leaves it whole from then on (the
    residual loop evaluates every term alone before it inverts a model, so a model's culprit
    is found there). Any other error is raised as it is.
    """
    skeleton, values = split(obj)
    try:
        return program(skeleton, values, *args)
    except TRACER_ERRORS:
        if not any(values):
            raise
        out = program(obj, _no_values(values), *args)
        if isinstance(values, dict):
            _NEEDS_CONSTANTS.add(type(obj))
        return out


def _no_values(values):
    return tuple({} for _ in values) if isinstance(values, tuple) else {}


def opaque_in(xp, *values):
    """`values` made [`opaque`][] when `xp` is `jax.numpy` (a term's JAX columns), else as they
    are (its NumPy twin): for the `transform(x, xp)` written once for both."""
    out = tuple(opaque(v) for v in values) if xp is jnp else values
    return out[0] if len(out) == 1 else out


def opaque_hypers(term):
    """`term` with each float hyperparameter [`split_hypers`][] would hand apart made
    [`opaque`][] (for a term's JAX columns: the constants then round as traced values do)."""
    _, values = split_hypers(term)
    fields = {}
    for name in values:
        v = getattr(term, name)
        fields[name] = tuple(opaque(x) for x in v) if isinstance(v, tuple) else opaque(v)
    return with_fields(term, fields) if fields else term


def split_hypers(term) -> tuple[object, dict[str, np.ndarray]]:
    """`term` with each float hyperparameter (or tuple of floats) replaced by its sign, and the
    values as float64 arrays (0-d, or a vector for a tuple: arrays, so that `eqx.filter_jit`
    traces them).

    **Returns:** `(skeleton, values)`; `values` is empty, and `skeleton` is `term` itself,
    when the term has no float hyperparameter to hand apart. Pass `skeleton` as a static
    argument and `values` as a traced one, and rebuild with [`join_hypers`][].
    """
    if type(term) in _NEEDS_CONSTANTS:
        return term, {}
    keep = getattr(type(term), "static_hypers", ())
    keep_zero = getattr(type(term), "static_while_zero", ())
    values, signs = {}, {}
    for f in dataclasses.fields(term):
        if "positive" not in f.metadata or f.name in keep:  # hyper() fields only
            continue
        v = getattr(term, f.name)
        if f.name in keep_zero and is_zero(v):
            continue
        if is_finite_number(v) and isinstance(v, float):
            values[f.name], signs[f.name] = np.asarray(v, np.float64), _sign(v)
        elif _is_float_tuple(v):
            values[f.name] = np.asarray(v, np.float64)
            signs[f.name] = tuple(_sign(float(x)) for x in v)
    if not values:
        return term, {}
    return with_fields(term, signs), values


def join_hypers(skeleton, values: dict):
    """The term [`split_hypers`][] split, with `values` (inside a compiled program: traced)
    put back; a tuple hyperparameter comes back as a tuple of scalars.

    The fields are set directly, as equinox does when it unflattens a module: the values were
    checked when the term was built, and a traced value is no plain number to check again.
    """
    if not values:
        return skeleton
    fields = {}
    for name, v in values.items():
        tup = isinstance(getattr(skeleton, name), tuple)
        fields[name] = tuple(v[i] for i in range(v.shape[0])) if tup else v
    return with_fields(skeleton, fields)


def with_fields(term, fields: dict):
    """A copy of the module `term` with `fields` set directly (no `__init__`, no checks), as
    equinox sets them when it unflattens a module."""
    new = object.__new__(type(term))
    for f in dataclasses.fields(term):
        object.__setattr__(new, f.name, fields.get(f.name, getattr(term, f.name)))
    return new
