"""The catalogue of physical effects: one module per family, each seen by the plant, the
compliance model and the residual loop.

A family ([`hdjax.effects.AbstractFamily`][]) bundles its regression terms
([`hdjax.effects.AbstractTerm`][]), its plant effects ([`hdjax.effects.PlantEffect`][]), its
vocabulary and its candidate generator. Adding one is a new module and one
[`hdjax.effects.register`][] line below (or in user code).
"""

from ._backlash import (
    Backlash as Backlash,
    BacklashFamily as BacklashFamily,
    LostMotion as LostMotion,
)
from ._base import (
    PLANT_SLOTS as PLANT_SLOTS,
    SEGMENT_START as SEGMENT_START,
    TORQUE_KINDS as TORQUE_KINDS,
    TORQUE_PATH as TORQUE_PATH,
    AbstractColumnListTerm as AbstractColumnListTerm,
    AbstractFamily as AbstractFamily,
    AbstractFriction as AbstractFriction,
    AbstractHysteresis as AbstractHysteresis,
    AbstractLinearTorqueTerm as AbstractLinearTorqueTerm,
    AbstractMemorylessTerm as AbstractMemorylessTerm,
    AbstractPathTerm as AbstractPathTerm,
    AbstractPlantEffect as AbstractPlantEffect,
    AbstractSignalTerm as AbstractSignalTerm,
    AbstractTerm as AbstractTerm,
    AbstractTorqueFreeTerm as AbstractTorqueFreeTerm,
    AbstractTorqueScaleFamily as AbstractTorqueScaleFamily,
    Candidate as Candidate,
    CandidateContext as CandidateContext,
    PlantEffect as PlantEffect,
)
from ._c import AbstractCEmitter as AbstractCEmitter, CSnippet as CSnippet
from ._coulomb import (
    Coulomb as Coulomb,
    CoulombFamily as CoulombFamily,
    CoulombFriction as CoulombFriction,
)
from ._damping import DampingFamily as DampingFamily, TwistRate as TwistRate
from ._fields import (
    bound as bound,
    f64 as f64,
    fmt as fmt,
    hyper as hyper,
    labels as labels,
    require as require,
)
from ._hysteresis import (
    BoucWen as BoucWen,
    Dahl as Dahl,
    Hysteresis as Hysteresis,
    HysteresisFamily as HysteresisFamily,
    LuGre as LuGre,
    TwistHysteresis as TwistHysteresis,
    dahl_initial as dahl_initial,
    dahl_state as dahl_state,
    dahl_state_numpy as dahl_state_numpy,
    driver_noise as driver_noise,
    noise_deviations as noise_deviations,
    one_way_from_rest as one_way_from_rest,
    play as play,
    starts_at_rest as starts_at_rest,
    twist_compliance as twist_compliance,
    twist_play as twist_play,
)
from ._kinematic import (
    Harmonics as Harmonics,
    KinematicFamily as KinematicFamily,
    KinematicHarmonics as KinematicHarmonics,
    PaperFourier as PaperFourier,
    harmonic_key as harmonic_key,
    harmonic_pairs as harmonic_pairs,
)
from ._offset import Constant as Constant, OffsetFamily as OffsetFamily
from ._registry import (
    discover_families as discover_families,
    families as families,
    in_slot as in_slot,
    library_options as library_options,
    neighbours as neighbours,
    plant_effect as plant_effect,
    plant_effect_names as plant_effect_names,
    plant_effects as plant_effects,
    register as register,
    setting_text as setting_text,
    term_type as term_type,
    term_types as term_types,
    unregister as unregister,
    vocabulary as vocabulary,
)
from ._ripple import (
    ComplianceRipple as ComplianceRipple,
    Ripple as Ripple,
    RippleFamily as RippleFamily,
    ripple_key as ripple_key,
    torque_ratio as torque_ratio,
)
from ._skew import (
    EncoderSkew as EncoderSkew,
    SkewFamily as SkewFamily,
    current_viscous_slope as current_viscous_slope,
    velocity_reading as velocity_reading,
)
from ._stiffening import (
    CubicSpring as CubicSpring,
    Stiffening as Stiffening,
    StiffeningFamily as StiffeningFamily,
)
from ._stribeck import (
    Stribeck as Stribeck,
    StribeckFamily as StribeckFamily,
    StribeckFriction as StribeckFriction,
)
from ._thermal import (
    Column as Column,
    ColumnTimesTorque as ColumnTimesTorque,
    Temperature as Temperature,
    ThermalFamily as ThermalFamily,
)
from ._viscous import (
    Viscous as Viscous,
    ViscousFamily as ViscousFamily,
    ViscousFriction as ViscousFriction,
)
from ._wave_generator import (
    WG_COMPLIANCE as WG_COMPLIANCE,
    CurrentPolynomial as CurrentPolynomial,
    WaveGenerator as WaveGenerator,
    WaveGeneratorFamily as WaveGeneratorFamily,
)

# The built-in catalogue. The order is the plant's order of application and the order of the
# vocabulary, the library options and the candidates; one line per family.
register(KinematicFamily())
register(CoulombFamily())
register(ViscousFamily())
register(SkewFamily())
register(StribeckFamily())
register(HysteresisFamily())
register(BacklashFamily())
register(StiffeningFamily())
register(RippleFamily())
register(DampingFamily())
register(ThermalFamily())
register(WaveGeneratorFamily())
register(OffsetFamily())
