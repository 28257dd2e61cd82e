"""The exported C estimator equals the JAX estimate: compiled with the system compiler under
`-std=c99 -Wall -Wextra -Werror -O2`, run on 10^5 samples through ctypes, compared with
`estimate_torque(..., causal=True)` / `predict_torque(..., causal=True)`.

Tolerances: double precision 1e-9 N·m (the C code repeats the JAX operations; what differs is
XLA's fused multiply-adds and its own tanh/exp, a few ulp of twists of ~1e-3 rad over
compliances of ~3e-5 rad/(N·m): ~1e-11 N·m measured); single precision 0.1 % of the rated
torque (float's 6e-8 relative on the twist, ~2e-5 N·m measured), its largest error printed.
Models: the paper's per-segment and shared layouts (eqs. (7)-(10), coefficients from
`tests/helpers.py`), one with a term of every effect family, one with the causal smoothed
velocity, and the network with Kalman-filtered current, raw and periodic angles. Seeds fixed.
"""

import dataclasses
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax import effects as fx, export, network as nw
from hdjax.compliance import ComplianceModel, estimate_torque

from .helpers import JOINT, sim_recording, true_coefficients

N = 100_000


@pytest.fixture(scope="session")
def compiler():
    cc = export.find_compiler()
    if cc is None:
        pytest.skip("no C compiler (cc, gcc or clang) on PATH: the C export is not checked here")
    return cc


def _with_truth(model: ComplianceModel, seed: int, effect_scale: float = 0.1) -> ComplianceModel:
    coef = true_coefficients(model, seed=seed)
    coef[model.n_coef - model.n_effect :] *= effect_scale  # effects a tenth of the base terms
    return eqx.tree_at(lambda m: m.coef, model, jnp.asarray(coef))


def every_effect_model() -> ComplianceModel:
    """The shared paper model with a term of every effect family the residual loop adds."""
    base = ComplianceModel.paper(JOINT, per_segment=False, poly_order=3, fourier_order=2)
    terms = (
        fx.Harmonics("theta_m", (2.0,)),
        fx.Harmonics("theta_l", (1.0, 3.0)),
        fx.Coulomb("omega_m", 0.5),
        fx.Coulomb("omega_l", 0.05),
        fx.Viscous("omega_l", 1.0),
        fx.Stribeck("omega_m", 0.5, 1.5),
        fx.TwistHysteresis(2.0, 3e-5),
        fx.TwistHysteresis(5.0, 3e-5, play=0.5),
        fx.Hysteresis(3.0),
        fx.Backlash(2.0),
        fx.Stiffening(90.0),
        fx.Ripple("theta_m", 2.0, 90.0),
        fx.TwistRate(101.0, 1.0, 0.01),
        fx.Column("temperature", 25.0, 1.0),
        fx.ColumnTimesTorque("temperature", 25.0, 1.0, 90.0),
        fx.EncoderSkew(delay=1.5e-3, ratio=160.0),
        fx.EncoderSkew(delay=-0.4e-3, ratio=160.0, sign=-1.0),
    )
    return _with_truth(base.with_effects(*terms), seed=3)


MODELS = {
    "paper_per_segment": lambda: _with_truth(ComplianceModel.paper(JOINT), seed=1),
    "paper_shared": lambda: _with_truth(ComplianceModel.paper(JOINT, per_segment=False), seed=2),
    "every_effect": every_effect_model,
    "smoothed_causal": lambda: _with_truth(
        ComplianceModel.paper(JOINT, per_segment=False, velocity="smoothed").with_effects(
            fx.Coulomb("omega_l", 0.05), fx.TwistRate(101.0, 1.0, 0.01)
        ),
        seed=4,
    ),
}


@dataclasses.dataclass
class Case:
    recording: hdjax.Recording
    torque: np.ndarray  # the JAX estimate with causal=True
    flags: np.ndarray
    kw: dict


@pytest.fixture(scope="module")
def model_cases():
    out = {}
    for name, make in MODELS.items():
        model = make()
        rec = export.synthetic_recording(JOINT, N, model=model, extras=("temperature",))
        torque, flags = export.expected(rec, JOINT, model=model)
        out[name] = Case(rec, torque, flags, {"model": model})
    return out


def _network(periodic: bool) -> nw.Network:
    lay = nw.make_layout(periodic=periodic, kalman=True)
    net = nw.Network(lay, (20,), key=jax.random.key(0))
    train = sim_recording(4000, seed=5)
    feats = nw.build_features(train, JOINT, periodic=periodic, kalman=True)
    return nw.standardise(net, feats.x, train.torque)


@pytest.fixture(scope="module")
def network_cases():
    out = {}
    for periodic in (False, True):
        net = _network(periodic)
        rec = export.synthetic_recording(JOINT, N, network=net)
        torque, flags = export.expected(rec, JOINT, network=net)
        out[periodic] = Case(rec, torque, flags, {"network": net})
    return out


def _c_code(case: Case, precision: str):
    if "model" in case.kw:
        model = case.kw["model"]
        return export.compliance_c(
            model, precision=precision, causal=model.velocity != "difference"
        )
    return export.network_c(case.kw["network"], JOINT, precision=precision)


def _run(case: Case, precision: str, tmp_path, compiler):
    lib = export.build_library(_c_code(case, precision), tmp_path)
    return lib.run(case.recording)


NETWORKS = {"network_raw_angles": False, "network_periodic_angles": True}


@pytest.mark.parametrize("name", list(MODELS) + list(NETWORKS))
@pytest.mark.parametrize("precision", ["double", "single"])
def test_c_equals_the_causal_jax_estimate(
    name, precision, model_cases, network_cases, tmp_path, compiler
):
    case = network_cases[NETWORKS[name]] if name in NETWORKS else model_cases[name]
    torque, flags = _run(case, precision, tmp_path, compiler)
    err = np.abs(torque - case.torque)
    print(f"{name}: {precision}, {N} samples, max |C - JAX| = {err.max():.3g} N·m")
    if precision == "double":
        assert err.max() <= 1e-9, (name, err.max(), int(err.argmax()))
        np.testing.assert_array_equal(flags, case.flags)
        # the recording leaves the calibrated range, so the flag is compared where it is set
        assert np.any(case.flags & 1) and not np.all(case.flags & 1), name
    else:
        print(f"  = {100 * err.max() / JOINT.rated_torque:.2e} % of the rated torque")
        assert err.max() <= 1e-3 * JOINT.rated_torque, (name, err.max())
    if name in MODELS:  # the recording sweeps the segments, some samples out of range
        assert np.ptp(case.torque) > 1.5 * JOINT.rated_torque


def test_causal_estimate_differs_from_the_recording_estimate_only_at_its_first_sample(
    model_cases,
):
    # velocity = "difference": only the first sample's velocity (the second's, or at rest)
    model = model_cases["paper_per_segment"].kw["model"]
    r = model_cases["paper_per_segment"].recording
    # angles away from 0 at the start, so that the kinematic terms read the first velocity
    rec = hdjax.make_recording(r.t, r.theta_m + 5.0, r.theta_l + 0.05, r.current)
    whole = np.asarray(estimate_torque(model, rec).torque)
    causal = np.asarray(estimate_torque(model, rec, causal=True).torque)
    assert whole[0] != causal[0]
    np.testing.assert_array_equal(whole[1:], causal[1:])


def test_smoothed_velocity_needs_its_causal_form(model_cases):
    model = model_cases["smoothed_causal"].kw["model"]
    with pytest.raises(hdjax.ExportError, match=r'velocity = "smoothed".*reads 5 samples ahead'):
        export.compliance_c(model)
    code = export.compliance_c(model, causal=True)
    assert "11 samples up to and including each one" in code.notes[0]
    # the causal velocity line is the centred one of 5 samples earlier (a pure delay)
    t = np.arange(200) * 1e-3
    theta = np.sin(3.0 * t) + 0.2 * t**2
    causal = np.asarray(hdjax.smoothed_velocity(t, theta, 5, causal=True))
    centred = np.asarray(hdjax.smoothed_velocity(t, theta, 5))
    np.testing.assert_allclose(causal[15:], centred[10:-5], rtol=0, atol=1e-12)
    assert causal[0] == 0.0


def test_every_registered_term_has_c_code_in_its_family_module():
    missing = [
        f"{family.name}: {cls.__name__}"
        for family in fx.families()
        for cls in family.terms
        if not export.has_c_code(cls)
    ]
    assert not missing, f"effect terms without c_code (hdjax export refuses them): {missing}"
    # one file per family: a term's C code lives beside its JAX and NumPy columns
    elsewhere = [
        f"{family.name}: {cls.__name__}.c_code in {cls.c_code.__module__}"
        for family in fx.families()
        for cls in family.terms
        if cls.c_code.__module__ != type(family).__module__
    ]
    assert not elsewhere, f"C code outside its family's module {elsewhere}"


def test_the_compared_models_hold_every_registered_term_type(model_cases):
    # the 10^5-sample comparison above runs every family's C code: a family registered later
    # fails here until every_effect_model holds a term of it
    held = {
        type(term)
        for case in model_cases.values()
        for term in case.kw["model"].base_terms + case.kw["model"].effect_terms
    }
    missing = [
        f"{family.name}: {cls.__name__}"
        for family in fx.families()
        for cls in family.terms
        if cls not in held
    ]
    assert not missing, f"no model of MODELS holds {missing}: add one to every_effect_model"


def test_the_network_flags_an_input_outside_its_training_spread(network_cases, tmp_path, compiler):
    case = network_cases[False]  # raw angles: theta_l is an input
    r, n = case.recording, 4000
    # both angles move 5 rad (the load's training spread is ~0.6 rad) over samples 1000-3000,
    # the twist unchanged
    shift = np.clip((np.arange(n) - 1000) / 2000, 0.0, 1.0) * 5.0
    rec = hdjax.make_recording(
        np.asarray(r.t)[:n],
        np.asarray(r.theta_m)[:n] + JOINT.ratio * shift,
        np.asarray(r.theta_l)[:n] + shift,
        np.asarray(r.current)[:n],
    )
    net = case.kw["network"]
    want, want_flags = export.expected(rec, JOINT, network=net)
    torque, flags = export.build_library(export.network_c(net, JOINT), tmp_path).run(rec)
    assert not np.any(want_flags[:1000] & 8) and np.all(want_flags[3000:] & 8)
    np.testing.assert_array_equal(flags, want_flags)
    assert np.max(np.abs(torque - want)) <= 1e-9


class NoCTerm(fx.AbstractSignalTerm):
    """A term of a user's family without C code."""

    signal: str = eqx.field(default="omega_m", static=True)

    key, names = fx.labels("noc:{signal}", "noc({signal})")

    def transform(self, x, xp):
        return x * x


def test_a_term_without_c_code_is_refused_with_its_name_and_family():
    model = _with_truth(ComplianceModel.paper(JOINT, per_segment=False).with_effects(NoCTerm()), 5)
    with pytest.raises(hdjax.ExportError, match=r"NoCTerm \(noc:omega_m.*has no C code"):
        export.compliance_c(model)


def test_a_hysteresis_state_from_the_first_motion_is_refused_as_noncausal():
    model = _with_truth(
        ComplianceModel.paper(JOINT, per_segment=False).with_effects(
            fx.TwistHysteresis(2.0, 3e-5, initial=-1.0)
        ),
        7,
    )
    with pytest.raises(hdjax.ExportError, match=r"TwistHysteresis.*first motion.*initial = 0"):
        export.compliance_c(model)


def test_a_term_reading_a_private_signal_is_refused():
    model = _with_truth(
        ComplianceModel.paper(JOINT, per_segment=False).with_effects(
            fx.Column("_torque_path", 0.0, 1.0)
        ),
        6,
    )
    with pytest.raises(hdjax.ExportError, match="'_torque_path'.*does not measure"):
        export.compliance_c(model)


def test_the_check_program_passes_its_vectors_and_fails_a_wrong_one(tmp_path, compiler):
    import subprocess

    from hdjax.modelfile import SavedModel

    model = MODELS["every_effect"]()
    saved = SavedModel(JOINT, model, None, {}, {})
    files = export.export_files(saved, n_vectors=500)
    assert set(files) == set(export.FILES)
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    export.compile_c(tmp_path, ["hdjax_estimator.c", "hdjax_check.c"], "hdjax_check")
    run = lambda csv: subprocess.run(  # noqa: E731
        [str(tmp_path / "hdjax_check"), csv], capture_output=True, text=True, cwd=tmp_path
    )
    done = run("test_vectors.csv")
    assert done.returncode == 0 and "500 samples" in done.stdout and "PASS" in done.stdout
    lines = (tmp_path / "test_vectors.csv").read_text().splitlines()
    cells = lines[300].split(",")
    cells[-2] = repr(float(cells[-2]) + 1e-6)  # one expected torque off by 1e-6 N·m
    lines[300] = ",".join(cells)
    (tmp_path / "wrong.csv").write_text("\n".join(lines) + "\n")
    done = run("wrong.csv")
    assert done.returncode == 1 and "FAIL" in done.stdout and "(sample 299)" in done.stdout


# ---------------------------------------------------------------------------------------------
# Encoder counts in: hdjax_sample_from_counts equals hdjax's reader of a count column

CPR_M, CPR_L = 2**23, 2**19  # a 23-bit motor and a 19-bit load encoder
BASE_M = 2**31 - 160_000_000  # multi-turn motor counts that cross 2^31 (int64, no wrap)
BASE_L = -123_456  # load counts below zero


def _counts_code(model, precision="double"):
    return export.counts_c(export.compliance_c(model, precision=precision), CPR_M, CPR_L)


def _counts_log(case: Case, path, motor_offset, load_offset):
    """The case's recording as a log of integer counts (a CSV with count columns, the offsets
    chosen so that the twist, and so the torque sweep, stays that of the case), its column map
    and the counts."""
    r = case.recording
    rad_m, rad_l = 2 * np.pi / CPR_M, 2 * np.pi / CPR_L
    ratio = JOINT.ratio
    # without offsets the load counts start where the motor's do, geared down (absolute
    # multi-turn encoders of an unloaded joint): the twist moves by under one load count
    base_l = BASE_L if motor_offset or load_offset else round(BASE_M * rad_m / ratio / rad_l)
    c_m = np.floor(np.asarray(r.theta_m) / rad_m).astype(np.int64) + BASE_M
    c_l = np.floor(np.asarray(r.theta_l) / rad_l).astype(np.int64) + base_l
    spec = {}
    if motor_offset == "first":  # load offset (rad) that keeps the twist
        off = -BASE_L * rad_l - float(r.theta_m[0]) / ratio
        spec = {"theta_m": "first", "theta_l": off}
    elif load_offset == "first":
        off = -BASE_M * rad_m - ratio * float(r.theta_l[0])
        spec = {"theta_m": off, "theta_l": "first"}
    else:
        spec = {"theta_m": None, "theta_l": None}
    columns = {}
    for name, source, cpr in (("theta_m", "enc_m", CPR_M), ("theta_l", "enc_l", CPR_L)):
        columns[name] = {"source": source, "counts_per_rev": cpr}
        if spec[name] is not None:
            columns[name]["offset"] = spec[name]
    cmap = hdjax.ColumnMap.from_dict({"columns": columns})
    t, cur, temp = (np.asarray(a) for a in (r.t, r.current, r.extras["temperature"]))
    rows = [
        f"{a!r},{m},{lo},{c!r},{k!r}"
        for a, m, lo, c, k in zip(
            t.tolist(), c_m.tolist(), c_l.tolist(), cur.tolist(), temp.tolist()
        )
    ]
    path.write_text("t,enc_m,enc_l,current,temperature\n" + "\n".join(rows) + "\n")
    return cmap, c_m, c_l, spec


@pytest.mark.parametrize(
    "motor_offset, load_offset",
    [("first", "number"), ("number", "first"), (None, None)],
    ids=["motor_first_load_rad", "motor_rad_load_first", "no_offset_null"],
)
def test_c_from_counts_equals_the_jax_estimate_of_the_counts_log(
    motor_offset, load_offset, model_cases, tmp_path, compiler
):
    case = model_cases["every_effect"]
    cmap, c_m, c_l, spec = _counts_log(case, tmp_path / "counts.csv", motor_offset, load_offset)
    assert c_m.min() < 2**31 < c_m.max(), "the motor counts cross 2^31"
    assert c_l.min() < 0 or motor_offset is None, "the load counts cross zero"
    rec = hdjax.load_recording(tmp_path / "counts.csv", cmap)  # hdjax's reader
    # the chunked reader (the map's "first" carried across chunks) reads the same angles
    chunked = hdjax.load_recording(tmp_path / "counts.csv", cmap, chunk=7777)
    np.testing.assert_array_equal(np.asarray(chunked.theta_m), np.asarray(rec.theta_m))
    np.testing.assert_array_equal(np.asarray(chunked.theta_l), np.asarray(rec.theta_l))
    model = case.kw["model"]
    want, want_flags = export.expected(rec, JOINT, model=model)
    assert np.ptp(want) > 1.5 * JOINT.rated_torque  # the counts sweep the segments
    lib = export.build_library(_counts_code(model), tmp_path, extra=("-pedantic",))
    x = lib.samples(rec)
    x[:, 1:3] = np.nan  # the angles come from the counts only
    zero, offset = None, (0.0, 0.0)
    if motor_offset is not None:
        zero = tuple(int(c[0]) if spec[k] == "first" else 0 for k, c in zip(spec, (c_m, c_l)))
        offset = tuple(0.0 if spec[k] == "first" else spec[k] for k in spec)
    torque, flags, stepped = lib.run_counts(x, c_m, c_l, zero=zero, offset=offset)
    err = np.abs(torque - want)
    print(f"counts ({motor_offset}, {load_offset}): {N} samples, max |C - JAX| = {err.max():.3g}")
    assert err.max() <= 1e-9, (err.max(), int(err.argmax()))
    np.testing.assert_array_equal(flags, want_flags)
    # and the angles the C code made of the counts are the reader's, to the bit
    np.testing.assert_array_equal(stepped[:, 1], np.asarray(rec.theta_m))
    np.testing.assert_array_equal(stepped[:, 2], np.asarray(rec.theta_l))


def test_the_count_conversion_is_the_readers_at_extreme_counts(tmp_path, compiler):
    # single precision (angles stay double); counts up to 2^53, negative, odd resolutions
    model = MODELS["paper_shared"]()
    code = export.counts_c(export.compliance_c(model, precision="single"), 5**11, 3 * 2**20)
    lib = export.build_library(code, tmp_path, extra=("-pedantic",))
    c_m = np.array([2**53, 2**53 - 1, -(2**53), 2**40 + 12345, 2**32 + 1, 2**31, -1, 0, 7])
    c_l = np.array([-(2**50) - 3, 2**31 - 1, 2**45 + 1, -(2**33), 1, 0, 2**52 + 11, 5, -7])
    x = np.zeros((c_m.size, 4))
    x[:, 0] = np.arange(c_m.size) * 1e-3
    for off_m, off_l in [(None, None), ("first", 0.25), (0.5, "first"), (-1e3, 2e-7)]:
        specs = [
            hdjax.ColumnMap.from_dict({"columns": {"theta_m": e}}).columns["theta_m"]
            for e in (
                {"source": "a", "counts_per_rev": 5**11, **({"offset": off_m} if off_m else {})},
                {
                    "source": "b",
                    "counts_per_rev": 3 * 2**20,
                    **({"offset": off_l} if off_l else {}),
                },
            )
        ]
        want_m, want_l = specs[0].apply(c_m), specs[1].apply(c_l)
        zero = (int(c_m[0]) if off_m == "first" else 0, int(c_l[0]) if off_l == "first" else 0)
        rad = tuple(0.0 if v in (None, "first") else v for v in (off_m, off_l))
        _, _, stepped = lib.run_counts(
            x, c_m, c_l, zero=None if off_m is None else zero, offset=rad
        )
        np.testing.assert_array_equal(stepped[:, 1], want_m, err_msg=f"motor {off_m}")
        np.testing.assert_array_equal(stepped[:, 2], want_l, err_msg=f"load {off_l}")
    assert "#define HDJAX_COUNTS_PER_REV_M 48828125LL" in code.header
    assert f"#define HDJAX_RAD_PER_COUNT_L {2 * np.pi / (3 * 2**20)!r}" in code.header


def test_counts_per_rev_come_from_the_joint_or_the_options():
    from hdjax.modelfile import SavedModel

    bits = dataclasses.replace(JOINT, encoder_bits_motor=21, encoder_bits_load=19)
    model = MODELS["paper_shared"]()
    header = lambda joint, **kw: export.export_files(  # noqa: E731
        SavedModel(joint, model, None, {}, {}), n_vectors=10, **kw
    )["hdjax_estimator.h"].decode()
    h = header(bits)
    assert "#define HDJAX_COUNTS_PER_REV_M 2097152LL" in h and "encoder_bits_motor = 21" in h
    assert "#define HDJAX_COUNTS_PER_REV_L 524288LL" in h
    h = header(bits, counts_per_rev_l=4096)  # an option overrides the joint
    assert "HDJAX_COUNTS_PER_REV_L 4096LL" in h and "--counts-per-rev-l 4096" in h
    assert "HDJAX_COUNTS_PER_REV_M 2097152LL" in h
    files = export.export_files(SavedModel(JOINT, model, None, {}, {}), n_vectors=10)
    assert "hdjax_sample_from_counts" not in files["hdjax_estimator.h"].decode()
    assert "--counts-per-rev-m N --counts-per-rev-l N" in files["README.md"].decode()
    with pytest.raises(hdjax.ConfigError, match="load encoder's resolution is unknown"):
        header(JOINT, counts_per_rev_m=4096)
    for bad in (0, -5, 2.5, True, "12x", 2**53 + 1):
        with pytest.raises(hdjax.ConfigError, match="whole number of encoder counts"):
            export.check_counts_per_rev(bad, "--counts-per-rev-m")


def _fused_multiply_add_flags() -> tuple[str, ...] | None:
    """Flags under which GCC contracts a multiply and an add across statements (its default
    `gnu` mode, with FMA instructions), where this CPU runs them; None elsewhere."""
    import platform

    if platform.machine() == "aarch64":
        return ("-std=gnu99",)
    if platform.machine() == "x86_64":
        try:
            flags = Path("/proc/cpuinfo").read_text().split()
        except OSError:
            return None
        return ("-std=gnu99", "-mfma") if "fma" in flags else None
    return None


def test_the_count_conversion_survives_fused_multiply_add(tmp_path, compiler):
    # GCC's default mode fuses `m *= scale; m += offset` into one multiply-add on FMA targets,
    # rounding once instead of twice: the angles then differ from the reader's by an ulp in a
    # share of the samples (the product goes through volatile, so they do not)
    flags = _fused_multiply_add_flags()
    if flags is None:
        pytest.skip("this CPU runs no fused multiply-add instruction the compiler can be asked for")
    code = export.counts_c(export.compliance_c(MODELS["paper_shared"](), precision="double"),
                           2**21, 3 * 2**20)  # fmt: skip
    lib = export.build_library(code, tmp_path, extra=flags)
    rng = np.random.default_rng(11)
    c_m = rng.integers(-(2**40), 2**40, 20000)
    c_l = rng.integers(-(2**30), 2**30, 20000)
    x = np.zeros((c_m.size, 4))
    x[:, 0] = np.arange(c_m.size) * 1e-3
    maps = [{"counts_per_rev": 2**21, "offset": 0.123456789}, {"counts_per_rev": 3 * 2**20,
            "offset": -2.5e-3}]  # fmt: skip
    want = [
        hdjax.ColumnMap.from_dict({"columns": {"theta_m": {"source": "a", **m}}})
        .columns["theta_m"]
        .apply(c)
        for m, c in zip(maps, (c_m, c_l))
    ]
    _, _, stepped = lib.run_counts(x, c_m, c_l, zero=(0, 0), offset=(0.123456789, -2.5e-3))
    np.testing.assert_array_equal(stepped[:, 1], want[0])
    np.testing.assert_array_equal(stepped[:, 2], want[1])
