"""The compliance-ripple and Stribeck families: the plant side, the candidates, and the loop on
plant draws against the true structure refitted.

- **Plant**: with a ripple $\\varepsilon(\\theta)$ on, the elastic torque in the first segment
  is $d_{eff} / (k_1 (1 + \\varepsilon))$ (closed form, computed here independently).
- **Candidates**: the ripple's order comes from the spectrum of residual ÷ torque: a synthetic
  residual $\\varepsilon k T \\sin(K\\theta + \\varphi)$ plus noise gives a spectrum peak at $K$.
- **Loop**: on plant draws (drawn amplitudes, phases, levels and Stribeck speeds; TRAIN and
  TEST from different seeds; 12 s at 4 ms, simulated as one batch), the loop names
  `ripple:theta_m:2` for a 2-per-motor-revolution ripple of 2-5 % and `stribeck:omega_l` for
  output-bearing Stribeck friction, and its TEST torque RMS stays within 1.5x that of the true
  structure refitted by the same pipeline. On the same joints with the Stribeck peak set to zero
  (plain Coulomb friction) it names Coulomb and no Stribeck.
- **Output-side ripple**: a 2-per-output-revolution ripple of 2-5 % (an oval output bearing or
  flexspline, plant `ripple_l`) on a link that swings ±360° under a gravity load whose arm
  changes once per 10 s period (20 s at 4 ms, so the load is not one function of the angle): the
  loop names `ripple:theta_l:2` (not the kinematic orders 1 and 3 that $T \\sin 2\\theta_l$ with
  $T \\propto \\cos\\theta_l$ also contains) and reaches the true structure. Order 1 is offered
  only over three output revolutions (`ripple_min_periods`).
- **Motor-side Stribeck friction** (plant `stribeck_m` with `coulomb_m`): the motor's friction
  enters the current, not the transmitted torque that the twist follows, and the starting
  model's torque segments carry the compliance, so on the bench it leaves nothing in the twist:
  the true structure refitted is no better than the starting model, and the loop must add no
  friction term of either side.

The draws on the `slow` and `fast` scenarios share one structure (ripple, Coulomb and Stribeck
effects all switched on, the absent ones at zero amplitude), so they are one compiled
simulation; the swing of the output-side ripple is another.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import effects, plant
from hdjax.compliance import ComplianceModel, signals_from_recording
from hdjax.discover import DiscoverOptions, LibraryOptions, build_library, discover, refit_structure
from hdjax.effects import Coulomb, Ripple, Stribeck

from .discover_batch import simulate_draws

JOINT = hdjax.Joint(ratio=160, rated_torque=400)
RATED = 400.0
OPTIONS = DiscoverOptions(max_effects=2, current_scale=10.0)
# the ripple is the one true effect: one step shows it is named first and reaches the truth
RIPPLE_OPTIONS = DiscoverOptions(max_effects=1, current_scale=10.0)
N_DRAWS = 2


def _params(ripple=0.0, phase=0.0, level=0.0, peak=0.0, speed=0.02, motor=(0.0, 0.0, 2.0)):
    level_m, peak_m, speed_m = motor
    eff = {
        "wg_compliance": True,
        "ripple_m": dict(orders=[2.0], amplitudes=[ripple], phases=[phase]),
        "coulomb_l": dict(level=level, smoothing=5e-3),
        "stribeck_l": dict(peak=peak, speed=speed, smoothing=5e-3),
        "coulomb_m": dict(level=level_m, smoothing=0.5),
        "stribeck_m": dict(peak=peak_m, speed=speed_m, smoothing=0.5),
    }
    return plant.song_params(defaults=False, effects=eff, damping=0.0)


@pytest.fixture(scope="module")
def draws():
    """`{kind: [(train, test, true terms), ...]}` for kinds ripple, stribeck, coulomb and
    stribeck_m (motor-side Coulomb and Stribeck friction)."""
    rng = np.random.default_rng(1402)
    specs = []
    for _ in range(N_DRAWS):
        amp, phase = rng.uniform(0.02, 0.05), rng.uniform(0.0, 2 * math.pi)
        specs.append(
            ("ripple", "slow", _params(ripple=amp, phase=phase), [Ripple("theta_m", 2.0, RATED)])
        )
    for _ in range(N_DRAWS):
        level, peak, speed = rng.uniform(4, 8), rng.uniform(10, 20), rng.uniform(0.015, 0.04)
        true = [Coulomb("omega_l", 5e-3), Stribeck("omega_l", 5e-3, speed)]
        specs.append(("stribeck", "fast", _params(level=level, peak=peak, speed=speed), true))
        # the same joint without the Stribeck excess: plain Coulomb friction
        specs.append(("coulomb", "fast", _params(level=level, speed=speed), true[:1]))
    for _ in range(N_DRAWS):
        motor = rng.uniform(0.15, 0.3), rng.uniform(0.2, 0.4), rng.uniform(1.0, 3.0)
        true = [Coulomb("omega_m", 0.5), Stribeck("omega_m", 0.5, motor[2])]
        specs.append(("stribeck_m", "fast", _params(motor=motor), true))
    params = [p for _, _, p, _ in specs for _ in (0, 1)]
    scenarios = [s for _, s, _, _ in specs for _ in (0, 1)]
    recs = simulate_draws(
        params, scenarios, range(500, 500 + len(params)), duration=12.0, output_period=4e-3
    )
    out = {}
    for i, (kind, _, _, true) in enumerate(specs):
        out.setdefault(kind, []).append((recs[2 * i], recs[2 * i + 1], true))
    return out


# -- the plant side ------------------------------------------------------------------------------


def test_plant_ripple_scales_the_compliance():
    amp, phase = 0.04, 0.7
    p = plant.song_params(
        defaults=False, effects={"ripple_m": dict(orders=[2.0], amplitudes=[amp], phases=[phase])}
    )
    k1 = float(p.compliance[0])
    theta_m = jnp.linspace(-3.0, 3.0, 7)
    d = 20.0 * k1  # a deflection inside the first segment (|T| < rated / 3)
    state = plant.PlantState(
        theta_m=theta_m,
        omega_m=0.0 * theta_m,
        theta_l=theta_m / 160.0 - d,
        omega_l=0.0 * theta_m,
        current=0.0 * theta_m,
        z=0.0 * theta_m,
        temperature=25.0 + 0.0 * theta_m,
    )
    got = np.asarray(plant.flexspline_torque(p, state))
    # the recorded motor angle is -theta_m (see hdjax/plant/_dynamics.py)
    eps = amp * np.sin(2.0 * -np.asarray(theta_m) + phase)
    np.testing.assert_allclose(got, d / (k1 * (1.0 + eps)), rtol=1e-12)


def test_plant_refuses_a_ripple_that_is_not_a_few_percent():
    with pytest.raises(hdjax.HdjaxError, match="sum to less than"):
        plant.make_effect("ripple_m", amplitudes=[0.6])


def test_every_new_term_has_a_matching_numpy_reference(draws):
    train = draws["ripple"][0][0]
    sig = signals_from_recording(train, JOINT.ratio)
    torque = jnp.asarray(train.torque)
    for term in (
        Ripple("theta_m", 2.0, RATED),
        Ripple("theta_l", 1.5, RATED),
        Stribeck("omega_l", 0.005, 0.02),
    ):
        ref = term.numpy_columns(sig, torque)
        got = np.asarray(term.columns(sig, torque))
        assert got.shape == ref.shape == (sig.n_samples, len(term.names()))
        # float64 elementwise maths: XLA's and NumPy's sin/exp/tanh differ by a few ulp
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12, err_msg=repr(term))
    # the inversion's slope for the group is u(theta) @ c
    term, c = Ripple("theta_m", 2.0, RATED), jnp.asarray([0.3, -0.2])
    u = term.numpy_torque_slope(sig)
    np.testing.assert_allclose(np.asarray(term.torque_gain(sig, c)), u @ np.asarray(c), rtol=1e-12)


def test_ripple_order_comes_from_the_spectrum_of_residual_over_torque(draws):
    train = draws["ripple"][0][0]
    sig = signals_from_recording(train, JOINT.ratio)
    torque = np.asarray(train.torque)
    theta = np.asarray(sig.theta_m)
    rng = np.random.default_rng(0)
    k1 = 1.0 / 6.7e4
    resid = 0.03 * k1 * torque * np.sin(2.7 * theta + 0.4) + rng.normal(0, 2e-7, theta.size)
    options = LibraryOptions(families=("ripple:theta_m",), ripple_named_orders_m=())
    model = ComplianceModel.paper(hdjax.Joint(ratio=160.0, rated_torque=RATED))
    cands, spectra = build_library(sig, torque, resid, model, options=options)
    assert spectra == {}  # the residual ÷ torque spectrum is not the residual's
    peaks = [c.term.order for c in cands if c.origin == "spectrum"]
    assert peaks and abs(peaks[0] - 2.7) < 0.01, peaks
    assert all(
        isinstance(c.term, Ripple) and c.key == effects.ripple_key("theta_m", c.term.order)
        for c in cands
    )


# -- the loop on plant draws ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def output_ripple():
    """`[(train, test, true terms), ...]`: drawn 2-per-output-revolution ripples, ±360° swing."""
    rng = np.random.default_rng(1404)
    params, true = [], []
    for _ in range(N_DRAWS):
        amp, phase = rng.uniform(0.02, 0.05), rng.uniform(0.0, 2 * math.pi)
        eff = {
            "wg_compliance": True,
            "ripple_l": dict(orders=[2.0], amplitudes=[amp], phases=[phase]),
        }
        params += [plant.song_params(defaults=False, effects=eff, damping=0.0)] * 2
        true.append([Ripple("theta_l", 2.0, RATED)])
    recs = simulate_draws(
        params,
        ["slow"] * len(params),
        range(600, 600 + len(params)),
        duration=20.0,
        output_period=4e-3,
        swing=(2 * math.pi, 10.0),
    )
    return [(recs[2 * i], recs[2 * i + 1], t) for i, t in enumerate(true)]


def _run(train, test, true, options=OPTIONS):
    res = discover(train, test, JOINT, options).aux
    ref = refit_structure(train, test, JOINT, true, OPTIONS)
    print(res.effects, res.baseline.rms, res.final.rms, ref.rms)
    return res, ref


@pytest.mark.slow
def test_loop_names_a_compliance_ripple(draws):
    for train, test, true in draws["ripple"]:
        res, ref = _run(train, test, true, RIPPLE_OPTIONS)
        assert res.effects and res.effects[0] == "ripple:theta_m:2", res.effects
        assert res.final.rms <= 1.5 * ref.rms, (res.final.rms, ref.rms)


@pytest.mark.slow
def test_loop_names_stribeck_friction_and_keeps_coulomb_for_coulomb(draws):
    for train, test, true in draws["stribeck"]:
        res, ref = _run(train, test, true)
        assert "stribeck:omega_l" in res.effects, res.effects
        assert res.final.rms <= 1.5 * ref.rms, (res.final.rms, ref.rms)
    for train, test, true in draws["coulomb"]:
        res, ref = _run(train, test, true)
        assert "coulomb:omega_l" in res.effects, res.effects
        assert not any(k.startswith("stribeck") for k in res.effects), res.effects
        assert res.final.rms <= 1.5 * ref.rms, (res.final.rms, ref.rms)


@pytest.mark.slow
def test_loop_names_an_output_side_compliance_ripple(output_ripple):
    for train, test, true in output_ripple:
        res, ref = _run(train, test, true, RIPPLE_OPTIONS)
        assert res.effects == ["ripple:theta_l:2"], res.effects
        assert res.final.rms <= 1.5 * ref.rms, (res.final.rms, ref.rms)


@pytest.mark.slow
def test_motor_side_stribeck_leaves_nothing_in_the_twist_and_nothing_is_added(draws):
    for train, test, true in draws["stribeck_m"]:
        res, ref = _run(train, test, true)
        # the true structure gains nothing over the starting model: nothing to find
        assert ref.rms >= 0.98 * res.baseline.rms, (ref.rms, res.baseline.rms)
        assert res.effects == [], res.effects
        assert res.final.rms <= 1.5 * ref.rms, (res.final.rms, ref.rms)
