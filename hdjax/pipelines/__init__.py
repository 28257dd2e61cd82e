"""Experiment pipelines: the runs that put the model packages together.

They sit above the model packages (compliance, network, fit, plant) and below the command
line: configuration only parses and validates, and these modules calibrate, train, estimate
and tabulate.

- `_paper`: the steps of `hdjax run` (build the model, calibrate, estimate, train the network,
  time), Song et al. 2019 Section IV.
- [`hdjax.pipelines.compare_methods`][]: every calibration method on the plant's four
  scenarios, as a loop over estimators ([`hdjax.pipelines.FITTERS`][]).
- [`hdjax.pipelines.periodic_features_effect`][]: how much the periodic angle features help.
"""

from ._compare import (
    FITTERS as FITTERS,
    METHOD_NAMES as METHOD_NAMES,
    compare_methods as compare_methods,
    format_table as format_table,
    plot_comparison as plot_comparison,
)
from ._periodic import (
    format_periodic_table as format_periodic_table,
    periodic_features_effect as periodic_features_effect,
)
