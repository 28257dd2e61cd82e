r"""The force/torque sensor's offset: from a rest window, or fitted as a constant.

A strain-gauge sensor reads a constant offset $w_0$ (drift since it was last zeroed) on top of
the wrench applied to it. Two ways to estimate it:

- **rest window** (`offset = "rest"`): $w_0$ is the mean of the fresh readings in a time
  window in which nothing but the offset acts on the sensor (no tool load, or a tool whose
  load you mean to zero out). Valid only when that is true of the window.
- **fitted constant** (`offset = "fit"`): the readings are modelled as the offset plus the
  static wrench of an unknown rigid payload (mass $m$, centre of mass $c$ in the sensor frame)
  under gravity $g$ (base frame):

  $$F = f_0 + m\,g_s,\qquad M = m_0 + c \times m\,g_s = m_0 - [g_s]_\times (m c),\qquad
  g_s = R(q)^\top g,$$

  linear in $(f_0, m_0, m, mc)$ and solved by least squares over all fresh rows. The poses
  must turn gravity through at least two directions in the sensor frame, or the offset and
  the payload cannot be told apart (refused). Inertial forces of the payload are neglected
  (slow motions). A negative $m$ means the sensor reports the wrench it applies to the
  payload rather than the payload's on it. This is the usual payload identification for
  wrist sensors (Kubus, Kröger and Wahl, ICRA 2008, eq. (6), static part).

The offset is always reported, with how it was obtained.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from .._custom_types import ArrayLike, Float, Real
from .._errors import CalibrationError, DataError


@dataclasses.dataclass(frozen=True)
class SensorOffset:
    r"""An estimated sensor offset and how it was obtained.

    **Fields:** `method` (`"none"`, `"rest"` or `"fit"`), `wrench` (the offset $w_0$, shape
    `(6,)`, N and N·m), `n_samples` (readings used); for `"fit"` also `mass` [kg], `com` [m],
    `residual_rms` (per channel, of the fitted model) and `stderr` (standard errors of the
    offset, from the residual variance of each channel, assuming independent residuals: with
    structured residuals (unmodelled dynamics) the real uncertainty is larger); `window` for
    `"rest"`.
    """

    method: str
    wrench: Float[np.ndarray, " 6"]
    n_samples: int = 0
    mass: float | None = None
    com: Float[np.ndarray, " 3"] | None = None
    residual_rms: Float[np.ndarray, " 6"] | None = None
    window: tuple[float, float] | None = None
    stderr: Float[np.ndarray, " 6"] | None = None

    def describe(self) -> str:
        if self.method == "none":
            return "no sensor offset removed"
        w = ", ".join(f"{v:.3g}" for v in self.wrench)
        text = f"sensor offset [{w}] (N, N·m) removed, "
        if self.method == "rest":
            lo, hi = self.window
            return text + f"mean of {self.n_samples} fresh readings at rest in {lo:g}..{hi:g} s"
        res = ", ".join(f"{v:.3g}" for v in self.residual_rms)
        se = ", ".join(f"{v:.2g}" for v in self.stderr)
        com = ", ".join(f"{1e3 * v:.1f}" for v in self.com)
        return text + (
            f"fitted with a payload of {self.mass:.3g} kg at [{com}] mm (sensor frame) over "
            f"{self.n_samples} fresh readings; standard errors [{se}]; residual RMS per channel "
            f"[{res}]"
        )

    def as_dict(self) -> dict:
        out = {"method": self.method, "wrench": [float(v) for v in self.wrench]}
        out["n_samples"] = self.n_samples
        if self.mass is not None:
            out["payload_mass_kg"] = self.mass
            out["payload_com_m"] = [float(v) for v in self.com]
            out["residual_rms"] = [float(v) for v in self.residual_rms]
            out["stderr"] = [float(v) for v in self.stderr]
        if self.window is not None:
            out["window_s"] = list(self.window)
        return out


def no_offset() -> SensorOffset:
    """The offset taken as zero."""
    return SensorOffset("none", np.zeros(6))


def offset_from_rest(
    wrench: Real[ArrayLike, "n_rows 6"], t: Real[ArrayLike, " n"], window: tuple[float, float]
) -> SensorOffset:
    """Mean of the readings with `window[0] <= t - t[0] <= window[1]` (module docstring).

    Pass only fresh rows (see [`hdjax.reference.detect_holds`][]) so that held repeats do
    not weigh the mean. **Raises:** [`hdjax.DataError`][] when fewer than 3 readings fall in
    the window.
    """
    w = np.asarray(wrench, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    rel = t - t[0]
    lo, hi = (float(v) for v in window)
    inside = (rel >= lo) & (rel <= hi)
    if inside.sum() < 3:
        raise DataError(
            f"the rest window {lo:g}..{hi:g} s (from the start) holds {int(inside.sum())} fresh "
            f"wrench readings; it needs at least 3 (the log spans {rel[-1]:.3g} s)"
        )
    return SensorOffset(
        "rest", w[inside].mean(axis=0), n_samples=int(inside.sum()), window=(lo, hi)
    )


def _skew(v: np.ndarray) -> np.ndarray:
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = np.zeros_like(x)
    return np.stack(
        [np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)],
        -2,
    )


def fit_offset_with_payload(
    wrench: Real[ArrayLike, "n 6"],
    rotations: Real[ArrayLike, "n 3 3"],
    gravity: Real[ArrayLike, " 3"] | Sequence[float] = (0.0, 0.0, -9.80665),
) -> SensorOffset:
    """Fit the offset and a payload's static wrench (module docstring) by least squares.

    **Arguments:** `wrench` `(n, 6)` in the sensor frame (fresh rows only), `rotations`
    `(n, 3, 3)` the sensor frame's base-frame orientation at each row, `gravity` (base frame).

    **Raises:** [`hdjax.CalibrationError`][] when the poses cannot separate offset and payload.
    """
    w = np.asarray(wrench, dtype=np.float64)
    rot = np.asarray(rotations, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 6 or rot.shape != (w.shape[0], 3, 3):
        raise DataError(
            f"expected wrench (n, 6) and rotations (n, 3, 3), got {w.shape}, {rot.shape}"
        )
    n = w.shape[0]
    g_s = np.einsum("nji,j->ni", rot, np.asarray(gravity, dtype=np.float64))
    design = np.zeros((n, 6, 10))
    design[:, :3, 0:3] = np.eye(3)
    design[:, 3:, 3:6] = np.eye(3)
    design[:, :3, 6] = g_s
    design[:, 3:, 7:10] = -_skew(g_s)
    a = design.reshape(6 * n, 10)
    b = w.reshape(6 * n)
    # Column scales differ (unit columns against g ~ 9.8): normalise before judging the rank.
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    x, _, rank, sv = np.linalg.lstsq(a / scale, b, rcond=None)
    if rank < 10 or sv[-1] < 1e-6 * sv[0]:
        raise CalibrationError(
            "the sensor offset cannot be fitted: the recorded poses do not turn gravity through "
            "two directions in the sensor frame, so offset and payload are confounded; use "
            'offset = "rest" with a window at rest, or offset = "none"'
        )
    x = x / scale
    resid = (b - a @ x).reshape(n, 6)
    # standard errors with one residual variance per channel (forces in N, moments in N·m):
    # cov = (A^T A)^-1 A^T S A (A^T A)^-1, S = diag of the channel variances, via QR of A
    sigma2 = np.sum(resid**2, axis=0) / max(1, n - 10 / 6)
    _, r = np.linalg.qr(a / scale)
    r_inv = np.linalg.inv(r)
    weighted = (a / scale) * np.sqrt(np.tile(sigma2, n))[:, None]
    middle = r_inv.T @ (weighted.T @ weighted) @ r_inv
    cov = r_inv @ middle @ r_inv.T
    stderr = np.sqrt(np.diag(cov)) / scale
    mass = float(x[6])
    com = x[7:10] / mass if abs(mass) > 1e-9 else np.full(3, np.nan)
    return SensorOffset(
        "fit",
        x[:6].copy(),
        n_samples=n,
        mass=mass,
        com=com,
        residual_rms=np.sqrt(np.mean(resid**2, axis=0)),
        stderr=stderr[:6],
    )
