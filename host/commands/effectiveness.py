"""Each rotor's control effectiveness from per-rotor runs (``heliquad effectiveness``)."""

from __future__ import annotations

import math
import os

__all__ = ["add_parser", "run"]

HELP = """\
Estimate each rotor's control effectiveness (rad/s^2 per unit of thrust command about roll,
pitch and yaw), its time constant and delay from per-rotor run folders (heliquad sweep
--inject motors) of the roll, pitch and yaw rigs, one or more each, flown with one geometry
(docs/effectiveness.md); then fit the rotor geometry that explains it (one cant of the arm
rotors, the torque ratios, each arm rotor's largest thrust) from the one flown. The rig's
hinge's damping is fitted with the estimate, from the axis sweep's models (--axis-models,
the recommended model's slowest pole; without them, from a free hinge); the rotors' places and spins and the rigs' inertia from
--vehicle (default: the simulated runs' vehicle file). Writes into --out: effectiveness.json (the estimate and its sigmas, beside what
the geometry flown and the fitted geometry predict), effectiveness.png and geometry.params
(the fitted geometry as CA_* parameters, for heliquad params load).

example: for a in roll pitch yaw; do heliquad sweep --axis $a --sil --inject motors --out $a-rotors; done
         heliquad effectiveness roll-rotors pitch-rotors yaw-rotors --out effectiveness
"""


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("effectiveness", help="each rotor's control effectiveness and the "
                       "geometry that explains it, from per-rotor runs",
                       description=HELP, formatter_class=fmt)
    p.add_argument("dirs", nargs="+", metavar="DIR", help="per-rotor run folders")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--axis-models", nargs="+", metavar="MODELS.json",
                   help="the axis sweeps' models.json (heliquad identify), one per rig: its "
                        "hinge, where the fit of its damping starts (default: a free hinge)")
    p.add_argument("--vehicle", metavar="FILE",
                   help="the vehicle file of what the builder knows: the rotors' places and "
                        "spins, the body's inertia, taken as the rigs' (default: the simulated "
                        "runs' own)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..campaign.effectiveness import FIGURE, estimate_from_runs, write_outputs
    from ..present.effectiveness import write_effectiveness
    from ..records.output import check_output_folder, new_output_folder

    check_output_folder(args.out, "--out")          # before the estimate's seconds
    doc, params = estimate_from_runs(args.dirs, args.axis_models, args.vehicle)
    new_output_folder(args.out, "the effectiveness estimate")
    written = write_outputs(args.out, doc, params)
    write_effectiveness(os.path.join(args.out, FIGURE), doc)
    e, t = doc["effectiveness_rad_s2"], doc["time_constant_s"]
    for name, row in zip(doc["rows"], e):
        print(f"{name:>5}: " + "  ".join(f"{v:9.3f}" for v in row) + "  rad/s^2")
    print("    T: " + "  ".join(f"{1e3 * v:7.1f} ms" if math.isfinite(v) else "     - ms"
                                for v in t))
    g = doc["geometry"]
    print(f"geometry: cant {g['cant_deg']:.2f} +/- {g['cant_sigma_deg']:.2f} deg, chi2/dof "
          f"{doc['chi2_dof']:.2f}; wrote {', '.join([*written, FIGURE])} in {args.out}")
    return 0
