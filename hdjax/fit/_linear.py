r"""Gradient fitting of the linear-in-parameters compliance model, against closed-form LS.

The compliance model of Song et al. eq. (10) is linear in its coefficients, $\Delta\theta = A x$,
so eq. (16) $f(x) = \lVert Ax - b\rVert^2$ is a quadratic with the closed-form minimiser of
eq. (17). Every gradient method here minimises the same objective, written as one loss over
one parameter pytree, and must land on that minimiser: a check that loss, parametrisation and
solvers are consistent before they are used where no closed form exists (the hybrid and joint
fits of [`hdjax.fit.fit_hybrid`][]).

Parametrisation: the coefficients the data can calibrate (those
[`hdjax.compliance.calibrate_lstsq`][] keeps) are fitted in column-scaled coordinates
$u = D x$ with $D$ the RMS of each design column, and the twist is divided by its RMS, so the
loss $L(u) = \mathrm{mean}((A D^{-1} u - b)^2) / \mathrm{mean}(b^2)$ is of order one.

Solvers:

- `"gauss_newton"`, `"levenberg_marquardt"`: `optimistix.least_squares` on the residual vector.
  On a linear residual Gauss-Newton is exact after one step; Levenberg-Marquardt approaches it
  as its damping shrinks.
- `"adam"`: `optax.adam` with an exponentially decaying rate inside one `lax.scan`. Even after
  column scaling the paper's per-segment design has a condition number near $10^7$, where a
  first-order method would need millions of steps to reach $10^{-6}$ relative accuracy
  (measured: 50,000 steps leave a relative loss excess of 0.2). With `whiten=True` (the default)
  Adam therefore runs on whitened coordinates $u = (R/\sqrt{n})^{-1} v$, $R$ the triangular QR
  factor of the scaled design: a fixed linear preconditioner, the same one a careful practitioner
  applies to any ill-conditioned regression, after which the loss Hessian is the identity.
  `whiten=False` shows what plain Adam reaches.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from .._custom_types import Array, ArrayLike, Bool, Float, Real
from .._errors import CalibrationError, ConfigError, DataError
from .._features import signals
from .._recording import Recording
from .._solution import RESULTS, Solution
from ..compliance import ComplianceModel
from ..compliance.internal import select_active

METHODS = ("gauss_newton", "levenberg_marquardt", "adam")


class LinearProblem(eqx.Module):
    """The scaled least-squares problem of eq. (16) for the active coefficients.

    **Fields:** `a` (scaled design, `(n, p)`), `b` (scaled twist), `col_scale` ($D$),
    `b_scale`, `active` (mask over the model's coefficients).
    """

    a: Float[Array, "n n_active"]
    b: Float[Array, " n"]
    col_scale: Float[Array, " n_active"]
    b_scale: Float[Array, ""]
    active: tuple[bool, ...] = eqx.field(static=True)

    def loss(self, u: Float[Array, " n_active"]) -> Float[Array, ""]:
        r"""$L(u) = \mathrm{mean}((A D^{-1} u - b)^2)/\mathrm{mean}(b^2)$ in scaled units."""
        return jnp.mean((self.a @ u - self.b) ** 2)

    def to_coef(
        self, u: Float[ArrayLike, " n_active"], n_coef: int
    ) -> Float[np.ndarray, " n_coef"]:
        coef = np.zeros(n_coef)
        coef[np.asarray(self.active)] = (
            np.asarray(u) / np.asarray(self.col_scale) * float(self.b_scale)
        )
        return coef

    def to_u(self, coef: Real[ArrayLike, " n_coef"]) -> Float[Array, " n_active"]:
        c = jnp.asarray(np.asarray(coef)[np.asarray(self.active)])
        return c * self.col_scale / self.b_scale


def linear_problem(
    model: ComplianceModel,
    recording: Recording,
    active: Bool[ArrayLike, " n_coef"] | Sequence[bool] | None = None,
) -> LinearProblem:
    """Build the scaled problem of eq. (16) from a compliance model and a recording.

    `active` (mask) defaults to the coefficients [`hdjax.compliance.calibrate_lstsq`][] would
    calibrate on this recording.
    """
    if not isinstance(recording, Recording) or recording.torque is None:
        raise DataError("gradient calibration needs a Recording with a reference torque")
    sig = signals(recording, model.joint, velocity=model.velocity)
    a = np.asarray(model.design(sig, recording.torque))
    if active is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            active, _, _ = select_active(model, a, np.asarray(recording.torque))
    active = np.asarray(active, bool)
    a = a[:, active]
    col = np.sqrt(np.mean(a * a, axis=0))
    if (col == 0).any():
        raise CalibrationError("a design column is zero over the data; it cannot be fitted")
    b = np.asarray(sig.twist)
    b_scale = float(np.sqrt(np.mean(b * b)))
    return LinearProblem(
        a=jnp.asarray(a / col),
        b=jnp.asarray(b / b_scale),
        col_scale=jnp.asarray(col),
        b_scale=jnp.asarray(b_scale),
        active=tuple(bool(x) for x in active),
    )


@eqx.filter_jit
def _adam(problem: LinearProblem, w, lr, steps: int, floor: float):
    opt = optax.adam(optax.exponential_decay(lr, steps, floor))
    loss = lambda v: problem.loss(w @ v)
    v0 = jnp.zeros(problem.a.shape[1], problem.a.dtype)

    def _step(carry, _):
        v, state = carry
        g = jax.grad(loss)(v)
        updates, state = opt.update(g, state, v)
        return (optax.apply_updates(v, updates), state), None

    (v, _), _ = jax.lax.scan(_step, (v0, opt.init(v0)), None, length=steps)
    return w @ v


def fit_compliance_gradient(
    model: ComplianceModel,
    recording: Recording,
    *,
    method: str,
    steps: int = 4000,
    learning_rate: float = 0.05,
    whiten: bool = True,
    rtol: float = 1e-12,
) -> Solution:
    """Calibrate a compliance model by a gradient method instead of eq. (17).

    **Arguments:**

    - `model`: a [`hdjax.compliance.ComplianceModel`][] (its coefficients are the start).
    - `recording`: a [`hdjax.Recording`][] with reference torque.
    - `method`: `"gauss_newton"`, `"levenberg_marquardt"` or `"adam"` (see the module docstring).
    - `steps`: maximum steps (Adam runs exactly this many).
    - `learning_rate`: Adam's initial rate (decays by $10^{-4}$ over `steps`).
    - `whiten`: precondition Adam by the design's triangular factor (see the module docstring).
    - `rtol`: relative/absolute tolerance of the optimistix solvers.

    **Returns:** an [`hdjax.Solution`][] whose `value` is the calibrated model; `stats` holds
    the final `loss` (scaled units), `steps`, `method` and `fit_time_s`. The result is
    `RESULTS.max_steps_reached` when an optimistix solver stopped at `steps` before its
    tolerance, `RESULTS.nonfinite` when the loss is not finite.
    """
    if method not in METHODS:
        raise ConfigError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    t0 = time.perf_counter()
    prob = linear_problem(model, recording)
    n, p = prob.a.shape
    u0 = prob.to_u(model.coef)
    result = RESULTS.successful
    if method == "adam":
        if whiten:
            _, r = jnp.linalg.qr(prob.a, mode="reduced")
            w = jax.scipy.linalg.solve_triangular(r / np.sqrt(n), jnp.eye(p), lower=False)
        else:
            w = jnp.eye(p)
        # optax mixes Python floats with int32 step counts; allow that under strict promotion.
        with jax.numpy_dtype_promotion("standard"):
            u = _adam(prob, w, jnp.asarray(learning_rate, jnp.float64), int(steps), 1e-4)
        n_steps = int(steps)
    else:
        solver_cls = optx.GaussNewton if method == "gauss_newton" else optx.LevenbergMarquardt
        solver = solver_cls(rtol=rtol, atol=rtol)
        sol = optx.least_squares(
            lambda u, _: prob.a @ u - prob.b, solver, u0, max_steps=int(steps), throw=False
        )
        u, n_steps = sol.value, int(sol.stats["num_steps"])
        if sol.result != optx.RESULTS.successful:
            result = RESULTS.max_steps_reached
    u = jax.block_until_ready(u)
    loss = float(prob.loss(u))
    coef = prob.to_coef(u, model.n_coef)
    fitted = eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))
    if not np.isfinite(loss):
        result = RESULTS.nonfinite
    stats = dict(loss=loss, steps=n_steps, method=method, fit_time_s=time.perf_counter() - t0)
    return Solution(_with_active(fitted, prob.active), result, stats)


def _with_active(model, active):
    d = {f: getattr(model, f) for f in model.__dataclass_fields__}
    d["active"] = tuple(active)
    return type(model)(**d)
