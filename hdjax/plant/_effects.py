r"""The switchable physical effects of the plant, one small `eqx.Module` each.

Every effect is off unless it is named in [`hdjax.plant.PlantParams`][]`.effects`. Each module
holds only float64 array leaves (differentiable) plus, where a structural choice is needed, a
static Python value (the Bouc-Wen exponent). Build effects by name with
[`hdjax.plant.make_effect`][], which validates names, shapes and signs in plain Python.

Friction laws use a smooth sign, $\operatorname{sgn}(\omega) \approx \tanh(\omega/\omega_s)$, so
gradients exist everywhere (Song et al. 2019 name "un-modelled friction" as their main error
source, Section IV.C).

Each effect has `reciprocals()`, the inverses of its scale parameters; the simulator computes
them once outside the time loop and passes them as `inv=`, because a division by a parameter
inside the loop keeps XLA from fusing the step into a few kernels (a 10-50x slowdown on CPU).

**Conventions.** The deflection $d = \theta_m/N - \theta_l$ is Hashimoto's $q_M/N - q_L$
(eq. (17)); the transmitted torque grows with it. The recorded angles are counted the other way
round, so that in a recording the twist $\theta_l - \theta_m/N$ (Song et al. eq. (5)) equals $d$
and grows with the recorded torque (see `hdjax/plant/_dynamics.py`).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .. import _trig
from .._custom_types import Array, Float
from .._errors import ConfigError
from .._io import did_you_mean

_f64 = lambda x: jnp.asarray(x, jnp.float64)


def _concrete(x):
    """A NumPy copy of `x` when it is concrete, else None (inside a trace)."""
    try:
        return np.asarray(x, dtype=np.float64)
    except Exception:  # a tracer
        return None


def _require(name: str, field: str, value, *, positive=False, nonneg=False, shape=None):
    arr = _concrete(value)
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


# ---------------------------------------------------------------------------------------------
# Kinematic error (Song et al. eq. (9), with free, possibly non-integer orders)
# ---------------------------------------------------------------------------------------------


class Harmonics(eqx.Module):
    r"""Kinematic error $\sum_j a_j \sin(o_j \theta + \varphi_j)$ of one angle [rad].

    Song et al. eq. (9) writes the kinematic error as a Fourier series of the output and the input
    angle; here orders are free floats (e.g. $2 - 2/N$). The angle is the *recorded* one (motor
    for `harmonic_m`, load for `harmonic_l`).

    **Arguments:**

    - `orders`: harmonic orders, shape `(n,)`.
    - `amplitudes`: amplitudes [rad of twist], shape `(n,)`, non-negative.
    - `phases`: phases [rad], shape `(n,)`.
    """

    orders: Float[Array, " n"]
    amplitudes: Float[Array, " n"]
    phases: Float[Array, " n"]

    def reciprocals(self):
        return {}

    def __call__(self, angle, inv=None):
        # a Python sum over the (static) number of harmonics keeps XLA from a reduction
        terms = [
            self.amplitudes[j] * _trig.sin(self.orders[j] * angle + self.phases[j])
            for j in range(self.orders.shape[0])
        ]
        return sum(terms[1:], terms[0]) if terms else jnp.zeros_like(angle)


class Coulomb(eqx.Module):
    r"""Coulomb friction $F_c \tanh(\omega/\omega_s)$ [N·m]."""

    level: Float[Array, ""]
    smoothing: Float[Array, ""]

    def reciprocals(self):
        return {"smoothing": 1.0 / self.smoothing}

    def __call__(self, omega, inv=None):
        inv = self.reciprocals() if inv is None else inv
        return self.level * jnp.tanh(omega * inv["smoothing"])


class Viscous(eqx.Module):
    r"""Viscous friction $F_v \omega$ [N·m]."""

    coefficient: Float[Array, ""]

    def reciprocals(self):
        return {}

    def __call__(self, omega, inv=None):
        return self.coefficient * omega


class Stribeck(eqx.Module):
    r"""Stribeck bump $F_s e^{-(\omega/\omega_{st})^2} \tanh(\omega/\omega_s)$ [N·m].

    `peak` is the breakaway torque *above* the Coulomb level, `speed` the Stribeck speed.
    """

    peak: Float[Array, ""]
    speed: Float[Array, ""]
    smoothing: Float[Array, ""]

    def reciprocals(self):
        return {"speed": 1.0 / self.speed, "smoothing": 1.0 / self.smoothing}

    def __call__(self, omega, inv=None):
        inv = self.reciprocals() if inv is None else inv
        x = omega * inv["speed"]
        return self.peak * jnp.exp(-(x * x)) * jnp.tanh(omega * inv["smoothing"])


# ---------------------------------------------------------------------------------------------
# Hysteresis: a torque state z in parallel with the elastic torque, driven by the deflection rate
# ---------------------------------------------------------------------------------------------


def _abs(x, eps):
    return jnp.sqrt(x * x + eps)


class BoucWen(eqx.Module):
    r"""Bouc-Wen hysteresis torque $z$ [N·m] driven by the deflection rate $\dot d$:

    $\dot z = a \dot d - \beta |\dot d| |z|^{n-1} z - \gamma \dot d |z|^n$,

    which saturates at $z_{max} = (a/(\beta+\gamma))^{1/n}$. `a` [N·m/rad] is the stiffness
    added right after a reversal; `beta`, `gamma` shape the loop (`beta >= gamma`,
    `beta + gamma > 0` keep it bounded and dissipative); `n` is a static integer exponent.
    Absolute values are smoothed ($\sqrt{x^2+\epsilon}$) so gradients exist.
    """

    a: Float[Array, ""]
    beta: Float[Array, ""]
    gamma: Float[Array, ""]
    n: int = eqx.field(static=True, default=1)

    def reciprocals(self):
        return {}

    def rate(self, z, d_dot, inv=None):
        az = _abs(z, 1e-12)
        ad = _abs(d_dot, 1e-16)
        zn = az ** (self.n - 1) if self.n > 1 else 1.0
        return self.a * d_dot - self.beta * ad * zn * z - self.gamma * d_dot * zn * az

    def saturation(self):
        return (self.a / (self.beta + self.gamma)) ** (1.0 / self.n)


class Dahl(eqx.Module):
    r"""Dahl hysteresis torque $z$ [N·m]: $\dot z = \sigma (\dot d - |\dot d| z / F_h)$.

    `sigma` [N·m/rad] is the stiffness right after a reversal, `level` [N·m] the saturation
    (the half-height of the loop).
    """

    sigma: Float[Array, ""]
    level: Float[Array, ""]

    def reciprocals(self):
        return {"level": 1.0 / self.level}

    def rate(self, z, d_dot, inv=None):
        inv = self.reciprocals() if inv is None else inv
        return self.sigma * (d_dot - _abs(d_dot, 1e-16) * z * inv["level"])

    def saturation(self):
        return self.level


class LuGre(eqx.Module):
    r"""LuGre-type hysteresis: a bristle state with a Stribeck-shaped limit.

    $\dot z = \sigma_0 (\dot d - |\dot d| z / g(\dot d))$ with
    $g(v) = F_c + (F_s - F_c) e^{-(v/v_s)^2}$, so the loop height depends on the deflection rate.
    """

    sigma0: Float[Array, ""]
    level: Float[Array, ""]
    peak: Float[Array, ""]
    speed: Float[Array, ""]

    def reciprocals(self):
        return {"speed": 1.0 / self.speed}

    def rate(self, z, d_dot, inv=None):
        inv = self.reciprocals() if inv is None else inv
        x = d_dot * inv["speed"]
        g = self.level + (self.peak - self.level) * jnp.exp(-(x * x))
        return self.sigma0 * (d_dot - _abs(d_dot, 1e-16) * z / g)

    def saturation(self):
        """Loop half-height at deflection rates well above `speed`."""
        return self.level


# ---------------------------------------------------------------------------------------------
# Compliance modifiers
# ---------------------------------------------------------------------------------------------


class Backlash(eqx.Module):
    r"""Lost motion: the deflection gains $\frac{b}{2}\tanh(T/T_b)$ [rad].

    `width` $b$ [rad] is the lost motion, `torque_scale` $T_b$ [N·m] the torque over which the
    play closes (catalogues measure lost motion at $\pm 4\%$ of rated torque).
    """

    width: Float[Array, ""]
    torque_scale: Float[Array, ""]

    def reciprocals(self):
        return {"torque_scale": 1.0 / self.torque_scale}

    def deflection(self, torque, inv=None):
        inv = self.reciprocals() if inv is None else inv
        return 0.5 * self.width * jnp.tanh(torque * inv["torque_scale"])

    def slope(self, torque, inv=None):
        inv = self.reciprocals() if inv is None else inv
        th = jnp.tanh(torque * inv["torque_scale"])
        return 0.5 * self.width * (1.0 - th * th) * inv["torque_scale"]


class Stiffening(eqx.Module):
    r"""A cubic spring $\kappa_3 d^3$ [N·m] in parallel with the flexspline."""

    cubic: Float[Array, ""]

    def reciprocals(self):
        return {}

    def torque(self, d):
        return self.cubic * d * d * d


class WaveGenerator(eqx.Module):
    r"""Wave-generator compliance, Song et al. eq. (8) with the WG torque in place of the current.

    $\Delta\theta_{wg} = \sum_{j=1}^m w_j u^j$ [rad at the motor side], $u = T/N$ [N·m] the torque
    the wave generator transmits. Its share of the joint deflection is $\Delta\theta_{wg}/N$
    (eq. (6)). `coefficients` are $w_1..w_m$; the polynomial must increase on the working range.
    """

    coefficients: Float[Array, " m"]

    def reciprocals(self):
        return {}

    def deflection(self, u, inv=None):
        # Horner: u * (w1 + u * (w2 + ...)), exact and NaN-free at u = 0
        acc = jnp.zeros_like(u)
        for j in range(self.coefficients.shape[0] - 1, -1, -1):
            acc = acc * u + self.coefficients[j]
        return acc * u

    def slope(self, u, inv=None):
        acc = jnp.zeros_like(u)
        for j in range(self.coefficients.shape[0] - 1, -1, -1):
            acc = acc * u + (j + 1.0) * self.coefficients[j]
        return acc


class Temperature(eqx.Module):
    r"""Thermal drift: a temperature state heated by the motor current.

    $\dot\vartheta = (\vartheta_a - \vartheta)/\tau_{th} + h\, i^2 + r$ ($r$ a slow ambient
    drift [K/s]). The flexspline compliance scales as $1 + \alpha(\vartheta - \vartheta_0)$ and
    the twist gains an offset $\beta(\vartheta - \vartheta_0)$; the recording gets a `temperature`
    column.
    """

    reference: Float[Array, ""]
    ambient: Float[Array, ""]
    initial: Float[Array, ""]
    alpha: Float[Array, ""]
    beta: Float[Array, ""]
    time_constant: Float[Array, ""]
    heating: Float[Array, ""]
    drift: Float[Array, ""]

    def reciprocals(self):
        return {"time_constant": 1.0 / self.time_constant}

    def rate(self, temp, current, inv=None):
        inv = self.reciprocals() if inv is None else inv
        return (
            (self.ambient - temp) * inv["time_constant"]
            + self.heating * current * current
            + self.drift
        )


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------

_HYSTERESIS_MODELS = ("bouc_wen", "dahl", "lugre")


def _defaults(rated_torque: float, k1: float) -> dict[str, dict]:
    """Default parameters of every effect for a joint of `rated_torque` and compliance `k1`.

    Sources: lost motion and hysteresis loss ~1 arcmin (2.9e-4 rad) for Harmonic Drive CSG/CSF
    size 40-50 units, ratio >= 80 (catalogue "lost motion" measured at +-4 % of rated torque);
    transmission accuracy ~1 arcmin peak-to-peak split over motor- and load-side harmonics.
    """
    arcmin = np.pi / (180.0 * 60.0)
    stiff = 1.0 / k1
    return {
        "harmonic_m": dict(orders=[2.0], amplitudes=[0.15 * arcmin], phases=[0.3]),
        "harmonic_l": dict(
            orders=[1.0, 2.0], amplitudes=[0.2 * arcmin, 0.1 * arcmin], phases=[0.0, 1.1]
        ),
        "coulomb_m": dict(level=0.1, smoothing=0.5),
        "viscous_m": dict(coefficient=2.0e-4),
        "stribeck_m": dict(peak=0.05, speed=2.0, smoothing=0.5),
        "coulomb_l": dict(level=0.0075 * rated_torque, smoothing=5e-3),
        "viscous_l": dict(coefficient=2.0),
        "stribeck_l": dict(peak=0.005 * rated_torque, speed=0.02, smoothing=5e-3),
        "hysteresis": dict(
            model="bouc_wen",
            a=0.5 * stiff,
            beta=0.5 * stiff / (0.025 * rated_torque),
            gamma=0.0,
            n=1,
        ),
        "backlash": dict(width=1.0 * arcmin, torque_scale=0.02 * rated_torque),
        "stiffening": dict(cubic=0.1 * rated_torque / (rated_torque * k1 * 1.0) ** 3),
        "temperature": dict(
            reference=25.0,
            ambient=25.0,
            initial=25.0,
            alpha=3e-3,
            beta=1e-6,
            time_constant=300.0,
            heating=3e-3,
            drift=0.02,
        ),
        "wg_compliance": dict(coefficients=[0.02, 0.0, 0.002]),
    }


EFFECT_NAMES = (
    "harmonic_m",
    "harmonic_l",
    "coulomb_m",
    "viscous_m",
    "stribeck_m",
    "coulomb_l",
    "viscous_l",
    "stribeck_l",
    "hysteresis",
    "backlash",
    "stiffening",
    "temperature",
    "wg_compliance",
)
"""Names of the switchable effects, in the order the plant applies them."""


def _vector(name, field, value):
    arr = _concrete(value)
    if arr is not None and arr.ndim != 1:
        raise ConfigError(
            f"effect {name!r}: parameter {field!r} must be a 1-D list, got shape {arr.shape}"
        )
    return _f64(value)


def check_effect_name(name: str) -> None:
    """Raise `ConfigError` for an unknown effect name, listing the known ones."""
    if name not in EFFECT_NAMES:
        raise ConfigError(
            f"unknown plant effect {name!r}{did_you_mean(name, EFFECT_NAMES)}; known effects: "
            f"{', '.join(EFFECT_NAMES)}"
        )


def make_effect(name: str, *, rated_torque: float = 400.0, k1: float = 1.4925e-5, **kwargs):
    """Build one effect module by name, filling unspecified parameters with defaults.

    **Arguments:**

    - `name`: one of [`hdjax.plant.EFFECT_NAMES`][].
    - `rated_torque`, `k1`: scale the defaults to the joint (rated torque [N·m] and the
      small-torque compliance [rad/N·m]).
    - `**kwargs`: the effect's parameters (see each effect class); unknown keys raise.

    **Returns:** the effect module.
    """
    check_effect_name(name)
    params = dict(_defaults(rated_torque, k1)[name])
    if name == "hysteresis" and "model" in kwargs and kwargs["model"] != params["model"]:
        model = kwargs["model"]
        if model not in _HYSTERESIS_MODELS:
            raise ConfigError(
                f"effect 'hysteresis': unknown model {model!r}"
                f"{did_you_mean(model, _HYSTERESIS_MODELS)}"
                f"; known models: {', '.join(_HYSTERESIS_MODELS)}"
            )
        level = 0.025 * rated_torque
        sigma = 0.5 / k1
        params = (
            dict(model="dahl", sigma=sigma, level=level)
            if model == "dahl"
            else dict(model="lugre", sigma0=sigma, level=level, peak=1.5 * level, speed=1e-3)
        )
    unknown = [k for k in kwargs if k not in params]
    if unknown:
        raise ConfigError(
            f"effect {name!r}: unknown parameter(s) {', '.join(map(repr, unknown))}"
            f"{did_you_mean(unknown[0], params)}; its parameters are {', '.join(params)}"
        )
    params.update(kwargs)
    return _build(name, params)


def _build(name: str, p: dict):
    if name in ("harmonic_m", "harmonic_l"):
        orders = _vector(name, "orders", p["orders"])
        amps = _vector(name, "amplitudes", p["amplitudes"])
        phases = _vector(name, "phases", p["phases"])
        n = orders.shape
        _require(name, "orders", orders, shape=n)
        _require(name, "amplitudes", amps, nonneg=True, shape=n)
        _require(name, "phases", phases, shape=n)
        return Harmonics(orders, amps, phases)
    if name in ("coulomb_m", "coulomb_l"):
        _require(name, "level", p["level"], nonneg=True, shape=())
        _require(name, "smoothing", p["smoothing"], positive=True, shape=())
        return Coulomb(_f64(p["level"]), _f64(p["smoothing"]))
    if name in ("viscous_m", "viscous_l"):
        _require(name, "coefficient", p["coefficient"], nonneg=True, shape=())
        return Viscous(_f64(p["coefficient"]))
    if name in ("stribeck_m", "stribeck_l"):
        _require(name, "peak", p["peak"], nonneg=True, shape=())
        for f in ("speed", "smoothing"):
            _require(name, f, p[f], positive=True, shape=())
        return Stribeck(_f64(p["peak"]), _f64(p["speed"]), _f64(p["smoothing"]))
    if name == "hysteresis":
        model = p["model"]
        if model not in _HYSTERESIS_MODELS:
            raise ConfigError(
                f"effect 'hysteresis': unknown model {model!r}"
                f"{did_you_mean(model, _HYSTERESIS_MODELS)}"
                f"; known models: {', '.join(_HYSTERESIS_MODELS)}"
            )
        if model == "bouc_wen":
            n = p["n"]
            if not isinstance(n, int) or isinstance(n, bool) or n < 1:
                raise ConfigError(
                    f"effect 'hysteresis': Bouc-Wen exponent n must be an int >= 1, got {n!r}"
                )
            _require(name, "a", p["a"], positive=True, shape=())
            _require(name, "beta", p["beta"], shape=())
            _require(name, "gamma", p["gamma"], shape=())
            b, g = _concrete(p["beta"]), _concrete(p["gamma"])
            if b is not None and g is not None and not (b + g > 0 and b - g >= 0):
                raise ConfigError(
                    f"effect 'hysteresis': Bouc-Wen needs beta + gamma > 0 and beta >= gamma "
                    f"(a bounded, dissipative loop), got beta={float(b)}, gamma={float(g)}"
                )
            return BoucWen(_f64(p["a"]), _f64(p["beta"]), _f64(p["gamma"]), n)
        if model == "dahl":
            _require(name, "sigma", p["sigma"], positive=True, shape=())
            _require(name, "level", p["level"], positive=True, shape=())
            return Dahl(_f64(p["sigma"]), _f64(p["level"]))
        for f in ("sigma0", "level", "peak", "speed"):
            _require(name, f, p[f], positive=True, shape=())
        return LuGre(_f64(p["sigma0"]), _f64(p["level"]), _f64(p["peak"]), _f64(p["speed"]))
    if name == "backlash":
        _require(name, "width", p["width"], nonneg=True, shape=())
        _require(name, "torque_scale", p["torque_scale"], positive=True, shape=())
        return Backlash(_f64(p["width"]), _f64(p["torque_scale"]))
    if name == "stiffening":
        _require(name, "cubic", p["cubic"], nonneg=True, shape=())
        return Stiffening(_f64(p["cubic"]))
    if name == "temperature":
        for f in ("reference", "ambient", "initial", "alpha", "beta", "drift"):
            _require(name, f, p[f], shape=())
        _require(name, "time_constant", p["time_constant"], positive=True, shape=())
        _require(name, "heating", p["heating"], nonneg=True, shape=())
        return Temperature(**{k: _f64(v) for k, v in p.items()})
    if name == "wg_compliance":
        w = _vector(name, "coefficients", p["coefficients"])
        arr = _concrete(w)
        if arr is not None and (arr.shape[0] < 1 or arr[0] <= 0):
            raise ConfigError(
                "effect 'wg_compliance': the linear coefficient w_1 must be positive (the wave "
                f"generator deflects with its torque), got coefficients {arr.tolist()}"
            )
        return WaveGenerator(w)
    raise AssertionError(name)  # pragma: no cover
