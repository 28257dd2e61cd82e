r"""Hybrid and joint fits: compliance model, network and plant parameters in one pytree.

One model, [`hdjax.fit.HybridModel`][], estimates the output torque as

$$\hat T = T_c(x_c;\ \Delta\theta, I, \theta, \omega) + g_w\big(\mathrm{Input},\ T_d(p)\big)$$

- $T_c$: the compliance model of Song et al. eq. (10) inverted for torque (eqs. (26)-(27)), with
  coefficients $x_c = x_c^{(0)} + |x_c^{(0)}| \odot \delta$ (relative corrections $\delta$ from
  a closed-form start, so one learning rate suits coefficients of $10^{-6}$ and of $10^{-2}$);
- $g_w$: the network of Section III (sigmoid hidden layers) on the paper's input vector, fitted
  to the residual of $T_c$ (variant (b)) or to the torque alone (variant (a), no $T_c$);
- $T_d(p) = N (K_t I + J_M \alpha_m + F_m(\omega_m))$: the motor-side equation of the plant
  ([`hdjax.plant`][], $J_M\dot\omega_m = K_t i - F_m(\omega_m) - T_J/N$, in the recordings' angle
  convention), whose parameters $p$ (torque constant, rotor inertia, Coulomb and viscous motor
  friction) are fitted as log-multipliers of the plant's values and fed to the network as one
  more input (variant (c)).

The network may also read the dynamic inputs of [`hdjax.fit.hybrid_inputs`][] (the twist rate
and Dahl memory states of the twist), which carry the structural damping and the hysteresis of
the joint when it rings.

All three sets of parameters sit in one pytree and are fitted by one loss, the mean squared torque
error divided by the torque variance, with `optax` (Adam, minibatches, one `lax.scan`) or with
`optimistix` Levenberg-Marquardt on the residual vector.
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from .._custom_types import Array, Float, PRNGKeyArray
from .._errors import ConfigError, DataError, DivergenceError, ModelMismatchError
from .._solution import RESULTS, Solution
from ..compliance import ComplianceModel, estimate_torque_arrays
from ..network import FeatureLayout, Network, standardise
from ..plant import PlantParams, motor_friction
from ._inputs import HybridInputs

PLANT_FIELDS = ("torque_constant", "inertia_m", "coulomb_m", "viscous_m")
"""Plant parameters fitted in variant (c), each as a log-multiplier of its preset value."""


class HybridModel(eqx.Module):
    r"""Compliance model + network + motor-side plant parameters (see the module docstring).

    Build with [`hdjax.fit.make_hybrid`][]. Trainable leaves: `coef_delta`, the network's
    weights and biases, `plant_log`.
    """

    compliance: ComplianceModel | None
    coef_delta: Float[Array, " n_coef"]
    coef_scale: Float[Array, " n_coef"]
    network: Network | None
    plant: PlantParams | None
    plant_log: Float[Array, " n_plant"]
    ratio: float = eqx.field(static=True)
    rated_torque: float = eqx.field(static=True)

    @property
    def fitted_compliance(self) -> ComplianceModel | None:
        """The compliance model with the fitted coefficients."""
        if self.compliance is None:
            return None
        coef = self.compliance.coef + self.coef_scale * self.coef_delta
        return eqx.tree_at(lambda m: m.coef, self.compliance, coef)

    def motor_torque(self, inp: HybridInputs) -> Float[Array, " n"]:
        r"""$T_d = N(K_t I + J_M\alpha_m + F_m(\omega_m))$ with the fitted plant parameters."""
        m = jnp.exp(self.plant_log)
        p = self.plant
        p = eqx.tree_at(
            lambda q: (
                q.torque_constant,
                q.inertia_m,
                q.effects["coulomb_m"].level,
                q.effects["viscous_m"].coefficient,
            ),
            p,
            (
                p.torque_constant * m[0],
                p.inertia_m * m[1],
                p.effects["coulomb_m"].level * m[2],
                p.effects["viscous_m"].coefficient * m[3],
            ),
        )
        fric = motor_friction(p, inp.omega_m)
        return self.ratio * (p.torque_constant * inp.current + p.inertia_m * inp.alpha_m + fric)

    def network_input(self, inp: HybridInputs) -> Float[Array, "n n_in"]:
        """The network's input rows: the features, and the motor torque when the plant is in."""
        if self.plant is None:
            return inp.x
        return jnp.concatenate([inp.x, self.motor_torque(inp)[:, None]], axis=1)

    def __call__(self, inp: HybridInputs) -> Float[Array, " n"]:
        """Torque estimate [N·m] for every row of `inp`."""
        tau = jnp.zeros(inp.x.shape[0], jnp.float64)
        if self.compliance is not None:
            tau = tau + estimate_torque_arrays(self.fitted_compliance, inp.sig)
        if self.network is not None:
            tau = tau + self.network(self.network_input(inp))
        return tau


def make_hybrid(
    inputs: HybridInputs,
    *,
    compliance: ComplianceModel | None = None,
    hidden: tuple[int, ...] | None = (16,),
    plant: PlantParams | None = None,
    key: PRNGKeyArray,
) -> HybridModel:
    """Build a hybrid model: variant (a) `compliance=None`; (b) a calibrated compliance model
    and a network on its residual; (c) also `plant` (a [`hdjax.plant.PlantParams`][] with
    `coulomb_m` and `viscous_m` on).

    The network's normalisation is set from `inputs` (target: the residual of the compliance
    model), and its output layer starts at zero so the hybrid starts at the compliance estimate.
    """
    if compliance is None and hidden is None:
        raise ConfigError("a hybrid model needs a compliance model, a network or both")
    if plant is not None:
        for name in ("coulomb_m", "viscous_m"):
            if not plant.has(name):
                raise ConfigError(f"plant parameters for variant (c) need the effect {name!r} on")
        if hidden is None:
            raise ConfigError("plant parameters enter through the network: give hidden widths")
    n_coef = 0 if compliance is None else compliance.n_coef
    if compliance is not None:
        act = np.asarray(compliance.active, bool)
        scale = np.where(act, np.abs(np.asarray(compliance.coef)), 0.0)
        floor = 1e-3 * scale[act].max() if act.any() else 0.0
        scale = np.where(act, np.maximum(scale, floor), 0.0)
    else:
        scale = np.zeros(0)
    model = HybridModel(
        compliance=compliance,
        coef_delta=jnp.zeros(n_coef, jnp.float64),
        coef_scale=jnp.asarray(scale, jnp.float64),
        network=None,
        plant=plant,
        plant_log=jnp.zeros(len(PLANT_FIELDS), jnp.float64),
        ratio=float(plant.ratio) if plant is not None else 1.0,
        rated_torque=float(plant.rated_torque) if plant is not None else 1.0,
    )
    if hidden is not None:
        names = inputs.layout.names + (("motor_torque",) if plant is not None else ())
        layout = FeatureLayout(
            names, inputs.layout.periodic, inputs.layout.orders, inputs.layout.kalman
        )
        net = Network(layout, hidden, key=key)
        target = np.asarray(inputs.torque) - np.asarray(model(inputs))
        net = standardise(net, np.asarray(model.network_input(inputs)), target)
        net = eqx.tree_at(
            lambda n: (n.weights[-1], n.biases[-1]),
            net,
            (jnp.zeros_like(net.weights[-1]), jnp.zeros_like(net.biases[-1])),
        )
        model = _replace(model, network=net)
    return model


def _replace(model: HybridModel, **changes) -> HybridModel:
    d = {f: getattr(model, f) for f in model.__dataclass_fields__}
    d.update(changes)
    return HybridModel(**d)


def _trainable_spec(model: HybridModel, *, compliance: bool, network: bool, plant: bool):
    spec = jax.tree.map(lambda _: False, model)
    spec = eqx.tree_at(lambda m: m.coef_delta, spec, compliance and model.compliance is not None)
    spec = eqx.tree_at(lambda m: m.plant_log, spec, plant and model.plant is not None)
    if model.network is not None and network:
        spec = eqx.tree_at(
            lambda m: (m.network.weights, m.network.biases),
            spec,
            (
                tuple(True for _ in model.network.weights),
                tuple(True for _ in model.network.biases),
            ),
        )
    return spec


@eqx.filter_jit
def _adam_fit(dyn, static, inp, var, key, lr, steps: int, batch: int | None):
    opt = optax.adam(optax.cosine_decay_schedule(lr, steps, 0.01))
    n = inp.x.shape[0]

    def loss(d, sub):
        model = eqx.combine(d, static)
        return jnp.mean((model(sub) - sub.torque) ** 2) / var

    def _step(carry, k):
        d, state = carry
        sub = inp if batch is None else inp.take(jax.random.randint(k, (batch,), 0, n))
        value, g = eqx.filter_value_and_grad(loss)(d, sub)
        updates, state = opt.update(g, state, d)
        return (eqx.apply_updates(d, updates), state), value

    keys = jax.random.split(key, steps)
    (dyn, _), hist = jax.lax.scan(_step, (dyn, opt.init(dyn)), keys)
    return dyn, hist


def fit_hybrid(
    model: HybridModel,
    inputs: HybridInputs,
    *,
    method: str = "adam",
    steps: int = 2000,
    learning_rate: float = 3e-3,
    batch_size: int | None = 512,
    key: PRNGKeyArray,
    train_compliance: bool = True,
    train_network: bool = True,
    train_plant: bool = True,
) -> Solution:
    """Fit all trainable parameters of a hybrid model jointly, with one loss.

    **Arguments:**

    - `model`: from [`hdjax.fit.make_hybrid`][].
    - `inputs`: [`hdjax.fit.HybridInputs`][] with a reference torque.
    - `method`: `"adam"` (optax, minibatches of `batch_size`, cosine-decayed rate) or
      `"levenberg_marquardt"` (optimistix on the residual vector of all samples; keep
      `inputs` to a few thousand rows).
    - `steps`, `learning_rate`, `batch_size`: optimiser settings.
    - `key`: PRNG key for minibatches (keyword-only).
    - `train_compliance`, `train_network`, `train_plant`: which parameter groups move.

    **Returns:** an [`hdjax.Solution`][] whose `value` is the fitted model; `stats` holds the
    loss `history` (one entry per Adam step; the final loss for Levenberg-Marquardt), the final
    `loss`, `steps`, `method` and `fit_time_s`. The result is `RESULTS.max_steps_reached` when
    Levenberg-Marquardt stopped at `steps` before its tolerance.

    **Raises:** [`hdjax.DivergenceError`][] naming the learning rate if the loss becomes
    non-finite.
    """
    check_inputs(model, inputs)
    if inputs.torque is None:
        raise DataError("fit_hybrid needs inputs with a reference torque")
    if method not in ("adam", "levenberg_marquardt"):
        raise ConfigError(f"unknown method {method!r}; use 'adam' or 'levenberg_marquardt'")
    y = np.asarray(inputs.torque)
    if not np.isfinite(y).all() or not np.isfinite(np.asarray(inputs.x)).all():
        raise DataError("fit_hybrid: inputs or torque contain NaN/inf")
    var = float(np.var(y))
    if not var > 0:
        raise DataError("fit_hybrid: the reference torque has zero variance")
    spec = _trainable_spec(
        model, compliance=train_compliance, network=train_network, plant=train_plant
    )
    dyn, static = eqx.partition(model, spec)
    t0 = time.perf_counter()
    result = RESULTS.successful
    with jax.numpy_dtype_promotion("standard"):
        if method == "adam":
            batch = None if batch_size is None or batch_size >= inputs.n_samples else batch_size
            dyn, hist = _adam_fit(
                dyn, static, inputs, var, key, jnp.asarray(learning_rate), int(steps), batch
            )
            hist = jax.block_until_ready(hist)
            n_steps = int(steps)
        else:

            def resid(d, _):
                return (eqx.combine(d, static)(inputs) - inputs.torque) / np.sqrt(var)

            sol = optx.least_squares(
                resid,
                optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8),
                dyn,
                max_steps=int(steps),
                throw=False,
            )
            dyn = sol.value
            r = resid(dyn, None)
            hist = jnp.asarray([jnp.mean(r * r)])
            n_steps = int(sol.stats["num_steps"])
            if sol.result != optx.RESULTS.successful:
                result = RESULTS.max_steps_reached
    fitted = eqx.combine(dyn, static)
    last = float(hist[-1])
    if not np.isfinite(last):
        raise DivergenceError(
            f"hybrid fit by {method} diverged (loss {last}); the learning rate {learning_rate:g} "
            f"is too large; try {learning_rate / 10:g}"
        )
    stats = dict(
        history=hist, loss=last, steps=n_steps, method=method, fit_time_s=time.perf_counter() - t0
    )
    return Solution(fitted, result, stats)


def check_inputs(model: HybridModel, inputs: HybridInputs) -> None:
    """Raise [`hdjax.ModelMismatchError`][] when `inputs` were built differently from the
    inputs the model was made with (network columns, compliance signals)."""
    if not isinstance(inputs, HybridInputs):
        raise ModelMismatchError(
            f"expected hdjax.fit.HybridInputs (from hdjax.fit.hybrid_inputs), got "
            f"{type(inputs).__name__}"
        )
    if model.compliance is not None and inputs.sig is None:
        raise ModelMismatchError(
            "the model has a compliance part but the inputs carry no compliance signals; build "
            "them with hybrid_inputs(..., compliance=model.compliance)"
        )
    if model.network is not None:
        names = model.network.layout.names
        if model.plant is not None:
            names = names[:-1]  # the motor torque is computed by the model
        if inputs.layout.names != names or inputs.layout.kalman != model.network.layout.kalman:
            raise ModelMismatchError(
                f"the inputs have network columns {list(inputs.layout.names)} but the model was "
                f"made with {list(names)}; build them with the same hybrid_inputs options "
                "(periodic, kalman, twist_rate, hysteresis)"
            )


@eqx.filter_jit
def _predict(model: HybridModel, inputs: HybridInputs):
    return model(inputs)


def predict_hybrid(model: HybridModel, inputs: HybridInputs) -> Float[Array, " n"]:
    """Torque estimates [N·m] of a hybrid model for every row of `inputs` (jitted).

    The compliance part is inverted for torque as Song et al. eqs. (26)-(27), the network is
    evaluated as eqs. (36)-(41). Refuses inputs built with other options than the model's (see
    [`hdjax.fit.check_inputs`][]).
    """
    check_inputs(model, inputs)
    return _predict(model, inputs)
