r"""The scalar Kalman filter on the motor current, Song et al. (2019) eqs. (29)-(35), Fig. 4.

The paper writes the current as a one-dimensional linear system with $F = B = H = 1$ (eqs.
(29)-(30)): a random walk $X(k) = X(k-1) + W(k-1)$ observed as $Z(k) = X(k) + V(k)$. It gives
the variance of the process noise $W$ as $Q = 0.05$ and that of the measurement noise $V$ as
$R = 0.25$ ("according to the motor driver manual"), the initial covariance as $P_0 = 0.01$,
the raw current every 0.5 ms and the filtered output every 20 ms.

**The names of the two variances swap between the two halves of the paper.** Eqs. (29)-(30)
follow the control-engineering convention (Q for the process, R for the measurement), but
eqs. (31)-(35) are copied from Thrun et al., *Probabilistic Robotics*, where $R_t$ is the
*process* noise covariance (added in the prediction, eq. (32)) and $Q_t$ the *measurement* noise
covariance (in the gain, eq. (33)). Read literally, eqs. (31)-(35) with the paper's $Q = 0.05$,
$R = 0.25$ would use 0.25 as the process noise and 0.05 as the measurement noise.

We implement the reading of the text around eqs. (29)-(30), which is the physical one: process
noise variance `q = 0.05` enters the prediction (the role of $R_t$ in eq. (32)) and measurement
noise variance `r = 0.25` enters the gain (the role of $Q_t$ in eq. (33)). Only this reading
reproduces Fig. 5: its steady-state gain is $K_\infty \approx 0.358$, so white measurement noise
leaves the filter with a standard deviation of $\sqrt{K_\infty / (2 - K_\infty)} \approx 0.47$ of
its input ("the fluctuation amplitude reduced by half"); the literal reading of eqs. (31)-(35)
gives $K_\infty \approx 0.85$ and a reduction to only $\approx 0.86$.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float, Real
from .._errors import ConfigError, DataError
from .._recording import Recording

PAPER_Q = 0.05
"""Process-noise variance of the current random walk (Song et al. text after eq. (30))."""
PAPER_R = 0.25
"""Measurement-noise variance of the driver's current (Song et al., from the driver manual)."""
PAPER_P0 = 0.01
"""Initial state covariance (Song et al.)."""
PAPER_RAW_PERIOD = 0.5e-3
"""Feedback period of the raw current [s] (Song et al.)."""
PAPER_OUTPUT_PERIOD = 20e-3
"""Period at which the filtered current is handed on [s] (Song et al.)."""


def steady_state_gain(q: float = PAPER_Q, r: float = PAPER_R) -> float:
    r"""Steady-state Kalman gain $K_\infty$ of the scalar random-walk filter.

    The predicted covariance solves $\bar P^2 - q \bar P - q r = 0$, so
    $\bar P = (q + \sqrt{q^2 + 4 q r}) / 2$ and $K_\infty = \bar P / (\bar P + r)$.
    """
    _check_variances(q, r, 1.0)
    p_pred = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    return p_pred / (p_pred + r)


def white_noise_std_ratio(q: float = PAPER_Q, r: float = PAPER_R) -> float:
    r"""Std of the filter's output over the std of white input noise, in steady state.

    The steady filter is $x_k = (1-K)x_{k-1} + K z_k$, whose noise gain is $\sqrt{K/(2-K)}$.
    """
    k = steady_state_gain(q, r)
    return math.sqrt(k / (2.0 - k))


def _check_variances(q, r, p0) -> None:
    for name, value in (("q", q), ("r", r), ("p0", p0)):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"Kalman filter {name} must be a number, got {value!r}")
        if not math.isfinite(value) or value <= 0:
            raise ConfigError(
                f"Kalman filter {name} must be a positive finite variance, got {value!r}"
            )


@eqx.filter_jit
def _kalman_scan(z, x0, q, r, p0):
    def _step(carry, z_t):
        mu, sigma = carry
        # Predict (eqs. (31)-(32) with A = B = 1, no control): the random walk only grows P.
        mu_bar = mu
        sigma_bar = sigma + q
        # Gain (eq. (33), C = 1): measurement-noise variance r.
        gain = sigma_bar / (sigma_bar + r)
        # Update (eqs. (34)-(35)).
        mu = mu_bar + gain * (z_t - mu_bar)
        sigma = (1.0 - gain) * sigma_bar
        return (mu, sigma), (mu, sigma)

    _, (mu, sigma) = jax.lax.scan(_step, (x0, p0), z)
    return mu, sigma


def kalman_filter(
    z: Real[ArrayLike, " n"],
    *,
    q: float = PAPER_Q,
    r: float = PAPER_R,
    p0: float = PAPER_P0,
    x0: float | None = None,
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    r"""Scalar random-walk Kalman filter over a signal, Song et al. eqs. (29)-(35).

    One `lax.scan` step per raw sample: predict $\bar\mu = \mu$, $\bar\Sigma = \Sigma + q$; gain
    $K = \bar\Sigma / (\bar\Sigma + r)$; update $\mu = \bar\mu + K(z - \bar\mu)$,
    $\Sigma = (1 - K)\bar\Sigma$. See the module docstring for which variance is which.

    **Arguments:**

    - `z`: the raw measurements, shape `(n,)`.
    - `q`: process-noise variance (the paper's $Q$ of eq. (29), playing $R_t$ in eq. (32)).
    - `r`: measurement-noise variance (the paper's $R$ of eq. (30), playing $Q_t$ in eq. (33)).
    - `p0`: initial covariance $\Sigma_0$.
    - `x0`: initial mean; the first measurement when `None`.

    **Returns:** `(mean, covariance)`, each of shape `(n,)`, the posterior after each sample.
    """
    _check_variances(q, r, p0)
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 1 or z.shape[0] < 1:
        raise DataError(f"Kalman filter input must be 1-D and non-empty, got shape {z.shape}")
    if not np.isfinite(z).all():
        first = int(np.flatnonzero(~np.isfinite(z))[0])
        raise DataError(f"Kalman filter input has NaN/inf, first at sample {first}")
    x0 = float(z[0]) if x0 is None else float(x0)
    f64 = lambda v: jnp.asarray(v, jnp.float64)
    return _kalman_scan(f64(z), f64(x0), f64(q), f64(r), f64(p0))


def filter_current(
    recording: Recording,
    *,
    q: float = PAPER_Q,
    r: float = PAPER_R,
    p0: float = PAPER_P0,
    output_period: float | None = PAPER_OUTPUT_PERIOD,
) -> Recording:
    r"""The recording with its `current` replaced by the Kalman-filtered current (Fig. 4).

    The filter runs on every raw sample (the paper's driver feeds back every 0.5 ms). With
    `output_period` (the paper's 20 ms) the filtered value is handed on only every
    `output_period` seconds and held in between, as a controller polling the filter would see
    it; `None` hands on every sample. The raw current is kept as the extra column
    `current_raw`.

    **Arguments:**

    - `recording`: the [`hdjax.Recording`][] to filter.
    - `q`, `r`, `p0`: see [`hdjax.network.kalman_filter`][].
    - `output_period`: hold period of the output [s], or `None`.

    **Returns:** a new `Recording`.
    """
    mean, _ = kalman_filter(recording.current, q=q, r=r, p0=p0)
    if output_period is not None:
        if not output_period > 0:
            raise ConfigError(f"output_period must be positive or None, got {output_period!r}")
        t = np.asarray(recording.t)
        # Index of the last sample at or before each output instant, held until the next one.
        slot = np.floor((t - t[0]) / output_period + 1e-9).astype(np.int64)
        first_in_slot = np.concatenate([[0], np.flatnonzero(np.diff(slot)) + 1])
        held = np.repeat(first_in_slot, np.diff(np.concatenate([first_in_slot, [t.size]])))
        mean = jnp.asarray(np.asarray(mean)[held])
    out = eqx.tree_at(lambda rec: rec.current, recording, mean)
    return out.with_extras(current_raw=recording.current)
