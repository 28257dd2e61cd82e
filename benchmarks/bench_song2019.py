"""The paper's job, timed as a user runs it: `hdjax run experiments/song2019.toml` in a fresh
process (JAX compilation included, with an empty compilation cache), and its errors next to the
paper's. Prints one JSON document.

    python benchmarks/bench_song2019.py [--duration S]

`--duration` shortens every simulated experiment (the paper's runs, and the default, are 60 s).
Target: the whole job in under 3 minutes on 2 CPU cores.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TARGET_S = 180.0


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=None, help="seconds per experiment")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "song2019"
        command = [sys.executable, "-m", "hdjax", "run", "experiments/song2019.toml"]
        command += ["--out", str(out), "--quiet"]
        if args.duration is not None:
            command += ["--set", f"data.duration={args.duration}"]
        env = dict(os.environ, XDG_CACHE_HOME=str(Path(tmp) / "cache"))
        start = time.perf_counter()
        subprocess.run(command, cwd=REPO, env=env, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        metrics = json.loads((out / "metrics.json").read_text())
        rated = tomllib.loads((out / "config.resolved.toml").read_text())["joint"]["rated_torque"]
    paper = metrics["paper"]["errors_max_rms_Nm"]
    rows = []
    for name, model in metrics["model"]["scenarios"].items():
        row = {"experiment": name, "model max": model["max"], "model RMS": model["rms"]}
        row["model max at s"] = model.get("max_at_s")
        network = metrics.get("network", {}).get("scenarios", {}).get(name)
        if network:
            row.update({"network max": network["max"], "network RMS": network["rms"]})
            row["network max at s"] = network.get("max_at_s")
        if name in paper["model"]:
            row["paper model max"], row["paper model RMS"] = paper["model"][name]
        if name in paper.get("network", {}):
            row["paper network max"], row["paper network RMS"] = paper["network"][name]
        rows.append(row)
    return {
        "benchmark": "hdjax run experiments/song2019.toml, fresh process, empty compile cache",
        "machine": platform.processor() or platform.machine(),
        "precision": "float64",
        "duration_per_experiment_s": args.duration or 60.0,
        "process_wall_s": wall,
        "run_wall_s": metrics.get("wall_s"),
        "rated_torque_Nm": float(rated),
        "target": f"process_wall_s < {TARGET_S:.0f}",
        "target_met": wall < TARGET_S,
        "errors_Nm": rows,
    }


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
