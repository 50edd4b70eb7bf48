"""Closed-loop validation of an identified model (``heliquad validate``)."""

from __future__ import annotations

import os

from ...sim.base import dialect as names
from ...sim.base.errors import InputError
from ...sim.base.firmware_facts import LOOP_RATE_HZ
from .shared_options import MAX_SEED, check_model, int_in

__all__ = ["add_parser", "run"]

HELP = f"""\
Check an identified model in closed loop as the firmware flies it: its discrete PID rate
loop at the loop rate ({LOOP_RATE_HZ:g} Hz) around the model, and for roll and pitch the PD angle loop
around that, with the firmware's gains or a gains file ({{"rate": {{"roll": [Kc, tau_I,
tau_D]}}, "angle": {{"roll": [Kc, tau_D]}}}}). Reports the gain and phase margins of each loop
(rate; angle; input: broken at the plant input with both loops closed) from every crossover
up to the Nyquist frequency, and marks a margin "not validated" when its crossover lies
outside the band the model was identified over (models.json's band_rad_s: sweep further,
e.g. --freqs-hz up to 40 Hz, to validate it). For a simulated sweep's models the simulator's
own loop margins are printed beside them. Then the step response, 0.5 Hz sine tracking and
rejection of Dryden turbulence; writes validation.json and validation.png. Exit code 1 if
the cascade is unstable.

example: heliquad validate models.json --axis roll
"""



def add_parser(sub, fmt) -> None:
    p = sub.add_parser("validate", help="closed-loop validation of an identified model",
                       description=HELP, formatter_class=fmt)
    p.add_argument("models", metavar="MODELS.json")
    p.add_argument("--model", type=int_in(0, 10_000), metavar="INDEX",
                   help="which model (default: the recommended one)")
    p.add_argument("--axis", choices=tuple(names.AXES),
                   help="axis of the model (default: the file's \"axis\" entry)")
    p.add_argument("--gains", metavar="FILE", help="gains file (default: the gains the sweep read from the board, which identify "
                        "records in the models' file; else the firmware's defaults, the paper's)")
    p.add_argument("--turbulence", choices=("none", "light", "moderate", "severe"),
                   default="moderate", help="Dryden level for disturbance rejection (default moderate)")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0)
    p.add_argument("--out", metavar="DIR", help="where validation.json and validation.png go "
                   "(default: beside MODELS.json)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.gains import read_gains
    from ..records.models import check_plant_models, read_models_json
    from ..records.output import check_output_folder

    doc = read_models_json(args.models)
    check_plant_models(args.models, doc, "validate")
    models = doc.models
    index = args.model if args.model is not None else doc.recommended
    if index is None or not 0 <= index < len(models):
        raise InputError(f"{args.models}: no model {index!r} (the file has {len(models)}; "
                         "give --model INDEX)")
    axis = args.axis or doc.axis
    if axis not in names.AXES:
        raise InputError(f"{args.models} does not say which axis: give --axis roll|pitch|yaw")
    m = models[index]
    num, den, delay = m.num, m.den, float(m.delay_s)
    check_model(f"{args.models}: models[{index}]", num, den)
    file_gains = read_gains(args.gains, axis) if args.gains else None
    out = args.out or os.path.dirname(os.path.abspath(args.models))
    check_output_folder(out, "--out")

    # the command's work, imported when it runs: --help imports every command module
    from ..campaign.validation import save_validation
    from ..validate.closed_loop import model_gains, sweep_inputs, validate_model, validation_record

    gains, where = (file_gains, args.gains) if file_gains else model_gains(doc, axis)
    print(f"gains: {where}: rate {_gains_text(gains.rate)}"
          + ("" if gains.angle is None else f", angle {_gains_text(gains.angle)}"))
    turbulence = None if args.turbulence == "none" else args.turbulence
    if doc.band_rad_s is None:
        print(f"{args.models} does not give the band its models were identified over; "
              f"the paper's {axis} band is assumed")
    report, traces = validate_model(num, den, delay, axis, gains, turbulence, args.seed,
                                    **sweep_inputs(args.models, doc))
    _print_validation(validation_record(report))
    written = save_validation(out, report, traces)
    print(f"wrote {' and '.join(os.path.join(out, name) for name in written)}")
    return 0 if report["stable"] else 1


def _gains_text(values) -> str:
    return "[" + ", ".join(f"{v:g}" for v in values) + "]"


def _margins_text(lp) -> str:
    gm = "inf" if lp["gain_margin_db"] is None else f"{lp['gain_margin_db']:.1f} dB"
    if lp["phase_crossover_rad_s"] is not None:
        gm += f" at {lp['phase_crossover_rad_s']:.3g} rad/s"
    pm = "none" if lp["phase_margin_deg"] is None else f"{lp['phase_margin_deg']:.1f} deg"
    if lp["gain_crossover_rad_s"] is not None:
        pm += f" at {lp['gain_crossover_rad_s']:.3g} rad/s"
    return f"gain margin {gm}, phase margin {pm}"


def _print_validation(r) -> None:
    """The validation as validation.json records it (degrees, deg/s and dB)."""
    # the command's work, imported when it runs: --help imports every command module
    from ..validate.loops import LOOP_DT_S

    coeffs = lambda c: "[" + ", ".join(f"{v:.5g}" for v in c) + "]"  # noqa: E731
    print(f"{r.axis}: G(s) = {coeffs(r.num)} / {coeffs(r.den)}"
          + (f" * exp(-{r.delay_s * 1e3:.3g} ms s)" if r.delay_s else ""))
    lo, hi = r.band_rad_s
    print(f"  identified over {lo:.3g}-{hi:.3g} rad/s; the firmware's loops at "
          f"{1 / LOOP_DT_S:g} Hz:")
    for name, lp in r.loops.items():
        print(f"  {name:5s} loop: {_margins_text(lp)}; closed loop "
              f"{'stable' if lp['closed_loop_stable'] else 'UNSTABLE'}")
        for why in lp["not_validated"]:
            print(f"        not validated: {why}")
        measured = r.measured_loop
        if measured and measured["loop"] == name:
            said = [] if measured["gain_margin_db"] is None and measured["phase_margin_deg"] \
                is None else [_margins_text(measured)]
            said += [f"no {why}" for why in measured.get("unmeasured", [])]
            print(f"        measured through the excitation ({measured['injection']} injection): "
                  + "; ".join(said))
        if name in (r.truth_loops or {}):
            print(f"        simulator's truth: {_margins_text(r.truth_loops[name])}")
    if not r.stable:
        # the command's work, imported when it runs: --help imports every command module
        from ..validate.closed_loop import instability_text

        print(f"  {instability_text(r.instability)}; no time responses")
        return
    st, sn = r.step, r.sine
    print(f"  step {st['size']:g} {st['unit']}: rise {st['rise_time_s']:.2f} s, overshoot "
          f"{st['overshoot_pct']:.1f} %, settling {st['settling_time_s']:.2f} s")
    print(f"  sine {sn['freq_hz']:g} Hz: tracking RMS {sn['tracking_rms']:.3g} {st['unit']} "
          f"({sn['tracking_rms_pct']:.1f} % of the reference RMS)")
    if r.turbulence is not None:
        tb = r.turbulence
        extra = f", angle RMS {tb['angle_rms_deg']:.2f} deg (max {tb['angle_max_deg']:.2f})" \
            if "angle_rms_deg" in tb else ""
        print(f"  {tb['level']} turbulence: gust rate RMS {tb['gust_rate_rms_deg_s']:.1f} deg/s -> "
              f"rate RMS {tb['rate_rms_deg_s']:.2f} deg/s{extra}")
