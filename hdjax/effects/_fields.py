"""The pieces an effect family's classes are declared with.

A family's regression term declares its hyperparameters with [`hyper`][] (static fields, the
positive ones checked at construction) and its vocabulary key and column names with
[`labels`][] (templates over those fields); its plant effect declares the sign of each array
parameter with [`bound`][] and is built from a parameter table by
[`hdjax.effects.AbstractPlantEffect.from_params`][], which checks each parameter with
[`require`][] in plain Python before anything is traced.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Hashable

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayInput, Float, Scalar
from .._errors import ConfigError


def fmt(x: Scalar) -> str:
    """A number as a short decimal string (`2`, `1.98`, `0.5`) for column names and keys; a
    traced value (a term inside a compiled program, where only the number of its names is
    read) as `?`."""
    return f"{x:.10g}" if isinstance(x, (int, float)) else "?"


def is_finite_number(x) -> bool:
    """Whether `x` is a plain finite Python number (not a bool, not a tracer)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def is_zero(x) -> bool:
    """Whether `x` is a plain Python 0 (never true for a traced value, whose value is unknown)."""
    return is_finite_number(x) and x == 0


def check_positive(owner: str, field: str, value) -> None:
    """Raise `ConfigError` when a plain-number hyperparameter is not finite and positive."""
    if isinstance(value, (int, float)) and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{owner}: {field} must be finite and positive, got {value!r}")


# ---------------------------------------------------------------------------------------------
# Declaring a term: hyperparameter fields and formatted labels
# ---------------------------------------------------------------------------------------------


def hyper(default: Hashable = dataclasses.MISSING, *, positive: bool = False) -> dataclasses.Field:
    """A term's hyperparameter: a static field (hashable, never traced), checked to be finite
    and positive at construction when `positive` (see [`AbstractTerm`][])."""
    return eqx.field(default=default, static=True, metadata={"positive": positive})


def _label_values(term) -> dict:
    # numbers as `fmt` writes them, so labels read `tanh(omega_m/0.5)`, never `0.50000000001`
    out = {}
    for f in dataclasses.fields(term):
        v = getattr(term, f.name)
        out[f.name] = fmt(v) if is_finite_number(v) else v
    return out


def labels(key: str, *names: str) -> tuple[property, Callable]:
    """A term's `key` property and `names()` method from `str.format` templates over its
    fields (numbers written by [`fmt`][]): one for the key, one per column, as in
    `key, names = labels("coulomb:{signal}", "tanh({signal}/{omega_s})")`."""

    def key_(self) -> str:
        return key.format_map(_label_values(self))

    def names_(self) -> tuple[str, ...]:
        values = _label_values(self)
        return tuple(t.format_map(values) for t in names)

    names_.__doc__ = f"The column names: {', '.join(names)}."
    return property(key_, doc=f"The vocabulary key: {key}."), names_


# ---------------------------------------------------------------------------------------------
# Declaring a plant effect: parameter fields and their checks
# ---------------------------------------------------------------------------------------------


BOUNDS = ("finite", "nonneg", "positive")
"""What [`bound`][] can require of a plant-effect parameter (every one must be finite)."""


def bound(rule: str, *, inverse: bool = False) -> dataclasses.Field:
    """A plant-effect parameter field that [`hdjax.effects.AbstractPlantEffect.from_params`][]
    checks to be `"nonneg"` or `"positive"` (a field declared without it need only be finite).
    With `inverse`, the parameter is a scale the effect divides by: its inverse is one of the
    effect's `reciprocals()`, computed once outside the plant's time loop."""
    if rule not in BOUNDS:
        raise ConfigError(f"bound {rule!r} is not one of {BOUNDS}")
    return eqx.field(metadata={"bound": rule, "inverse": inverse})


def f64(x: ArrayInput) -> Float[Array, " ..."]:
    """`x` as a float64 JAX array."""
    return jnp.asarray(x, jnp.float64)


def concrete(x, name: str = "", field: str = ""):
    """A NumPy copy of `x` when it is concrete, else None (inside a trace).

    A value that is not a number (a word, a table) is a `ConfigError` that names the parameter,
    never an error from inside JAX later on."""
    try:
        return np.asarray(x, dtype=np.float64)
    except Exception:
        if not isinstance(x, (str, bytes, dict, list, tuple)):
            return None  # a tracer or another abstract value
        raise ConfigError(
            f"effect {name!r}: parameter {field!r} must be a number or a list of numbers, got {x!r}"
        ) from None


def require(
    name: str,
    field: str,
    value: ArrayInput,
    *,
    positive: bool = False,
    nonneg: bool = False,
    shape: tuple[int, ...] | None = None,
) -> None:
    """Validate one plant-effect parameter in plain Python (skipped for tracers).

    `value` is the parameter as the user gives it (a number, a list, an array): this function
    checks its shape, finiteness and sign itself and raises a `ConfigError` that says what is
    wrong, so its annotation stays the loose `ArrayInput`."""
    arr = concrete(value, name, field)
    if arr is None:
        return
    if shape is not None and arr.shape != shape:
        raise ConfigError(
            f"effect {name!r}: parameter {field!r} must have shape {shape}, got {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"effect {name!r}: parameter {field!r} must be finite, got {arr}")
    if positive and not np.all(arr > 0):
        raise ConfigError(f"effect {name!r}: parameter {field!r} must be positive, got {arr}")
    if nonneg and not np.all(arr >= 0):
        raise ConfigError(f"effect {name!r}: parameter {field!r} must be non-negative, got {arr}")


def vector(name: str, field: str, value):
    """A 1-D float64 parameter, refusing other ranks."""
    arr = concrete(value, name, field)
    if arr is not None and arr.ndim != 1:
        raise ConfigError(
            f"effect {name!r}: parameter {field!r} must be a 1-D list, got shape {arr.shape}"
        )
    return f64(value)


# ---------------------------------------------------------------------------------------------
# Numbers of candidates
# ---------------------------------------------------------------------------------------------


def rounded(x: float, digits: int = 4) -> float:
    """`x` to `digits` significant digits: a candidate's hyperparameter, short in its column
    names and stable from run to run."""
    return float(f"{x:.{digits}g}")
