"""Many joints, many logs: the manifest, the per-(joint, log) task and the fleet table.

- [`hdjax.fleet.load_manifest`][]: read and check a fleet manifest (joints with their ratio,
  rated torque, column map and name; their logs with dates).
- [`hdjax.fleet.run_task`][]: one (joint, log) task (calibrate, calibrate + discover, or
  estimate), a plain function of plain data, so any Dask worker can run it; a failure becomes
  a row with its one-line error.
- [`hdjax.fleet.write_table`][], [`hdjax.fleet.drift_figure`][]: the results as one Parquet
  table (a row per joint-log) and a drift plot per joint.

The `hdjax fleet` command schedules the tasks on Dask (`hdjax.cli._fleet`).
"""

from ._manifest import Manifest as Manifest, Task as Task, load_manifest as load_manifest
from ._table import drift_figure as drift_figure, write_table as write_table
from ._task import run_task as run_task
