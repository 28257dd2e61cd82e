r"""The amplitude of every added effect, with a 95 % moving-block bootstrap interval over TRAIN.

An effect's coefficients are those of its columns in the final fit (Song et al. eqs.
(15)-(17)); by the Frisch-Waugh-Lovell theorem they are the regression of the twist on the
effect's columns after both are made orthogonal to every other column of the model.

**Errors in the variables.** The design's torque columns are built from the measured reference
torque, so the sensor's noise attenuates the compliance and biases every effect that moves with
the torque. With `instruments` (the design at [`instrument_torque`][], the mean of each
sample's two neighbours, independent of a white sensor noise at the sample) the coefficients
are two-stage least squares: the design's columns are replaced by their fits on the
instruments' (columns free of the torque are reproduced), then the regression above is solved
(Fuller 1987, ch. 2; the two-stage estimator of Theil 1953).

**The encoder's noise in the velocity columns.** The load encoder's white noise $e_k$ is in the
twist $y_k$ and in the backward-difference link speed $\omega_{l,k} = (\theta_{l,k} -
\theta_{l,k-1})/\Delta t$, so every column built from $\omega_l$ (the paper's kinematic term
of eq. (9), friction and skew screens of the link speed) shares the noise of the sample it
explains and biases the other coefficients (the θ_m order-2 harmonic of the clean noisy joints
came out 0.2-0.6 % low, more than its interval's half-width). The instruments' signals
therefore carry [`instrument_speed`][] for $\omega_l$: the slope through neighbouring samples
that leaves out samples $k$ and $k-1$, independent of $e_k$ and $e_{k-1}$ while the true speed
is smooth at the sampling rate. The motor encoder's noise enters the twist divided by the ratio
and is left as it is.

**Bootstrap.** Moving blocks (Kunsch 1989) of `length` samples, no shorter than twice the
residual's correlation length, drawn with replacement until they cover the record, resample
the estimating equation $x_\perp^T(y - X\beta) = 0$ with the structural residual
$y - X\hat\beta$ of the design itself (so the torque noise is in it); block sums come from
cumulative sums, so a few hundred replicates cost little.

**Partialling out.** The projections onto the other columns come from the design's Gram
matrix, formed once for all effects ([`partial_out`][]): per effect a small Cholesky solve on
the Jacobi-scaled Gram block of the other columns, refined once with the true residual (the
corrected semi-normal equations of [`hdjax.compliance.calibrate_lstsq`][], as accurate as QR
while the scaled condition number is at most `CSNE_MAX_COND`; above it, a QR of those columns).
No $n \times p$ factor is formed per effect, and no scaled copy of the design.

**Amplitude.** A harmonic's is $\sqrt{a^2 + b^2}$ (the twist it adds at its peak); a
one-column effect's is its coefficient times the column's largest magnitude over TRAIN (signed:
the twist it adds at its extreme, e.g. a Coulomb level). It is given in arcsec of twist and in
N·m of *equivalent torque*: the twist divided by the model's local compliance
$\partial\Delta\theta/\partial T$, averaged with the effect column's energy as weights (the
torque that would have to act through the flexspline to produce the same twist). The ratio is
formed in every replicate from the replicate's own blocks, which for it are also no shorter
than twice the torque's correlation length (the compliance follows the torque, so a twist
amplitude and the compliance it is divided by vary together along the record).

References: H. R. Kunsch, "The jackknife and the bootstrap for general stationary
observations", Ann. Statist. 17 (1989) 1217-1241; W. A. Fuller, "Measurement Error Models",
Wiley 1987; H. Theil, "Repeated least squares applied to complete equation systems", The Hague
1953.
"""

from __future__ import annotations

import typing
from collections.abc import Iterator

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.linalg

from .._features import Signals
from ..compliance import ComplianceModel
from ..compliance.internal import CSNE_MAX_COND, scaled_cho_factor
from ._chunked import Chunks
from ._folds import MAX_BLOCKS, correlation_length
from ._pipeline import PipelineData, canonical, structure_shape

ARCSEC = 180.0 * 3600.0 / np.pi
N_BOOTSTRAP = 400
LEVEL = 0.95


def bootstrap_length(residual, starts) -> int:
    """Bootstrap block length: twice the residual's correlation length, and long enough that
    the record holds at most `MAX_BLOCKS` blocks (the replicates' block starts stay small)."""
    n = int(np.asarray(residual).size)
    return int(max(2 * correlation_length(residual, starts), -(-n // MAX_BLOCKS), 1))


def _amplitude(term, beta: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """Amplitudes of coefficient rows `beta` (shape `(..., m)`)."""
    if type(term).__name__ == "Harmonics" and beta.shape[-1] == 2:
        return np.hypot(beta[..., 0], beta[..., 1])
    if beta.shape[-1] == 1:
        return beta[..., 0] * peak[0]
    return np.sqrt(np.sum((beta * peak) ** 2, axis=-1))


def _local_compliance(model: ComplianceModel, torque: np.ndarray) -> np.ndarray:
    k = np.asarray(model.k)
    seg = np.searchsorted(np.asarray(model.knots), torque, side="right")
    return k[seg]


def instrument_torque(torque, starts) -> np.ndarray:
    """The reference torque's instrument: at each sample, the mean of its two neighbours in the
    same segment (one neighbour at a segment's ends, the sample itself in a one-sample segment).

    The torque sensor's noise is white, so the neighbours' mean is independent of the noise at
    the sample, while the true torque is smooth at the sampling rate."""
    t = np.asarray(torque, np.float64)
    starts = np.asarray(starts, bool)
    n = t.size
    ends = np.r_[starts[1:], True]
    prev = np.where(starts, np.nan, np.r_[np.nan, t[:-1]])
    nxt = np.where(ends, np.nan, np.r_[t[1:], np.nan])
    both = np.vstack([prev, nxt])
    cnt = np.sum(np.isfinite(both), axis=0)
    out = np.where(cnt > 0, np.nansum(both, axis=0) / np.maximum(cnt, 1), t)
    return out.reshape(n)


INSTRUMENT_HALF_WIDTH = 4
"""Samples on each side of [`instrument_speed`][]'s line (besides the two it leaves out)."""


def instrument_speed(t, theta, starts, half: int = INSTRUMENT_HALF_WIDTH) -> np.ndarray:
    """A speed at each sample free of the angle's noise at that sample and the one before:
    the slope of the least-squares line through `theta` at samples `k-1-half .. k-2` and
    `k+1 .. k+half` of the same segment (`starts` marks where segments begin), leaving out
    `k` and `k-1`, the two samples the backward difference at `k` reads; the backward
    difference where fewer than 3 such samples exist. Exact for an angle linear in time."""
    t = np.asarray(t, np.float64)
    th = np.asarray(theta, np.float64)
    n = th.size
    seg = np.cumsum(np.asarray(starts, bool)) - 1
    k = np.arange(n)
    s1 = np.zeros(n)
    st = np.zeros(n)
    sx = np.zeros(n)
    stt = np.zeros(n)
    stx = np.zeros(n)
    for offset in [*range(-1 - half, -1), *range(1, half + 1)]:
        j = np.clip(k + offset, 0, n - 1)
        ok = (k + offset >= 0) & (k + offset < n) & (seg[j] == seg)
        tc = np.where(ok, t[j] - t, 0.0)  # centred on the sample: no cancellation
        xc = np.where(ok, th[j] - th, 0.0)
        s1 += ok
        st += tc
        sx += xc
        stt += tc * tc
        stx += tc * xc
    m = np.maximum(s1, 1.0)
    den = stt - st * st / m
    good = (s1 >= 3) & (den > 0)
    backward = np.zeros(n)
    inner = np.flatnonzero(~np.asarray(starts, bool))
    inner = inner[inner > 0]
    backward[inner] = (th[inner] - th[inner - 1]) / (t[inner] - t[inner - 1])
    return np.where(good, (stx - st * sx / m) / np.where(good, den, 1.0), backward)


def instrumented_signals(sig: Signals, starts) -> Signals:
    """`sig` with the link speed `omega_l` replaced by [`instrument_speed`][] (the signals the
    instruments' design is built from; see the module docstring). Without time stamps `sig`
    is returned as it is."""
    if sig.t is None:
        return sig
    speed = instrument_speed(np.asarray(sig.t), np.asarray(sig.theta_l), starts)
    return eqx.tree_at(lambda s: s.omega_l, sig, jnp.asarray(speed))


class _ArrayRows:
    """A design held in memory, as a one-chunk row source (`designs(model)` as `Chunks`)."""

    def __init__(self, a: np.ndarray):
        self.a = a

    def designs(self, model):
        yield 0, self.a.shape[0], self.a


class _FitRows:
    """The design's rows with the active columns replaced by their first-stage fits on the
    instruments' rows, `Z[:, cols] @ gamma` (two-stage least squares)."""

    def __init__(self, rows, inst, cols: np.ndarray, gamma: np.ndarray):
        self.rows, self.inst, self.cols, self.gamma = rows, inst, cols, gamma

    def designs(self, model):
        for (lo, hi, a), (_, _, z) in zip(self.rows.designs(model), self.inst.designs(model)):
            f = np.array(a, copy=True)
            f[:, self.cols] = z[:, self.cols] @ self.gamma
            yield lo, hi, f


@typing.runtime_checkable
class RowSource(typing.Protocol):
    """Where design rows come from, chunk by chunk: `designs(model)` yields `(lo, hi, rows)`
    (`Chunks` for a log, one chunk for a design in memory, or the two-stage fits of either)."""

    def designs(self, model) -> Iterator[tuple[int, int, np.ndarray]]: ...


def _csne(gram_cc: np.ndarray, rhs: np.ndarray, residual_pass) -> np.ndarray:
    """Solve `gram_cc w = rhs` on the Jacobi-scaled Gram block, refined once with
    `residual_pass(w)` (the columns' products with the true residual; corrected semi-normal
    equations), or by least squares on the Gram block above `CSNE_MAX_COND`."""
    d = np.sqrt(np.diag(gram_cc))
    d[d == 0] = 1.0
    gs = gram_cc / np.outer(d, d)
    chol = scaled_cho_factor(gs, CSNE_MAX_COND)
    if chol is None:
        solve = lambda r: scipy.linalg.lstsq(gs, r / _col(d, r))[0] / _col(d, r)  # noqa: E731
    else:
        solve = lambda r: (  # noqa: E731
            scipy.linalg.cho_solve(chol[0], r / _col(d, r), check_finite=False) / _col(d, r)
        )
    w = solve(rhs)
    return w + solve(residual_pass(w))


def _col(d: np.ndarray, r: np.ndarray) -> np.ndarray:
    return d if r.ndim == 1 else d[:, None]


def _two_stage(model, rows, inst, cols: np.ndarray) -> _FitRows | _ArrayRows:
    """The first stage of two-stage least squares over row sources: the active columns' fits
    on the active instrument columns (columns free of the reference torque are reproduced).
    Designs held in memory give the fitted design formed once (every later pass reads it),
    and their active columns are taken once for both passes of the first stage."""
    in_memory = isinstance(rows, _ArrayRows) and isinstance(inst, _ArrayRows)
    if in_memory:
        held = [(_columns(inst.a, cols), _columns(rows.a, cols))]
        pairs = lambda: held  # noqa: E731
    else:
        pairs = lambda: (  # noqa: E731
            (z[:, cols], a[:, cols])
            for (_, _, a), (_, _, z) in zip(rows.designs(model), inst.designs(model))
        )
    zz = zx = 0.0
    for zc, ac in pairs():
        zz = zz + zc.T @ zc
        zx = zx + zc.T @ ac

    def residual_pass(g):
        out = 0.0
        for zc, ac in pairs():
            out = out + zc.T @ (ac - zc @ g)
        return out

    gamma = _csne(zz, zx, residual_pass)
    if not in_memory:
        return _FitRows(rows, inst, cols, gamma)
    fz = held.pop()[0] @ gamma
    if _all_columns(rows.a, cols):  # every column fitted: the fits are the design
        return _ArrayRows(fz)
    fitted = np.array(rows.a, copy=True)  # as `_FitRows.designs` forms it, once
    fitted[:, cols] = fz
    return _ArrayRows(fitted)


def _all_columns(x: np.ndarray, cols: np.ndarray) -> bool:
    """Whether `cols` are all of `x`'s columns, in order."""
    return cols.size == x.shape[1] and np.array_equal(cols, np.arange(x.shape[1]))


def _columns(x: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """`x[:, cols]`, without the copy when `cols` are all of `x`'s columns in order (read
    only)."""
    return x if _all_columns(x, cols) else x[:, cols]


def effect_intervals(
    model: ComplianceModel,
    design: np.ndarray | None,
    data: PipelineData,
    estimate: np.ndarray,
    *,
    length: int,
    instruments: np.ndarray | Chunks | None = None,
    n_bootstrap: int = N_BOOTSTRAP,
    seed: int = 0,
    chunks: Chunks | None = None,
) -> list[dict]:
    """Amplitude and 95 % interval of each effect group of `model` (see the module docstring).

    **Arguments:** `model` (calibrated on `data`), `design` (its design matrix on `data`, with
    the same hysteresis driver as at calibration), `estimate` (its torque estimate on `data`,
    where the local compliance is read), `length` (bootstrap block length in samples),
    `instruments` (optional: the design evaluated at [`instrument_torque`][] on
    [`instrumented_signals`][], or with `chunks` the `Chunks` of those; with it the amplitudes
    are two-stage least-squares estimates, which neither the torque sensor's noise nor the load
    encoder's in the link speed biases), `chunks` (instead of `design`: the record
    with the same driver, whose design rows are formed chunk by chunk for the Gram matrix and
    the projections, [`partial_out`][]).

    **Returns:** per effect, a dict with `effect`, `arcsec`, `arcsec_ci95`, `nm`, `nm_ci95`,
    `block_samples`.
    """
    active = np.asarray(model.active)
    y = data.twist
    n = y.size
    if chunks is None:
        # compliances the shape constraint holds at its floor are known, not estimated: they
        # leave the regression (their twist taken from the target) and the intervals are
        # conditional on the active set
        held = _held_at_floor(model, design, y, data.torque)
        if held.any():
            y = y - design[:, held] @ np.asarray(model.coef)[held]
            active = active & ~held
    cols = np.flatnonzero(active)
    if chunks is not None:
        model = canonical(model)
    rows = _ArrayRows(design) if chunks is None else chunks
    if instruments is None:
        fit = rows
    else:
        inst = _ArrayRows(instruments) if chunks is None else instruments
        fit = _two_stage(model, rows, inst, cols)
    gram = row_gram(model, fit, y)
    p = model.n_coef

    def residual_pass(w):
        out = 0.0
        for lo, hi, f in fit.designs(model):
            fc = _columns(f, cols)
            out = out + fc.T @ (y[lo:hi] - fc @ w)
        return out

    coef = np.zeros(p)
    coef[cols] = _csne(gram[np.ix_(cols, cols)], gram[cols, p], residual_pass)
    # the structural residual: that of the design itself (torque noise included), and the
    # effect columns themselves
    resid = np.empty(n)
    eff = np.arange(p - model.n_effect, p)
    x_all = np.empty((n, eff.size))
    for lo, hi, a in rows.designs(model):
        resid[lo:hi] = y[lo:hi] - a @ coef
        x_all[lo:hi] = a[:, eff]
    comp = _local_compliance(model, np.asarray(estimate))
    rng = np.random.default_rng(seed)
    length = int(max(1, min(length, n // 4)))
    # the equivalent torque divides by a compliance that follows the torque: its replicates'
    # blocks also hold the torque's dependence
    length_nm = int(max(length, min(2 * correlation_length(data.torque, data.starts), n // 4)))
    schemes = [_Blocks(rng, n, length, n_bootstrap), _Blocks(rng, n, length_nm, n_bootstrap)]
    out = []
    i = model.n_coef - model.n_effect
    for term in model.effect_terms:
        m = len(term.names())
        sl = np.arange(i, i + m)
        i += m
        others = np.flatnonzero(active & ~np.isin(np.arange(model.n_coef), sl))
        x = x_all[:, sl - eff[0]]
        xp, _ = partial_out(model, fit, y, others, sl, gram)
        row = _bootstrapped(term, coef[sl], xp, x, resid, comp, schemes)
        row |= dict(block_samples=length, nm_block_samples=length_nm)
        out.append(row)
    return out


def _bootstrapped(term, beta, xp, x, resid, comp, schemes) -> dict:
    """One effect's amplitude and its 95 % intervals (twist, equivalent torque, and its own
    parameter where its coefficient is one) from the moving-block replicates of `schemes`:
    `beta` its coefficients, `xp` its columns with the others partialled out, `x` its columns,
    `resid` the structural residual, `comp` the local compliance per sample."""
    n, m = xp.shape
    target = xp @ beta + resid
    peak = np.abs(x).max(axis=0)
    amp = float(_amplitude(term, beta[None, :], peak)[0])
    # the replicates resample the estimating equation xp'(y - X beta) = 0
    xx = np.einsum("ni,nj->nij", xp, xp).reshape(n, m * m)
    xy = xp * target[:, None]
    # local compliance weighted by the effect's column energy: twist -> equivalent torque,
    # the ratio formed in each replicate from the same blocks
    w = np.sum(x * x, axis=1)
    if not np.sum(w) > 0:
        w = np.ones(n)
    k_eff = float(np.sum(w * comp) / np.sum(w))
    ci = []
    boot_coef = None
    for blocks in schemes:
        boot = np.linalg.solve(
            blocks.sums(xx).reshape(-1, m, m) + 1e-300 * np.eye(m), blocks.sums(xy)[..., None]
        )
        boot_coef = boot[..., 0] if boot_coef is None else boot_coef
        amps = _amplitude(term, boot[..., 0], peak)
        k_boot = blocks.sums(w * comp) / np.maximum(blocks.sums(w), np.finfo(float).tiny)
        ci.append((amps, amps / k_boot))
    q = [(1 - LEVEL) / 2, (1 + LEVEL) / 2]
    lo, hi = np.quantile(ci[0][0], q)
    nm_lo, nm_hi = np.quantile(ci[1][1], q)
    row = dict(
        effect=term.key,
        arcsec=amp * ARCSEC,
        arcsec_ci95=[float(lo) * ARCSEC, float(hi) * ARCSEC],
        nm=amp / k_eff,
        nm_ci95=[float(nm_lo), float(nm_hi)],
    )
    label = getattr(term, "coefficient_label", None)
    if label is not None and m == 1:
        # the coefficient is the physical parameter itself (a delay): its own interval
        name, unit = label
        row[name] = float(beta[0]) * unit
        row[name + "_ci95"] = [float(v) * unit for v in np.quantile(boot_coef[:, 0], q)]
    return row


def _held_at_floor(model: ComplianceModel, design: np.ndarray, y, torque) -> np.ndarray:
    """Which coefficients of `model` the shape constraint holds at its floor on this data (the
    compliances of the segments with an active constraint)."""

    held = np.zeros(model.n_coef, bool)
    shape = structure_shape(model, design, y, torque)
    if shape is None:
        return held
    held[: model.n_segments] = shape.active_segments(np.asarray(model.coef), model.n_segments)
    return held & np.asarray(model.active)


class _Blocks:
    """Moving blocks of `length` samples drawn with replacement until they cover `n` samples,
    `n_bootstrap` times; `sums(v)` is each replicate's sum of `v` (through cumulative sums)."""

    def __init__(self, rng, n: int, length: int, n_bootstrap: int):
        self.length = length
        self.starts = rng.integers(0, n - length + 1, size=(n_bootstrap, -(-n // length)))

    def sums(self, v: np.ndarray) -> np.ndarray:
        c = np.concatenate([np.zeros((1,) + v.shape[1:]), np.cumsum(v, axis=0)])
        return (c[self.starts + self.length] - c[self.starts]).sum(axis=1)


def _gram(design: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The Gram matrix of `[design | y]`, without forming that matrix."""
    p = design.shape[1]
    g = np.empty((p + 1, p + 1))
    g[:p, :p] = design.T @ design
    g[:p, p] = g[p, :p] = y @ design
    g[p, p] = y @ y
    return g


def row_gram(model, rows: RowSource, y: np.ndarray) -> np.ndarray:
    """[`_gram`][] summed over the design's chunks (one for a design in memory)."""
    g = None
    for lo, hi, a in rows.designs(model):
        part = _gram(a, y[lo:hi])
        g = part if g is None else g + part
    return g


def partial_out(model, rows: RowSource, y, others, cols, gram):
    """The columns `cols` of the design and the target `y`, each made orthogonal to the
    columns `others` (the residuals of their least-squares fits on them, Frisch-Waugh-Lovell),
    the design's rows read from `rows` (one chunk for a design in memory).

    `gram` is the Gram matrix of `[design | y]` ([`row_gram`][]). The fits are the corrected
    semi-normal equations on the Jacobi-scaled Gram block of `others` (one refinement step
    with the true residual, its $A^\top r$ summed over a pass), or, above `CSNE_MAX_COND` or
    when Cholesky fails, the QR of those columns folded in chunk by chunk (TSQR).

    **Returns:** `(x_perp, y_perp)`, shapes `(n, len(cols))` and `(n,)`.
    """
    n, m = y.size, len(cols)
    t = np.empty((n, m + 1))

    def target(lo, hi, a):
        return np.concatenate([a[:, cols], y[lo:hi, None]], axis=1)

    if others.size == 0:
        for lo, hi, a in rows.designs(model):
            t[lo:hi] = target(lo, hi, a)
        return t[:, :-1], t[:, -1]
    p = gram.shape[0] - 1
    d = np.sqrt(np.diag(gram)[others])
    d[d == 0] = 1.0
    gs = gram[np.ix_(others, others)] / np.outer(d, d)
    chol = scaled_cho_factor(gs, CSNE_MAX_COND)
    if chol is None:
        k = others.size
        r = np.zeros((0, k + m + 1))
        for lo, hi, a in rows.designs(model):
            block = np.concatenate([a[:, others] / d, target(lo, hi, a)], axis=1)
            r = np.linalg.qr(np.vstack([r, block]), mode="r")
        r_full = np.zeros((k + m + 1, k + m + 1))
        r_full[: r.shape[0]] = r
        r11 = r_full[:k, :k]
        z = scipy.linalg.lstsq(r11, r_full[:k, k:])[0]
        # one refinement step with the true residual (seminormal equations on R), as the
        # Cholesky branch takes: the chunks' R is as accurate as one QR's, its solve is not
        atr = np.zeros((k, m + 1))
        for lo, hi, a in rows.designs(model):
            ao = a[:, others] / d
            atr += ao.T @ (target(lo, hi, a) - ao @ z)
        z += scipy.linalg.lstsq(r11, scipy.linalg.lstsq(r11.T, atr)[0])[0]
        w_o = z / d[:, None]
        for lo, hi, a in rows.designs(model):
            t[lo:hi] = target(lo, hi, a) - a[:, others] @ w_o
        return t[:, :-1], t[:, -1]
    factor = chol[0]
    w = np.zeros((p, m + 1))
    w[others] = (
        scipy.linalg.cho_solve(
            factor, gram[np.ix_(others, np.r_[cols, p])] / d[:, None], check_finite=False
        )
        / d[:, None]
    )
    atr = np.zeros((p, m + 1))
    for lo, hi, a in rows.designs(model):
        atr += a.T @ (target(lo, hi, a) - a @ w)
    w[others] += (
        scipy.linalg.cho_solve(factor, atr[others] / d[:, None], check_finite=False) / d[:, None]
    )
    for lo, hi, a in rows.designs(model):
        t[lo:hi] = target(lo, hi, a) - a @ w
    return t[:, :-1], t[:, -1]
