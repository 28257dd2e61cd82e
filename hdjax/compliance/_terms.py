"""Term groups: named blocks of design-matrix columns of the twist model.

The twist model of Song et al. eq. (10) is linear in its coefficients,

$$\\Delta\\theta = \\sum_j k_j \\phi_j(T) + h(x) + \\sum_g c_g^\\top \\psi_g(x, T),$$

with the piecewise-linear flexspline basis $\\phi_j$ (eq. (7)), the torque-free terms $h$ of the
wave generator (eq. (8)) and the kinematic error (eq. (9)), and optional *effect* groups
$\\psi_g$ added by the residual loop. Each group is a frozen, hashable dataclass (so it can sit in
a static field of an `eqx.Module`) with a `key`, column `names` and a pure `columns` function.

`torque_kind` tells the inversion how a group depends on the torque $T$:

- `"none"`: not at all (a column of $h$);
- `"linear"`: linearly, $\\psi = u(x) T$ (a stiffness that drifts with a column such as
  temperature) - solved in closed form;
- `"memoryless"`: nonlinearly through the present torque only (stiffening, backlash) - solved by
  safeguarded Newton steps;
- `"path"`: through the torque history (hysteresis) - solved by fixed-point iteration on the
  estimated torque path, computed causally.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from .._trig import sincos
from ._signals import Signals

TORQUE_KINDS = ("none", "linear", "memoryless", "path")

TORQUE_PATH = "_torque_path"
"""Name of an optional signal that drives path-dependent terms at calibration (see
[`Hysteresis`][]): the torque *estimated* by a previous model, so the state is computed as the
estimator will compute it, causally and without the reference sensor."""

SEGMENT_START = "_segment_start"
"""Name of an optional signal, 1 at the first sample of each contiguous segment of a recording
with gaps: memory states (hysteresis) restart there, as [`dahl_state`][]'s `reset`."""


def _fmt(order: float) -> str:
    """An order as a short decimal string (`2`, `1.98`, `0.5`)."""
    return f"{order:.10g}"


def harmonic_pairs(u, order: int):
    r"""$[(\cos nu, \sin nu)]_{n=1..order}$ by the angle-addition recurrence from one `sincos`."""
    # The barrier materialises sin/cos once: without it XLA fuses (and so recomputes) them into
    # every column that a stacked design materialises separately.
    s1, c1 = jax.lax.optimization_barrier(sincos(u))
    out = [(c1, s1)]
    for _ in range(1, order):
        c, s = out[-1]
        out.append((c * c1 - s * s1, s * c1 + c * s1))
    return out


@dataclasses.dataclass(frozen=True)
class Constant:
    """Constant offset $k_0 = \\omega_0/N + a_0$ (eq. (10)); also absorbs encoder offsets."""

    key: str = "constant"
    torque_kind: str = "none"

    def names(self) -> tuple[str, ...]:
        return ("k0",)

    def column_list(self, sig: Signals) -> list:
        return [jnp.ones((sig.n_samples,), jnp.float64)]

    def columns(self, sig: Signals, torque=None):
        return jnp.ones((sig.n_samples, 1), jnp.float64)


@dataclasses.dataclass(frozen=True)
class CurrentPolynomial:
    """Wave-generator deformation as a polynomial in current, eq. (8), without its constant.

    Columns $I, I^2, \\dots, I^p$; the fitted coefficient of $I^i$ is $\\omega_i / N$ (eq. (10)).
    `scale` divides the current first (the rated current, say) so high powers stay O(1).
    """

    order: int = 6
    scale: float = 1.0
    key: str = "current:poly"
    torque_kind: str = "none"

    def names(self) -> tuple[str, ...]:
        return tuple(f"w{i}" for i in range(1, self.order + 1))

    def column_list(self, sig: Signals) -> list:
        x = sig.current / self.scale
        out = [x]
        for _ in range(1, self.order):
            out.append(out[-1] * x)
        return out

    def columns(self, sig: Signals, torque=None):
        return jnp.stack(self.column_list(sig), axis=1)


@dataclasses.dataclass(frozen=True)
class PaperFourier:
    """Kinematic error in the paper's form, eq. (9), without its constant $a_0$.

    For $n = 1..$`order`: $\\cos(n\\theta_{fso}\\omega_{fso}), \\sin(n\\theta_{fso}\\omega_{fso}),
    \\cos(n\\theta_{wgi}\\omega_{wgi}), \\sin(n\\theta_{wgi}\\omega_{wgi})$ with coefficients
    $a_n, b_n, c_n, d_n$. (The argument angle-times-velocity is the paper's; plain harmonics of
    the angles are [`hdjax.compliance.Harmonics`][].)
    """

    order: int = 3
    key: str = "kinematic:paper"
    torque_kind: str = "none"

    def names(self) -> tuple[str, ...]:
        out = []
        for n in range(1, self.order + 1):
            out += [f"a{n}", f"b{n}", f"c{n}", f"d{n}"]
        return tuple(out)

    def column_list(self, sig: Signals) -> list:
        hl = harmonic_pairs(sig.theta_l * sig.omega_l, self.order)
        hm = harmonic_pairs(sig.theta_m * sig.omega_m, self.order)
        cols = []
        for (cl, sl), (cm, sm) in zip(hl, hm):
            cols += [cl, sl, cm, sm]
        return cols

    def columns(self, sig: Signals, torque=None):
        return jnp.stack(self.column_list(sig), axis=1)


@dataclasses.dataclass(frozen=True)
class Harmonics:
    """Harmonics of one angle at a list of (possibly non-integer) orders: $\\cos(k\\theta),
    \\sin(k\\theta)$ per order $k$ - the kinematic error as a function of angle alone."""

    signal: str = "theta_m"
    orders: tuple[float, ...] = (1.0, 2.0)
    torque_kind: str = "none"

    @property
    def key(self) -> str:
        return ",".join(f"harmonic:{self.signal}:{_fmt(k)}" for k in self.orders)

    def names(self) -> tuple[str, ...]:
        out = []
        for k in self.orders:
            out += [f"cos({_fmt(k)}*{self.signal})", f"sin({_fmt(k)}*{self.signal})"]
        return tuple(out)

    def column_list(self, sig: Signals) -> list:
        theta = sig.get(self.signal)
        cols = []
        for k in self.orders:
            s, c = sincos(k * theta)
            cols += [c, s]
        return cols

    def columns(self, sig: Signals, torque=None):
        return jnp.stack(self.column_list(sig), axis=1)


@dataclasses.dataclass(frozen=True)
class Coulomb:
    """Coulomb-like friction signature, a smooth sign $\\tanh(\\omega/\\omega_s)$ of a velocity."""

    signal: str = "omega_m"
    omega_s: float = 1.0
    torque_kind: str = "none"

    @property
    def key(self) -> str:
        return f"coulomb:{self.signal}"

    def names(self) -> tuple[str, ...]:
        return (f"tanh({self.signal}/{_fmt(self.omega_s)})",)

    def columns(self, sig: Signals, torque=None):
        return jnp.tanh(sig.get(self.signal) / self.omega_s)[:, None]


@dataclasses.dataclass(frozen=True)
class Viscous:
    """Viscous friction signature: a velocity, divided by `scale`."""

    signal: str = "omega_m"
    scale: float = 1.0
    torque_kind: str = "none"

    @property
    def key(self) -> str:
        return f"viscous:{self.signal}"

    def names(self) -> tuple[str, ...]:
        return (f"{self.signal}/{_fmt(self.scale)}",)

    def columns(self, sig: Signals, torque=None):
        return (sig.get(self.signal) / self.scale)[:, None]


@dataclasses.dataclass(frozen=True)
class TwistRate:
    """Structural damping signature: the twist rate $\\dot{\\Delta\\theta} = s(\\omega_l -
    \\omega_m/N)$ (eq. (5) differentiated), divided by `scale`. A damped flexspline carries
    $c\\dot{\\Delta\\theta}$ on top of its elastic torque, which the twist alone cannot show."""

    ratio: float = 1.0
    sign: float = 1.0
    scale: float = 1.0
    key: str = "damping:twist_rate"
    torque_kind: str = "none"

    def names(self) -> tuple[str, ...]:
        return (f"twist_rate/{_fmt(self.scale)}",)

    def columns(self, sig: Signals, torque=None):
        rate = self.sign * (sig.omega_l - sig.omega_m / self.ratio)
        return (rate / self.scale)[:, None]


@dataclasses.dataclass(frozen=True)
class Column:
    """An extra recording column (e.g. `temperature`), centred and scaled: a twist drift."""

    name: str
    center: float = 0.0
    scale: float = 1.0
    torque_kind: str = "none"

    @property
    def key(self) -> str:
        return f"column:{self.name}"

    def names(self) -> tuple[str, ...]:
        return (f"({self.name}-{_fmt(self.center)})/{_fmt(self.scale)}",)

    def columns(self, sig: Signals, torque=None):
        return ((sig.get(self.name) - self.center) / self.scale)[:, None]

    def slope(self, sig: Signals):
        """$u(x)$ such that the column is $u(x)$ (no torque dependence)."""
        return (sig.get(self.name) - self.center) / self.scale


@dataclasses.dataclass(frozen=True)
class ColumnTimesTorque:
    """An extra column times torque: a compliance that drifts with e.g. temperature,
    $\\psi = \\frac{x - x_0}{s} \\frac{T}{\\tau_0}$ (linear in torque, inverted in closed form)."""

    name: str
    center: float = 0.0
    scale: float = 1.0
    torque_scale: float = 1.0
    torque_kind: str = "linear"

    @property
    def key(self) -> str:
        return f"column:{self.name}*torque"

    def names(self) -> tuple[str, ...]:
        return (
            f"({self.name}-{_fmt(self.center)})/{_fmt(self.scale)}*T/{_fmt(self.torque_scale)}",
        )

    def torque_slope(self, sig: Signals):
        """$u(x)$ with $\\psi = u(x) T$."""
        return (sig.get(self.name) - self.center) / (self.scale * self.torque_scale)

    def columns(self, sig: Signals, torque):
        return (self.torque_slope(sig) * torque)[:, None]


@dataclasses.dataclass(frozen=True)
class Stiffening:
    """Nonlinear stiffness beyond the piecewise segments: $(T/\\tau_s)^3$ (odd, smooth)."""

    torque_scale: float = 1.0
    key: str = "stiffness:torque"
    torque_kind: str = "memoryless"

    def names(self) -> tuple[str, ...]:
        return (f"(T/{_fmt(self.torque_scale)})^3",)

    def columns(self, sig: Signals, torque):
        return ((torque / self.torque_scale) ** 3)[:, None]

    def value_and_slope(self, torque):
        u = torque / self.torque_scale
        return u**3, 3.0 * u**2 / self.torque_scale


@dataclasses.dataclass(frozen=True)
class Backlash:
    """Lost motion around zero torque: a smooth step $\\tanh(T/T_b)$ of width $T_b$."""

    width: float = 1.0
    key: str = "backlash:torque"
    torque_kind: str = "memoryless"

    def names(self) -> tuple[str, ...]:
        return (f"tanh(T/{_fmt(self.width)})",)

    def columns(self, sig: Signals, torque):
        return jnp.tanh(torque / self.width)[:, None]

    def value_and_slope(self, torque):
        v = jnp.tanh(torque / self.width)
        return v, (1.0 - v**2) / self.width


def dahl_state(torque, torque_scale: float, reset=None):
    """Causal Dahl-type hysteresis state driven by a torque path.

    $z_k = z_{k-1} + \\frac{\\Delta T_k}{T_h} (1 - z_{k-1}\\,\\mathrm{sgn}\\,\\Delta T_k)$,
    clipped to $[-1, 1]$: the rate-independent Dahl model ($\\sigma = 1$) with the torque as its
    input, so
    $z$ saturates at $\\pm 1$ after a torque reversal of a few $T_h$ (the loop of Song et al.
    Fig. 2, B to B'). Starts at $z_0 = 0$, and restarts at 0 wherever `reset` (optional, 1 at
    the first sample of a segment after a gap) is set.
    """

    dT = jnp.diff(torque, prepend=torque[:1]) / torque_scale
    if reset is None:
        reset = jnp.zeros(dT.shape, bool)
    return _dahl_scan(dT, jnp.asarray(reset).astype(bool))


@jax.jit
def _dahl_scan(du, reset):
    # du = dT / T_h, so one compiled scan serves every torque scale.
    def _step(z, x):
        d, rs = x
        # a segment after a gap starts afresh: no state, no step across the gap
        z, d = jnp.where(rs, 0.0, z), jnp.where(rs, 0.0, d)
        # Dahl: dz = dT/Th * (1 - z sign(dT)); explicit step, clipped for large steps.
        z = jnp.clip(z + d * (1.0 - z * jnp.sign(d)), -1.0, 1.0)
        return z, z

    return jax.lax.scan(_step, jnp.zeros((), du.dtype), (du, reset))[1]


@dataclasses.dataclass(frozen=True)
class Hysteresis:
    """Hysteresis in twist as a Dahl state driven by the torque path ([`dahl_state`][]).

    At estimation the state is driven by the torque being estimated (the estimate without the
    path terms, causally, one pass), never by the reference sensor. At calibration it is
    driven by the signal `TORQUE_PATH` when present (the residual loop supplies the previous
    model's estimate), else by the reference torque.
    """

    torque_scale: float = 1.0
    key: str = "hysteresis:torque"
    torque_kind: str = "path"

    def names(self) -> tuple[str, ...]:
        return (f"dahl(T/{_fmt(self.torque_scale)})",)

    def columns(self, sig: Signals, torque):
        # A torque path supplied with the signals (the estimate of a previous model, so that
        # calibration sees the state the estimator will see) takes precedence.
        driver = sig.extras.get(TORQUE_PATH, torque)
        return dahl_state(driver, self.torque_scale, sig.extras.get(SEGMENT_START))[:, None]


TERM_TYPES = (
    Constant,
    CurrentPolynomial,
    PaperFourier,
    Harmonics,
    Coulomb,
    Viscous,
    TwistRate,
    Column,
    ColumnTimesTorque,
    Stiffening,
    Backlash,
    Hysteresis,
)


def term_to_dict(term) -> dict:
    """A JSON-ready description of a term group (for saved models and reports)."""
    d = {"type": type(term).__name__}
    for f in dataclasses.fields(term):
        v = getattr(term, f.name)
        d[f.name] = list(v) if isinstance(v, tuple) else v
    return d


def term_from_dict(d: dict):
    """Inverse of [`term_to_dict`][]."""
    types = {t.__name__: t for t in TERM_TYPES}
    d = dict(d)
    cls = types[d.pop("type")]
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()}
    return cls(**kwargs)


def is_finite_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
