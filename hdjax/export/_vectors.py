"""Test vectors: inputs and the JAX estimate of them, for a build of the exported C code to be
checked against (`test_vectors.csv`, read by `hdjax_check.c`).

Without a recording of the user's, [`synthetic_recording`][] makes one that sweeps the
calibrated torque range: the twist is the model's flexspline compliance (eq. (7)) along a
torque path, so the estimate visits every segment, and the angles and current move the way a
joint's do.
"""

from __future__ import annotations

import numpy as np

from .._custom_types import Float, Shaped
from .._errors import ExportError
from .._io import csv_bytes
from .._joint import Joint
from .._recording import Recording, make_recording
from ..compliance import ComplianceModel, CurrentPolynomial, estimate_torque
from ..effects import Column
from ..network import Network, predict_torque

VECTOR_COLUMNS = ("t", "theta_m", "theta_l", "current")


def _extra_values(model: ComplianceModel | None, name: str, t: np.ndarray) -> np.ndarray:
    """An extra column that moves around the centre and scale the model's terms were given."""
    center, scale = 25.0, 1.0
    terms = () if model is None else model.base_terms + model.effect_terms
    for term in terms:
        if isinstance(term, Column) and term.name == name:
            center, scale = term.center, term.scale
    return center + scale * np.sin(2 * np.pi * 0.05 * (t - t[0]))


def synthetic_recording(
    joint: Joint,
    n: int,
    *,
    model: ComplianceModel | None = None,
    network: Network | None = None,
    extras: tuple[str, ...] = (),
    dt: float = 5e-4,
) -> Recording:
    r"""A recording that exercises an exported model: a torque path over the calibrated range.

    The torque is $0.95\,T_{max}\sin(2\pi f t)$ plus a slower ripple, the load angle a sway
    plus a drift (so both velocities change sign and the kinematic terms turn), the current
    the torque over the rated torque times the current polynomial's scale. With `model`, the
    twist is that of the model's flexspline compliance (eq. (7)) at the torque; with `network`,
    the inputs move within the training spread it stores.

    **Arguments:** `joint`; `n` samples every `dt` seconds; `model` or `network`; `extras`
    (extra columns to add, each moving around the centre and scale a `Column` term of the
    model gives it).

    **Returns:** an [`hdjax.Recording`][] without a torque column.
    """
    if n < 2:
        raise ExportError(f"test vectors need at least 2 samples, got {n}")
    t = np.arange(n) * dt
    phase = 2 * np.pi * t
    cols = {name: _extra_values(model, name, t) for name in extras}
    if network is not None:
        mean = dict(zip(network.layout.names, np.asarray(network.x_mean)))
        scale = dict(zip(network.layout.names, np.asarray(network.x_scale)))
        get = lambda k, d: (float(mean.get(k, d[0])), float(scale.get(k, d[1])))  # noqa: E731
        (ml, sl), (mt, st), (mc, sc) = (
            get("theta_l", (0.0, 0.5)),
            get("twist", (0.0, 1e-3)),
            get("current", (0.0, 1.0)),
        )
        theta_l = ml + sl * np.sin(0.25 * phase)
        twist = mt + st * np.sin(0.5 * phase + 0.3)
        theta_m = joint.ratio * (theta_l - joint.twist_sign * twist)
        current = mc + sc * np.sin(0.5 * phase + 0.3)
        return make_recording(t, theta_m, theta_l, current, None, cols, source="test vectors")
    if model is None:
        raise ExportError("synthetic_recording needs a model or a network")
    lo, hi = model.torque_range
    amp = 0.95 * max(abs(lo), abs(hi))
    torque = np.clip(amp * np.sin(0.5 * phase) + 0.05 * amp * np.sin(7.0 * phase), lo, hi)
    theta_l = 0.4 * np.sin(0.2 * phase) + 0.05 * t
    scale = next((tm.scale for tm in model.base_terms if isinstance(tm, CurrentPolynomial)), 1.0)
    current = torque / model.rated_torque * scale
    # the flexspline's twist of eq. (7) at that torque (the other terms only shift the estimate
    # a little; computed in NumPy, so that no program is compiled for it)
    k = np.asarray(model.k, np.float64)
    k = np.where(k > 0, k, np.max(k))  # a segment left out of the calibration: the stiffest
    twist = np.zeros(n)
    for (lo_j, hi_j), kj in zip(model.segment_bounds, k):
        twist += kj * (np.clip(torque, lo_j, hi_j) - min(max(0.0, lo_j), hi_j))
    theta_m = joint.ratio * (theta_l - joint.twist_sign * twist)
    return make_recording(t, theta_m, theta_l, current, None, cols, source="test vectors")


def expected(
    recording: Recording,
    joint: Joint,
    *,
    model: ComplianceModel | None = None,
    network: Network | None = None,
) -> tuple[Float[np.ndarray, " n"], Shaped[np.ndarray, " n"]]:
    """The JAX estimate the exported step must reproduce (`causal=True`): torque [N·m] and the
    `HDJAX_*` flags of each sample (compliance model: out of range, ambiguous, unresolved;
    network: the flags its step sets, computed here from the same rules)."""
    if model is not None:
        est = estimate_torque(model, recording, causal=True)
        flags = (
            (~np.asarray(est.in_range)).astype(np.uint32)
            | np.asarray(est.ambiguous).astype(np.uint32) * 2
            | np.asarray(est.unresolved).astype(np.uint32) * 4
        )
        return np.asarray(est.torque, np.float64), flags
    from ..network.internal import network_features

    torque = np.asarray(predict_torque(network, recording, joint, causal=True), np.float64)
    feats = network_features(network, recording, joint, causal=True)
    from ._network import INPUT_SIGMAS

    z = (np.asarray(feats.x) - np.asarray(network.x_mean)) / np.asarray(network.x_scale)
    outside = ~np.all(np.abs(z) <= INPUT_SIGMAS, axis=1)
    rated = joint.rated_torque
    flags = (~((torque >= -rated) & (torque <= rated))).astype(np.uint32) | outside * 8
    return torque, flags.astype(np.uint32)


def vectors_csv(
    recording: Recording, extras: tuple[str, ...], torque: np.ndarray, flags: np.ndarray
) -> bytes:
    """`test_vectors.csv`: the inputs of each sample (`t`, `theta_m`, `theta_l`, `current`,
    the extras in the order of the sample's `extra` array), the expected torque and flags, in
    full float64 precision."""
    cols = {name: np.asarray(getattr(recording, name)) for name in VECTOR_COLUMNS}
    for name in extras:
        if name not in recording.extras:
            raise ExportError(
                f"{recording.source}: the model reads the column {name!r}, which the recording "
                "for the test vectors lacks"
            )
        cols[f"extra:{name}"] = np.asarray(recording.extras[name])
    cols["torque_expected"] = torque
    cols["flags_expected"] = flags.astype(np.float64)
    return csv_bytes(cols)
