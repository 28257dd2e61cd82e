"""Figures, tables and atomically written result directories.

- [`hdjax.report.torque_figure`][]: estimated against measured torque with the error
  (Song et al. Figs. 9-16).
- [`hdjax.report.error_rate_figure`][]: error rate in % of rated torque, methods side by side
  (Fig. 17).
- [`hdjax.report.sweep_figure`][], [`hdjax.report.find_knee`][]: a sweep's held-out error and
  compute time with the knee marked.
- [`hdjax.report.ResultDir`][]: a result directory written in a staging directory and renamed
  into place when complete, stamped with a marker file;
  [`hdjax.report.check_output_dir`][] and [`hdjax.report.check_output_file`][]: the rules that
  keep a user's files safe (never write over an input, replace only an hdjax result).
"""

from ._figures import (
    error_rate_figure as error_rate_figure,
    error_rate_title as error_rate_title,
    find_knee as find_knee,
    sweep_figure as sweep_figure,
    torque_figure as torque_figure,
)
from ._outputs import (
    MARKER as MARKER,
    check_not_input as check_not_input,
    check_output_dir as check_output_dir,
    check_output_file as check_output_file,
    read_marker as read_marker,
)
from ._report import (
    ResultDir as ResultDir,
    environment as environment,
    json_bytes as json_bytes,
    markdown_table as markdown_table,
)
