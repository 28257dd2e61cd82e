"""Every public function and method of hdjax that takes or gives arrays says their dtype and
shape with jaxtyping, so that the import hook (pyproject's pytest `addopts`) checks them.

The walk covers what the packages export (their `__init__`), the methods and properties of the
exported classes, and the generated `__init__` of their dataclasses and equinox modules. A
parameter or return fails when its annotation

- does not resolve (a typo, a name only imported under `TYPE_CHECKING`, or `Float[Array, ...]`
  with a bare ellipsis): jaxtyping then silently checks nothing for it;
- names a bare array type (`jax.Array`, `np.ndarray`, `ArrayLike`) outside a jaxtyping
  `Float[...]`/`Int[...]`/... wrapper, also inside a union, tuple, list or dict;
- is missing, or is `Any`/`object` (at the top: `dict[str, Any]` may hold settings), unless
  the parameter is listed in `NON_ARRAY` below.
"""

import importlib
import inspect
import types
import typing

import jax
import jaxtyping
import numpy as np
import pytest

import hdjax

PACKAGES = ("hdjax", *(f"hdjax.{p}" for p in hdjax._SUBPACKAGES), "hdjax.network.trainers")

# Parameters that never hold an array and may stay unannotated or `Any`/`object`, each with why.
# Keys are "<defining module>.<qualified name>"; values the parameter names ("return" for the
# result).
NON_ARRAY: dict[str, set[str]] = {
    # the fitted value and auxiliary data of a Solution are any pytree (a model, a network, a
    # dict of stats); the result code and stats carry the typed part
    "hdjax._solution.Solution.__init__": {"value", "aux"},
    # the model's remaining fields by keyword (joint, knots, torque_range, velocity)
    "hdjax.compliance._model.ComplianceModel.build": {"static"},
    # twist scales (a tuple of positive numbers) checked in plain Python with a ConfigError that
    # says what is wrong; an annotation would pre-empt that message under the test-time hook
    "hdjax.fit._inputs.dynamic_columns": {"hysteresis"},
    "hdjax.fit._inputs.hybrid_inputs": {"hysteresis"},
    # any JSON-serialisable value (a report's dict of numbers and names)
    "hdjax.report._report.json_bytes": {"obj"},
    "hdjax.report._report.ResultDir.write_json": {"obj"},
    # a configuration value as TOML gives it (a number, a string, a list, a table)
    "hdjax.config._load.parse_value": {"return"},
    "hdjax.config._schema.apply_setting": {"value"},
    # the simulated drive is duck-typed (`initial_state`, `observe`, `step`; IdealJoint,
    # PlantJoint or the user's own), and its state is whatever that drive's state is
    "hdjax.strain._simulate.simulate_torque_control": {"joint", "state0"},
    # any other TorqueController field by keyword (gains, inertias, limits)
    "hdjax.strain._control.hashimoto_controller": {"overrides"},
    # the [data] reference table as the configuration gives it, checked with a ConfigError
    "hdjax.reference._spec.check_reference": {"v"},
    # a PlantParams, refused otherwise in __check_init__ with a ConfigError that says so
    "hdjax.strain._plant_joint.PlantJoint.__init__": {"params"},
    # an effect's switch (an effect module, a dict of its parameters, True, None/False), refused
    # otherwise with a ConfigError that lists what is accepted
    "hdjax.plant._params.with_effects": {"more"},
    # simulate_scenario's keywords, bound to its annotated signature (one list of them)
    "hdjax.plant._scenarios.simulate_scenarios": {"options"},
}

# Module prefixes whose findings are tolerated while another change owns them; each must
# still have a finding (the test fails on a stale entry, so the list only shrinks). Empty: every
# public signature passes.
PENDING: tuple[str, ...] = ()

_RAW = (jax.Array, np.ndarray)
_UNRESOLVED = object()


def _resolve(ann, namespace):
    if not isinstance(ann, str):
        return ann

    def probe(value: ann):  # the same de-stringing jaxtyping's decorator does
        del value

    try:
        return typing.get_type_hints(probe, namespace, include_extras=True)["value"]
    except Exception:
        return _UNRESOLVED


def _problem(ann, top: bool = True) -> str | None:
    """Why an (evaluated) annotation fails the rule, or None."""
    if ann is inspect.Parameter.empty:
        return "no annotation"
    if ann is _UNRESOLVED:
        return "annotation does not resolve (jaxtyping would check nothing)"
    if isinstance(ann, type) and issubclass(ann, jaxtyping.AbstractArray):
        return None
    if ann in _RAW:
        return f"bare {ann.__module__}.{ann.__qualname__}: say dtype and shape with jaxtyping"
    if ann is typing.Any or ann is object:  # inside a container (`dict[str, Any]`) it may stay
        return "Any/object" if top else None
    for arg in typing.get_args(ann):
        for a in arg if isinstance(arg, list) else [arg]:
            if a is Ellipsis or a is type(None) or isinstance(a, str | int):
                continue
            why = _problem(a, top=False)
            if why:
                return why
    return None


def _functions(cls):
    for klass in cls.__mro__:
        if not klass.__module__.startswith("hdjax"):
            continue
        for name, attr in vars(klass).items():
            if name.startswith("_") and name not in ("__init__", "__call__"):
                continue
            if isinstance(attr, staticmethod | classmethod):
                attr = attr.__func__
            if isinstance(attr, property):
                attr = attr.fget
            if isinstance(attr, types.FunctionType | types.MethodType) or (
                callable(attr) and hasattr(attr, "__wrapped__") and not inspect.isclass(attr)
            ):
                yield attr


def _public_functions():
    seen = set()
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in getattr(module, "__all__", None) or dir(module):
            obj = getattr(module, name, None)
            if name.startswith("_") or isinstance(obj, types.ModuleType):
                continue
            if not (getattr(obj, "__module__", None) or "").startswith("hdjax"):
                continue
            if inspect.isclass(obj):
                if issubclass(obj, BaseException) or id(obj) in seen:
                    continue
                seen.add(id(obj))
                candidates = list(_functions(obj))
            elif callable(obj):
                candidates = [obj]
            else:
                continue
            for fn in candidates:
                fn = inspect.unwrap(fn)
                if id(fn) not in seen and isinstance(fn, types.FunctionType):
                    seen.add(id(fn))
                    yield fn


def findings() -> list[tuple[str, str, str]]:
    """(function, parameter, why) for every public parameter or return that breaks the rule."""
    out = []
    for fn in _public_functions():
        where = f"{fn.__module__}.{fn.__qualname__}"
        allowed = NON_ARRAY.get(where, set())
        sig = inspect.signature(fn, eval_str=False)
        slots = [(n, p.annotation) for n, p in sig.parameters.items() if n not in ("self", "cls")]
        if not (fn.__name__ == "__init__" and sig.return_annotation is sig.empty):
            slots.append(("return", sig.return_annotation))
        for name, ann in slots:
            why = _problem(_resolve(ann, fn.__globals__))
            unresolved = why is not None and why.startswith("annotation does not resolve")
            if why and (unresolved or name not in allowed):
                out.append((where, name, why))
    return out


@pytest.fixture(scope="module")
def found():
    return findings()


def test_public_array_signatures_are_annotated(found):
    bad = [f for f in found if not f[0].startswith(PENDING)]
    assert not bad, "\n".join(f"{w}({n}): {why}" for w, n, why in bad)


def test_pending_entries_are_not_stale(found):
    for prefix in PENDING:
        assert any(w.startswith(prefix) for w, _, _ in found), f"{prefix} is done: drop it"


def test_allow_list_is_not_stale():
    names = {f"{fn.__module__}.{fn.__qualname__}": fn for fn in _public_functions()}
    for where, params in NON_ARRAY.items():
        assert where in names, f"NON_ARRAY names {where}, which is no public function"
        sig = inspect.signature(names[where])
        assert params <= set(sig.parameters) | {"return"}, (where, params)


def test_the_walk_sees_what_it_should():
    # the rule bites: a bare array, an unresolvable string and a missing annotation are found
    assert _problem(np.ndarray) and _problem(dict[str, jax.Array]) and _problem(_UNRESOLVED)
    assert _problem(inspect.Parameter.empty)
    assert _problem(jaxtyping.Float[jaxtyping.Array, " n"] | None) is None
    where = {f"{f.__module__}.{f.__qualname__}" for f in _public_functions()}
    assert "hdjax._features.twist" in where and "hdjax.network._mlp.Network.__call__" in where


if __name__ == "__main__":  # python tests/test_public_annotations.py lists every finding
    for w, n, why in findings():
        print(f"{w}\t{n}\t{why}")
