"""One definition per firmware fact.

The control loop's rate (and so its period), the host build's largest loop rate, the most its
ptys' backlog bound can be, the Teensy image's USB IDs and the SafetyLimits defaults (abort limits, the excitation's band, length and amplitude bounds) are
written once, in the firmware's C++; Python reads them through the bindings in
sim/base/firmware_facts.py. These tests check that module against the bindings and the host
build, and scan the Python sources (host/, sim/) for a hand copy: a number equal to a fact
(in its own units or the command line's: Hz, s, us, deg, deg/s) that is assigned to, the
default of, or given as a keyword for a name that speaks of the loop, of a limit or of a
backlog, or that appears in the definition of a ``--loop-hz`` or ``--backlog-bytes`` option.
"""

from __future__ import annotations

import ast
import math
import pathlib
import re
import subprocess

import pytest

from heliquad import _firmware as fw
from heliquad.sim.base import firmware_facts as facts
from heliquad.sim.rig.lockstep import find_firmware

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: Names that speak of the loop, of a length of time, and of an angle or a rate.
LOOP = re.compile(r"loop|(^|_)dt(_|$)|period|(^|_)hz$|--loop", re.I)
TIME = re.compile(r"(^|_)s$|duration|rig_time|--rig-time", re.I)
MOTION = re.compile(r"angle|rate|amplitude|(^|_)(deg|rad)(_|$)", re.I)
#: Names that speak of a loop's stability margin: a specification (a phase margin in deg),
#: never a fact of the firmware's, whatever number it shares with one.
MARGIN = re.compile(r"margin", re.I)
#: Names that speak of what waits for a reader on a pty.
BACKLOG = re.compile(r"backlog|(^|_)pty(_|$)", re.I)
#: Names that speak of a USB identity.
USB = re.compile(r"usb|vid|vendor|(^|_)pid$|product", re.I)


def test_the_facts_are_the_bindings():
    lim = fw.SafetyLimits()
    assert facts.LOOP_RATE_HZ == fw.LOOP_RATE_HZ
    assert facts.LOOP_PERIOD_S == 1 / fw.LOOP_RATE_HZ
    assert facts.MAX_LOOP_RATE_HZ == fw.MAX_LOOP_RATE_HZ > facts.LOOP_RATE_HZ
    # Linux's N_TTY_BUF_SIZE (4096), less one: the most of a pty's queue TIOCINQ shows.
    assert facts.MAX_PTY_BACKLOG_BYTES == fw.MAX_PTY_BACKLOG_BYTES == 4096 - 1
    assert (facts.ABORT_ANGLE_RAD, facts.ABORT_RATE_RAD_S) == (lim.abort_angle_rad,
                                                               lim.abort_rate_rad_s)
    assert (facts.MIN_FREQ_HZ, facts.MAX_FREQ_FRACTION, facts.MAX_DURATION_S,
            facts.MIN_FADE_CYCLES) == (lim.min_freq_hz, lim.max_freq_fraction,
                                       lim.max_duration_s, lim.min_fade_cycles)
    assert [facts.max_amplitude(i) for i in ("angle", "rate", "mixer")] == \
        [lim.max_amplitude[int(fw.Injection.ANGLE)], lim.max_amplitude[int(fw.Injection.RATE)],
         lim.max_amplitude[int(fw.Injection.MIXER)]]
    assert facts.MAX_HARMONICS == fw.MAX_HARMONICS
    assert facts.MIN_TIME_CONSTANT_S == fw.MIN_TIME_CONSTANT_S
    assert (facts.MIN_ROTORS, facts.MAX_ROTORS) == (fw.MIN_ROTORS, fw.MAX_ROTORS) == (4, 8)
    assert facts.USB_IDENTITY == (fw.USB_VID, fw.USB_PID, fw.USB_MANUFACTURER, fw.USB_PRODUCT)


@pytest.mark.parametrize("hz", [fw.MAX_LOOP_RATE_HZ * 1.001, 0.0])
def test_the_host_build_refuses_a_loop_rate_beyond_its_bound(hz, tmp_path):
    # The bound the command line checks --loop-hz against is the host build's own.
    res = subprocess.run([find_firmware(), "--sim-link", str(tmp_path / "s"), "--telemetry",
                          str(tmp_path / "t"), "--loop-hz", repr(hz)],
                         capture_output=True, text=True, timeout=30)
    assert res.returncode == 2
    assert f"--loop-hz must be in (0, {fw.MAX_LOOP_RATE_HZ:g}]" in res.stderr


def fact_values() -> list:
    """(number, what it is, the names it would be a copy under) of every fact, in the units
    a copy would be written in."""
    out = [(facts.LOOP_RATE_HZ, "the loop rate", LOOP),
           (facts.LOOP_PERIOD_S, "the loop period", LOOP),
           (1e6 / facts.LOOP_RATE_HZ, "the loop period (us)", LOOP),
           (facts.MAX_LOOP_RATE_HZ, "the host build's largest loop rate", LOOP),
           (facts.MAX_DURATION_S, "the longest excitation", TIME),
           (facts.MAX_PTY_BACKLOG_BYTES, "the pty's backlog bound", BACKLOG),
           (facts.USB_IDENTITY.vid, "the USB vendor ID", USB),
           (facts.USB_IDENTITY.pid, "the USB product ID", USB)]
    for what, rad in (("the abort angle", facts.ABORT_ANGLE_RAD),
                      ("the abort rate", facts.ABORT_RATE_RAD_S),
                      ("the angle amplitude bound", facts.max_amplitude("angle")),
                      ("the rate amplitude bound", facts.max_amplitude("rate"))):
        out += [(rad, what, MOTION), (round(math.degrees(rad), 3), what + " (deg)", MOTION)]
    return out


def _number(node) -> float | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
            and not isinstance(node.value, bool):
        return float(node.value)
    return None


def _named_numbers(tree):
    """(name, number node) pairs: assignments, parameter defaults, keyword arguments, and
    every number inside a call whose first argument is an option string (``"--loop-hz"``)."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                if isinstance(t, (ast.Name, ast.Attribute)):
                    yield t.id if isinstance(t, ast.Name) else t.attr, node.value
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args.posonlyargs + node.args.args
            for a, d in zip(args[len(args) - len(node.args.defaults):], node.args.defaults):
                yield a.arg, d
            for a, d in zip(node.args.kwonlyargs, node.args.kw_defaults):
                if d is not None:
                    yield a.arg, d
        elif isinstance(node, ast.Call):
            for k in node.keywords:
                if k.arg:
                    yield k.arg, k.value
            first = node.args[0] if node.args else None
            if isinstance(first, ast.Constant) and isinstance(first.value, str) \
                    and first.value.startswith("--"):
                for sub in ast.walk(node):
                    yield first.value, sub


def copies(source: str, path: str = "<source>") -> list:
    """Where ``source`` writes a fact by hand (module docstring)."""
    values = fact_values()
    found = []
    for name, node in _named_numbers(ast.parse(source, path)):
        value = _number(node)
        if value is None:
            continue
        for fact, what, context in values:
            if math.isclose(value, fact, rel_tol=1e-6) and context.search(name) \
                    and not MARGIN.search(name):
                found.append(f"{path}:{node.lineno}: {name} = {node.value!r} copies {what}")
    return found


def test_no_hand_copy_in_python():
    found = []
    for folder in ("host", "sim"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            found += copies(path.read_text(), str(path.relative_to(ROOT)))
    assert not found, "\n".join(found)


@pytest.mark.parametrize("source", [
    "MAX_RIG_TIME_S = 300.0",
    "def run(loop_hz: float = 200.0): pass",
    "p.add_argument('--loop-hz', type=number_in(1, 2000), default=200.0)",
    "LOOP_DT_S = 0.005",
    "MAX_ANGLE_DEG = 80.0",
    "start(abort_rate_rad_s=6.981317)",
    "TELEMETRY_BACKLOG_BYTES = 4095",
    "def run_board(backlog_bytes: int = 4095): pass",
    "p.add_argument('--backlog-bytes', type=int_in(0, 4095))",
    "class Pty:\n    MAX_BACKLOG = 4095",
    "TEENSY_VID = 0x16C0",
    "BoardPort(device, vid=0x16C0, pid=0x0483)",
])
def test_the_scan_finds_a_copy(source):
    assert copies(source)


@pytest.mark.parametrize("source", [
    "CLIP_ITERATIONS = 200",
    "def short(text, limit=80): pass",
    "MAX_DWELL_S = 60.0",
    "p.add_argument('--cycles', type=int_in(1, 200))",
    "LOOP_DT_S = LOOP_PERIOD_S",
    "REGISTER_MASK = 4095",
    "p.add_argument('--backlog-bytes', type=int_in(0, MAX_PTY_BACKLOG_BYTES))",
    "class Spec:\n    phase_margin_deg: float = 45.0",
])
def test_the_scan_passes_what_is_no_copy(source):
    assert not copies(source)
