"""SIGINT and SIGTERM at any moment: exit code 130 or 143, one line on stderr, no partial result
(a sweep keeps its finished members). Real processes, since signals are the point; few of them."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .helpers import tiny_config

REPO = Path(__file__).resolve().parents[1]

CONFIG = tiny_config(
    "sig",
    'kind = "synthetic"\nn_samples = 4000\n',
    "figures = false\ntiming = true\ntiming_repeats = 1000000\n",
)

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/maps").exists(), reason="watches /proc/PID/maps for start-up"
)


@pytest.fixture(autouse=True)
def _terminal_signals():
    """The in-process tests below run as at a terminal too: SIGINT raises KeyboardInterrupt
    and SIGTERM ends the process, whatever the test runner inherited."""
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    yield
    for s, h in old.items():
        signal.signal(s, h)


def _start(tmp_path, *args, ignored=()):
    """`hdjax` as a user at a terminal starts it: SIGINT and SIGTERM at their defaults, whatever
    the test runner inherited (a background job of a shell starts with SIGINT ignored, and so
    would every command it starts); the signals in `ignored` ignored instead."""

    def defaults():
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_IGN if s in ignored else signal.SIG_DFL)

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen(
        [sys.executable, "-m", "hdjax", *args],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=defaults,
    )


def _wait_for(cond, proc, timeout=120.0):
    t0 = time.monotonic()
    while not cond():
        assert proc.poll() is None, f"ended early: {proc.communicate()}"
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.005)


def _loading_jax(proc) -> bool:
    """The process is importing JAX (its compiled extension is mapped): start-up."""
    try:
        maps = Path(f"/proc/{proc.pid}/maps").read_text()
    except OSError:
        return False
    return "jaxlib" in maps


def _finish(proc, sig):
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        # the signal was lost: the test fails, and the command must not run on after it (a
        # million timing repeats at full load) nor leave its pipes for a later test's collector
        proc.kill()
        proc.communicate()
        raise
    return proc.returncode, err


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_during_start_up(tmp_path, sig, code):
    (tmp_path / "cfg.toml").write_text(CONFIG)
    proc = _start(tmp_path, "run", "cfg.toml", "--out", "o", "-q")
    _wait_for(lambda: _loading_jax(proc), proc)
    rc, err = _finish(proc, sig)
    assert rc == code, err
    assert err.strip().count("\n") == 0 and "Traceback" not in err, err
    assert "interrupted" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.toml"]


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_mid_run_removes_the_staging_folder(tmp_path, sig, code):
    (tmp_path / "cfg.toml").write_text(CONFIG)
    proc = _start(tmp_path, "run", "cfg.toml", "--out", "o")
    staging = tmp_path / f".o.tmp-{proc.pid}"
    # the timing stage (a million repeats) keeps the run busy once it has started writing
    _wait_for(lambda: staging.exists(), proc)
    _wait_for(
        lambda: False if proc.stderr is None else "estimating torque with the model" in _peek(proc),
        proc,
    )
    rc, err = _finish(proc, sig)
    assert rc == code, err
    assert err.strip().splitlines()[-1] == f"hdjax: interrupted ({sig.name})", err
    assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.toml"]


def test_a_command_started_with_sigint_ignored_keeps_ignoring_it(tmp_path):
    # a background job of a shell, or `nohup`: Ctrl-C at the terminal is not meant for it
    (tmp_path / "cfg.toml").write_text(CONFIG)
    proc = _start(tmp_path, "run", "cfg.toml", "--out", "o", ignored=(signal.SIGINT,))
    _wait_for(
        lambda: False if proc.stderr is None else "estimating torque with the model" in _peek(proc),
        proc,
    )
    proc.send_signal(signal.SIGINT)
    time.sleep(2.0)
    assert proc.poll() is None, proc.communicate()  # still running
    rc, err = _finish(proc, signal.SIGTERM)  # SIGTERM still ends it cleanly
    assert rc == 143, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.toml"]


_seen: dict[int, str] = {}


def _peek(proc) -> str:
    """Progress lines so far (read line by line without blocking past one line)."""
    import select

    text = _seen.setdefault(proc.pid, "")
    while select.select([proc.stderr], [], [], 0)[0]:
        line = proc.stderr.readline()
        if not line:
            break
        text += line
    _seen[proc.pid] = text
    return text


def test_sigterm_mid_sweep_keeps_finished_members(tmp_path):
    cfg = CONFIG.replace("n_samples = 4000", "n_samples = 20000").replace(
        "timing = true", "timing = false"
    )
    (tmp_path / "cfg.toml").write_text(cfg)
    values = "1,3,5,7,9,11,13,15,17,19"
    proc = _start(
        tmp_path,
        "sweep",
        "cfg.toml",
        "--out",
        "sw",
        "-q",
        "--setting",
        "model.n_segments",
        "--values",
        values,
    )
    members = tmp_path / "sw.partial" / "members"
    _wait_for(lambda: members.is_dir() and any(members.glob("*.json")), proc)
    rc, err = _finish(proc, signal.SIGTERM)
    assert rc == 143, err
    assert err.strip() == "hdjax: interrupted (SIGTERM)"
    assert not (tmp_path / "sw").exists()
    kept = sorted(p.name for p in members.glob("*.json"))
    assert 1 <= len(kept) < 10 and kept[0].startswith("000_")
    leftovers = [p for p in tmp_path.rglob("*") if ".tmp" in p.name]
    assert not leftovers


def test_a_swallowed_interrupt_still_ends_the_command(tmp_path, monkeypatch, capsys):
    """Python drops an exception raised inside some callbacks (JAX's garbage-collection callback
    is one); the signal is remembered and ends the command at its next step, with no result."""
    from hdjax.cli import main
    from hdjax.pipelines import internal as _pipeline

    (tmp_path / "cfg.toml").write_text(CONFIG.replace("timing = true", "timing = false"))
    real = _pipeline.calibrate

    def calibrate_with_a_swallowed_ctrl_c(*a, **k):
        try:
            signal.raise_signal(signal.SIGINT)
        except BaseException:  # what a callback that swallows exceptions does
            pass
        return real(*a, **k)

    monkeypatch.setattr(_pipeline, "calibrate", calibrate_with_a_swallowed_ctrl_c)
    before = signal.getsignal(signal.SIGINT)
    code = main(["run", str(tmp_path / "cfg.toml"), "--out", str(tmp_path / "o"), "-q"])
    assert code == 130
    assert capsys.readouterr().err.strip() == "hdjax: interrupted (SIGINT)"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.toml"]
    assert signal.getsignal(signal.SIGINT) is before  # the handlers are restored
    from hdjax._interrupts import pending

    assert pending() is None  # and the next command in this process starts clean


def test_an_interrupt_that_surfaces_as_another_error_still_ends_the_command(
    tmp_path, monkeypatch, capsys
):
    """A signal that lands inside C code (numpy's dtype hook, called by JAX) can surface as a
    `SystemError` ("returned a result with an exception set") instead of the interrupt: the
    command still ends as interrupted, with its exit code and no traceback or result."""
    from hdjax.cli import main
    from hdjax.pipelines import internal as _pipeline

    (tmp_path / "cfg.toml").write_text(CONFIG.replace("timing = true", "timing = false"))

    def calibrate_cut_inside_c_code(*a, **k):
        try:
            signal.raise_signal(signal.SIGTERM)
        except BaseException as err:
            raise SystemError("<function> returned a result with an exception set") from err

    monkeypatch.setattr(_pipeline, "calibrate", calibrate_cut_inside_c_code)
    code = main(["run", str(tmp_path / "cfg.toml"), "--out", str(tmp_path / "o"), "-q"])
    assert code == 143
    assert capsys.readouterr().err.strip() == "hdjax: interrupted (SIGTERM)"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.toml"]


def test_a_swallowed_interrupt_ends_the_timing_loop():
    """The timing stage repeats one call up to a million times; a signal swallowed inside it
    (as JAX's gc callback does) must end the loop, not leave the command running for minutes."""
    from hdjax import _interrupts
    from hdjax.pipelines._paper import time_per_100

    from .helpers import sim_recording

    rec = sim_recording(200, seed=1)
    calls = []

    def fn(r):
        calls.append(1)
        if len(calls) == 3:
            try:
                signal.raise_signal(signal.SIGINT)
            except BaseException:  # what a callback that swallows exceptions does
                pass
        return r.n_samples

    with pytest.raises(_interrupts.Interrupted), _interrupts.handling():
        time_per_100(fn, rec, 1_000_000)
    assert len(calls) == 3


def test_an_interrupt_swallowed_by_a_gc_callback_prints_no_traceback(capsys, monkeypatch):
    """Python reports an exception raised inside a garbage-collection callback (as JAX's is) to
    `sys.unraisablehook`, which prints "Exception ignored in ..." and a traceback; while a
    command runs, the interrupt is kept quiet (and remembered) and anything else passed on."""
    import gc

    from hdjax import _interrupts

    seen = []  # the hook in place before the command: Python's printer, here a recorder
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(type(u.exc_value)))

    def ctrl_c(phase, info):
        if phase == "start":
            signal.raise_signal(signal.SIGINT)

    def broken(phase, info):
        if phase == "start":
            raise ValueError("a real bug in a callback")

    with pytest.raises(_interrupts.Interrupted), _interrupts.handling():
        for callback in (ctrl_c, broken):
            gc.callbacks.append(callback)
            try:
                gc.collect()
            finally:
                gc.callbacks.remove(callback)
        assert _interrupts.pending() == signal.SIGINT
        assert seen == [ValueError]
        _interrupts.check()
    assert capsys.readouterr().err == ""
