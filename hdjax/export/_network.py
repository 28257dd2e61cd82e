r"""The back-propagation network's step in C, with its Kalman-filtered current (Song et al.
2019, Section III).

Per sample, as [`hdjax.network.predict_torque`][] with `causal=True` computes it:

1. the scalar Kalman filter on the current, eqs. (31)-(35) (started at the first current with
   the paper's $P_0$, as [`hdjax.network.kalman_filter`][]), when the network was trained on
   the filtered current;
2. the input vector after eq. (28): current, angles (or their sines and cosines), causal
   velocities (eqs. (13)-(14)) and the twist (eq. (5));
3. the stored standardisation, the sigmoid hidden layers (eqs. (38)-(39)) and the linear
   output (eq. (40)), then the torque's own scale.

The network stores no calibrated torque range; `HDJAX_OUT_OF_RANGE` marks a torque beyond the
joint's rated torque, and `HDJAX_INPUT_OUTSIDE` an input more than
[`INPUT_SIGMAS`][] standard deviations from its training mean.
"""

from __future__ import annotations

import numpy as np

from .._errors import ExportError
from .._joint import Joint
from ..network import PAPER_P0, PAPER_Q, PAPER_R, Network
from ._assemble import CCode, StepParts, assemble
from ._causal import velocity_notes
from ._emitter import Emitter, helpers

INPUT_SIGMAS = 4.0
"""How far (in training standard deviations) an input may lie from its training mean before the
step sets `HDJAX_INPUT_OUTSIDE`."""


def _array(name: str, values, em: Emitter) -> str:
    arr = np.asarray(values, np.float64)
    if arr.ndim == 1:
        body = ", ".join(em.num(v) for v in arr)
        return f"static const {em.real} {name}[{arr.shape[0]}] = {{{body}}};"
    rows = ",\n    ".join("{" + ", ".join(em.num(v) for v in row) + "}" for row in arr)
    return f"static const {em.real} {name}[{arr.shape[0]}][{arr.shape[1]}] = {{\n    {rows}}};"


def _feature(name: str, em: Emitter, current: str) -> str:
    """The C expression of one input of the layout (see `hdjax.network.make_layout`)."""
    if name == "current":
        return current
    if name in ("theta_m", "theta_l", "omega_m", "omega_l", "twist"):
        return em.signal(name)
    for fn in ("sin", "cos"):
        if name.startswith(fn) and "_" in name:
            order, angle = name[len(fn) :].split("_", 1)
            if order.isdigit() and angle in ("theta_m", "theta_l"):
                # jnp.sin of k * theta, both in double; libm's in double precision, hdjax's
                # reduction then the float kernel in single
                arg = f"{em.dnum(float(order))} * {em.angle(angle)}"
                if em.real == "double":
                    return f"{fn}({arg})"
                return f"hdjax_{fn}f({arg})"
    raise ExportError(f"the network's input {name!r} has no C code")


def network_c(
    network: Network, joint: Joint, *, precision: str = "double", causal: bool = False
) -> CCode:
    r"""The C code of a trained network's per-sample estimate (Song et al. eqs. (29)-(41)).

    **Arguments:**

    - `network`: a trained [`hdjax.network.Network`][].
    - `joint`: the [`hdjax.Joint`][] (ratio and twist sign of eq. (5), rated torque).
    - `precision`: `"double"` (equals [`hdjax.network.predict_torque`][] with `causal=True` to
      rounding) or `"single"`.
    - `causal`: accepted for symmetry with [`hdjax.export.compliance_c`][]; the network's
      inputs are causal already (but for the first sample's velocity, see the notes).

    **Returns:** a [`hdjax.export.CCode`][].
    """
    if not isinstance(network, Network):
        raise ExportError(f"network_c exports an hdjax.network.Network, got {type(network)}")
    em = Emitter(precision)
    R, n = em.real, em.num
    lay = network.layout
    notes = velocity_notes("the network", "difference", causal, 5)
    states, body = [], []
    if lay.kalman:
        # eqs. (31)-(35): predict, gain, update, from the first current and P0 (see kalman.py)
        states += [
            (f"{R} kf_mu; /* the Kalman-filtered current [A] */", "s->kf_mu = 0;"),
            (f"{R} kf_p; /* its variance */", "s->kf_p = 0;"),
        ]
        body += [
            "/* -- the Kalman filter on the current, eqs. (31)-(35) */",
            f"if ({em.first}) {{ s->kf_mu = {em.signal('current')}; s->kf_p = {n(PAPER_P0)}; }}",
            "{",
            f"    const {R} p_bar = s->kf_p + {n(PAPER_Q)};",
            f"    const {R} gain = p_bar / (p_bar + {n(PAPER_R)});",
            f"    s->kf_mu = s->kf_mu + gain * ({em.signal('current')} - s->kf_mu);",
            f"    s->kf_p = ({n(1.0)} - gain) * p_bar;",
            "}",
        ]
        current = "s->kf_mu"
    else:
        current = em.signal("current")
    feats = [_feature(name, em, current) for name in lay.names]
    n_in = len(feats)
    weights = [np.asarray(w, np.float64) for w in network.weights]
    biases = [np.asarray(b, np.float64) for b in network.biases]
    consts = [
        _array("x_mean", network.x_mean, em),
        _array("x_scale", network.x_scale, em),
    ]
    for i, (w, b) in enumerate(zip(weights, biases)):
        consts += [_array(f"w{i}", w, em), _array(f"b{i}", b, em)]
    body += ["/* -- the input vector after eq. (28), standardised */"]
    body += [f"{R} z[{n_in}];", "int i, j;"]
    body += [f"z[{i}] = {f};" for i, f in enumerate(feats)]
    body += [
        f"for (i = 0; i < {n_in}; ++i) {{",
        "    z[i] = (z[i] - x_mean[i]) / x_scale[i];",
        f"    if (!(z[i] <= {n(INPUT_SIGMAS)} && z[i] >= {n(-INPUT_SIGMAS)})) "
        "flags |= HDJAX_INPUT_OUTSIDE;",
        "}",
    ]
    prev, width = "z", n_in
    for layer, w in enumerate(weights[:-1]):
        out = w.shape[1]
        body += [
            f"/* -- hidden layer {layer + 1}: sigmoid, eqs. (38)-(39) */",
            f"{R} a{layer}[{out}];",
            f"for (j = 0; j < {out}; ++j) {{",
            f"    {R} acc = {prev}[0] * w{layer}[0][j];",
            f"    for (i = 1; i < {width}; ++i) acc = acc + {prev}[i] * w{layer}[i][j];",
            f"    a{layer}[j] = {n(1.0)} / ({n(1.0)} + {em.fn('exp')}(-(acc + b{layer}[j])));",
            "}",
        ]
        prev, width = f"a{layer}", out
    last = len(weights) - 1
    rated = joint.rated_torque
    body += [
        "/* -- the linear output, eq. (40), in N m */",
        "{",
        f"    {R} acc = {prev}[0] * w{last}[0][0];",
        f"    for (i = 1; i < {width}; ++i) acc = acc + {prev}[i] * w{last}[i][0];",
        f"    acc = acc + b{last}[0];",
        f"    torque = (double)({n(float(network.y_mean))} + {n(float(network.y_scale))} * acc);",
        "}",
        f"if (!(torque >= {n(-rated)} && torque <= {n(rated)})) flags |= HDJAX_OUT_OF_RANGE;",
    ]
    helper = ""
    if em.real != "double" and any(name[:3] in ("sin", "cos") for name in lay.names):
        helper = f"""\
static inline {R} hdjax_sinf(double x) {{ {R} s, c; hdjax_sincos(x, &s, &c); return s; }}
static inline {R} hdjax_cosf(double x) {{ {R} s, c; hdjax_sincos(x, &s, &c); return c; }}
"""
    hidden = "-".join(str(h) for h in network.hidden)
    description = (
        f"the back-propagation network of Song et al. (2019), eqs. (29)-(41): {n_in} inputs, "
        f"hidden layers {hidden}, {'Kalman-filtered' if lay.kalman else 'raw'} current, "
        f"{precision} precision"
    )
    parts = StepParts(
        emitter=em,
        states=tuple(states),
        helpers=(helper, "\n".join(consts) + "\n"),
        body=tuple(body),
        flags=("HDJAX_OUT_OF_RANGE", "HDJAX_INPUT_OUTSIDE"),
        description=description,
    )
    return assemble(
        parts,
        ratio=joint.ratio,
        twist_sign=joint.twist_sign,
        velocity="difference",
        half_window=5,
        precision=precision,
        kind="network",
        notes=notes,
        helpers=helpers(R),
    )
