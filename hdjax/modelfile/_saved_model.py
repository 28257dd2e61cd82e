"""Saved models: a calibrated compliance model (and optionally a trained network) in one file.

The file is JSON (human-readable, float64 values written exactly with `repr`):

```json
{"format": "hdjax-model", "format_version": 1, "hdjax_version": "...",
 "joint": {...}, "units": {...}, "compliance": {...} | null, "network": {...} | null,
 "feature_layout": {"compliance": [...], "network": [...] | null}, "checksum": "sha256:..."}
```

The checksum covers everything else, so a truncated or edited file is refused rather than
half-read. Loading refuses a file of another format version; applying a model refuses data
whose joint ratio differs, or which lacks a column the model reads.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from .. import __version__
from .._custom_types import PathLike
from .._errors import DataError, ModelMismatchError
from .._io import atomic_write_bytes
from .._joint import Joint
from .._recording import Recording
from ..compliance import ComplianceModel
from ..network import FeatureLayout, Network

FORMAT = "hdjax-model"
FORMAT_VERSION = 1
UNITS = {
    "t": "s",
    "theta_m": "rad",
    "theta_l": "rad",
    "current": "A",
    "torque": "N·m",
    "twist": "rad",
}
_CORE_SIGNALS = ("twist", "current", "theta_m", "theta_l", "omega_m", "omega_l")


@dataclasses.dataclass(frozen=True)
class SavedModel:
    """What a model file holds.

    **Fields:** `joint` ([`hdjax.Joint`][]), `compliance` (a calibrated
    [`hdjax.compliance.ComplianceModel`][] or `None`), `network` (a trained
    [`hdjax.network.Network`][] or `None`), `units` (column -> unit), `meta` (free-form: seed,
    experiment name, version that wrote it).
    """

    joint: Joint
    compliance: object | None
    network: object | None
    units: dict
    meta: dict

    def columns_needed(self) -> tuple[str, ...]:
        """Extra (non-core) signals the compliance model reads, e.g. `temperature`."""
        if self.compliance is None:
            return ()
        out = []
        for term in self.compliance.base_terms + self.compliance.effect_terms:
            for name in (getattr(term, "name", None), getattr(term, "signal", None)):
                if name is not None and name not in _CORE_SIGNALS and name not in out:
                    out.append(name)
        return tuple(out)


def _checksum(payload: dict) -> str:
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


def _network_to_dict(net) -> dict:
    lay = net.layout
    return {
        "hidden": list(net.hidden),
        "layout": {
            "names": list(lay.names),
            "periodic": bool(lay.periodic),
            "orders": list(lay.orders),
            "kalman": bool(lay.kalman),
        },
        "weights": [np.asarray(w).tolist() for w in net.weights],
        "biases": [np.asarray(b).tolist() for b in net.biases],
        "x_mean": np.asarray(net.x_mean).tolist(),
        "x_scale": np.asarray(net.x_scale).tolist(),
        "y_mean": float(net.y_mean),
        "y_scale": float(net.y_scale),
    }


def _network_from_dict(d: dict):
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    lay = d["layout"]
    layout = FeatureLayout(
        tuple(lay["names"]), bool(lay["periodic"]), tuple(lay["orders"]), bool(lay["kalman"])
    )
    hidden = tuple(d["hidden"])
    # the structure only (traced, not compiled: drawing the initial weights would compile a
    # program per layer, seconds for a file read); every array is the stored one
    net = eqx.filter_eval_shape(lambda: Network(layout, hidden, key=jax.random.PRNGKey(0)))
    weights = tuple(jnp.asarray(w, jnp.float64) for w in d["weights"])
    biases = tuple(jnp.asarray(b, jnp.float64) for b in d["biases"])
    if [w.shape for w in weights] != [w.shape for w in net.weights] or [
        b.shape for b in biases
    ] != [b.shape for b in net.biases]:
        raise DataError("network weights do not match the stored layer widths")
    stats = [jnp.asarray(d[k], jnp.float64) for k in ("x_mean", "x_scale", "y_mean", "y_scale")]
    if stats[0].shape != net.x_mean.shape or stats[1].shape != net.x_scale.shape:
        raise DataError("network input statistics do not match the stored input layout")
    return eqx.tree_at(
        lambda n: (n.weights, n.biases, n.x_mean, n.x_scale, n.y_mean, n.y_scale),
        net,
        (weights, biases, *stats),
    )


def save_model(
    path: PathLike,
    joint: Joint,
    *,
    compliance: ComplianceModel | None = None,
    network: Network | None = None,
    meta: dict | None = None,
) -> Path:
    """Write a model file atomically (see the module docstring for the format).

    **Arguments:**

    - `path`: the file to write (conventionally `model.json`).
    - `joint`: the [`hdjax.Joint`][] the model was calibrated for.
    - `compliance`: a calibrated compliance model, or `None`.
    - `network`: a trained network, or `None`.
    - `meta`: extra JSON-ready facts (seed, experiment, data provenance).

    **Returns:** the path written.
    """
    if compliance is None and network is None:
        raise ModelMismatchError("nothing to save: give a compliance model, a network or both")
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "hdjax_version": __version__,
        "joint": joint.to_dict(),
        "units": dict(UNITS),
        "compliance": None if compliance is None else compliance.to_dict(),
        "network": None if network is None else _network_to_dict(network),
        "feature_layout": {
            "compliance": None if compliance is None else list(_CORE_SIGNALS),
            "network": None if network is None else list(network.layout.names),
        },
        "meta": dict(meta or {}),
    }
    payload["checksum"] = _checksum(payload)
    text = json.dumps(payload, indent=1, allow_nan=True)
    path = Path(path)
    atomic_write_bytes(path, text.encode())
    return path


def load_model(path: PathLike) -> SavedModel:
    """Read a model file, refusing a corrupt file or an incompatible format version.

    **Raises:** [`hdjax.DataError`][] for a missing, unreadable, truncated or edited file
    (checksum mismatch); [`hdjax.ModelMismatchError`][] for another format or version.
    """
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such model file")
    try:
        if path.is_dir():
            raise DataError(f"{path}: is a folder; give a model file (model.json)")
        payload = json.loads(path.read_bytes().decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise DataError(
            f"{path}: corrupt model file, not valid JSON ({err}); save the model again"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ModelMismatchError(f'{path}: not an hdjax model file (no "format": "{FORMAT}")')
    version = payload.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelMismatchError(
            f"{path}: model file format version {version!r} is incompatible with this hdjax "
            f"(reads version {FORMAT_VERSION}); recalibrate with this version or use the hdjax "
            f"that wrote it ({payload.get('hdjax_version', 'unknown')})"
        )
    stored = payload.pop("checksum", None)
    if stored != _checksum(payload):
        raise DataError(
            f"{path}: corrupt model file (checksum mismatch: the file was truncated or edited); "
            "save the model again"
        )
    try:
        joint = Joint.from_dict(payload["joint"], where=f"{path} joint")
        comp = payload["compliance"]
        comp = None if comp is None else ComplianceModel.from_dict(comp)
        net = payload["network"]
        net = None if net is None else _network_from_dict(net)
        units, meta = payload["units"], payload["meta"]
        for key, table in (("units", units), ("meta", meta)):
            if not isinstance(table, dict):
                raise TypeError(f"{key!r} must be a table, got {type(table).__name__}")
    except (KeyError, TypeError, ValueError) as err:
        raise DataError(f"{path}: corrupt model file ({type(err).__name__}: {err})") from None
    return SavedModel(joint=joint, compliance=comp, network=net, units=units, meta=meta)


def ratio_mismatch(
    ratio: float,
    recording,  # a Recording, or any object with theta_m, theta_l and source (streams)
    *,
    whose: str = "the joint's",
) -> str:
    """Why the recording's angles do not match the gear `ratio` (`""` when they do, or when the
    output moves too little to tell): the slope of $\theta_m$ against $\theta_l$ must be
    within 5 % of the ratio (Song et al. eq. (5) with a small twist)."""
    theta_l = np.asarray(recording.theta_l)
    theta_m = np.asarray(recording.theta_m)
    if np.ptp(theta_l) > 0.5 and np.all(np.isfinite(theta_l)) and np.all(np.isfinite(theta_m)):
        slope = np.polyfit(theta_l, theta_m, 1)[0]
        if not np.isclose(abs(slope), ratio, rtol=0.05):
            return (
                f"{recording.source}: the motor angle moves {abs(slope):.4g} times the output "
                f"angle but {whose} ratio is {ratio:g}; this data comes from another joint (or "
                "the angle columns are scaled differently)"
            )
    return ""


def angle_ratio_mismatch(saved: SavedModel, recording: Recording) -> str:
    """Why the recording's angles do not match the model's ratio (`""` when they do)."""
    return ratio_mismatch(saved.joint.ratio, recording, whose="the model's")


def check_compatible(
    saved: SavedModel,
    recording: Recording,
    joint: Joint | None = None,
    *,
    check_angles: bool = True,
) -> None:
    """Refuse to apply a saved model to data it does not fit.

    Checks: the data's joint (if given) has the model's ratio; the data's own angle ratio
    $\\Delta\\theta_m / \\Delta\\theta_l$ (when the output moves enough to tell) matches the
    model's ratio within 5 % (skipped with `check_angles=False`, as `hdjax estimate --force`
    does); every extra column the model reads is present.

    **Raises:** [`hdjax.ModelMismatchError`][] saying what differs.
    """
    ratio = saved.joint.ratio
    if joint is not None and not np.isclose(joint.ratio, ratio, rtol=1e-9):
        raise ModelMismatchError(
            f"the model was calibrated for ratio {ratio:g} but the data's joint has ratio "
            f"{joint.ratio:g}; calibrate a model for this joint"
        )
    why = angle_ratio_mismatch(saved, recording) if check_angles else ""
    if why:
        raise ModelMismatchError(why)
    missing = [c for c in saved.columns_needed() if c not in recording.extras]
    if missing:
        raise ModelMismatchError(
            f"{recording.source}: the model reads column(s) {', '.join(missing)} that the data "
            f"lacks (it has {', '.join(recording.column_names)}); the feature layout differs"
        )
