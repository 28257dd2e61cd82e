"""Building an experiment's data from its `[data]` table: plant scenarios, files or synthetic.

- `kind = "plant"`: the built-in joint simulator's scenarios (`slow`, `fast`, `sudden`,
  `static`, Song et al. Section IV.B). The test recordings use the experiment's seed, the
  calibration (training) recordings the same scenarios with `seed + train_seed_offset`, so the
  model never sees the noise or the load realisation it is scored on.
- `settle` (any kind): the first seconds of every recording are left out (the simulated
  joint starts from rest and settles under its load in the first few hundred milliseconds; the
  paper's runs start settled).
- `kind = "files"`: CSV or `.npz` recordings, read through a column map (`[data.columns]`,
  `[data.extras]`, see [`hdjax.ColumnMap`][]); paths are relative to the experiment file.
  Test recordings are named files, or the last `split` fraction of each training file (with
  `split_blocks = B`: every round(1/split)-th block of B samples, so both parts span the run).
- `[fit] chunk > 0` with `kind = "files"`: the same parts as streams read chunk by chunk
  ([`hdjax.pipelines.StreamedDataset`][]), so memory is bounded by the chunk, not the logs.
- `kind = "synthetic"`: recordings generated from a known compliance (a five-segment
  flexspline, a cubic wave-generator term, a first-order kinematic error and white encoder
  noise) — a self-contained demo and test bed that needs no plant.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import plant
from .._errors import ConfigError
from .._formats import load_recording
from .._io import ColumnMap, load_csv, load_npz
from .._joint import Joint
from .._recording import Recording, make_recording
from ..compliance import paper_knots
from ..config import Experiment, column_map
from ..config.internal import joint_of, resolve_path
from ..reference import describe_column_reference, load_with_reference
from ._streamed_dataset import StreamedDataset, build_streamed_dataset, streams


@dataclasses.dataclass
class Dataset:
    """Calibration and test recordings of one experiment.

    **Fields:** `train` (recordings to calibrate / train on), `test` (name -> recording to
    score on), `joint` (the [`hdjax.Joint`][]), `provenance` (one line per recording) and
    `reference` (which reference torque was used: `kind`, `description`, and for a wrench
    reference its holds and sensor offset per file).
    """

    train: list[Recording]
    test: dict[str, Recording]
    joint: Joint
    provenance: list[str]
    reference: dict = dataclasses.field(default_factory=lambda: {"kind": "column"})

    @property
    def n_train(self) -> int:
        return sum(r.n_samples for r in self.train)


def build_dataset(
    exp: Experiment, progress: Callable[[str], None] | None = None
) -> Dataset | StreamedDataset:
    """The [`hdjax.pipelines.Dataset`][] an experiment describes (a
    [`hdjax.pipelines.StreamedDataset`][] when `[fit] chunk` streams the files).

    **Arguments:**

    - `exp`: a resolved [`hdjax.config.Experiment`][].
    - `progress`: optional callable taking a message (long steps report through it).

    **Raises:** [`hdjax.DataError`][] for a missing file or column, [`hdjax.ConfigError`][] for a
    bad column map or an unavailable plant.
    """
    data = exp["data"]
    joint = joint_of(exp)
    say = progress or (lambda msg: None)
    if streams(exp):  # [fit] chunk on files: parts read chunk by chunk, never whole
        ds = build_streamed_dataset(exp, joint, say)
        ds.reference = {
            "kind": "column",
            "description": describe_column_reference(data["columns"], data["kind"]),
        }
        ds.provenance.append(ds.reference["description"])
        return ds
    if data["kind"] == "files":
        ds = _from_files(exp, joint, say)
    elif data["kind"] == "synthetic":
        ds = _synthetic(exp, joint, say)
    elif data["kind"] == "real_log":
        ds = _from_real_log(exp, joint, say)
    else:
        ds = _from_plant(exp, joint, say)
    if data["settle"] > 0:
        ds = _drop_settling(ds, data["settle"])
    if data["reference"]["kind"] == "column":
        ds.reference = {
            "kind": "column",
            "description": describe_column_reference(data["columns"], data["kind"]),
        }
        ds.provenance.append(ds.reference["description"])
    return ds


def _drop_settling(ds: Dataset, settle: float) -> Dataset:
    """Leave out the first `settle` seconds of every recording (start-up transients)."""

    def cut(rec: Recording) -> Recording:
        t = np.asarray(rec.t)
        keep = t >= t[0] + settle
        if keep.sum() < 2:
            raise ConfigError(
                f"[data] settle = {settle:g} s leaves fewer than 2 samples of {rec.source} "
                f"({t[-1] - t[0]:.3g} s long)"
            )
        return rec.select(keep)

    note = f"first {settle:g} s of every recording left out (start-up transient)"
    return Dataset(
        train=[cut(r) for r in ds.train],
        test={k: cut(r) for k, r in ds.test.items()},
        joint=ds.joint,
        provenance=ds.provenance + [note],
        reference=ds.reference,
    )


# ---------------------------------------------------------------------------------------------
# Files


def _load(path: Path, fmt: str, cmap: ColumnMap, check_units: bool, exp) -> tuple:
    """The recording at `path` and, for a wrench reference, its report (else `None`)."""
    if fmt == "auto":
        loader = load_recording
    else:
        loader = load_npz if fmt == "npz" else load_csv
    spec = exp["data"]["reference"]
    if spec["kind"] != "wrench":
        return loader(path, cmap, check_units=check_units), None
    rec, ref = load_with_reference(
        path, cmap, spec, loader, base_dir=exp.base_dir, check_units=check_units
    )
    return rec, ref.as_dict()


def _from_files(exp, joint: Joint, say) -> Dataset:
    data = exp["data"]
    cmap = column_map(data)
    train, test, prov, refs = [], {}, [], {}
    split = data["split"]
    for name in data["train"]:
        path = resolve_path(exp, name)
        say(f"loading {path}")
        rec, refs[str(path)] = _load(path, data["format"], cmap, data["check_units"], exp)
        if split > 0 and not data["test"]:
            a, b = _split(rec, split, data["split_blocks"])
            train.append(a)
            test[_unique(path.stem, test)] = b
            prov.append(f"{path}: {a.n_samples} calibration + {b.n_samples} test samples")
        else:
            train.append(rec)
            prov.append(f"{path}: {rec.n_samples} calibration samples")
    tests = data["test"]
    items = tests.items() if isinstance(tests, dict) else ((Path(t).stem, t) for t in tests)
    for label, name in items:
        path = resolve_path(exp, name)
        say(f"loading {path}")
        rec, refs[str(path)] = _load(path, data["format"], cmap, data["check_units"], exp)
        test[_unique(label, test)] = rec
        prov.append(f"{path}: {rec.n_samples} test samples ({label})")
    for rec in train:
        if rec.torque is None:
            raise ConfigError(
                f"{rec.source}: a calibration recording needs a reference torque column; map "
                "one in [data.columns] torque = ..."
            )
    if data["reference"]["kind"] == "wrench":
        first = next(iter(refs.values()))
        prov += [f"{p}: {r['description']}" for p, r in refs.items()]
        reference = {"kind": "wrench", "description": first["description"], "files": refs}
        return Dataset(train=train, test=test, joint=joint, provenance=prov, reference=reference)
    return Dataset(train=train, test=test, joint=joint, provenance=prov)


def _split(rec: Recording, fraction: float, block: int) -> tuple[Recording, Recording]:
    """Calibration and test parts: the last `fraction` of the samples, or (with `block`)
    every k-th block of `block` samples, k = round(1/fraction), so both parts span the run."""
    if not block:
        return rec.split(1.0 - fraction)
    every = max(2, round(1.0 / fraction))
    held = (np.arange(rec.n_samples) // block) % every == every - 1
    if held.sum() < 2 or (~held).sum() < 2:
        raise ConfigError(
            f"{rec.source}: split_blocks = {block} leaves too few samples in one part "
            f"({rec.n_samples} samples); use smaller blocks"
        )
    return rec.select(~held), rec.select(held)


def _unique(label: str, taken) -> str:
    out, i = label, 2
    while out in taken:
        out, i = f"{label}_{i}", i + 1
    return out


# ---------------------------------------------------------------------------------------------
# Plant


def _from_plant(exp, joint: Joint, say) -> Dataset:
    data = exp["data"]
    seed = exp["experiment"]["seed"]
    simulate = plant_simulator(data)
    train, test, prov = [], {}, []
    for name in data["scenarios"]:
        for role, s in (("test", seed), ("calibration", seed + data["train_seed_offset"])):
            say(f"simulating scenario {name!r} ({data['duration']:g} s, seed {s}, {role})")
            rec = simulate(name, data["duration"], s)
            (train.append(rec) if role == "calibration" else test.__setitem__(name, rec))
            prov.append(
                f"plant {data['preset']} scenario {name!r}, {data['duration']:g} s, seed {s}: "
                f"{rec.n_samples} {role} samples"
            )
    rec0 = next(iter(test.values()))
    if rec0.torque is None:
        raise ConfigError("the plant scenarios returned no reference torque")
    return Dataset(train=train, test=test, joint=joint, provenance=prov)


def _plant_params(data: dict):
    """The `[data]` plant: its preset with `effects` switched on or off."""
    preset = {"song": "song_params", "hashimoto": "hashimoto_params"}[data["preset"]]
    params = getattr(plant, preset)()
    return params if not data["effects"] else plant.with_effects(params, dict(data["effects"]))


MAX_REAL_LOG_S = 600.0
"""The longest `kind = "real_log"` recording [s] (its simulation runs at a 0.25 ms step)."""


def _from_real_log(exp, joint: Joint, say) -> Dataset:
    """`kind = "real_log"`: the plant on one-way sweeps from rest under gravity with pauses,
    read through a real log's sensors ([`hdjax.plant.simulate_real_log`][]): jittered time
    stamps with dropped samples, encoder skew, white load-encoder noise, quantised multi-turn
    encoders with the joint's offsets, a held reference. Calibration runs `sweeps` at
    `speed`, the test `test_sweeps` at `test_speed` (another motion, not the same one with new
    noise); the encoders' offsets are the joint's, the same in both."""
    import jax

    data = exp["data"]
    seed = exp["experiment"]["seed"]
    sensors = plant.RealLogSensors(
        period=data["sample_period"],
        jitter=data["jitter"],
        drop=data["drop"],
        skew=data["skew_ms"] * 1e-3,
        noise_arcsec=data["noise_arcsec"],
        bits=data["encoder_bits"],
        hold=data["hold"],
        twist_sign=joint.twist_sign,
        offset_seed=seed,
    )
    params = _plant_params(data)
    for key in ("sweeps", "test_sweeps"):
        speed = data["speed" if key == "sweeps" else "test_speed"]
        ends = [a for pair in data[key] for a in pair]
        path = sum(abs(b - a) for a, b in zip(ends, ends[1:]))
        seconds = path / speed + 2.0 * len(data[key]) + 2.0  # the moves, their ramps and pauses
        if seconds > MAX_REAL_LOG_S:
            raise ConfigError(
                f"[data] {key} at {speed:g} rad/s take about {seconds:.0f} s to simulate, over "
                f"the {MAX_REAL_LOG_S:.0f} s a real_log recording may last: give shorter sweeps "
                "or a higher speed"
            )
    parts, prov = {}, []
    for role, s, sweeps, speed in (
        ("calibration", seed + data["train_seed_offset"], data["sweeps"], data["speed"]),
        ("test", seed, data["test_sweeps"], data["test_speed"]),
    ):
        say(f"simulating one-way sweeps {sweeps} rad at {speed:g} rad/s, seed {s}, {role}")
        rec = plant.simulate_real_log(
            params,
            sensors,
            key=jax.random.PRNGKey(s),
            sweeps=tuple(tuple(p) for p in sweeps),
            speed=speed,
        )
        parts[role] = rec
        prov.append(
            f"plant {data['preset']} on one-way sweeps {sweeps} rad at {speed:g} rad/s, seed "
            f"{s}, read as a real log ({data['sample_period'] * 1e3:g} ms with jitter and drops, "
            f"skew {data['skew_ms']:g} ms, {data['noise_arcsec']:g} arcsec load-encoder noise, "
            f"{data['encoder_bits']}-bit encoders): {rec.n_samples} {role} samples"
        )
    return Dataset(
        train=[parts["calibration"]], test={"sweep": parts["test"]}, joint=joint, provenance=prov
    )


def plant_simulator(data: dict):
    """A function `(scenario, duration, seed) -> Recording` for the `[data]` plant settings.

    **Raises:** [`hdjax.ConfigError`][] when the built-in plant has no scenarios.
    """
    scenario = getattr(plant, "simulate_scenario", None)
    if scenario is None:
        raise ConfigError(
            "the built-in plant has no scenarios in this installation "
            '(hdjax.plant.simulate_scenario is missing); use [data] kind = "files" or '
            '"synthetic"'
        )
    import jax

    params = _plant_params(data)

    def simulate(name: str, duration: float, seed: int) -> Recording:
        key = jax.random.PRNGKey(seed)
        return scenario(name, key=key, duration=duration, params=params)

    return simulate


# ---------------------------------------------------------------------------------------------
# Synthetic

SYNTHETIC_POLY = (4.0e-5, -1.5e-5, 2.5e-5)
"""Wave-generator twist [rad] per power 1..3 of the normalised current (the true order is 3)."""
SYNTHETIC_FOURIER = (1.0e-5, -0.6e-5)
"""First-order paper-form kinematic error of the output side (a1, b1) [rad], Song et al. eq. (9)."""


def synthetic_recording(
    joint: Joint,
    n_samples: int,
    *,
    seed: int,
    noise_arcsec: float = 1.0,
    dt: float = 1e-3,
    source: str = "synthetic",
) -> Recording:
    r"""A recording whose twist follows a known compliance model (for demos and tests).

    The torque sweeps the rated range with two incommensurate sines; the current is
    $T / (N K_t)$ plus a friction-like part and 1 % noise; the twist is the five-segment
    flexspline of eq. (7) (knots $\\pm\\tau_0/3, \\pm 2\\tau_0/3$) with the
    paper's k-shape scaled to $k_1 = 1/(6.7\cdot10^4)$ rad/N·m, plus a cubic polynomial in the
    normalised current (`SYNTHETIC_POLY`), a first-order kinematic error in the paper's form
    (eq. (9), `SYNTHETIC_FOURIER`) and white noise of `noise_arcsec`.
    """
    rng = np.random.default_rng(seed)
    tau0, n_ratio = joint.rated_torque, joint.ratio
    t = np.arange(n_samples) * dt
    span = t[-1] if t[-1] > 0 else 1.0
    f1, f2 = 3.0 / span, 7.3 / span
    ph = rng.uniform(0, 2 * np.pi, 3)
    torque = tau0 * (0.8 * np.sin(2 * np.pi * f1 * t + ph[0]) + 0.15 * np.sin(2 * np.pi * f2 * t))
    theta_l = 0.4 * np.sin(2 * np.pi * 1.7 * f1 * t + ph[1]) + 0.1 * np.sin(2 * np.pi * f2 * t)
    kt = joint.torque_constant or 0.25
    current = torque / (n_ratio * kt)
    i_scale = tau0 / (n_ratio * kt)
    # Friction and inertia make the motor current differ from the output torque; without this
    # the current polynomial and the flexspline compliance would be collinear.
    friction = 0.2 * np.tanh(np.gradient(theta_l, dt) / 0.05) + 0.1 * np.sin(2 * np.pi * f2 * t)
    current = current + i_scale * (friction + 0.01 * rng.standard_normal(n_samples))
    k = np.array([0.26305, 0.19913, 0.04946, 0.29008, 0.08434]) * (1 / 6.7e4 / 0.26305)
    k_torque_order = np.array([k[2], k[1], k[0], k[3], k[4]])
    knots = list(paper_knots(tau0, 5))
    bounds = list(zip([-np.inf, *knots], [*knots, np.inf]))
    hinge = np.stack([np.clip(torque, lo, hi) - min(max(0.0, lo), hi) for lo, hi in bounds], axis=1)
    x = current / i_scale
    twist = hinge @ k_torque_order + sum(c * x ** (i + 1) for i, c in enumerate(SYNTHETIC_POLY))
    omega_l = np.concatenate([[0.0], np.diff(theta_l) / dt])
    a1, b1 = SYNTHETIC_FOURIER
    ul = theta_l * omega_l
    twist = twist + a1 * np.cos(ul) + b1 * np.sin(ul)
    twist = twist + noise_arcsec * (math.pi / 648000.0) * rng.standard_normal(n_samples)
    theta_m = n_ratio * (theta_l - joint.twist_sign * twist)
    return make_recording(t, theta_m, theta_l, current, torque, source=source, check_units=False)


def _synthetic(exp, joint: Joint, say) -> Dataset:
    data = exp["data"]
    seed = exp["experiment"]["seed"]
    n = data["n_samples"]
    noise = data["noise_arcsec"]
    say(f"generating synthetic recordings ({n} samples each)")
    train = [
        synthetic_recording(
            joint, n, seed=seed + data["train_seed_offset"], noise_arcsec=noise, source="synth-cal"
        )
    ]
    test = {"synthetic": synthetic_recording(joint, n, seed=seed, noise_arcsec=noise)}
    prov = [
        f"synthetic: {n} calibration samples (seed {seed + data['train_seed_offset']}), "
        f"{n} test samples (seed {seed}), noise {noise:g} arcsec"
    ]
    return Dataset(train=train, test=test, joint=joint, provenance=prov)
