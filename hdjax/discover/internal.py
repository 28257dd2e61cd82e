"""What `hdjax.discover` lends to the other hdjax packages: the loop's entry, its configuration and
its report writer, for the command line.

Not part of the documented API: these names may change with the packages that use them.
"""

from ._chunked import check_chunk as check_chunk
from ._config import (
    discover_options as discover_options,
    load_discover_config as load_discover_config,
)
from ._experiment import experiment_toml as experiment_toml
from ._loop import discover as discover
from ._report import write_report as write_report
from ._start import paper_model as paper_model
from ._subsample import (
    SELECT_BLOCKS as SELECT_BLOCKS,
    load_selection as load_selection,
    refit_on_whole_log as refit_on_whole_log,
)
