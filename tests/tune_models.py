"""Identified models the tuner's tests design on (tests/tune_test.py, tests/tune_cli_test.py):
the demo's roll and yaw models as identify fitted them from the simulated vehicle, each
with a second-best structure beside it and points with a relative sigma, written as
identify writes them (models.json and points.csv in one folder)."""

from __future__ import annotations

import json
import pathlib

import numpy as np

#: The demo's recommended models: (num, den, delay_s, band_rad_s).
ROLL = ([538.3], [1.0, 34.89, 5.604], 0.0155, (3.14, 28.6))
YAW = ([6.06], [1.0, 0.129], 0.022, (0.94, 10.0))
#: Their second-best structures: roll as a first-order lag whose delay takes the fast pole
#: (1/34.73 s), yaw with a little more delay.
ROLL_SECOND = ([15.5], [1.0, 0.161], 0.0155 + 1 / 34.73)
YAW_SECOND = ([6.06], [1.0, 0.129], 0.026)
#: The points' relative sigma (sigma / |G|).
RELATIVE_SIGMA = 0.03


def response(num, den, delay_s, omega):
    s = 1j * np.asarray(omega, dtype=float)
    return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * delay_s)


def _model(num, den, delay_s, aicc):
    poles = np.roots(den)
    return {"order": [len(num) - 1, len(den) - 1], "num": list(num), "den": list(den),
            "delay_s": delay_s, "stable": bool(np.all(poles.real < 0)), "degenerate": False,
            "metrics": {"J": 1.0, "rms": 0.01, "aicc": aicc},
            "poles": [[float(p.real), float(p.imag)] for p in poles]}


def write_models(folder, axis, main, second=None, band=None, gain=1.0, sigma=RELATIVE_SIGMA,
                 recommended=0, **top):
    """models.json (and points.csv) for ``axis`` in ``folder``: the model ``main`` (num,
    den, delay_s[, band]) recommended, ``second`` beside it; ``gain`` scales both. Returns
    the models.json path."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    num, den, delay = main[:3]
    band = band or main[3]
    models = [_model([gain * c for c in num], den, delay, -100.0)]
    if second is not None:
        models.append(_model([gain * c for c in second[0]], second[1], second[2], -90.0))
    omega = np.geomspace(band[0], band[1], 12)
    g = gain * response(num, den, delay, omega)
    rows = "".join(f"{float(w)!r},{float(abs(v))!r},{float(np.angle(v))!r},{float(sigma * abs(v))!r}\n"
                   for w, v in zip(omega, g))
    (folder / "points.csv").write_text("omega_rad_s,magnitude,phase_rad,sigma\n" + rows)
    doc = {"models": models, "recommended": recommended, "axis": axis,
           "points_file": "points.csv", "band_rad_s": list(band), **top}
    path = folder / "models.json"
    path.write_text(json.dumps(doc))
    return path
