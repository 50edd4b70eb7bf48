"""Benchmark: a small study's wall time on one local Dask worker and on two, and what Dask's
scheduler costs per run, against the same runs made one by one in this process.

One spec of --runs short runs (a multisine of 5 lines, 10 s of rig time, on roll and pitch,
light turbulence, seeds from 1); three measurements in one benchmark run:

1. **one by one**: each run made in this process, no Dask (host/study/runs.py's
   perform_run, as a worker makes it), after importing what a run needs as a worker's
   runner does before its first run (so that neither side's run time carries the imports):
   the baseline, the sum of the runs' times;
2. ``heliquad study SPEC --workers 1``: the command's wall time; a run's mean time on the
   worker (made in its runner) against in this process; the time between runs (the first
   run's start to the last one's end, less the runs' own times, over the runs: the
   scheduler's cost per run), and its start and finish (cluster, table, figures);
3. ``heliquad study SPEC --workers 2``: its wall time; the speed-up over (2), whole and of
   the runs alone (first start to last end: the rate a long study makes runs at, its
   start and finish left out);
4. the machine's own ceiling, measured in the same run: a fixed CPU-bound loop in one
   process, then in two at once (two copies' work over the wall time, against one's): what
   two workers could reach at best on these cores as they are shared now (a virtual
   machine's two cores can be one physical core's two threads, or shared with others).

Each figure is printed with its ratio to the baseline measured in the same benchmark run. On
a machine whose two cores something else also uses, the speed-up is that machine's.

    python benchmarks/study_speed.py [--runs 16]
"""

from __future__ import annotations

import argparse
import functools
import importlib
import json
import os
import subprocess
import sys
import tempfile
import time

from heliquad.host.commands.study import command_line, option_names, run_command
from heliquad.host.study.runner import WARM
from heliquad.host.study.runs import RECORD, RUNS, perform_run
from heliquad.host.study.spec import load_spec

SPEC = """
[study]
description = "study_speed: short multisine runs"
[factors]
axis = ["roll", "pitch"]
turbulence = "light"
seed = {{first = 1, count = {seeds}}}
[sweep]
signal = "multisine"
lines = 5
rig-time = 10
"""


def one_by_one(spec_path: str, out: str) -> tuple:
    """Every run made in this process, in order, after the imports a runner makes before
    its first run: (wall seconds, the runs' records)."""
    for module in WARM:
        importlib.import_module(module)
    spec = load_spec(spec_path, option_names())
    perform = functools.partial(perform_run, command=run_command, line=command_line)
    t0 = time.perf_counter()
    records = [perform(run, out) for run in spec.runs]
    return time.perf_counter() - t0, records


def study(spec_path: str, out: str, workers: int) -> tuple:
    """``heliquad study`` with ``workers`` local workers: (wall seconds, the records)."""
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "study", spec_path,
                          "--out", out, "--workers", str(workers)], capture_output=True,
                         text=True)
    wall = time.perf_counter() - t0
    if res.returncode:
        raise SystemExit(f"heliquad study --workers {workers}: {res.stderr.strip()}")
    records = []
    for name in sorted(os.listdir(os.path.join(out, RUNS))):
        with open(os.path.join(out, RUNS, name, RECORD)) as f:
            records.append(json.load(f))
    return wall, records


#: The ceiling's work: a pure-Python loop of about a second on this machine.
SPIN = "s = 0\nfor i in range(15_000_000):\n    s += i * i"


def machine_ceiling() -> float:
    """Two copies of :data:`SPIN` at once against one: how many times one's work two
    processes do in the same wall time on this machine now (2.0: two free cores)."""
    def wall(copies: int) -> float:
        t0 = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(copies)]
        for proc in procs:
            proc.wait()
        return time.perf_counter() - t0
    one = min(wall(1) for _ in range(2))
    two = min(wall(2) for _ in range(2))
    return 2 * one / two


def span(records: list) -> float:
    """The first run's start to the last one's end."""
    return (max(r["started_at"] + r["run_s"] for r in records) -
            min(r["started_at"] for r in records))


def between_runs(records: list) -> float:
    """On one worker: the first run's start to the last one's end, less the runs' own
    times, per run (what the scheduler adds to each)."""
    return (span(records) - sum(r["run_s"] for r in records)) / len(records)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=16,
                        help="runs in the study (even; default 16: with fewer, the study's "
                             "start and finish, some 4-5 s once, weigh more than its runs)")
    args = parser.parse_args(argv)
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    with tempfile.TemporaryDirectory(prefix="study_speed-") as tmp:
        spec_path = os.path.join(tmp, "spec.toml")
        with open(spec_path, "w") as f:
            f.write(SPEC.format(seeds=max(1, args.runs // 2)))
        base, base_records = one_by_one(spec_path, os.path.join(tmp, "seq"))
        n = len(base_records)
        mean_run = sum(r["run_s"] for r in base_records) / n
        print(f"{n} runs one by one in this process: {base:.1f} s ({mean_run:.2f} s a run)",
              flush=True)
        one, one_records = study(spec_path, os.path.join(tmp, "w1"), 1)
        gap = between_runs(one_records)
        fixed = one - span(one_records)
        worker_run = sum(r["run_s"] for r in one_records) / n
        print(f"heliquad study --workers 1: {one:.1f} s ({one / base:.2f}x the one-by-one "
              f"time); a run {worker_run:.2f} s on the worker ({worker_run / mean_run - 1:+.1%}"
              f" against in this process); between runs {gap * 1e3:.0f} ms a run "
              f"({gap / mean_run:.1%} of a run's time); start and finish (cluster, table, "
              f"figures) {fixed:.1f} s", flush=True)
        two, two_records = study(spec_path, os.path.join(tmp, "w2"), 2)
        print(f"heliquad study --workers 2: {two:.1f} s ({two / base:.2f}x the one-by-one "
              f"time); speed-up over one worker {one / two:.2f}x; the runs alone (first "
              f"start to last end) {span(one_records) / span(two_records):.2f}x, start and "
              f"finish {two - span(two_records):.1f} s", flush=True)
    ceiling = machine_ceiling()
    print(f"the machine's ceiling now: two processes of a CPU-bound loop do {ceiling:.2f}x "
          f"one's work; the study's speed-up is {one / two / ceiling:.0%} of it", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f} (this benchmark's own included)")


if __name__ == "__main__":
    main()
