"""Frequency sweeps (``heliquad sweep``): the paper's sine dwells (or one multisine) for one
axis, logged.

The same protocol runs on any session (:mod:`heliquad.host.acquire.session`: the simulated
rig in lockstep, or a Teensy or ``heliquad board`` pty on a port): the session hovers, the
board's parameters and gains are recorded, and each frequency of the plan
(:class:`SweepPlan`) is measured by :func:`heliquad.host.acquire.measure.measure`, its
amplitude designed from the last one's response when the plan leaves it open. Everything is
logged to ``DIR/sweep.tlog``; ``DIR/manifest.json`` (:class:`SweepManifest`: axis,
injection, frequencies requested and used, sample windows, the parameters and gains read
from the board, firmware version, start time, aborts) is rewritten after every frequency, so
Ctrl-C or a breach leaves a valid, identifiable session.

Safety: the firmware enforces its own rules (docs/safety.md): it refuses an excitation out
of bounds or while disarmed, and stops one when its axis passes the abort limits, when the
host's heartbeat stops, or on disarm; HQ_EXCITATION_STATUS says why, and the sweep ends with
that reason in the manifest (``aborted``), never as complete. As a second line the host
stops an excitation whose samples pass the rig's swing or rate limits
(:class:`~heliquad.host.acquire.measure.Limits`, the firmware's own by default).
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import os

import numpy as np

from ...sim.base.errors import DiskFull, FirmwareError, InputError
from .. import __version__
from ..process.signals import ABORTED_BY, stopped_by
from ..records import paper
from ..records.gains import gains_from_params, single
from ..records.manifest import MANIFEST, UNSET, SweepManifest, write_manifest
from .design import SEQUENTIAL_RIG_TIME_S, AmplitudeDesign, Dwell
from .excitation import amplitude_bound, default_amplitude, default_peak
from .measure import MAX_ANGLE_DEG, MAX_RATE_DEG_S, Limits, loss_text, measure, saturation_text
from .chirp import design as chirp_design
from .linearity import LINES as LINEARITY_LINES, REALISATIONS, linearity_design
from .multisine import FADE_CYCLES as MULTISINE_FADE_CYCLES, LINES, RIG_TIME_S, design
from .redesign import SPREAD, Redesign
# Imported here, not when the sweep reads the board: a Ctrl-C that lands in the middle of an
# import leaves Python to end by SIGINT even after the tool has stopped in order.
from .param_protocol import session_params

__all__ = ["SweepPlan", "default_plan", "multisine_plan", "linearity_plan", "chirp_plan", "run_sweep", "sil_source", "SWEEP_TLOG",
           "cut_text", "tuning_freqs_hz"]

SWEEP_TLOG = "sweep.tlog"
N_FREQUENCIES = 15
#: The tuning band, Hz: from the bottom of the axis's Table 1 band up to this top, above the
#: phase crossovers of the vehicle's rate loops (where tune reads their gain margins, up to
#: about 48 Hz), as far as the firmware's excitation reaches at 200 Hz (a quarter of the
#: loop rate; a dwell's frequency is what whole loop steps make of it); the paper's 15
#: frequencies and one. Not lower at the bottom: tune holds the angle loop's crossover
#: inside the band, and from 0.2 Hz it put the rate loops at their gain margin's limit
#: (the simulator's truth 0.4 dB under the spec) and the angle loops' crossovers where the
#: gusts are strongest, which a verification in moderate turbulence measured 6 deg off.
TUNING_TOP_HZ = 45.0
TUNING_FREQUENCIES = 16
MEASURED_CYCLES = 8
FADE_CYCLES = 2


def tuning_freqs_hz(axis: str) -> np.ndarray:
    """The tuning band's frequencies (``heliquad sweep --tuning-band``; the demo's tuning
    sweep): log-spaced from the bottom of the axis's Table 1 band up to
    :data:`TUNING_TOP_HZ`, so that a model fitted to them holds where ``heliquad tune``
    reads every margin of the rate and angle loops (docs/tuning.md)."""
    lo = paper.BANDS_HZ[axis][0]
    return np.logspace(math.log10(lo), math.log10(TUNING_TOP_HZ), TUNING_FREQUENCIES)


class SweepPlan:
    """What a sweep does: axis, injection point, frequencies and amplitudes (firmware units).

    ``amplitudes``: one per frequency, or None for a designed amplitude
    (:class:`~heliquad.host.acquire.design.AmplitudeDesign`, given as ``design``). ``dwell``: a
    :class:`~heliquad.host.acquire.design.Dwell` for the sequential dwell; without one every
    frequency runs ``cycles`` measured cycles (the published dwell)."""

    def __init__(self, axis, inject, freqs_hz, amplitudes, cycles=MEASURED_CYCLES,
                 fade_cycles=FADE_CYCLES, dwell=None, design=None):
        if inject == "angle" and axis == "yaw":
            raise InputError("yaw is rate-only: use --inject rate or mixer")
        self.axis, self.inject = axis, inject
        self.freqs_hz = [float(f) for f in freqs_hz]
        self.amplitudes = [None if a is None else float(a) for a in amplitudes]
        self.cycles, self.fade_cycles = int(cycles), int(fade_cycles)
        self.dwell, self.design = dwell, design
        self.multisine = None
        self.chirp = None
        self.sequential = None                  # a multisine's SequentialMultisine
        self.linearity = None                   # a linearity campaign's excitations
        self.seed = None                        # and the seed of its phases
        self.response = None                    # a rate or angle sweep's (choices.RESPONSES)
        self.redesign = None                    # a two-pass sequential multisine's Redesign

    @classmethod
    def of_multisine(cls, axis, inject, multisine) -> "SweepPlan":
        """One excitation: the multisine (:mod:`.multisine`), its base frequency, declared
        peak, whole periods and fade."""
        plan = cls(axis, inject, [multisine.base_hz], [multisine.peak], multisine.periods,
                   multisine.fade_cycles)
        plan.multisine = multisine
        return plan

    @classmethod
    def of_chirp(cls, axis, inject, chirp) -> "SweepPlan":
        """One excitation: the chirp (:mod:`.chirp`), from its start frequency, one sweep."""
        plan = cls(axis, inject, [chirp.start_hz], [chirp.amplitude], 1, chirp.fade_cycles)
        plan.chirp = chirp
        return plan

    @classmethod
    def of_linearity(cls, axis, inject, runs, seed) -> "SweepPlan":
        """A linearity campaign (:mod:`.linearity`): ``runs`` its excitations in order,
        ``(multisine, level, realisation)``; ``seed`` the one its phases were drawn from."""
        first = runs[0][0]
        plan = cls(axis, inject, [ms.base_hz for ms, _, _ in runs],
                   [ms.peak for ms, _, _ in runs], first.periods, first.fade_cycles)
        plan.multisine, plan.linearity, plan.seed = first, list(runs), seed
        return plan

    def select(self, i: int) -> dict:
        """Before excitation ``i`` (from 0): a linearity campaign's multisine, or a redesigned
        multisine's pass, made the one flown; the fields its manifest entry gets (none for
        another plan)."""
        if self.redesign is not None:
            return self._select_pass(i)
        if not self.linearity:
            return {}
        ms, level, index = self.linearity[i]
        self.multisine = ms
        return {"realisation": index, "level": level, "phases_rad": list(ms.phases)}

    def _select_pass(self, i: int) -> dict:
        rd = self.redesign
        if i == 0:
            self.multisine = rd.first
            return {"line_amplitudes": list(rd.first.amplitudes)}
        self.multisine = rd.second
        self.sequential = dataclasses.replace(self.sequential, prior=rd.prior)
        return {"redesign_of": rd.first_index, "weights": list(rd.weights),
                "line_amplitudes": list(rd.second.amplitudes),
                "phases_rad": list(rd.second.phases)}

    def after(self, entry: dict, index: int) -> str | None:
        """After excitation ``entry`` (``index`` in the manifest's frequencies): a redesigned
        multisine's second pass added to the plan when the first calls for one; what to say
        of it (None for another plan)."""
        rd = self.redesign
        if rd is None or rd.second is not None or rd.why_not is not None:
            return None
        second = rd.second_pass(entry, index, self.sequential.min_periods,
                                self.sequential.target_sigma)
        if second is None:
            return f"no second pass: {rd.why_not}"
        self.freqs_hz.append(second.base_hz)
        self.amplitudes.append(second.peak)
        amps = np.asarray(second.amplitudes)
        if rd.equal_why:
            return f"second pass, {second.periods} periods, equal lines: {rd.equal_why}"
        return (f"second pass, lines redesigned from the first: amplitudes "
                f"{amps.min() / amps.max():.2g} to 1 of the largest, {second.periods} periods")

    @property
    def signal(self) -> str:
        return "chirp" if self.chirp is not None else \
            "dwell" if self.multisine is None else "multisine"

    def cycles_for(self, freq_hz: float) -> int:
        """The measured cycles (a multisine: base periods) an excitation is started with."""
        if self.multisine is not None and self.redesign is not None:
            return self.multisine.periods               # the pass under way's
        return self.dwell.cycles(freq_hz) if self.dwell else self.cycles

    def record(self) -> dict:
        """The design, for the manifest."""
        if self.multisine is not None:
            out = self.multisine.record()
            if self.sequential is not None:
                out["sequential"] = {"target_sigma": self.sequential.target_sigma,
                                     "min_periods": self.sequential.min_periods}
            if self.redesign is not None:
                out["redesign"] = {"rig_time_s": self.redesign.rig_time_s, "spread": SPREAD}
            if self.linearity:
                del out["phases_rad"]                   # each realisation's, in its entry
                out["linearity"] = {
                    "realisations": len({i for _, _, i in self.linearity}),
                    "peaks": sorted({ms.peak for ms, _, _ in self.linearity}, reverse=True),
                    "seed": self.seed, "design": "odd, random phases"}
            return out
        if self.chirp is not None:
            return self.chirp.record()
        out = {"cycles": self.cycles} if self.dwell is None else {
            "dwell": "sequential", "min_cycles": self.dwell.min_cycles,
            "max_cycles": self.dwell.max_cycles, "max_dwell_s": self.dwell.max_dwell_s,
            "target_sigma": self.dwell.target_sigma}
        if self.design is not None:
            out.update(amplitude="designed", swing_deg=self.design.swing_deg,
                       amplitude_bound=self.design.bound)
        return out


def default_plan(axis, inject="mixer", freqs_hz=None, amplitude=None, cycles=None,
                 dwell=None, swing_deg=None, fade_cycles=None):
    """The paper's Table 1 (docs/paper.md): 15 log-spaced frequencies over the axis's band.

    ``cycles``: a fixed dwell of that many measured cycles (the published one: 8); without
    it the dwell is sequential (``dwell``, default :class:`~heliquad.host.acquire.design.Dwell`).
    ``amplitude``: one for every frequency; without it a mixer sweep's amplitudes are
    designed for a swing of ``swing_deg`` (:class:`~heliquad.host.acquire.design.AmplitudeDesign`)
    and angle and rate sweeps use :func:`.excitation.default_amplitude`. ``fade_cycles``:
    the cycles each frequency is faded in and out over (default :data:`FADE_CYCLES`)."""
    if freqs_hz is None:
        lo, hi = paper.BANDS_HZ[axis]
        freqs_hz = np.logspace(math.log10(lo), math.log10(hi), N_FREQUENCIES)
    design = None
    if amplitude is not None:
        amps = [amplitude] * len(freqs_hz)
    elif inject == "mixer":
        design = AmplitudeDesign(amplitude_bound(inject))
        if swing_deg is not None:
            design.swing_deg = swing_deg
        amps = [None] * len(freqs_hz)
    else:
        amps = [default_amplitude(inject)] * len(freqs_hz)
    fade = fade_cycles or FADE_CYCLES
    if cycles is not None:
        return SweepPlan(axis, inject, freqs_hz, amps, cycles, fade, design=design)
    return SweepPlan(axis, inject, freqs_hz, amps, MEASURED_CYCLES, fade, dwell=dwell or Dwell(),
                     design=design)


def multisine_plan(axis, inject="mixer", amplitude=None, lines=None, rig_time_s=None,
                   band_hz=None, like=None, sequential=None, base_period_s=None,
                   fade_cycles=None, redesign=False) -> SweepPlan:
    """A multisine over the axis's Table 1 band (or ``band_hz``) in ``rig_time_s``
    (:func:`heliquad.host.acquire.multisine.design`). ``amplitude`` is its peak; without it, the
    dwell's amplitude for angle and rate injection (the same largest setpoint), and for
    mixer injection the firmware's bound: the designed dwell reaches it on a rig in
    turbulence, and a multisine shares its power among its lines (on the vehicle's rigs in
    still air the roll rig then swings about 5 deg). ``like``: the same lines as that
    :class:`~heliquad.host.acquire.multisine.Multisine`, as many periods as fit ``rig_time_s``;
    ``base_period_s``: the base period instead of the one chosen for ``rig_time_s``;
    ``fade_cycles``: cycles of the lowest line in each fade (default one). ``redesign``
    (with ``sequential``): two passes (:mod:`.redesign`), on the grid designed for half the
    rig time, so that each pass holds its least periods."""
    if amplitude is None:
        amplitude = default_peak(inject)
    if sequential is not None and rig_time_s is None:
        rig_time_s = SEQUENTIAL_RIG_TIME_S
    band = band_hz or paper.BANDS_HZ[axis]
    rig = rig_time_s or RIG_TIME_S
    try:
        ms = design(band, amplitude, lines or LINES, rig / 2 if redesign else rig,
                    fade_cycles=fade_cycles or MULTISINE_FADE_CYCLES, like=like,
                    base_period_s=base_period_s)
    except InputError as exc:
        if redesign:
            raise InputError(f"{exc} (--redesign designs the grid for half of the rig time, "
                             f"{rig:g} s, so that each pass holds its periods)") from None
        raise
    if redesign and len(ms.orders) < 3:
        raise InputError(f"--redesign redesigns from at least 3 lines; the grid has "
                         f"{len(ms.orders)} (more --lines)")
    if not redesign:
        plan = SweepPlan.of_multisine(axis, inject, ms)
        plan.sequential = sequential
        return plan
    rd = Redesign.of(band, ms, rig, sequential.min_periods)
    plan = SweepPlan.of_multisine(axis, inject, rd.first)
    plan.sequential, plan.redesign = sequential, rd
    return plan


def linearity_plan(axis, inject="mixer", amplitude=None, seed=0, realisations=None,
                   band_hz=None, lines=None) -> SweepPlan:
    """A linearity campaign over the axis's Table 1 band (or ``band_hz``): odd random-phase
    multisines on about ``lines`` lines, ``realisations`` of them at the peak ``amplitude``
    (default: a multisine's) and at a quarter of it (:mod:`.linearity`)."""
    runs = linearity_design(band_hz or paper.BANDS_HZ[axis],
                            default_peak(inject) if amplitude is None else amplitude, seed,
                            realisations or REALISATIONS, lines or LINEARITY_LINES)
    return SweepPlan.of_linearity(axis, inject, runs, seed)


def chirp_plan(axis, inject="mixer", amplitude=None, sweep_s=None, band_hz=None,
               law="log") -> SweepPlan:
    """A chirp over the axis's Table 1 band (or ``band_hz``), sweeping ``sweep_s`` seconds
    (:func:`heliquad.host.acquire.chirp.design`; ``amplitude`` in firmware units)."""
    chirp = chirp_design(band_hz or paper.BANDS_HZ[axis], inject, amplitude, sweep_s, law)
    return SweepPlan.of_chirp(axis, inject, chirp)


def _write_manifest(out_dir, manifest: SweepManifest) -> None:
    path = os.path.join(out_dir, MANIFEST)
    existed = os.path.exists(path)
    try:
        write_manifest(path, manifest)
    except DiskFull as exc:
        if existed:
            exc.also("its previous version is kept")
        raise


def sil_source(cfg) -> dict:
    """The manifest's ``source`` of a simulated sweep, from its SilConfig: what
    :mod:`.truth` needs to rebuild the plant (docs/file-formats.md)."""
    return {"kind": "sil", "plant": cfg.plant, "num": list(cfg.num), "den": list(cfg.den),
            "params": os.path.abspath(cfg.params) if cfg.params else None,
            "turbulence": cfg.turbulence, "seed": cfg.seed, "ideal_sensor": cfg.ideal_sensor,
            "collective": cfg.collective}


def _record_params(session, axis: str, manifest: SweepManifest, progress) -> None:
    """What the board flies: every parameter it has, read from it, and the axis's gains
    among them (host/records/gains.py)."""
    params = session_params(session, progress)
    if params is None:
        return
    manifest.params = {name: single(v) for name, v in params.items()}   # 2.422, not 2.4219999
    gains = gains_from_params(axis, params)
    manifest.gains = None if gains is None else dataclasses.asdict(gains)


def _check_rotors(plan: SweepPlan, params: dict | None) -> None:
    """A per-rotor run's lines go to rotor ``j mod count`` on the board: refused unless the
    board flies the rotors they were shared out among (its CA_ROTOR_COUNT, when read)."""
    rotors = getattr(plan.multisine, "rotors", None)
    flies = (params or {}).get("CA_ROTOR_COUNT")
    if rotors is not None and flies is not None and int(flies) != rotors:
        raise InputError(f"the board flies {int(flies)} rotors (CA_ROTOR_COUNT) and the run's "
                         f"lines are shared out among {rotors}: give --rotors {int(flies)}")


def run_sweep(session, plan: SweepPlan, out_dir: str, source: dict, progress=print,
              max_angle_deg=MAX_ANGLE_DEG, max_rate_deg_s=MAX_RATE_DEG_S,
              port_found: dict | None = None) -> dict:
    """Run the plan on ``session``; returns the manifest's document (as written to
    ``out_dir``). ``port_found``: what ``--port auto`` found, when it chose the port.

    Ctrl-C and SIGTERM end the sweep in order (the manifest says so; the return is normal).
    Any other error that ends it (a full disk, the firmware died, the link lost) stops the
    excitation, records the error in the manifest's ``aborted`` and the frequency that was
    running in ``in_progress_hz``, and is raised again."""
    limits = Limits(max_angle_deg, max_rate_deg_s)
    manifest = _new_manifest(session, plan, source, port_found, limits)
    current = None
    try:
        _write_manifest(out_dir, manifest)
        session.hover(progress)
        _record_params(session, plan.axis, manifest, progress)
        _write_manifest(out_dir, manifest)
        _check_rotors(plan, manifest.params)
        last = None                              # (amplitude, rate per unit) just measured
        i = 0
        while i < len(plan.freqs_hz):            # a redesign adds its second pass on the way
            f, amp = plan.freqs_hz[i], plan.amplitudes[i]
            i += 1
            current, chosen = f, plan.select(i - 1)
            entry, last = _measure_designed(session, plan, f, amp, last, limits, manifest,
                                            progress)
            entry.update(chosen)
            manifest.frequencies.append(entry)
            current = None
            _write_manifest(out_dir, manifest)
            bar = "#" * i + "." * (len(plan.freqs_hz) - i)
            what = _excitation_text(plan, entry, f)
            progress(f"[{bar}] {i}/{len(plan.freqs_hz)}  {what}  "
                     f"{entry['samples']} samples{loss_text(entry)}{saturation_text(entry)}  "
                     f"{entry['status']}")
            if entry["status"] != "ok":
                manifest.aborted = entry["status"]
                break
            said = plan.after(entry, len(manifest.frequencies) - 1)
            if said:
                manifest.planned_hz = list(plan.freqs_hz)       # a second pass, if added
                progress(f"  {said}")
        else:
            manifest.complete = True
    except BaseException as exc:
        _stop_excitation(session)
        manifest.in_progress_hz = current             # None: during the hover, or between two
        if isinstance(exc, KeyboardInterrupt):
            how = ABORTED_BY[stopped_by(exc)]            # Ctrl-C, SIGTERM or SIGHUP
            manifest.aborted = how
            _keep_manifest(out_dir, manifest, exc)
            progress(f"{how}: the excitation is stopped; the log and manifest are kept")
            return manifest.document()
        manifest.aborted = _one_line(exc)
        _keep_manifest(out_dir, manifest, exc)
        raise
    _write_manifest(out_dir, manifest)
    return manifest.document()


def _new_manifest(session, plan, source, port_found, limits) -> SweepManifest:
    """The manifest of a sweep about to start: what it flies, where, with which tool."""
    return SweepManifest(
        axis=plan.axis, inject=plan.inject, source=source,
        port_found=UNSET if port_found is None else port_found,
        firmware=f"heliquad {__version__}",
        started=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        tlog=SWEEP_TLOG, tlog_start_us=getattr(session, "start_us", None),
        cycles=plan.cycles, fade_cycles=plan.fade_cycles, design=plan.record(),
        limits={"max_angle_deg": limits.max_angle_deg, "max_rate_deg_s": limits.max_rate_deg_s},
        signal=plan.signal, planned_hz=list(plan.freqs_hz), response=plan.response or UNSET)


def _excitation_text(plan, entry, f) -> str:
    """One excitation of the plan for the progress line."""
    if plan.chirp is not None:
        lo, hi = plan.chirp.band_hz
        return f"chirp ({plan.chirp.law}), {lo:.4g}-{hi:.4g} Hz in {plan.chirp.sweep_s:g} s"
    if plan.multisine is not None:
        return (f"multisine, {len(plan.multisine.orders)} lines on "
                f"{entry.get('freq_hz', f):.4g} Hz")
    return f"{entry.get('freq_hz', f):.4g} Hz"


def _measure_designed(session, plan, f, amp, last, limits, manifest, progress):
    """One frequency of a sweep, its amplitude designed when ``amp`` is None: (its manifest
    entry, (amplitude, rate per unit) for the next). A designed amplitude found less than
    half of what the swing target allows is finished after the least cycles (its entry
    kept as superseded) and the frequency is measured again with the better one; so is one
    whose input, amplified by the loop near its crossover, swings past the linear range."""
    redesign = None
    if amp is None:
        amp = plan.design.first() if last is None else plan.design.next(f, *last)
        redesign = lambda rpu, ipu: plan.design.next(f, amp, rpu, ipu)   # noqa: E731
    watch = measure(session, plan, f, amp, limits, progress, redesign=redesign)
    if watch.again is not None and watch.entry["status"] == "ok":
        why = ("swung the rig far less than the target" if watch.again > amp else
               "swung the axis's command past the linear range")
        watch.entry["status"] = (f"superseded: amplitude {amp:.3g} {why}; measured again at "
                                 f"{watch.again:.3g}")
        manifest.frequencies.append(watch.entry)
        progress(f"  {watch.entry.get('freq_hz', f):.4g} Hz: amplitude {amp:.3g} {why}; "
                 f"measuring again at {watch.again:.3g}")
        amp = watch.again
        watch = measure(session, plan, f, amp, limits, progress)
    return watch.entry, (amp, watch.rate_per_unit(), watch.rate_per_unit(of="input"))


def _stop_excitation(session) -> None:
    """Ask the firmware to stop the excitation, as far as the link still carries it."""
    try:
        session.tel.stop_excitation()
    except Exception:                  # the port went away: nothing more can be sent on it
        pass


def _one_line(exc: BaseException) -> str:
    """An error that ended a sweep, in one line for the manifest."""
    text = " ".join(str(exc).split())
    if isinstance(exc, (DiskFull, FirmwareError, InputError)):
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _keep_manifest(out_dir, manifest, exc: BaseException) -> None:
    """The last manifest of a sweep that ``exc`` ended. If it cannot be written either, the
    one line raised says both (and the previous manifest stays as it was)."""
    try:
        _write_manifest(out_dir, manifest)
    except DiskFull as failed:
        if isinstance(exc, DiskFull):
            exc.also(f"{MANIFEST} could not be updated either")
            exc.clauses.extend(failed.clauses)
            return
        raise failed.also(f"the sweep had stopped: {manifest.aborted}") from exc


def cut_text(manifest) -> str | None:
    """``the sweep was cut: WHY (K of N frequencies measured)`` for a sweep that did not
    complete (Ctrl-C, a breach, a board that went away), or None."""
    if manifest.get("complete", True):
        return None
    measured = sum(1 for f in manifest["frequencies"] if f.get("status") == "ok")
    planned = manifest.get("planned_hz")
    of = f" of {len(planned)}" if planned else ""
    return (f"the sweep was cut: {manifest.get('aborted') or 'it did not complete'} "
            f"({measured}{of} frequencies measured)")


