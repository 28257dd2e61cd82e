r"""Checks of a reference torque that need no truth: what the estimate is scored against.

A torque estimate is only as good as its reference shows, and a real log's reference brings
errors of its own. Each check compares the reference with the twist (through the calibrated
model's torque estimate, which follows the twist sample by sample) and with the motor current:

- **delay**: the lag of the reference behind the twist, from the peak of the cross-correlation
  of their first differences (refined between samples by a parabola); a held or filtered
  reference lags;
- **held samples**: the share of rows whose reference repeats the previous value exactly (a
  sample-and-hold stream: fresh values arrive less often than rows);
- **steps**: jumps in the reference that the twist does not show, found as peaks of the
  two-window mean difference of reference minus estimate, well above its noise; each is checked
  against the current (when the log has one distinct from the reference): a step the current
  does not show either is in the reference alone (a controller's friction feed-forward when the
  joint starts or stops, say);
- **outside the calibrated range**: the share of the squared error on rows whose estimate lies
  outside the torque range the model was calibrated on (where it extrapolates).

Every check returns a finding (a dict with `check`, `flagged`, its numbers and a `message`).
"""

from __future__ import annotations

import numpy as np

from .._custom_types import ArrayLike, Bool, Float

MAX_LAG = 20
"""Lags searched by the delay check, in samples either way."""

STEP_WINDOW_S = 0.1
"""Each window of the step check spans this long [s] (at least 5 samples)."""

STEP_SIGMAS = 6.0
"""A step is flagged when the two-window mean difference exceeds this many of its own noise
standard deviations."""

MAX_STEPS = 6


def _finite(*xs):
    ok = np.ones(np.asarray(xs[0]).shape, bool)
    for x in xs:
        if x is not None:
            ok &= np.isfinite(np.asarray(x, np.float64))
    return ok


def reference_delay(t, reference, estimate) -> dict:
    """The delay check: the lag [ms] of `reference` behind `estimate` (positive: the reference
    is late)."""
    r = np.diff(np.asarray(reference, np.float64))
    e = np.diff(np.asarray(estimate, np.float64))
    dt = float(np.median(np.diff(np.asarray(t, np.float64)))) if np.size(t) > 1 else np.nan
    n = r.size
    if n < 4 * MAX_LAG or not np.std(r) > 0 or not np.std(e) > 0:
        return dict(check="delay", flagged=False, delay_ms=float("nan"), message="")
    r, e = r - r.mean(), e - e.mean()
    lags = np.arange(-MAX_LAG, MAX_LAG + 1)
    cc = np.array(
        [np.dot(r[max(0, k) : n + min(0, k)], e[max(0, -k) : n - max(0, k)]) for k in lags]
    )
    cc /= np.sqrt(np.dot(r, r) * np.dot(e, e))
    i = int(np.argmax(cc))
    frac = 0.0
    if 0 < i < lags.size - 1:
        a, b, c = cc[i - 1], cc[i], cc[i + 1]
        den = a - 2 * b + c
        frac = 0.5 * (a - c) / den if den < 0 else 0.0
    lag = float(lags[i] + frac)
    delay_ms = lag * dt * 1e3
    flagged = abs(lag) >= 0.5 and cc[i] > 0.2
    msg = (
        f"the reference lags the twist by {delay_ms:.3g} ms ({lag:.2g} samples; correlation "
        f"{cc[i]:.2f}): a held or filtered reference is late, and the estimate is scored "
        "against a delayed torque; shift the reference's timestamps or compare at equal delay"
        if flagged and lag > 0
        else f"the reference leads the twist by {-delay_ms:.3g} ms ({-lag:.2g} samples): "
        "check the two streams' timestamps"
        if flagged
        else ""
    )
    return dict(
        check="delay",
        flagged=bool(flagged),
        delay_ms=delay_ms,
        delay_samples=lag,
        correlation=float(cc[i]),
        message=msg,
    )


def held_samples(t, reference) -> dict:
    """The held-samples check: the share of rows repeating the previous reference value."""
    x = np.asarray(reference, np.float64)
    if x.size < 2:
        return dict(check="held", flagged=False, held_fraction=0.0, message="")
    rep = np.r_[False, np.diff(x) == 0.0]
    share = float(rep.mean())
    fresh_t = np.asarray(t, np.float64)[~rep]
    period = float(np.median(np.diff(fresh_t))) if fresh_t.size > 1 else float("nan")
    flagged = share > 0.05
    msg = (
        f"{share:.0%} of the rows repeat the previous reference value: a sample-and-hold "
        f"stream with a fresh value about every {1e3 * period:.3g} ms; a held value is late by "
        "up to that, so score on fresh rows only"
        if flagged
        else ""
    )
    return dict(
        check="held",
        flagged=bool(flagged),
        held_fraction=share,
        fresh_period_ms=1e3 * period,
        message=msg,
    )


def _window_steps(d, w: int) -> np.ndarray:
    """Mean of the `w` samples after each sample minus the mean of the `w` before."""
    c = np.r_[0.0, np.cumsum(d)]
    n = d.size
    k = np.arange(w, n - w + 1)
    out = np.zeros(n)
    out[k] = (c[k + w] - c[k]) / w - (c[k] - c[k - w]) / w
    return out


def reference_steps(t, reference, estimate, current=None, omega=None) -> dict:
    """The steps check: jumps in `reference - estimate`, each with the current's share of it
    and whether the joint starts or stops there (from `omega`, when given)."""
    t = np.asarray(t, np.float64)
    d = np.asarray(reference, np.float64) - np.asarray(estimate, np.float64)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = max(5, int(round(STEP_WINDOW_S / dt)))
    empty = dict(check="steps", flagged=False, steps=[], message="")
    if d.size < 4 * w:
        return empty
    s = _window_steps(d - np.median(d), w)
    noise = 1.4826 * np.median(np.abs(np.diff(d) - np.median(np.diff(d)))) / np.sqrt(2.0)
    sigma = noise * np.sqrt(2.0 / w)
    if not sigma > 0:
        return empty
    big = np.abs(s) > STEP_SIGMAS * sigma
    steps = []
    cur = None
    if current is not None:
        dc = np.asarray(current, np.float64) - np.asarray(estimate, np.float64)
        if np.ptp(np.asarray(current) - np.asarray(reference)) > 0:
            cur = _window_steps(dc - np.median(dc), w)
    while big.any() and len(steps) < MAX_STEPS:
        k = int(np.argmax(np.where(big, np.abs(s), -1.0)))
        step = dict(t_s=float(t[k] - t[0]), size=float(s[k]))
        if cur is not None:
            step["current_size"] = float(cur[k])
        if omega is not None:
            om = np.abs(np.asarray(omega, np.float64))
            top = np.quantile(om, 0.99)
            before = om[max(0, k - w) : k].mean() if k else 0.0
            after = om[k : k + w].mean()
            moving = lambda v: v > 0.05 * top
            step["motion"] = (
                "start"
                if not moving(before) and moving(after)
                else "stop"
                if moving(before) and not moving(after)
                else "moving"
                if moving(after)
                else "rest"
            )
        steps.append(step)
        big[max(0, k - 2 * w) : k + 2 * w] = False
    steps.sort(key=lambda x: x["t_s"])
    alone = [
        x
        for x in steps
        if cur is not None and abs(x.get("current_size", 0.0)) < 0.3 * abs(x["size"])
    ]
    parts = []
    for x in steps:
        where = (
            f" as the joint {'starts' if x.get('motion') == 'start' else 'stops'}"
            if x.get("motion") in ("start", "stop")
            else ""
        )
        parts.append(f"{x['size']:+.3g} N·m at {x['t_s']:.3g} s{where}")
    if not steps:
        return empty
    if cur is None:
        tail = (
            "; the log has no current distinct from the reference to tell whether the joint "
            "felt them"
        )
    elif alone:
        tail = (
            f"; {len(alone)} of them the current does not show either, so they are in the "
            "reference alone (a controller's feed-forward, say): the estimate is scored against "
            "them, and no model of the joint can follow them"
        )
    else:
        tail = "; the current shows them too"
    msg = "the reference steps where the twist does not: " + ", ".join(parts) + tail
    return dict(
        check="steps",
        flagged=True,
        steps=steps,
        in_reference_alone=len(alone),
        noise_nm=float(sigma),
        message=msg,
    )


def outside_range(error, in_range) -> dict:
    """The outside-the-calibrated-range check: the share of the squared `error` on rows whose
    estimate lies outside the calibrated range (`in_range` false)."""
    e = np.asarray(error, np.float64)
    out = ~np.asarray(in_range, bool)
    total = float(np.sum(e**2))
    share = float(np.sum(e[out] ** 2) / total) if total > 0 else 0.0
    flagged = share > 0.1
    msg = (
        f"{share:.0%} of the squared error lies on the {int(out.sum())} rows ({out.mean():.0%}) "
        "whose estimate falls outside the calibrated torque range, where the model extrapolates: "
        "calibrate on a wider torque range"
        if flagged
        else ""
    )
    return dict(
        check="outside_range",
        flagged=bool(flagged),
        error_share=share,
        rows=int(out.sum()),
        message=msg,
    )


def reference_checks(
    t: Float[ArrayLike, " n"],
    reference: Float[ArrayLike, " n"],
    estimate: Float[ArrayLike, " n"],
    *,
    current: Float[ArrayLike, " n"] | None = None,
    omega: Float[ArrayLike, " n"] | None = None,
    in_range: Bool[ArrayLike, " n"] | None = None,
) -> list[dict]:
    """All the checks of the module docstring on one recording.

    **Arguments:** timestamps `t` [s], the `reference` torque, the model's torque `estimate`
    on the same rows, and optionally the `current` (in torque units, or any units: only its
    steps' share is read), the link speed `omega` (whether a step comes as the joint starts or
    stops) and the estimate's `in_range` flags.

    **Returns:** the findings, in the order delay, held samples, steps, outside the range.
    """
    ok = _finite(reference, estimate)
    pick = lambda x: None if x is None else np.asarray(x, np.float64)[ok]
    t, ref, est = pick(t), pick(reference), pick(estimate)
    cur = pick(current)
    if cur is not None and np.ptp(cur) > 0:
        # the current in torque units: its least-squares gain and offset on the reference
        a = np.column_stack([cur, np.ones_like(cur)])
        cur = a @ np.linalg.lstsq(a, ref, rcond=None)[0]
    out = [reference_delay(t, ref, est), held_samples(t, ref)]
    out.append(reference_steps(t, ref, est, cur, pick(omega)))
    if in_range is not None:
        out.append(outside_range(est - ref, np.asarray(in_range, bool)[ok]))
    return out
