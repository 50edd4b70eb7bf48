"""heliquad study: a spec's runs are the combinations of its factors, each named and seeded
from them; a run is what a user makes by hand with the same options (same numbers); a study
resumes from its run folders' records (a finished run is never made again, an unfinished
one is, a failed one is a row with its error); the table holds one row per run."""

from __future__ import annotations

import cmath
import io
import json
import math
import os
import re
import subprocess
import sys
import threading
import tomllib

import pyarrow.parquet as pq
import pytest

from heliquad.host.commands.study import command_line, option_names, run_command
from heliquad.host.records.points import read_points_csv
from heliquad.host.study import runs
from heliquad.host.study.execute import forget, plan
from heliquad.host.study.spec import parse_spec
from heliquad.sim.base.errors import InputError
from tool_runs import HANG_GUARD_S, children, cmdline

COMMANDS = option_names()


def spec(text: str):
    return parse_spec(tomllib.loads(text), COMMANDS, "s.toml")


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600, cwd=cwd)


# --- the spec -------------------------------------------------------------------------------

GRIDS = """
[factors]
axis = ["roll", "yaw"]
[[grid]]
turbulence = "none"
seed = [1]
[[grid]]
turbulence = ["light", "severe"]
seed = {first = 1, count = 2}
[sweep]
signal = "multisine"
"""


def test_the_runs_are_every_combination_of_each_grid():
    s = spec(GRIDS)
    got = [(r.factors["axis"], r.factors["turbulence"], r.seed) for r in s.runs]
    assert got == [("roll", "none", 1), ("yaw", "none", 1)] + [
        (a, t, n) for a in ("roll", "yaw") for t in ("light", "severe") for n in (1, 2)]
    assert s.factor_names == ("axis", "turbulence", "seed")
    still = s.runs[0]
    assert "turbulence" not in still.options["sweep"]          # "none": the option left out
    assert still.options["sweep"]["signal"] == "multisine"     # [sweep]: every run's
    assert len({r.name for r in s.runs}) == len(s.runs)
    assert [r.name for r in s.runs] == [r.name for r in spec(GRIDS).runs]   # deterministic


def test_a_run_without_a_seed_has_one_derived_from_its_options():
    a = spec('[factors]\naxis = ["roll", "pitch"]\n')
    b = spec('[factors]\naxis = ["roll", "pitch"]\n')
    assert [r.seed for r in a.runs] == [r.seed for r in b.runs]
    assert a.runs[0].seed != a.runs[1].seed
    # another shared option: other runs (other names and seeds), never the old records
    c = spec('[factors]\naxis = ["roll", "pitch"]\n[sweep]\nlines = 6\nsignal = "multisine"\n')
    assert not {r.name for r in a.runs} & {r.name for r in c.runs}


@pytest.mark.parametrize("text, says", [
    ('[factors]\naxis = ["roll"]\nwind = [1]\n', "unknown factor 'wind'"),
    ('[factors]\naxis = []\n', "the grid is empty"),
    ('[factors]\naxis = ["roll", "roll"]\n', "repeats a value"),
    ('[factors]\naxis = ["roll"]\nlines = {count = 2}\n', "for seed only"),
    ('[factors]\naxis = ["roll"]\nport = ["/dev/ttyACM0"]\n', "set by the study itself"),
    ('[factors]\naxis = ["roll"]\n[identify]\nlines = 4\n', "unknown option of heliquad identify"),
])
def test_a_bad_spec_says_what_is_wrong(text, says):
    with pytest.raises(InputError, match=says):
        spec(text)


def test_a_runs_command_lines_are_the_ones_a_user_types():
    assert command_line("sweep", {"axis": "roll", "freqs-hz": [1, 2.5], "ideal-sensor": True,
                                  "seed": 3}, "F") == \
        ["sweep", "--axis", "roll", "--freqs-hz", "1", "2.5", "--ideal-sensor", "--seed", "3",
         "--sil", "--out", "F"]
    assert command_line("identify", {"delay": False, "order": ["0/2", "1/3"]}, "F") == \
        ["identify", "--no-delay", "--order", "0/2", "--order", "1/3", "F"]
    assert command_line("validate", {"turbulence": "severe"}, "F") == \
        ["validate", "--turbulence", "severe", os.path.join("F", "models.json")]
    assert command_line("tune", {"phase-margin": 50.0}, "F") == \
        ["tune", "--phase-margin", "50.0", os.path.join("F", "models.json"), "--out",
         os.path.join("F", "tuned")]


def test_validate_and_tune_are_steps_only_where_the_spec_asks():
    assert set(spec(ONE).runs[0].options) == {"sweep", "identify"}
    asked = spec(ONE + "[validate]\nturbulence = 'severe'\n[tune]\n").runs[0].options
    assert asked["validate"] == {"turbulence": "severe"} and asked["tune"] == {}
    # a factor of validate's alone asks for it too
    by_factor = spec('[factors]\naxis = "roll"\nmodel = [0, 1]\n').runs
    assert [r.options["validate"] for r in by_factor] == [{"model": 0}, {"model": 1}]
    assert "tune" not in by_factor[0].options
    # a spec without them names its runs as before they could be asked for (a study's
    # folder made then is resumed, not made again); one with them makes other runs
    assert [r.name for r in spec(ONE).runs] == ["roll-1-dcc09b69", "roll-2-a0c6dcb7",
                                                "roll-3-d0b9f380"]
    assert spec(ONE + "[validate]\n").runs[0].name != "roll-1-dcc09b69"


def test_a_run_that_validates_and_tunes_records_their_figures(tmp_path):
    run = spec('[factors]\naxis = "roll"\nseed = 1\n[sweep]\nsignal = "multisine"\n'
               'rig-time = 20\ntuning-band = true\n[validate]\n[tune]\n').runs[0]
    record = runs.perform_run(run, str(tmp_path), run_command, command_line)
    assert record["status"] == runs.FINISHED, record["error"]
    assert record["commands"][2:] == ["heliquad validate sweep/models.json",
                                      "heliquad tune sweep/models.json --out sweep/tuned"]
    folder = tmp_path / "runs" / run.name / "sweep"
    validation = json.loads((folder / "validation.json").read_text())
    assert record["validated_stable"] is validation["stable"] is True
    assert record["truth_phase_margin_deg"] == validation["truth_loops"]["input"][
        "phase_margin_deg"]
    tuned = json.loads((folder / "tuned" / "tune.json").read_text())["axes"]["roll"]
    assert record["tuned_meets_spec"] is tuned["meets_spec"] is True
    assert record["tuned_gains"] == tuned["tuned"]["gains"]
    assert record["tuned_phase_margin_deg"] >= 45.0           # tune's default specification
    assert record["verdicts"] is None


@pytest.mark.pil
def test_a_firmware_factor_flies_the_teensy_image_in_its_runs(tmp_path):
    # the exact image in the emulated chip, as `sweep --firmware teensy35` flies it: the
    # same run's points within a gyro step of the host build's (measured 0.01 dB)
    made = {}
    for run in spec('[factors]\naxis = "roll"\nseed = 1\nfirmware = ["host", "teensy35"]\n'
                    '[sweep]\nsignal = "multisine"\nrig-time = 10\nlines = 5\n').runs:
        record = runs.perform_run(run, str(tmp_path), run_command, command_line)
        assert record["status"] == runs.FINISHED, record["error"]
        made[run.factors["firmware"]] = record
    assert "--firmware teensy35" in made["teensy35"]["commands"][0]
    host, image = (read_points_csv(tmp_path / "runs" / made[f]["run"] / "sweep" / "points.csv")
                   for f in ("host", "teensy35"))
    assert len(host) == len(image) == 5
    for p, q in zip(host, image):
        assert abs(20 * math.log10(abs(q.gain / p.gain))) < 0.1
        assert abs(math.degrees(cmath.phase(q.gain / p.gain))) < 0.5


def test_a_verdict_of_validate_or_tune_is_said_and_the_run_goes_on(tmp_path):
    def command(words, log):
        return {"validate": 1, "tune": 1}.get(words[0], 0)

    run = spec(ONE + "[validate]\n[tune]\n").runs[0]
    record = runs.perform_run(run, str(tmp_path), command, fake_line)
    assert record["status"] == runs.FAILED          # no models.json: its figures cannot be read
    assert record["verdicts"] == ("validate: the cascade is unstable with the model; tune: the "
                                  "sweep's band forbids the specification (nothing written)")
    assert record["validate_s"] >= 0 and record["tune_s"] >= 0   # both made

    def failing(words, log):
        return 1 if words[0] == "identify" else 0

    run = spec(ONE + "[validate]\n").runs[1]
    record = runs.perform_run(run, str(tmp_path), failing, fake_line)
    assert record["error"] == "RuntimeError: heliquad identify ended with exit code 1 (see run.log)"
    assert "validate_s" not in record                # nothing after a failed step


def test_threads_running_commands_at_once_each_write_their_own_log(tmp_path):
    # a Dask worker with several threads: each run's output in its own run.log, none lost
    logs = {i: io.StringIO() for i in (1, 2)}
    threads = [threading.Thread(target=run_command, args=(
        ["sweep", "--sil", "--axis", "roll", "--seed", str(i), "--signal", "multisine",
         "--lines", "4", "--rig-time", "10", "--out", str(tmp_path / f"s{i}")], logs[i]))
        for i in logs]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i, log in logs.items():
        assert log.getvalue().count("next: heliquad identify") == 1
        assert str(tmp_path / f"s{i}") in log.getvalue()
        assert str(tmp_path / f"s{3 - i}") not in log.getvalue()


# --- a run's folder, and resuming -----------------------------------------------------------

ONE = '[factors]\naxis = ["roll"]\nseed = [1, 2, 3]\n'


def fake_line(step, options, folder):
    return [step, folder]


def test_a_studys_commands_draw_in_their_worker_and_others_in_a_process_of_their_own():
    from heliquad.host.present.plot_process import (InlinePlots, PlotProcess, command_plots,
                                                    drawing_here)

    seen = {}
    with drawing_here():
        seen["here"] = type(command_plots())
        other = threading.Thread(target=lambda: seen.update(other=command_plots()))
        other.start()
        other.join()
    with seen["other"] as plots:                 # another thread: its own process, closed
        assert isinstance(plots, PlotProcess)
    assert seen["here"] is InlinePlots
    with command_plots() as plots:
        assert isinstance(plots, PlotProcess)


def test_a_run_that_raises_is_a_failed_record_with_its_error(tmp_path):
    def command(words, log):
        raise InputError("the rig fell over")

    run = spec(ONE).runs[0]
    record = runs.perform_run(run, str(tmp_path), command, fake_line)
    assert record["status"] == runs.FAILED and record["error"] == "the rig fell over"
    assert runs.read_record(runs.run_folder(str(tmp_path), run.name)) == record


def test_an_unfinished_run_is_made_again_and_a_finished_one_never(tmp_path):
    s = spec(ONE)
    finished, unfinished, never = s.runs
    calls = []

    def command(words, log):
        calls.append(words[0])
        raise RuntimeError("stop here")            # a failed record: the run is over

    out = str(tmp_path)
    runs.perform_run(finished, out, command, fake_line)
    left = runs.run_folder(out, unfinished.name)        # started, stopped mid-sweep
    os.makedirs(os.path.join(left, runs.SWEEP))
    with open(os.path.join(left, runs.STARTED), "w") as f:
        json.dump({"attempt": 1}, f)
    with open(os.path.join(left, runs.SWEEP, "sweep.tlog"), "wb") as f:
        f.write(b"half a log")
    kept, todo = plan(s, out)
    assert list(kept) == [finished.name] and todo == [unfinished, never]
    calls.clear()
    record = runs.perform_run(unfinished, out, lambda w, log: 0 if calls.append(w) else
                              _raise(), fake_line)
    assert record["attempt"] == 2
    assert not os.path.exists(os.path.join(left, runs.SWEEP, "sweep.tlog"))   # cleared first
    # a retried task whose run finished meanwhile returns its record, making nothing
    again = runs.perform_run(finished, out, command, fake_line)
    assert again == runs.read_record(runs.run_folder(out, finished.name))
    assert calls == [["sweep", os.path.join(left, runs.SWEEP)]]
    # --retry-failed: the failed runs are to make again (their records removed only when
    # they are handed out: a dry run changes nothing)
    _, todo = plan(s, out, retry_failed=True)
    assert todo == s.runs
    assert runs.read_record(runs.run_folder(out, finished.name))["status"] == runs.FAILED
    forget(out, todo)
    assert runs.read_record(runs.run_folder(out, finished.name)) is None


def _raise():
    raise RuntimeError("the sweep folder has no models.json here")


# --- a study end to end, against the same run made by hand ----------------------------------

STUDY = """
[study]
description = "one run that works, one that identify refuses"
[factors]
axis = "roll"
turbulence = "light"
seed = 3
band = ["none", [0.5, 5]]
[sweep]
signal = "multisine"
lines = 5
rig-time = 10
"""


@pytest.fixture(scope="module")
def scheduler():
    """A Dask scheduler with one worker thread in this process (the study's client is the
    command, in its own)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None, protocol="tcp://", host="127.0.0.1") as cluster:
        yield cluster.scheduler_address


def test_a_study_row_is_the_run_made_by_hand_and_a_rerun_makes_nothing(tmp_path, scheduler):
    (tmp_path / "s.toml").write_text(STUDY)
    res = heliquad("study", "s.toml", "--out", "out", "--scheduler", scheduler, cwd=tmp_path)
    assert res.returncode == 1, res.stderr              # one run failed: said, exit 1
    assert "1 of 2 runs failed" in res.stderr.splitlines()[-1]
    table = pq.read_table(tmp_path / "out" / "study.parquet").to_pylist()
    assert [r["status"] for r in table] == ["finished", "failed"]
    ok, failed = table
    assert failed["error"] == "--band is an option of --from-record"
    # the runs were made in the worker's runners (in this process: the scheduler's worker is
    # a thread here), ended with the study: the cluster's workers keep nothing of it
    assert all(r["worker"].split(":")[1] != str(os.getpid()) for r in table)
    assert [p for p in children(os.getpid()) if "study.runner" in cmdline(p)] == []
    assert ok["seed"] == 3 and ok["axis"] == "roll" and ok["turbulence"] == "light"
    # the row's commands, typed by hand into another folder: the same numbers
    hand = tmp_path / "hand"
    for command in ok["commands"].split(" && "):
        words = command.split()[1:]
        res = heliquad(*[str(hand) if w == "sweep" and i else w for i, w in enumerate(words)],
                       cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    mine = json.loads((tmp_path / "out" / "runs" / ok["run"] / "sweep" / "models.json")
                      .read_text())
    theirs = json.loads((hand / "models.json").read_text())
    assert mine["sil_truth"] == theirs["sil_truth"]
    assert mine["models"] == theirs["models"]
    for picture in ("bode.png", "responses.png"):      # drawn in the worker, not a process
        assert (tmp_path / "out" / "runs" / ok["run"] / "sweep" / picture).stat().st_size > 0
    assert json.loads(ok["model_num"]) == theirs["models"][theirs["recommended"]]["num"]
    assert ok["points_worst_db"] == theirs["sil_truth"]["points_worst_db"]
    # again: nothing left to make, the records untouched
    records = {p: p.read_bytes() for p in (tmp_path / "out" / "runs").glob("*/record.json")}
    res = heliquad("study", "s.toml", "--out", "out", "--scheduler", scheduler, cwd=tmp_path)
    assert "2 runs, 2 already over, 0 to make" in res.stdout
    assert {p: p.read_bytes() for p in records} == records
    assert pq.read_table(tmp_path / "out" / "study.parquet").num_rows == 2
    assert (tmp_path / "out" / "index.html").read_text().count("<tr>") == 3


#: The local cluster the study starts, in a process of its own: a cluster started in the
#: test's process would leave multiprocessing's resource tracker running under it.
WORKER_CALLBACKS = """
import json, warnings
warnings.simplefilter("ignore")                       # Dask's port-in-use notices
from heliquad.host.study.execute import _client, _close
client = _client(1, None)
try:
    callbacks = client.run(lambda dask_worker: {
        name: pc.callback_time for name, pc in dask_worker.periodic_callbacks.items()})
finally:
    _close(client, None)
print(json.dumps(list(callbacks.values())))
"""


def test_the_local_clusters_workers_wake_their_event_loop_seldom():
    # Dask's periodic work in a worker's event loop takes the GIL from the run beside it
    pytest.importorskip("distributed")
    done = subprocess.run([sys.executable, "-c", WORKER_CALLBACKS], capture_output=True,
                          text=True, timeout=HANG_GUARD_S)
    assert done.returncode == 0, done.stderr
    (worker,) = json.loads(done.stdout.strip().splitlines()[-1])
    assert "profile" not in worker and worker["tick"] == 1000
    assert worker["memory_monitor"] == 1000 and worker["monitor"] == 5000
    assert worker["heartbeat"]                                  # the rest as Dask has it


# --- vehicle parameters perturbed per run ---------------------------------------------------

PERTURB = """
[factors]
axis = "roll"
seed = [1, 2, 3, 4]
[perturb]
"body.mass_kg" = {normal = 0.1}
"rig.hinge_damping_n_m_s_rad" = {uniform = 0.5}
"""


def test_perturbed_vehicle_numbers_are_drawn_per_run_and_written_as_a_vehicle_file(tmp_path):
    from heliquad.host.study.perturb import base_text, perturbed_text
    from heliquad.sim.plant.vehicle_params import load_params

    s = spec(PERTURB)
    assert s.columns == ("axis", "seed", "body.mass_kg", "rig.hinge_damping_n_m_s_rad")
    masses = [r.perturb["body.mass_kg"] for r in s.runs]
    assert [r.perturb for r in s.runs] == [r.perturb for r in spec(PERTURB).runs]
    assert len(set(masses)) == len(masses)                     # each run its own draw
    nominal = load_params().body
    for r in s.runs:                                           # uniform: within its width
        assert abs(r.perturb["rig.hinge_damping_n_m_s_rad"] /
                   load_params().rig.hinge_damping_n_m_s_rad - 1) <= 0.5
    path = tmp_path / "vehicle.toml"
    path.write_text(perturbed_text(base_text(None), s.runs[0].perturb))
    got = load_params(str(path))                               # a vehicle file the sim reads
    assert got.body.mass_kg == masses[0]
    assert got.body.inertia_kg_m2 == nominal.inertia_kg_m2     # the rest as it was


def test_an_arrays_elements_and_the_rotors_numbers_are_drawn_each_its_own(tmp_path):
    from heliquad.host.study.perturb import base_text, perturbed_text
    from heliquad.sim.plant.vehicle_params import load_params

    s = spec('[factors]\naxis = "roll"\nseed = [1, 2]\n[perturb]\n'
             '"body.inertia_kg_m2" = {normal = 0.1}\n'
             '"rotors.max_thrust_n" = {uniform = 0.2}\n'
             '"rotors.1.time_constant_s" = {normal = 0.3}\n'
             '"rotors.2.position_m[0]" = {normal = 0.05}\n')
    assert s.columns == ("axis", "seed", "body.inertia_kg_m2[0]", "body.inertia_kg_m2[1]",
                         "body.inertia_kg_m2[2]", *(f"rotors.{n}.max_thrust_n"
                                                    for n in range(1, 6)),
                         "rotors.1.time_constant_s", "rotors.2.position_m[0]")
    nominal = load_params()
    for run in s.runs:
        drawn = run.perturb
        assert len({drawn[f"body.inertia_kg_m2[{i}]"] for i in range(3)}) == 3  # own draws
        path = tmp_path / f"{run.name}.toml"
        path.write_text(perturbed_text(base_text(None), drawn))
        got = load_params(str(path))                           # a vehicle file the sim reads
        assert list(got.body.inertia_kg_m2) == [drawn[f"body.inertia_kg_m2[{i}]"]
                                                for i in range(3)]
        for n, rotor in enumerate(got.rotors, 1):
            assert rotor.max_thrust_n == drawn[f"rotors.{n}.max_thrust_n"]
            assert abs(rotor.max_thrust_n / nominal.rotors[n - 1].max_thrust_n - 1) <= 0.2
            want = drawn["rotors.1.time_constant_s"] if n == 1 else \
                nominal.rotors[n - 1].time_constant_s
            assert rotor.time_constant_s == want               # the others as they were
        assert got.rotors[1].position_m[0] == drawn["rotors.2.position_m[0]"]
        assert list(got.rotors[1].position_m[1:]) == list(nominal.rotors[1].position_m[1:])
        assert got.body.mass_kg == nominal.body.mass_kg


def test_a_number_whose_line_cannot_be_rewritten_is_refused_before_any_run(tmp_path):
    from heliquad.host.study.perturb import base_text

    text = base_text(None).replace("inertia_kg_m2 = [0.0118, 0.0118, 0.0226]",
                                   "inertia_kg_m2 = [\n  0.0118,\n  0.0118,\n  0.0226,\n]")
    assert "inertia_kg_m2 = [\n" in text
    (tmp_path / "v.toml").write_text(text)
    with pytest.raises(InputError, match=r"body.inertia_kg_m2\[0\]: its line in the vehicle "
                                         "file could not be rewritten"):
        spec(f'[factors]\naxis = "roll"\n[sweep]\nparams = "{tmp_path / "v.toml"}"\n'
             '[perturb]\n"body.inertia_kg_m2" = {normal = 0.1}\n')


@pytest.mark.parametrize("table, says", [
    ('"body.mass_g" = {normal = 0.1}', "not a number of the vehicle file"),
    ('"body.inertia_kg_m2[3]" = {normal = 0.1}', "not a number of the vehicle file"),
    ('"rotors.6.max_thrust_n" = {normal = 0.1}', "not a number of the vehicle file"),
    ('"rotors.spin" = {normal = 0.1}', "a rotor's spin is its direction"),
    ('"rig.hinge.x" = {normal = 0.1}', "not a number of the vehicle file"),
    ('"body.mass_kg" = {lognormal = 0.1}', "give {normal = S} or {uniform = W}"),
    ('"body.mass_kg" = {normal = 2}', "a relative width from 0 to below 1"),
])
def test_a_bad_perturbation_says_what_is_wrong(table, says):
    with pytest.raises(InputError, match=re.escape(says)):
        spec(f'[factors]\naxis = "roll"\n[perturb]\n{table}\n')
