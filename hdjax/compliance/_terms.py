"""Term groups of the twist model and their saved form.

The twist model of Song et al. eq. (10) is linear in its coefficients,

$$\\Delta\\theta = \\sum_j k_j \\phi_j(T) + h(x) + \\sum_g c_g^\\top \\psi_g(x, T),$$

with the piecewise-linear flexspline basis $\\phi_j$ (eq. (7)), the torque-free terms $h$ of the
wave generator (eq. (8)) and the kinematic error (eq. (9)), and optional *effect* groups
$\\psi_g$ added by the residual loop. Each group is an [`hdjax.effects.AbstractTerm`][] defined
with its physical family in [`hdjax.effects`][]; the type table used to read a saved model is
the registry's ([`hdjax.effects.term_types`][]).
"""

from __future__ import annotations

import dataclasses

from .._errors import ConfigError
from ..effects import TORQUE_PATH as TORQUE_PATH, AbstractTerm, term_type

# Entries older saved models wrote for every term (then dataclass fields, now class-level).
_LEGACY_FIELDS = ("key", "torque_kind")


def term_to_dict(term: AbstractTerm) -> dict:
    """A JSON-ready description of a term group (for saved models and reports)."""
    d = {"type": type(term).__name__}
    for f in dataclasses.fields(term):
        v = getattr(term, f.name)
        d[f.name] = list(v) if isinstance(v, tuple) else v
    return d


def term_from_dict(d: dict) -> AbstractTerm:
    """Inverse of [`term_to_dict`][]; also reads the form older versions wrote (with `key` and
    `torque_kind` entries), checking that they agree with the registered term."""
    d = dict(d)
    if "type" not in d:
        raise ConfigError(f"a saved term has no 'type' entry: {d!r}")
    cls = term_type(d.pop("type"))
    legacy = {k: d.pop(k) for k in _LEGACY_FIELDS if k in d}
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise ConfigError(
            f"saved term {cls.__name__} has unknown field(s) {', '.join(unknown)}; its fields "
            f"are {', '.join(sorted(names)) or '(none)'}"
        )
    term = cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})
    for k, v in legacy.items():
        if getattr(term, k) != v:
            raise ConfigError(
                f"saved term {cls.__name__} says {k}={v!r}, but this version's {cls.__name__} "
                f"has {k}={getattr(term, k)!r}: the model was saved by an incompatible version; "
                "recalibrate it"
            )
    return term
