r"""The compliance model's step in C: Song et al. eqs. (26)-(27), one sample at a time.

The generated step follows [`hdjax.compliance.estimate_torque`][] operation for operation, so
that it equals the JAX estimate of the same recording (with `causal=True`) to rounding:

1. the signals of the sample (eq. (5), backward difference or the trailing velocity line);
2. each term's per-sample update (the Dahl state of the measured twist, ...);
3. the torque-free part $h$ of eq. (10), per segment or shared, and the twist less the
   torque-free effect groups and the torque gain of the linear ones (eq. (26));
4. eq. (27) in every calibrated segment, and the segment rules of `hdjax.compliance`
   (deepest valid candidate, else the nearest clipped onto its edge);
5. a fixed number of safeguarded Newton steps for the memoryless effects (backlash,
   stiffening);
6. for hysteresis driven by the torque path, the implicit Dahl step of the sample, and steps
   3-5 once more with its states removed.

Every loop has a length fixed at export, so a step costs bounded time.
"""

from __future__ import annotations

import math

import numpy as np

from .._errors import ExportError
from ..compliance import ComplianceModel
from ..compliance.internal import (
    EDGE_TOLERANCE,
    MIN_PATH_SLOPE,
    NEWTON_STEPS,
    calibrated_segments,
    check_estimable,
)
from ._assemble import CCode, StepParts, assemble
from ._causal import check_terms, velocity_notes
from ._emitter import Emitter, c_double, helpers


def _sum_products(pairs) -> str:
    """`a0 * b0 + a1 * b1 + ...` (left to right, as the JAX loops add them)."""
    return " + ".join(f"{a} * {b}" for a, b in pairs)


def _clip(x: str, lo: float, hi: float, n) -> str:
    """`jnp.clip(x, lo, hi)` in C, one-sided for an unbounded segment."""
    if math.isfinite(lo) and math.isfinite(hi):
        return f"hdjax_clip({x}, {n(lo)}, {n(hi)})"
    if math.isfinite(lo):
        return f"({x} > {n(lo)} ? {x} : {n(lo)})"
    if math.isfinite(hi):
        return f"({x} < {n(hi)} ? {x} : {n(hi)})"
    return x


def _group_sum(cols, coef, em) -> str:
    return _sum_products((col, em.num(c)) for col, c in zip(cols, coef))


class _Code:
    """The snippets of a model's terms, by role, with their coefficients."""

    def __init__(self, model: ComplianceModel, em: Emitter):
        self.updates, self.base_lines, self.base_cols = [], [], []
        self.states, self.helpers = [], []
        self.none, self.linear, self.memoryless, self.path = [], [], [], []
        coef = np.asarray(model.coef, np.float64)
        i = model.n_coef - model.n_effect
        terms = [(t, None) for t in model.base_terms]
        for term in model.effect_terms:
            m = len(term.names())
            terms.append((term, coef[i : i + m]))
            i += m
        for index, (term, c) in enumerate(terms):
            view = em.for_term(index)
            snip = term.c_code(view)
            if snip.noncausal:
                raise ExportError(
                    f"term {type(term).__name__} ({term.key}) cannot be exported: {snip.noncausal}"
                )
            self.updates += list(snip.update)
            self.states += [
                (f"{em.real} {view.prefix}{name};", f"{view.state(name)} = {em.num(v)};")
                for name, v in snip.state
            ] + [
                (f"double {view.prefix}{name};", f"{view.state(name)} = {c_double(v)};")
                for name, v in snip.double_state
            ]
            self.helpers += [h for h in snip.helpers if h not in self.helpers]
            kind = term.torque_kind
            n_cols = len(term.names())
            wants = {"none": len(snip.columns), "linear": len(snip.columns)}
            if kind in wants and wants[kind] != n_cols:
                raise ExportError(
                    f"term {type(term).__name__} ({term.key}): its C code gives "
                    f"{wants[kind]} column(s) for its {n_cols} name(s)"
                )
            if c is None:  # a base term: a column of h
                if kind != "none":
                    raise ExportError(f"base term {type(term).__name__} depends on the torque")
                self.base_lines += list(snip.lines)
                self.base_cols += list(snip.columns)
            elif kind == "none":
                self.none.append((snip, c))
            elif kind == "linear":
                self.linear.append((snip, c))
            elif kind == "memoryless":
                if snip.value is None or snip.slope is None:
                    raise ExportError(f"term {type(term).__name__}: C code without value/slope")
                self.memoryless.append((snip, c, view))
            else:
                if snip.path_scale is None or "z" not in dict(snip.state):
                    raise ExportError(f"term {type(term).__name__}: C code without a Dahl state")
                self.path.append((snip, c, view))


def _memoryless_terms(code: _Code, t: str, f: str | None, slope: str, em: Emitter) -> list[str]:
    """Statements adding each memoryless group's $c f(T)$ to `f` (if given) and $c f'(T)$ to
    `slope`, at the torque `t`."""
    out = []
    for snip, c, view in code.memoryless:
        body = [f"const {em.real} {em.torque} = {t};"] + list(snip.lines)
        if f is not None or view.value in snip.slope:
            body.append(f"const {em.real} {view.value} = {snip.value};")
        if f is not None:
            body.append(f"{f} = {f} + {em.num(c[0])} * {view.value};")
        body.append(f"{slope} = {slope} + {em.num(c[0])} * ({snip.slope});")
        out += ["{"] + ["    " + b for b in body] + ["}"]
    return out


def _solve(model: ComplianceModel, code: _Code, em: Emitter) -> str:
    """`hdjax__solve`: eq. (27) with the segment rules, then the memoryless Newton steps."""
    R, n = em.real, em.num
    k = np.asarray(model.k, np.float64)
    ok = calibrated_segments(model)
    bounds = model.segment_bounds
    default_width = 2.0 * model.rated_torque / model.n_segments
    tol = EDGE_TOLERANCE * model.rated_torque
    has_g = bool(code.linear)
    lines = []
    first = True
    for s, (lo, hi) in enumerate(bounds):
        if not ok[s]:
            continue
        a = min(max(0.0, lo), hi)  # the point of segment s nearest to 0 N·m
        phi_a = np.asarray([min(max(a, l_), h_) - min(max(0.0, l_), h_) for l_, h_ in bounds])
        off = float(phi_a @ k) - k[s] * a
        h = f"h[{s if model.per_segment else 0}]"
        den = n(k[s]) if not has_g else f"({n(k[s])} + g)"
        parts = []
        if math.isfinite(lo):
            parts.append(f"{n(lo)} - ts")
        if math.isfinite(hi):
            parts.append(f"ts - {n(hi)}")
        if not parts:
            dist = f"-({R})INFINITY"
        elif len(parts) == 1:
            dist = parts[0]
        else:
            dist = f"hdjax_max({parts[0]}, {parts[1]})"
        width = (hi - lo) if math.isfinite(hi - lo) else default_width
        clip = _clip("ts", lo, hi, n)
        body = [
            f"/* segment {s}: [{lo:.6g}, {hi:.6g}) N m */",
            f"const {R} ts = (r - {h} - {n(off)}) / {den};",
            f"const {R} dist = {dist};",
            f"const int valid = (dist <= {n(tol)}) && (ts == ts);",
            f"const {R} depth = valid ? -dist / {n(width)} : -({R})INFINITY;",
            f"const {R} tclip = {clip};",
        ]
        if first:
            body += [
                "n_valid = valid;",
                f"best_depth = depth; best_t = ts; best_seg = {s};",
                f"near_dist = dist; near_t = tclip; near_seg = {s};",
            ]
            first = False
        else:
            body += [
                "n_valid += valid;",
                f"if (depth > best_depth) {{ best_depth = depth; best_t = ts; best_seg = {s}; }}",
                f"if (dist < near_dist) {{ near_dist = dist; near_t = tclip; near_seg = {s}; }}",
            ]
        lines += ["{"] + ["    " + b for b in body] + ["}"]
    lines += [
        f"{R} t = n_valid > 0 ? best_t : near_t;",
        "const int seg = n_valid > 0 ? best_seg : near_seg;",
        "*flags |= (n_valid > 1 ? HDJAX_AMBIGUOUS : 0u) | (n_valid == 0 ? HDJAX_UNRESOLVED : 0u);",
        "*seg_out = seg;",
    ]
    if code.memoryless:
        # safeguarded Newton steps on the memoryless groups, from the piecewise solution
        span = model.rated_torque / 4.0
        hsel = "h[0]"
        if model.per_segment:
            hsel = "h[seg]"
        hinge = []
        for (lo, hi), kj in zip(bounds, k):
            zero = min(max(0.0, lo), hi)
            hinge.append((f"({_clip('t', lo, hi, n)} - {n(zero)})", n(kj)))
        knots = " + ".join(f"(t >= {n(kn)})" for kn in model.knots) or "0"
        k_arr = ", ".join(n(kj) for kj in k)
        body = [
            f"{R} f = {_sum_products(hinge)}" + (" + g * t" if has_g else "") + " + hh;",
            f"{R} sl = kseg[{knots}]" + (" + g" if has_g else "") + ";",
        ]
        body += _memoryless_terms(code, "t", "f", "sl", em)
        body += [
            f"const {R} step = hdjax_clip((f - r) / sl, {n(-span)}, {n(span)});",
            f"t = t - (sl > {n(0.0)} ? step : {n(0.0)});",
        ]
        lines += [
            f"static const {R} kseg[{len(k)}] = {{{k_arr}}};",
            f"const {R} hh = {hsel};",
            "int it;",
            f"for (it = 0; it < {NEWTON_STEPS}; ++it) {{",
        ]
        lines += ["    " + b for b in body] + ["}"]
    lines.append("return t;")
    g_arg = f", {R} g" if has_g else ""
    decl = [
        f"static {R} hdjax__solve({R} r, const {R} *h{g_arg}, int *seg_out, unsigned *flags)",
        "{",
        "    /* eq. (27) in every calibrated segment, the segment rules, Newton steps */",
        "    int n_valid = 0, best_seg = 0, near_seg = 0;",
        f"    {R} best_depth = 0, best_t = 0, near_dist = 0, near_t = 0;",
    ]
    # with one calibrated segment nothing compares depths or distances
    lines.insert(-1, "(void)best_depth; (void)near_dist;")
    return "\n".join(decl + ["    " + ln for ln in lines] + ["}", ""])


def _step_body(model: ComplianceModel, code: _Code, em: Emitter) -> list[str]:
    R, n = em.real, em.num
    rows = model.n_segments if model.per_segment else 1
    base = np.asarray(model.base_coef, np.float64)
    body = ["/* -- per-sample updates of the terms' states */"] + code.updates
    body += ["/* -- h of eq. (10): the wave generator and the kinematic error, per segment */"]
    body += code.base_lines
    hs = []
    for s in range(rows):
        hs.append(_group_sum(code.base_cols, base[s], em) if code.base_cols else n(0.0))
    body.append(f"const {R} h[{rows}] = {{{', '.join(hs)}}};")
    body.append("/* -- eq. (26): the twist less the torque-free effect groups */")
    body.append(f"{R} r = {em.signal('twist')};")
    for snip, c in code.none:
        body += list(snip.lines)
        body.append(f"r = r - ({_group_sum(snip.columns, c, em)});")
    g_arg = ""
    if code.linear:
        body.append("/* the torque gain of the groups linear in torque */")
        gains = []
        for snip, c in code.linear:
            body += list(snip.lines)
            gains.append(_group_sum(snip.columns, c, em))
        body.append(f"{R} g = {gains[0]};")
        body += [f"g = g + {gi};" for gi in gains[1:]]
        g_arg = ", g"
    body.append("/* -- eq. (27) and the memoryless groups */")
    body.append(f"{R} t = hdjax__solve(r, h{g_arg}, &segment, &flags);")
    if code.path:
        k = np.asarray(model.k, np.float64)
        k_arr = ", ".join(n(kj) for kj in k)
        body.append("/* -- hysteresis of the torque path: the implicit Dahl step of this sample */")
        body.append("{")
        inner = [
            f"static const {R} kseg[{len(k)}] = {{{k_arr}}};",
            f"{R} kk = kseg[segment]" + (" + g" if code.linear else "") + ";",
        ]
        inner += _memoryless_terms(code, "t", None, "kk", em)
        inner.append(f"if (!(kk > {n(0.0)})) kk = {n(float(np.max(k)))};")
        zs = [view.state("z") for _, _, view in code.path]
        scales = [n(snip.path_scale) for snip, _, _ in code.path]
        coefs = [n(c[0]) for _, c, _ in code.path]
        tp = "s->path_tp"
        inner.append(f"if ({em.first}) {tp} = t;")
        for i, ci in enumerate(coefs):
            inner.append(f"const {R} a{i} = {ci} / kk;")
        az = " + ".join(f"a{i} * {z}" for i, z in enumerate(zs))
        inner.append(f"const {R} at_prev = {tp} + ({az});")
        inner.append(f"const {R} side = t >= at_prev ? {n(1.0)} : {n(-1.0)};")
        gain = " + ".join(
            f"a{i} * ({n(1.0)} - {z} * side) / {th}" for i, (z, th) in enumerate(zip(zs, scales))
        )
        inner.append(f"const {R} gain = {n(1.0)} + ({gain});")
        inner.append(
            f"const {R} tk = {tp} + (t - at_prev) / (gain > {n(MIN_PATH_SLOPE)} ? gain : "
            f"{n(MIN_PATH_SLOPE)});"
        )
        for z, th in zip(zs, scales):
            inner.append(
                f"{z} = hdjax_clip({z} + (tk - {tp}) / {th} * ({n(1.0)} - {z} * side), "
                f"{n(-1.0)}, {n(1.0)});"
            )
        inner.append(f"{tp} = tk;")
        inner.append("/* the whole step once more, with the states removed */")
        inner.append(f"{R} r2 = r;")
        inner += [f"r2 = r2 - {z} * {ci};" for z, ci in zip(zs, coefs)]
        inner.append("flags = 0u;")
        inner.append(f"t = hdjax__solve(r2, h{g_arg}, &segment, &flags);")
        body += ["    " + b for b in inner] + ["}"]
    lo, hi = model.torque_range
    body.append(f"if (!(t >= {n(lo)} && t <= {n(hi)})) flags |= HDJAX_OUT_OF_RANGE;")
    body.append("torque = (double)t;")
    return body


def compliance_c(
    model: ComplianceModel,
    *,
    precision: str = "double",
    causal: bool = False,
    half_window: int = 5,
) -> CCode:
    r"""The C code of a calibrated compliance model's per-sample estimate (eqs. (26)-(27)).

    **Arguments:**

    - `model`: a calibrated [`hdjax.compliance.ComplianceModel`][].
    - `precision`: `"double"` (equals [`hdjax.compliance.estimate_torque`][] with
      `causal=True` to rounding) or `"single"` (the model's arithmetic in `float`; angles,
      time and twist stay double).
    - `causal`: export a model whose velocities are a centred window (`velocity =
      "smoothed"`) in its causal form, the window ending at each sample; refused otherwise.
    - `half_window`: the half-width of the smoothed velocity's window (as in
      [`hdjax.signals`][]).

    **Returns:** a [`hdjax.export.CCode`][].

    **Raises:** [`hdjax.ExportError`][] for a term without C code or an estimate that reads
    samples ahead; [`hdjax.InversionError`][] for a model that cannot be inverted.
    """
    if not isinstance(model, ComplianceModel):
        raise ExportError(f"compliance_c exports a ComplianceModel, got {type(model).__name__}")
    check_estimable(model)
    check_terms(model.base_terms + model.effect_terms)
    notes = velocity_notes("the compliance model", model.velocity, causal, half_window)
    em = Emitter(precision)
    code = _Code(model, em)
    solve = _solve(model, code, em)
    body = _step_body(model, code, em)
    states = list(code.states)
    if code.path:
        states.append((f"{em.real} path_tp; /* the torque of the last step */", "s->path_tp = 0;"))
    n_seg = model.n_segments
    description = (
        f"the compliance model of Song et al. (2019), eqs. (26)-(27): {n_seg} torque "
        f"segment{'s' if n_seg > 1 else ''}, {len(model.base_terms)} base and "
        f"{len(model.effect_terms)} effect term group(s), {precision} precision"
    )
    parts = StepParts(
        emitter=em,
        states=tuple(states),
        helpers=tuple(code.helpers) + (solve,),
        body=tuple(body),
        flags=("HDJAX_OUT_OF_RANGE", "HDJAX_AMBIGUOUS", "HDJAX_UNRESOLVED"),
        description=description,
    )
    return assemble(
        parts,
        ratio=model.ratio,
        twist_sign=model.twist_sign,
        velocity=model.velocity,
        half_window=half_window,
        precision=precision,
        kind="compliance",
        notes=notes,
        helpers=helpers(em.real),
    )
