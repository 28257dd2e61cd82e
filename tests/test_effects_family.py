"""A new effect family is one class and one `register` call: a toy family defined here, in the
test file, goes through simulate -> discover -> save -> load -> estimate with no other edit.

The toy is quadratic (aerodynamic-like) drag in the output bearing, $F = c\\,\\omega_l|\\omega_l|$.
The bearing sits between the flexspline and the torque sensor, so the flexspline carries
$T_{sensor} + F$ and the twist gains $k_1 c\\,\\omega_l|\\omega_l|$ that the sensor does not see:
the twist model needs the column $\\omega_l|\\omega_l|$. The loop is offered the toy and the
built-in viscous column of the same velocity (the closest competitor) and must name the toy.

Also: every registered term's NumPy reference equals its JAX columns; the registry refuses
colliding names; a saved model whose term type is not registered is refused with a message.
"""

import json
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jaxtyping import Array, Float

import hdjax
from hdjax import effects, export, plant
from hdjax.compliance import ComplianceModel, estimate_torque, signals_from_recording
from hdjax.discover import DiscoverOptions, LibraryOptions, discover, report_dict
from hdjax.modelfile import load_model, save_model

JOINT = hdjax.Joint(ratio=160, rated_torque=400)


# -- the toy family: everything a family needs, in one place ------------------------------------


class Drag(effects.AbstractSignalTerm):
    """Twist signature of quadratic drag: $\\omega|\\omega|/s^2$ of a velocity."""

    signal: str = effects.hyper("omega_l")
    scale: float = effects.hyper(1.0, positive=True)

    key, names = effects.labels("drag:{signal}", "{signal}|{signal}|/{scale}^2")

    def transform(self, x, xp):
        return x * xp.abs(x) / self.scale**2

    def c_code(self, c):
        # the column for the exported C estimator (docs/adding-an-effect.md)
        x = c.signal(self.signal)
        return effects.CSnippet(columns=(f"{x} * {c.fn('fabs')}({x}) / {c.num(self.scale**2)}",))


class QuadraticDrag(effects.AbstractFriction):
    """Drag torque $c\\,\\omega|\\omega|$ [N·m] (flat at rest: no slope to limit the step)."""

    coefficient: Float[Array, ""] = effects.bound("nonneg")

    def __call__(self, omega, inv=None):
        return self.coefficient * omega * jnp.abs(omega)

    def max_slope(self):
        return 0.0


class DragFamily(effects.AbstractFamily):
    """Quadratic drag of the output bearing (toy)."""

    name: ClassVar[str] = "toy_drag"
    terms: ClassVar[tuple] = (Drag,)
    plant_effects: ClassVar[tuple] = (
        QuadraticDrag.entry(
            "drag_l", "output_friction", lambda rated, k1, given: {"coefficient": 1.0}
        ),
    )
    discover_families: ClassVar[tuple] = ("drag:omega_l",)
    options: ClassVar[dict] = {"drag_scale_fractions": (1.0,)}

    def candidates(self, ctx):
        if not ctx.wants("drag:omega_l"):
            return []
        rms = float(np.sqrt(np.mean(np.asarray(ctx.sig.omega_l) ** 2)))
        fractions = ctx.option(self, "drag_scale_fractions")
        return [effects.Candidate.of(Drag("omega_l", f * rms)) for f in fractions if rms > 0]


@pytest.fixture(scope="module")
def toy():
    family = effects.register(DragFamily())  # the one registration line
    yield family
    effects.unregister(family)


@pytest.fixture(scope="module")
def recordings(toy):
    params = plant.song_params(
        defaults=False, effects={"wg_compliance": True, "drag_l": {"coefficient": 60.0}}
    )
    out = []
    for seed in (11, 12):
        rec = plant.simulate_scenario(
            "slow", key=jax.random.PRNGKey(seed), duration=20.0, params=params, output_period=4e-3
        )
        out.append(rec.select(np.asarray(rec.t) >= 0.5))
    return out


def test_toy_family_simulate_discover_save_load_estimate(toy, recordings, tmp_path):
    train, test = recordings
    assert "drag_l" in effects.plant_effect_names() and "drag:omega_l" in effects.vocabulary()
    # discover: offered the toy and its closest built-in competitor, it must name the toy
    options = DiscoverOptions(
        max_effects=1, library=LibraryOptions(families=("drag:omega_l", "viscous:omega_l"))
    )
    res = discover(train, test, JOINT, options)
    print(res.aux.effects, res.aux.baseline.rms, res.aux.final.rms, res.aux.final_ranking[:2])
    assert res.aux.effects == ["drag:omega_l"]
    assert res.aux.final.rms < 0.7 * res.aux.baseline.rms
    report = json.loads(json.dumps(report_dict(res)))
    assert "drag:omega_l" in report["vocabulary"]
    # save -> load: the toy term round-trips through the registry's type table
    model = res.value
    path = save_model(tmp_path / "model.json", JOINT, compliance=model)
    loaded = load_model(path).compliance
    assert isinstance(loaded, ComplianceModel)
    assert loaded.effect_terms == model.effect_terms
    assert isinstance(loaded.effect_terms[0], Drag)
    np.testing.assert_array_equal(np.asarray(loaded.coef), np.asarray(model.coef))
    # estimate with the loaded model: the same torque as the fitted one (same arrays in, same
    # program), and closer to the sensor than the starting model
    t_loaded = np.asarray(estimate_torque(loaded, test).torque)
    t_fitted = np.asarray(estimate_torque(model, test).torque)
    np.testing.assert_array_equal(t_loaded, t_fitted)
    rms = float(np.sqrt(np.mean((t_loaded - np.asarray(test.torque)) ** 2)))
    assert rms == pytest.approx(res.aux.final.rms, rel=1e-9)
    # the exported C step equals the causal estimate (its c_code, as the docs write it)
    if export.find_compiler() is not None:
        lib = export.build_library(export.compliance_c(loaded), tmp_path / "c")
        causal = np.asarray(estimate_torque(loaded, test, causal=True).torque)
        assert np.max(np.abs(lib.run(test)[0] - causal)) <= 1e-9


def test_unregistered_term_type_is_refused_with_a_message(toy, tmp_path):
    model = ComplianceModel.paper(JOINT).with_effects(Drag("omega_l", 0.5))
    d = model.to_dict()
    effects.unregister(toy)
    try:
        with pytest.raises(hdjax.HdjaxError, match="unknown term type 'Drag'.*registered"):
            ComplianceModel.from_dict(d)
    finally:
        effects.register(toy)
    assert ComplianceModel.from_dict(d).effect_terms == (Drag("omega_l", 0.5),)


def test_registry_refuses_collisions(toy):
    class Clash(DragFamily):
        name: ClassVar[str] = "clash"

    with pytest.raises(hdjax.HdjaxError, match="term type 'Drag' is already registered"):
        effects.register(Clash())
    assert effects.register(DragFamily()) is not None  # the same family again: a no-op
    assert effects.families().count(toy) == 1


def test_old_saved_terms_still_load():
    # the form earlier versions wrote: key and torque_kind stored with every term
    old = {"type": "Backlash", "width": 8.0, "key": "backlash:torque", "torque_kind": "memoryless"}
    assert ComplianceModel.paper(JOINT).with_effects(effects.Backlash(8.0)).effect_terms == (
        hdjax.compliance.term_from_dict(old),
    )
    bad = dict(old, torque_kind="none")
    with pytest.raises(hdjax.HdjaxError, match="incompatible version"):
        hdjax.compliance.term_from_dict(bad)


def _all_terms(rated):
    return [
        effects.Constant(),
        effects.CurrentPolynomial(order=4, scale=3.0),
        effects.PaperFourier(order=2),
        effects.Harmonics("theta_m", (1.0, 2.5)),
        effects.Harmonics("theta_l", (3.0,)),
        effects.Coulomb("omega_l", 0.05),
        effects.Stribeck("omega_m", 0.5, 2.0),
        effects.Ripple("theta_m", 2.0, rated),
        effects.Viscous("omega_m", 2.0),
        effects.Hysteresis(0.05 * rated),
        effects.TwistHysteresis(0.05 * rated, 1.5e-5),
        effects.TwistHysteresis(0.05 * rated, 1.5e-5, initial=-1.0),
        effects.TwistHysteresis(0.05 * rated, 1.5e-5, initial=-1.0, play=0.02 * rated),
        effects.EncoderSkew(delay=1.5e-3, ratio=160.0, sign=-1.0),
        effects.EncoderSkew(delay=-0.4e-3, ratio=160.0),
        effects.Backlash(0.02 * rated),
        effects.Stiffening(rated),
        effects.TwistRate(ratio=160.0, sign=-1.0, scale=0.01),
        effects.Column("temperature", 30.0, 2.0),
        effects.ColumnTimesTorque("temperature", 30.0, 2.0, rated),
    ]


def test_every_term_has_a_matching_numpy_reference(recordings):
    rec = recordings[1]
    sig = signals_from_recording(rec, JOINT.ratio)
    rng = np.random.default_rng(0)
    n = sig.n_samples
    sig = eqx.tree_at(lambda s: s.extras, sig, {"temperature": jnp.asarray(rng.normal(30, 2, n))})
    torque = jnp.asarray(rec.torque)
    terms = _all_terms(JOINT.rated_torque)
    # every registered built-in type is covered here
    assert {type(t) for t in terms} >= {t for t in effects.term_types() if t is not Drag}
    for term in terms:
        ref = term.numpy_columns(sig, torque)
        got = np.asarray(term.columns(sig, torque))
        assert got.shape == ref.shape == (n, len(term.names())), term
        # float64 elementwise maths: XLA's and NumPy's tanh/sin differ by a few ulp; the Dahl
        # scan accumulates rounding along the path
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12, err_msg=repr(term))
