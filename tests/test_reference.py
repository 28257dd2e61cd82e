"""hdjax.reference: DH kinematics, the pinocchio path, holds, the sensor offset, the builder and
the [data.reference] table."""

import math
import re

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import hdjax
from hdjax.reference import (
    UrdfArm,
    build_wrench_reference,
    check_reference,
    detect_holds,
    dh_arm,
    fit_offset_with_payload,
    forward_kinematics,
    jacobians,
    link_transform,
    offset_from_rest,
    rpy_matrix,
    tool_rotations,
)

SEED = 20261201


def _random_arm(rng, convention):
    """A random 6-joint arm and its tool mount `(xyz, rpy)`, the angles as drawn."""
    tool = rng.uniform(-0.2, 0.2, 3), rng.uniform(-np.pi, np.pi, 3)
    links = np.column_stack(
        [
            rng.uniform(-0.5, 0.5, 6),
            rng.uniform(-np.pi, np.pi, 6),
            rng.uniform(-0.5, 0.5, 6),
            rng.uniform(-np.pi, np.pi, 6),
        ]
    )
    return dh_arm(links, convention=convention, tool_xyz=tool[0], tool_rpy=tool[1]), tool


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_jacobian_matches_finite_differences_of_the_forward_kinematics(convention):
    # Reference: central differences of the tool pose (h = 1e-6 rad in float64: truncation
    # ~h^2 = 1e-12, rounding ~1e-16/h = 1e-10), so 1e-8 is a safe bound on a correct Jacobian.
    rng = np.random.default_rng(SEED)
    h = 1e-6
    fk = eqx.filter_jit(lambda arm, x: forward_kinematics(arm, x)[1])
    for _ in range(5):
        arm, _ = _random_arm(rng, convention)
        q = rng.uniform(-np.pi, np.pi, 6)
        pose = lambda x: np.asarray(fk(arm, jnp.asarray(x)))
        t0 = pose(q)
        jb = np.asarray(jacobians(arm, q[None], frame="base"))[0]
        jt = np.asarray(jacobians(arm, q[None], frame="tool"))[0]
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            tp, tm = pose(q + dq), pose(q - dq)
            v = (tp[:3, 3] - tm[:3, 3]) / (2 * h)
            dr = (tp[:3, :3] - tm[:3, :3]) / (2 * h)
            w_hat = dr @ t0[:3, :3].T  # skew(omega) in base axes
            w = np.array([w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]])
            np.testing.assert_allclose(jb[:, i], np.r_[v, w], atol=1e-8)
            r = t0[:3, :3]
            np.testing.assert_allclose(jt[:, i], np.r_[r.T @ v, r.T @ w], atol=1e-8)


def test_link_transform_conventions_closed_form():
    # one link, by hand: standard = Rz(t) Tz(d) Tx(a) Rx(al); modified = Rx(al) Tx(a) Rz(t) Tz(d)
    a, al, d, t = 0.3, 0.7, -0.2, 1.1
    ct, st, ca, sa = math.cos(t), math.sin(t), math.cos(al), math.sin(al)
    std = np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )
    mod = np.array(
        [
            [ct, -st, 0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0, 0, 0, 1],
        ]
    )
    np.testing.assert_allclose(np.asarray(link_transform(a, al, d, t)), std, atol=1e-15)
    got = np.asarray(link_transform(a, al, d, t, modified=True))
    np.testing.assert_allclose(got, mod, atol=1e-15)


def test_rpy_matrix_is_yaw_pitch_roll_by_hand():
    # URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll), each about the fixed base axes. By hand, roll
    # 90 deg then pitch 90 deg: Rx(90) takes y to z and z to -y, Ry(90) then takes z to -x and
    # x to z, so the frame's axes x, y, z point along base -z, x, -y. The other order (Rx Ry Rz)
    # puts them along base y, z, x, so this catches a swapped product.
    np.testing.assert_allclose(
        rpy_matrix(math.pi / 2, math.pi / 2, 0.0),
        [[0, 1, 0], [0, 0, -1], [-1, 0, 0]],
        atol=1e-15,
    )
    # yaw 90 deg then (applied first) roll 90 deg: x, y, z along base y, z, x
    np.testing.assert_allclose(
        rpy_matrix(math.pi / 2, 0.0, math.pi / 2),
        [[0, 0, 1], [1, 0, 0], [0, 1, 0]],
        atol=1e-15,
    )
    # generic angles: the product Rz Ry Rx written out element by element
    r, p, y = 0.3, -1.1, 2.4
    cr, sr, cp, sp, cy, sy = (f(v) for v in (r, p, y) for f in (math.cos, math.sin))
    closed = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    np.testing.assert_allclose(rpy_matrix(r, p, y), closed, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# URDF through pinocchio


def _rpy(r: np.ndarray) -> tuple[float, float, float]:
    """URDF rpy of a rotation matrix (R = Rz(y) Ry(p) Rx(r)), away from pitch = +-90 deg."""
    return (
        math.atan2(r[2, 1], r[2, 2]),
        math.asin(-max(-1.0, min(1.0, r[2, 0]))),
        math.atan2(r[1, 0], r[0, 0]),
    )


def _origin(t: np.ndarray) -> str:
    return _origin_of(t[:3, 3], _rpy(t[:3, :3]))


def _origin_of(xyz, rpy) -> str:
    xyz, rpy = (" ".join(f"{float(v):.17g}" for v in x) for x in (xyz, rpy))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _urdf_of(arm, masses=None, tool=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))) -> str:
    """A URDF with the same kinematics as a DH arm: T_i(q) = A_i Rz(q) B_i.

    The sensor mount is written from its angles `tool = (xyz, rpy)` as the arm was built from,
    not from `arm.tool`, so pinocchio's reading of URDF rpy checks hdjax's `rpy_matrix`."""
    modified = arm.convention == "modified"
    eye = np.eye(4)
    a_, b_ = [], []
    for i in range(arm.n_joints):
        a, al, d, th = (float(x[i]) for x in (arm.a, arm.alpha, arm.d, arm.theta_offset))
        if modified:
            a_.append(np.asarray(link_transform(a, al, 0.0, th, modified=True)))
            b_.append(np.asarray(link_transform(0.0, 0.0, d, 0.0, modified=True)))
        else:
            a_.append(np.asarray(link_transform(0.0, 0.0, 0.0, th)))
            b_.append(np.asarray(link_transform(a, al, d, 0.0)))
    inertial = lambda i: (
        ""
        if masses is None
        else f'<inertial><origin xyz="{masses[i][1]} 0 0"/><mass value="{masses[i][0]}"/>'
        f'<inertia ixx="1e-3" iyy="1e-3" izz="{masses[i][2]}" ixy="0" ixz="0" iyz="0"/>'
        "</inertial>"
    )
    parts = ['<robot name="arm">', '<link name="base"/>']
    prev = "base"
    for i in range(arm.n_joints):
        origin = (b_[i - 1] if i else eye) @ a_[i]
        parts += [
            f'<link name="l{i}">{inertial(i)}</link>',
            f'<joint name="j{i}" type="revolute"><parent link="{prev}"/><child link="l{i}"/>'
            f'{_origin(origin)}<axis xyz="0 0 1"/>'
            '<limit lower="-10" upper="10" effort="1" velocity="1"/></joint>',
        ]
        prev = f"l{i}"
    parts += [
        '<link name="flange"/>',
        f'<joint name="flange" type="fixed"><parent link="{prev}"/><child link="flange"/>'
        f"{_origin(b_[-1])}</joint>",
        '<link name="sensor"/>',
        '<joint name="mount" type="fixed"><parent link="flange"/><child link="sensor"/>'
        f"{_origin_of(*tool)}</joint>",
        "</robot>",
    ]
    return "\n".join(parts)


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_jacobian_matches_pinocchio_on_a_urdf(tmp_path, convention):
    # Independent computation: pinocchio's frame Jacobian (LOCAL / LOCAL_WORLD_ALIGNED) on a
    # URDF written from the same table and the tool mount's own angles (not from arm.tool, so
    # a wrong rotation order in rpy_matrix shows); both are exact, so agreement to 1e-10.
    pytest.importorskip("pinocchio")
    rng = np.random.default_rng(SEED + 1)
    arm, tool = _random_arm(rng, convention)
    path = tmp_path / "arm.urdf"
    path.write_text(_urdf_of(arm, tool=tool))
    urdf = UrdfArm(path, "sensor")
    q = rng.uniform(-np.pi, np.pi, (4, 6))
    for frame in ("tool", "base"):
        ours = np.asarray(jacobians(arm, q, frame=frame))
        theirs = np.stack([urdf.jacobian(x, frame=frame) for x in q])
        np.testing.assert_allclose(ours, theirs, atol=1e-10)
        np.testing.assert_allclose(
            ours[:, :, 2], urdf.jacobian_columns(q, 2, frame=frame), atol=1e-10
        )
    np.testing.assert_allclose(
        np.asarray(tool_rotations(arm, jnp.asarray(q))), urdf.tool_rotation(q), atol=1e-10
    )
    with pytest.raises(hdjax.ConfigError, match="no frame 'sensr'.*did you mean 'sensor'"):
        UrdfArm(path, "sensr")


def test_rnea_of_a_planar_two_link_arm_matches_the_closed_form(tmp_path):
    # Closed form (Spong et al. 2006, eq. (7.87)): link masses m_i with centres lc_i along the
    # link and inertias I_i about z, joints about z, gravity along -y in the arm's plane.
    pytest.importorskip("pinocchio")
    l1, m1, m2, lc1, lc2, i1, i2, g = 0.7, 2.0, 1.3, 0.35, 0.25, 0.05, 0.02, 9.81
    arm = dh_arm([[l1, 0, 0, 0], [0.5, 0, 0, 0]])
    # the URDF link frame of joint i sits at joint i, x along link i; centres at lc_i along x
    text = _urdf_of(arm, masses=[(m1, lc1, i1), (m2, lc2, i2)])
    path = tmp_path / "planar.urdf"
    path.write_text(text)
    urdf = UrdfArm(path, "sensor", gravity=(0.0, -g, 0.0))
    rng = np.random.default_rng(SEED + 2)
    for _ in range(5):
        q1, q2 = rng.uniform(-np.pi, np.pi, 2)
        c2 = math.cos(q2)
        # izz in the URDF is about the centre of mass; 1e-3 ixx/iyy do not act in the plane
        m11 = m1 * lc1**2 + i1 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * c2) + i2
        m12 = m2 * (lc2**2 + l1 * lc2 * c2) + i2
        m22 = m2 * lc2**2 + i2
        grav = np.array(
            [
                (m1 * lc1 + m2 * l1) * g * math.cos(q1) + m2 * lc2 * g * math.cos(q1 + q2),
                m2 * lc2 * g * math.cos(q1 + q2),
            ]
        )
        qd = rng.normal(size=2)
        qdd = rng.normal(size=2)
        h = -m2 * l1 * lc2 * math.sin(q2)
        cor = np.array([h * qd[1] * qd[0] * 2 + h * qd[1] ** 2, -h * qd[0] ** 2])
        truth = np.array([[m11, m12], [m12, m22]]) @ qdd + cor + grav
        got = urdf.rnea([q1, q2], qd, qdd)[0]
        np.testing.assert_allclose(got, truth, rtol=1e-10, atol=1e-10)
    # the same model torque through the builder (model_torque = "rnea", zero wrench), joint 2
    n = 40
    q = rng.uniform(-np.pi, np.pi, (n, 2))
    v, a = rng.normal(size=(n, 2)), rng.normal(size=(n, 2))
    cols = {"q1": q[:, 0], "q2": q[:, 1], "v1": v[:, 0], "v2": v[:, 1]}
    cols |= {"a1": a[:, 0], "a2": a[:, 1]}
    cols |= {f"w{i}": rng.normal(size=n) * (i == 0) for i in range(6)}  # only Fx, never held
    spec = check_reference(
        "[data.reference]",
        {
            "kind": "wrench",
            "joint": 2,
            "urdf": str(path),
            "frame": "sensor",
            "angles": ["q1", "q2"],
            "wrench": [f"w{i}" for i in range(6)],
            "model_torque": "rnea",
            "velocities": ["v1", "v2"],
            "accelerations": ["a1", "a2"],
            "gravity": [0.0, -g, 0.0],
        },
    )
    ref = build_wrench_reference(spec, cols, np.arange(n) * 0.01, base_dir=tmp_path)
    c2, s2, c12 = np.cos(q[:, 1]), np.sin(q[:, 1]), np.cos(q[:, 0] + q[:, 1])
    m21, m22 = m2 * (lc2**2 + l1 * lc2 * c2) + i2, m2 * lc2**2 + i2
    tau2 = m21 * a[:, 0] + m22 * a[:, 1] + m2 * l1 * lc2 * s2 * v[:, 0] ** 2 + m2 * lc2 * g * c12
    np.testing.assert_allclose(ref.model, tau2, rtol=1e-10, atol=1e-10)
    # Fx in the sensor (tip) frame: the tip x axis is along link 2, so J_2^T W = 0 for Fx
    np.testing.assert_allclose(ref.external, 0.0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Holds, offset and the builder on a simulated planar arm with known joint torques


def _planar_log(rng, n=600, hold_every=3, w0=None, payload=None, contact=True, rest=0.0):
    """A planar 2-link arm (joints about z, gravity -y) with a sensor at the tip.

    Returns raw columns, time, the fresh mask and the true joint-2 torque at every row:
    closed-form tau = tau_model + J^T F_ext (Spong eq. (4.110)) with J of the planar arm.
    """
    l2 = 0.5  # l1 = 0.7 does not enter joint 2's column
    t = np.cumsum(rng.uniform(0.003, 0.005, n))
    tm = np.maximum(t - t[0] - rest, 0.0)  # still, and unloaded, for the first `rest` seconds
    q1 = 0.8 * np.sin(1.3 * tm) + 0.2
    q2 = 1.1 * np.sin(0.7 * tm + 0.4)
    s12, c12 = np.sin(q1 + q2), np.cos(q1 + q2)
    # the external force on the arm at the tip, base axes, and a moment about z
    fb = np.zeros((n, 3))
    mb = np.zeros((n, 3))
    if contact:
        on = tm > 0
        fb[:, 0], fb[:, 1] = on * 5 * np.sin(2.1 * t), on * (-3 + 2 * np.cos(1.7 * t))
        mb[:, 2] = on * 0.4 * np.sin(3.1 * t)
    if payload is not None:  # a point mass m at distance cx along the tool x axis
        m, cx = payload
        fb[:, 1] += -m * 9.81
        mb[:, 2] += cx * c12 * (-m * 9.81)
    # what the joints must supply against it: tau = -J^T F_ext (+ the arm's own model torque)
    j2 = np.stack([-l2 * s12, l2 * c12], 1)
    ext2 = -(j2[:, 0] * fb[:, 0] + j2[:, 1] * fb[:, 1] + mb[:, 2])
    tau_model = 3.0 * np.cos(q1 + q2) + 0.1 * np.sin(t)
    # the sensor reports -F_ext (the wrench the arm applies) in tool axes: R = Rz(q1 + q2)
    c, s = c12, s12
    to_tool = lambda v: np.stack(
        [c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]], 1
    )
    w = -np.concatenate([to_tool(fb), to_tool(mb)], 1)
    if w0 is not None:
        w = w + w0
    w = w + 1e-9 * rng.standard_normal(w.shape)  # a real sensor never repeats a value exactly
    fresh = np.zeros(n, bool)
    k = 0
    while k < n:  # holds of irregular length around hold_every rows
        fresh[k] = True
        k += int(rng.integers(1, 2 * hold_every))
    idx = np.maximum.accumulate(np.where(fresh, np.arange(n), 0))
    w_held = w[idx]
    cols = {
        "q1": q1,
        "q2": q2,
        "tau_ff": tau_model,
        **{f"w{i}": w_held[:, i] for i in range(6)},
    }
    return cols, t, fresh, tau_model + ext2


def _planar_spec(tmp_path, **kw):
    (tmp_path / "planar_dh.toml").write_text(
        '[arm]\nconvention = "standard"\nlinks = [[0.7, 0, 0, 0], [0.5, 0, 0, 0]]\n'
    )
    table = {
        "kind": "wrench",
        "joint": 2,
        "dh": "planar_dh.toml",
        "angles": ["q1", "q2"],
        "wrench": [f"w{i}" for i in range(6)],
        "model_torque": "tau_ff",
        **kw,
    }
    return check_reference("[data.reference]", table)


def test_builder_reproduces_the_known_joint_torque_at_the_fresh_rows(tmp_path):
    # truth: the closed-form planar Jacobian; the builder only sees the held stream
    rng = np.random.default_rng(SEED + 3)
    cols, t, fresh, truth = _planar_log(rng)
    ref = build_wrench_reference(_planar_spec(tmp_path), cols, t, base_dir=tmp_path)
    np.testing.assert_array_equal(ref.fresh, fresh)
    np.testing.assert_allclose(ref.torque, truth[fresh], atol=1e-8)  # 1e-9 jitter
    # the wrench given in base axes with the base-frame Jacobian gives the same torque
    idx = np.maximum.accumulate(np.where(fresh, np.arange(t.size), 0))
    q12 = (cols["q1"] + cols["q2"])[idx]  # the pose when each held value was measured
    c, s = np.cos(q12), np.sin(q12)
    base = dict(cols)
    for f, (x, y) in ((0, (0, 1)), (1, (3, 4))):
        base[f"w{x}"] = c * cols[f"w{x}"] - s * cols[f"w{y}"]
        base[f"w{y}"] = s * cols[f"w{x}"] + c * cols[f"w{y}"]
    ref_b = build_wrench_reference(
        _planar_spec(tmp_path, wrench_frame="base"), base, t, base_dir=tmp_path
    )
    np.testing.assert_allclose(ref_b.torque, truth[fresh], atol=1e-8)
    # the wrong sign convention is a different torque (the check can fail)
    flipped = build_wrench_reference(
        _planar_spec(tmp_path, wrench_sign=-1), cols, t, base_dir=tmp_path
    )
    assert np.max(np.abs(flipped.torque - truth[fresh])) > 1.0


def test_holds_are_detected_and_never_interpolated():
    rng = np.random.default_rng(SEED + 4)
    n = 50
    t = np.arange(n) * 0.004
    fresh = rng.random(n) < 0.4
    fresh[0] = True
    values = rng.normal(size=(n, 6))
    idx = np.maximum.accumulate(np.where(fresh, np.arange(n), 0))
    held = values[idx]
    held[5:, 2] = held[5, 2]  # one channel constant from row 5 on: rows stay fresh by the others
    h = detect_holds(held, t)
    np.testing.assert_array_equal(h.fresh, fresh)
    assert h.n_fresh == fresh.sum() and h.held
    assert "only those rows are used" in h.describe()
    assert not detect_holds(values, t).held
    bad = held.copy()
    bad[7, 3] = np.nan
    with pytest.raises(hdjax.DataError, match="channel 4 at row 8"):
        detect_holds(bad, t)


def test_offset_fit_recovers_the_offset_and_the_payload(tmp_path):
    # truth: the offset and the payload the log was generated with. Noise-free the fit is
    # exact (1e-7 for the helper's 1e-9 jitter); with 0.05 N / N·m noise on 4 more seeds the
    # offset error stays within 5 of its reported standard errors and the torque error is the
    # noise's own plus the offset's.
    w0 = np.array([0.8, -1.5, 7.0, 0.05, -0.03, 0.02])
    for seed in range(5):
        rng = np.random.default_rng(SEED + 10 + seed)
        cols, t, fresh, truth = _planar_log(rng, w0=w0, payload=(2.5, 0.04), contact=False)
        if seed:
            noise = rng.normal(scale=0.05, size=(t.size, 6))
            idx = np.maximum.accumulate(np.where(fresh, np.arange(t.size), 0))
            for i in range(6):
                cols[f"w{i}"] = cols[f"w{i}"] + noise[idx, i]
        spec = _planar_spec(tmp_path, offset="fit", gravity=[0.0, -9.81, 0.0])
        ref = build_wrench_reference(spec, cols, t, base_dir=tmp_path)
        off = ref.offset
        if seed == 0:  # exact up to the helper's 1e-9 jitter
            np.testing.assert_allclose(off.wrench, w0, atol=1e-7)
            assert off.mass == pytest.approx(-2.5, abs=1e-7)  # reaction convention
        else:  # within 5 of the fit's own standard errors (the pooled noise is 0.05 here)
            assert np.all(np.abs(off.wrench - w0) < 5 * off.stderr), (off.wrench, off.stderr)
            assert off.mass == pytest.approx(-2.5, abs=0.2)
        err = ref.torque - truth[fresh]
        if seed == 0:
            np.testing.assert_allclose(err, 0.0, atol=1e-7)
        else:
            # the readings' noise passes into tau (std ~ hypot(0.5 * 0.05, 0.05) = 0.056) and
            # so does the offset's error (lever 0.5 m on Fx, Fy; Mz directly): 5 of its SEs
            se = off.stderr
            bound = 0.075 + 5 * (0.5 * np.hypot(se[0], se[1]) + se[5])
            assert np.sqrt(np.mean(err**2)) < bound
        # reported with the fitted numbers, on every seed: the mass to the 3 digits shown
        # (half a unit of the 3rd digit: 0.005 kg here) and near the truth
        shown = re.search(r"payload of (\S+) kg at \[(.*?)\] mm", off.describe())
        assert shown, off.describe()
        assert abs(float(shown[1]) - off.mass) <= 0.005 and abs(float(shown[1]) + 2.5) < 0.2
        com = [float(v) for v in shown[2].split(", ")]
        np.testing.assert_allclose(com, 1e3 * np.asarray(off.com), atol=0.05)  # mm, 1 decimal
    # a single pose cannot separate offset and payload: refused
    rot = np.repeat(np.eye(3)[None], 20, axis=0)
    with pytest.raises(hdjax.CalibrationError, match="confounded"):
        fit_offset_with_payload(np.ones((20, 6)), rot, (0, 0, -9.81))


def test_offset_from_a_rest_window(tmp_path):
    rng = np.random.default_rng(SEED + 20)
    w0 = np.array([0.4, 0.2, -3.0, 0.01, 0.02, -0.01])
    cols, t, fresh, truth = _planar_log(rng, w0=w0, rest=0.3)
    spec = _planar_spec(tmp_path, offset="rest", rest=[0.0, 0.3])
    ref = build_wrench_reference(spec, cols, t, base_dir=tmp_path)
    np.testing.assert_allclose(ref.offset.wrench, w0, atol=1e-8)  # the 1e-9 jitter
    np.testing.assert_allclose(ref.torque, truth[fresh], atol=1e-8)
    assert "at rest in 0..0.3 s" in ref.offset.describe()
    with pytest.raises(hdjax.DataError, match="holds 0 fresh"):
        offset_from_rest(np.ones((5, 6)), np.arange(5.0), (10.0, 11.0))


# ---------------------------------------------------------------------------------------------
# The [data.reference] table

_OK = {
    "kind": "wrench",
    "joint": 1,
    "dh": "arm.toml",
    "angles": ["q1"],
    "wrench": ["a", "b", "c", "d", "e", "f"],
    "model_torque": "none",
}


@pytest.mark.parametrize(
    "change, message",
    [
        ({"kind": "wrenh"}, "kind must be one of column, wrench, got 'wrenh' (did you mean"),
        ({"joint": 0}, "joint must be a positive integer"),
        ({"joint": 2}, "joint = 2 but angles names only 1 joints"),
        ({"wrench": ["a", "b"]}, "wrench must name 6 columns"),
        ({"urdf": "x.urdf"}, "exactly one of 'dh'"),
        ({"wrench_frame": "world"}, "wrench_frame must be"),
        ({"wrench_sign": 2}, "wrench_sign must be 1 or -1"),
        ({"model_torque": "rnea"}, "needs a URDF"),
        ({"offset": "rest"}, "needs rest = [t0, t1]"),
        ({"offset": "fit", "wrench_frame": "base"}, 'needs wrench_frame = "tool"'),
        ({"offest": "none"}, "unknown key 'offest' (did you mean 'offset'"),
        ({"rest": [0, 1]}, "'rest' is used only with offset"),
    ],
)
def test_reference_table_errors_are_one_line(change, message):
    table = {**_OK, **change}
    with pytest.raises(hdjax.ConfigError) as err:
        check_reference("[data.reference]", table)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_reference_in_an_experiment_file(tmp_path):
    from hdjax.config import resolve

    base = {"joint": {"ratio": 100, "rated_torque": 50}}
    cfg = resolve({**base, "data": {"kind": "synthetic"}})
    assert cfg["data"]["reference"] == {"kind": "column"}
    files = {"kind": "files", "train": ["a.csv"], "split": 0.3}
    cfg = resolve({**base, "data": {**files, "reference": _OK}})
    assert cfg["data"]["reference"]["offset"] == "none"  # defaults filled in
    with pytest.raises(hdjax.ConfigError, match='needs \\[data\\] kind = "files"'):
        resolve({**base, "data": {"kind": "synthetic", "reference": _OK}})
    with pytest.raises(hdjax.ConfigError, match="remove torque from"):
        resolve({**base, "data": {**files, "columns": {"torque": "x"}, "reference": _OK}})
    with pytest.raises(hdjax.ConfigError, match='kind = "column" takes no other keys'):
        resolve({**base, "data": {**files, "reference": {"kind": "column", "joint": 3}}})


def test_a_column_reference_is_named_in_the_dataset(tmp_path):
    from hdjax import save_csv
    from hdjax.config import experiment_from_dict
    from hdjax.pipelines import build_dataset, synthetic_recording

    joint = {"ratio": 100, "rated_torque": 50}
    rec = synthetic_recording(hdjax.Joint(**joint), 200, seed=0)
    save_csv(rec, tmp_path / "log.csv")
    # a synthetic log at 1 kHz moves fast; the units check would take it for degrees
    files = {"kind": "files", "train": ["log.csv"], "split": 0.3, "check_units": False}
    exp = experiment_from_dict({"joint": joint, "data": files}, base_dir=tmp_path)
    ds = build_dataset(exp)
    assert ds.reference == {
        "kind": "column",
        "description": "reference: the log column 'torque' ([data.columns] torque)",
    }
    assert ds.provenance[-1] == ds.reference["description"]
