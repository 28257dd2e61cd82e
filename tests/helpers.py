"""A small zoo of simulated data with known coefficients, shared by the foundation tests.

Everything is built from [`hdjax.compliance.Signals`][] directly, so the design matrix is known
exactly: the twist is `model.design(sig, torque) @ truth` (plus optional noise), with the
paper-form Fourier columns evaluated at the products `theta * omega` (eq. (9)). The products are
spread over many periods so the cos/sin columns are close to orthogonal and the design is well
conditioned. Seeds are fixed and printed by the tests that use them.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np

import hdjax
from hdjax.compliance import ComplianceModel, Signals

from .conftest import REPO

JOINT = hdjax.Joint(ratio=101.0, rated_torque=90.0, name="sim")
"""The simulated joint: ratio 101, rated torque 90 N·m (knots at +-30, +-60 N·m)."""


@dataclasses.dataclass(frozen=True)
class SimCase:
    """A simulated calibration problem: signals, reference torque and the true coefficients."""

    name: str
    model: ComplianceModel  # structure, with the true coefficients in `coef`
    sig: Signals
    torque: np.ndarray
    truth: np.ndarray
    noise: float
    seed: int


def make_signals(n: int, *, seed: int, current_of_torque: bool = False, torque=None):
    """Random but smooth-enough inputs: angles, velocities, current, torque in [-tau0, tau0].

    `theta * omega` spans tens of radians so the paper-form harmonics decorrelate. The current is
    independent of the torque unless `current_of_torque` (then it is `torque / 30` plus noise,
    as a motor current would be).
    """
    rng = np.random.default_rng(seed)
    tau0 = JOINT.rated_torque
    if torque is None:
        torque = rng.uniform(-tau0, tau0, n)
    theta_m = rng.uniform(0.0, 60.0, n)
    theta_l = rng.uniform(-3.0, 3.0, n)
    omega_m = rng.uniform(-3.0, 3.0, n)
    omega_l = rng.uniform(-3.0, 3.0, n)
    if current_of_torque:
        current = torque / 30.0 + 0.05 * rng.standard_normal(n)
    else:
        current = rng.uniform(-1.5, 1.5, n)
    sig = Signals(
        twist=jnp.zeros(n, jnp.float64),
        current=jnp.asarray(current, jnp.float64),
        theta_m=jnp.asarray(theta_m, jnp.float64),
        theta_l=jnp.asarray(theta_l, jnp.float64),
        omega_m=jnp.asarray(omega_m, jnp.float64),
        omega_l=jnp.asarray(omega_l, jnp.float64),
        extras={},
    )
    return sig, np.asarray(torque, np.float64)


def true_coefficients(model: ComplianceModel, *, seed: int, spread: float = 1.0) -> np.ndarray:
    """Plausible coefficients: segment compliances 2e-5..4e-5 rad/(N·m) (~5-8 arcsec per N·m),
    torque-free terms of a few 1e-5 rad (arcseconds), per-segment blocks differing by `spread`
    times their size."""
    rng = np.random.default_rng(seed)
    n_seg = model.n_segments
    k = rng.uniform(2e-5, 4e-5, n_seg)
    nb = model.n_base
    shared = rng.uniform(-3e-5, 3e-5, nb)
    if model.per_segment:
        rows = [shared + spread * rng.uniform(-3e-5, 3e-5, nb) for _ in range(n_seg)]
        base = np.concatenate(rows)
    else:
        base = shared
    eff = rng.uniform(-3e-5, 3e-5, model.n_effect)
    return np.concatenate([k, base, eff])


def simulate(
    name: str,
    n: int = 4000,
    *,
    seed: int = 0,
    noise: float = 0.0,
    per_segment: bool = True,
    poly_order: int = 6,
    fourier_order: int = 3,
    kinematic: str = "paper",
    spread: float = 1.0,
    current_of_torque: bool = False,
) -> SimCase:
    """A calibration problem with a known answer: twist = A(sig, torque) @ truth + noise."""
    model = ComplianceModel.paper(
        JOINT,
        poly_order=poly_order,
        fourier_order=fourier_order,
        kinematic=kinematic,
        per_segment=per_segment,
    )
    sig, torque = make_signals(n, seed=seed, current_of_torque=current_of_torque)
    truth = true_coefficients(model, seed=seed + 1, spread=spread)
    model = eqx_set_coef(model, truth)
    twist = np.asarray(model.predict_twist(sig, torque))
    twist = twist + noise * np.random.default_rng(seed + 2).standard_normal(n)
    sig = dataclasses_replace_twist(sig, twist)
    return SimCase(name, model, sig, torque, truth, noise, seed)


def eqx_set_coef(model: ComplianceModel, coef) -> ComplianceModel:
    import equinox as eqx

    return eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef, jnp.float64))


def dataclasses_replace_twist(sig: Signals, twist) -> Signals:
    import equinox as eqx

    return eqx.tree_at(lambda s: s.twist, sig, jnp.asarray(twist, jnp.float64))


def sim_recording(n: int = 400, *, seed: int = 0, dt: float = 0.004, with_torque: bool = True):
    """A small Recording with plausible magnitudes (for loader and feature tests)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt + 10.0
    theta_l = 0.8 * np.sin(2 * np.pi * 0.5 * (t - t[0]))
    torque = 80.0 * np.sin(2 * np.pi * 1.0 * (t - t[0]))
    twist = 3e-5 * torque
    theta_m = JOINT.ratio * (theta_l - twist)
    current = torque / 30.0 + 0.01 * rng.standard_normal(n)
    return hdjax.make_recording(
        t,
        theta_m,
        theta_l,
        current,
        torque if with_torque else None,
        {"temperature": 25.0 + 0.01 * np.arange(n)},
        source=f"sim(seed={seed})",
    )


def path_recording(theta_l, torque, twist, *, dt: float, source: str):
    """A Recording of `JOINT` moving along the output path `theta_l` under `torque`, its motor
    angle carrying `twist` (the current: torque / 10, no extra columns)."""
    theta_l = np.asarray(theta_l, np.float64)
    return hdjax.make_recording(
        t=np.arange(theta_l.size) * dt,
        theta_m=JOINT.ratio * (theta_l + twist),
        theta_l=theta_l,
        current=np.asarray(torque) / 10.0,
        torque=torque,
        extras={},
        source=source,
    )


def tree_allclose(a, b, *, rtol=1e-12, atol=0.0) -> bool:
    """Whether two pytrees have the same structure and close leaves."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    if ta != tb:
        return False
    return all(
        np.allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol) for x, y in zip(la, lb)
    )


def numpy_design(model: ComplianceModel, sig: Signals, torque) -> np.ndarray:
    """The design of eqs. (7)-(10) written out independently in NumPy (paper-form or harmonic
    kinematic terms, polynomial in current, hinge basis, per-segment or shared blocks)."""
    from hdjax.compliance import Constant, CurrentPolynomial, Harmonics, PaperFourier

    T = np.asarray(torque, np.float64)
    edges = np.r_[-np.inf, np.asarray(model.knots), np.inf]
    hinge = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        hinge.append(np.clip(T, lo, hi) - np.clip(0.0, lo, hi))
    cols = []
    g = {k: np.asarray(getattr(sig, k)) for k in ("current", "theta_m", "theta_l")}
    g["omega_m"], g["omega_l"] = np.asarray(sig.omega_m), np.asarray(sig.omega_l)
    for term in model.base_terms:
        if isinstance(term, Constant):
            cols.append(np.ones_like(T))
        elif isinstance(term, CurrentPolynomial):
            cols += [(g["current"] / term.scale) ** i for i in range(1, term.order + 1)]
        elif isinstance(term, PaperFourier):
            ul, um = g["theta_l"] * g["omega_l"], g["theta_m"] * g["omega_m"]
            for n in range(1, term.order + 1):
                cols += [np.cos(n * ul), np.sin(n * ul), np.cos(n * um), np.sin(n * um)]
        elif isinstance(term, Harmonics):
            for k in term.orders:
                cols += [np.cos(k * g[term.signal]), np.sin(k * g[term.signal])]
        else:
            raise NotImplementedError(term)
    base = np.stack(cols, axis=1)
    H = np.stack(hinge, axis=1)
    if model.per_segment:
        seg = np.searchsorted(np.asarray(model.knots), T, side="right")
        blocks = [base * (seg == s)[:, None] for s in range(model.n_segments)]
        return np.concatenate([H] + blocks, axis=1)
    return np.concatenate([H, base], axis=1)


def png_image(data) -> np.ndarray:
    """Decode PNG bytes (or a path) into an (height, width, channels) array in [0, 1]."""
    import io
    from pathlib import Path

    import matplotlib.image

    if isinstance(data, str | Path):
        data = Path(data).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG file"
    return matplotlib.image.imread(io.BytesIO(data), format="png")


def assert_figure(data, size: tuple[int, int], *, min_ink: float = 0.01) -> np.ndarray:
    """Check a rendered figure: a PNG of `size` = (width, height) pixels that is not blank.

    "Not blank": at least `min_ink` of the pixels differ from the background colour (the most
    common one) and the image has more than a handful of distinct colours (lines, text and
    anti-aliasing), which an empty canvas or a single filled rectangle does not.
    """
    img = png_image(data)
    assert (img.shape[1], img.shape[0]) == tuple(size), f"image is {img.shape[1]}x{img.shape[0]}"
    flat = np.round(img.reshape(-1, img.shape[-1]) * 255).astype(np.uint8)
    colours, counts = np.unique(flat, axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    ink = np.mean(np.any(flat != background, axis=1))
    assert ink >= min_ink, f"only {ink:.2%} of the pixels are drawn"
    assert len(colours) > 16, f"only {len(colours)} colours: an empty plot"
    return img


def tiny_config(name: str, data: str, outputs: str = "figures = false\ntiming = false\n") -> str:
    """An experiment file for the command-line tests: a 160:1 joint, a small continuous model
    (polynomial order 2, three segments, no kinematic terms), no network, and the given `[data]`
    and `[outputs]` bodies (each a block of `key = value` lines)."""
    return (
        f'[experiment]\nname = "{name}"\n[joint]\nratio = 160\nrated_torque = 400\n'
        f"[data]\n{data}"
        '[model]\npoly_order = 2\nkinematic = "none"\nper_segment = false\nn_segments = 3\n'
        f"[network]\nenabled = false\n[outputs]\n{outputs}"
    )


def run_probe(script: str, args: list[str], env: dict) -> dict:
    """Run `script` (Python source that ends by printing one JSON line) in a fresh interpreter
    in the repository, with `args` as its `sys.argv[1:]`; return that JSON, or fail the test
    with the script's stderr."""
    out = subprocess.run(
        [sys.executable, "-c", script, *args], cwd=REPO, env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])
