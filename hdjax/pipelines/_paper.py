"""The steps of an experiment: build the model, calibrate, estimate, train the network, time.

Each step is a plain function of the resolved configuration and the data, so `hdjax run`,
`hdjax sweep` and scripts share them.
"""

from __future__ import annotations

import time
import timeit
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .. import _interrupts as interrupts, network as nw
from .._errors import ConfigError
from .._features import Signals, signals
from .._joint import Joint
from .._metrics import error_metrics
from .._recording import Recording
from ..compliance import (
    RecordingStream,
    calibrate_rls,
    calibrate_stream,
    estimate_torque,
)
from ..discover import calibrate_start, calibrate_structure
from ..modelfile import check_compatible, load_model
from . import _streamed as S
from ._streamed_dataset import PartStream

PAPER_MS_PER_100 = {"model": 9.232, "network": 25.442}
"""Song et al. Section IV.B: time to estimate 100 torques on an i7-7700H [ms]."""


PAPER_ERRORS = {
    "model": {
        "slow": (84.8, 42.3),
        "fast": (400.0, 67.06),
        "sudden": (80.23, 32.99),
        "static": (29.9, 14.48),
    },
    "network": {
        "slow": (29.9, 14.48),
        "fast": (167.1, 11.3),
        "sudden": (43.1, 2.84),
        "static": (20.4, 5.9),
    },
}
"""Song et al. Section IV.B (Figs. 9-16): (maximum, RMS) torque error [N·m] per experiment."""


# ---------------------------------------------------------------------------------------------
# The compliance model


def current_scale(cfg: dict, train: list[Recording] | PartStream) -> float:
    """The `[model] current_scale`, with `"auto"` = the largest |current| in the training data."""
    value = cfg["model"]["current_scale"]
    if isinstance(train, RecordingStream):  # streamed parts know their peak from the build pass
        peak = train.peak_current
    else:
        peak = max(float(np.max(np.abs(np.asarray(r.current)))) for r in train)
    if value == "auto":
        return peak if peak > 0 else 1.0
    value = float(value)
    # The polynomial columns are powers of current / scale: a scale far from the data's range
    # overflows them or makes them vanish, and the fit fails deep inside the solver.
    if peak > 0 and not 1e-3 <= peak / value <= 1e3:
        raise ConfigError(
            f"[model] current_scale = {value:g} A is far from the data's largest |current| "
            f"({peak:.4g} A): the normalised current would reach {peak / value:.3g}; set "
            f'current_scale near {peak:.4g} or to "auto"'
        )
    return value


def stacked_signals(model, recordings: list[Recording]):
    """Signals and reference torque of several recordings, stacked (velocities per recording)."""
    sigs = [signals(r, model.joint, velocity=model.velocity) for r in recordings]
    torque = jnp.concatenate([jnp.asarray(r.column("torque")) for r in recordings])
    return Signals.concatenate(sigs), torque


def calibrate(cfg: dict, model, train: list[Recording] | PartStream, warn=None):
    """Calibrate by the `[fit]` method; returns the calibration's [`hdjax.Solution`][].

    Least squares on recordings held in memory (the default) calibrates through
    [`hdjax.discover.calibrate_start`][], the function that calibrates `hdjax discover`'s
    starting model: segments the data does not determine are merged, the segment
    compliances are held above a floor (shape-constrained eq. (17)), and a rank-deficient
    structure falls back to a simpler one. Recursive least squares (eqs. (18)-(21)) and the
    streamed fit of long logs calibrate `model` as it is. Warnings and those notes (terms the
    data cannot reach, merges, fallbacks) go to `warn` (a callable) when given.
    """
    fit = cfg["fit"]
    streamed = isinstance(train, RecordingStream)  # a StreamedDataset's parts, read in chunks
    chunked = streamed or (fit.get("chunk") and fit["method"] == "lstsq")
    data = None if chunked else stacked_signals(model, train)
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if fit["method"] == "rls":
            result = calibrate_rls(
                model,
                data,
                block_size=fit["block"],
                forgetting=fit["forgetting"],
                init_samples=fit["init_samples"] or None,
            )
        elif data is None:
            stream = train if streamed else RecordingStream.from_recordings(train, fit["chunk"])
            result = calibrate_stream(model, stream, chunk=fit["chunk"], throw=False)
        else:  # the starting model of hdjax discover, from the same function
            scale = current_scale(cfg, train)
            result = calibrate_start(
                cfg["model"], model.joint, data, notes, scale=scale, throw=False
            )
    for msg in [str(w.message) for w in caught] + notes:
        (warn or (lambda msg: None))(msg)
    return result


def calibrate_saved(cfg: dict, train: list[Recording] | PartStream, warn=None):
    """Calibrate the structure of the saved model `[model] structure` names (segments, terms,
    effects: what `hdjax discover` found) on the TRAIN recording by the residual loop's own
    fit ([`hdjax.discover.calibrate_structure`][]); returns the fit's [`hdjax.Solution`][].

    On the loop's TRAIN log this gives the loop's final model, so `hdjax run` with the
    `experiment.toml` that `hdjax discover` writes reproduces its TEST error. Refused, in one
    line, for a file without a compliance model, another joint's model, several TRAIN
    recordings, or a streamed or recursive fit.
    """
    path = cfg["model"]["structure"]
    fit = cfg["fit"]
    where = f"[model] structure = {path!r}"
    if isinstance(train, RecordingStream) or fit["method"] != "lstsq" or fit.get("chunk"):
        raise ConfigError(
            f"{where}: a saved structure is calibrated in memory by least squares; set [fit] "
            'method = "lstsq" and chunk = 0, and [data] chunk = 0'
        )
    if len(train) != 1:
        raise ConfigError(
            f"{where}: a saved structure is calibrated on one TRAIN recording (the one the "
            f"residual loop ran on); this experiment has {len(train)}: list one in [data] train"
        )
    saved = load_model(path)
    if saved.compliance is None:
        raise ConfigError(f"{where}: the file holds no compliance model (a network only)")
    check_compatible(saved, train[0], check_angles=False)
    notes: list[str] = []
    result = calibrate_structure(saved.compliance, train[0], notes)
    for msg in dict.fromkeys(notes):
        (warn or (lambda msg: None))(msg)
    return result


def estimate_model(model, recordings: dict[str, Recording | PartStream]) -> dict:
    """Torque estimates of a calibrated model on each recording (name -> TorqueEstimate, or a
    `StreamedEstimate` for a streamed part)."""
    return {
        name: (
            S.estimate_model_streamed(model, rec, rec.n_samples, rec.chunk)
            if isinstance(rec, RecordingStream)
            else estimate_torque(model, rec)
        )
        for name, rec in recordings.items()
    }


def metrics_of(
    estimates: dict, recordings: dict[str, Recording | PartStream], rated: float
) -> dict:
    """name -> error metrics dict (rms, max, bias, rms_pct, max_pct, n), over all samples; an
    in-memory recording's also has `max_at_s`, the time of its largest error."""
    out = {}
    for name, est in estimates.items():
        if isinstance(est, S.StreamedEstimate):  # errors summed chunk by chunk
            out[name] = est.errors.as_dict(rated, in_range=est.in_range)
            continue
        torque = est.torque if hasattr(est, "torque") else est
        measured = recordings[name].column("torque")
        m = error_metrics(torque, measured, rated).as_dict()
        worst = int(np.argmax(np.abs(np.asarray(torque) - np.asarray(measured))))
        m["max_at_s"] = float(np.asarray(recordings[name].column("t"))[worst])
        if hasattr(est, "in_range"):
            m["out_of_range_pct"] = 100.0 * float(1.0 - np.mean(np.asarray(est.in_range)))
        out[name] = m
    return out


# ---------------------------------------------------------------------------------------------
# The network


def network_available() -> str:
    """`""` when the network package offers what the paper run uses, else why not."""
    for name in ("Network", "build_features", "train_optax", "predict_torque"):
        if not hasattr(nw, name):
            return f"hdjax.network is not available (it has no {name!r})"
    return ""


def train_network(
    cfg: dict, joint: Joint, train: list[Recording] | PartStream, seed: int, val=None
):
    """Train the `[network]` on the training recordings; returns `(network, info dict)`.

    At most `max_train_samples` samples are used, spread evenly over all training recordings
    (every k-th sample); features are built per recording so velocities and the Kalman filter
    never straddle two recordings.
    """
    n_cfg = cfg["network"]
    if isinstance(train, RecordingStream):  # features chunk by chunk, the Kalman state carried
        x, y, layout = S.training_rows(
            train, joint, train.n_samples, n_cfg["max_train_samples"], n_cfg
        )
    else:
        feats = [
            nw.build_features(
                r,
                joint,
                periodic=n_cfg["periodic"],
                orders=tuple(n_cfg["orders"]),
                kalman=n_cfg["kalman"],
            )
            for r in train
        ]
        x = np.concatenate([np.asarray(f.x) for f in feats])
        y = np.concatenate([np.asarray(r.column("torque")) for r in train])
        stride = max(1, -(-x.shape[0] // n_cfg["max_train_samples"]))
        x, y, layout = x[::stride], y[::stride], feats[0].layout
    key = jax.random.PRNGKey(seed)
    k_init, k_train = jax.random.split(key)
    net = nw.Network(layout, tuple(n_cfg["hidden"]), key=k_init)
    t0 = time.perf_counter()
    if n_cfg["trainer"] == "backprop":
        res = nw.train_backprop(
            net,
            x,
            y,
            mu=n_cfg["learning_rate"],
            eta=n_cfg["eta"],
            error_target=0.0,
            max_learnings=n_cfg["steps"],
            key=k_train,
        )
    else:
        res = nw.train_optax(
            net,
            x,
            y,
            learning_rate=n_cfg["learning_rate"],
            steps=n_cfg["steps"],
            key=k_train,
            optimizer=n_cfg["optimizer"],
            batch_size=n_cfg["batch_size"] or None,
        )
    fit_s = time.perf_counter() - t0
    hist = np.asarray(res.stats["history"])
    info = {
        "trainer": n_cfg["trainer"],
        "hidden": list(n_cfg["hidden"]),
        "n_parameters": int(res.value.n_parameters),
        "train_samples": int(x.shape[0]),
        "steps": int(res.stats["steps"]),
        "final_loss": float(hist[-1]) if hist.size else float("nan"),
        "fit_s": fit_s,
        "layout": list(res.value.layout.names),
    }
    return res.value, info


def estimate_network(net, joint: Joint, recordings: dict[str, Recording | PartStream]) -> dict:
    """Torque estimates of a trained network on each recording (name -> array, or a
    `StreamedEstimate` for a streamed part)."""
    return {
        name: (
            S.estimate_network_streamed(net, joint, rec, rec.n_samples)
            if isinstance(rec, RecordingStream)
            else nw.predict_torque(net, rec, joint)
        )
        for name, rec in recordings.items()
    }


def figure_series(est, rec) -> tuple:
    """`(t, measured, estimated, errors)` for a torque figure: the whole recording, or the
    samples a streamed estimate kept with its `(rms, max)` over every sample."""
    if isinstance(est, S.StreamedEstimate):
        return est.t, est.measured, est.torque, (est.errors.rms, est.errors.peak)
    torque = est.torque if hasattr(est, "torque") else est
    return np.asarray(rec.t), np.asarray(rec.column("torque")), np.asarray(torque), None


def first_samples(rec, n: int) -> Recording:
    """The first `n` samples of a recording or of a streamed part (for the timing)."""
    return S.head(rec, n) if isinstance(rec, RecordingStream) else rec


# ---------------------------------------------------------------------------------------------
# Timing


def time_per_100(fn, rec: Recording, repeats: int) -> dict:
    """Time `fn(rec100)` on the first 100 samples: first call and steady state [ms].

    The steady state is `min(timeit.repeat(number=1))` with `block_until_ready`, i.e. one call
    from Python as a user makes it (checks, signals and the jitted estimate).
    """
    if rec.n_samples < 100:
        raise ConfigError(f"timing needs at least 100 samples, {rec.source} has {rec.n_samples}")
    rec100 = rec.select(slice(0, 100))
    run = lambda: jax.block_until_ready(fn(rec100))
    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    timer = timeit.Timer(run)
    steady = float("inf")
    for _ in range(repeats):
        # a signal whose exception was swallowed (in JAX's gc callback) ends the loop here
        interrupts.check()
        steady = min(steady, timer.timeit(number=1))
    return {"first_call_ms": 1e3 * first, "ms_per_100": 1e3 * steady}
