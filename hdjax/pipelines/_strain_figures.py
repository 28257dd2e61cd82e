r"""Figures and numbers of the Hashimoto et al. (1993) reproduction, written into one folder.

[`hdjax.pipelines.reproduce_figures`][] runs the sensor model (eqs. (8), (13)), the three
torque-control experiments (Figs. 15-17, eq. (20)) on the constrained and the free link, and the
strain-gauge / deformation comparison, writes one PNG per figure and `strain_metrics.json`,
`strain_comparison.md`, and returns the numbers. Matplotlib is imported here only, with the Agg
backend.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .._custom_types import PathLike
from .._errors import ConfigError
from .._io import atomic_write_bytes
from .._plotting import pyplot
from ..strain import (
    RATED_TORQUE_PAPER,
    FlexsplineGeometry,
    StrainGaugeSensor,
    hashimoto_controller,
    loop_poles,
    misalignment_error_index,
    resolved_torque_gain,
    steady_state_error,
)
from ._strain_compare import compare_feedback
from ._strain_experiments import (
    FRICTION_PAPER,
    SMOOTHING_STICK,
    TorqueLoop,
    open_loop_error_friction,
    paper_joint,
    sine_tracking,
    static_characteristic,
    step_response,
)

_pyplot = pyplot


def _save(fig, path: Path) -> str:
    fig.savefig(path, dpi=120, bbox_inches="tight")
    _pyplot().close(fig)
    return str(path)


def _pair_figure(title, open_run, closed_run, xlabel, x_of, y_label):
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    for ax, run, name in (
        (axes[0], open_run, "(a) open loop"),
        (axes[1], closed_run, "(b) closed loop"),
    ):
        x = x_of(run)
        ax.plot(x, np.asarray(run.reference), "k--", lw=1, label="desired $T_d$")
        ax.plot(x, np.asarray(run.torque), lw=1.2, label="joint torque $T_J$")
        ax.set_title(name)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(y_label)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(title)
    return fig


def _open_and_closed(experiment, joint, **kw):
    """One experiment of Figs. 15-17 on `joint`, open loop and closed loop."""
    return experiment(TorqueLoop(False, joint), **kw), experiment(TorqueLoop(True, joint), **kw)


def _open_and_closed_metrics(opened, closed, **fields: str) -> dict[str, float]:
    """`open_KEY` and `closed_KEY` for each `KEY=field` of an open- and closed-loop result."""
    return {
        f"{side}_{key}": getattr(result, field)
        for side, result in (("open", opened), ("closed", closed))
        for key, field in fields.items()
    }


def reproduce_figures(out_dir: PathLike, *, quick: bool = False) -> dict:
    """Write the reproduction figures and metrics into `out_dir`; return the metrics.

    **Arguments:**

    - `out_dir`: folder to write into (created if missing).
    - `quick`: shorter runs, fewer comparison cases (no hysteresis variant) and a 10x wider
      friction smooth-sign (1e-2 rad/s, 10x fewer Runge-Kutta substeps) for smoke tests; the
      numbers move by a few %.

    **Returns:** a dict of metrics (also written as `strain_metrics.json`), with the paths of
    the files written under `"files"`.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"out_dir {str(out)!r} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    plt = _pyplot()
    sm = 1e-2 if quick else SMOOTHING_STICK
    joint_c = paper_joint(smoothing=sm)
    files: dict[str, str] = {}
    metrics: dict = {}

    # -- sensor model: eqs. (8), (13) ------------------------------------------------------------
    geom = FlexsplineGeometry()
    k_r = float(resolved_torque_gain(geom))
    sensor = StrainGaugeSensor(geometry=geom)
    metrics["sensor"] = {
        "K_R_uV_per_Nm": 1e6 * k_r,
        "amplified_mV_per_Nm": 1e3 * float(sensor.sensitivity()),
        "E_R_at_2deg_pct": 100.0 * float(misalignment_error_index(math.radians(2.0))),
        "ripple_Nm_at_2deg": float(StrainGaugeSensor(dalpha=math.radians(2.0)).ripple_amplitude()),
    }
    da = np.linspace(-5, 5, 201)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    axes[0].plot(da, 100 * np.asarray(misalignment_error_index(np.radians(da))))
    axes[0].axhline(1.0, color="k", ls=":", lw=1)
    axes[0].axvspan(-2, 2, color="g", alpha=0.1)
    axes[0].set_xlabel("gauge misalignment Δα [deg]")
    axes[0].set_ylabel("$E_R$ [% of rated], eq. (13)")
    axes[0].set_title("sensing inaccuracy from Δα")
    q_m = np.linspace(0, 2 * np.pi, 721)
    for d in (0.0, 2.0, 5.0):
        s = StrainGaugeSensor(dalpha=math.radians(d))
        axes[1].plot(np.degrees(q_m), np.asarray(s.read(10.0, q_m, 0.0)), label=f"Δα={d:g}°")
    axes[1].set_xlabel("wave-generator angle β [deg]")
    axes[1].set_ylabel("reading at 10 N·m [N·m]")
    axes[1].set_title("bridge reading over one motor turn")
    axes[1].legend(fontsize=8)
    files["sensor"] = _save(fig, out / "strain_sensor_misalignment.png")

    # -- poles and eq. (20) ------------------------------------------------------------------------
    metrics["loop"] = {}
    for label, constrained in (("constrained", True), ("free", False)):
        ctl = hashimoto_controller(constrained=constrained)
        poles = loop_poles(ctl)
        metrics["loop"][label] = {
            "discrete_poles": [[float(z.real), float(z.imag)] for z in poles.discrete],
            "spectral_radius": poles.spectral_radius,
            "plant_mode_rad_s": poles.plant_mode,
            "eq20_E_T_closed_Nm": steady_state_error(ctl, FRICTION_PAPER),
            "eq20_E_T_open_Nm": steady_state_error(
                hashimoto_controller(feedback=False, constrained=constrained), FRICTION_PAPER
            ),
        }

    # -- Fig. 15: static characteristic ------------------------------------------------------------
    static_kw = dict(amplitude=20.0, period=2.0, cycles=1.25)
    if quick:
        static_kw.update(amplitude=10.0, period=0.5)
    s_open, s_closed = _open_and_closed(static_characteristic, joint_c, **static_kw)
    metrics["fig15"] = {
        **_open_and_closed_metrics(
            s_open, s_closed, half_width_Nm="half_width", half_width_pct_rated="half_width_pct"
        ),
        "eq20_closed_Nm": metrics["loop"]["constrained"]["eq20_E_T_closed_Nm"],
    }
    fig = _pair_figure(
        "Fig. 15: static characteristic (constrained link)",
        s_open.run,
        s_closed.run,
        "desired torque $T_d$ [N·m]",
        lambda r: np.asarray(r.reference),
        "torque [N·m]",
    )
    files["fig15"] = _save(fig, out / "strain_fig15_static.png")

    # -- Fig. 16: step response --------------------------------------------------------------------
    f70 = open_loop_error_friction(0.70, 5.0)
    st_open, st_closed = _open_and_closed(step_response, joint_c)
    st_open70 = step_response(TorqueLoop(False, paper_joint(friction=f70, smoothing=sm)))
    metrics["fig16"] = {
        "step_Nm": 5.0,
        "open_error_pct": st_open.steady_state_error_pct,
        "closed_error_pct": st_closed.steady_state_error_pct,
        "closed_rise_time_ms": 1e3 * st_closed.rise_time,
        "closed_overshoot_pct": st_closed.overshoot_pct,
        "friction_for_70pct_Nm_motor": f70,
        "open_error_pct_at_that_friction": st_open70.steady_state_error_pct,
    }
    t_ms = lambda r: 1e3 * np.asarray(r.t)
    fig = _pair_figure(
        "Fig. 16: 5 N·m step (constrained link)",
        st_open.run,
        st_closed.run,
        "time [ms]",
        t_ms,
        "torque [N·m]",
    )
    files["fig16"] = _save(fig, out / "strain_fig16_step.png")

    # -- Fig. 17: 5 N·m, 20 Hz sine ----------------------------------------------------------------
    # quick: every run 0.2 s long, so that runs of one sensor type share one compiled loop
    sine_kw = dict(duration=0.2 if quick else 0.3)
    sn_open, sn_closed = _open_and_closed(sine_tracking, joint_c, **sine_kw)
    metrics["fig17"] = {
        **_open_and_closed_metrics(sn_open, sn_closed, rms_error_Nm="rms_error", gain="gain"),
        "closed_phase_deg": sn_closed.phase_deg,
    }
    fig = _pair_figure(
        "Fig. 17: 5 N·m, 20 Hz (constrained link)",
        sn_open.run,
        sn_closed.run,
        "time [ms]",
        t_ms,
        "torque [N·m]",
    )
    files["fig17"] = _save(fig, out / "strain_fig17_sine.png")

    # -- free link: step and sine ----------------------------------------------------------------
    free = paper_joint(constrained=False, smoothing=sm)
    fs = step_response(TorqueLoop(True, free))
    fsn = sine_tracking(TorqueLoop(True, free), **sine_kw)
    metrics["free_link"] = {
        "closed_step_error_pct": fs.steady_state_error_pct,
        "closed_step_rise_time_ms": 1e3 * fs.rise_time,
        "closed_sine_rms_error_Nm": fsn.rms_error,
        "eq20_closed_Nm": metrics["loop"]["free"]["eq20_E_T_closed_Nm"],
    }

    # -- comparison: strain gauges vs deformation --------------------------------------------------
    dalphas = (0.0, 2.0) if quick else (0.0, 0.5, 1.0, 2.0, 5.0)
    duration = 0.2 if quick else 0.3
    comp = compare_feedback(dalpha_deg=dalphas, duration=duration, smoothing=sm)
    metrics["comparison"] = comp.as_dict()
    table = (
        "Linear joint (Table I), free link turning at 1 rad/s, 5 N·m 20 Hz reference:\n\n"
        + comp.table()
        + "\n"
    )
    if not quick:
        comp_h = compare_feedback(
            dalpha_deg=(0.0, 2.0), hysteresis=True, duration=duration, smoothing=sm
        )
        metrics["comparison_with_hysteresis"] = comp_h.as_dict()
        table += (
            "\nSame with the plant's Bouc-Wen hysteresis torque in the flexspline:\n\n"
            + comp_h.table()
            + "\n"
        )
    atomic_write_bytes(out / "strain_comparison.md", table.encode())
    files["comparison_table"] = str(out / "strain_comparison.md")
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    by_name = {c.name: c for c in comp.cases}
    strain_cases = [c for c in comp.cases if c.name.startswith("strain")]
    deform = next(c for c in comp.cases if c.name.startswith("deformation"))
    ideal = by_name["ideal (true torque)"]
    t = 1e3 * np.asarray(ideal.run.t)
    axes[0].plot(t, np.asarray(ideal.run.reference), "k--", lw=1, label="desired")
    show = [c for c in strain_cases if c.name.endswith("=2 deg")] + [deform]
    for c in show:
        axes[0].plot(t, np.asarray(c.run.torque), lw=1, label=c.name)
    axes[0].set_xlabel("time [ms]")
    axes[0].set_ylabel("true joint torque [N·m]")
    axes[0].set_title("free link at 1 rad/s, 5 N·m 20 Hz")
    axes[0].legend(fontsize=7)
    axes[1].plot(
        comp.dalpha_deg, [c.rms_tracking for c in strain_cases], "o-", label="strain: RMS tracking"
    )
    axes[1].plot(comp.dalpha_deg, [c.ripple for c in strain_cases], "s-", label="strain: 2β ripple")
    axes[1].axhline(deform.rms_tracking, color="C0", ls=":", label="deformation: RMS tracking")
    axes[1].axhline(deform.ripple, color="C1", ls=":", label="deformation: 2β ripple")
    axes[1].set_xlabel("gauge misalignment Δα [deg]")
    axes[1].set_ylabel("[N·m]")
    axes[1].set_title("robustness to Δα")
    axes[1].legend(fontsize=7)
    files["comparison"] = _save(fig, out / "strain_comparison.png")

    metrics["rated_torque_Nm"] = RATED_TORQUE_PAPER
    metrics["files"] = files
    atomic_write_bytes(out / "strain_metrics.json", json.dumps(metrics, indent=2).encode())
    files["metrics"] = str(out / "strain_metrics.json")
    return metrics
