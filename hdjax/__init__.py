"""hdjax: torque estimation for robotic joints with harmonic (strain-wave) reducers.

Angles and twists are handled in float64: importing hdjax turns on JAX's 64-bit mode
(`jax_enable_x64`), because a twist of one arcsecond sits under hundreds of radians of motor
angle and float32 cannot resolve it.

Sub-packages (imported on first access, so `import hdjax` stays light):

- `hdjax.compliance`: the Song et al. (2019) compliance model, least squares, recursive least
  squares and torque inversion.
- `hdjax.plant`: a differentiable two-inertia harmonic-drive joint with hysteresis and friction,
  and the paper's four load experiments.
- `hdjax.network`: the Kalman-filtered current and the back-propagation network.
- `hdjax.fit`: joint gradient fitting of compliance, network and plant.
- `hdjax.discover`: the residual loop (find, trace, add, refit, report).
- `hdjax.effects`: the catalogue of physical effects, one module per family (plant effect,
  regression term, candidates).
- `hdjax.strain`: Hashimoto et al. (1993) strain-gauge sensing and joint torque control.
- `hdjax.reference`: joint-torque references from a force/torque sensor and the arm's Jacobian.
- `hdjax.pipelines`: the experiment pipelines (an experiment's data and model, the paper run,
  method comparison, periodic features) above the model packages.
- `hdjax.modelfile`: a calibrated model (and network) saved to and loaded from one file.
- `hdjax.config`: experiment files, parsed and validated (no model built, no data read).
- `hdjax.report`: metrics, figures and reports.
- `hdjax.export`: a calibrated model as dependency-free C code with a per-sample step.
"""

from ._interrupts import guard_startup as _guard_startup

_guard_startup()  # the `hdjax` command: a signal while JAX is imported exits at once (130/143)

import importlib  # noqa: E402
import importlib.metadata  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from ._errors import (  # noqa: E402
    CalibrationError as CalibrationError,
    ConfigError as ConfigError,
    DataError as DataError,
    DivergenceError as DivergenceError,
    ExportError as ExportError,
    HdjaxError as HdjaxError,
    InversionError as InversionError,
    ModelMismatchError as ModelMismatchError,
    UnitWarning as UnitWarning,
)
from ._features import (  # noqa: E402
    Signals as Signals,
    find_gaps as find_gaps,
    finite_difference_velocity as finite_difference_velocity,
    signals as signals,
    smoothed_velocity as smoothed_velocity,
    twist as twist,
)
from ._formats import load_recording as load_recording  # noqa: E402
from ._io import (  # noqa: E402
    ColumnMap as ColumnMap,
    load_csv as load_csv,
    load_npz as load_npz,
    save_csv as save_csv,
    save_npz as save_npz,
)
from ._joint import Joint as Joint, load_joint as load_joint  # noqa: E402
from ._metrics import ErrorMetrics as ErrorMetrics, error_metrics as error_metrics  # noqa: E402
from ._recording import Recording as Recording, make_recording as make_recording  # noqa: E402
from ._solution import RESULTS as RESULTS, Solution as Solution  # noqa: E402

try:
    __version__ = importlib.metadata.version("hdjax")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+unknown"

_SUBPACKAGES = (
    "compliance",
    "plant",
    "network",
    "fit",
    "discover",
    "effects",
    "strain",
    "reference",
    "pipelines",
    "modelfile",
    "report",
    "config",
    "export",
)


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f"hdjax.{name}")
    raise AttributeError(f"module 'hdjax' has no attribute {name!r}")
