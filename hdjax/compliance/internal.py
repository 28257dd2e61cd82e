"""What `hdjax.compliance` lends to the other hdjax packages: the design rows, the inversion's
parts and the streamed calibration.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._inversion import (
    EDGE_TOLERANCE as EDGE_TOLERANCE,
    MIN_PATH_SLOPE as MIN_PATH_SLOPE,
    NEWTON_STEPS as NEWTON_STEPS,
    calibrated_segments as calibrated_segments,
    check_estimable as check_estimable,
    effect_groups as effect_groups,
    invert_twist as invert_twist,
)
from ._lstsq import (
    CSNE_MAX_COND as CSNE_MAX_COND,
    CalibrationData as CalibrationData,
    compact_column_list as compact_column_list,
    design_columns as design_columns,
    failure_message as failure_message,
    join_model_hypers as join_model_hypers,
    prepare as prepare,
    select_active as select_active,
    split_model_hypers as split_model_hypers,
    term_columns as term_columns,
    term_signals as term_signals,
)
from ._model import (
    base_term_columns as base_term_columns,
    is_segment_name as is_segment_name,
)
from ._nested import (
    batched_estimates as batched_estimates,
    estimable as estimable,
    member_message as member_message,
    nested_fit as nested_fit,
)
from ._shape import solve_on as solve_on
from ._stream import scaled_cho_factor as scaled_cho_factor
from ._stream_fit import (
    MIN_CHUNK as MIN_CHUNK,
    SMOOTH_HALF_WINDOW as SMOOTH_HALF_WINDOW,
    calibrate_chunks as calibrate_chunks,
    peak_abs as peak_abs,
    recording_arrays as recording_arrays,
    recording_from_arrays as recording_from_arrays,
    windows as windows,
)
