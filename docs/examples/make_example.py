"""Write the worked example of the Getting-started page: two logs of a simulated joint in a
layout of its own (raw encoder counts, other column names), as a user's bench would write them.

    python docs/examples/make_example.py

The joint is the built-in plant (ratio 160, rated torque 400 N·m) with one effect the paper's
model lacks: a kinematic error of order 2 in the motor angle (0.3 arcmin). Both logs are 30 s
sampled every 4 ms, of the same joint under weights on its link, but two recordings of two
motions and load paths (each with its own sensor noise seed):

- TRAIN: the `slow` experiment, a swing of +-1.4 rad (80 deg) with a period of 20 s, the arm
  holding the weights lengthened from 0.5 to 0.75 of its longest at 20 s;
- TEST: a smaller, quicker swing, +-1.1 rad with a period of 16 s, the arm lengthened at 16 s,
  so the angles, speeds and the torque's path differ from TRAIN's at every sample, while the
  torque stays inside the range TRAIN calibrates.
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


DT = 5e-4  # integration step [s]
DURATION = 30.5  # [s], of which the first 0.5 s (the start from rest) is left out
SWINGS = {"train": (1.4, 20.0), "test": (1.1, 16.0)}  # amplitude [rad], period [s]


def write_log(path: Path, seed: int, swing: tuple[float, float]) -> None:
    """Simulate the joint over one swing `(amplitude, period)` and write its log to `path`."""
    params = plant.song_params(defaults=False, effects=EFFECTS)
    amplitude, period = swing
    drive = plant.swing_drive(params, amplitude=amplitude, period=period, duration=DURATION, dt=DT)
    # the sensor-noise key as `simulate_scenario` derives it, so TRAIN is the `slow` scenario's
    # recording with this seed
    key = jax.random.fold_in(jax.random.PRNGKey(seed), 1)
    rec = plant.simulate(params, drive, key=key, dt=DT, output_period=4e-3)
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
    write_log(HERE / "bench_train.csv", seed=11, swing=SWINGS["train"])
    write_log(HERE / "bench_test.csv", seed=12, swing=SWINGS["test"])
