"""What `hdjax.pipelines` lends to the other hdjax packages: the paper's pipeline steps and the
streamed estimates, for the command line and the fleet.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._model import build_model as build_model
from ._paper import (
    PAPER_ERRORS as PAPER_ERRORS,
    PAPER_MS_PER_100 as PAPER_MS_PER_100,
    calibrate as calibrate,
    calibrate_saved as calibrate_saved,
    current_scale as current_scale,
    estimate_model as estimate_model,
    estimate_network as estimate_network,
    figure_series as figure_series,
    first_samples as first_samples,
    metrics_of as metrics_of,
    network_available as network_available,
    stacked_signals as stacked_signals,
    time_per_100 as time_per_100,
    train_network as train_network,
)
from ._preflight import check_angles as check_angles
from ._streamed import (
    ErrorSums as ErrorSums,
    StreamedEstimate as StreamedEstimate,
    model_estimates as model_estimates,
)
from ._streamed_dataset import PartStream as PartStream
