"""Pictures of a scenario: torque, twist and current against time, and the twist-torque loop.

matplotlib is imported lazily, with the Agg backend, inside the plotting function, so that
`import hdjax.plant` stays light and works without a display.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._custom_types import PathLike
from .._errors import ConfigError, DataError
from .._plotting import pyplot
from .._recording import Recording


def plot_scenario(
    recording: Recording, path: PathLike, *, ratio: float = 160.0, title: str | None = None
) -> Path:
    r"""Save a four-panel figure of a recording (Song et al. Figs. 2 and 9-12 in one).

    Panels: sensor torque, twist $\theta_l - \theta_m/N$ (Song eq. (5)) and current against time,
    and twist against torque, where the hysteresis shows as a loop (as the paper's Fig. 2).

    **Arguments:**

    - `recording`: a recording with a `torque` column.
    - `path`: output file (`.png`, `.pdf`, `.svg`); its folder must exist.
    - `ratio`: reduction ratio $N$ for the twist (160 for the Song preset, 100 for Hashimoto's).
    - `title`: figure title (default: the recording's source).

    **Returns:** the path written.
    """
    path = Path(path)
    if not path.parent.exists():
        raise ConfigError(f"cannot write {path}: folder {path.parent} does not exist")
    if recording.torque is None:
        raise DataError(f"recording {recording.source!r} has no torque column to plot")
    plt = pyplot()

    cols = recording.to_numpy()
    t = cols["t"]
    twist_arcmin = (cols["theta_l"] - cols["theta_m"] / ratio) * (180.0 * 60.0 / np.pi)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    ax_tq, ax_tw, ax_i, ax_loop = axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1]
    ax_tq.plot(t, cols["torque"], lw=0.6)
    ax_tq.set(xlabel="t [s]", ylabel="sensor torque [N·m]", title="torque")
    ax_tw.plot(t, twist_arcmin, lw=0.6, color="tab:orange")
    ax_tw.set(xlabel="t [s]", ylabel="twist [arcmin]", title=r"twist $\theta_l - \theta_m/N$")
    ax_i.plot(t, cols["current"], lw=0.4, color="tab:green")
    ax_i.set(xlabel="t [s]", ylabel="current [A]", title="motor current")
    ax_loop.plot(cols["torque"], twist_arcmin, lw=0.4, color="tab:red")
    ax_loop.set(xlabel="sensor torque [N·m]", ylabel="twist [arcmin]", title="twist-torque loop")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    fig.suptitle(title or recording.source)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
