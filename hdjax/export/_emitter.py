"""The exporter's side of a term's C code: names, literals and the helpers every step uses.

[`Emitter`][] implements [`hdjax.effects.AbstractCEmitter`][] for one model and one precision;
[`Emitter.for_term`][] gives each term a view whose state members and locals carry the term's
own prefix. It records which signals the code reads, so the step declares only those (the
generated code compiles with `-Wall -Wextra -Werror`).
"""

from __future__ import annotations

import math

from .._errors import ExportError
from ..effects import AbstractCEmitter

PRECISIONS = ("double", "single")
"""`--precision`: the C type of the model's arithmetic (angles, time and twist stay double)."""

CORE_SIGNALS = ("twist", "current", "theta_m", "theta_l", "omega_m", "omega_l")

_MATH = ("tanh", "exp", "sin", "cos", "sqrt", "fabs", "log", "pow", "atan", "atan2", "fmod")


def c_real(precision: str) -> str:
    """The C type of `precision` (`double` or `float`)."""
    if precision not in PRECISIONS:
        raise ExportError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    return "double" if precision == "double" else "float"


def c_double(x: float) -> str:
    """A C double literal that reads back as exactly `x` (shortest round-trip form)."""
    x = float(x)
    if math.isnan(x):
        raise ExportError("a coefficient of the model is NaN; recalibrate it")
    if math.isinf(x):
        return "HUGE_VAL" if x > 0 else "(-HUGE_VAL)"
    text = repr(x)
    return f"({text})" if x < 0 or text.startswith("-") else text


def c_number(x: float, real: str) -> str:
    """A literal of the C type `real` for `x` (floats carry the `f` suffix)."""
    if real == "double":
        return c_double(x)
    x = float(x)
    if math.isnan(x):
        raise ExportError("a coefficient of the model is NaN; recalibrate it")
    if math.isinf(x):
        return "INFINITY" if x > 0 else "(-INFINITY)"
    text = repr(x) + "f"
    return f"({text})" if text.startswith("-") else text


class Emitter(AbstractCEmitter):
    """Names and literals of one exported model (see [`hdjax.effects.AbstractCEmitter`][]).

    **Arguments:** `precision` (`"double"` or `"single"`), `extras` (the extra columns the
    model reads, in the order of the sample's `extra` array).
    """

    torque = "T"
    first = "(s->n == 0)"

    def __init__(self, precision: str, prefix: str = "") -> None:
        self.precision = precision
        self.real = c_real(precision)
        self._extras: list[str] = []  # extra columns in the order the code first reads them
        self.prefix = prefix
        self.value = f"{prefix}v"
        self.used_real: set[str] = set()  # signals read as `real`
        self.used_double: set[str] = set()  # signals read as double
        self.states: list[tuple[str, float]] = []  # (member, initial value)
        self._root = self

    def for_term(self, index: int) -> Emitter:
        """The view of term `index`: its members and locals are prefixed `t<index>_`."""
        view = Emitter(self.precision, prefix=f"t{index}_")
        view._root = self._root
        return view

    @property
    def extras(self) -> tuple[str, ...]:
        """The extra columns the code reads, in the order of the sample's `extra` array."""
        return tuple(self._root._extras)

    # -- literals ----------------------------------------------------------------------------

    def num(self, x: float) -> str:
        return c_number(x, self.real)

    def dnum(self, x: float) -> str:
        return c_double(x)

    # -- names -------------------------------------------------------------------------------

    def _signal_name(self, name: str) -> str:
        if name in CORE_SIGNALS:
            return name
        if not isinstance(name, str) or not name or name.startswith("_"):
            raise ExportError(
                f"a term reads the signal {name!r}, which a controller does not measure (the "
                f"core signals are {', '.join(CORE_SIGNALS)}, or an extra column of the log)"
            )
        extras = self._root._extras
        if name not in extras:
            extras.append(name)
        return f"x{extras.index(name)}"

    def signal(self, name: str) -> str:
        base = self._signal_name(name)
        if self.real == "double":
            self._root.used_double.add(base)
            return f"d_{base}"
        self._root.used_double.add(base)
        self._root.used_real.add(base)
        return base

    def angle(self, name: str) -> str:
        base = self._signal_name(name)
        self._root.used_double.add(base)
        return f"d_{base}"

    def state(self, name: str) -> str:
        return f"s->{self.prefix}{name}"

    def time(self) -> str:
        return "x->t"

    def local(self, name: str) -> str:
        return f"{self.prefix}{name}"

    def fn(self, name: str) -> str:
        if name not in _MATH:
            raise ExportError(f"C code asks for the math function {name!r}, not one of {_MATH}")
        return name if self.real == "double" else f"{name}f"

    def sincos(self, arg: str, sin: str, cos: str) -> str:
        return f"{self.real} {sin}, {cos}; hdjax_sincos({arg}, &{sin}, &{cos});"


def helpers(real: str) -> str:
    """The static helpers of every generated estimator: clip, sign and the sine and cosine of
    `hdjax._trig` (Cody-Waite reduction in double, fdlibm's kernels at precision `real`)."""
    from .. import _trig

    n = lambda x: c_number(x, real)  # noqa: E731
    d = c_double
    s, c = _trig._S, _trig._C
    ps = f"{n(s[5])}"
    for coef in s[4::-1]:
        ps = f"({ps}) * z + {n(coef)}"
    pc = f"{n(c[5])}"
    for coef in c[4::-1]:
        pc = f"({pc}) * z + {n(coef)}"
    return f"""\
static inline {real} hdjax_clip({real} x, {real} lo, {real} hi)
{{
    /* jnp.clip: min(max(x, lo), hi) */
    const {real} y = x > lo ? x : lo;
    return y < hi ? y : hi;
}}

static inline {real} hdjax_max({real} a, {real} b)
{{
    return a > b ? a : b;
}}

static inline {real} hdjax_sign({real} x)
{{
    return x > {n(0.0)} ? {n(1.0)} : (x < {n(0.0)} ? {n(-1.0)} : {n(0.0)});
}}

static inline void hdjax_sincos(double x, {real} *sin_x, {real} *cos_x)
{{
    /* hdjax's sine and cosine: n = round(2x/pi), r = x - n pi/2 with pi/2 in four parts
       (Cody-Waite), then fdlibm's __kernel_sin and __kernel_cos on |r| <= pi/4 */
    const double q = nearbyint(x * {d(_trig._INV_PIO2)});
    const double rd = (((x - q * {d(_trig._C1)}) - q * {d(_trig._C2)}) - q * {d(_trig._C3)})
        - q * {d(_trig._C4)};
    const {real} r = ({real})rd;
    const {real} z = r * r;
    const {real} ps = {ps};
    const {real} pc = {pc};
    const {real} sr = r + r * z * ps;
    const {real} hz = {n(0.5)} * z;
    const {real} w = {n(1.0)} - hz;
    const {real} cr = w + ((({n(1.0)} - w) - hz) + z * z * pc);
    const double m = q - 4.0 * floor(q * 0.25);
    if (m == 0.0) {{ *sin_x = sr; *cos_x = cr; }}
    else if (m == 1.0) {{ *sin_x = cr; *cos_x = -sr; }}
    else if (m == 2.0) {{ *sin_x = -sr; *cos_x = -cr; }}
    else {{ *sin_x = -cr; *cos_x = sr; }}
}}
"""
