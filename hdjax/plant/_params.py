r"""Plant parameters and the two presets (Song et al. 2019 bench; Hashimoto et al. 1993 Table I).

[`hdjax.plant.PlantParams`][] is an `eqx.Module` whose leaves are float64 arrays, so a loss can be
differentiated with respect to every parameter and a batch of parameter sets can be `vmap`-ed.
Switchable effects live in the `effects` dict (name -> effect module, see
`hdjax/plant/_effects.py`); an effect that is absent is off.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Mapping

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .. import effects as _effects_registry
from .._custom_types import Array, ArrayInput, Float
from .._errors import ConfigError, check_keys, did_you_mean
from ..effects import bound
from ._effects import _concrete, check_effect_name, make_effect

_f64 = lambda x: jnp.asarray(x, jnp.float64)

FLEXSPLINE_KINDS = ("piecewise", "smooth")


class PlantParams(eqx.Module):
    r"""Physical parameters of the two-inertia harmonic-drive joint.

    **Arguments:**

    - `ratio`: reduction ratio $N$ (Song et al. eq. (1)).
    - `rated_torque`: rated torque $\tau_0$ [N·m]; places the compliance knots at $\pm\tau_0/3$,
      $\pm 2\tau_0/3$ (Song et al. eq. (7)).
    - `inertia_m`: motor rotor plus wave-generator inertia $J_M$ [kg·m²].
    - `inertia_l`: link (plus torque-sensor flange) inertia $J_L$ [kg·m²].
    - `torque_constant`: $K_t$ [N·m/A], motor torque $K_t i$.
    - `current_time_constant`: $\tau_i$ [s] of the first-order current loop
      $\dot i = (i_{ref} - i)/\tau_i$.
    - `compliance`: $(k_1, k_2, k_3, k_4, k_5)$ [rad/N·m], the flexspline compliances of Song et
      al. eq. (7) ($k_1$ on $|T| < \tau_0/3$, $k_4, k_5$ above, $k_2, k_3$ below).
    - `damping`: structural damping $c$ [N·m·s/rad] on the deflection rate.
    - `corner`: torque width [N·m] over which the `"smooth"` flexspline rounds the knots.
    - `effects`: switched-on effects, name -> module (see [`hdjax.plant.EFFECT_NAMES`][]).
    - `flexspline`: `"piecewise"` (Song eq. (7), exact) or `"smooth"` (softplus-rounded knots).
    - `newton_iterations`: Newton steps used to invert the series compliance when the wave
      generator, backlash or the smooth flexspline make it non-piecewise-linear (static).
    """

    # the scalars with their sign, checked in __check_init__ (a joint may be undamped)
    ratio: Float[Array, ""] = bound("positive")
    rated_torque: Float[Array, ""] = bound("positive")
    inertia_m: Float[Array, ""] = bound("positive")
    inertia_l: Float[Array, ""] = bound("positive")
    torque_constant: Float[Array, ""] = bound("positive")
    current_time_constant: Float[Array, ""] = bound("positive")
    compliance: Float[Array, " n_segments"]  # five (eq. (7)), checked in __check_init__
    damping: Float[Array, ""] = bound("nonneg")
    corner: Float[Array, ""] = bound("positive")
    effects: dict
    flexspline: str = eqx.field(static=True, default="piecewise")
    newton_iterations: int = eqx.field(static=True, default=3)

    def __check_init__(self):
        for name, sign in _SCALARS.items():
            arr = _concrete(getattr(self, name))
            if arr is None:
                continue
            if arr.shape != ():
                raise ConfigError(
                    f"plant parameter {name!r} must be a scalar, got shape {arr.shape}"
                )
            if not np.isfinite(arr):
                raise ConfigError(f"plant parameter {name!r} must be finite, got {float(arr)}")
            if sign == "positive" and not arr > 0:
                raise ConfigError(f"plant parameter {name!r} must be positive, got {float(arr)}")
            if sign == "nonneg" and arr < 0:
                raise ConfigError(f"plant parameter {name!r} must be >= 0, got {float(arr)}")
        k = _concrete(self.compliance)
        if k is not None:
            if k.shape != (5,):
                raise ConfigError(
                    "plant parameter 'compliance' must hold the five compliances k1..k5 of Song "
                    f"et al. eq. (7), shape (5,), got shape {k.shape}"
                )
            if not np.all(np.isfinite(k) & (k > 0)):
                raise ConfigError(
                    "plant parameter 'compliance' (k1..k5, rad/N·m) must be positive: a "
                    f"non-positive compliance is a non-monotone spring; got {k.tolist()}"
                )
        if self.flexspline not in FLEXSPLINE_KINDS:
            raise ConfigError(
                f"flexspline must be one of {', '.join(FLEXSPLINE_KINDS)}, got "
                f"{self.flexspline!r}{did_you_mean(str(self.flexspline), FLEXSPLINE_KINDS)}"
            )
        if not isinstance(self.effects, dict):
            raise ConfigError(f"effects must be a dict name -> effect, got {type(self.effects)}")
        for name in self.effects:
            check_effect_name(name)

    def has(self, name: str) -> bool:
        """Whether the effect `name` is switched on."""
        return name in self.effects

    @property
    def effect_names(self) -> tuple[str, ...]:
        """Switched-on effects in registry order."""
        return tuple(n for n in _effects_registry.plant_effect_names() if n in self.effects)


_SCALARS = {
    f.name: f.metadata["bound"] for f in dataclasses.fields(PlantParams) if "bound" in f.metadata
}
"""The scalar parameters and their sign (`"positive"` or `"nonneg"`), from their fields."""


def _k1(params) -> float:
    k = _concrete(params.compliance)
    return 1.4925e-5 if k is None else float(k[0])


def with_effects(
    params: PlantParams, effects: Mapping | None = None, **more: object
) -> PlantParams:
    """A copy of `params` with effects switched on, replaced or (with value `None`/`False`) off.

    **Arguments:**

    - `params`: the parameters to start from.
    - `effects`, `**more`: name -> parameters. A value may be an effect module, a dict of
      parameters (missing ones take defaults, see `make_effect`), `True` (all defaults) or
      `None`/`False` (switch off).

    **Returns:** new `PlantParams`.
    """
    spec = dict(effects or {})
    spec.update(more)
    new = dict(params.effects)
    rated = _concrete(params.rated_torque)
    rated = 400.0 if rated is None else float(rated)
    for name, value in spec.items():
        check_effect_name(name)
        if value is None or value is False:
            new.pop(name, None)
        elif value is True:
            new[name] = make_effect(name, rated_torque=rated, k1=_k1(params))
        elif isinstance(value, Mapping):
            new[name] = make_effect(name, rated_torque=rated, k1=_k1(params), **dict(value))
        elif isinstance(value, eqx.Module):
            new[name] = value
        else:
            raise ConfigError(
                f"effect {name!r}: expected a dict of parameters, True, None or an effect module, "
                f"got {type(value).__name__}"
            )
    return eqx.tree_at(lambda p: p.effects, params, new)


def make_params(
    *,
    # the numbers as the user gives them: `PlantParams` checks each one's shape, finiteness and
    # sign with a ConfigError that names the parameter (a type check would pre-empt it)
    ratio: ArrayInput,
    rated_torque: ArrayInput,
    inertia_m: ArrayInput,
    inertia_l: ArrayInput,
    torque_constant: ArrayInput,
    current_time_constant: ArrayInput,
    compliance: ArrayInput,
    damping: ArrayInput = 0.0,
    corner: ArrayInput | None = None,
    effects: Mapping | None = None,
    flexspline: str = "piecewise",
    newton_iterations: int = 3,
) -> PlantParams:
    """Build validated `PlantParams` from numbers (see [`hdjax.plant.PlantParams`][])."""
    rated = float(rated_torque)
    base = PlantParams(
        ratio=_f64(ratio),
        rated_torque=_f64(rated_torque),
        inertia_m=_f64(inertia_m),
        inertia_l=_f64(inertia_l),
        torque_constant=_f64(torque_constant),
        current_time_constant=_f64(current_time_constant),
        compliance=_f64(compliance),
        damping=_f64(damping),
        corner=_f64(0.02 * rated if corner is None else corner),
        effects={},
        flexspline=flexspline,
        newton_iterations=newton_iterations,
    )
    return with_effects(base, effects or {})


# Catalogue values for Harmonic Drive CSF/CSG size 40, ratio >= 80 (the size that carries the
# paper's 400 N·m at ratio 160): K1 = 6.7e4 N·m/rad below T1 = 137 N·m, K2 = 1.1e5 up to
# T2 = 392 N·m, K3 = 1.2e5 above. The segment *shape* comes from the paper's fitted k1..k5
# (Song et al. Section II.C: 0.26305, 0.19913, 0.04946, 0.29008, 0.08434, units not stated),
# scaled so that k1 = 1/K1 of the catalogue.
_SONG_K_PAPER = np.array([0.26305, 0.19913, 0.04946, 0.29008, 0.08434])
SONG_COMPLIANCE = _SONG_K_PAPER * ((1.0 / 6.7e4) / _SONG_K_PAPER[0])
"""Default flexspline compliances k1..k5 [rad/N·m] of the Song preset (see `song_params`)."""

SONG_DEFAULT_EFFECTS = (
    "harmonic_m",
    "harmonic_l",
    "coulomb_m",
    "viscous_m",
    "coulomb_l",
    "viscous_l",
    "hysteresis",
    "wg_compliance",
)
"""Effects switched on in the Song preset (the rest stay off for 'undeclared effect' tests)."""


def song_params(
    effects: Mapping | None = None, *, defaults: bool = True, **kwargs: ArrayInput | str | None
) -> PlantParams:
    r"""The Song et al. (2019) bench (Section IV.A, Figs. 7-8): ratio 160, rated torque 400 N·m.

    Sources of the defaults:

    - `ratio` 160, `rated_torque` 400 N·m: Song et al. Section IV.A.
    - `compliance`: paper's k1..k5 shape scaled to the CSG/CSF-40 catalogue K1 = 6.7e4 N·m/rad
      (see `SONG_COMPLIANCE`); the resulting stiffnesses span 5.1e4..3.6e5 N·m/rad.
    - `inertia_m` 1.5e-4 kg·m²: a 750 W-class servo rotor (~1.0e-4) plus a size-40 wave
      generator (~0.5e-4); assumption, the paper gives no motor data.
    - `inertia_l` 1.0 kg·m²: a ~1 m aluminium link with sensor flange; assumption.
    - `torque_constant` 0.25 N·m/A, `current_time_constant` 1/(2π·1 kHz): a typical servo
      driver current loop (the paper's driver feeds current back every 0.5 ms).
    - `damping` 20 N·m·s/rad: about 5 % of critical damping of the joint mode; assumption.
    - Effects on by default: kinematic error (≈1 arcmin transmission accuracy), motor and output
      friction, Bouc-Wen hysteresis (≈1 arcmin hysteresis loss) and wave-generator compliance
      (Song eq. (8) shape, ≈10 % of the twist at rated torque). `defaults=False` switches them off.

    **Arguments:**

    - `effects`: further effects (name -> parameters, see `with_effects`).
    - `defaults`: keep the default effects on.
    - `**kwargs`: overrides of the scalar parameters (`damping=...`, `flexspline=...`).

    **Returns:** `PlantParams`.
    """
    on = {name: True for name in SONG_DEFAULT_EFFECTS} if defaults else {}
    return _from_preset("song", kwargs, on, effects)


def hashimoto_params(
    effects: Mapping | None = None, **kwargs: ArrayInput | str | None
) -> PlantParams:
    r"""Hashimoto et al. (1993) one-link arm, Table I, eqs. (15)-(17).

    $J_L = 0.88$ kg·m², $J_M = 9.4\cdot10^{-5}$ kg·m², $K = 8800$ N·m/rad (all five compliances
    $1/K$: a linear joint), $K_t = 0.1$ N·m/V (taken per ampere), $N = 100$. The rated torque 40
    N·m follows from the paper's "hysteresis loss ±4 N·m is 10 % of the rated torque". Damping is
    zero as in the paper's idealisation. Motor-side Coulomb friction $\tau_F$ (eq. (16)) is on
    with $N\tau_F = 4$ N·m, the paper's open-loop hysteresis half-width (Fig. 15), smoothed over
    0.2 rad/s. The current loop (1 kHz) is an assumption.

    **Arguments:**

    - `effects`: further effects (name -> parameters, see `with_effects`).
    - `**kwargs`: overrides of the scalar parameters.

    **Returns:** `PlantParams`.
    """
    return _from_preset(
        "hashimoto", kwargs, {"coulomb_m": {"level": 0.04, "smoothing": 0.2}}, effects
    )


CURRENT_LOOP_TIME_CONSTANT = 1.0 / (2.0 * np.pi * 1000.0)
"""The current loop of both presets [s]: 1 kHz, a typical servo driver's (an assumption)."""


_PRESET_NAMES = ("song", "hashimoto")
_PRESETS = {
    # parameter: (Song et al. 2019, Hashimoto et al. 1993); sources in the presets' docstrings
    "ratio": (160.0, 100.0),
    "rated_torque": (400.0, 40.0),
    "inertia_m": (1.5e-4, 9.4e-5),
    "inertia_l": (1.0, 0.88),
    "torque_constant": (0.25, 0.1),
    "compliance": (SONG_COMPLIANCE, np.full(5, 1.0 / 8800.0)),
    "damping": (20.0, 0.0),
}


def _from_preset(preset: str, overrides: dict, on: dict, effects: Mapping | None) -> PlantParams:
    # a preset's parameters (its column of `_PRESETS`) with the user's overrides (refusing
    # unknown names), its effects `on` with the user's `effects` on top
    allowed = [k for k in inspect.signature(make_params).parameters if k != "effects"]
    check_keys(overrides, allowed, noun="plant parameter")
    column = _PRESET_NAMES.index(preset)
    values = {name: row[column] for name, row in _PRESETS.items()}
    scalars = {"current_time_constant": CURRENT_LOOP_TIME_CONSTANT, **values, **overrides}
    return make_params(**scalars, effects={**on, **(effects or {})})
