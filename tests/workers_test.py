"""Child processes side by side (host/process/workers.py), and the demo's axes run that way: whole
lines with each child's name, results apart from the output, a failing child reported while
the others finish, and Ctrl-C or SIGTERM passed on to every child, which stops in order."""

import io
import json
import os
import re
import signal
import subprocess
import sys

import pytest

from heliquad.host.process.workers import run_children
from tool_runs import Tool, assert_nothing_left, private_tmpdir, size, wait_for

# A child that writes its lines a character at a time, each flushed: lines of two such
# children arrive here cut anywhere, and must still be shown whole.
CHATTY = """
import os, sys
from heliquad.host.process.workers import send_result
name = sys.argv[1]
for i in range(40):
    for ch in f"{name}-line-{i}\\n":
        os.write(1, ch.encode())
send_result({"name": name, "lines": 40})
"""

FAILING = """
import sys
print("about to fail")
raise RuntimeError("this axis broke")
"""

# A child that says it is ready, then waits for a signal; Ctrl-C or SIGTERM stops it in
# order, which it says, counting the signals it got.
WAITING = """
import signal, sys, time
from heliquad.host.process.workers import send_result
got = []
def stop(signum, frame):
    got.append(signal.Signals(signum).name)
    raise KeyboardInterrupt
signal.signal(signal.SIGINT, stop)
signal.signal(signal.SIGTERM, stop)
try:
    print("ready", flush=True)
    while True:
        signal.pause()
except KeyboardInterrupt:
    time.sleep(0.2)          # stopping takes a while; a second signal would show
    print("stopped by " + " ".join(got), flush=True)
    send_result({"stopped_by": got})
"""

# The parent: runs two WAITING children as the demo runs its axes, as the command line
# does (SIGTERM raises Terminated).
PARENT = """
import signal, sys
from heliquad.host.process.signals import Terminated
from heliquad.host.process.workers import run_children
def on_sigterm(signum, frame):
    raise Terminated()
signal.signal(signal.SIGTERM, on_sigterm)
child = sys.argv[1]
try:
    run_children([(n, [sys.executable, "-c", child]) for n in ("a", "b")])
except KeyboardInterrupt as exc:
    print("parent stopped: " + type(exc).__name__, flush=True)
    sys.exit(130)
"""


def test_lines_come_whole_with_the_childs_name_and_results_come_apart():
    out, err = io.StringIO(), io.StringIO()
    children = run_children([(n, [sys.executable, "-c", CHATTY, n]) for n in ("a", "b")],
                            out, err)
    lines = out.getvalue().splitlines()
    assert len(lines) == 80 and err.getvalue() == ""
    for line in lines:
        name, text = re.fullmatch(r"\[(\w)\] (.*)", line).groups()
        assert re.fullmatch(rf"{name}-line-\d+", text), line
    assert [c.result for c in children] == [{"name": "a", "lines": 40},
                                           {"name": "b", "lines": 40}]
    assert [c.returncode for c in children] == [0, 0]


def test_a_failing_child_is_reported_and_the_others_finish():
    out, err = io.StringIO(), io.StringIO()
    bad, good = run_children([("bad", [sys.executable, "-c", FAILING]),
                              ("good", [sys.executable, "-c", CHATTY, "good"])], out, err)
    assert bad.result is None and bad.returncode == 1
    assert "[bad] about to fail" in out.getvalue()
    assert "[bad] RuntimeError: this axis broke" in err.getvalue().splitlines()
    assert good.result == {"name": "good", "lines": 40} and good.returncode == 0
    assert out.getvalue().count("[good] good-line-") == 40


@pytest.mark.parametrize("signame, raised", [("SIGINT", "KeyboardInterrupt"),
                                             ("SIGTERM", "Terminated")])
def test_ctrl_c_or_sigterm_is_passed_on_once_and_the_children_stop_in_order(signame, raised):
    # As a terminal sends Ctrl-C (SIGINT to the parent's process group; the children have
    # groups of their own) and as a service manager sends SIGTERM (to the parent), once both
    # children are waiting: the outcome does not depend on timing.
    proc = subprocess.Popen([sys.executable, "-c", PARENT, WAITING], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    ready = set()
    while ready != {"[a] ready", "[b] ready"}:
        line = proc.stdout.readline()
        assert line, proc.communicate(timeout=60)
        ready.add(line.strip())
    if signame == "SIGINT":
        os.killpg(proc.pid, signal.SIGINT)
    else:
        os.kill(proc.pid, signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err == "", err
    assert sorted(line for line in out.splitlines() if "stopped by" in line) == [
        f"[a] stopped by {signame}", f"[b] stopped by {signame}"]
    assert out.splitlines()[-1] == f"parent stopped: {raised}"


# An axis of the demo as a stand-in: pitch breaks, the others report a model.
FAKE_AXIS = """
import json, sys
from heliquad.host.process.workers import send_result
options = json.loads(sys.argv[1])
print("flying", options["axis"])
if options["axis"] == "pitch":
    raise RuntimeError("the pitch rig broke")
send_result({"status": "done", "sim_s": 10.0,
             "summary": [options["axis"], "(1) / (1 s + 1)", "the only model", 0.01, 0.1]})
"""


def test_a_failing_axis_of_the_demo_is_said_and_the_others_are_summarised(
        monkeypatch, tmp_path, capsys):
    import argparse

    from heliquad.host.commands import demo

    monkeypatch.setattr(demo, "AXIS_COMMAND", FAKE_AXIS)
    args = argparse.Namespace(out=str(tmp_path / "demo"), axes=["roll", "pitch", "yaw"],
                              ideal_sensor=False, seed=1, firmware="host", link=None,
                              turbulence=None, load_params=None)
    assert demo.run_demo(args) == demo.EXIT_STOPPED
    out, err = capsys.readouterr()
    assert "[roll] flying roll" in out and "[yaw] flying yaw" in out
    assert "[pitch] RuntimeError: the pitch rig broke" in err
    assert "== pitch: failed: it ended (exit code 1) without a result" in out
    summary = out[out.index("== identified versus"):]
    assert "roll: (1) / (1 s + 1)" in summary and "yaw: (1) / (1 s + 1)" in summary
    assert "pitch: no model; failed: it ended (exit code 1) without a result" in summary
    assert "20 s simulated" in summary and "no report: " in out


@pytest.mark.parametrize("stop, aborted, code", [
    ("ctrl_c", "interrupted (Ctrl-C)", 130), ("sigterm", "terminated (SIGTERM)", 143),
    ("sighup", "hung up (SIGHUP)", 129)])           # passed on as SIGHUP, said as such
def test_the_demo_stopped_stops_every_axis_in_order_and_keeps_their_records(
        stop, aborted, code, tmp_path):
    # Sent once both axes' sweeps have started logging (yaw's takes several seconds more
    # than that; roll's may have just ended, so its manifest is complete or stopped).
    out = tmp_path / "demo"
    with private_tmpdir(tmp_path) as tmp:
        tool = Tool("demo", "--axes", "roll", "yaw", "--out", out, tmpdir=tmp)
        wait_for(lambda: all(size(out / axis / "sweep.tlog") > 0 for axis in ("roll", "yaw")),
                 "both sweeps logging", tool.proc)
        getattr(tool, stop)()
        rc, stdout, stderr = tool.finish()
        assert rc == code and "Traceback" not in stderr, stderr
        yaw = json.loads((out / "yaw" / "manifest.json").read_text())
        assert yaw["aborted"] == aborted and not yaw["complete"]
        roll = json.loads((out / "roll" / "manifest.json").read_text())
        assert roll["complete"] or roll["aborted"] == aborted
        assert f"[yaw] {aborted}: the excitation is stopped" in stdout
        assert not (out / "report.html").exists()
        assert_nothing_left(tmp)
