r"""Kinematic error: the output does not follow the input exactly, periodically in the angles.

The transmission error of a harmonic drive is periodic in the wave-generator and flexspline
angles (tooth placement, cam eccentricity, the bearing); Song et al. write it as a Fourier
series of both, eq. (9), in the twist model eq. (10). Here the orders are free floats: besides
the integers, the combination orders $2 \pm 2/N$ and $1 \pm 1/N$ of the cam's two lobes meeting
the flexspline appear on real joints. The plant adds $\sum_j a_j \sin(o_j\theta + \varphi_j)$ of
the recorded motor angle (`harmonic_m`) and load angle (`harmonic_l`) to the deflection; the
regression term is a $\cos, \sin$ pair per order; the residual loop takes its orders from the
order spectrum of the twist residual (peaks, refined) merged with the integers and the
combination orders.

References: Song et al. 2019, eq. (9).
"""

from __future__ import annotations

from typing import ClassVar

import jax
import numpy as np

from .. import _trig
from .._custom_types import Array, Float, NumpyDesign, Pointwise, PointwiseOut, SamplesLike
from .._features import Signals
from .._trig import sincos
from ._base import (
    AbstractColumnListTerm,
    AbstractFamily,
    AbstractPlantEffect,
    Candidate,
    CandidateContext,
    both_sides,
)
from ._c import AbstractCEmitter, CSnippet
from ._fields import bound, fmt, hyper
from ._traced import opaque


def c_harmonic_pairs(c: AbstractCEmitter, arg: str, order: int, tag: str) -> tuple[list, list]:
    """[`harmonic_pairs`][] in C: the statements declaring $\\cos nu, \\sin nu$, $n = 1..$`order`,
    of the double expression `arg`, and their `(cos, sin)` local names."""
    s1, c1 = c.local(f"s1{tag}"), c.local(f"c1{tag}")
    lines = [c.sincos(arg, s1, c1)]
    pairs = [(c1, s1)]
    for n in range(2, order + 1):
        (cp, sp), cn, sn = pairs[-1], c.local(f"c{n}{tag}"), c.local(f"s{n}{tag}")
        lines.append(f"const {c.real} {cn} = {cp} * {c1} - {sp} * {s1};")
        lines.append(f"const {c.real} {sn} = {sp} * {c1} + {cp} * {s1};")
        pairs.append((cn, sn))
    return lines, pairs


def harmonic_pairs(u: PointwiseOut, order: int) -> list[tuple[PointwiseOut, PointwiseOut]]:
    r"""$[(\cos nu, \sin nu)]_{n=1..order}$ by the angle-addition recurrence from one `sincos`."""
    # The barrier materialises sin/cos once: without it XLA fuses (and so recomputes) them into
    # every column that a stacked design materialises separately.
    s1, c1 = jax.lax.optimization_barrier(sincos(u))
    out = [(c1, s1)]
    for _ in range(1, order):
        c, s = out[-1]
        out.append((c * c1 - s * s1, s * c1 + c * s1))
    return out


class PaperFourier(AbstractColumnListTerm):
    """Kinematic error in the paper's form, eq. (9), without its constant $a_0$.

    For $n = 1..$`order`: $\\cos(n\\theta_{fso}\\omega_{fso}), \\sin(n\\theta_{fso}\\omega_{fso}),
    \\cos(n\\theta_{wgi}\\omega_{wgi}), \\sin(n\\theta_{wgi}\\omega_{wgi})$ with coefficients
    $a_n, b_n, c_n, d_n$. (The argument angle-times-velocity is the paper's; plain harmonics of
    the angles are [`hdjax.compliance.Harmonics`][].)
    """

    order: int = hyper(3)

    @property
    def key(self) -> str:
        return "kinematic:paper"

    def names(self) -> tuple[str, ...]:
        out = []
        for n in range(1, self.order + 1):
            out += [f"a{n}", f"b{n}", f"c{n}", f"d{n}"]
        return tuple(out)

    def column_list(self, sig: Signals) -> list[Float[Array, " n"]]:
        hl = harmonic_pairs(sig.theta_l * sig.omega_l, self.order)
        hm = harmonic_pairs(sig.theta_m * sig.omega_m, self.order)
        cols = []
        for (cl, sl), (cm, sm) in zip(hl, hm):
            cols += [cl, sl, cm, sm]
        return cols

    def extrapolating_arguments(self, sig: Signals) -> tuple[Float[np.ndarray, " n"], ...]:
        """The output's $\\theta\\omega$: on a joint's swing it stays under a radian or two, so
        its harmonics cover less than a period there and a fit of them is a smooth function
        of it (a held-out sweep at another speed leaves its training part's range). The
        motor's $\\theta\\omega$ turns through many periods."""
        return (np.asarray(sig.theta_l, np.float64) * np.asarray(sig.omega_l, np.float64),)

    def numpy_columns(self, sig: Signals, torque: SamplesLike | None = None) -> NumpyDesign:
        ul = np.asarray(sig.theta_l) * np.asarray(sig.omega_l)
        um = np.asarray(sig.theta_m) * np.asarray(sig.omega_m)
        cols = []
        for n in range(1, self.order + 1):
            cols += [np.cos(n * ul), np.sin(n * ul), np.cos(n * um), np.sin(n * um)]
        return np.column_stack(cols)

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """Eq. (9)'s columns for the exported estimator: the harmonics of $\\theta\\omega$ of
        each side by the angle-addition recurrence, as `column_list` computes them."""
        lines_l, hl = c_harmonic_pairs(
            c, f"{c.angle('theta_l')} * {c.angle('omega_l')}", self.order, "l"
        )
        lines_m, hm = c_harmonic_pairs(
            c, f"{c.angle('theta_m')} * {c.angle('omega_m')}", self.order, "m"
        )
        cols = []
        for (cl, sl), (cm, sm) in zip(hl, hm):
            cols += [cl, sl, cm, sm]
        return CSnippet(columns=tuple(cols), lines=tuple(lines_l + lines_m))


class Harmonics(AbstractColumnListTerm):
    """Harmonics of one angle at a list of (possibly non-integer) orders: $\\cos(k\\theta),
    \\sin(k\\theta)$ per order $k$ - the kinematic error as a function of angle alone."""

    signal: str = hyper("theta_m")
    orders: tuple[float, ...] = hyper((1.0, 2.0))

    @property
    def key(self) -> str:
        return ",".join(f"harmonic:{self.signal}:{fmt(k)}" for k in self.orders)

    def names(self) -> tuple[str, ...]:
        out = []
        for k in self.orders:
            out += [f"cos({fmt(k)}*{self.signal})", f"sin({fmt(k)}*{self.signal})"]
        return tuple(out)

    def column_list(self, sig: Signals) -> list[Float[Array, " n"]]:
        theta = sig.get(self.signal)
        cols = []
        for k in self.orders:
            s, c = sincos(opaque(k) * theta)  # a constant order rounds as a traced one
            cols += [c, s]
        return cols

    def numpy_columns(self, sig: Signals, torque: SamplesLike | None = None) -> NumpyDesign:
        th = np.asarray(sig.get(self.signal))
        return np.column_stack([f(k * th) for k in self.orders for f in (np.cos, np.sin)])

    def c_code(self, c: AbstractCEmitter) -> CSnippet:
        """The harmonics for the exported estimator: $\\cos, \\sin$ of the order times the angle
        (in double)."""
        lines, cols = [], []
        for j, k in enumerate(self.orders):
            s, co = c.local(f"s{j}"), c.local(f"c{j}")
            lines.append(c.sincos(f"{c.dnum(k)} * {c.angle(self.signal)}", s, co))
            cols += [co, s]
        return CSnippet(columns=tuple(cols), lines=tuple(lines))


class KinematicHarmonics(AbstractPlantEffect):
    r"""Kinematic error $\sum_j a_j \sin(o_j \theta + \varphi_j)$ of one angle [rad].

    Song et al. eq. (9) writes the kinematic error as a Fourier series of the output and the input
    angle; here orders are free floats (e.g. $2 - 2/N$). The angle is the *recorded* one (motor
    for `harmonic_m`, load for `harmonic_l`).

    **Arguments:**

    - `orders`: harmonic orders, shape `(n,)`.
    - `amplitudes`: amplitudes [rad of twist], shape `(n,)`, non-negative.
    - `phases`: phases [rad], shape `(n,)`.
    """

    orders: Float[Array, " n"]
    amplitudes: Float[Array, " n"] = bound("nonneg")
    phases: Float[Array, " n"]

    def __call__(self, angle: Pointwise, inv: dict | None = None) -> PointwiseOut:
        return _trig.harmonic_sum(self.orders, self.amplitudes, self.phases, angle)


_ARCMIN = np.pi / (180.0 * 60.0)


def harmonic_key(signal: str, order: float) -> str:
    """The vocabulary key of one harmonic order of one angle."""
    return f"harmonic:{signal}:{fmt(round(order, 6))}"


class KinematicFamily(AbstractFamily):
    """Kinematic error: plant `harmonic_m`, `harmonic_l`; terms `Harmonics`, `PaperFourier`;
    candidates from the order spectrum of the residual (`harmonic:theta_m:ORDER`, ...)."""

    name: ClassVar[str] = "kinematic"
    terms: ClassVar[tuple] = (PaperFourier, Harmonics)
    # transmission accuracy ~1 arcmin peak-to-peak split over motor- and load-side harmonics
    plant_effects: ClassVar[tuple] = both_sides(
        "harmonic",
        "kinematic",
        KinematicHarmonics.from_params,
        motor=lambda rated, k1, given: dict(
            orders=[2.0], amplitudes=[0.15 * _ARCMIN], phases=[0.3]
        ),
        output=lambda rated, k1, given: dict(
            orders=[1.0, 2.0], amplitudes=[0.2 * _ARCMIN, 0.1 * _ARCMIN], phases=[0.0, 1.1]
        ),
    )
    discover_families: ClassVar[tuple] = ("harmonic:theta_m", "harmonic:theta_l")
    vocabulary: ClassVar[str] = "harmonic:theta_m:ORDER, harmonic:theta_l:ORDER"
    options: ClassVar[dict] = {
        "orders_m": (0.5, 8.0),
        "orders_l": (0.5, 12.0),
        "integer_orders_m": (1.0, 2.0, 3.0, 4.0),
        "integer_orders_l": (1.0, 2.0, 3.0, 4.0),
        "n_peaks": 3,
    }

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        existing = {"theta_m": [], "theta_l": []}
        for term in ctx.existing_terms:
            if isinstance(term, Harmonics):
                existing[term.signal] += list(term.orders)
        out = []
        for signal, suffix in (("theta_m", "m"), ("theta_l", "l")):
            if f"harmonic:{signal}" not in ctx.families:
                continue
            named = list(ctx.option(self, f"integer_orders_{suffix}"))
            if signal == "theta_m":
                r = ctx.ratio
                named += [2.0 - 2.0 / r, 2.0 + 2.0 / r, 1.0 - 1.0 / r, 1.0 + 1.0 / r]
            orders = ctx.spectrum_orders(
                signal,
                ctx.option(self, f"orders_{suffix}"),
                named,
                existing[signal],
                ctx.option(self, "n_peaks"),
            )
            for k, origin in orders:
                term = Harmonics(signal=signal, orders=(float(round(k, 6)),))
                out.append(Candidate(harmonic_key(signal, k), f"harmonic:{signal}", term, origin))
        return out
