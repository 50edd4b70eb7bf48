"""Many simulated campaigns from one spec, on this machine or a Dask cluster
(``heliquad study``)."""

from __future__ import annotations

import argparse
import functools
import importlib
import json
import os
import sys
import threading

from ...sim.base.errors import InputError
from .shared_options import int_in

__all__ = ["add_parser", "run", "run_command", "command_line", "option_names"]

HELP = """\
Make every run a study's spec (a TOML file, docs/studies.md) names: for each combination of
its factors' values (axis, signal, turbulence, seed, firmware, any option of heliquad sweep,
identify, validate or tune), `heliquad sweep --sil` on the simulated rig then `heliquad
identify`, and where the spec asks ([validate], [tune]) `heliquad validate` and `heliquad
tune` on the models, in-process, exactly as typed by hand with those options. Each run has
a folder DIR/runs/NAME (its name and seed derived from its factors) holding the sweep folder,
the commands' output and record.json, written last and atomically: a run whose folder holds
one is finished and is never made again, so running the same command again does only what is
missing (--retry-failed redoes the failed ones too). A run that fails is a row with its error
(and the figures of the steps before); validate's and tune's exit 1 are verdicts, said in the
row's verdicts, and the run goes on.

Runs execute on Dask distributed: a local cluster of one worker process per core (--workers N
for another count), or an existing scheduler (--scheduler tcp://HOST:8786) whose workers have
heliquad installed and see DIR at the same path. Writes DIR/study.parquet and DIR/study.csv
(one row per run: its factors, errors against the simulator's truth, sigma calibration, rig
time, recommended model, timings, failures), DIR/figures/*.png and DIR/index.html.

exit codes: 0 every run finished; 1 some runs failed, or the study stopped (a scheduler
lost, a worker without heliquad); 2 bad input (the spec, the options, a scheduler that does
not answer); 130 Ctrl-C (finished runs kept; run the command again to go on).

example: heliquad study benchmarks/studies/closed_loop_id.toml --out cl_study
         heliquad study spec.toml --out study --scheduler tcp://10.0.0.5:8786
"""

#: The commands a run makes (host/study/spec.py's STEPS), their modules here.
STEP_MODULES = {"sweep": "sweep", "identify": "identify", "validate": "validate", "tune": "tune"}


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("study", help="many simulated sweeps and identifications from a spec, "
                                     "locally or on a Dask cluster",
                       description=HELP, formatter_class=fmt)
    p.add_argument("spec", metavar="SPEC.toml", help="the study's spec (docs/studies.md)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="the study's folder: a run folder each, the table, figures, index.html")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                       help="a local cluster of N worker processes (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="an existing Dask scheduler, e.g. tcp://HOST:8786")
    p.add_argument("--retry-failed", action="store_true",
                   help="make the runs that failed before again (default: kept as failed)")
    p.add_argument("--dry-run", action="store_true",
                   help="list the runs and what is left to make; make none")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..study.execute import run_study
    from ..study.runs import perform_run
    from ..study.spec import load_spec

    spec = load_spec(args.spec, option_names())
    check_runs(spec.runs)
    perform = functools.partial(perform_run, command=run_command, line=command_line)
    return run_study(spec, os.path.abspath(args.out), perform, workers=args.workers,
                     scheduler=args.scheduler, retry_failed=args.retry_failed,
                     dry_run=args.dry_run)


#: The sweep's options that its plan does not depend on: a plan checked once for all their
#: values (a study's hundred seeds).
PLAN_FREE = ("seed", "turbulence")


def check_runs(runs) -> None:
    """Every run's command lines parse, and its sweep's plan passes the checks the sweep
    makes before it flies, before any run starts: an InputError names the first run that
    would fail them."""
    # the sweep command's checks, imported when a study runs: --help imports every module
    from .sweep import checked_plan

    planned = set()
    for r in runs:
        for step, options in r.options.items():
            args = _parse(command_line(step, options), f"run {r.name}")
            key = json.dumps({k: v for k, v in options.items() if k not in PLAN_FREE},
                             sort_keys=True)
            if step == "sweep" and key not in planned:
                planned.add(key)
                try:
                    checked_plan(args)
                except InputError as exc:
                    raise InputError(f"run {r.name}: {exc}") from None


class _Refused(Exception):
    """argparse's error, raised instead of its exit (a study's run line that is wrong)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise _Refused(message)


@functools.lru_cache(maxsize=None)
def _parser() -> argparse.ArgumentParser:
    """A parser with the commands a run makes, as the program's parser has them."""
    parser = _Parser(prog="heliquad", add_help=False)
    sub = parser.add_subparsers(dest="command", parser_class=_Parser)
    for module in STEP_MODULES.values():
        importlib.import_module(f"{__package__}.{module}").add_parser(
            sub, argparse.RawDescriptionHelpFormatter)
    return parser


def _actions(step: str) -> dict:
    """{long option name without --: its argparse action} of command ``step``."""
    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {s[2:]: a for a in sub.choices[step]._actions for s in a.option_strings
            if s.startswith("--") and not s.startswith("--no-")}


def option_names() -> dict:
    """{command: the long names of its options} for each command a run makes."""
    return {step: frozenset(_actions(step)) for step in STEP_MODULES}


def command_line(step: str, options: dict, folder: str | None = None) -> list:
    """The command line (words after ``heliquad``) of command ``step`` with ``options``
    ({long name: value}: true/false for a flag, a list for several values) and the study's
    folder: the sweep's --sil --out FOLDER, identify's FOLDER."""
    actions = _actions(step)
    words = [step]
    for name, value in options.items():
        action = actions[name]
        if isinstance(action, argparse.BooleanOptionalAction):
            words.append(f"--{name}" if value else f"--no-{name}")
        elif action.nargs == 0:             # a flag
            words += [f"--{name}"] if value else []
        elif isinstance(action, argparse._AppendAction):
            for v in value if isinstance(value, list) else [value]:
                words += [f"--{name}", _word(v)]
        elif isinstance(value, list):
            words += [f"--{name}", *map(_word, value)]
        else:
            words += [f"--{name}", _word(value)]
    # the run folders' layout, imported when a line is made: --help imports every module
    from ..study.runs import TUNED

    place = folder if folder is not None else "DIR"
    models = os.path.join(place, "models.json")
    return words + {"sweep": ["--sil", "--out", place], "identify": [place],
                    "validate": [models],
                    "tune": [models, "--out", os.path.join(place, TUNED)]}[step]


def _word(value) -> str:
    return repr(value) if isinstance(value, float) else str(value)


def _parse(words: list, what: str):
    try:
        return _parser().parse_args(words)
    except _Refused as exc:
        raise InputError(f"{what}: heliquad {' '.join(words)}: {exc}") from None


def run_command(words: list, log) -> int:
    """Run ``heliquad WORDS`` in this process, as the program does, what it prints (stdout
    and stderr) written to the file object ``log``; its exit code (an error raises, as in
    the program). Threads may each run one at once: each one's output goes to its own log."""
    # the plots' module, imported when a run is made: the client plans runs without it
    from ..present.plot_process import drawing_here

    args = _parse(words, "run")
    _ThreadStreams.install()
    _ThreadStreams.local.log = log
    try:
        with drawing_here():            # a worker per core: no plotting process per run
            return int(args.func(args) or 0)
    finally:
        _ThreadStreams.local.log = None


class _ThreadStreams:
    """sys.stdout and sys.stderr in a process whose threads run commands (a Dask worker
    with several threads): a write goes to the log of the command its thread is running,
    else where it went before. (contextlib.redirect_stdout swaps the one sys.stdout of the
    process, and two threads swapping it in turn would put it back wrong.)"""

    local = threading.local()
    _lock = threading.Lock()

    def __init__(self, before):
        self.before = before

    @classmethod
    def install(cls) -> None:
        with cls._lock:
            if not isinstance(sys.stdout, cls):
                sys.stdout = cls(sys.stdout)
            if not isinstance(sys.stderr, cls):
                sys.stderr = cls(sys.stderr)

    def _target(self):
        return getattr(self.local, "log", None) or self.before

    def write(self, text):
        return self._target().write(text)

    def flush(self):
        return self._target().flush()

    def isatty(self):
        return self._target().isatty()

    def __getattr__(self, name):
        return getattr(self._target(), name)
