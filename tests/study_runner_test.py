"""A study's runs are made in a runner, a process of the worker's own (host/study/runner.py):
what the run returns or raises comes back; a runner that dies mid-run costs that run only
(a failed record saying so, the next run in a new runner); a runner never outlives its
worker, killed or closed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import tomllib

import pytest

cloudpickle = pytest.importorskip("cloudpickle")

from heliquad.host.commands.study import option_names       # noqa: E402
from heliquad.host.study import runner, runs                # noqa: E402
from heliquad.host.study.spec import parse_spec             # noqa: E402
from tool_runs import (HANG_GUARD_S, assert_nothing_left, children,  # noqa: E402
                       private_tmpdir, wait_for)

# The performs below are this module's: the runner receives them by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])

SPEC = """
[study]
description = "runner"
[factors]
axis = "roll"
seed = [1, 2]
[sweep]
signal = "multisine"
"""


def _runs():
    return parse_spec(tomllib.loads(SPEC), option_names(), "s.toml").runs


def _where(run, out):
    return {"run": run.name, "pid": os.getpid(), "out": out}


def _raises(run, out):
    raise ValueError(f"{run.name} refused")


def _dies(run, out):
    os.makedirs(runs.run_folder(out, run.name), exist_ok=True)
    with open(os.path.join(runs.run_folder(out, run.name), runs.STARTED), "w") as f:
        json.dump({"attempt": 2, "at": 1.0, "pid": os.getpid()}, f)
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_run_is_made_in_a_process_of_its_own_kept_for_the_next(tmp_path):
    first, second = _runs()
    with private_tmpdir(tmp_path) as tmp:
        try:
            a = runner.in_runner(_where, first, str(tmp_path))
            b = runner.in_runner(_where, second, str(tmp_path))
            assert a["run"] == first.name and b["run"] == second.name
            assert a["pid"] != os.getpid() and a["pid"] == b["pid"]     # one runner, kept
            with pytest.raises(ValueError, match=f"{first.name} refused"):
                runner.in_runner(_raises, first, str(tmp_path))
            assert runner.in_runner(_where, first, str(tmp_path))["pid"] == a["pid"]
        finally:
            runner.close_runners()
        assert_nothing_left(tmp)


class _Awkward(Exception):
    def __init__(self, a, b):
        super().__init__(f"{a} and {b}")


def _awkward(run, out):
    raise _Awkward("one", "two")


def _wait_forever(run, out):
    """A run that starts what a SIL run starts (a process in a session of its own, as the
    firmware is; a temporary folder), says where its TMPDIR is, and waits forever; should its
    process die while the run lives, the run writes a file (as a run would its record)."""
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(3600)"],
                             start_new_session=True)
    tempfile.mkdtemp(prefix="heliquad-sil-")
    with open(out, "w") as f:
        f.write(tempfile.gettempdir())
    child.wait()
    open(out + ".after", "w").close()
    while True:
        signal.pause()


def test_what_the_run_raises_comes_back_even_when_it_cannot_be_rebuilt(tmp_path):
    first, _ = _runs()
    with private_tmpdir(tmp_path) as tmp:
        try:
            with pytest.raises(RuntimeError, match="_Awkward: one and two.*not sendable"):
                runner.in_runner(_awkward, first, str(tmp_path))
            # a perform the runner cannot import: its error, not a dead runner
            (tmp_path / "only_here.py").write_text("def perform(run, out):\n    return 1\n")
            sys.path.insert(0, str(tmp_path))
            try:
                import only_here
                with pytest.raises(ModuleNotFoundError, match="only_here"):
                    runner.in_runner(only_here.perform, first, str(tmp_path))
            finally:
                sys.path.remove(str(tmp_path))
                sys.modules.pop("only_here", None)
            assert runner.in_runner(_where, first, str(tmp_path))["run"] == first.name
        finally:
            runner.close_runners()
        assert_nothing_left(tmp)


def test_closing_a_workers_runners_ends_a_run_in_flight_at_once(tmp_path):
    # A worker closing (its plugin's teardown) must not wait for the run: the run is not
    # over (no record), the runner ends, the waiting thread is told; what the run started
    # (a process in a session of its own, its temporary folder) is gone when the close
    # returns, and the run wrote nothing after its process was killed.
    first, _ = _runs()
    started = tmp_path / "started"
    with private_tmpdir(tmp_path) as tmp:
        raised = []

        def make():
            try:
                runner.in_runner(_wait_forever, first, str(started))
            except BaseException as exc:   # noqa: BLE001 - what the worker's thread sees
                raised.append(exc)
        thread = threading.Thread(target=make)
        thread.start()
        wait_for(started.exists, "the run started")
        runner.close_runners()
        thread.join(HANG_GUARD_S)
        assert not thread.is_alive()
        assert [type(e) for e in raised] == [runner.RunnerGone]
        assert runs.read_record(runs.run_folder(str(tmp_path), first.name)) is None
        scratch = started.read_text()
        assert os.path.basename(scratch).startswith("heliquad-runner-")
        assert not os.path.exists(scratch)
        assert not (tmp_path / "started.after").exists()
        assert_nothing_left(tmp)


def test_a_run_over_before_its_process_died_keeps_its_record(tmp_path):
    first, _ = _runs()
    out = str(tmp_path)
    os.makedirs(runs.run_folder(out, first.name))
    kept = {"run": first.name, "status": runs.FINISHED}
    with open(os.path.join(runs.run_folder(out, first.name), runs.RECORD), "w") as f:
        json.dump(kept, f)
    assert runs.died_record(first, out, "the run's process died of SIGKILL") == kept


def test_a_runner_that_dies_mid_run_fails_that_run_only(tmp_path):
    first, second = _runs()
    out = str(tmp_path / "study")
    with private_tmpdir(tmp_path) as tmp:
        try:
            record = runner.in_runner(_dies, first, out)
            assert record["status"] == runs.FAILED and record["attempt"] == 2
            assert record["error"] == "the run's process died of SIGKILL"
            assert runs.read_record(runs.run_folder(out, first.name)) == record
            assert runner.in_runner(_where, second, out)["run"] == second.name
        finally:
            runner.close_runners()
        assert_nothing_left(tmp)


#: A worker that starts a runner, hands it a run that waits forever, and says the runner's
#: pid once the run has started. The run starts what a SIL run starts: a process in a
#: session of its own (as the firmware is) and a temporary folder; should that process die
#: while the run's process lives, the run writes a file (as a run would its failed record).
WORKER = textwrap.dedent("""
    import os, subprocess, sys, tempfile, time
    from heliquad.host.study import runner
    started, wrote = sys.argv[1:3]

    def wait_forever(run, out):
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(3600)"],
                                 start_new_session=True)
        with open(os.path.join(tempfile.mkdtemp(prefix="heliquad-sil-"), "log"), "w") as f:
            f.write("kept until the runner ends")
        open(started, "w").close()
        child.wait()
        open(wrote, "w").close()
        while True:
            time.sleep(3600)

    r = runner.Runner()
    print(r.proc.pid, flush=True)
    r.call(wait_forever, None, None)
""")


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM"])
def test_a_runner_ends_when_its_worker_is_gone(tmp_path, how):
    # ...at once, writing nothing more, and what its run started goes with it once it is
    # gone: the firmware-like process (in a session of its own, it would serve on until its
    # idle timeout) and the temporary folders
    started, wrote = tmp_path / "started", tmp_path / "wrote"
    with private_tmpdir(tmp_path) as tmp:
        worker = subprocess.Popen([sys.executable, "-c", WORKER, str(started), str(wrote)],
                                  stdout=subprocess.PIPE, text=True)
        pid = int(worker.stdout.readline())
        wait_for(started.exists, "the run started", worker)
        worker.send_signal(getattr(signal, how))
        worker.wait(HANG_GUARD_S)
        worker.stdout.close()
        status = []                              # the runner, ours now: its exit status

        def ended():
            got, code = os.waitpid(pid, os.WNOHANG)
            if got:
                status.append(os.waitstatus_to_exitcode(code))
            return bool(status)
        wait_for(ended, "the runner's end")
        assert status == [runner.ORPHANED]
        wait_for(lambda: not children(os.getpid()) and not any(tmp.iterdir()),
                 "the run's process and folders gone")
        assert not wrote.exists()
        assert_nothing_left(tmp)
