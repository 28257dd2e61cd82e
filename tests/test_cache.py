"""Warm starts: the CLI keeps JAX's compiled programs in $XDG_CACHE_HOME/hdjax, so a second run
of the same shapes compiles nothing of note; --no-cache turns the cache off."""

import json
import os
import subprocess
import sys

import jax

from hdjax._cache import cache_dir
from hdjax.cli import _compilation_cache
from tests.conftest import REPO, use_session_cache

# Runs one CLI command in a fresh process and prints the durations of JAX's backend-compile
# events (a compilation, or on a cache hit the load of the compiled program), how many programs
# came from the persistent cache and how many were compiled afresh and written to it (misses).
# The cache keeps every program (MIN_COMPILE_SECONDS = 0), so a miss is a fresh compilation.
PROBE = """
import json, sys
import jax.monitoring as mon
compiles, hits, misses = [], [], []
COMPILE = "/jax/core/compile/backend_compile_duration"
mon.register_event_duration_secs_listener(
    lambda e, d, **k: compiles.append(d) if e == COMPILE else 0)
mon.register_event_listener(
    lambda e, **k: hits.append(1) if e == "/jax/compilation_cache/cache_hits" else 0)
mon.register_event_listener(
    lambda e, **k: misses.append(1) if e == "/jax/compilation_cache/cache_misses" else 0)
from hdjax.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "compiles": compiles, "hits": len(hits), "misses": len(misses)}))
"""


def probe(args, env):
    out = subprocess.run(
        [sys.executable, "-c", PROBE, *args], cwd=REPO, env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_second_run_compiles_nothing_of_note(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "HDJAX_NO_CACHE"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    cfg = REPO / "experiments" / "synthetic.toml"
    args = lambda i: ["run", str(cfg), "--out", str(tmp_path / f"r{i}"), "--no-figures",
                      "--no-network", "--set", "data.n_samples=2000", "--set",
                      "outputs.timing=false", "-q"]  # fmt: skip
    first = probe(args(1), env)
    assert first["code"] == 0 and max(first["compiles"]) > 0.1  # something worth caching
    stored = list((tmp_path / "xdg" / "hdjax" / "jax").iterdir())
    assert stored, "the first run left nothing in the cache directory"
    second = probe(args(2), env)
    assert first["misses"] > 0
    assert second["code"] == 0 and second["hits"] > 0
    # Nothing is compiled afresh: every program is loaded from the cache. (The durations of
    # those loads are wall time on a shared machine, so they are measured in
    # benchmarks/bench_warm_start.py, not asserted here.)
    assert second["misses"] == 0, second
    # --no-cache: nothing is read or written
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg-off")
    off = probe([*args(3), "--no-cache"], env)
    assert off["code"] == 0 and off["hits"] == 0
    assert not (tmp_path / "xdg-off" / "hdjax").exists()


def test_cache_dir_and_flag(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache_dir() == tmp_path / "hdjax" / "jax"
    monkeypatch.setenv("XDG_CACHE_HOME", "")
    assert cache_dir() == __import__("pathlib").Path.home() / ".cache" / "hdjax" / "jax"
    monkeypatch.delenv("HDJAX_NO_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    try:
        assert _compilation_cache(["run", "x.toml", "--no-cache"]) == ["run", "x.toml"]
        assert jax.config.jax_compilation_cache_dir is None
        assert _compilation_cache(["run", "x.toml"]) == ["run", "x.toml"]
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "hdjax" / "jax")
        monkeypatch.setenv("HDJAX_NO_CACHE", "1")
        _compilation_cache([])  # HDJAX_NO_CACHE=1: off
        assert jax.config.jax_compilation_cache_dir is None
    finally:
        use_session_cache()  # back to the test session's shared cache
