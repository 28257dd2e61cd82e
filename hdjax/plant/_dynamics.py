r"""The two-inertia harmonic-drive joint: state, right-hand side and one RK4 step.

Chain (Song et al. 2019, Figs. 3 and 7; Hashimoto et al. 1993, eqs. (15)-(17)):
motor (current loop, torque $K_t i$) -> wave generator -> flexspline -> output bearing -> torque
sensor -> link with load.

**Sign conventions.** The state follows Hashimoto: $q_M$ = `theta_m`, $q_L$ = `theta_l`, the
deflection $d = \theta_m/N - \theta_l$ and the transmitted joint torque
$T_J = T(d, \dot d, z, \dots)$ grow together (eq. (17): $T_J = K(q_M/N - q_L)$ in the linear
case), a positive motor torque drives the link in the positive direction, and `load_torque` is an
external torque on the link in that same direction. A *recording* (`hdjax/plant/_sensors.py`)
reports the angles counted the other way round ($\theta^{rec} = -\theta$), so that the recorded
twist $\theta_l^{rec} - \theta_m^{rec}/N$ of Song et al. eq. (5) equals $d$ and grows with the
recorded torque and current (`hdjax.Joint(twist_sign=+1)`).

**Deflection budget** (Song et al. eq. (6)):

$d = \Delta\theta_f(T_s) + \Delta\theta_{wg}(T_s/N)/N + b(T_s) + \theta_{err}
+ \beta\Delta\vartheta$

with $\Delta\theta_f$ the flexspline compliance (eq. (7), scaled by $1 + \alpha\Delta\vartheta$
under `temperature`; the whole elastic part $G$ scaled by $1 + \varepsilon(\theta)$ under a
compliance ripple, `ripple_m`/`ripple_l`), $\Delta\theta_{wg}$ the wave-generator polynomial
(eq. (8) in the WG torque),
$b$ the lost motion (`backlash`), $\theta_{err}$ the kinematic error (eq. (9), harmonics of the
recorded angles). It is inverted for the elastic torque $T_s$ (closed form, eq. (27), when only
the piecewise flexspline is on; a few Newton steps otherwise). The transmitted torque is

$T_J = T_s + \kappa_3 d_{eff}^3 + z + c\,\dot d$

with $z$ the hysteresis state, $\kappa_3$ the `stiffening` cubic and $c$ the structural damping.
Equations of motion:

$J_M \dot\omega_m = K_t i - F_m(\omega_m) - T_J/N$,
$J_L \dot\omega_l = T_J - F_l(\omega_l) + \tau_{load}$,
$\dot i = (\tau_{cmd}/K_t - i)/\tau_i$.

The torque sensor sits between the output bearing and the link: $T_{sensor} = T_J - F_l(\omega_l)$.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from .._custom_types import Array, ArrayLike, Float
from ..effects import WG_COMPLIANCE, in_slot
from ._params import PlantParams

Reciprocals = dict[str, Any]
"""`reciprocals(params)`: the inverses of the scale parameters (arrays), and per effect its own
(a dict by effect name)."""

_f64 = lambda x: jnp.asarray(x, jnp.float64)


class PlantState(eqx.Module):
    r"""State of the joint (all float64 scalars, or batched arrays under `vmap`).

    **Arguments:**

    - `theta_m`, `omega_m`: motor angle [rad] and speed [rad/s] (Hashimoto's $q_M$).
    - `theta_l`, `omega_l`: link angle [rad] and speed [rad/s] (Hashimoto's $q_L$).
    - `current`: motor current $i$ [A].
    - `z`: hysteresis torque [N·m] (stays 0 when `hysteresis` is off).
    - `temperature`: joint temperature [°C] (constant when `temperature` is off).
    """

    theta_m: Float[Array, " ..."]
    omega_m: Float[Array, " ..."]
    theta_l: Float[Array, " ..."]
    omega_l: Float[Array, " ..."]
    current: Float[Array, " ..."]
    z: Float[Array, " ..."]
    temperature: Float[Array, " ..."]


def zero_state(temperature: Float[ArrayLike, ""] = 25.0) -> PlantState:
    """A state at rest at the origin (no deflection, no current)."""
    z = jnp.zeros((), jnp.float64)
    return PlantState(z, z, z, z, z, z, _f64(temperature))


def reciprocals(params: PlantParams) -> Reciprocals:
    """Inverses of the scale parameters, computed once outside the time loop.

    Dividing by a traced parameter inside `lax.scan` keeps XLA from fusing the step (a division is
    "expensive" and is not duplicated into its consumers), which costs 10-50x on CPU. Every
    function below takes them as `inv=` and computes them itself when `inv` is None.
    """
    return {
        "ratio": 1.0 / params.ratio,
        "inertia_m": 1.0 / params.inertia_m,
        "inertia_l": 1.0 / params.inertia_l,
        "torque_constant": 1.0 / params.torque_constant,
        "current_time_constant": 1.0 / params.current_time_constant,
        "compliance": 1.0 / params.compliance,
        "corner": 1.0 / params.corner,
        "effects": {name: eff.reciprocals() for name, eff in params.effects.items()},
        **(
            {"series": 1.0 / (params.compliance + _wg_linear(params))}
            if params.has(WG_COMPLIANCE)
            else {}
        ),
    }


def _wg_linear(params):
    return params.effects[WG_COMPLIANCE].coefficients[0] / (params.ratio * params.ratio)


def _inv(params, inv):
    return reciprocals(params) if inv is None else inv


def _eff(params, inv, name):
    return params.effects[name], inv["effects"][name]


def _slot(params, slot: str) -> tuple[str, ...]:
    """The switched-on effects that enter the joint in `slot` (see `hdjax.effects.PLANT_SLOTS`),
    in registration order; resolved in Python at trace time, so the traced program is the same
    as with the names written out."""
    return in_slot(params.effects, slot)


def _one(params, slot: str):
    """The name of the one switched-on effect in a single-effect slot, or None."""
    names = _slot(params, slot)
    return names[0] if names else None


# ---------------------------------------------------------------------------------------------
# Compliance of the flexspline (Song et al. eq. (7)) and its inverse (eq. (27))
# ---------------------------------------------------------------------------------------------


def flexspline_deflection(
    params: PlantParams, torque: Float[ArrayLike, "*batch"], *, inv: Reciprocals | None = None
) -> Float[Array, "*batch"]:
    r"""Flexspline deformation $\Delta\theta_f(T)$ [rad], Song et al. eq. (7).

    Five segments with knots $\pm\tau_0/3, \pm2\tau_0/3$, extended linearly beyond $\pm\tau_0$.
    With `flexspline="smooth"` the knots are rounded by a softplus of width `corner`.
    """
    inv = _inv(params, inv)
    k1, k2, k3, k4, k5 = (params.compliance[j] for j in range(5))
    c = params.rated_torque * (1.0 / 3.0)
    b = 2.0 * c
    if params.flexspline == "smooth":
        w, iw = params.corner, inv["corner"]
        r = lambda x: w * jax.nn.softplus(x * iw)
    else:
        r = lambda x: jnp.maximum(x, 0.0)
    return (
        k1 * torque
        + (k4 - k1) * r(torque - c)
        + (k5 - k4) * r(torque - b)
        - (k2 - k1) * r(-torque - c)
        - (k3 - k2) * r(-torque - b)
    )


def _flexspline_slope(params: PlantParams, torque, inv):
    k1, k2, k3, k4, k5 = (params.compliance[j] for j in range(5))
    c = params.rated_torque * (1.0 / 3.0)
    b = 2.0 * c
    if params.flexspline == "smooth":
        iw = inv["corner"]
        h = lambda x: jax.nn.sigmoid(x * iw)
    else:
        h = lambda x: jnp.where(x > 0, 1.0, 0.0)
    return (
        k1
        + (k4 - k1) * h(torque - c)
        + (k5 - k4) * h(torque - b)
        + (k2 - k1) * h(-torque - c)
        + (k3 - k2) * h(-torque - b)
    )


def flexspline_inverse(
    params: PlantParams,
    deflection: Float[ArrayLike, "*batch"],
    *,
    scale: Float[ArrayLike, " ..."] = 1.0,
    extra: Float[ArrayLike, " ..."] = 0.0,
    inv: Reciprocals | None = None,
) -> Float[Array, "*batch"]:
    r"""Inverse of eq. (7): torque [N·m] from flexspline deformation, Song et al. eq. (27).

    Exact for the piecewise flexspline. `scale` multiplies every compliance and `extra` adds a
    constant compliance on every segment (a linear series element), both keeping the knots in
    torque where they are; used for the thermal factor and the linear wave-generator term.
    """
    inv = _inv(params, inv)
    torque, _ = _inverse_and_stiffness(params, deflection, scale, extra, inv)
    return torque


def _segment_compliances(params, scale, extra, inv):
    k = [params.compliance[j] * scale + extra for j in range(5)]
    plain = isinstance(scale, float) and scale == 1.0
    if plain and isinstance(extra, float) and extra == 0.0:
        ik = [inv["compliance"][j] for j in range(5)]
    elif plain and "series" in inv:
        ik = [inv["series"][j] for j in range(5)]
    else:
        ik = [1.0 / kj for kj in k]
    return k, ik


def _inverse_and_stiffness(params, d, scale, extra, inv):
    """Piecewise-linear inverse and the stiffness of the segment `d` falls in (no division)."""
    (k1, k2, k3, k4, k5), ik = _segment_compliances(params, scale, extra, inv)
    c = params.rated_torque * (1.0 / 3.0)
    torque = (
        jnp.clip(d, -k1 * c, k1 * c) * ik[0]
        + jnp.clip(d - k1 * c, 0.0, k4 * c) * ik[3]
        + jnp.maximum(d - (k1 + k4) * c, 0.0) * ik[4]
        + jnp.clip(d + k1 * c, -k2 * c, 0.0) * ik[1]
        + jnp.minimum(d + (k1 + k2) * c, 0.0) * ik[2]
    )
    d1, d2p, d2n = k1 * c, (k1 + k4) * c, -(k1 + k2) * c
    stiffness = jnp.where(
        d >= d1,
        jnp.where(d >= d2p, ik[4], ik[3]),
        jnp.where(d >= -d1, ik[0], jnp.where(d >= d2n, ik[1], ik[2])),
    )
    return torque, stiffness


# ---------------------------------------------------------------------------------------------
# Deflection budget (Song et al. eq. (6)) and its inversion
# ---------------------------------------------------------------------------------------------


def _needs_newton(params: PlantParams) -> bool:
    if params.flexspline == "smooth" or _slot(params, "compliance"):
        return True
    return params.has(WG_COMPLIANCE) and params.effects[WG_COMPLIANCE].coefficients.shape[0] > 1


def _thermal(params: PlantParams, temperature):
    """(compliance factor, temperature rise) of the `temperature` effect, or (1.0, 0.0)."""
    name = _one(params, "temperature")
    if name is None:
        return 1.0, 0.0
    eff = params.effects[name]
    dtemp = temperature - eff.reference
    return 1.0 + eff.alpha * dtemp, dtemp


def compliance_deflection(
    params: PlantParams,
    torque: Float[ArrayLike, "*batch"],
    temperature: Float[ArrayLike, " ..."],
    *,
    inv: Reciprocals | None = None,
) -> Float[Array, "*batch"]:
    r"""Elastic part of the deflection, $G(T) = s\Delta\theta_f(T) + \Delta\theta_{wg}(T/N)/N
    + b(T)$.

    `s` is the thermal compliance factor $1 + \alpha\Delta\vartheta$ (1 without `temperature`).
    """
    inv = _inv(params, inv)
    scale, _ = _thermal(params, temperature)
    g = scale * flexspline_deflection(params, torque, inv=inv)
    if params.has(WG_COMPLIANCE):
        wg = params.effects[WG_COMPLIANCE]
        g = g + wg.deflection(torque * inv["ratio"]) * inv["ratio"]
    for name in _slot(params, "compliance"):
        eff, ie = _eff(params, inv, name)
        g = g + eff.deflection(torque, ie)
    return g


def _compliance_slope(params: PlantParams, torque, temperature, inv):
    scale, _ = _thermal(params, temperature)
    g = scale * _flexspline_slope(params, torque, inv)
    if params.has(WG_COMPLIANCE):
        wg = params.effects[WG_COMPLIANCE]
        g = g + wg.slope(torque * inv["ratio"]) * inv["ratio"] * inv["ratio"]
    for name in _slot(params, "compliance"):
        eff, ie = _eff(params, inv, name)
        g = g + eff.slope(torque, ie)
    return g


def kinematic_error(
    params: PlantParams, theta_m: Float[ArrayLike, "*batch"], theta_l: Float[ArrayLike, "*batch"]
) -> Float[Array, "*batch"]:
    r"""Kinematic error $\theta_{err}$ [rad] (Song et al. eq. (9)) from the *state* angles.

    Harmonics are of the recorded angles $-\theta_m$, $-\theta_l$ (see the module docstring).
    """
    err = jnp.zeros_like(theta_m)
    for name in _slot(params, "kinematic_m"):
        err = err + params.effects[name](-theta_m)
    for name in _slot(params, "kinematic_l"):
        err = err + params.effects[name](-theta_l)
    return err


def _ripple_stiffness(params: PlantParams, state: PlantState, inv):
    r"""$1/(1 + \sum\varepsilon)$ of the compliance ripples (`compliance_ripple_*` slots), of the
    recorded angles $-\theta_m$, $-\theta_l$; 1.0 without one. The series compliance is scaled
    by $1 + \varepsilon$, so $G(T_s) = d_{eff}/(1 + \varepsilon)$."""
    change = None
    for slot, angle in (
        ("compliance_ripple_m", -state.theta_m),
        ("compliance_ripple_l", -state.theta_l),
    ):
        for name in _slot(params, slot):
            eff, ie = _eff(params, inv, name)
            change = eff(angle, ie) if change is None else change + eff(angle, ie)
    return 1.0 if change is None else 1.0 / (1.0 + change)


def effective_deflection(
    params: PlantParams, state: PlantState, *, inv: Reciprocals | None = None
) -> Float[Array, " ..."]:
    r"""$d_{eff} = d - \theta_{err} - \beta\Delta\vartheta$: the deflection the springs carry."""
    inv = _inv(params, inv)
    d = state.theta_m * inv["ratio"] - state.theta_l
    d = d - kinematic_error(params, state.theta_m, state.theta_l)
    thermal = _one(params, "temperature")
    if thermal is not None:
        _, dtemp = _thermal(params, state.temperature)
        d = d - params.effects[thermal].beta * dtemp
    return d


def elastic_torque(params: PlantParams, d_eff, temperature, *, inv: Reciprocals | None = None):
    r"""Solve $G(T_s) = d_{eff}$ for the elastic torque $T_s$ [N·m].

    Closed form (eq. (27)) when the series compliance is piecewise linear (the flexspline, with the
    thermal factor and the linear wave-generator term folded into every segment). Otherwise
    `params.newton_iterations` (static) Newton steps from that closed form (wave-generator
    polynomial, backlash, smooth flexspline). With the Song preset's wave generator, three steps
    leave at most 2e-8 N·m within rated torque and 0.05 N·m at twice rated torque.
    """
    inv = _inv(params, inv)
    scale, _ = _thermal(params, temperature)
    extra = 0.0
    if params.has(WG_COMPLIANCE):
        extra = params.effects[WG_COMPLIANCE].coefficients[0] * inv["ratio"] * inv["ratio"]
    torque, _ = _inverse_and_stiffness(params, d_eff, scale, extra, inv)
    if _needs_newton(params):
        for _ in range(params.newton_iterations):
            residual = compliance_deflection(params, torque, temperature, inv=inv) - d_eff
            torque = torque - residual / _compliance_slope(params, torque, temperature, inv)
    return torque


def flexspline_torque(
    params: PlantParams, state: PlantState, *, inv: Reciprocals | None = None
) -> Float[Array, " ..."]:
    r"""Transmitted joint torque $T_J$ [N·m] (Hashimoto eq. (17); Song's $T_f$).

    $T_J = T_s(d_{eff}) + \kappa_3 d_{eff}^3 + z + c\,\dot d$ (see the module docstring). In the
    linear Hashimoto preset this is exactly $K(\theta_m/N - \theta_l) + c\,\dot d$.

    **Arguments:**

    - `params`: [`hdjax.plant.PlantParams`][].
    - `state`: [`hdjax.plant.PlantState`][].
    - `inv`: optional `reciprocals(params)`, precomputed (speed only).

    **Returns:** the torque, same shape as the state's leaves.
    """
    inv = _inv(params, inv)
    d_eff = effective_deflection(params, state, inv=inv)
    torque = elastic_torque(
        params, d_eff * _ripple_stiffness(params, state, inv), state.temperature, inv=inv
    )
    for name in _slot(params, "spring"):
        torque = torque + params.effects[name].torque(d_eff)
    d_dot = state.omega_m * inv["ratio"] - state.omega_l
    return torque + state.z + params.damping * d_dot


def _friction(params, inv, slot, omega):
    f = jnp.zeros_like(omega)
    for name in _slot(params, slot):
        eff, ie = _eff(params, inv, name)
        f = f + eff(omega, ie)
    return f


def motor_friction(
    params: PlantParams, omega_m: Float[ArrayLike, "*batch"], *, inv: Reciprocals | None = None
) -> Float[Array, "*batch"]:
    """Motor-side friction $F_m(\\omega_m)$ [N·m] (Coulomb, viscous, Stribeck; each if on)."""
    return _friction(params, _inv(params, inv), "motor_friction", omega_m)


def output_friction(
    params: PlantParams, omega_l: Float[ArrayLike, "*batch"], *, inv: Reciprocals | None = None
) -> Float[Array, "*batch"]:
    """Output-bearing friction $F_l(\\omega_l)$ [N·m] (Coulomb, viscous, Stribeck; each if on)."""
    return _friction(params, _inv(params, inv), "output_friction", omega_l)


def sensor_torque(
    params: PlantParams, state: PlantState, *, inv: Reciprocals | None = None
) -> Float[Array, " ..."]:
    r"""Noiseless torque-sensor reading $T_J - F_l(\omega_l)$ [N·m] (sensor after the bearing)."""
    inv = _inv(params, inv)
    return flexspline_torque(params, state, inv=inv) - output_friction(
        params, state.omega_l, inv=inv
    )


# ---------------------------------------------------------------------------------------------
# Right-hand side and one step
# ---------------------------------------------------------------------------------------------


def derivatives(
    params: PlantParams,
    state: PlantState,
    motor_torque: Float[ArrayLike, " ..."],
    load_torque: Float[ArrayLike, " ..."],
    *,
    inv: Reciprocals | None = None,
) -> PlantState:
    r"""Time derivative of the state (pure, jittable, vmappable).

    **Arguments:**

    - `params`: [`hdjax.plant.PlantParams`][].
    - `state`: [`hdjax.plant.PlantState`][].
    - `motor_torque`: commanded motor torque $\tau_{cmd} = K_t i_{ref}$ [N·m at the motor]; the
      current follows $i_{ref}$ through the first-order current loop.
    - `load_torque`: external torque on the link [N·m], positive in the direction of positive
      $\theta_l$ (e.g. gravity of the weights).
    - `inv`: optional `reciprocals(params)`, precomputed (speed only).

    **Returns:** a `PlantState` holding the derivatives.
    """
    inv = _inv(params, inv)
    t_j = flexspline_torque(params, state, inv=inv)
    if "one" in inv:
        t_j = _materialise(t_j, inv["one"])  # computed once for both accelerations
    # mechanics: Hashimoto eqs. (15)-(16) with friction on both sides
    acc_m = (
        params.torque_constant * state.current
        - motor_friction(params, state.omega_m, inv=inv)
        - t_j * inv["ratio"]
    ) * inv["inertia_m"]
    acc_l = (t_j - output_friction(params, state.omega_l, inv=inv) + load_torque) * inv["inertia_l"]
    # current loop
    di = (motor_torque * inv["torque_constant"] - state.current) * inv["current_time_constant"]
    # hysteresis and temperature
    d_dot = state.omega_m * inv["ratio"] - state.omega_l
    dz = jnp.zeros_like(state.z)
    for name in _slot(params, "hysteresis"):
        eff, ie = _eff(params, inv, name)
        dz = dz + eff.rate(state.z, d_dot, ie)
    dtemp = jnp.zeros_like(state.temperature)
    for name in _slot(params, "temperature"):
        eff, ie = _eff(params, inv, name)
        dtemp = dtemp + eff.rate(state.temperature, state.current, ie)
    return PlantState(
        theta_m=state.omega_m,
        omega_m=acc_m,
        theta_l=state.omega_l,
        omega_l=acc_l,
        current=di,
        z=dz,
        temperature=dtemp,
    )


def _axpy(a, x: PlantState, y: PlantState) -> PlantState:
    return jax.tree.map(lambda xi, yi: yi + a * xi, x, y)


def _materialise(tree, one):
    r"""`tree` divided by a traced 1.0: numerically the identity, a fusion boundary for XLA.

    XLA's CPU fusion copies cheap producers into every consumer. In an RK4 step each stage's
    accelerations feed the next stage and the final update of every state, and the joint torque
    feeds both accelerations, so without a boundary whole stages (the kinematic-error harmonics,
    the compliance inversion) are recomputed many times: 12 500 scalar operations per step with
    the Song preset instead of 1 900 (Hashimoto preset: 1 200 instead of 380), and about half the
    speed. A division is "expensive" to XLA, so its result is computed once and stored. `one` must
    be a traced 1.0 (`rk4_step` uses `1.0 + 0.0 * omega_m`, which XLA does not fold); the division
    by exactly 1.0 is exact, so values and gradients are unchanged.
    """
    return jax.tree.map(lambda x: x / one, tree)


def rk4_step(
    params: PlantParams,
    state: PlantState,
    motor_torque: Float[ArrayLike, " ..."],
    load_torque: Float[ArrayLike, " ..."],
    dt: Float[ArrayLike, ""],
    *,
    inv: Reciprocals | None = None,
) -> PlantState:
    r"""One classical Runge-Kutta step of length `dt` with inputs held over the step (ZOH).

    The linear current loop is integrated exactly: over the step
    $i(t_0 + s) = i_{ref} + (i_0 - i_{ref}) e^{-s/\tau_i}$, and the mechanics see that exact
    current at the RK4 stages. This keeps a fast (kHz) current loop from limiting the step; the
    mechanical modes must satisfy the RK4 stability limit (checked by the simulators).

    **Arguments:**

    - `params`, `state`: as in [`hdjax.plant.derivatives`][].
    - `motor_torque`, `load_torque`: held constant over the step [N·m].
    - `dt`: step [s].
    - `inv`: optional `reciprocals(params)`, precomputed (speed only).

    **Returns:** the state at $t + dt$.
    """
    inv = _inv(params, inv)
    i_ref = motor_torque * inv["torque_constant"]
    i0 = state.current
    decay_half = jnp.exp(-0.5 * dt * inv["current_time_constant"])
    i_half = i_ref + (i0 - i_ref) * decay_half
    i_full = i_ref + (i0 - i_ref) * decay_half * decay_half
    with_i = lambda st, i: eqx.tree_at(lambda x: x.current, st, i)
    one = 1.0 + 0.0 * state.omega_m  # a 1.0 XLA cannot fold (see `_materialise`)
    inv = {**inv, "one": one}
    # store each stage's accelerations and state rates once (see `_materialise`); the angle
    # rates are the stage speeds and the current is integrated exactly, both cheap to recompute
    rates = lambda k: (
        (k.omega_m, k.omega_l)
        + ((k.z,) if _slot(params, "hysteresis") else ())
        + ((k.temperature,) if _slot(params, "temperature") else ())
    )

    def f(st):
        k = derivatives(params, st, motor_torque, load_torque, inv=inv)
        return eqx.tree_at(rates, k, _materialise(rates(k), one))

    k1 = f(state)
    k2 = f(with_i(_axpy(0.5 * dt, k1, state), i_half))
    k3 = f(with_i(_axpy(0.5 * dt, k2, state), i_half))
    k4 = f(with_i(_axpy(dt, k3, state), i_full))
    incr = jax.tree.map(
        lambda a, b, c, d: (a + 2.0 * b + 2.0 * c + d) * (1.0 / 6.0), k1, k2, k3, k4
    )
    return with_i(_axpy(dt, incr, state), i_full)


def equilibrium_state(
    params: PlantParams,
    *,
    theta_l: Float[ArrayLike, " ..."] = 0.0,
    load_torque: Float[ArrayLike, " ..."] = 0.0,
    temperature: Float[ArrayLike, " ..."] | None = None,
) -> PlantState:
    r"""The state at rest holding a constant `load_torque` with the link at `theta_l`.

    Statics: $T_J = -\tau_{load}$, $K_t i = T_J/N$ (friction is zero at rest), virgin hysteresis
    $z = 0$, and the deflection solves $T_J(d) = -\tau_{load}$ by Newton steps (the kinematic
    error depends on $\theta_m$, stiffening and the thermal offset make the map implicit).
    """
    if temperature is None:
        thermal = _one(params, "temperature")
        temperature = params.effects[thermal].initial if thermal is not None else 25.0
    temperature = _f64(temperature)
    theta_l = _f64(theta_l)
    t_j = -_f64(load_torque)
    zero = jnp.zeros_like(t_j)

    def at(d):
        return PlantState(
            params.ratio * (theta_l + d),
            zero,
            theta_l + zero,
            zero,
            t_j / (params.ratio * params.torque_constant),
            zero,
            temperature + zero,
        )

    residual = lambda d: flexspline_torque(params, at(d)) - t_j

    def newton(_, d):
        r, slope = jax.jvp(residual, (d,), (jnp.ones_like(d),))
        return d - r / slope

    d = jax.lax.fori_loop(0, 6, newton, compliance_deflection(params, t_j, temperature))
    return at(d)
