"""`hdjax bench`: a small successful run prints its JSON, timed with the repeats asked for."""

import json
import math
import timeit

from hdjax.cli import main


def test_bench_prints_json_timed_with_the_given_repeats(monkeypatch, capsys):
    real, asked = timeit.repeat, []

    def repeat(stmt, *, number, repeat):  # the real timing, recording what it was asked
        asked.append((number, repeat))
        return real(stmt, number=number, repeat=repeat)

    monkeypatch.setattr(timeit, "repeat", repeat)
    assert main(["bench", "--samples", "1000", "--repeats", "2", "-q"]) == 0
    out, err = capsys.readouterr()
    assert err == ""  # -q
    # the order-6 fit and the sweep: 2 repeats each; the 100-sample estimate: at least 20
    assert asked == [(1, 2), (1, 2), (1, 20)], asked
    result = json.loads(out)
    assert result["n_samples"] == 1000 and result["precision"] == "float64"
    times = ["single_order6_s", "sweep_orders_1_8_s", "estimate_100_ms"]
    times += ["single_order6_first_s", "sweep_orders_1_8_first_s", "estimate_100_first_ms"]
    for key in times:
        assert math.isfinite(result[key]) and result[key] > 0, (key, result[key])
    assert result["ratio"] == result["sweep_orders_1_8_s"] / result["single_order6_s"]
    assert result["target_met"] == (result["ratio"] < result["target_ratio"])
    speedup = result["paper_estimate_100_ms"] / result["estimate_100_ms"]
    assert math.isclose(result["speedup_vs_paper"], speedup, rel_tol=1e-12)
