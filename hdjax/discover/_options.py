"""The residual loop's settings, and the stopping rule they set, in words."""

from __future__ import annotations

import dataclasses

from .._errors import ConfigError
from ._chunked import check_chunk
from ._library import LibraryOptions


@dataclasses.dataclass(frozen=True)
class DiscoverOptions:
    """Settings of the residual loop (see the module docstring for the stopping rule)."""

    max_effects: int = 5
    min_gain: float = 0.05
    min_torque_gain: float = 0.02
    min_stability: float = 0.7
    n_resamples: int = 20
    n_shortlist: int = 3
    n_grid_tries: int = 3
    seed: int = 0
    n_folds: int = 5
    block: int = 200
    sindy_threshold: float = 0.02
    library: LibraryOptions = dataclasses.field(default_factory=LibraryOptions)
    n_segments: int = 5
    poly_order: int = 6
    fourier_order: int = 3
    per_segment: bool = False
    current_scale: float | None = None
    chunk: int = 0
    """Samples per chunk of the loop's least-squares fits (calibration, cross-validation,
    candidate scores, intervals), so that no design of the whole record is formed; 0: the
    whole record at once. Same coefficients to 1e-9 relative; memory bounded by the chunk."""
    n_shortlist_rounds: int = 2
    """Rounds of `n_shortlist` eligible candidates: a round is tried only when no trial of
    the rounds before it qualifies (the stopping rule)."""

    def __post_init__(self):
        check_chunk(self.chunk)
        for name in ("n_shortlist", "n_shortlist_rounds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(
                    f"discover {name} must be a whole number of at least 1, got {value!r}"
                )


def _percent(fraction: float) -> str:
    """A setting as a percentage with the digits it was given (0.05 -> 5%, 0.998 -> 99.8%)."""
    return f"{100 * fraction:.4g}%"


def stopping_rule(options: DiscoverOptions) -> str:
    """The loop's stopping rule in words, with the values `options` gives it (the report's
    `stopping_rule`, and the module docstring of [`hdjax.discover._loop`][] in general)."""
    o = options
    return (
        f"a candidate is eligible when pysindy STLSQ selects it (threshold {o.sindy_threshold:g}) "
        f"and it removes at least {_percent(o.min_gain)} (min_gain) of the model's cross-validated "
        f"twist error ({o.n_folds} folds of whole contiguous blocks of TRAIN) in the standard "
        f"fold assignment and in at least {_percent(o.min_stability)} (min_stability) of "
        f"{o.n_resamples} resampled ones; of the {o.n_shortlist} best eligible candidates (an "
        "alias of one already among them takes no place, and a speed term is tried as the "
        "reading the motor current supports, encoder skew or friction), those that lower the "
        "cross-validated "
        "torque error (whole pipeline per fold: calibration, then inversion) by at least "
        f"{_percent(o.min_torque_gain)} (min_torque_gain) qualify; of those within one standard "
        "error of the lowest (paired over the held-out blocks), the one with the fewest columns, "
        "then the lowest is added, where of errors closer than min_torque_gain one seriously "
        "collinear with the model's columns (variance inflation over 10) gives way to one TRAIN "
        "determines more than twice as well; "
        + (
            f"when none qualifies, the next {o.n_shortlist} eligible are tried, up to "
            f"{o.n_shortlist_rounds} rounds in all (n_shortlist_rounds); "
            if o.n_shortlist_rounds > 1
            else ""
        )
        + "stop when none qualifies, or after "
        f"{o.max_effects} effects (max_effects); then, if the final model's error lies within "
        "one standard error of the starting model's, every step is taken back"
    )
