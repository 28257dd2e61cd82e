"""Experiment pipelines: the runs that put the model packages together.

They sit above the model packages (compliance, network, fit, plant) and below the command
line: configuration only parses and validates, and these modules calibrate, train, estimate
and tabulate.

- `_paper`: the steps of `hdjax run` (build the model, calibrate, estimate, train the network,
  time), Song et al. 2019 Section IV.
- [`hdjax.pipelines.compare_methods`][]: every calibration method on the plant's four
  scenarios, as a loop over estimators ([`hdjax.pipelines.FITTERS`][]).
- [`hdjax.pipelines.periodic_features_effect`][]: how much the periodic angle features help.
- Hashimoto et al. 1993, Figs. 15-17: [`hdjax.pipelines.static_characteristic`][],
  [`hdjax.pipelines.step_response`][], [`hdjax.pipelines.sine_tracking`][] on
  [`hdjax.pipelines.paper_joint`][]; the strain-gauge / deformation feedback comparison
  [`hdjax.pipelines.compare_feedback`][]; everything at once with its figures:
  [`hdjax.pipelines.reproduce_figures`][].
- [`hdjax.pipelines.build_dataset`][]: the calibration and test recordings of an experiment
  (plant scenarios, files through a column map, or synthetic); with `[fit] chunk` on files a
  [`hdjax.pipelines.StreamedDataset`][] that reads them chunk by chunk.
- [`hdjax.pipelines.preflight`][]: the checks of a resolved config (or one `--set` or sweep
  member) before any work: the model can be built, the data fits in memory.
"""

from ._compare import (
    FITTERS as FITTERS,
    METHOD_NAMES as METHOD_NAMES,
    compare_methods as compare_methods,
    format_table as format_table,
    plot_comparison as plot_comparison,
)
from ._dataset import (
    Dataset as Dataset,
    build_dataset as build_dataset,
    synthetic_recording as synthetic_recording,
)
from ._periodic import (
    format_periodic_table as format_periodic_table,
    periodic_features_effect as periodic_features_effect,
)
from ._preflight import preflight as preflight
from ._strain_compare import (
    CaseResult as CaseResult,
    Comparison as Comparison,
    compare_feedback as compare_feedback,
)
from ._strain_experiments import (
    FRICTION_PAPER as FRICTION_PAPER,
    SineResult as SineResult,
    StaticResult as StaticResult,
    StepResponse as StepResponse,
    TorqueLoop as TorqueLoop,
    open_loop_error_friction as open_loop_error_friction,
    paper_joint as paper_joint,
    sine_tracking as sine_tracking,
    static_characteristic as static_characteristic,
    step_response as step_response,
)
from ._strain_figures import reproduce_figures as reproduce_figures
from ._streamed_dataset import StreamedDataset as StreamedDataset
