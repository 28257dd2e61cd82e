"""The compliance model of Song et al. (2019), Section II, as an `eqx.Module`.

$$\\Delta\\theta = \\underbrace{\\sum_j k_j\\,\\phi_j(T_f)}_{\\Delta\\theta_f,\\ \\text{eq. (7)}}
+ \\underbrace{k_0 + \\sum_i w_i I^i + \\theta_{err}}_{h,\\ \\text{eqs. (8)-(10)}}
+ \\text{effects}$$

The flexspline compliance is piecewise linear in torque between `knots` (default the paper's
$\\pm\\tau_0/3, \\pm 2\\tau_0/3$, five segments); $\\phi_j(T) = \\mathrm{clip}(T, l_j, u_j) -
\\mathrm{clip}(0, l_j, u_j)$ is the part of the torque path from 0 to $T$ that lies in segment
$j$, so $k_j$ is the compliance (inverse stiffness) of segment $j$ and eq. (7) is reproduced
exactly. The base terms $h$ have coefficients per torque segment (`per_segment=True`, the
paper's Table I) or shared by all segments (a continuous model). Effect groups (added by the
residual loop) are always shared.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, ArrayLike, Float, Int
from .._errors import ConfigError
from .._joint import Joint
from ..effects import AbstractTerm, Constant, CurrentPolynomial, Harmonics, PaperFourier
from ..effects.internal import coupled
from ._signals import VELOCITY_METHODS, Signals
from ._terms import term_from_dict, term_to_dict

KINEMATIC_FORMS = ("paper", "harmonic", "none")
_PAPER_K_NAMES = ("k3", "k2", "k1", "k4", "k5")
_SEGMENT_NAME = re.compile(r"k([1-9]|\[\d+\])")


def is_segment_name(name: str) -> bool:
    """Whether a coefficient name (of `ComplianceModel.term_names`) is a segment
    compliance $k_j$: `k1`..`k5` of the paper's five segments or `k[j]` of any other count;
    not `k0`, the twist model's constant (eq. (10))."""
    return _SEGMENT_NAME.fullmatch(name) is not None


def paper_knots(rated_torque: float, n_segments: int = 5) -> tuple[float, ...]:
    """Inner knots of eq. (7), generalised to any odd number of segments.

    Five segments give the paper's knots $\\pm\\tau_0/3, \\pm 2\\tau_0/3$ (a central segment
    $[-\\tau_0/3, \\tau_0/3)$ twice as wide as the others); $2m+1$ segments put knots at
    $\\pm j\\tau_0/(m+1)$, $j = 1..m$. The count must be odd so the segments are symmetric
    and 0 N·m lies inside the central one; pass explicit `knots` for other layouts.
    """
    if isinstance(n_segments, bool) or not isinstance(n_segments, int) or n_segments < 1:
        raise ConfigError(f"n_segments must be a positive odd integer, got {n_segments!r}")
    if n_segments % 2 == 0:
        raise ConfigError(
            f"n_segments must be odd (segments symmetric about 0 N·m, as eq. (7)), got "
            f"{n_segments}; give explicit knots for other layouts"
        )
    m = (n_segments - 1) // 2
    pos = [rated_torque * j / (m + 1) for j in range(1, m + 1)]
    return tuple([-x for x in reversed(pos)] + pos)


class ComplianceModel(eqx.Module):
    """The twist model of Song et al. eq. (10), linear in its coefficients.

    Build one with [`hdjax.compliance.ComplianceModel.paper`][]; fit it with
    [`hdjax.compliance.calibrate_lstsq`][] or [`hdjax.compliance.calibrate_rls`][], which return a
    new module; invert it with [`hdjax.compliance.estimate_torque`][].

    **Fields:**

    - `coef`: all coefficients (float64), in the order of `term_names`.
    - `joint`: the [`hdjax.Joint`][] (ratio, rated torque, twist sign); `ratio`, `rated_torque`
      and `twist_sign` read it.
    - `knots`: inner segment boundaries [N·m], increasing, with 0 strictly inside the central
      segment. The outer segments extend without bound (extrapolation is flagged).
    - `torque_range`: the torque range the model is valid for (calibrated range).
    - `base_terms`: groups of $h$ (constant, current polynomial, kinematic error).
    - `effect_terms`: extra groups added by the residual loop (shared across segments).
    - `per_segment`: whether `base_terms` coefficients are per torque segment.
    - `active`: per coefficient, whether it was calibrated (inactive ones are zero).
    - `velocity`: how velocities are derived (`"difference"`, eqs. (13)-(14), or `"smoothed"`).
    """

    coef: Float[Array, " p"]
    joint: Joint = eqx.field(static=True)
    knots: tuple[float, ...] = eqx.field(static=True)
    torque_range: tuple[float, float] = eqx.field(static=True)
    base_terms: tuple = eqx.field(static=True)
    effect_terms: tuple = eqx.field(static=True)
    per_segment: bool = eqx.field(static=True)
    active: tuple[bool, ...] = eqx.field(static=True)
    velocity: str = eqx.field(static=True, default="difference")

    def __check_init__(self):
        if not isinstance(self.joint, Joint):
            raise ConfigError(f"joint must be an hdjax.Joint, got {type(self.joint).__name__}")
        k = self.knots
        if any(b <= a for a, b in zip(k, k[1:])):
            raise ConfigError(f"knots must be strictly increasing, got {k}")
        if 0.0 in k:
            raise ConfigError(f"0 N·m must lie strictly inside a segment, but it is a knot: {k}")
        if self.velocity not in VELOCITY_METHODS:
            raise ConfigError(f"velocity must be one of {VELOCITY_METHODS}")
        for term in self.base_terms + self.effect_terms:
            if not isinstance(term, AbstractTerm):
                raise ConfigError(
                    f"term {term!r} is not an hdjax.effects.AbstractTerm; define term groups "
                    "with their family in hdjax.effects"
                )
        if len(self.active) != self.n_coef:
            raise ConfigError(f"active has {len(self.active)} entries for {self.n_coef} terms")
        if isinstance(self.coef, np.ndarray | jnp.ndarray) and self.coef.shape != (self.n_coef,):
            raise ConfigError(f"coef has shape {self.coef.shape}, expected ({self.n_coef},)")

    # -- construction ------------------------------------------------------------------------

    @classmethod
    def paper(
        cls,
        joint: Joint,
        *,
        n_segments: int = 5,
        knots: tuple[float, ...] | None = None,
        poly_order: int = 6,
        current_scale: float = 1.0,
        kinematic: str = "paper",
        fourier_order: int = 3,
        harmonic_orders_m: tuple[float, ...] = (1.0, 2.0),
        harmonic_orders_l: tuple[float, ...] = (1.0, 2.0),
        per_segment: bool = True,
        velocity: str = "difference",
        torque_range: tuple[float, float] | None = None,
    ) -> ComplianceModel:
        """The paper's model structure for a joint, with zero coefficients.

        **Arguments:**

        - `joint`: ratio, rated torque and twist sign.
        - `n_segments` / `knots`: flexspline segments (default five, knots $\\pm\\tau_0/3,
          \\pm 2\\tau_0/3$, eq. (7)); explicit `knots` override `n_segments`.
        - `poly_order`: order of the wave-generator polynomial in current, eq. (8) (0 = none).
        - `current_scale`: the current is divided by this before the powers are taken.
        - `kinematic`: `"paper"` (eq. (9), arguments $\\theta\\omega$, order `fourier_order`),
          `"harmonic"` (plain harmonics of $\\theta_m$ and $\\theta_l$ at the given orders) or
          `"none"`.
        - `per_segment`: coefficients of the constant, polynomial and kinematic terms per
          segment (Table I) or shared.
        - `velocity`: `"difference"` (eqs. (13)-(14)) or `"smoothed"`.
        - `torque_range`: range the model is calibrated for, default $[-\\tau_0, \\tau_0]$.
        """
        _check_int("n_segments", n_segments, 1)
        _check_int("poly_order", poly_order, 0)
        _check_int("fourier_order", fourier_order, 0)
        if kinematic not in KINEMATIC_FORMS:
            raise ConfigError(f"kinematic must be one of {KINEMATIC_FORMS}, got {kinematic!r}")
        if knots is None:
            knots = paper_knots(joint.rated_torque, n_segments)
        knots = tuple(float(k) for k in knots)
        base: list = [Constant()]
        if poly_order > 0:
            base.append(CurrentPolynomial(order=poly_order, scale=float(current_scale)))
        if kinematic == "paper" and fourier_order > 0:
            base.append(PaperFourier(order=fourier_order))
        elif kinematic == "harmonic":
            for signal, orders in (("theta_m", harmonic_orders_m), ("theta_l", harmonic_orders_l)):
                if orders:
                    base.append(Harmonics(signal=signal, orders=tuple(float(o) for o in orders)))
        if torque_range is None:
            torque_range = (-joint.rated_torque, joint.rated_torque)
        return cls.build(
            joint=joint,
            knots=knots,
            base_terms=tuple(base),
            effect_terms=(),
            per_segment=per_segment,
            velocity=velocity,
            torque_range=tuple(float(x) for x in torque_range),
        )

    @classmethod
    def build(
        cls,
        *,
        base_terms: Sequence[AbstractTerm],
        effect_terms: Sequence[AbstractTerm] = (),
        per_segment: bool = True,
        **static: Any,
    ) -> ComplianceModel:
        """A model with the given structure, zero coefficients and every term active."""
        n_seg = len(static["knots"]) + 1
        n_base = sum(len(t.names()) for t in base_terms)
        n = n_seg + n_base * (n_seg if per_segment else 1)
        n += sum(len(t.names()) for t in effect_terms)
        return cls(
            coef=jnp.zeros(n, jnp.float64),
            base_terms=tuple(base_terms),
            effect_terms=coupled(effect_terms),
            per_segment=per_segment,
            active=(True,) * n,
            **static,
        )

    def restructured(
        self,
        *,
        knots: Sequence[float] | None = None,
        effect_terms: Sequence[AbstractTerm] | None = None,
    ) -> ComplianceModel:
        """The same joint and base terms with other knots and/or effect groups (coefficients
        reset to zero, every term active)."""
        return ComplianceModel.build(
            joint=self.joint,
            knots=self.knots if knots is None else tuple(knots),
            torque_range=self.torque_range,
            velocity=self.velocity,
            base_terms=self.base_terms,
            effect_terms=self.effect_terms if effect_terms is None else tuple(effect_terms),
            per_segment=self.per_segment,
        )

    def with_effects(self, *terms: AbstractTerm) -> ComplianceModel:
        """The same structure with further effect groups (coefficients reset to zero)."""
        return self.restructured(effect_terms=self.effect_terms + tuple(terms))

    # -- structure ---------------------------------------------------------------------------

    @property
    def ratio(self) -> float:
        """Reduction ratio $N$ of the joint."""
        return self.joint.ratio

    @property
    def rated_torque(self) -> float:
        """Rated torque $\\tau_0$ [N·m] of the joint."""
        return self.joint.rated_torque

    @property
    def twist_sign(self) -> float:
        """Twist sign of the joint (see [`hdjax.Joint`][])."""
        return self.joint.twist_sign

    @property
    def n_segments(self) -> int:
        return len(self.knots) + 1

    @property
    def segment_bounds(self) -> tuple[tuple[float, float], ...]:
        """(lower, upper) of each segment; the outer ones are unbounded."""
        edges = (-math.inf,) + self.knots + (math.inf,)
        return tuple(zip(edges[:-1], edges[1:]))

    @property
    def n_base(self) -> int:
        return sum(len(t.names()) for t in self.base_terms)

    @property
    def n_effect(self) -> int:
        return sum(len(t.names()) for t in self.effect_terms)

    @property
    def n_coef(self) -> int:
        n_seg = self.n_segments
        return n_seg + self.n_base * (n_seg if self.per_segment else 1) + self.n_effect

    @property
    def k_names(self) -> tuple[str, ...]:
        """Names of the segment compliances (the paper's k1..k5 when there are five)."""
        if self.n_segments == 5:
            return _PAPER_K_NAMES
        return tuple(f"k[{j}]" for j in range(self.n_segments))

    @property
    def term_names(self) -> tuple[str, ...]:
        """One name per coefficient: `k1`, `w3[seg 2]`, `tanh(omega_m/0.5)`, ..."""
        names = list(self.k_names)
        base = [n for t in self.base_terms for n in t.names()]
        if self.per_segment:
            for s in range(self.n_segments):
                names += [f"{n}[seg {s}]" for n in base]
        else:
            names += base
        names += [n for t in self.effect_terms for n in t.names()]
        return tuple(names)

    @property
    def effect_keys(self) -> tuple[str, ...]:
        return tuple(t.key for t in self.effect_terms)

    # -- pieces of the coefficient vector ----------------------------------------------------

    @property
    def k(self) -> Float[Array, " n_seg"]:
        """Segment compliances $k_j$ [rad/(N·m)] in torque order."""
        return self.coef[: self.n_segments]

    @property
    def base_coef(self) -> Float[Array, "n_seg_or_1 n_base"]:
        """Coefficients of the base terms, one row per segment (or one shared row)."""
        n_seg, nb = self.n_segments, self.n_base
        rows = n_seg if self.per_segment else 1
        return self.coef[n_seg : n_seg + rows * nb].reshape(rows, nb)

    @property
    def effect_coef(self) -> Float[Array, " n_effect"]:
        return self.coef[self.n_coef - self.n_effect :]

    # -- columns -----------------------------------------------------------------------------

    def hinge_basis(self, torque: Float[ArrayLike, " n"]) -> Float[Array, "n n_seg"]:
        """$\\phi_j(T)$ of eq. (7): the part of the path from 0 to $T$ inside segment $j$."""
        cols = []
        for lo, hi in self.segment_bounds:
            zero = min(max(0.0, lo), hi)
            cols.append(jnp.clip(torque, lo, hi) - zero)
        return jnp.stack(cols, axis=1)

    def segment_index(self, torque: Float[ArrayLike, "*shape"]) -> Int[Array, "*shape"]:
        """Index of the segment each torque falls in (`[l_j, u_j)` as eq. (7))."""
        # the number of knots at or below the torque (searchsorted side="right"), elementwise
        torque = jnp.asarray(torque, jnp.float64)
        seg = jnp.zeros(torque.shape, jnp.int32)
        for knot in self.knots:
            seg = seg + (torque >= knot).astype(jnp.int32)
        return seg

    def base_column_list(self, sig: Signals) -> list:
        """The base terms' columns as separate 1-D arrays (XLA fuses them; no stacking)."""
        return base_term_columns(self.base_terms, sig)

    def base_columns(self, sig: Signals) -> Float[Array, "n n_base"]:
        """Columns of the base terms (shared layout, before per-segment expansion)."""
        if not self.base_terms:
            return jnp.zeros((sig.n_samples, 0), jnp.float64)
        return jnp.concatenate([t.columns(sig) for t in self.base_terms], axis=1)

    def effect_columns(
        self, sig: Signals, torque: Float[ArrayLike, " n"] | None
    ) -> Float[Array, "n n_effect"]:
        """Columns of the effect groups, evaluated at `torque` where they depend on it."""
        if not self.effect_terms:
            return jnp.zeros((sig.n_samples, 0), jnp.float64)
        return jnp.concatenate([t.columns(sig, torque) for t in self.effect_terms], axis=1)

    def design(self, sig: Signals, torque: Float[ArrayLike, " n"]) -> Float[Array, "n p"]:
        """The design matrix $A$ of eq. (15) at the given torque (eq. (10), row per sample)."""
        torque = jnp.asarray(torque, jnp.float64)
        parts = [self.hinge_basis(torque)]
        base = self.base_columns(sig)
        if self.per_segment:
            seg = self.segment_index(torque)
            onehot = (seg[:, None] == jnp.arange(self.n_segments, dtype=seg.dtype)[None, :]).astype(
                base.dtype
            )
            parts.append((onehot[:, :, None] * base[:, None, :]).reshape(sig.n_samples, -1))
        else:
            parts.append(base)
        parts.append(self.effect_columns(sig, torque))
        return jnp.concatenate(parts, axis=1)

    def predict_twist(self, sig: Signals, torque: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
        """Forward model: the twist $\\Delta\\theta$ of eq. (10) at a given torque."""
        return self.design(sig, torque) @ self.coef

    def to_dict(self) -> dict:
        """A JSON-ready description (structure and coefficients)."""
        return {
            "ratio": self.ratio,
            "rated_torque": self.rated_torque,
            "twist_sign": self.twist_sign,
            "joint": self.joint.to_dict(),
            "knots": list(self.knots),
            "torque_range": list(self.torque_range),
            "base_terms": [term_to_dict(t) for t in self.base_terms],
            "effect_terms": [term_to_dict(t) for t in self.effect_terms],
            "per_segment": self.per_segment,
            "active": list(self.active),
            "velocity": self.velocity,
            "coef": [float(c) for c in np.asarray(self.coef)],
            "term_names": list(self.term_names),
        }

    @classmethod
    def from_dict(cls, d: dict) -> ComplianceModel:
        """Inverse of `to_dict`."""
        return cls(
            coef=jnp.asarray(d["coef"], jnp.float64),
            joint=(
                Joint.from_dict(d["joint"])
                if "joint" in d
                else Joint(
                    ratio=float(d["ratio"]),
                    rated_torque=float(d["rated_torque"]),
                    twist_sign=float(d["twist_sign"]),
                )
            ),
            knots=tuple(float(k) for k in d["knots"]),
            torque_range=tuple(float(x) for x in d["torque_range"]),
            base_terms=tuple(term_from_dict(t) for t in d["base_terms"]),
            effect_terms=tuple(term_from_dict(t) for t in d["effect_terms"]),
            per_segment=bool(d["per_segment"]),
            active=tuple(bool(a) for a in d["active"]),
            velocity=str(d["velocity"]),
        )


def base_term_columns(terms: tuple, sig: Signals) -> list:
    """The columns of base terms `terms` (the torque-free part $h$ of eq. (10)) as separate
    1-D arrays, in order."""
    cols = []
    for term in terms:
        if hasattr(term, "column_list"):
            cols += term.column_list(sig)
        else:
            block = term.columns(sig)
            cols += [block[:, j] for j in range(block.shape[1])]
    return cols


def _check_int(name: str, value, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ConfigError(f"{name} must be an integer >= {minimum}, got {value!r}")
