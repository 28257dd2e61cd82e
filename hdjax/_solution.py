"""One fit result: the fitted value, a result code with an actionable message, and statistics.

Modelled on `optimistix.Solution`: every fit in hdjax returns a [`Solution`][] (the fitted
model or estimator in `value`, a [`RESULTS`][] member in `result`, numbers in `stats`, and, for
fits that produce more than numbers, a record in `aux`). `RESULTS` messages say what to do, not
only what went wrong.

- `compliance.calibrate_lstsq`, `calibrate_stream`, `calibrate_rls`: `value` the calibrated
  `ComplianceModel`; `stats` `rank`, `n_terms`, `condition`, `residual_rms`, `n_samples`,
  `segment_counts`, `dropped`, `collinear`, `fit_time_s`.
- `fit.fit_compliance_gradient`: the `ComplianceModel`; `loss`, `steps`, `method`, `fit_time_s`.
- `fit.fit_hybrid`: the `HybridModel`; `history`, `loss`, `steps`, `method`, `fit_time_s`.
- `plant.fit_plant`: the `PlantParams`; `names`, `values`, `loss`, `steps`, `fit_time_s`.
- `network.train_backprop`, `train_optax`: the `Network`; `history`, `val_rmse`, `steps`,
  `target_reached`, `fit_time_s`.
- `discover.discover`: the final `ComplianceModel`; `n_effects`, `fit_time_s`, ...; the loop's
  record in `aux`.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx

from ._errors import CalibrationError


class RESULTS(eqx.Enumeration):
    """How a fit ended; the message of each failure says how to fix it."""

    successful = ""
    rank_deficient = (
        "excitation too poor: some model columns are collinear on this data (e.g. a constant "
        "current makes the current polynomial collinear with the constant); add load variation "
        "or motion, or remove those terms from the model"
    )
    not_invertible = (
        "the calibrated compliance is not increasing in torque, so torque cannot be recovered "
        "from twist; add data in the torque ranges the model covers, or use fewer segments"
    )
    max_steps_reached = (
        "the optimiser stopped at its step limit before reaching its target (tolerance or error "
        "target); raise the number of steps, or loosen the target"
    )
    nonfinite = (
        "the fit produced non-finite values; check the data for NaN or inf and the inputs' "
        "scales (angles in radians, current in amperes)"
    )
    twist_reversed = (
        "the twist falls as torque rises over the data: the encoders count against the "
        "torque, so set twist_sign = -1 in the [joint] table"
    )


class Solution(eqx.Module):
    """A fit's outcome.

    **Fields:**

    - `value`: the fitted model or estimator.
    - `result`: a [`RESULTS`][] member (`RESULTS.successful` when nothing went wrong).
    - `stats`: numbers about the fit (`fit_time_s`, `steps`, `loss`, `rank`, ...; the table in
      the module docstring lists them per fit).
    - `aux`: what a fit produces besides the value and numbers (the residual loop's per-step
      record), or `None`.
    """

    value: Any
    result: RESULTS
    stats: dict
    aux: Any = None

    @property
    def ok(self) -> bool:
        """Whether the fit succeeded."""
        return bool(self.result == RESULTS.successful)

    @property
    def message(self) -> str:
        """The result's message ("" on success)."""
        return RESULTS[self.result]

    def raise_if_failed(self) -> Solution:
        """This solution, or `CalibrationError` with the result's message if the fit failed."""
        if not self.ok:
            raise CalibrationError(self.message)
        return self
