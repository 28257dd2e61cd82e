r"""The abstract shapes of an effect family: its regression term, its plant effect, the family.

A *family* is one physical effect of the joint (Coulomb friction, lost motion, hysteresis, ...)
seen from every side hdjax looks at it:

- the **plant** simulates it: an [`hdjax.effects.AbstractPlantEffect`][] with differentiable
  array parameters, in one of the plant's *slots* (motor or output friction, kinematic error,
  an additive compliance, a parallel spring, ...);
- the **compliance model** regresses on it: an [`hdjax.effects.AbstractTerm`][], a group of
  design-matrix columns with hashable hyperparameters (a smoothing speed, an order), whose
  dependence on torque tells the inversion what to do;
- the **residual loop** proposes it: the family's `candidates(ctx)` generates the terms to try
  (a grid of scales, or the orders a spectrum of the residual points at).

The layout follows diffrax's `AbstractTerm` and optimistix's `_solver/`: abstract classes declare
`eqx.AbstractVar`/`eqx.AbstractClassVar` and abstract methods, final classes fill them in, and
`__check_init__` validates what a user can get wrong.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import typing
from collections.abc import Callable, Mapping, Sequence
from types import ModuleType
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._custom_types import (
    Array,
    ArrayLike,
    Design,
    Float,
    NumpyDesign,
    Pointwise,
    PointwiseOut,
    Samples,
    SamplesLike,
)
from .._errors import ConfigError
from .._features import Signals
from ._fields import check_positive, f64, require, vector

TORQUE_KINDS = ("none", "linear", "memoryless", "path")
"""How a term depends on the torque $T$ (see [`hdjax.effects.AbstractTerm`][])."""

TORQUE_PATH = "_torque_path"
"""Name of an optional signal that drives path-dependent terms at calibration (see
[`hdjax.compliance.Hysteresis`][]): the torque *estimated* by a previous model, so the state is
computed as the estimator will compute it, causally and without the reference sensor."""

SEGMENT_START = "_segment_start"
"""Name of an optional signal, 1 at the first sample of each contiguous segment of a recording
with gaps: memory states (hysteresis) restart there (see [`hdjax.effects.dahl_state`][])."""


def late(x, reset=None, at_reset: float | None = 0.0):
    """`x` one sample late: `x[k-1]` at sample `k`; at the record's first sample and at each
    `reset`, `at_reset` (the state a restart begins with), or with `None` the sample's own
    value. JAX or NumPy arrays alike."""
    xp = jnp if isinstance(x, jax.Array) else np
    prev = xp.concatenate([x[:1], x[:-1]])
    first = xp.zeros(x.shape, bool)
    first = first.at[0].set(True) if xp is jnp else np.r_[True, np.zeros(x.shape[0] - 1, bool)]
    if reset is not None:
        first = first | (xp.asarray(reset) != 0)
    fill = x if at_reset is None else xp.full(x.shape, at_reset, x.dtype)
    return xp.where(first, fill, prev)


PLANT_SLOTS = (
    "kinematic_m",
    "kinematic_l",
    "compliance_ripple_m",
    "compliance_ripple_l",
    "motor_friction",
    "output_friction",
    "hysteresis",
    "compliance",
    "spring",
    "temperature",
    "wave_generator",
)
"""Where a plant effect enters the joint (see `hdjax/plant/_dynamics.py`):

- `kinematic_m`, `kinematic_l`: a twist offset [rad] from the recorded motor / load angle,
  `effect(angle, inv)` (Song et al. eq. (9));
- `compliance_ripple_m`, `compliance_ripple_l`: a relative change of the series compliance
  from the recorded motor / load angle, `effect(angle, inv)` and `max_change()` (the plant
  scales the compliance budget by one plus the sum of the changes);
- `motor_friction`, `output_friction`: a friction torque [N·m] from the motor / link speed,
  `effect(omega, inv)`;
- `compliance`: a deflection [rad] in series with the flexspline, `deflection(T, inv)` and
  `slope(T, inv)` (the plant then inverts the budget by Newton steps);
- `spring`: a torque [N·m] in parallel with the flexspline, `torque(d_eff)`;
- `hysteresis`, `temperature`, `wave_generator`: the state-carrying or closed-form effects the
  plant handles by name (at most one each).
"""


# ---------------------------------------------------------------------------------------------
# Regression terms
# ---------------------------------------------------------------------------------------------


class AbstractTerm(eqx.Module):
    r"""A named group of columns of the twist model (Song et al. eq. (10)), linear in its
    coefficients.

    Every field is static (hashable hyperparameters fixed at construction), so a term can sit
    in a static field of [`hdjax.compliance.ComplianceModel`][] and is never traced.

    `torque_kind` tells the inversion how the group depends on the torque $T$:

    - `"none"`: not at all (a column of the torque-free part $h$);
    - `"linear"`: $\psi = u(x) T$, solved in closed form (`torque_slope` gives $u$);
    - `"memoryless"`: nonlinearly through the present torque only, solved by safeguarded
      Newton steps (`value_and_slope`);
    - `"path"`: through the torque history, solved by fixed-point iteration on the causally
      estimated torque path.

    **Subclasses implement:** `key` (the vocabulary key), `names()` (one name per column),
    `columns(sig, torque)` (JAX, shape `(n, len(names))`) and `numpy_columns(sig, torque)` (the
    same in NumPy: the reference the tests compare with, and what the residual loop scores
    with when `score_in_numpy`). `key` and `names` are often templates over the fields
    ([`labels`][]); a hyperparameter declared with
    `hyper(..., positive=True)` is checked here, at construction.

    **For the exported estimator** (`hdjax export`), a term also defines
    `c_code(c) -> CSnippet`: its columns as C code of one sample
    ([`hdjax.effects.CSnippet`][], written with the exporter's
    [`hdjax.effects.AbstractCEmitter`][]). A term that leaves `c_code` at `None` works
    everywhere else, and the exporter refuses a model holding it.
    """

    torque_kind: eqx.AbstractClassVar[str]
    score_in_numpy: ClassVar[bool] = True
    static_hypers: ClassVar[tuple[str, ...]] = ()
    """Float hyperparameters that the column programs keep as constants. The others reach
    them as traced values (one compiled program then serves every value), so the columns must
    compute with a traced value wherever they read one (no Python `if` or `float()` on it; select
    with `jnp.where`): a term whose columns branch on such a value in Python names it here."""
    static_while_zero: ClassVar[tuple[str, ...]] = ()
    """Float hyperparameters kept as constants of the column programs while they are 0 (and
    traced otherwise): the columns may skip, in Python, the work such a value switches on."""
    c_code: ClassVar[Callable | None] = None

    def __check_init__(self):
        if self.torque_kind not in TORQUE_KINDS:
            raise ConfigError(
                f"term {type(self).__name__} has torque_kind {self.torque_kind!r}; "
                f"expected one of {TORQUE_KINDS}"
            )
        for f in dataclasses.fields(self):
            if f.metadata.get("positive"):
                check_positive(type(self).__name__, f.name, getattr(self, f.name))

    @property
    @abc.abstractmethod
    def key(self) -> str:
        """The vocabulary key of this term (e.g. `coulomb:omega_m`)."""

    @abc.abstractmethod
    def names(self) -> tuple[str, ...]:
        """One name per column."""

    @abc.abstractmethod
    def columns(self, sig: Signals, torque: SamplesLike | None = None) -> Design:
        """The columns, shape `(n_samples, len(names()))`."""

    @abc.abstractmethod
    def numpy_columns(self, sig: Signals, torque: SamplesLike | None = None) -> NumpyDesign:
        """The columns computed in NumPy (the reference for `columns`)."""

    def beside(self, terms: tuple[AbstractTerm, ...]) -> AbstractTerm:
        """This term as it reads in a model whose effect terms are `terms` (itself among
        them): a term whose columns depend on another term's parameters takes them here
        (the hysteresis of the measured twist takes the encoders' time skew, see
        [`hdjax.effects.TwistHysteresis`][]). Itself by default."""
        return self

    def extrapolating_arguments(self, sig: Signals) -> tuple[Float[np.ndarray, " n"], ...]:
        """The signals (NumPy, one value per sample) in which a fit of this term, as a base
        term of a starting model, extrapolates outside the range it was fitted on: those its
        columns are smooth, non-periodic functions of over a record. The residual loop's
        cross-validation scores a held-out sample only inside its fold's fitted range of
        each, as a TEST recording covered by TRAIN is. None by default (a function of the
        torque is covered by the torque's own range)."""
        return ()


class AbstractTorqueFreeTerm(AbstractTerm):
    """A term that does not depend on the torque (`torque_kind = "none"`)."""

    torque_kind: ClassVar[str] = "none"


class AbstractColumnListTerm(AbstractTorqueFreeTerm):
    """A torque-free group computed column by column: subclasses implement `column_list(sig)`,
    one 1-D array per column (the compliance model's base design takes the list as it is, so
    XLA fuses the columns without stacking them), and `numpy_columns`."""

    @abc.abstractmethod
    def column_list(self, sig: Signals) -> list[Float[Array, " n"]]:
        """The columns as separate arrays, in the order of `names()`."""

    def columns(self, sig: Signals, torque: SamplesLike | None = None) -> Design:
        return jnp.stack(self.column_list(sig), axis=1)


class AbstractSignalTerm(AbstractTorqueFreeTerm):
    """A one-column, torque-free term that is a function of one named signal, written once for
    both array libraries: subclasses have a `signal` (a field or a property: the signal or extra
    column it reads) and implement `transform(x, xp)` with `xp` either `jax.numpy` or
    `numpy`."""

    @abc.abstractmethod
    def transform(self, x: SamplesLike, xp: ModuleType) -> Float[ArrayLike, " n"]:
        """The column as a function of the signal `x`, with array namespace `xp`."""

    def columns(self, sig: Signals, torque: SamplesLike | None = None) -> Float[Array, "n 1"]:
        return self.transform(sig.get(self.signal), jnp)[:, None]

    def numpy_columns(
        self, sig: Signals, torque: SamplesLike | None = None
    ) -> Float[np.ndarray, "n 1"]:
        return self.transform(np.asarray(sig.get(self.signal)), np)[:, None]


class AbstractLinearTorqueTerm(AbstractTerm):
    r"""A term linear in torque, $\psi = u(x) T$ (`torque_kind = "linear"`), inverted in closed
    form. Subclasses implement `torque_slope(sig)` $= u(x)$ and its NumPy twin: shape
    `(n_samples,)` for a one-column term, `(n_samples, n_columns)` for a group (e.g. the
    $\sin, \cos$ pair of a compliance ripple), one column of $u$ per column of the group."""

    torque_kind: ClassVar[str] = "linear"

    @abc.abstractmethod
    def torque_slope(self, sig: Signals) -> Float[Array, "n ..."]:
        r"""$u(x)$ with $\psi = u(x) T$."""

    @abc.abstractmethod
    def numpy_torque_slope(self, sig: Signals) -> Float[np.ndarray, "n ..."]:
        """`torque_slope` in NumPy."""

    def torque_gain(self, sig: Signals, coef: Float[ArrayLike, " k"]) -> Samples:
        r"""$\partial\psi/\partial T = u(x)\,c$ for the group's fitted coefficients `coef`."""
        u = self.torque_slope(sig)
        return u @ coef if u.ndim == 2 else u * coef[0]

    def columns(self, sig: Signals, torque: SamplesLike) -> Design:
        u = self.torque_slope(sig)
        return (u if u.ndim == 2 else u[:, None]) * torque[:, None]

    def numpy_columns(self, sig: Signals, torque: SamplesLike | None = None) -> NumpyDesign:
        u = self.numpy_torque_slope(sig)
        return (u if u.ndim == 2 else u[:, None]) * np.asarray(torque)[:, None]


class AbstractMemorylessTerm(AbstractTerm):
    r"""A one-column term $\psi = f(T)$ of the present torque (`torque_kind = "memoryless"`).

    Subclasses implement `value_and_slope(torque)` $= (f(T), f'(T))$ (the inversion's Newton
    steps use the slope) and `numpy_value(torque)`.
    """

    torque_kind: ClassVar[str] = "memoryless"

    @abc.abstractmethod
    def value_and_slope(
        self, torque: Pointwise
    ) -> tuple[Float[ArrayLike, "*shape"], Float[ArrayLike, "*shape"]]:
        """$(f(T), f'(T))$."""

    @abc.abstractmethod
    def numpy_value(self, torque: Pointwise) -> Float[np.ndarray, "*shape"]:
        """$f(T)$ in NumPy."""

    def columns(self, sig: Signals, torque: SamplesLike) -> Float[Array, "n 1"]:
        return self.value_and_slope(torque)[0][:, None]

    def numpy_columns(
        self, sig: Signals, torque: SamplesLike | None = None
    ) -> Float[np.ndarray, "n 1"]:
        return self.numpy_value(np.asarray(torque))[:, None]


class AbstractPathTerm(AbstractTerm):
    """A term driven by the torque history (`torque_kind = "path"`): hysteresis."""

    torque_kind: ClassVar[str] = "path"
    score_in_numpy: ClassVar[bool] = False


# ---------------------------------------------------------------------------------------------
# Plant effects
# ---------------------------------------------------------------------------------------------


class AbstractPlantEffect(eqx.Module):
    """An effect the plant simulates: array parameters (differentiable) and `reciprocals()`.

    `reciprocals()` returns the inverses of its scale parameters (name -> array; the fields
    declared `bound(..., inverse=True)`); the simulator computes them once outside the time
    loop and passes them back as `inv=`, because a division by a parameter inside the loop
    keeps XLA from fusing the step (see `hdjax/plant/_dynamics.py`).

    [`from_params`][] builds one from a parameter table, validated in plain Python: the
    fields' jaxtyping annotations give the shapes (`Float[Array, ""]` a number,
    `Float[Array, " n"]` a list, fields naming the same dimension of equal length) and
    [`bound`][] the signs.
    """

    def reciprocals(self) -> dict:
        """Inverses of the scale parameters (those declared `bound(..., inverse=True)`),
        computed once outside the time loop."""
        return {
            f.name: 1.0 / getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.metadata.get("inverse")
        }

    @classmethod
    def entry(cls, name: str, slot: str, defaults: Callable) -> PlantEffect:
        """The [`PlantEffect`][] that switches this effect on as `name` in `slot`, with the
        `defaults` given and built by [`from_params`][]."""
        return PlantEffect(name, slot, defaults, cls.from_params)

    @classmethod
    def from_params(cls, name: str, params: Mapping) -> AbstractPlantEffect:
        """The effect `name` from its parameters `params` (field name -> value; the static
        fields are passed as they are), after checking each array parameter's shape, that it
        is finite and its [`bound`][]; `ConfigError` naming the parameter otherwise."""
        hints = _array_hints(cls)
        sizes: dict[str, tuple] = {}
        values = {}
        for f in dataclasses.fields(cls):
            if f.name not in hints:
                if f.name in params:
                    values[f.name] = params[f.name]
                continue
            dims = hints[f.name]
            value = params[f.name]
            if dims:
                value = vector(name, f.name, value)
                shape = sizes.setdefault(dims[0], tuple(value.shape))
            else:
                shape = ()
            rule = f.metadata.get("bound", "finite")
            require(
                name,
                f.name,
                value,
                positive=rule == "positive",
                nonneg=rule == "nonneg",
                shape=shape,
            )
            values[f.name] = f64(value)
        return cls(**values)


@functools.cache
def _array_hints(cls) -> dict[str, tuple[str, ...]]:
    # field name -> its dimension names, for the fields annotated as jaxtyping arrays
    out = {}
    for field_name, hint in typing.get_type_hints(cls).items():
        if hasattr(hint, "dim_str"):
            out[field_name] = tuple(hint.dim_str.split())
    return out


class AbstractFriction(AbstractPlantEffect):
    """A friction law for the `motor_friction` / `output_friction` slots:
    `effect(omega, inv)` [N·m], and `max_slope()`, its largest slope $|dF/d\\omega|$ near zero
    speed [N·m·s/rad] (the integrator's stability check uses it)."""

    @abc.abstractmethod
    def __call__(self, omega: Pointwise, inv: dict | None = None) -> PointwiseOut:
        """The friction torque at speed `omega`."""

    @abc.abstractmethod
    def max_slope(self) -> Float[Array, ""]:
        """The largest slope of the friction law (a float or a 0-d array)."""


class AbstractHysteresis(AbstractPlantEffect):
    """A hysteresis law for the `hysteresis` slot: `rate(z, d_dot, inv)` ($\\dot z$ of the
    hysteresis torque), `saturation()` (the loop's half-height) and `initial_stiffness()` (the
    stiffness right after a reversal, for the integrator's stability check)."""

    @abc.abstractmethod
    def rate(self, z: Pointwise, d_dot: Pointwise, inv: dict | None = None) -> PointwiseOut:
        """$\\dot z$ at hysteresis torque `z` and deflection rate `d_dot`."""

    @abc.abstractmethod
    def saturation(self) -> Float[Array, ""]:
        """The loop's half-height [N·m]."""

    @abc.abstractmethod
    def initial_stiffness(self) -> Float[Array, ""]:
        """$dz/dd$ right after a reversal [N·m/rad]."""


_SLOT_BASES = {
    "motor_friction": AbstractFriction,
    "output_friction": AbstractFriction,
    "hysteresis": AbstractHysteresis,
}


def check_slot(name: str, slot: str, effect) -> None:
    """Raise `ConfigError` when a built plant effect does not have its slot's interface."""
    base = _SLOT_BASES.get(slot, AbstractPlantEffect)
    if not isinstance(effect, base):
        raise ConfigError(
            f"plant effect {name!r} in slot {slot!r} must be an {base.__name__}, got "
            f"{type(effect).__name__}"
        )


@dataclasses.dataclass(frozen=True)
class PlantEffect:
    """How a family switches an effect on in the plant.

    **Fields:**

    - `name`: the plant's effect name (`PlantParams.effects` key, e.g. `coulomb_m`).
    - `slot`: where it enters the joint, one of [`hdjax.effects.PLANT_SLOTS`][].
    - `defaults`: `(rated_torque, k1, given) -> dict`, the default parameters for a joint of that
      rated torque [N·m] and small-torque compliance [rad/N·m] (`given` are the user's
      parameters, for families whose defaults depend on a choice such as the hysteresis model).
    - `build`: `(name, params) -> AbstractPlantEffect`, validating in plain Python.
    """

    name: str
    slot: str
    defaults: Callable[[float, float, Mapping], dict]
    build: Callable[[str, dict], AbstractPlantEffect]

    def __post_init__(self):
        if self.slot not in PLANT_SLOTS:
            raise ConfigError(
                f"plant effect {self.name!r}: slot {self.slot!r} is not one of {PLANT_SLOTS}"
            )


SIDES = {
    "friction": ("motor_friction", "output_friction"),
    "kinematic": ("kinematic_m", "kinematic_l"),
    "compliance_ripple": ("compliance_ripple_m", "compliance_ripple_l"),
}
"""The slot pairs of the effects that act on the motor side and on the output side."""


def both_sides(stem: str, sides: str, build: Callable, *, motor: Callable, output: Callable):
    """The plant effects `<stem>_m` and `<stem>_l` of a family acting on either side of the
    joint, in the slot pair [`SIDES`][]`[sides]`, with one builder and the defaults `motor`
    and `output` (see [`PlantEffect`][])."""
    slot_m, slot_l = SIDES[sides]
    return (
        PlantEffect(f"{stem}_m", slot_m, motor, build),
        PlantEffect(f"{stem}_l", slot_l, output, build),
    )


# ---------------------------------------------------------------------------------------------
# Candidates for the residual loop
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One candidate effect: its vocabulary `key`, `family` and the term group it adds."""

    key: str
    family: str
    term: AbstractTerm
    origin: str = "grid"

    @classmethod
    def of(cls, term: AbstractTerm, origin: str = "grid") -> Candidate:
        """The candidate that adds `term`, under its own key as key and family."""
        return cls(term.key, term.key, term, origin)


@typing.runtime_checkable
class OptionsLike(typing.Protocol):
    """The library options a [`CandidateContext`][] carries: a dataclass instance with one
    field per family option ([`hdjax.discover.LibraryOptions`][], built by the discover layer,
    which this one does not import)."""

    __dataclass_fields__: ClassVar[dict]


OptionValue = Sequence[float] | float
"""A family option's value: a grid of numbers, a (min, max) pair, or one number (a count, a
threshold)."""


@dataclasses.dataclass
class CandidateContext:
    """What a family's candidate generator may read (built by the residual loop each step).

    **Fields:** `sig` (training [`hdjax.compliance.Signals`][]), `torque` (reference torque),
    `residual` (twist residual of the present model), `ratio`, `rated_torque`, `twist_sign`,
    `existing_keys` / `existing_terms` (effects already in the model, not offered again),
    `extra_columns` (usable extra recording columns), `families` (discover families switched
    on), `options` (the library options), `spectrum_orders` (a callable
    `(signal, order_range, named_orders, existing_orders, n_peaks, *, residual=None,
    where=None) -> [(order, origin)]`: the spectrum peaks of the residual against `signal`
    (refined) and the named orders it can resolve, not yet in the model; it records the
    spectrum; spectrum families call it. With `residual` (and a boolean mask `where` of the
    samples it covers) it analyses that signal instead and records nothing: the ripple family
    passes residual ÷ torque).
    """

    sig: Signals
    torque: SamplesLike
    residual: SamplesLike
    ratio: float
    rated_torque: float
    twist_sign: float
    existing_keys: tuple[str, ...]
    existing_terms: tuple
    extra_columns: tuple[str, ...]
    families: frozenset
    options: OptionsLike
    spectrum_orders: Callable | None = None
    unidentified: list = dataclasses.field(default_factory=list)
    """One line per family the data cannot identify (a log too short or too one-sided),
    naming the family and what data would identify it; a family that offers nothing for such a
    reason says so here rather than falling silent."""

    def option(self, family: AbstractFamily, name: str) -> OptionValue:
        """A library option of `family`, or the family's default when the options lack it."""
        return getattr(self.options, name, family.options[name])

    def wants(self, family_name: str) -> bool:
        """Whether the discover family `family_name` is switched on and not yet in the model."""
        return family_name in self.families and family_name not in self.existing_keys

    def cannot_identify(self, family_name: str, why: str, needs: str) -> None:
        """Record that the data cannot identify `family_name`: `why`, and the data that `needs`
        (both short clauses)."""
        self.unidentified.append(f"{family_name} cannot be identified: {why}; {needs}")

    def barely_identify(self, family_name: str, why: str, needs: str) -> None:
        """Record that the data identify `family_name` only through a small part of it (it is
        still offered): `why`, and the data that `needs` (both short clauses)."""
        self.unidentified.append(f"{family_name} is barely identified: {why}; {needs}")


# ---------------------------------------------------------------------------------------------
# The family
# ---------------------------------------------------------------------------------------------


class AbstractFamily(eqx.Module):
    """One physical effect family: its terms, plant effects, vocabulary and candidates.

    **Class variables:** every family declares

    - `name`: short name (`"coulomb"`);
    - `terms`: its [`hdjax.effects.AbstractTerm`][] classes (the saved-model type table is the
      union over the registered families);

    and, where it has them,

    - `plant_effects`: its [`hdjax.effects.PlantEffect`][] entries (default none);
    - `discover_families`: the names the residual loop offers it under
      (`"coulomb:omega_m"`, ...; default none);
    - `vocabulary`: the keys it reports, as written in a discover report (default: its
      `discover_families`, comma-separated; see [`vocabulary_text`][]);
    - `options`: library options (grids) with their defaults (default none); they become
      fields of [`hdjax.discover.LibraryOptions`][].

    **Methods:** `candidates(ctx)`: the terms to try at one step of the residual loop;
    `neighbours(term, step)`: where a family's candidate has a continuous setting offered on
    a grid (a hysteresis width), the term with that setting a factor `step` up and down, which
    the loop tries to refine the setting it chose (default: none), and `setting_text(term)`,
    that setting as the loop's notes write it.
    """

    name: eqx.AbstractClassVar[str]
    terms: eqx.AbstractClassVar[tuple]
    plant_effects: ClassVar[tuple] = ()
    discover_families: ClassVar[tuple] = ()
    vocabulary: ClassVar[str | None] = None
    options: ClassVar[dict] = {}

    def vocabulary_text(self) -> str:
        """The keys this family reports, as a discover report writes them."""
        if self.vocabulary is None:
            return ", ".join(self.discover_families)
        return self.vocabulary

    def __check_init__(self):
        owner = f"effect family {type(self).__name__}"
        if not (isinstance(self.name, str) and self.name):
            raise ConfigError(f"{owner}: name must be a non-empty string")
        for t in self.terms:
            if not (isinstance(t, type) and issubclass(t, AbstractTerm)):
                raise ConfigError(f"{owner}: terms must be AbstractTerm subclasses, got {t!r}")
        for p in self.plant_effects:
            if not isinstance(p, PlantEffect):
                raise ConfigError(f"{owner}: plant_effects must be PlantEffect, got {p!r}")
        if self.discover_families and not self.terms:
            raise ConfigError(f"{owner}: a family the loop can offer needs at least one term")
        if not isinstance(self.options, dict):
            raise ConfigError(f"{owner}: options must be a dict name -> default")

    @abc.abstractmethod
    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        """The candidate terms of this family for one step of the residual loop."""

    def neighbours(self, term: AbstractTerm, step: float) -> list[AbstractTerm]:
        """`term` with its continuous setting a factor `step` up and down (none by default)."""
        return []

    def setting_text(self, term: AbstractTerm) -> str:
        """The setting `neighbours` moves, as a report writes it (empty by default)."""
        return ""


class AbstractTorqueScaleFamily(AbstractFamily):
    r"""A family whose one term is a memoryless function of the torque with one torque scale,
    offered at fractions of the rated torque $\tau_0$ (Song et al. eq. (7) places the compliance
    knots at fractions of $\tau_0$ too).

    **Class variables**, besides those of [`hdjax.effects.AbstractFamily`][] (one term, one
    discover family):

    - `scale_field`: the term's field that holds the torque scale [N·m];
    - `fractions`: the fractions of $\tau_0$ tried (default `(1.0,)`: the scale $\tau_0$);
    - `fractions_option`: the name of a library option (one of `options`) that holds the
      fractions instead, so a user may change the grid (default none).
    """

    scale_field: eqx.AbstractClassVar[str]
    fractions: ClassVar[tuple[float, ...]] = (1.0,)
    fractions_option: ClassVar[str | None] = None

    def __check_init__(self):
        owner = f"effect family {type(self).__name__}"
        if len(self.terms) != 1 or len(self.discover_families) != 1:
            raise ConfigError(
                f"{owner}: a torque-scale family has one term and one discover family"
            )
        if self.scale_field not in {f.name for f in dataclasses.fields(self.terms[0])}:
            raise ConfigError(f"{owner}: scale_field {self.scale_field!r} is no field of its term")
        if self.fractions_option is not None and self.fractions_option not in self.options:
            raise ConfigError(
                f"{owner}: fractions_option {self.fractions_option!r} is not an option"
            )

    def candidates(self, ctx: CandidateContext) -> list[Candidate]:
        """One candidate of the family's term per fraction $f$: the scale $f\tau_0$."""
        (term,), (key,) = self.terms, self.discover_families
        if not ctx.wants(key):
            return []
        option = self.fractions_option
        fractions = self.fractions if option is None else ctx.option(self, option)
        return [Candidate.of(term(**{self.scale_field: f * ctx.rated_torque})) for f in fractions]


def coupled(terms: Sequence[AbstractTerm]) -> tuple[AbstractTerm, ...]:
    """`terms` (a model's effect terms), each as it reads beside the others
    ([`AbstractTerm.beside`][])."""
    terms = tuple(terms)
    return tuple(t.beside(terms) for t in terms)
