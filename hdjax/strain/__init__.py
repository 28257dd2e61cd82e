"""Hashimoto, Kiyosawa & Paul (1993): the flexspline strain-gauge torque sensor and joint torque
control of a harmonic-drive joint.

- Sensor model, eqs. (1)-(14): [`hdjax.strain.FlexsplineGeometry`][],
  [`hdjax.strain.strain_per_torque`][] (eq. (7); eq. (A6) is its negative),
  [`hdjax.strain.resolved_torque_gain`][] (eq. (8)), [`hdjax.strain.gauge_strains`][],
  [`hdjax.strain.bridge_output`][] (eq. (5)), [`hdjax.strain.residual_ripple`][]
  (eqs. (10)-(12)), [`hdjax.strain.misalignment_error_index`][] (eq. (13)).
- The sensor on a simulated joint: [`hdjax.strain.StrainGaugeSensor`][] ($\beta$ from the
  wave-generator angle), against [`hdjax.strain.DeformationSensor`][] (stiffness times the
  quantised encoder twist) and [`hdjax.strain.IdealTorqueSensor`][].
- Torque control, eqs. (15)-(20): [`hdjax.strain.TorqueController`][],
  [`hdjax.strain.hashimoto_controller`][], [`hdjax.strain.control_law`][] (eq. (19)),
  [`hdjax.strain.steady_state_error`][] (eq. (20)), [`hdjax.strain.loop_poles`][],
  [`hdjax.strain.check_loop`][], [`hdjax.strain.simulate_torque_control`][] on
  [`hdjax.strain.PlantJoint`][] (`hdjax.plant`) or [`hdjax.strain.IdealJoint`][].
- The paper's experiments (Figs. 15-17) live in `hdjax.pipelines`, above this package:
  [`hdjax.pipelines.static_characteristic`][],
  [`hdjax.pipelines.step_response`][], [`hdjax.pipelines.sine_tracking`][]; the comparison
  [`hdjax.pipelines.compare_feedback`][]; everything at once:
  [`hdjax.pipelines.reproduce_figures`][].
"""

from ._bridge_sensor import (
    AbstractTorqueSensor as AbstractTorqueSensor,
    IdealTorqueSensor as IdealTorqueSensor,
    StrainGaugeSensor as StrainGaugeSensor,
)
from ._control import (
    KD_PAPER as KD_PAPER,
    KP_PAPER as KP_PAPER,
    RATED_TORQUE_PAPER as RATED_TORQUE_PAPER,
    SAMPLE_PERIOD_PAPER as SAMPLE_PERIOD_PAPER,
    TABLE_I as TABLE_I,
    TorqueController as TorqueController,
    control_law as control_law,
    hashimoto_controller as hashimoto_controller,
    steady_state_error as steady_state_error,
)
from ._deformation import DeformationSensor as DeformationSensor, quantise as quantise
from ._gauges import (
    EPS_RATED_PAPER as EPS_RATED_PAPER,
    PSI0_PAPER as PSI0_PAPER,
    FlexsplineGeometry as FlexsplineGeometry,
    GaugeStrains as GaugeStrains,
    Ripple as Ripple,
    bridge_output as bridge_output,
    gauge_strains as gauge_strains,
    misalignment_error_index as misalignment_error_index,
    residual_ripple as residual_ripple,
    resolved_torque_gain as resolved_torque_gain,
    strain_per_torque as strain_per_torque,
    strain_per_torque_appendix as strain_per_torque_appendix,
    torsional_strain as torsional_strain,
)
from ._joint_model import IdealJoint as IdealJoint
from ._plant_joint import PlantJoint as PlantJoint
from ._simulate import (
    ControlRun as ControlRun,
    TorqueReference as TorqueReference,
    simulate_torque_control as simulate_torque_control,
    sine_reference as sine_reference,
    step_reference as step_reference,
    triangle_reference as triangle_reference,
)
from ._stability import (
    LoopPoles as LoopPoles,
    SamplingWarning as SamplingWarning,
    check_loop as check_loop,
    loop_poles as loop_poles,
)

# The experiments and the figure reproduction moved to `hdjax.pipelines` (they put the sensor, the
# controller and the plant together, above this package); the old `hdjax.strain.X` names say
# where they went.
_MOVED_TO_PIPELINES = (
    "FRICTION_PAPER",
    "CaseResult",
    "Comparison",
    "SineResult",
    "StaticResult",
    "StepResponse",
    "compare_feedback",
    "open_loop_error_friction",
    "paper_joint",
    "reproduce_figures",
    "sine_tracking",
    "static_characteristic",
    "step_response",
)


def __getattr__(name: str):
    if name in _MOVED_TO_PIPELINES:
        raise AttributeError(f"hdjax.strain.{name} moved: use hdjax.pipelines.{name}")
    raise AttributeError(f"module 'hdjax.strain' has no attribute {name!r}")
