"""Warm starts of `hdjax discover`: a second run of the same shapes compiles nothing afresh that
the cache keeps (every program it looks up is loaded from the compilation cache the first run
filled in $XDG_CACHE_HOME/hdjax). How long the loads take is wall time on a shared machine:
benchmarks/bench_warm_start.py measures it, no test asserts it."""

import json
import os

import hdjax

from .discover_data import ARCSEC, synthetic_recording
from .helpers import run_probe

# Runs one CLI command in a fresh process and prints, for each backend compilation JAX did,
# its duration and whether the persistent cache answered it. JAX records the duration of every
# backend compile (around the cache lookup: on a hit it is the load); a lookup records
# `compile_requests_use_cache`, and a hit `cache_hits`, before the duration of its own compile.
# A compile with no hit since the previous one was compiled afresh (a miss, or a program the
# cache does not take).
PROBE = """
import json, sys
import jax.monitoring as mon
events, compiles = [], []
COMPILE = "/jax/core/compile/backend_compile_duration"
def on_duration(e, d, **k):
    if e == COMPILE:
        compiles.append({"s": d, "hit": "hit" in events, "cached": "lookup" in events})
        events.clear()
def on_event(e, **k):
    if e == "/jax/compilation_cache/cache_hits":
        events.append("hit")
    elif e == "/jax/compilation_cache/compile_requests_use_cache":
        events.append("lookup")
mon.register_event_duration_secs_listener(on_duration)
mon.register_event_listener(on_event)
from hdjax.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "compiles": compiles}))
"""


def test_second_discover_compiles_nothing_of_note(tmp_path):
    effect = [("harmonic_m", 2.0, 30 * ARCSEC)]
    hdjax.save_csv(synthetic_recording(1, effect, n=4000), tmp_path / "train.csv")
    hdjax.save_csv(synthetic_recording(2, effect, n=2000), tmp_path / "test.csv")
    (tmp_path / "joint.toml").write_text("[joint]\nratio = 160\nrated_torque = 400\n")
    env = {k: v for k, v in os.environ.items() if k != "HDJAX_NO_CACHE"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    args = lambda i: ["discover", "--train", str(tmp_path / "train.csv"), "--test",
                      str(tmp_path / "test.csv"), "--joint", str(tmp_path / "joint.toml"),
                      "--out", str(tmp_path / f"out{i}"), "--quiet"]  # fmt: skip
    first = run_probe(PROBE, args(1), env)
    assert first["code"] == 0
    assert any(c["cached"] and not c["hit"] for c in first["compiles"]), "nothing to cache"
    assert list((tmp_path / "xdg" / "hdjax" / "jax").iterdir()), "nothing in the cache"
    second = run_probe(PROBE, args(2), env)
    assert second["code"] == 0
    report = [json.loads((tmp_path / f"out{i}" / "report.json").read_text()) for i in (1, 2)]
    assert report[1]["effects"] == report[0]["effects"] == ["harmonic:theta_m:2"]  # same work
    hits = [c for c in second["compiles"] if c["hit"]]
    assert hits, "the second run loaded nothing from the cache"
    missed = [c for c in second["compiles"] if c["cached"] and not c["hit"]]
    # every program the cache keeps is loaded from it: none is compiled again
    assert not missed, (
        f"{len(missed)} programs looked up in the cache were compiled again on the second run; "
        f"{len(hits)} loaded from the cache"
    )
