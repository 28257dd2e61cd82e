"""A differentiable two-inertia harmonic-drive joint with hysteresis, friction and the paper's
four load experiments (Song et al. 2019, Section IV; Hashimoto et al. 1993, eqs. (15)-(17))."""

from ._controller import ControllerGains as ControllerGains, default_gains as default_gains
from ._dynamics import (
    PlantState as PlantState,
    compliance_deflection as compliance_deflection,
    derivatives as derivatives,
    effective_deflection as effective_deflection,
    equilibrium_state as equilibrium_state,
    flexspline_deflection as flexspline_deflection,
    flexspline_inverse as flexspline_inverse,
    flexspline_torque as flexspline_torque,
    kinematic_error as kinematic_error,
    motor_friction as motor_friction,
    output_friction as output_friction,
    reciprocals as reciprocals,
    rk4_step as rk4_step,
    sensor_torque as sensor_torque,
    zero_state as zero_state,
)
from ._effects import EFFECT_NAMES as EFFECT_NAMES, make_effect as make_effect
from ._figures import plot_scenario as plot_scenario
from ._identify import (
    fit_plant as fit_plant,
    simulate_signals as simulate_signals,
)
from ._params import (
    SONG_COMPLIANCE as SONG_COMPLIANCE,
    SONG_DEFAULT_EFFECTS as SONG_DEFAULT_EFFECTS,
    PlantParams as PlantParams,
    hashimoto_params as hashimoto_params,
    make_params as make_params,
    song_params as song_params,
    with_effects as with_effects,
)
from ._real_log import (
    RealLogSensors as RealLogSensors,
    real_log as real_log,
    simulate_real_log as simulate_real_log,
    sweep_drive as sweep_drive,
)
from ._scenarios import (
    SCENARIOS as SCENARIOS,
    scenario_drive as scenario_drive,
    simulate_scenario as simulate_scenario,
    simulate_scenarios as simulate_scenarios,
    swing_drive as swing_drive,
)
from ._sensors import SensorConfig as SensorConfig
from ._simulate import (
    Drive as Drive,
    Outputs as Outputs,
    check_step as check_step,
    estimate_memory as estimate_memory,
    integrate as integrate,
    simulate as simulate,
    spread_batch as spread_batch,
    stiffest_modes as stiffest_modes,
    to_recording as to_recording,
)
