"""Many plant draws in one compiled run, for the statistical tests of the residual loop.

`simulate_draws` stacks parameter sets of one structure (the same effects switched on, other
values) and runs them, each with its own scenario drive and sensor noise, as one `vmap`-ed
integration (one compilation, one loop), so tens of joints cost about as much as a few.
"""

import jax
import jax.numpy as jnp
import numpy as np

from hdjax import plant
from hdjax.plant._controller import default_gains
from hdjax.plant._simulate import _initial, integrate, spread_batch, to_recording

DT = 5e-4


@jax.jit
def _run(params_b, gains, drives_b, stride):
    def one(p, d):
        s0 = _initial(p, d, gains)
        return integrate(p, gains, s0, d, DT, stride=stride)[1]

    return jax.vmap(one)(params_b, drives_b)


_run = jax.jit(_run.__wrapped__, static_argnums=(3,))


def swing_drive(params, *, amplitude: float, period: float, duration: float, dt: float = DT):
    """A `slow`-like drive with its own swing ([`hdjax.plant.swing_drive`][]), the arm moved over
    1 s at the start of each period."""
    return plant.swing_drive(
        params, amplitude=amplitude, period=period, duration=duration, dt=dt, rope_time=1.0
    )


def simulate_draws(params_list, scenarios, seeds, *, duration, output_period, skip=0.5, swing=None):
    """One recording per (params, scenario, seed) triple, simulated as one batch.

    All parameter sets must share their structure (effects on, static fields). The controller
    gains are the first set's (a bench keeps its tuning across joints of one type). `swing`
    (optional `(amplitude, period)`, or a list of them, one per draw) replaces the named
    scenarios by [`swing_drive`][].
    """
    stride = int(round(output_period / DT))
    n_steps = int(round(duration / DT))
    n_out = n_steps // stride
    drives = []
    if swing is not None and not isinstance(swing[0], (tuple, list)):
        swing = [swing] * len(params_list)
    for j, (p, name, seed) in enumerate(zip(params_list, scenarios, seeds)):
        key = jax.random.PRNGKey(seed)
        if swing is None:
            d = plant.scenario_drive(
                name, p, duration=duration, dt=DT, key=jax.random.fold_in(key, 0)
            )
        else:
            d = swing_drive(p, amplitude=swing[j][0], period=swing[j][1], duration=duration)
        drives.append(jax.tree.map(lambda x: x[: n_out * stride], d))
    stack = lambda xs: jax.tree.map(lambda *a: jnp.stack(a), *xs)
    gains = default_gains(params_list[0])
    outs = _run(stack(params_list), gains, spread_batch(stack(drives)), stride)
    t = np.arange(n_out) * output_period
    recs = []
    for j, (p, seed) in enumerate(zip(params_list, seeds)):
        out = jax.tree.map(lambda x: x[j], outs)
        rec = to_recording(
            p,
            out,
            t,
            sensors=plant.SensorConfig(),
            key=jax.random.fold_in(jax.random.PRNGKey(seed), 1),
            source=f"draw:{j}",
        )
        recs.append(rec.select(np.asarray(rec.t) >= skip))
    return recs
