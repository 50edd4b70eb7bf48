"""An ArduPilot SystemID log as the sweeps it flew, for ``heliquad identify LOG.BIN``: each
SystemID segment (:mod:`..records.ardupilot_log`) becomes a chirp's sweep of one axis, its
manifest and its samples as HQ_SYSID_SAMPLE rows, which identify measures as it measures a
chirp of heliquad's own (the composite of windows against the excitation).

What ``SID_AXIS`` (SIDS's ``Ax``) excites, by the numbering of ArduCopter's SystemID mode
(:data:`SID_AXES`): 1-3 the angle targets (roll, pitch, yaw), 7-9 the rate targets, 10-12
the mixer's inputs. The others (4-6 a recovery's disturbance, 13 the throttle, the position
and velocity axes above) are not an attitude axis's plant heliquad identifies: such a segment
is skipped and said. The log's numbering is checked against its data: the excitation must
show most in the named axis's field where it enters (ROut, POut or YOut for the mixer; the
rate or angle targets for the others); a log whose ``Ax`` names another axis than the one
excited (an ArduCopter that numbered its axes otherwise) is refused, not misread.

The fields, in heliquad's units (HQ_SYSID_SAMPLE's): ``axis_cmd`` the rate controller's
output into the mixer (RATE's ``ROut``, in ArduPilot's mixer units, -1 to 1), ``rate_sp`` and
``rate`` RATE's target and measured rates (deg/s to rad/s), ``angle_sp`` and ``angle`` ATT's
(deg to rad; yaw unwrapped), ``excitation`` SIDD's ``Targ``. A loop whose RATE (or ATT, for
an angle's excitation) is missing is a hole, as a sample lost on a link. The band is the part
of SIDS's ``FSt``-``FSp`` the chirp's frequency (SIDD's ``F``) reached: a segment cut short
(the pilot left the mode) is measured up to where it got, and said.
"""

from __future__ import annotations

import os

import numpy as np

from ...sim.base.dialect import AXES, INJECTIONS, dialect
from ...sim.base.errors import InputError
from ..records.ardupilot_log import ATT_FIELDS, RATE_FIELDS, read_ardupilot
from ..records.tlog import message_dtype

__all__ = ["SID_AXES", "ardupilot_sweeps", "segment_note"]

#: SID_AXIS values heliquad identifies: (axis, where the excitation enters).
SID_AXES = {1: ("roll", "angle"), 2: ("pitch", "angle"), 3: ("yaw", "angle"),
            7: ("roll", "rate"), 8: ("pitch", "rate"), 9: ("yaw", "rate"),
            10: ("roll", "mixer"), 11: ("pitch", "mixer"), 12: ("yaw", "mixer")}
#: A segment whose chirp reached less than this ratio of frequencies is not a sweep.
MIN_SPAN = 1.5
#: The chirp reached its stop when its frequency came within this share of it.
REACHED = 0.98


def ardupilot_sweeps(path, opened=None) -> tuple:
    """``(sweeps, skipped, damage)`` of the ArduPilot log at ``path``: for each segment
    identify can measure, ``(name, manifest, samples)`` (``name``: ``sidK-AXIS``, K its place
    in the log from 1), for each other a line saying why not, and where the reading stopped
    (:class:`~..records.bin_log.BinDamage`). InputError when no segment can be measured."""
    log = read_ardupilot(path, None if opened is None else opened[0])
    sweeps, skipped = [], []
    for k, seg in enumerate(log.segments, 1):
        try:
            name, manifest, samples = _sweep(seg, path, log)
        except InputError as exc:
            skipped.append(f"SystemID segment {k}: {exc}")
            continue
        sweeps.append((f"sid{k}-{name}", manifest, samples))
    if not sweeps:
        raise InputError(f"{path}: no SystemID segment identify can measure ("
                         + "; ".join(skipped) + ")")
    return sweeps, skipped, log.damage


def _sweep(seg, path, log) -> tuple:
    """``(axis, manifest, samples)`` of one segment, or InputError saying why it is not
    measured."""
    if seg.setup is None:
        raise InputError("no SIDS before it: its set-up (axis, band) is unknown")
    code = int(seg.setup["Ax"])
    if code not in SID_AXES:
        raise InputError(f"SID_AXIS {code} is not an attitude axis's excitation heliquad "
                         f"identifies (those are {', '.join(map(str, SID_AXES))})")
    axis, inject = SID_AXES[code]
    signals = _signals(seg, axis, inject)
    _check_axis(seg, code, axis, inject)
    active = np.flatnonzero(seg.target != 0)
    if active.size < 2:
        raise InputError("its excitation is zero throughout")
    rows = np.arange(active[0], active[-1] + 1)
    lo, hi, said = _band(seg, rows)
    loop_us = float(np.median(np.diff(seg.time_us[rows])))
    if not loop_us > 0:
        raise InputError(f"its loops' times do not rise (their median step is {loop_us:g} us)")
    samples, lost = _samples(seg, rows, signals, axis, inject, loop_us)
    start, end = int(samples.time_us[0]), int(samples.time_us[-1])
    entry = {"signal": "chirp", "requested_hz": lo, "freq_hz": lo, "stop_hz": hi,
             "law": "log", "sweep_s": _sweep_s(seg, rows, lo, hi),
             "record_s": (end - start) * 1e-6, "fade_samples": 0,
             "amplitude": float(seg.setup["Mag"]), "status": "ok", "start_us": start,
             "end_us": end, "samples": int(samples.size), "lost": lost,
             "period_samples": max(int(round(1e6 / (loop_us * lo))), 1)}
    manifest = {"axis": axis, "inject": inject, "tlog": os.path.basename(path),
                "source": {"kind": "ardupilot", "file": os.path.basename(path),
                           "firmware": log.version, "sid_axis": code,
                           "setup": {k: float(v) for k, v in seg.setup.items()}},
                "signal": "chirp", "frequencies": [entry], "params": log.params or None,
                "gains": None, "complete": said is None, "aborted": said}
    return axis, manifest, samples


def _signals(seg, axis, inject) -> dict:
    """HQ_SYSID_SAMPLE's fields from the segment's RATE (and ATT) fields, heliquad's units."""
    target, rate, out = RATE_FIELDS[axis]
    if out not in seg.fields:
        raise InputError("the log has no RATE records (the rate controllers' targets, rates "
                         "and outputs), which ArduCopter logs every loop in SystemID mode")
    signals = {"axis_cmd": seg.fields[out], "rate_sp": np.radians(seg.fields[target]),
               "rate": np.radians(seg.fields[rate])}
    desired, angle = ATT_FIELDS[axis]
    if angle in seg.fields:
        signals.update(angle_sp=_radians(seg.fields[desired], axis == "yaw"),
                       angle=_radians(seg.fields[angle], axis == "yaw"))
    elif inject == "angle":
        raise InputError("the log has no ATT records, and its excitation is the angle target's")
    return signals


def _radians(degrees, unwrap: bool):
    """An angle in rad from deg, its finite values unwrapped when ``unwrap`` (ATT's yaw runs
    0 to 360); NaN kept."""
    out = np.array(degrees, dtype=float)
    if unwrap:
        ok = np.isfinite(out)
        out[ok] = np.unwrap(out[ok], period=360.0)
    return np.radians(out)


def _entry_field(axis, inject) -> str:
    """The field of ``axis`` where an excitation at ``inject`` enters: the mixer's input
    (RATE's output), the rate target or the angle target."""
    target, _, out = RATE_FIELDS[axis]
    return {"mixer": out, "rate": target}.get(inject, ATT_FIELDS[axis][0])


def _check_axis(seg, code, axis, inject) -> None:
    """The excitation shows most in the named axis's field where it enters (module
    docstring), else InputError."""
    fields = {a: _entry_field(a, inject) for a in AXES}
    shown = {}
    for a, name in fields.items():
        x = seg.fields.get(name)
        ok = np.isfinite(x) if x is not None else np.zeros(0, bool)
        if ok.sum() > 2 and np.std(x[ok]) > 0 and np.std(seg.target[ok]) > 0:
            shown[a] = abs(float(np.corrcoef(seg.target[ok], x[ok])[0, 1]))
    most = max(shown, key=shown.get) if shown else None
    if most is not None and most != axis:
        raise InputError(f"SID_AXIS {code} is {axis}'s {inject} by ArduCopter's numbering, but "
                         f"the excitation shows in {fields[most]} (correlation "
                         f"{shown[most]:.2f}, {fields[axis]} {shown.get(axis, 0):.2f}): this "
                         "log numbers its axes otherwise")


def _band(seg, rows) -> tuple:
    """``(lo, hi, cut)``: the part of SIDS's band the chirp's frequency reached, and a line
    when it stopped before its stop frequency (None when it reached it)."""
    start, stop = sorted((float(seg.setup["FSt"]), float(seg.setup["FSp"])))
    f = seg.freq_hz[rows]
    f = f[np.isfinite(f) & (f > 0)]
    if not f.size:
        raise InputError("its SIDD gives no frequency")
    lo, hi = max(start, float(f.min())), min(stop, float(f.max()))
    if not hi >= MIN_SPAN * lo:
        raise InputError(f"its chirp swept {lo:.4g}-{hi:.4g} Hz, less than a ratio of "
                         f"{MIN_SPAN:g}: not a sweep")
    cut = None if float(f.max()) >= REACHED * stop else \
        f"the chirp stopped at {f.max():.4g} Hz of its {stop:.4g}"
    return lo, hi, cut


def _sweep_s(seg, rows, lo, hi) -> float:
    """How long the chirp's frequency took from ``lo`` to ``hi`` (its fades and constant
    parts not counted)."""
    f, t = seg.freq_hz[rows], seg.time_us[rows]
    moving = np.flatnonzero((f > lo * (1 + 1e-6)) & (f < hi * (1 - 1e-6)))
    return float(t[moving[-1]] - t[moving[0]]) * 1e-6 if moving.size > 1 else 0.0


def _samples(seg, rows, signals, axis, inject, loop_us) -> tuple:
    """``(samples, lost)``: the segment's loops ``rows`` as HQ_SYSID_SAMPLE rows (each loop's
    number from its time on the loop's period; a loop without its records left out, a hole)
    and how many loops the record misses."""
    need = ["axis_cmd", "rate"] + (["angle_sp", "angle"] if inject == "angle" else
                                   ["rate_sp"] if inject == "rate" else [])
    ok = np.all([np.isfinite(signals[n][rows]) for n in need], axis=0)
    keep = rows[ok]
    if keep.size < 2:
        raise InputError("none of its loops has its RATE (and ATT) records")
    t = seg.time_us[keep]
    seq = np.round((t - t[0]) / loop_us).astype(np.int64)
    if np.any(np.diff(seq) <= 0):
        raise InputError("its loops' times do not rise by whole loop periods")
    mav = dialect()
    out = np.zeros(keep.size, dtype=message_dtype(mav, "HQ_SYSID_SAMPLE"))
    out["time_us"], out["seq"] = t.astype(np.uint64), seq
    out["excitation"] = seg.target[keep]
    for name, x in signals.items():
        out[name] = np.nan_to_num(x[keep])
    out["axis"], out["injection"] = AXES[axis], INJECTIONS[inject]
    out["exc_state"], out["armed"] = mav.HQ_EXCITATION_STATE_RUNNING, 1
    lost = int(seq[-1] + 1 - keep.size)
    return out.view(np.recarray), lost


def segment_note(manifest) -> str:
    """One line on what a segment is: its SID_AXIS, band and firmware."""
    src = manifest["source"]
    e = manifest["frequencies"][0]
    return (f"SID_AXIS {src['sid_axis']} ({manifest['axis']}, {manifest['inject']} "
            f"injection), chirp {e['freq_hz']:.4g}-{e['stop_hz']:.4g} Hz swept in "
            f"{e['sweep_s']:.1f} s of a {e['record_s']:.1f} s record"
            + (f", {src['firmware']}" if src.get("firmware") else "")
            + (f"; {e['lost'] / (e['samples'] + e['lost']):.1%} of its loops without their "
               "records, holes" if e["lost"] else ""))
