"""The registry of effect families and the tables derived from it.

Everything that used to be a hand-written table is computed here from the registered families:
the saved-model type table ([`term_types`][]), the plant's effect names and slots
([`plant_effect_names`][], [`plant_effect`][]), the residual loop's families and options
([`discover_families`][], [`library_options`][]) and the vocabulary of a discover report
([`vocabulary`][]). Registering a family is one call, [`register`][].
"""

from __future__ import annotations

from collections.abc import Iterable

from .._errors import ConfigError, did_you_mean
from ._base import AbstractFamily, AbstractTerm, PlantEffect

_FAMILIES: list[AbstractFamily] = []


def register(family: AbstractFamily) -> AbstractFamily:
    """Add an effect family to the catalogue (after the built-in ones); returns it.

    Refuses a family whose name, term types, plant effect names, discover families or option
    names collide with a registered one. Registering the same family class again is a no-op.
    """
    if not isinstance(family, AbstractFamily):
        raise ConfigError(f"register() takes an AbstractFamily instance, got {family!r}")
    if any(type(f) is type(family) for f in _FAMILIES):
        return family
    taken = {
        "family name": [f.name for f in _FAMILIES],
        "term type": [t.__name__ for t in term_types()],
        "plant effect": list(plant_effect_names()),
        "discover family": list(discover_families()),
        "library option": [k for f in _FAMILIES for k in f.options],
    }
    mine = {
        "family name": [family.name],
        "term type": [t.__name__ for t in family.terms],
        "plant effect": [p.name for p in family.plant_effects],
        "discover family": list(family.discover_families),
        "library option": list(family.options),
    }
    for what, names in mine.items():
        for name in names:
            if name in taken[what]:
                raise ConfigError(
                    f"effect family {type(family).__name__}: {what} {name!r} is already "
                    "registered; choose another name"
                )
    _FAMILIES.append(family)
    return family


def unregister(family: AbstractFamily) -> None:
    """Remove a family registered with [`register`][] (tests use it to clean up)."""
    _FAMILIES[:] = [f for f in _FAMILIES if type(f) is not type(family)]


def families() -> tuple[AbstractFamily, ...]:
    """The registered families, in registration order."""
    return tuple(_FAMILIES)


def term_types() -> tuple[type[AbstractTerm], ...]:
    """Every registered term class (the saved-model type table)."""
    return tuple(t for f in _FAMILIES for t in f.terms)


def term_type(name: str) -> type[AbstractTerm]:
    """The term class saved under `name` (its class name)."""
    types = {t.__name__: t for t in term_types()}
    if name not in types:
        raise ConfigError(
            f"unknown term type {name!r}{did_you_mean(name, list(types))}; the registered "
            f"types are {', '.join(types)} (a model saved with a family that is not "
            "registered in this session needs that family registered first)"
        )
    return types[name]


def _family_of(term: AbstractTerm) -> AbstractFamily | None:
    return next((f for f in _FAMILIES if type(term) in f.terms), None)


def neighbours(term: AbstractTerm, step: float) -> list[AbstractTerm]:
    """`term` with its continuous setting a factor `step` up and down, by its family's
    [`hdjax.effects.AbstractFamily`][]`.neighbours` (none for a term without one)."""
    family = _family_of(term)
    return family.neighbours(term, step) if family else []


def setting_text(term: AbstractTerm) -> str:
    """The setting [`neighbours`][] moves, as the loop's notes write it (a hysteresis width),
    by its family; empty for a term without one."""
    family = _family_of(term)
    return family.setting_text(term) if family else ""


def plant_effects() -> tuple[PlantEffect, ...]:
    """Every registered plant effect, in registration order."""
    return tuple(p for f in _FAMILIES for p in f.plant_effects)


def plant_effect_names() -> tuple[str, ...]:
    """Names of the switchable plant effects, in registration order."""
    return tuple(p.name for p in plant_effects())


def plant_effect(name: str) -> PlantEffect:
    """The registered plant effect `name`; `ConfigError` listing the known ones otherwise."""
    for p in plant_effects():
        if p.name == name:
            return p
    names = plant_effect_names()
    raise ConfigError(
        f"unknown plant effect {name!r}{did_you_mean(name, names)}; known effects: "
        f"{', '.join(names)}"
    )


def in_slot(names: Iterable[str], slot: str) -> tuple[str, ...]:
    """Those of the effect `names` that enter the plant in `slot`, in registration order."""
    names = set(names)
    return tuple(p.name for p in plant_effects() if p.slot == slot and p.name in names)


def discover_families() -> tuple[str, ...]:
    """The families the residual loop can offer, in registration order."""
    return tuple(k for f in _FAMILIES for k in f.discover_families)


def vocabulary() -> str:
    """The keys a discover report can name (the report's `vocabulary` entry)."""
    return ", ".join(f.vocabulary_text() for f in _FAMILIES if f.vocabulary_text())


def library_options() -> dict:
    """Every registered family's library options with their defaults, in registration order."""
    return {k: v for f in _FAMILIES for k, v in f.options.items()}
