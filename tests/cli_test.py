"""The heliquad command line: formats, help, and bad input (one line, exit 2)."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import scipy.io

from dwell_plant import simulate_sine_dwell
from heliquad.host.records import paper
from heliquad.sim.base.firmware_facts import MAX_PTY_BACKLOG_BYTES
from heliquad.sim.rig.board import TELEMETRY_BACKLOG_BYTES

ROLL = paper.MODELS["roll"][(0, 2)]


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=120)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Five settled sine runs through the roll model, as RUN.csv files."""
    folder = tmp_path_factory.mktemp("runs")
    paths = []
    for i, f in enumerate(np.logspace(math.log10(0.5), math.log10(4.5), 5)):
        d = simulate_sine_dwell(*ROLL, f, cycles=8, settle_cycles=math.ceil(6 * f))
        path = folder / f"run{i}.csv"
        d.to_csv(path)
        paths.append(path)
    return paths


def test_fsf_then_fit_round_trip(runs, tmp_path):
    points = tmp_path / "points.csv"
    res = heliquad("fsf", *runs, "--out", points)
    assert res.returncode == 0, res.stderr
    assert "[5/5]" in res.stdout
    header = points.read_text().splitlines()[0]
    assert header == "omega_rad_s,magnitude,phase_rad,sigma,coherence"
    table = np.loadtxt(points, delimiter=",", skiprows=1)
    assert table.shape == (5, 5) and np.all(np.diff(table[:, 0]) > 0)
    G = np.polyval(ROLL[0], 1j * table[:, 0]) / np.polyval(ROLL[1], 1j * table[:, 0])
    np.testing.assert_allclose(table[:, 1] * np.exp(1j * table[:, 2]), G, rtol=1e-6)

    models, mat, png = tmp_path / "models.json", tmp_path / "models.mat", tmp_path / "bode.png"
    res = heliquad("fit", points, "--order", "0/2", "--order", "0/3", "--json", models,
                   "--mat", mat, "--plot", png)
    assert res.returncode == 0, res.stderr
    doc = json.loads(models.read_text())
    assert doc["recommended"] == 0
    first = doc["models"][0]
    assert first["order"] == [0, 2] and first["den"][0] == 1.0 and first["stable"] is True
    assert set(first["metrics"]) >= {"rms", "J", "aicc"}
    np.testing.assert_allclose(first["num"], ROLL[0], rtol=1e-5)
    np.testing.assert_allclose(first["den"], ROLL[1], rtol=1e-5)
    assert first["delay_s"] == 0.0
    loaded = scipy.io.loadmat(mat, squeeze_me=True)
    assert int(loaded["recommended"]) == 1
    assert png.stat().st_size > 10_000


def test_fit_with_delay_writes_the_delay(runs, tmp_path):
    points = tmp_path / "p.csv"
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), 15)
    F = np.polyval(ROLL[0], 1j * omega) / np.polyval(ROLL[1], 1j * omega) * np.exp(-0.02j * omega)
    np.savetxt(points, np.column_stack([omega, np.abs(F), np.unwrap(np.angle(F))]),
               delimiter=",", header="omega_rad_s,magnitude,phase_rad", comments="")
    models = tmp_path / "m.json"
    res = heliquad("fit", points, "--order", "0/2", "--delay", "--json", models)
    assert res.returncode == 0, res.stderr
    assert json.loads(models.read_text())["models"][0]["delay_s"] == pytest.approx(0.02, rel=1e-4)


def test_fit_says_and_records_what_it_minimised(tmp_path):
    # Noisy points, where the two costs' minima differ: J by default, lower than the J of the
    # relative error's fit (--cost relative, with the file's weights).
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), 15)
    rng = np.random.default_rng(2)
    F = np.polyval(ROLL[0], 1j * omega) / np.polyval(ROLL[1], 1j * omega) * \
        (1 + 0.1 * (rng.normal(size=15) + 1j * rng.normal(size=15)))
    points = tmp_path / "p.csv"
    np.savetxt(points, np.column_stack([omega, np.abs(F), np.unwrap(np.angle(F))]),
               delimiter=",", header="omega_rad_s,magnitude,phase_rad", comments="")
    found = {}
    for name, options in (("j", ()), ("relative", ("--cost", "relative"))):
        models = tmp_path / f"{name}.json"
        res = heliquad("fit", points, "--order", "0/2", "--json", models, *options)
        assert res.returncode == 0, res.stderr
        found[name] = (res.stdout, json.loads(models.read_text()))
    assert "minimised: CIFER's J" in found["j"][0]
    assert "minimised: the weighted relative complex error" in found["relative"][0]
    assert [found[name][1]["cost"] for name in ("j", "relative")] == ["j", "relative"]
    J = {name: found[name][1]["models"][0]["metrics"]["J"] for name in found}
    assert J["j"] < 0.99 * J["relative"]


def test_fit_refuses_an_unknown_cost(tmp_path):
    res = heliquad("fit", tmp_path / "p.csv", "--cost", "dB", "--json", tmp_path / "m.json")
    assert res.returncode == 2 and "invalid choice: 'dB'" in res.stderr
    assert not (tmp_path / "m.json").exists()

def test_fsf_finds_the_frequency_or_takes_it(runs, tmp_path):
    out = tmp_path / "one.csv"
    assert heliquad("fsf", runs[0], "--out", out).returncode == 0
    found = np.loadtxt(out, delimiter=",", skiprows=1)
    assert heliquad("fsf", runs[0], "--freq-hz", 0.5, "--out", out).returncode == 0
    given = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_allclose(found, given, rtol=1e-9)


@pytest.mark.parametrize("sub", ["fsf", "fit"])
def test_help_explains_the_formats(sub):
    res = heliquad(sub, "--help")
    assert res.returncode == 0
    for needle in {"fsf": ["t_s,u,y", "omega_rad_s,magnitude,phase_rad"],
                   "fit": ["omega_rad_s,magnitude,phase_rad", "MODELS.json", "descending"]}[sub]:
        assert needle in res.stdout


def write(path, text):
    path.write_text(text)
    return path


GOOD_RUN = "t_s,u,y\n" + "".join(f"{k / 200},{math.sin(k / 10)},{0.5 * math.sin(k / 10)}\n"
                                   for k in range(2000))
GOOD_POINTS = "omega_rad_s,magnitude,phase_rad\n" + "".join(
    f"{w},{1 / math.hypot(1, w)},{-math.atan(w)}\n" for w in np.logspace(-1, 1, 8))

BAD_FSF = {
    "empty file": ("", "empty file"),
    "header only": ("t_s,u,y\n", "no data rows"),
    "misnamed column": (GOOD_RUN.replace("t_s,u,y", "time,u,y", 1), "missing column"),
    "missing column": ("t_s,u\n0,1\n0.005,2\n", "missing column"),
    "NaN": ("t_s,u,y\n0,1,2\n0.005,nan,3\n0.01,1,1\n", "column u has NaN"),
    "non-numeric": ("t_s,u,y\n0,1,2\n0.005,abc,3\n0.01,1,1\n", "could not convert|abc"),
    "non-increasing time": ("t_s,u,y\n0,1,2\n0.005,1,3\n0.005,1,1\n0.01,1,1\n", "does not increase"),
    "constant input": ("t_s,u,y\n" + "".join(f"{k / 200},1,1\n" for k in range(100)), "constant"),
}


@pytest.mark.parametrize("case", BAD_FSF)
def test_fsf_bad_input_is_one_line_exit_2(case, tmp_path):
    text, match = BAD_FSF[case]
    res = heliquad("fsf", write(tmp_path / "run.csv", text), "--out", tmp_path / "p.csv")
    assert_one_line_error(res, match)
    assert not (tmp_path / "p.csv").exists()


BAD_FIT = {
    "empty file": ("", [], "empty file"),
    "misnamed column": (GOOD_POINTS.replace("omega_rad_s", "omega"), [], "missing column"),
    "NaN": (GOOD_POINTS.replace("\n", "\nnan,1,0\n", 1), [], "NaN"),
    "non-increasing omega": (GOOD_POINTS + "0.5,1,0\n", [], "does not increase"),
    "too few points": ("omega_rad_s,magnitude,phase_rad\n1,1,0\n2,0.5,-1\n", ["--order", "2/4"],
                       "needs at least"),
    "unknown order syntax": (GOOD_POINTS, ["--order", "2-4"], "form M/N"),
    "improper order": (GOOD_POINTS, ["--order", "3/1"], "improper"),
    "dB magnitude": (GOOD_POINTS.replace(",0.", ",-3.", 1), [], "positive"),
    "sigma weights without sigma": (GOOD_POINTS, ["--weights", "sigma"], "no sigma column"),
    "coherence all 0": (GOOD_POINTS.replace("phase_rad", "phase_rad,coherence")
                        .replace("\n", ",0\n").replace("phase_rad,coherence,0", "phase_rad,coherence"),
                        [], "every point has coherence 0"),
    "unknown option": (GOOD_POINTS, ["--frobnicate"], "unrecognized"),
}


@pytest.mark.parametrize("case", BAD_FIT)
def test_fit_bad_input_is_one_line_exit_2(case, tmp_path):
    text, extra, match = BAD_FIT[case]
    res = heliquad("fit", write(tmp_path / "p.csv", text), *extra, "--json", tmp_path / "m.json")
    assert_one_line_error(res, match)
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("F, extra", [
    (lambda w: 3 / (1j * w), ["--allow-unstable"]),           # an integrator: trial poles on a point
    (lambda w: 1 / (1j * w - 2), ["--allow-unstable"]),
    (lambda w: np.full(w.shape, 1e-12 + 0j), []),
])
def test_fit_of_awkward_points_prints_no_warning(F, extra, tmp_path):
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), 10)
    np.savetxt(tmp_path / "p.csv", np.column_stack([omega, np.abs(F(omega)), np.angle(F(omega))]),
               delimiter=",", header="omega_rad_s,magnitude,phase_rad", comments="")
    res = heliquad("fit", tmp_path / "p.csv", *extra, "--json", tmp_path / "m.json",
                   "--plot", tmp_path / "b.png")
    assert res.returncode == 0 and res.stderr == "", res.stderr


def test_missing_file_is_one_line_exit_2(tmp_path):
    assert_one_line_error(heliquad("fit", tmp_path / "nope.csv", "--json", tmp_path / "m.json"),
                          "no such file")
    assert_one_line_error(heliquad("fsf", tmp_path / "nope.csv", "--out", tmp_path / "p.csv"),
                          "no such file")


def assert_one_line_error(res, match):
    import re

    assert res.returncode == 2, (res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr
    assert re.search(match, lines[0]), lines[0]


def _subcommands(parser) -> list:
    import argparse

    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return list(action.choices)


def test_a_command_line_builds_only_the_command_it_names():
    # Every command's module is imported only for --help or a name that is not a command;
    # the name each module's parser takes is the one COMMANDS files it under.
    from heliquad.host.cli.parser import _build_parser
    from heliquad.host.commands import COMMANDS

    assert _subcommands(_build_parser([])) == list(COMMANDS)
    assert _subcommands(_build_parser(["--version"])) == list(COMMANDS)
    assert _subcommands(_build_parser(["identfy", "x"])) == list(COMMANDS)
    assert _subcommands(_build_parser(["-h", "identify"])) == list(COMMANDS)
    assert _subcommands(_build_parser(["--", "identify", "x"])) == list(COMMANDS)
    for name in COMMANDS:
        assert _subcommands(_build_parser([name, "--help"])) == [name]


def test_a_misspelt_command_is_told_the_commands_there_are():
    res = heliquad("identfy", "somewhere")
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert "invalid choice: 'identfy'" in res.stderr and "identify" in res.stderr
    assert "mavlink-dialect" in res.stderr


@pytest.mark.parametrize("given, expected", [(None, "1"), ("2", "2")])
def test_the_command_line_keeps_openblas_to_one_thread_unless_told(given, expected):
    import os

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given:
        env["OPENBLAS_NUM_THREADS"] = given
    res = subprocess.run([sys.executable, "-c", "import os, sys, heliquad.host.cli.parser; "
                          "print(os.environ['OPENBLAS_NUM_THREADS'], 'numpy' in sys.modules)"],
                         capture_output=True, text=True, env=env, timeout=60)
    assert res.stdout.split() == [expected, "False"]          # set before numpy is imported



def multisine_run(path, jitter=0.0, input_noise=0.0):
    """A multisine's periodic steady state through the roll model (seven lines on a 0.25 Hz
    base, 4 periods at 200 Hz) as RUN.csv; the timestamps jittered by ``jitter`` of the
    interval, the logged input with white noise of that standard deviation."""
    fs, base, orders = 200.0, 0.25, [2, 3, 4, 6, 8, 11, 16]
    t = np.arange(4 * int(fs / base)) / fs
    u, y = np.zeros_like(t), np.zeros_like(t)
    for k, l in enumerate(orders):
        w = 2 * np.pi * base * l
        G = np.polyval(ROLL[0], 1j * w) / np.polyval(ROLL[1], 1j * w)
        phase = -np.pi * k * k / len(orders)                        # Schroeder's phases
        u += 0.1 * np.sin(w * t + phase)
        y += 0.1 * abs(G) * np.sin(w * t + phase + np.angle(G))
    rng = np.random.default_rng(3)
    t = t + jitter / fs * rng.uniform(-1, 1, t.size)
    u = u + input_noise * rng.standard_normal(t.size)
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t_s,u,y", comments="")
    return base, orders


@pytest.mark.parametrize("named, jitter", [(None, 0.0), ([2, 4, 8], 0.0), (None, 0.003)])
def test_fsf_of_a_multisine_run_gives_a_point_per_line(named, jitter, tmp_path):
    # Every line, each the model's response to 1e-6; or those named, to 1 % (the lines left
    # out of the FSF's model leak into the others' a little: 0.1 % here); timestamps
    # jittered by 0.3 % of the interval: the base period is still found whole.
    from heliquad.host.records.points import read_points_csv

    base, orders = multisine_run(tmp_path / "ms.csv", jitter=jitter)
    orders = named or orders
    res = heliquad("fsf", tmp_path / "ms.csv", "--freq-hz", base, "--orders", *orders,
                   "--out", tmp_path / "points.csv")
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert f"multisine, {len(orders)} line(s)" in res.stdout
    got = read_points_csv(tmp_path / "points.csv")
    w = 2 * np.pi * base * np.array(orders)
    truth = np.polyval(ROLL[0], 1j * w) / np.polyval(ROLL[1], 1j * w)
    np.testing.assert_allclose([p.omega_rad_s for p in got], w, rtol=1e-4)
    np.testing.assert_allclose([p.gain for p in got], truth, rtol=1e-2 if named else 1e-3 if jitter else 1e-6)


def test_fsf_takes_a_multisine_whose_input_is_noisy_and_refuses_a_wrong_base(tmp_path):
    # Noise in the input as strong as the multisine itself: still a multisine of these lines.
    # The same record read with a base frequency a harmonic off: none of the lines is there.
    base, orders = multisine_run(tmp_path / "ms.csv", input_noise=0.25)
    ok = heliquad("fsf", tmp_path / "ms.csv", "--freq-hz", base, "--orders", *orders,
                  "--out", tmp_path / "points.csv")
    assert ok.returncode == 0 and "multisine, 7 line(s)" in ok.stdout, ok.stderr
    wrong = heliquad("fsf", tmp_path / "ms.csv", "--freq-hz", 2 * base, "--orders", 5, 7,
                     "--out", tmp_path / "other.csv")
    assert_one_line_error(wrong, "exact base frequency")
    assert not (tmp_path / "other.csv").exists()


#: Valid points whose sigmas span 246 decades: weights from 1e8 to 1e-238.
EXTREME_SIGMA = """omega_rad_s,magnitude,phase_rad,sigma
0.0015685468666967863,2.376295660031014e-10,0.13838996184400454,4.027584638572843e+184
0.9023815289310845,29507906.020784054,-0.38167181000867206,1.2217410388488216e-08
42.89224569739084,0.0013788495495198616,-1.1358431679273335,5.205024339095458e+187
294.7254058051131,6.4292450127982316e-12,2.5349908670855195,5.316349095937748e+238
"""


@pytest.mark.parametrize("order, code", [("1/2", 0), ("0/1", 2)])
def test_fit_of_points_with_extreme_sigmas_is_a_model_or_one_line(order, code, tmp_path):
    # Its costs overflow: a model, or "no fit could be started"; no traceback, no warning.
    (tmp_path / "p.csv").write_text(EXTREME_SIGMA)
    res = heliquad("fit", tmp_path / "p.csv", "--order", order, "--json", tmp_path / "m.json")
    assert res.returncode == code
    assert res.stderr == "" if code == 0 else \
        res.stderr.count("\n") == 1 and "no fit could be started" in res.stderr, res.stderr


def test_the_boards_backlog_option_and_the_simulator_agree_on_its_bound():
    # heliquad board --backlog-bytes: the simulator's default is the parser's largest value,
    # the firmware's bound on its pty.
    assert TELEMETRY_BACKLOG_BYTES == MAX_PTY_BACKLOG_BYTES
    res = heliquad("board", "--backlog-bytes", MAX_PTY_BACKLOG_BYTES + 1)
    assert res.returncode == 2 and f"outside 0..{MAX_PTY_BACKLOG_BYTES}" in res.stderr, res.stderr
