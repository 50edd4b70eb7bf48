"""The report's section of a ``heliquad effectiveness`` folder: each rotor's identified control
effectiveness against what the geometry the runs flew (the board's CA_* parameters) predicts
and what the fitted geometry does, row by row and rotor by rotor, with each difference in the
estimate's sigmas; each rotor's time constant and delay; the fitted geometry; the figure.
Reads effectiveness.json's document; computes only the differences it shows."""

from __future__ import annotations

import html
import math
import os

from ..records import schema as S
from ..records.reading import read_json
from .report_html import image_html, number_text, table_html

__all__ = ["effectiveness_html", "read_effectiveness", "FLOWN_OFF_SIGMAS"]

#: A flown geometry's entry further than this many of the estimate's sigmas from it is
#: flagged: the board flies a geometry the rigs say is not the vehicle's.
FLOWN_OFF_SIGMAS = 3.0


def read_effectiveness(path) -> dict:
    """effectiveness.json's document, checked for what the section shows (docs/file-formats.md);
    one InputError naming the file and key for anything else."""
    row = S.List(S.Null(S.Num()), 1, 8)
    rows3 = S.List(row, 3, 3)
    per_rotor = S.List(S.Null(S.Num()), 1, 8)
    schema = S.Obj(required={"rotors": S.Int(1, 8), "rows": S.List(S.Str(), 3, 3),
                             "runs": S.List(S.Obj()), "chi2_dof": S.Null(S.Num()),
                             "effectiveness_rad_s2": rows3,
                             "effectiveness_sigma_rad_s2": rows3,
                             "flown_geometry_rad_s2": rows3, "fitted_geometry_rad_s2": rows3,
                             "time_constant_s": per_rotor, "time_constant_sigma_s": per_rotor,
                             "delay_s": per_rotor, "delay_sigma_s": per_rotor},
                   optional={"geometry": S.Null(S.Obj())})
    return read_json(path, "effectiveness file (effectiveness.json)", schema)


def _entry(est, sigma, flown, fitted):
    """One cell: the estimate with its sigma, the flown geometry's value and its distance in
    sigmas (flagged beyond FLOWN_OFF_SIGMAS), the fitted geometry's value."""
    off = (flown - est) / sigma if sigma and math.isfinite(sigma) and sigma > 0 else math.nan
    mark = "flag" if math.isfinite(off) and abs(off) > FLOWN_OFF_SIGMAS else "small"
    return (f"{number_text(est)} &plusmn; {number_text(sigma, '.2g')}<br>"
            f"<span class='{mark}'>flown {number_text(flown)} ({number_text(off, '+.1f')} "
            f"&sigma;)</span><br><span class='small'>fitted {number_text(fitted)}</span>")


def effectiveness_html(folder: str, doc: dict) -> str:
    """The section of the folder holding effectiveness.json's ``doc``."""
    n = int(doc["rotors"])
    as_rows = [doc[k] for k in ("effectiveness_rad_s2", "effectiveness_sigma_rad_s2",
                                "flown_geometry_rad_s2", "fitted_geometry_rad_s2")]
    rows = []
    for r, name in enumerate(doc["rows"]):
        cells = [_entry(*(float("nan") if m[r][i] is None else float(m[r][i]) for m in as_rows))
                 for i in range(n)]
        rows.append([f"{name} (rad/s^2 per unit of command)"] + cells)
    lags = [["time constant (ms)"] + [f"{number_text(1e3 * t)} &plusmn; "
                                      f"{number_text(1e3 * s, '.2g')}"
                                      for t, s in zip(doc["time_constant_s"],
                                                      doc["time_constant_sigma_s"])],
            ["delay (ms)"] + [f"{number_text(1e3 * t)} &plusmn; {number_text(1e3 * s, '.2g')}"
                              for t, s in zip(doc["delay_s"], doc["delay_sigma_s"])]]
    lags = [[c.replace("nan", "-") if isinstance(c, str) else c for c in r] for r in lags]
    header = [""] + [f"rotor {i + 1}" + (" (central)" if i == 0 else "") for i in range(n)]
    g = doc.get("geometry") or {}
    fitted = (f"<p>The geometry that best explains them: cant {number_text(g.get('cant_deg'))} "
              f"&plusmn; {number_text(g.get('cant_sigma_deg'), '.2g')} deg, torque ratios "
              f"{number_text(g.get('central_torque_ratio_m'))} m (central) and "
              f"{number_text(g.get('arm_torque_ratio_m'))} m (arms), chi2/dof "
              f"{number_text(g.get('chi2_dof'), '.3g')}; written as geometry.params.</p>"
              if g else "")
    return (f"<h2>Control effectiveness: {html.escape(os.path.basename(os.path.abspath(folder)))}"
            f"</h2><p>Each rotor's angular acceleration per unit of its thrust command from "
            f"{len(doc['runs'])} per-rotor runs (chi2/dof {number_text(doc['chi2_dof'], '.3g')}),"
            f" against the geometry the runs flew and the fitted one; a flown value more than "
            f"{FLOWN_OFF_SIGMAS:g} sigmas off is flagged.</p>"
            + table_html(header, rows + lags, left=(0,), raw=tuple(range(1, n + 1)))
            + fitted + image_html(os.path.join(folder, "effectiveness.png"), "effectiveness"))
