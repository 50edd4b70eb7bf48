"""``heliquad verify DIR``: tuned gains proven on the board, or the previous ones restored
(docs/verification.md).

On one session (the simulated rig, or a board's port): the board hovers, the parameters the
axis's tuned gains change are read and kept in ``DIR/previous.params`` before anything is
set, the tuned values are set and read back, then the sweeps fly (the rate setpoint's, and
for roll and pitch the angle setpoint's, each in ``DIR/verify/AXIS/INJECT`` with one
``session.tlog`` beside them), each loop is measured from its sweep and judged against
tune.json's prediction (:mod:`heliquad.host.validate.verification`). Rejected, or ended
early (a sweep stopped, Ctrl-C), the previous gains go back on the board and are read back.
Whatever happened is written to ``DIR/verify.json``, which says which gains the board holds.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import os

import numpy as np

from ...sim.base.dialect import dialect
from ...sim.base.errors import BoardRefused, FirmwareError, InputError, LinkLost
from ...sim.base.firmware_facts import LOOP_RATE_HZ, MAX_FREQ_FRACTION, MIN_FREQ_HZ
from ...sim.rig.setup import SilConfig
from ..acquire.design import INPUT_FRACTION
from ..acquire.excitation import amplitude_bound, firmware_amplitude
from ..acquire.multisine import FADE_CYCLES, MAX_LINES, MIN_PERIODS
from ..acquire.param_protocol import (Param, ParamClient, ParamRefused,
                                      SessionLink, same_value, value_text)
from ..acquire.session import SilSession
from ..acquire.sweep import SWEEP_TLOG, default_plan, multisine_plan, run_sweep, sil_source
from ..process.signals import ABORTED_BY, EXIT_CODES, WORDS, stopped_by
from ..records.gains import recorded_gains
from ..records.params_file import TYPE_NAMES, read_params_file, write_params_file
from ..records.tlog import TlogDamage, imu_path_of, read_tlog_table
from ..records.tune import read_tune
from ..records.verify import VerifyFile, read_verify, write_verify_json
from ..validate.verification import (CROSSOVERS, FLOOR, SWEEP_OF_LOOP, judge, margins_only,
                                     measured_margins, sorted_points, sweep_band,
                                     truth_margins)
from ..validate.truth import sil_truth_loops
from .sweep_points import estimate_points

__all__ = ["VerifyPlan", "verify_axis", "read_tune_dir", "prepare_verification",
           "run_verification", "sil_session", "PREVIOUS_PARAMS", "VERIFY_JSON",
           "SESSION_TLOG"]

PREVIOUS_PARAMS = "previous.params"
VERIFY_JSON = "verify.json"
SESSION_TLOG = "session.tlog"
#: The lowest line a sweep may have: twice the firmware's band's bottom (a multisine's base
#: frequency lies below its lowest line); and its top: the firmware's band or a multisine's
#: quarter of the loop rate, 2 % below (a line moves to the nearest harmonic of the base).
BOTTOM_RAD_S = 2 * math.pi * MIN_FREQ_HZ * 2
TOP_RAD_S = 2 * math.pi * min(MAX_FREQ_FRACTION, 0.25) * LOOP_RATE_HZ * 0.98
#: MAV_PARAM_TYPE of a real parameter (a line of previous.params without its type).
REAL32 = next(k for k, v in TYPE_NAMES.items() if v == "REAL32")
#: The rate setpoint sweep's peak unless given, firmware units: 20 deg/s (a tenth of the
#: firmware's bound; at 10 deg/s moderate turbulence hides the roll rate loop near its
#: crossover, docs/verification.md), and no more than lets the axis's command swing by the
#: sweep design's linear share of its bound (design.INPUT_FRACTION): at the sweep's top
#: lines the plant no longer follows, so the command swings by about Kc times the peak (the
#: yaw rate loop, Kc 4.4, measures a gain margin 2 dB too high at 20 deg/s). The angle
#: setpoint's peak is the sweep's default (5 deg).
RATE_PEAK = firmware_amplitude("rate", 20.0)
#: A multisine sweep's rig time unless given, s; a loop whose lowest line needs longer gets
#: the least that holds its periods and fades (times LEAST_SLACK: the base period lies a
#: little below the lowest line).
RIG_TIME_S = 20.0
LEAST_SLACK = 1.1
#: A dwell's frequencies per loop.
DWELL_FREQUENCIES = 8
#: How long the simulated board waits between frames before it takes its simulator for
#: gone, s of wall time: verify measures the loops (and the truth) with the board held
#: between two frames, which on a loaded machine takes longer than a firmware's default
#: 10 s, and it must then still be there to land, or to take its previous gains back.
SIL_IDLE_TIMEOUT_S = 600


@dataclasses.dataclass
class VerifyPlan:
    """What a verification does: the axis, tune.json (``tune``, a TuneFile, read from
    ``dir``), the values it loads (``entries``: ``(name, value)`` from tuned.params), the
    sweeps' signal (``multisine`` or ``dwell``) with its lines, rig time per sweep and
    cycles, and their amplitudes per injection (firmware units; None: the sweep's default)."""

    axis: str
    dir: str
    tune: object
    entries: list
    signal: str = "multisine"
    lines: int | None = None
    rig_time_s: float | None = None
    cycles: int | None = None
    amplitudes: dict = dataclasses.field(default_factory=dict)
    board: str = "sil"

    @property
    def loops(self) -> tuple:
        # every loop a sweep measures; yaw flies its rate loop alone
        return tuple(k for k in SWEEP_OF_LOOP if self.axis != "yaw" or k == "rate")

    def predicted(self, loop: str) -> dict:
        """tune.json's prediction of the tuned ``loop`` (InputError when it has none)."""
        found = self.tune.axes[self.axis]["tuned"]["loops"].get(loop)
        if found is None or not any(found.get(k) for k in CROSSOVERS):
            what = "has no prediction" if found is None else "predicts no crossover"
            raise InputError(f"tune.json {what} of the tuned {self.axis} {loop} loop: verify "
                             "has nothing to measure it against")
        return found

    def sweep_plan(self, loop: str):
        """The sweep that measures ``loop``, its band from the loop's predicted crossovers,
        and that band (rad/s)."""
        inject = SWEEP_OF_LOOP[loop]
        low, high = sweep_band(self.predicted(loop), TOP_RAD_S, BOTTOM_RAD_S)
        band_hz = (low / (2 * math.pi), high / (2 * math.pi))
        amplitude = self.amplitudes.get(inject)
        if amplitude is None and inject == "rate":
            kc = self.tune.axes[self.axis]["tuned"]["gains"]["rate"][0]
            amplitude = min(RATE_PEAK, INPUT_FRACTION * amplitude_bound("mixer") / kc)
        if self.signal == "multisine":
            # the least that holds the design's whole periods and fades of its lowest line
            least = (MIN_PERIODS + 2 * FADE_CYCLES) / band_hz[0] * LEAST_SLACK
            plan = multisine_plan(self.axis, inject, amplitude, self.lines or MAX_LINES,
                                  max(self.rig_time_s or RIG_TIME_S, least), band_hz=band_hz)
        else:
            freqs = np.geomspace(*band_hz, self.lines or DWELL_FREQUENCIES)
            plan = default_plan(self.axis, inject, freqs, amplitude, self.cycles)
        return plan, [low, high]


class _Board:
    """The board's gains while verify runs: what it held before (``previous``, the
    parameters as read), and which it holds now (``holds``: tuned, previous or unknown)."""

    def __init__(self, session, progress):
        self.client = ParamClient(SessionLink(session))
        self.progress = progress
        self.params: dict[str, Param] = {}
        self.previous: dict[str, float] = {}
        self.holds = "previous"

    def read(self, names) -> None:
        self.params = {p.name: p for p in self.client.fetch_all()}
        missing = [n for n in names if n not in self.params]
        if missing:
            raise BoardRefused(f"the board has no parameter {missing[0]} (tuned.params sets "
                               "it): is it heliquad's firmware?")
        self.previous = {n: self.params[n].value for n in names}

    def load(self, entries, what: str) -> None:
        """Set ``entries`` and read each back; ``holds`` is unknown until all are."""
        self.holds = "unknown"
        for name, value in entries:
            self.client.set(self.params[name], value)
        for name, value in entries:
            got = self.client.get(name)
            if not same_value(got.value, value):
                raise BoardRefused(f"{name} reads back {got.text()} after it was set to "
                                   f"{value:g}")
        self.holds = what
        self.progress(f"the {what} gains are on the board, read back: " + ", ".join(
            f"{n} {value_text(v, self.params[n].type)}" for n, v in entries))

    def restore(self) -> dict | None:
        """The previous gains back (best effort: a refusal or a lost link is said, and
        ``holds`` stays unknown); what was restored, or None."""
        try:
            self.load(list(self.previous.items()), "previous")
        except (ParamRefused, BoardRefused, LinkLost) as exc:
            self.progress(f"the previous gains could not be restored: {exc}")
            return None
        return dict(self.previous)


def _keep_previous(plan: VerifyPlan, board: _Board) -> None:
    """DIR/previous.params: the board's values of what verify sets, before it sets any
    (beside those an earlier run kept for other parameters)."""
    path = os.path.join(plan.dir, PREVIOUS_PARAMS)
    kept = {}
    if os.path.exists(path):          # an earlier run's, for another axis: its lines kept
        kept = {p.name: Param(p.name, p.value, p.type or REAL32, -1)
                for p in read_params_file(path)}
    for name, value in board.previous.items():
        kept[name] = Param(name, value, board.params[name].type, -1)
    write_params_file(path, kept.values(), header="heliquad verify: the gains the board held "
                      "before the tuned ones were set")


def read_tune_dir(dir_path: str, axis: str | None = None) -> tuple:
    """``(tune.json's TuneFile, the axis, the tuned values it loads)`` of a tune folder:
    tune.json and tuned.params there, the axis tuned (``None``: the file's only one),
    tuned.params holding tune.json's values. InputError in one line otherwise."""
    if not os.path.isdir(dir_path):
        raise InputError(f"{dir_path} is not a folder (heliquad tune --out DIR writes one)")
    paths = [os.path.join(dir_path, n) for n in ("tune.json", "tuned.params")]
    for path in paths:
        if not os.path.isfile(path):
            raise InputError(f"{dir_path} has no {os.path.basename(path)} (heliquad tune "
                             "--out DIR writes tune.json and tuned.params)")
    tune = read_tune(paths[0])
    tuned = {p.name: p.value for p in read_params_file(paths[1])}
    if axis is None:
        if len(tune.axes) > 1:
            raise InputError(f"{paths[0]} tunes {', '.join(tune.axes)}: give --axis (the rig "
                             "frees one axis; verify one per run)")
        axis = next(iter(tune.axes))
    if axis not in tune.axes:
        raise InputError(f"--axis {axis}: {paths[0]} tunes {', '.join(tune.axes)} only")
    entries = []
    for name, value in tune.axes[axis]["params"].items():
        if name not in tuned or not same_value(tuned[name], value):
            raise InputError(f"{paths[1]}: {name} is "
                             f"{'missing' if name not in tuned else tuned[name]}, tune.json "
                             f"says {value:g} (tuned.params and tune.json are not of one run)")
        entries.append((name, tuned[name]))
    return tune, axis, entries


def prepare_verification(dir_path: str, axis: str | None, **options) -> VerifyPlan:
    """The plan of a verification of ``axis`` from a tune folder (``options``: VerifyPlan's
    sweep settings and ``board``), every sweep it will fly checked now (a band or amplitude
    the firmware refuses is said before the board is touched); InputError when the folder
    holds an earlier verification of the axis."""
    tune, axis, entries = read_tune_dir(dir_path, axis)
    plan = VerifyPlan(axis=axis, dir=dir_path, tune=tune, entries=entries, **options)
    for loop in plan.loops:
        plan.sweep_plan(loop)
    axis_dir = os.path.join(dir_path, "verify", axis)
    if os.path.lexists(axis_dir):
        raise InputError(f"{axis_dir} holds an earlier verification of {axis}: move it away "
                         "first (verify.json keeps what it found)")
    return plan


def sil_session(axis: str, tlog: str, **cfg) -> tuple:
    """``(session, manifest source)``: the simulated board on the axis's rig, the 6-DoF
    vehicle (``cfg``: SilConfig's ``params``, ``turbulence``, ``seed``, ``ideal_sensor``,
    ``collective``, ``param_store``)."""
    config = SilConfig(axis=axis, rig=axis, inject="rate", plant="vehicle",
                       idle_timeout_s=SIL_IDLE_TIMEOUT_S,
                       **{k: v for k, v in cfg.items() if v is not None})
    source = sil_source(config)
    try:
        session = SilSession(config, tlog)
    except FirmwareError as exc:
        raise InputError(str(exc)) from None
    source["firmware"] = session.fw.record()
    return session, source


def run_verification(plan: VerifyPlan, open_session, progress=print) -> tuple:
    """:func:`verify_axis` of ``plan`` on the session ``open_session(axis, tlog path)`` opens
    (a ``(session, manifest source)``), in ``DIR/verify/AXIS``; the session closed after,
    a simulated board landed first so that its firmware saves the parameters changed while
    it flew (its parameter store). Returns verify_axis's ``(exit code, lines)``."""
    axis_dir = os.path.join(plan.dir, "verify", plan.axis)
    os.makedirs(axis_dir)
    session, source = open_session(plan.axis, os.path.join(axis_dir, SESSION_TLOG))
    try:
        progress(f"verify: {plan.axis} on {plan.board} -> {axis_dir}")
        return verify_axis(session, source, plan, progress)
    finally:
        try:
            if isinstance(session, SilSession):
                _land(session)
        finally:
            session.close()


def _land(session) -> None:
    """The simulated board lands (its firmware saves what changed while it flew); one that
    went away first is said in one line (verify.json already says what it held)."""
    try:
        session.land()
    except FirmwareError as exc:
        raise LinkLost(f"the simulated board went away before it landed ({exc}): parameters "
                       "changed while it flew are not saved in its parameter store") from None


def verify_axis(session, source: dict, plan: VerifyPlan, progress=print) -> tuple:
    """Verify ``plan``'s axis on ``session`` (``source``: the sweeps' manifest source).
    Returns ``(exit code, lines)``: 0 accepted; 1 rejected, one line per failed loop, or a
    sweep that stopped early; a signal's code. A lost link or a refusal is raised again,
    saying which gains the board holds, once verify.json says it too."""
    axis_dir = os.path.join(plan.dir, "verify", plan.axis)
    entry = {"board": plan.board, "started": datetime.datetime.now(datetime.timezone.utc)
             .isoformat(timespec="seconds"), "verdict": "unfinished", "board_holds": "previous",
             "said": [], "loaded": dict(plan.entries), "previous": {}, "restored": None,
             "sweeps": {}, "band_rad_s": {}, "loops": {}}
    board = _Board(session, progress)
    try:
        session.hover(progress)
        board.read([n for n, _ in plan.entries])
        entry["previous"] = dict(board.previous)
        _keep_previous(plan, board)
        board.load(plan.entries, "tuned")
        manifests, aborted = _fly(session, source, plan, axis_dir, entry, progress)
        if aborted is None:
            _judge(plan, axis_dir, manifests, entry, progress)
        if entry["verdict"] != "accepted":
            entry["restored"] = board.restore()
    except (InputError, OSError, FirmwareError) as exc:   # the link lost, a refusal, a disk
        lost = isinstance(exc, (LinkLost, FirmwareError))   # the firmware died: gone as well
        if board.holds != "previous" and not lost:
            entry["restored"] = board.restore()
        said = f"the board went away: {exc}" if isinstance(exc, FirmwareError) else str(exc)
        entry["said"].append(f"ended: {said}")
        _write(plan, entry, board)
        if isinstance(exc, OSError):
            raise
        kind = LinkLost if lost else BoardRefused if isinstance(exc, BoardRefused) else InputError
        raise kind(f"{said}; {_holds_text(board)}") from None
    except KeyboardInterrupt as exc:
        how = stopped_by(exc)
        entry["restored"] = board.restore()
        entry["said"].append(f"ended: {ABORTED_BY[how]}")
        _write(plan, entry, board)
        return EXIT_CODES[how], [f"{WORDS[how]}: {_holds_text(board)}"]
    _write(plan, entry, board)
    if aborted is not None:
        code = next((EXIT_CODES[s] for s, how in ABORTED_BY.items() if aborted == how), 1)
        return code, [f"the sweep stopped: {aborted}; {_holds_text(board)}"]
    lines = [f"{plan.axis} {loop} loop: {'; '.join(r['failures'])}"
             for loop, r in entry["loops"].items() if r["failures"]]
    if entry["verdict"] == "accepted":
        return 0, []
    return 1, [*lines, f"rejected: {_holds_text(board)}"]


def _fly(session, source, plan: VerifyPlan, axis_dir: str, entry: dict, progress) -> tuple:
    """The sweeps, one per loop: ``({loop: manifest}, None)``, or ``(those flown, why the
    last stopped early)``."""
    manifests = {}
    for loop in plan.loops:
        sweep, band = plan.sweep_plan(loop)
        sweep_dir = os.path.join(axis_dir, sweep.inject)
        os.makedirs(sweep_dir)
        os.symlink(os.path.join("..", SESSION_TLOG), os.path.join(sweep_dir, SWEEP_TLOG))
        entry["sweeps"][loop] = os.path.relpath(sweep_dir, plan.dir)
        entry["band_rad_s"][loop] = band
        progress(f"the {loop} loop: {sweep.inject} setpoint sweep, {sweep.signal} "
                 f"{band[0]:.3g}-{band[1]:.3g} rad/s -> {sweep_dir}")
        manifests[loop] = run_sweep(session, sweep, sweep_dir, source, progress)
        if not manifests[loop]["complete"]:
            entry["said"].append(f"the {loop} loop's sweep stopped: "
                                 f"{manifests[loop]['aborted']}")
            return manifests, manifests[loop]["aborted"]
    return manifests, None


def _judge(plan: VerifyPlan, axis_dir: str, manifests: dict, entry: dict, progress) -> None:
    """Each loop measured from its sweep, against the truth on the simulated rig, judged;
    the axis's verdict."""
    damage = TlogDamage()
    tlog = os.path.join(axis_dir, SESSION_TLOG)
    samples = read_tlog_table(tlog, dialect(), "HQ_SYSID_SAMPLE", damage=damage)
    imu_path = imu_path_of(tlog, dialect())
    gains = recorded_gains(plan.tune.axes[plan.axis]["tuned"]["gains"])
    spec = plan.tune.spec
    for loop, manifest in manifests.items():
        points = estimate_points(manifest, samples, "excitation", progress)[0]
        omega, closed, sigma = sorted_points(points)
        if len(omega) < 2:
            raise InputError(f"the {loop} loop's sweep gave {len(omega)} usable points")
        predicted = plan.predicted(loop)
        measured = measured_margins(omega, closed, gains, loop, sigma)
        allowed, failures = judge(predicted, measured, spec)
        record = {"sweep": entry["sweeps"][loop],
                  "predicted": {**margins_only(predicted),
                                **{f"uncertainty_{k}": v for k, v in
                                   (predicted.get("uncertainty") or {}).items()}},
                  "allowed": allowed, "measured": measured, "passed": not failures,
                  "failures": failures}
        truth = _truth(manifest, os.path.join(plan.dir, entry["sweeps"][loop]), gains, loop,
                       entry["band_rad_s"][loop], imu_path)
        if truth is not None:
            record["truth"] = truth
        entry["loops"][loop] = record
        progress(f"the {loop} loop: {_compare(record)}")
    entry["verdict"] = "accepted" if all(r["passed"] for r in entry["loops"].values()) \
        else "rejected"


def _truth(manifest, sweep_dir, gains, loop, band, imu_path):
    """The loop's margins around the simulator's truth (a simulated sweep's, its logged
    angle as the firmware on ``imu_path`` makes it), or None."""
    found, _ = sil_truth_loops(manifest, sweep_dir, imu_path)
    if found is None or (loop == "angle" and found[1] is None):
        return None
    return truth_margins(*found, gains, loop, band)


def _compare(record) -> str:
    """Predicted, measured (and the truth's) margins of a loop, in one line."""
    def text(m, key, unit):
        v = (m or {}).get(key)
        return "none" if v is None else f"{v:.1f} {unit}"

    out = []
    for key, unit in (("phase_margin_deg", "deg"), ("gain_margin_db", "dB")):
        held = (" (extrapolated: held to the specification only)"
                if key in record["predicted"].get("extrapolated", ()) else
                f" +/- {record['allowed'][key]:.1f}")
        own = (record["measured"].get("uncertainty") or {}).get(key)
        said = (f"{key.split('_margin')[0]} margin predicted {text(record['predicted'], key, unit)}"
                f"{held}, measured {text(record['measured'], key, unit)}"
                + (f" +/- {own:.1f}" if own and record["measured"].get(key) is not None else ""))
        if "truth" in record:
            said += f", truth {text(record['truth'], key, unit)}"
        out.append(said)
    return "; ".join(out) + ("" if record["passed"] else " (failed)")


def _holds_text(board: _Board) -> str:
    return {"tuned": "the board holds the tuned gains",
            "previous": "the board holds its previous gains",
            "unknown": "the board may hold some of the tuned gains: check them with heliquad "
                       "params, or load previous.params"}[board.holds]


def _write(plan: VerifyPlan, entry: dict, board: _Board) -> None:
    """verify.json with this axis's entry (and the other axes' of an earlier run)."""
    entry["board_holds"] = board.holds
    path = os.path.join(plan.dir, VERIFY_JSON)
    axes = dict(read_verify(path).axes) if os.path.exists(path) else {}
    axes[plan.axis] = entry
    write_verify_json(path, VerifyFile(tune="tune.json", spec=dict(plan.tune.spec),
                                       floor=dict(FLOOR), axes=axes))
