"""Joint gradient fitting of compliance model, network and plant parameters."""

from ._estimators import (
    AbstractEstimator as AbstractEstimator,
    ComplianceEstimator as ComplianceEstimator,
    HybridEstimator as HybridEstimator,
    NetworkEstimator as NetworkEstimator,
)
from ._hybrid import (
    PLANT_FIELDS as PLANT_FIELDS,
    HybridModel as HybridModel,
    check_inputs as check_inputs,
    fit_hybrid as fit_hybrid,
    make_hybrid as make_hybrid,
    predict_hybrid as predict_hybrid,
)
from ._inputs import (
    DAHL_FRACTIONS as DAHL_FRACTIONS,
    HybridInputs as HybridInputs,
    dahl_scales as dahl_scales,
    dynamic_columns as dynamic_columns,
    hybrid_inputs as hybrid_inputs,
)
from ._linear import (
    METHODS as METHODS,
    LinearProblem as LinearProblem,
    fit_compliance_gradient as fit_compliance_gradient,
    linear_problem as linear_problem,
)
