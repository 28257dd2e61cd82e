"""An experiment's files as streams: `[fit] chunk > 0` with `[data] kind = "files"`.

[`build_streamed_dataset`][] describes the same calibration and test parts as
[`hdjax.pipelines.build_dataset`][] (the last `split` of each training file as its test part, or
every k-th block with `split_blocks`, the first `settle` seconds of each part left out), but as
[`hdjax.compliance.RecordingStream`][]s that read the files chunk by chunk through the
format readers ([`hdjax._formats.iter_recordings`][]), so no whole recording is ever in memory:
memory is bounded by the chunk. The rows a part keeps are regrouped into chunks of exactly
`chunk` samples (the last one shorter), so the concatenated chunks are the part that
`build_dataset` would have loaded.

One pass at build time counts each part's samples and gathers what the checks need without
holding the data: the largest |current| (for `current_scale = "auto"`) and the sums of a
straight-line fit of the motor against the output angle (the angle-ratio check).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .._errors import ConfigError, DataError
from .._formats import count_rows, iter_recordings
from .._joint import Joint
from ..compliance import RecordingStream
from ..compliance.internal import recording_arrays, recording_from_arrays
from ..config import column_map
from ..config.internal import resolve_path
from ..modelfile.internal import ratio_mismatch


@dataclasses.dataclass
class PartStats:
    """What one pass over a part knows: its samples, the peak |current|, the angle fit."""

    source: str
    n: int = 0
    peak_current: float = 0.0
    theta_l_min: float = np.inf
    theta_l_max: float = -np.inf
    finite: bool = True
    origin: tuple[float, float] | None = None
    sums: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(4))

    def add(self, cols: dict[str, np.ndarray]) -> None:
        x, y = cols["theta_l"], cols["theta_m"]
        self.n += x.shape[0]
        self.peak_current = max(self.peak_current, float(np.max(np.abs(cols["current"]))))
        self.finite = self.finite and bool(np.isfinite(x).all() and np.isfinite(y).all())
        if not self.finite:
            return
        self.theta_l_min = min(self.theta_l_min, float(x.min()))
        self.theta_l_max = max(self.theta_l_max, float(x.max()))
        if self.origin is None:  # centred sums: no cancellation for multi-turn angles
            self.origin = (float(x[0]), float(y[0]))
        dx, dy = x - self.origin[0], y - self.origin[1]
        self.sums += [dx.sum(), dy.sum(), dx @ dx, dx @ dy]

    def slope(self) -> float:
        """The least-squares slope of theta_m against theta_l (`np.polyfit(.., 1)[0]`)."""
        sx, sy, sxx, sxy = self.sums
        return float((self.n * sxy - sx * sy) / (self.n * sxx - sx * sx))

    def ratio_mismatch(self, ratio: float) -> str:
        """As `ratio_mismatch` (the saved model's check) on the whole part."""
        if not (self.finite and self.theta_l_max - self.theta_l_min > 0.5):
            return ""
        # the same rule on a two-sample stand-in with the part's slope and spread
        slope = self.slope()
        stand_in = _Angles(np.array([0.0, 1.0]), np.array([0.0, slope]), self.source)
        return ratio_mismatch(ratio, stand_in)


@dataclasses.dataclass(frozen=True)
class _Angles:
    theta_l: np.ndarray
    theta_m: np.ndarray
    source: str


class PartStream(RecordingStream):
    """A [`hdjax.compliance.RecordingStream`][] that knows its size from the build pass:
    `n_samples`, `peak_current` and the `chunk` it is read in."""

    def __init__(self, opener, label: str, chunk: int, stats: list[PartStats]):
        super().__init__(opener, label)
        self.chunk = chunk
        self.n_samples = sum(s.n for s in stats)
        self.peak_current = max(s.peak_current for s in stats)


@dataclasses.dataclass
class StreamedDataset:
    """Calibration and test parts of an experiment as streams (see the module docstring).

    **Fields:** `train` (one [`hdjax.compliance.RecordingStream`][] of every calibration part),
    `test` (name -> stream), `joint`, `provenance`, `reference`, `chunk`, and `stats`
    (source label -> `PartStats` of each part).
    """

    train: RecordingStream
    test: dict[str, RecordingStream]
    joint: Joint
    provenance: list[str]
    chunk: int
    train_stats: list[PartStats]
    test_stats: dict[str, PartStats]
    reference: dict = dataclasses.field(default_factory=lambda: {"kind": "column"})

    @property
    def n_train(self) -> int:
        return sum(s.n for s in self.train_stats)

    def ratio_mismatches(self) -> list[tuple[str, str]]:
        """`(source, why)` of every part, as `check_angles` asks of in-memory recordings."""
        parts = self.train_stats + list(self.test_stats.values())
        return [(s.source, s.ratio_mismatch(self.joint.ratio)) for s in parts]


def streams(exp) -> bool:
    """Whether the experiment is run from streams (`[fit] chunk > 0` on files)."""
    return bool(exp["fit"].get("chunk")) and exp["data"]["kind"] == "files"


# ---------------------------------------------------------------------------------------------
# A part of a file: the rows it keeps, regrouped into chunks


def _columns(rec) -> dict[str, np.ndarray]:
    # t, angles, current, torque, x:extras (a missing torque: one line)
    return recording_arrays(rec)


def _regroup(tables, chunk: int):
    """Tables of any sizes -> tables of exactly `chunk` rows (the last one 2..chunk rows)."""
    held, n_held = [], 0
    for cols in tables:
        n = cols["t"].shape[0]
        if n == 0:
            continue
        held.append(cols)
        n_held += n
        while n_held >= chunk + 2:  # always keep two rows back: a chunk needs two samples
            joined = {k: np.concatenate([c[k] for c in held]) for k in held[0]}
            yield {k: v[:chunk] for k, v in joined.items()}
            held, n_held = [{k: v[chunk:] for k, v in joined.items()}], n_held - chunk
    if not held:
        return
    joined = {k: np.concatenate([c[k] for c in held]) for k in held[0]}
    if n_held > chunk:  # chunk + 1 rows: two chunks of at least two rows
        yield {k: v[: chunk - 1] for k, v in joined.items()}
        joined = {k: v[chunk - 1 :] for k, v in joined.items()}
    yield joined


def _part_tables(path, cmap, chunk, check_units, keep, settle: float):
    """The rows of `path` that `keep(start, n)` selects, without the first `settle` seconds."""
    start, t0 = 0, None
    for rec in iter_recordings(path, cmap, chunk=chunk, check_units=check_units):
        cols = _columns(rec)
        n = cols["t"].shape[0]
        mask = keep(start, n)
        start += n
        if settle > 0:
            sel = np.flatnonzero(mask)
            if t0 is None and sel.size:
                t0 = cols["t"][sel[0]]
            if t0 is not None:
                mask[sel] = cols["t"][sel] >= t0 + settle
        yield {k: v[mask] for k, v in cols.items()}


def _part_stream(path, cmap, chunk, check_units, keep, settle, label) -> RecordingStream:
    def chunks():
        for cols in _regroup(_part_tables(path, cmap, chunk, check_units, keep, settle), chunk):
            yield recording_from_arrays(cols, str(path))

    return RecordingStream(lambda: iter([chunks()]), label)


def _joined(streams_: list[RecordingStream]) -> RecordingStream:
    label = ", ".join(s.label for s in streams_)
    return RecordingStream(lambda: (c for s in streams_ for c in s), label)


def _keep_all(start, n):
    return np.ones(n, bool)


def _stats(stream: RecordingStream, source: str, settle: float) -> PartStats:
    st = PartStats(source)
    for chunks in stream:
        for c in chunks:
            st.add({k: np.asarray(getattr(c, k)) for k in ("theta_l", "theta_m", "current")})
    if st.n < 2:
        why = f"[data] settle = {settle:g} s leaves" if settle > 0 else "the part has"
        raise ConfigError(f"{why} fewer than 2 samples of {source}")
    return st


# ---------------------------------------------------------------------------------------------
# The experiment's parts


def build_streamed_dataset(exp, joint: Joint, say) -> StreamedDataset:
    """The [`StreamedDataset`][] of an experiment whose `[fit] chunk` streams its files.

    **Raises:** [`hdjax.ConfigError`][] for settings that need whole recordings (a wrench
    reference), [`hdjax.DataError`][] for a missing file or column.
    """
    data = exp["data"]
    chunk = int(exp["fit"]["chunk"])
    if data["reference"]["kind"] != "column":
        raise ConfigError(
            f"[fit] chunk = {chunk} streams the files, but [data.reference] kind = "
            f'"{data["reference"]["kind"]}" needs whole recordings; set chunk = 0'
        )
    cmap = column_map(data)
    units = data["check_units"]
    settle = float(data["settle"])
    split, block = data["split"], data["split_blocks"]
    train, test, prov, train_stats, test_stats = [], {}, [], [], {}

    def add_test(label, stream, source):
        name = _unique(label, test)
        test_stats[name] = _stats(stream, source, settle)
        test[name] = PartStream(stream.opener, stream.label, chunk, [test_stats[name]])
        return name

    for name in data["train"]:
        path = _checked(resolve_path(exp, name), data["format"])
        say(f"reading {path} in chunks of {chunk} samples")
        if split > 0 and not data["test"]:
            n = count_rows(path, cmap, chunk=chunk)
            held = _held(n, split, block, str(path))
            a = _part_stream(path, cmap, chunk, units, lambda s, k: ~held(s, k), settle, str(path))
            b = _part_stream(path, cmap, chunk, units, held, settle, f"{path} (test)")
            train.append(a)
            train_stats.append(_stats(a, str(path), settle))
            t = add_test(path.stem, b, f"{path} (test part)")
            prov.append(
                f"{path}: {train_stats[-1].n} calibration + {test_stats[t].n} test samples, "
                f"read in chunks of {chunk}"
            )
        else:
            a = _part_stream(path, cmap, chunk, units, _keep_all, settle, str(path))
            train.append(a)
            train_stats.append(_stats(a, str(path), settle))
            n = train_stats[-1].n
            prov.append(f"{path}: {n} calibration samples, read in chunks of {chunk}")
    tests = data["test"]
    items = tests.items() if isinstance(tests, dict) else ((Path(t).stem, t) for t in tests)
    for label, name in items:
        path = _checked(resolve_path(exp, name), data["format"])
        b = _part_stream(path, cmap, chunk, units, _keep_all, settle, str(path))
        t = add_test(label, b, str(path))
        prov.append(f"{path}: {test_stats[t].n} test samples ({label}), read in chunks of {chunk}")
    if settle > 0:
        prov.append(f"first {settle:g} s of every recording left out (start-up transient)")
    joined = _joined(train)
    return StreamedDataset(
        joint=joint,
        chunk=chunk,
        train=PartStream(joined.opener, joined.label, chunk, train_stats),
        test=test,
        provenance=prov,
        train_stats=train_stats,
        test_stats=test_stats,
    )


def _checked(path: Path, fmt: str) -> Path:
    suffix = {"csv": ".csv", "npz": ".npz"}.get(fmt)
    if suffix and path.suffix.lower() != suffix:
        raise ConfigError(
            f'[data] format = "{fmt}" but {path} has the suffix {path.suffix!r}; streamed files '
            'are read by their suffix: rename the file or set format = "auto"'
        )
    return path


def _held(n: int, fraction: float, block: int, source: str):
    """`held(start, k)`: the test rows among `start .. start + k` (as `_dataset._split`)."""
    if not block:
        first = int(round(n * (1.0 - fraction)))  # as Recording.split(1 - fraction)
        if first < 2 or n - first < 2:
            raise DataError(
                f"cannot split {n} samples at {1.0 - fraction}: each part needs at least 2"
            )
        return lambda s, k: np.arange(s, s + k) >= first
    every = max(2, round(1.0 / fraction))
    held = lambda s, k: (np.arange(s, s + k) // block) % every == every - 1
    n_held = int(held(0, n).sum())
    if n_held < 2 or n - n_held < 2:
        raise ConfigError(
            f"{source}: split_blocks = {block} leaves too few samples in one part "
            f"({n} samples); use smaller blocks"
        )
    return held


def _unique(label: str, taken) -> str:
    out, i = label, 2
    while out in taken:
        out, i = f"{label}_{i}", i + 1
    return out
