r"""The switchable physical effects of the plant, built by name from the effect families.

Every effect is off unless it is named in [`hdjax.plant.PlantParams`][]`.effects`. The effects
themselves live with their family in [`hdjax.effects`][] (one module per family, e.g.
`hdjax/effects/_coulomb.py`); each registered family declares its plant effects (name, slot,
defaults, builder), and this module only looks them up. Build effects by name with
[`hdjax.plant.make_effect`][], which validates names, shapes and signs in plain Python.

Friction laws use a smooth sign, $\operatorname{sgn}(\omega) \approx \tanh(\omega/\omega_s)$, so
gradients exist everywhere (Song et al. 2019 name "un-modelled friction" as their main error
source, Section IV.C).

Each effect has `reciprocals()`, the inverses of its scale parameters; the simulator computes
them once outside the time loop and passes them as `inv=`, because a division by a parameter
inside the loop keeps XLA from fusing the step into a few kernels (a 10-50x slowdown on CPU).

**Conventions.** The deflection $d = \theta_m/N - \theta_l$ is Hashimoto's $q_M/N - q_L$
(eq. (17)); the transmitted torque grows with it. The recorded angles are counted the other way
round, so that in a recording the twist $\theta_l - \theta_m/N$ (Song et al. eq. (5)) equals $d$
and grows with the recorded torque (see `hdjax/plant/_dynamics.py`).
"""

from __future__ import annotations

from .. import effects
from .._custom_types import ArrayInput
from .._errors import ConfigError, did_you_mean
from ..effects import AbstractPlantEffect
from ..effects.internal import check_slot, concrete as _concrete

__all__ = ["EFFECT_NAMES", "check_effect_name", "make_effect", "_concrete"]

EFFECT_NAMES = effects.plant_effect_names()
"""Names of the built-in switchable effects, in the order the plant applies them (families
registered later add theirs: `hdjax.effects.plant_effect_names()`)."""


def check_effect_name(name: str) -> None:
    """Raise `ConfigError` for an unknown effect name, listing the known ones."""
    effects.plant_effect(name)


def make_effect(
    name: str,
    *,
    rated_torque: float = 400.0,
    k1: float = 1.4925e-5,
    # the parameters as the user gives them (numbers, lists, a model name), checked by the
    # effect's builder with a ConfigError that names the parameter
    **kwargs: ArrayInput | str,
) -> AbstractPlantEffect:
    """Build one effect module by name, filling unspecified parameters with defaults.

    **Arguments:**

    - `name`: one of `hdjax.effects.plant_effect_names()` (the built-ins are
      [`hdjax.plant.EFFECT_NAMES`][]).
    - `rated_torque`, `k1`: scale the defaults to the joint (rated torque [N·m] and the
      small-torque compliance [rad/N·m]).
    - `**kwargs`: the effect's parameters (see each effect class); unknown keys raise.

    **Returns:** the effect module.
    """
    spec = effects.plant_effect(name)
    params = dict(spec.defaults(rated_torque, k1, kwargs))
    unknown = [k for k in kwargs if k not in params]
    if unknown:
        raise ConfigError(
            f"effect {name!r}: unknown parameter(s) {', '.join(map(repr, unknown))}"
            f"{did_you_mean(unknown[0], params)}; its parameters are {', '.join(params)}"
        )
    params.update(kwargs)
    effect = spec.build(name, params)
    check_slot(name, spec.slot, effect)
    return effect
