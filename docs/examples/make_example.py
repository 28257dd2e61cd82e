"""Write the worked example of the Getting-started page: two logs of a simulated joint in a
layout of its own (raw encoder counts, other column names), as a user's bench would write them.

    python docs/examples/make_example.py

The joint is the built-in plant (ratio 160, rated torque 400 N·m) with one effect the paper's
model lacks: a kinematic error of order 2 in the motor angle (0.3 arcmin). `slow` experiment,
30 s sampled every 4 ms; TRAIN and TEST come from different seeds.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import numpy as np

from hdjax import plant

HERE = Path(__file__).resolve().parent
COUNTS = 2**21  # counts per revolution of both encoders
ARCMIN = math.pi / (180 * 60)
EFFECTS = {
    "wg_compliance": True,
    "harmonic_m": dict(orders=[2.0], amplitudes=[0.3 * ARCMIN], phases=[0.3]),
}


def write_log(path: Path, seed: int) -> None:
    params = plant.song_params(defaults=False, effects=EFFECTS)
    rec = plant.simulate_scenario(
        "slow", key=jax.random.PRNGKey(seed), duration=30.5, params=params, output_period=4e-3
    )
    keep = np.asarray(rec.t) >= 0.5  # leave out the start from rest
    t = np.asarray(rec.t)[keep] - 0.5
    motor = np.round(np.asarray(rec.theta_m)[keep] / (2 * math.pi) * COUNTS).astype(np.int64)
    output = np.round(np.asarray(rec.theta_l)[keep] / (2 * math.pi) * COUNTS).astype(np.int64)
    current = np.asarray(rec.current)[keep]
    torque = np.asarray(rec.torque)[keep]
    with open(path, "w") as f:
        f.write("time_s,motor_counts,output_counts,iq_A,torque_sensor_Nm\n")
        for row in zip(t, motor, output, current, torque, strict=True):
            f.write(f"{row[0]:.3f},{row[1]},{row[2]},{row[3]:.4f},{row[4]:.3f}\n")


if __name__ == "__main__":
    write_log(HERE / "bench_train.csv", seed=11)
    write_log(HERE / "bench_test.csv", seed=12)
