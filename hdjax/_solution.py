"""One fit result: the fitted value, a result code with an actionable message, and statistics.

Modelled on `optimistix.Solution`: every fit in hdjax can be read as a [`Solution`][] (the
fitted model or estimator in `value`, a [`RESULTS`][] member in `result`, numbers in `stats`).
`RESULTS` messages say what to do, not only what went wrong.
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
        "the optimiser stopped at its step limit before reaching its target; raise the number "
        "of steps, or loosen the target"
    )
    nonfinite = (
        "the fit produced non-finite values; check the data for NaN or inf and the inputs' "
        "scales (angles in radians, current in amperes)"
    )


class Solution(eqx.Module):
    """A fit's outcome.

    **Fields:**

    - `value`: the fitted model or estimator.
    - `result`: a [`RESULTS`][] member (`RESULTS.successful` when nothing went wrong).
    - `stats`: numbers about the fit (`fit_time_s`, `steps`, `loss`, `rank`, ...).
    """

    value: Any
    result: RESULTS
    stats: dict

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
