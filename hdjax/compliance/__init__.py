"""The Song et al. (2019) compliance model: structure, calibration and torque inversion."""

from ..effects import (
    Backlash as Backlash,
    Column as Column,
    ColumnTimesTorque as ColumnTimesTorque,
    Constant as Constant,
    Coulomb as Coulomb,
    CurrentPolynomial as CurrentPolynomial,
    Harmonics as Harmonics,
    Hysteresis as Hysteresis,
    PaperFourier as PaperFourier,
    Stiffening as Stiffening,
    TwistRate as TwistRate,
    Viscous as Viscous,
    dahl_state as dahl_state,
)
from ._inversion import (
    SingleEstimate as SingleEstimate,
    TorqueEstimate as TorqueEstimate,
    estimate_torque as estimate_torque,
    estimate_torque_arrays as estimate_torque_arrays,
    estimate_torque_single as estimate_torque_single,
    torque_estimator as torque_estimator,
)
from ._lstsq import (
    calibrate_lstsq as calibrate_lstsq,
    calibration_messages as calibration_messages,
    check_invertible as check_invertible,
)
from ._model import ComplianceModel as ComplianceModel, paper_knots as paper_knots
from ._rls import (
    RLSState as RLSState,
    calibrate_rls as calibrate_rls,
    rls_init as rls_init,
    rls_scan as rls_scan,
    rls_solve as rls_solve,
    rls_step as rls_step,
)
from ._segments import merge_sparse_segments as merge_sparse_segments
from ._shape import (
    SLOPE_FLOOR as SLOPE_FLOOR,
    ShapeConstraint as ShapeConstraint,
    ShapeData as ShapeData,
)
from ._signals import Signals as Signals, signals_from_recording as signals_from_recording
from ._stream import NormalEquations as NormalEquations, StreamingQR as StreamingQR
from ._stream_fit import (
    RecordingStream as RecordingStream,
    calibrate_stream as calibrate_stream,
)
from ._terms import term_from_dict as term_from_dict, term_to_dict as term_to_dict
