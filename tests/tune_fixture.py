"""tune.json and tuned.params as ``heliquad tune`` writes them, for gains a test chooses,
their predicted margins computed around the simulated vehicle's own truth (the sampled
responses of the rig's plant) by the cascade's loops (host/validate/loops.py), as tune does
around a model. Not a test module: a helper the verify tests import.

``wrong_gain``: predictions made around a plant with that much more gain than the vehicle's
(the predictions a wrong model gives), so that a faithful measurement must disagree.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from heliquad.host.acquire.param_protocol import Param
from heliquad.host.records.gains import PARAM_AXIS, Gains, firmware_gains
from heliquad.host.records.params_file import write_params_file
from heliquad.host.records.tune import TuneFile, write_tune_json
from heliquad.host.validate.closed_loop import margins_record
from heliquad.host.validate.loops import (LOOP_DT_S, RAW_PATH, angle_over_rate,
                                         loop_functions, margins)
from heliquad.sim.rig.setup import SilConfig, make_plant

#: The band the "models" were identified over (tune.json's band_rad_s), rad/s.
BAND_RAD_S = (1.0, 150.0)
#: tune.json's uncertainty of every predicted margin (dB, deg): as small as a good model's.
UNCERTAINTY = {"phase_margin_deg": 2.0, "gain_margin_db": 0.5}
#: The specification the fixtures are "designed" to.
SPEC = {"phase_margin_deg": 30.0, "gain_margin_db": 6.0}
REAL32 = 9


@functools.cache
def _plant(axis: str):
    return make_plant(SilConfig(axis=axis, rig=axis, plant="vehicle"), LOOP_DT_S)


def vehicle_truth(axis: str):
    """``(h, h_a)``: the simulated vehicle on the axis's rig, as the loops see it: the
    sampled rate, and the logged angle as the firmware flies it on the simulated board's raw
    IMU path (the sum of the logged rates, as verify's truth takes it)."""
    plant = _plant(axis)
    integral = angle_over_rate(RAW_PATH, LOOP_DT_S)
    return (lambda w: plant.sampled(w)[0]), (lambda w: plant.sampled(w)[0] * integral(w))


def reduced_gains(axis: str, factor: float) -> Gains:
    """The firmware's (the paper's) gains with the rate loop's Kc scaled by ``factor``."""
    g = firmware_gains(axis)
    return Gains((g.rate[0] * factor, *g.rate[1:]), g.angle)


def predicted_loops(axis: str, gains: Gains, plant_gain: float = 1.0) -> dict:
    """tune.json's ``loops`` of ``gains`` around the vehicle's truth (times ``plant_gain``),
    each with :data:`UNCERTAINTY`."""
    h, h_a = vehicle_truth(axis)
    fns = loop_functions(lambda w: plant_gain * h(w), lambda w: plant_gain * h_a(w), gains)
    out = {}
    for name, L in fns.items():
        record = margins_record(margins(L, BAND_RAD_S))
        out[name] = {**record, "uncertainty": dict(UNCERTAINTY)}
    return out


def params_of(axis: str, gains: Gains) -> dict:
    ax = PARAM_AXIS[axis]
    out = dict(zip((f"RATE_{ax}_KC", f"RATE_{ax}_TI", f"RATE_{ax}_TD"),
                   (float(np.float32(v)) for v in gains.rate)))
    if gains.angle is not None:
        out.update(zip((f"ANG_{ax}_KC", f"ANG_{ax}_TD"),
                       (float(np.float32(v)) for v in gains.angle)))
    return out


def write_tune_dir(folder, axes: dict, wrong_gain: float = 1.0, spec=None) -> str:
    """A tune folder: tune.json and tuned.params for ``axes`` (``{axis: tuned Gains}``),
    predictions around the vehicle's truth times ``wrong_gain``. Returns the folder."""
    os.makedirs(folder, exist_ok=True)
    entries, params = {}, {}
    for axis, gains in axes.items():
        current = firmware_gains(axis)
        p = params_of(axis, gains)
        params.update(p)
        entries[axis] = {
            "band_rad_s": list(BAND_RAD_S),
            "current": {"gains": {"rate": list(current.rate), "angle": current.angle and
                                  list(current.angle)},
                        "loops": predicted_loops(axis, current, wrong_gain)},
            "tuned": {"gains": {"rate": list(gains.rate), "angle": gains.angle and
                                list(gains.angle)},
                      "loops": predicted_loops(axis, gains, wrong_gain)},
            "params": p}
    write_tune_json(os.path.join(folder, "tune.json"),
                    TuneFile(spec=dict(spec or SPEC), axes=entries))
    write_params_file(os.path.join(folder, "tuned.params"),
                      [Param(n, v, REAL32, -1) for n, v in params.items()],
                      header="test fixture: tuned gains")
    return folder
