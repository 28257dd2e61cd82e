"""Benchmark: `hdjax discover --chunk N --select-samples M` on a 10^7-sample Parquet log.

Targets on this 2-core CPU: at most 2 GB peak resident memory and 6 min wall for the command
on 10^7 TRAIN samples (float64 throughout). The effects are chosen on M samples of TRAIN (20
whole blocks, one centred in each twentieth of the log) and the starting and final models are
calibrated again on every row, streamed, so the memory follows M and the chunk, not the log.

What the selection costs is measured first, at 10^6 TRAIN samples: the same command with
`--select-samples` (M/10 samples: the same fraction as at 10^7) against the full in-memory
run on all of them (the reference, timed in the same run): the effects found, the final
coefficients, the TEST errors and the width of each effect's 95 % interval.

The recordings carry three undeclared effects (a motor-angle harmonic of order 2, Coulomb
friction of the link, a temperature drift of the compliance; `benchmarks/bench_discover.py`).

    python benchmarks/bench_discover_select.py [--samples 10000000] [--select 1000000]
"""

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))

from _long_logs import machine  # noqa: E402
from bench_discover_long import _precision, _run_isolated  # noqa: E402

TARGET_GB, TARGET_S = 2.0, 360.0


def _write(path: Path, seed: int, n: int) -> None:
    """A simulated recording with the three effects, written to Parquet in chunks."""
    from bench_discover import EFFECTS

    from hdjax._formats._parquet import ParquetWriter
    from tests.discover_data import synthetic_recording

    cols = synthetic_recording(seed, EFFECTS, n=n).to_numpy()
    names = ["t", "theta_m", "theta_l", "current", "torque", *sorted(set(cols) - {
        "t", "theta_m", "theta_l", "current", "torque"})]  # fmt: skip
    with ParquetWriter(path, names) as w:
        for lo in range(0, n, 1 << 19):
            w.write({k: cols[k][lo : lo + (1 << 19)] for k in names})


def _widths(report: dict) -> dict:
    """Each effect's 95 % interval width (arcsec)."""
    out = {}
    for s in report.get("steps", []):
        ci = (s.get("amplitude") or {}).get("arcsec_ci95")
        if ci:
            out[s["effect"]] = ci[1] - ci[0]
    return out


def _command(d: Path, tmp: Path, out: str, *extra) -> list[str]:
    return [
        sys.executable, "-m", "hdjax", "discover", "--train", str(d / "train.parquet"),
        "--test", str(d / "test.parquet"), "--joint", str(tmp / "joint.toml"),
        "--out", str(d / out), "--no-cache", "--no-figures", *extra,
    ]  # fmt: skip


def _run(cmd, out_dir: Path) -> dict:
    proc, wall, cpu, peak, report = _run_isolated(cmd, out_dir)
    return dict(
        exit_code=proc.returncode,
        stderr_tail=proc.stderr[-800:] if proc.returncode else "",
        wall_s=wall,
        cpu_s=cpu,
        peak_rss_gb=peak,
        effects=report.get("effects"),
        test_rms_before_after=[(report.get(k) or {}).get("rms") for k in ("baseline", "final")],
        selection=report.get("selection"),
        report=report,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=10_000_000)
    ap.add_argument("--select", type=int, default=1_000_000)
    ap.add_argument("--chunk", type=int, default=65536)
    ap.add_argument("--reference-samples", type=int, default=1_000_000)
    args = ap.parse_args()
    from tests.discover_data import JOINT

    out = {"benchmark": "hdjax discover --select-samples on a long Parquet log", **machine()}
    tmp = Path(tempfile.mkdtemp(prefix="hdjax-select-"))
    try:
        (tmp / "joint.toml").write_text(
            f"[joint]\nratio = {JOINT.ratio}\nrated_torque = {JOINT.rated_torque}\n"
        )
        # -- what the selection costs, against the full in-memory run (the reference) -------
        n_ref = args.reference_samples
        m_ref = max(10_000, args.select * n_ref // args.samples)
        ref = tmp / "ref"
        ref.mkdir()
        _write(ref / "train.parquet", 1, n_ref)
        _write(ref / "test.parquet", 2, max(n_ref // 4, 2000))
        full = _run(_command(ref, tmp, "full"), ref / "full")
        sel = _run(
            _command(ref, tmp, "sel", "--chunk", str(args.chunk), "--select-samples", str(m_ref)),
            ref / "sel",
        )
        wf, ws = _widths(full["report"]), _widths(sel["report"])
        same = set(full["effects"] or []) == set(sel["effects"] or [])
        out["cost"] = dict(
            train_samples=n_ref,
            select_samples=m_ref,
            full_in_memory={k: v for k, v in full.items() if k != "report"},
            selected={k: v for k, v in sel.items() if k != "report"},
            same_effects=same,
            precision=(
                _precision(full["report"], sel["report"])
                if full["effects"] == sel["effects"]
                else "effects in another order: coefficients not compared"
            ),
            test_rms_over_full=sel["test_rms_before_after"][1] / full["test_rms_before_after"][1],
            interval_width_over_full=[
                f"{k} {ws[k] / wf[k]:.2f}×" for k in ws if k in wf and wf[k] > 0
            ],
        )
        # -- the long log --------------------------------------------------------------------
        big = tmp / "big"
        big.mkdir()
        _write(big / "train.parquet", 1, args.samples)
        _write(big / "test.parquet", 2, max(n_ref // 4, 2000))
        run = _run(
            _command(
                big, tmp, "out", "--chunk", str(args.chunk), "--select-samples", str(args.select)
            ),  # fmt: skip
            big / "out",
        )
        run.pop("report")
        out.update(
            train_samples=args.samples,
            select_samples=args.select,
            chunk=args.chunk,
            **run,
            reference={"full_in_memory_wall_s_at_reference_samples": full["wall_s"]},
            target_peak_rss_gb=TARGET_GB,
            target_seconds=TARGET_S,
            target_met=bool(
                run["exit_code"] == 0
                and run["peak_rss_gb"] <= TARGET_GB
                and run["wall_s"] <= TARGET_S
            ),  # fmt: skip
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
