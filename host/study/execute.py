"""A study's runs on Dask distributed: what is left to make (the run folders' records say),
a local cluster or an existing scheduler, the runs handed out and their records gathered,
a progress line on stderr, then the table, figures and page of every run that is over.

Dask's scheduler hands each run to a worker; a worker that dies mid-run has its runs given
to another (the run's folder then holds a start mark and no record: the new attempt clears
it and makes the run again). Each worker makes its runs in a runner, a process of its own
that ends with the worker (:mod:`.runner`). The folders are written by the workers, at the
same path the client gives (a shared file system on a cluster): the sweep's log is written
as it flies and read back by identify, so the run's folder lives where the run does.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
import warnings

from ...sim.base.errors import InputError
from ..process.signals import TERMINAL_SIGNALS, ignoring
from ..records.output import check_output_folder
from .runner import PLUGIN_NAME, in_runner, runner_plugin
from .runs import FAILED, RECORD, RUNS, read_record, run_folder, worker_version

__all__ = ["run_study", "plan", "EXIT_FAILED"]

#: The exit code of a study that made every run but some failed, or that stopped (a
#: scheduler lost, a worker without heliquad): the records made so far kept.
EXIT_FAILED = 1
#: How long a scheduler may take to answer before the study says it does not.
CONNECT_TIMEOUT_S = 5
#: How often the progress line is redrawn while no run ends (seconds).
TICK_S = 0.5
#: Dask's settings for the local cluster's workers (given to their nannies, so that a worker
#: started again has them too): no sampling profiler (the running task's stack every 10 ms,
#: for a dashboard the local cluster has none of), the loop-latency tick every second, not
#: every 20 ms (it feeds only a warning the study silences), the worker's memory checked
#: every second, not 100 ms (its nanny still stops it at 95 % every 100 ms: the worker's
#: own memory, not its runners'), its system figures every 5 s, not 0.5 s. The runs are
#: made in runners of their own (host/study/runner.py), so these wake-ups no longer take
#: the GIL from a run; they still take CPU on the cores the runs use, for nothing a study
#: reads.
WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.tick.interval": "1s",
                 "distributed.worker.memory.monitor-interval": "1s",
                 "distributed.admin.system-monitor.interval": "5s"}


def plan(spec, out: str, retry_failed: bool = False) -> tuple:
    """``(records of the runs already over, runs to make)``: a run whose folder holds its
    record is over (a failed one is to make again with ``retry_failed``: :func:`forget`
    removes its record before it is handed out); any other run is to make."""
    kept, todo = {}, []
    for run in spec.runs:
        record = read_record(run_folder(out, run.name))
        if record is not None and retry_failed and record.get("status") == FAILED:
            record = None
        if record is None:
            todo.append(run)
        else:
            kept[run.name] = record
    return kept, todo


def forget(out: str, runs) -> None:
    """Remove the records of ``runs`` (failed runs to make again), so that their workers do
    not take them for over."""
    for run in runs:
        path = os.path.join(run_folder(out, run.name), RECORD)
        if os.path.exists(path):
            os.unlink(path)


def run_study(spec, out: str, perform, workers=None, scheduler=None, retry_failed=False,
              dry_run=False) -> int:
    """Make what is left of ``spec``'s runs into ``out`` by ``perform(run, out)`` on Dask,
    then write the table, figures and page; the exit code (0, or :data:`EXIT_FAILED`)."""
    check_output_folder(out, "--out")
    kept, todo = plan(spec, out, retry_failed)
    print(f"study: {len(spec.runs)} runs, {len(kept)} already over, {len(todo)} to make "
          f"-> {out}", flush=True)
    if dry_run:
        for run in spec.runs:
            print(f"{'over' if run.name in kept else 'to make':>8}  {run.name}")
        return 0
    client = _client(workers, scheduler) if todo else None   # before anything is written
    forget(out, todo)
    stopped = None
    with _dask_quiet():
        try:
            os.makedirs(os.path.join(out, RUNS), exist_ok=True)
            if client is not None:
                stopped = _execute(client, todo, out, perform)
        finally:                             # Ctrl-C too: every run over is in the table
            if client is not None:
                _close(client, scheduler)
            records = _write_results(spec, out)
    if stopped:
        kept = (f"; the {len(records)} runs over are kept: run the same command again to "
                "make the rest") if records else ""
        sys.stderr.write(f"heliquad study: {stopped}{kept}\n")
        return EXIT_FAILED
    failed = sum(r.get("status") == FAILED for r in records)
    if failed:
        sys.stderr.write(f"heliquad study: {failed} of {len(records)} runs failed (their "
                         f"errors are in the table's error column)\n")
        return EXIT_FAILED
    return 0


@contextlib.contextmanager
def _dask_quiet():
    """Dask's own log lines kept off stderr while the study runs (a lost scheduler's
    reconnection attempts, with their tracebacks): the study says in one line what
    happened. Its handlers' levels are put back at the end."""
    handlers = logging.getLogger("distributed").handlers
    before = [h.level for h in handlers]
    for h in handlers:
        h.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for h, level in zip(handlers, before):
            h.setLevel(level)


def _write_results(spec, out: str) -> list:
    """The table, figures and page of every run of ``spec`` that is over; their records."""
    # the table's and figures' libraries, imported once runs are over (pyarrow, matplotlib)
    from .present import write_page
    from .table import write_table

    records = [r for r in (read_record(run_folder(out, run.name)) for run in spec.runs)
               if r is not None]
    if records:
        paths = write_table(records, spec.columns, out)
        figures = write_page(records, spec, out)
        print(f"wrote {', '.join(os.path.basename(p) for p in (*paths, *figures))} in {out}",
              flush=True)
    return records


def _client(workers, scheduler):
    """A Dask client: of an existing scheduler (InputError when it does not answer), else
    of a local cluster, ``workers`` processes (default one per core) of one thread each."""
    # Dask, imported when runs are made: planning, a dry run and --help do without it
    import distributed

    if scheduler is not None:
        try:
            with warnings.catch_warnings():     # Dask's table of versions: ours is checked
                warnings.simplefilter("ignore", distributed.versions.VersionMismatchWarning)
                return distributed.Client(scheduler, timeout=CONNECT_TIMEOUT_S,
                                          set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler {scheduler}: no answer in {CONNECT_TIMEOUT_S} s "
                             f"({' '.join(str(exc).split()) or type(exc).__name__})") from None
    # the workers start with a terminal's Ctrl-C and hang-up ignored: it reaches this
    # process, which closes the cluster in order (the workers' runs left unfinished)
    with ignoring(TERMINAL_SIGNALS):
        cluster = distributed.LocalCluster(n_workers=workers or os.cpu_count() or 1,
                                           threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=logging.ERROR,
                                           config=WORKER_CONFIG)
    return distributed.Client(cluster, set_as_default=False)


def _execute(client, todo, out, perform) -> str | None:
    """Hand ``todo`` out, gather the records as runs end, show progress; None once every run
    is over, else why the study stopped."""
    # Dask, imported when runs are made: planning, a dry run and --help do without it
    import distributed

    why = _check_workers(client)
    if why:
        return why
    plugin = runner_plugin()                  # a worker's runners, ended with it
    try:
        client.register_plugin(plugin)
    except Exception as exc:            # noqa: BLE001: the worker's own error, said in a line
        return (f"a worker cannot start the runs' processes ({type(exc).__name__}: "
                f"{' '.join(str(exc).split())})")
    futures = [client.submit(in_runner, perform, run, out, key=f"heliquad-study-{run.name}-"
                             f"{os.getpid()}-{time.time_ns()}") for run in todo]
    return _gather(client, futures, distributed.as_completed(futures, loop=client.loop))


def _check_workers(client) -> str | None:
    """Why the study cannot start on ``client``'s workers (none; one that cannot import
    heliquad), or None."""
    try:
        versions = client.run(worker_version)
    except Exception as exc:            # noqa: BLE001: the worker's own error, said in a line
        return (f"a worker cannot run heliquad ({type(exc).__name__}: "
                f"{' '.join(str(exc).split())}): install heliquad on every worker")
    if not versions:
        return "the scheduler has no worker"
    ours = worker_version()
    other = sorted(w for w, v in versions.items() if v != ours)
    if other:
        return (f"worker {other[0]} runs heliquad {versions[other[0]]}, this one {ours}: "
                "install the same heliquad on every worker")
    return None


def _gather(client, futures, done) -> str | None:
    """Wait for every run, its record said on the progress line; a future that raised (its
    worker died too often, the scheduler went away) is said and stops the study."""
    progress = Progress(len(futures), sum(client.nthreads().values()) or 1)
    while not done.is_empty():
        for future in done.next_batch(block=False):
            try:
                progress.record(future.result())
            except Exception as exc:    # noqa: BLE001: not the run's failure: the cluster's
                progress.close()
                if client.status != "running" or "connection-lost" in str(exc):
                    return "the connection to the scheduler was lost"
                for f in futures:
                    f.cancel()
                return f"run {_run_of(future)} could not be made: {type(exc).__name__}: " \
                       f"{' '.join(str(exc).split())}"
        progress.show()
        if not done.is_empty():
            time.sleep(TICK_S)
    progress.close()
    return None


def _run_of(future) -> str:
    return str(future.key).removeprefix("heliquad-study-").rsplit("-", 2)[0]


def _close(client, scheduler) -> None:
    """Close the client (and the local cluster this study started); a scheduler given is left
    running, the study's tasks on it cancelled."""
    cluster = client.cluster if scheduler is None else None
    if scheduler is not None:
        # the study's runners ended on the cluster's workers: they keep nothing of it
        with contextlib.suppress(Exception):
            client.unregister_worker_plugin(PLUGIN_NAME)
    try:
        client.close(timeout=CONNECT_TIMEOUT_S)
    finally:
        if cluster is not None:
            cluster.close(timeout=CONNECT_TIMEOUT_S)


class Progress:
    """The progress line on stderr: runs done, failed, running, the time left (from the
    mean time between runs ending so far); redrawn in place on a terminal, else a line per
    run that ends."""

    def __init__(self, total: int, slots: int, stream=None):
        self.total, self.slots = total, slots
        self.done = self.failed = 0
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.t0 = time.monotonic()

    def text(self) -> str:
        left = self.total - self.done
        elapsed = time.monotonic() - self.t0
        eta = "?" if not self.done else _duration(elapsed / self.done * left)
        return (f"study: {self.done}/{self.total} done, {self.failed} failed, "
                f"{min(self.slots, left)} running, {_duration(elapsed)} elapsed, "
                f"about {eta} left")

    def record(self, record: dict) -> None:
        self.done += 1
        self.failed += record.get("status") == FAILED
        if not self.tty:
            self.stream.write(self.text() + (f" ({record['run']}: failed)" if
                                             record.get("status") == FAILED else "") + "\n")
            self.stream.flush()

    def show(self) -> None:
        if self.tty:
            self.stream.write("\r\x1b[K" + self.text())
            self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"
