"""The recording: one joint's synchronous samples as a pytree of float64 arrays.

Schema (SI units throughout):

| field | unit | meaning |
|---|---|---|
| `t` | s | sample time, strictly increasing (jitter and gaps allowed) |
| `theta_m` | rad | motor / wave-generator input angle, unwrapped (multi-turn) |
| `theta_l` | rad | output / flexspline angle |
| `current` | A | motor current (or a signal proportional to it) |
| `torque` | N·m | reference torque (sensor); optional when only estimating |
| `extras` | any | further numeric columns by name, e.g. `temperature` |

A `Recording` is an `eqx.Module`, so it passes through `jax.jit`, `jax.vmap` and `jax.tree_util`
unchanged. Build one with [`hdjax.make_recording`][] (which validates) or load one with
[`hdjax.load_recording`][]; the raw constructor does no checking so that JAX transformations can
rebuild it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._custom_types import Array, ArrayInput, ArrayLike, Bool, Float, Int, Real
from ._errors import DataError, UnitWarning

CORE_COLUMNS = ("t", "theta_m", "theta_l", "current")
"""Columns every recording has."""

SIGNAL_COLUMNS = CORE_COLUMNS + ("torque",)
"""Core columns plus the optional reference torque."""

# A harmonic-drive output rarely turns more than two revolutions in one log; a span beyond this
# in "radians" is far more often a column in degrees.
_OUTPUT_SPAN_WARN_RAD = 4.0 * math.pi
# An output speed beyond ~30 rad/s (~290 rpm) is far above any harmonic-drive catalogue limit.
_OUTPUT_SPEED_WARN_RAD_S = 30.0


class Recording(eqx.Module):
    """Synchronous samples of one joint (see the module docstring for the schema).

    **Arguments:**

    - `t`, `theta_m`, `theta_l`, `current`: float64 arrays of shape `(n,)`.
    - `torque`: reference torque of shape `(n,)`, or `None` when there is no sensor.
    - `extras`: further numeric columns by name, each of shape `(n,)`.
    - `source`: where the samples came from (a path or a scenario name), for messages.
    """

    t: Float[Array, " n"]
    theta_m: Float[Array, " n"]
    theta_l: Float[Array, " n"]
    current: Float[Array, " n"]
    torque: Float[Array, " n"] | None
    extras: dict[str, Float[Array, " n"]]
    source: str = eqx.field(static=True, default="<memory>")

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.t.shape[-1])

    @property
    def has_torque(self) -> bool:
        """Whether a reference torque is present."""
        return self.torque is not None

    @property
    def column_names(self) -> tuple[str, ...]:
        """Names of all columns present, core first, then `torque`, then extras (sorted)."""
        names = list(CORE_COLUMNS)
        if self.torque is not None:
            names.append("torque")
        return tuple(names) + tuple(sorted(self.extras))

    def column(self, name: str) -> Float[Array, " n"]:
        """One column by name (core, `torque` or an extra)."""
        if name in CORE_COLUMNS:
            return getattr(self, name)
        if name == "torque":
            if self.torque is None:
                raise DataError(
                    f"recording {self.source!r} has no 'torque' column; a reference torque is "
                    "needed for calibration and error metrics"
                )
            return self.torque
        if name in self.extras:
            return self.extras[name]
        raise DataError(
            f"recording {self.source!r} has no column {name!r}; it has "
            f"{', '.join(self.column_names)}"
        )

    def select(
        self, index: slice | Int[ArrayLike, " m"] | Bool[ArrayLike, " n"] | Sequence[int]
    ) -> Recording:
        """Rows selected by a slice, an integer index array or a boolean mask (outside jit)."""
        pick = lambda x: None if x is None else jnp.asarray(np.asarray(x)[index])
        return Recording(
            t=pick(self.t),
            theta_m=pick(self.theta_m),
            theta_l=pick(self.theta_l),
            current=pick(self.current),
            torque=pick(self.torque),
            extras={k: pick(v) for k, v in self.extras.items()},
            source=self.source,
        )

    def split(self, fraction: float) -> tuple[Recording, Recording]:
        """Split in time: the first `fraction` of samples and the rest."""
        if not 0.0 < fraction < 1.0:
            raise DataError(f"split fraction must lie in (0, 1), got {fraction}")
        k = int(round(self.n_samples * fraction))
        if k < 2 or self.n_samples - k < 2:
            raise DataError(
                f"cannot split {self.n_samples} samples at {fraction}: each part needs at least 2"
            )
        return self.select(slice(0, k)), self.select(slice(k, None))

    def with_torque(self, torque: Real[ArrayLike, " n"]) -> Recording:
        """The same recording with another reference torque."""
        return eqx.tree_at(
            lambda r: r.torque, self, jnp.asarray(torque, jnp.float64), is_leaf=lambda x: x is None
        )

    def with_extras(self, **columns: Real[ArrayLike, " n"]) -> Recording:
        """The same recording with extra columns added or replaced."""
        extras = dict(self.extras)
        extras.update({k: jnp.asarray(v, jnp.float64) for k, v in columns.items()})
        return eqx.tree_at(lambda r: r.extras, self, extras)

    def to_numpy(self) -> dict[str, Float[np.ndarray, " n"]]:
        """All columns as float64 NumPy arrays, in `column_names` order."""
        return {name: np.asarray(self.column(name), dtype=np.float64) for name in self.column_names}


def _as_column(name: str, values, source: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise DataError(
            f"{source}: column {name!r} is not numeric ({err}); every cell must be a number"
        ) from None
    if arr.ndim != 1:
        raise DataError(f"{source}: column {name!r} must be one-dimensional, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise DataError(
            f"{source}: column {name!r} has {int(bad.sum())} NaN/inf value(s), first at row "
            f"{first} (value {arr[first]}); drop or interpolate those rows before loading"
        )
    return arr


def make_recording(
    t: ArrayInput,
    theta_m: ArrayInput,
    theta_l: ArrayInput,
    current: ArrayInput,
    torque: ArrayInput | None = None,
    extras: Mapping[str, ArrayInput] | None = None,
    *,
    source: str = "<memory>",
    check_units: bool = True,
) -> Recording:
    """Build a validated [`hdjax.Recording`][] from array-likes.

    Checks, in plain Python before anything is traced: every column numeric, one-dimensional,
    finite and of one length; at least two samples; `t` strictly increasing (no duplicates);
    extras not shadowing core names. With `check_units`, warns ([`hdjax.UnitWarning`][]) when the
    output angle looks like degrees rather than radians.

    **Arguments:**

    - `t`, `theta_m`, `theta_l`, `current`, `torque`: see [`hdjax.Recording`][].
    - `extras`: further numeric columns by name.
    - `source`: a label for messages (a file path, a scenario name).
    - `check_units`: warn on angles that look like degrees.

    **Returns:** a `Recording` of float64 JAX arrays.
    """
    cols = {"t": t, "theta_m": theta_m, "theta_l": theta_l, "current": current}
    arrays = {k: _as_column(k, v, source) for k, v in cols.items()}
    if torque is not None:
        arrays["torque"] = _as_column("torque", torque, source)
    extra_arrays = {}
    for name, values in (extras or {}).items():
        if name in SIGNAL_COLUMNS:
            raise DataError(f"{source}: extra column {name!r} shadows a core column; rename it")
        extra_arrays[name] = _as_column(name, values, source)
    lengths = {k: v.shape[0] for k, v in {**arrays, **extra_arrays}.items()}
    if len(set(lengths.values())) > 1:
        detail = ", ".join(f"{k}={n}" for k, n in lengths.items())
        raise DataError(f"{source}: columns have different lengths ({detail}); they must match")
    n = lengths["t"]
    if n < 2:
        raise DataError(f"{source}: a recording needs at least 2 samples, got {n}")
    dt = np.diff(arrays["t"])
    if (dt <= 0).any():
        k = int(np.flatnonzero(dt <= 0)[0])
        what = "duplicated" if dt[k] == 0 else "decreasing"
        raise DataError(
            f"{source}: time column 't' must be strictly increasing, but it is {what} at row "
            f"{k + 1} (t[{k}]={arrays['t'][k]!r}, t[{k + 1}]={arrays['t'][k + 1]!r}); sort the "
            "rows and drop duplicated time stamps"
        )
    if check_units:
        _warn_if_degrees(arrays["theta_l"], arrays["t"], source)
    as_jax = lambda a: jnp.asarray(a, dtype=jnp.float64)
    return Recording(
        t=as_jax(arrays["t"]),
        theta_m=as_jax(arrays["theta_m"]),
        theta_l=as_jax(arrays["theta_l"]),
        current=as_jax(arrays["current"]),
        torque=None if torque is None else as_jax(arrays["torque"]),
        extras={k: as_jax(v) for k, v in extra_arrays.items()},
        source=source,
    )


def _warn_if_degrees(theta_l: np.ndarray, t: np.ndarray, source: str) -> None:
    span = float(np.ptp(theta_l))
    speed = float(np.max(np.abs(np.diff(theta_l) / np.diff(t))))
    if span > _OUTPUT_SPAN_WARN_RAD or speed > _OUTPUT_SPEED_WARN_RAD_S:
        warnings.warn(
            f"{source}: theta_l spans {span:.4g} rad ({span / (2 * math.pi):.3g} revolutions) and "
            f"reaches {speed:.4g} rad/s, which looks like degrees; angles must be radians "
            "(in a column map, scale a degree column by 0.017453292519943295)",
            UnitWarning,
            stacklevel=3,
        )
