"""The loop's choice among trials, each rule against a reference known independently.

- Memory states carry across a short gap (dropped samples) and restart at a long one, or where
  recordings meet: counted from the timestamps alone.
- The determined share of a candidate's column is $1 - R^2$ of that column regressed on the
  model's columns with an intercept (closed form by `numpy.linalg.lstsq`).
- Of two tied trials (errors within `min_torque_gain`), one seriously collinear with the
  model's columns (variance inflation over 10) and determined less than half as well as the
  other is not chosen, even with the lower error; otherwise, or when not tied, the error
  chooses.
- An alias of a shortlisted candidate takes no place on the shortlist.
- The shortlist's second round is tried only when no trial of the first qualifies.
- A speed-term trial is replaced by the trial of the reading the current supports.
- A record that moves at one speed is told apart from one whose speed varies: the share of
  moving samples near the median speed, counted on speed profiles built by hand.
"""

import types

import numpy as np
import pytest

from hdjax._errors import ConfigError
from hdjax.discover import DiscoverOptions
from hdjax.discover._aliases import unspanned_share
from hdjax.discover._decision import (
    VELOCITY_KEYS,
    Ranked,
    Trial,
    choose,
    eligible,
    read_speed_trials,
    shortlist_rounds,
    speed_reading,
)
from hdjax.discover._folds import GAP_FACTOR, MEMORY_GAP, memory_starts, segment_starts
from hdjax.discover._pipeline import CrossValidation, pipeline_signals, within_one_se
from hdjax.effects import SEGMENT_START
from hdjax.effects._skew import ONE_SPEED_SHARE, cruise_share

from .discover_data import JOINT, synthetic_recording


def test_memory_carries_across_dropped_samples_and_restarts_at_long_gaps_and_joins():
    t = np.arange(3000) * 1e-3
    t[1000:] += 5e-3  # five samples dropped: a gap, not a restart
    t[2000:] += 0.5  # half a second missing: a restart
    t = np.concatenate([t, t[:500]])  # a second recording appended: time goes back
    gaps = np.flatnonzero(segment_starts(t))
    assert gaps.tolist() == [0, 1000, 2000, 3000]  # every one is a gap for derivatives
    assert 5e-3 > GAP_FACTOR * 1e-3 and 5e-3 < MEMORY_GAP < 0.5
    assert np.flatnonzero(memory_starts(t)).tolist() == [0, 2000, 3000]


def test_the_loop_signals_restart_memory_only_where_memory_starts_says():
    rec = synthetic_recording(0, n=2000)
    keep = np.ones(2000, bool)
    keep[400:405] = False  # five samples dropped
    keep[1200:1300] = False  # 0.2 s missing
    rec = rec.select(keep)
    data = pipeline_signals(rec, JOINT.ratio, 1.0, "difference")
    assert np.flatnonzero(data.starts).tolist() == [0, 400, 1195]  # gaps for the derivatives
    reset = np.asarray(data.sig.extras[SEGMENT_START])
    assert np.flatnonzero(reset).tolist() == [0, 1195]  # the memory runs across the drop


def test_the_determined_share_is_one_minus_r_squared_on_the_model_columns():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(4000, 3)) + 5.0  # the model's columns (a constant offset too)
    for noise in (0.05, 0.5, 3.0):
        c = a @ np.array([1.0, -2.0, 0.5]) + noise * rng.normal(size=4000) + 7.0
        x = np.c_[np.ones(4000), a]
        r = c - x @ np.linalg.lstsq(x, c, rcond=None)[0]
        reference = float(r @ r / np.sum((c - c.mean()) ** 2))
        assert abs(unspanned_share(a, c[:, None]) - reference) < 1e-9
    assert unspanned_share(a, (2.0 * a[:, 1] + 1.0)[:, None]) < 1e-12  # in the span
    assert unspanned_share(a, np.ones((4000, 1))) == 0.0  # constant: nothing determined


def _trial(key, errors, width=1):
    term = types.SimpleNamespace(names=lambda: tuple(f"c{i}" for i in range(width)))
    cand = types.SimpleNamespace(key=key, term=term)
    sq = np.asarray(errors, float)
    cv = CrossValidation(float(np.sqrt(sq.mean())), 1.0, [], [], sq)
    return Trial(cand, 0.5, np.zeros(5), 1.0, None, None, cv)


def test_of_two_trials_alike_on_the_blocks_the_poorly_determined_one_is_not_chosen():
    rng = np.random.default_rng(0)
    blocks = np.repeat(np.arange(20), 50)
    base = rng.uniform(0.5, 1.5, blocks.size)
    speed = _trial("skew:encoders", base)  # the lower error, by a hair
    # the other: block by block alternately above and below it, a hair above over all
    memory = _trial("hysteresis:torque", base + 0.01 * (-1.0) ** blocks + 1e-5)
    current = _trial("none", 4.0 * base).cv
    options = DiscoverOptions()
    share = {"skew:encoders": 0.02, "hysteresis:torque": 0.07}
    notes: list[str] = []
    assert within_one_se(memory.cv, speed.cv, blocks) and memory.cv_rms > speed.cv_rms
    best = choose([speed, memory], current, blocks, options, notes, lambda t: share[t.key])
    assert best.key == "hysteresis:torque"
    assert any("less than half as well" in n for n in notes)
    # not seriously collinear (a share of at least 0.1), however much better the other: the
    # error chooses
    share = {"skew:encoders": 0.2, "hysteresis:torque": 0.9}
    best = choose([speed, memory], current, blocks, options, [], lambda t: share[t.key])
    assert best.key == "skew:encoders"
    # both alike determined (within a factor of two): the error chooses
    share = {"skew:encoders": 0.05, "hysteresis:torque": 0.07}
    best = choose([speed, memory], current, blocks, options, [], lambda t: share[t.key])
    assert best.key == "skew:encoders"
    # without the measure, as before: the lower error
    assert choose([speed, memory], current, blocks, options, []).key == "skew:encoders"
    # not tied: an error higher by more than min_torque_gain, though within one standard
    # error, is not chosen for being better determined
    share = {"skew:encoders": 0.02, "hysteresis:torque": 0.07}
    worse = _trial("hysteresis:torque", 1.1 * base + 0.5 * (-1.0) ** blocks)
    assert worse.cv_rms > (1 + options.min_torque_gain) * speed.cv_rms
    assert within_one_se(worse.cv, speed.cv, blocks)
    best = choose([speed, worse], current, blocks, options, [], lambda t: share[t.key])
    assert best.key == "skew:encoders"
    # and one the blocks tell apart, never
    worse = _trial("hysteresis:torque", 1.5 * base)
    best = choose([speed, worse], current, blocks, options, [], lambda t: share[t.key])
    assert best.key == "skew:encoders"


def _ranked(key):
    cand = types.SimpleNamespace(key=key)
    return Ranked(cand, 0.5, np.zeros(5), True, 1.0, [])


def _keys(rounds):
    return [r.candidate.key for r in rounds]


def test_an_alias_of_a_shortlisted_candidate_takes_no_place():
    ranked = [_ranked(k) for k in ("viscous:omega_m", "skew:encoders", "viscous:omega_l")]
    ranked += [_ranked("hysteresis:torque"), _ranked("coulomb:omega_l")]
    speed = {"viscous:omega_m", "skew:encoders", "viscous:omega_l"}
    aliased = lambda a, b: {a.candidate.key, b.candidate.key} <= speed
    options = DiscoverOptions(n_shortlist=3)
    keys = _keys(eligible(ranked, options, aliased))
    assert keys == ["viscous:omega_m", "hysteresis:torque", "coulomb:omega_l"]
    keys = _keys(eligible(ranked, options))
    assert keys == [*("viscous:omega_m", "skew:encoders", "viscous:omega_l")] + [
        "hysteresis:torque",
        "coulomb:omega_l",
    ]


def test_a_speed_trial_stands_for_the_reading_the_current_supports(monkeypatch):
    import hdjax.discover._decision as decision

    reading = {"viscous:omega_m": "skew:encoders", "skew:encoders": "skew:encoders"}
    monkeypatch.setattr(decision, "_reading", lambda t, data: (reading.get(t.key), ""))
    viscous, memory = _trial("viscous:omega_m", [4.0]), _trial("hysteresis:torque", [3.0])
    skew = _trial("skew:encoders", [1.0])
    data = pipeline_signals(synthetic_recording(0, n=500), JOINT.ratio, 1.0, "difference")
    asked = []

    def try_key(key, answer=skew):
        asked.append(key)
        return answer

    out = read_speed_trials([viscous, memory], data, try_key)
    assert [t.key for t in out] == ["skew:encoders", "hysteresis:torque"] and asked == [skew.key]
    # the reading's own trial refused (it does not qualify): the trial stays
    out = read_speed_trials([viscous, memory], data, lambda key: None)
    assert [t.key for t in out] == ["viscous:omega_m", "hysteresis:torque"]
    # the reading's key already tried (in this round or an earlier one): not tried again
    asked.clear()
    assert read_speed_trials([viscous, skew], data, try_key) == [viscous, skew]
    assert read_speed_trials([viscous], data, try_key, frozenset({skew.key})) == [viscous]
    assert asked == []
    # no current to decide by: the trial stands
    reading.clear()
    assert read_speed_trials([viscous], data, try_key) == [viscous] and asked == []


def test_the_current_tells_skew_from_friction_but_never_one_side_from_the_other(monkeypatch):
    """A friction reading keeps the trial's own side: the current's viscous slope holds the
    friction of both sides, so it cannot move a motor-side trial to the output side."""
    import hdjax.discover._decision as decision

    data = pipeline_signals(synthetic_recording(0, n=500), JOINT.ratio, 1.0, "difference")
    model = types.SimpleNamespace(knots=np.zeros(0), k=np.full(1, 1.0 / 6.7e4))
    per_speed = {"value": 0.0}  # the twist's speed term [N·m per rad/s of link speed]
    monkeypatch.setattr(decision, "_twist_per_speed", lambda m, key: per_speed["value"] / 6.7e4)
    monkeypatch.setattr(decision, "current_viscous_slope", lambda *a: (2.0, 0.1))
    motor, output, skew = (_trial(k, [1.0]) for k in VELOCITY_KEYS[::-1])
    for t in (motor, output, skew):
        object.__setattr__(t, "model", model)  # only its compliance is read (frozen: set once)
    notes: list[str] = []
    # a speed term within the current's friction: friction, on the side the trial has
    assert speed_reading(motor, [output, motor], data, notes) is motor
    assert speed_reading(output, [output, motor], data, notes) is output
    assert speed_reading(skew, [skew, motor, output], data, notes) is output
    assert notes[0].startswith("viscous:omega_m: friction, not skew"), notes
    # one far over it: the skew, from either side
    per_speed["value"] = 60.0
    assert speed_reading(motor, [motor, skew], data, notes) is skew
    assert speed_reading(output, [output, skew], data, notes) is skew


def test_a_second_round_of_the_shortlist_is_tried_only_when_no_trial_of_the_first_qualifies():
    ranked = [_ranked(k) for k in ("a", "b", "c", "d", "e", "f", "g", "h")]
    options = DiscoverOptions(n_shortlist=3)
    current = 10.0
    refused = (1.0 - options.min_torque_gain / 2) ** 2 * current**2  # squared errors
    accepted = (0.5 * current) ** 2
    rounds = []

    def try_round(errors):
        def run(part, trials):
            rounds.append(_keys(part))
            return trials + [_trial(r.candidate.key, [errors[r.candidate.key]] * 4) for r in part]

        return run

    # every trial of the first round refused: the next three are tried, and no third round
    errors = dict.fromkeys("abcdefgh", refused)
    shortlist, trials = shortlist_rounds(ranked, options, current, try_round(errors))
    assert rounds == [["a", "b", "c"], ["d", "e", "f"]]
    assert _keys(shortlist) == list("abcdef") and [t.key for t in trials] == list("abcdef")
    # one of the first round qualifies: the second is not tried
    rounds.clear()
    shortlist_rounds(ranked, options, current, try_round({**errors, "b": accepted}))
    assert rounds == [["a", "b", "c"]]
    # one round only, as before the rounds
    rounds.clear()
    one = DiscoverOptions(n_shortlist=3, n_shortlist_rounds=1)
    shortlist_rounds(ranked, one, current, try_round(errors))
    assert rounds == [["a", "b", "c"]]
    # a round of no candidates, or no round at all, is refused before anything runs
    for bad in ({"n_shortlist": 0}, {"n_shortlist_rounds": 0}, {"n_shortlist_rounds": -2}):
        with pytest.raises(ConfigError, match=next(iter(bad))):
            DiscoverOptions(**bad)
    # fewer eligible than a round: one short round
    rounds.clear()
    shortlist_rounds(ranked[:2], options, current, try_round(errors))
    assert rounds == [["a", "b"]]


def test_a_sweep_at_one_speed_is_told_from_a_varying_speed():
    t = np.arange(0.0, 10.0, 1e-3)
    ramp = np.clip(np.minimum(t - 1.0, 8.0 - t) / 0.5, 0.0, 1.0)  # rest, 0.5 s ramps, cruise
    share, speed = cruise_share(-0.4 * ramp)
    cruising = (ramp >= 0.9).sum() / (ramp > 0.02).sum()  # |w| within 10 % of 0.4 rad/s
    assert speed == 0.4 and abs(share - cruising) < 1e-3 and share > ONE_SPEED_SHARE
    share, _ = cruise_share(0.4 * np.sin(2 * np.pi * 0.2 * t))  # to and fro, speed varies
    assert share < 0.2
    assert cruise_share(np.zeros(100)) == (0.0, 0.0)
