"""`hdjax fleet MANIFEST.toml --out DIR`: every (joint, log) task of a manifest, on Dask."""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path

from .._errors import ConfigError
from .._formats import require
from .._lazy import dask_distributed
from ..fleet import drift_figure, load_manifest, run_task, write_table
from ..report import markdown_table, read_marker
from ._common import add_command, add_flag, add_quiet, resumable_result

HELP = "run calibrate + discover (or estimate) on every joint-log of a manifest, on Dask"
EXAMPLE = """\
example:
  hdjax fleet cell.toml --out runs/cell
  hdjax fleet cell.toml --out runs/cell --workers 4
  hdjax fleet cell.toml --out runs/cell --scheduler tcp://10.0.0.5:8786
  hdjax fleet cell.toml --out runs/cell --scheduler tcp://10.0.0.5:8786 --connect-timeout 5

Each (joint, log) pair is one task on a Dask cluster: by default a local cluster with one
single-threaded worker process per core, each bound to its own core (--no-pin: not bound), or
the existing cluster at --scheduler; the longest logs start first. Results stream
into OUT.partial/ as tasks finish (tasks/*.json and results.parquet, a row per joint-log); OUT
appears when all tasks have run, with results.parquet, report.md and figures/drift_JOINT.png.
Finished tasks are skipped when the command is run again (after an interruption, or with
--overwrite after adding logs to the manifest); a failing task is reported with its one-line
error and does not stop the others. Exit code 0 when every task succeeded, 1 when some failed.
"""

WORKER_ENV = {
    # one core per worker: XLA, OpenMP and BLAS would otherwise each start a thread per core
    # (XLA has no flag for its other threads, JAX's dispatch and XLA's compiler; see _pin)
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


def worker_env() -> dict[str, str]:
    """The local workers' environment: `WORKER_ENV`, its XLA flag appended to the caller's own
    `XLA_FLAGS` (which the workers would otherwise lose, and compile differently)."""
    own = os.environ.get("XLA_FLAGS", "").split()
    flags = own + [f for f in WORKER_ENV["XLA_FLAGS"].split() if f not in own]
    return {**WORKER_ENV, "XLA_FLAGS": " ".join(flags)}


CONNECT_TIMEOUT = 20.0

# a scheduler address: [scheme://]host:port, with Dask's comm schemes
_SCHEMES = ("tcp", "tls", "ucx", "ws", "wss")
_ADDRESS = re.compile(
    r"(?:(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://)?(\[[^\]]+\]|[^\s:/\[\]]+):\d{1,5}"
)
"""Seconds `--scheduler` is tried before the command gives up (`--connect-timeout`)."""


def add_parser(sub) -> None:
    p = add_command(sub, "fleet", HELP, EXAMPLE)
    p.add_argument("manifest", help="the fleet manifest (TOML: [fleet], [model], [[joints]])")
    p.add_argument("--out", required=True, help="the result folder")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="address of a running Dask scheduler, tcp://HOST:PORT (default: a local cluster)",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        metavar="SECONDS",
        help=f"how long to try to reach --scheduler (default {CONNECT_TIMEOUT:g} s)",
    )
    p.add_argument(
        "--workers", type=int, help="worker processes of the local cluster (default: one per core)"
    )
    add_flag(p, "--overwrite", "replace an earlier fleet result")
    add_flag(p, "--fresh", "rerun tasks that finished before")
    add_flag(p, "--no-pin", "do not bind each worker of the local cluster to its own core")
    add_quiet(p, "no progress bar on stderr")


class ProgressBar:
    """`[#####-----] 5/16 done, 2 running, 1 failed` on stderr (redrawn in place on a terminal)."""

    def __init__(self, total: int, quiet: bool, stream=None):
        self.total, self.quiet = total, quiet
        self.stream = stream or sys.stderr
        self.tty = getattr(self.stream, "isatty", lambda: False)()
        self.last = ""

    def __call__(self, done: int, running: int, failed: int) -> None:
        if self.quiet:
            return
        width = 24
        fill = int(width * done / self.total) if self.total else width
        line = (
            f"[{'#' * fill}{'-' * (width - fill)}] {done}/{self.total} done, {running} running, "
            f"{failed} failed"
        )
        if line == self.last:
            return
        self.last = line
        print(("\r" if self.tty else "") + line, end="" if self.tty else "\n", file=self.stream)
        self.stream.flush()

    def close(self):
        if self.tty and not self.quiet and self.last:
            print(file=self.stream)


def _not_an_address(address: str, why: str) -> ConfigError:
    return ConfigError(
        f"--scheduler {address!r} is not a scheduler address ({why}); give it as "
        "tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786"
    )


def _check_address(address: str) -> None:
    """Check `--scheduler` in plain Python, before Dask starts its event loop."""
    m = _ADDRESS.fullmatch(address)
    if m is None:
        raise _not_an_address(address, "expected [scheme://]HOST:PORT")
    if m["scheme"] is not None and m["scheme"] not in _SCHEMES:
        raise _not_an_address(address, f"unknown scheme {m['scheme']!r}; one of {_SCHEMES}")


def _client(args, n_tasks: int):
    """A Dask client: of the cluster at --scheduler, or of a new local cluster."""
    require("distributed", "fleet")
    import logging

    distributed = dask_distributed()
    Client, LocalCluster = distributed.Client, distributed.LocalCluster

    if args.scheduler:
        _check_address(args.scheduler)
        timeout = args.connect_timeout or CONNECT_TIMEOUT
        try:
            return Client(args.scheduler, timeout=f"{timeout}s"), None
        except ValueError as err:  # an address Dask still refuses
            raise _not_an_address(args.scheduler, " ".join(str(err).split())) from None
        except (OSError, TimeoutError) as err:
            raise ConfigError(
                f"--scheduler {args.scheduler}: cannot connect ({' '.join(str(err).split())}); "
                "check the address and that the scheduler is running, raise --connect-timeout, "
                "or leave --scheduler out for a local cluster"
            ) from None
    n = args.workers or os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=min(n, max(1, n_tasks)),
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=logging.ERROR,
        env=worker_env(),
    )
    client = Client(cluster)
    if not args.no_pin:
        _pin(client)
    return client, cluster


def _pin_process(core: int) -> int:
    """Bind every thread of this process (and so the threads it starts) to `core`."""
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), {core})
        except OSError:  # a thread that ended meanwhile
            pass
    return core


def _pin(client) -> None:
    """One core per local worker: worker i on the i-th core this process may use.

    A single-threaded worker still runs JAX's dispatch and XLA's compiler threads beside its
    task; unbound, one worker spreads over more than one core, and two workers on two cores
    crowd each other. Bound, every worker has one core whatever the number of workers.
    Skipped where the system cannot bind threads or there are more workers than cores.
    """
    if not hasattr(os, "sched_setaffinity") or not os.path.isdir("/proc/self/task"):
        return
    cores = sorted(os.sched_getaffinity(0))
    workers = sorted(client.scheduler_info().get("workers", {}))
    if len(workers) > len(cores):
        return
    for core, addr in zip(cores, workers):
        client.run(_pin_process, core, workers=[addr])


def _cached(folder: Path, task_id: str) -> dict | None:
    p = folder / "tasks" / f"{task_id}.json"
    try:
        row = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return row if row.get("status") == "ok" and row.get("task_id") == task_id else None


def _check_cluster_options(args) -> None:
    """Refuse cluster options that contradict each other or make no sense."""
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    if args.scheduler is not None:
        if not args.scheduler.strip():
            raise ConfigError("--scheduler is empty; give the address as tcp://HOST:PORT")
        if args.workers is not None:
            raise ConfigError(
                "--workers sets the size of the local cluster; with --scheduler the cluster's "
                "own workers run the tasks: drop --workers (or --scheduler)"
            )
    if args.connect_timeout is not None:
        if args.scheduler is None:
            raise ConfigError("--connect-timeout applies to --scheduler only; drop it")
        if not args.connect_timeout > 0 or args.connect_timeout == float("inf"):
            raise ConfigError(
                f"--connect-timeout must be a positive number of seconds, got "
                f"{args.connect_timeout:g}"
            )


def command(args, parser) -> int:
    import jax

    _check_cluster_options(args)
    man = load_manifest(args.manifest)
    out = Path(args.out)
    inputs = [man.path] + [Path(t.log) for t in man.tasks]
    inputs += [Path(j["model"]) for j in man.joints.values() if j["model"]]
    rd = resumable_result(out, overwrite=args.overwrite, inputs=inputs, command="fleet")
    try:
        ordered = _collect(args, man, out, rd.staging, rd, run_task, write_table, read_marker, jax)
    except BaseException:
        rd.abort()  # keeps the finished tasks in OUT.partial for the next run
        raise
    n_failed = sum(r["status"] != "ok" for r in ordered)
    for r in ordered:
        if r["status"] != "ok":
            print(f"hdjax fleet: {r['joint']} {r['log']}: {r['error']}", file=sys.stderr)
    print(f"{len(ordered) - n_failed} of {len(ordered)} tasks ok, {n_failed} failed; wrote {out}")
    return 1 if n_failed else 0


def _collect(args, man, out, staging, rd, run_task, write_table, read_marker, jax) -> list[dict]:
    """Reuse finished tasks, run the others, write the table and the report, commit."""
    rows: dict[str, dict] = {}
    if not args.fresh:
        sources = [staging] + ([out] if out.is_dir() and read_marker(out) else [])
        for t in man.tasks:
            for src in sources:
                row = _cached(src, t.task_id)
                if row is not None:
                    rows[t.task_id] = row
                    if src != staging:
                        rd.write_json(f"tasks/{t.task_id}.json", row)
                    break
    todo = [t for t in man.tasks if t.task_id not in rows]
    bar = ProgressBar(len(man.tasks), args.quiet)
    if rows and not args.quiet:
        print(
            f"hdjax fleet: {len(rows)} of {len(man.tasks)} tasks finished before; skipped",
            file=sys.stderr,
        )
    if todo:
        client, cluster = _client(args, len(todo))
        try:
            _run(client, todo, rows, rd, bar, jax.config.jax_compilation_cache_dir, run_task,
                 write_table)  # fmt: skip
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    bar.close()
    ordered = [rows[t.task_id] for t in man.tasks]
    write_table(ordered, rd.path("results.parquet"))
    _report(man, ordered, rd)
    rd.commit()
    return ordered


def _run(client, todo, rows, rd, bar, cache_dir, run_task, write_table) -> int:
    """Submit every task, collect rows as they finish (each saved at once), redraw the bar."""
    as_completed = dask_distributed().as_completed

    futures = {}
    # longest first (by log size): a long task started last would leave the other workers
    # idle at the end; the priority keeps that order in the scheduler's queue
    for rank, t in enumerate(sorted(todo, key=_log_size, reverse=True)):
        fut = client.submit(
            run_task,
            t.spec,
            cache_dir,
            key=f"hdjax-fleet-{t.task_id}",
            pure=False,
            priority=len(todo) - rank,
        )
        futures[fut] = t
    done = failed = 0
    bar(len(rows), min(len(todo), _n_workers(client)), 0)
    last_table = 0.0
    for fut in as_completed(list(futures)):
        t = futures[fut]
        try:
            row = fut.result()
        except Exception as err:  # noqa: BLE001 - a worker lost or killed: the task failed
            row = {
                "joint": t.joint, "log": t.log, "date": t.date, "task": t.spec["task"],
                "status": "failed", "error": f"{type(err).__name__}: {' '.join(str(err).split())}",
            }  # fmt: skip
        row["task_id"] = t.task_id
        rows[t.task_id] = row
        rd.write_json(f"tasks/{t.task_id}.json", row)
        done += 1
        failed += row["status"] != "ok"
        if time.monotonic() - last_table > 2.0:  # the table so far, for a look while it runs
            write_table(list(rows.values()), rd.path("results.parquet"))
            last_table = time.monotonic()
        bar(len(rows), _running(client, futures), failed)
    return failed


def _log_size(task) -> int:
    try:
        return Path(task.log).stat().st_size
    except OSError:  # a missing log fails in its task, with its one-line error
        return 0


def _n_workers(client) -> int:
    try:
        return max(1, len(client.scheduler_info().get("workers", {})))
    except Exception:  # noqa: BLE001 - only for the progress line
        return 1


def _running(client, futures) -> int:
    """Tasks executing now. Dask's `processing()` lists every task a worker holds, the ones
    queued behind its threads too: a worker runs at most one task per thread."""
    try:
        held, threads = client.processing(), client.nthreads()
    except Exception:  # noqa: BLE001 - only for the progress line
        return 0
    pending = {f.key for f in futures if not f.done()}
    return sum(
        min(sum(k in pending for k in keys), threads.get(worker, 1))
        for worker, keys in held.items()
    )


def _report(man, rows, rd) -> None:
    lines = [
        f"# Fleet {man.settings['name']}",
        "",
        f"Manifest `{man.path.name}`: {len(man.joints)} joints, {len(rows)} joint-logs, task "
        f"`{man.settings['task']}`. Every row is in `results.parquet` (coefficients as `coef:NAME` "
        "columns, effects and their amplitudes as lists).",
        "",
    ]
    for name in man.joints:
        jr = sorted((r for r in rows if r["joint"] == name), key=lambda r: r["date"])
        png = f"figures/drift_{''.join(c if c.isalnum() or c in '-_.' else '_' for c in name)}.png"
        rd.write_bytes(png, drift_figure(name, jr))
        table = [
            [
                r["date"],
                Path(r["log"]).name,
                r["status"],
                r.get("n_samples"),
                r.get("twist_rms_arcsec"),
                r.get("baseline_test_rms_Nm"),
                r.get("test_rms_Nm"),
                ", ".join(r.get("effects") or []) or ("none" if r["status"] == "ok" else ""),
                r.get("error", ""),
            ]
            for r in jr
        ]
        header = ["date", "log", "status", "samples", "twist RMS [arcsec]",
                  "TEST RMS before [N·m]", "TEST RMS [N·m]", "effects", "error"]  # fmt: skip
        lines += [f"## {name}", "", markdown_table(header, table), "", f"![drift]({png})", ""]
    rd.write_text("report.md", "\n".join(lines))
