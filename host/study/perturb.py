"""Vehicle parameters perturbed per run (a spec's ``[perturb]`` table, docs/studies.md): each
named number of the vehicle file drawn, for each run, around its value in the file, from a
stated distribution; the run's own vehicle file written into its folder and given to its
sweep (``--params``), so the run is one a user can make again by hand with that file.

A key is ``section.name``, a number of one of the file's sections (``body.mass_kg``,
``rig.hinge_damping_n_m_s_rad``); its value ``{normal = S}`` (the nominal times 1 + S x a
standard normal draw) or ``{uniform = W}`` (the nominal times 1 + a uniform draw in
[-W, W]). The draws are the run's own: seeded by its name and the key.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import math
import re
import tomllib

import numpy as np

from ...sim.base.errors import InputError
from ...sim.base.userfiles import read_text
from ...sim.plant import vehicle_params

__all__ = ["check_perturb", "draw", "perturbed_text", "DISTRIBUTIONS", "VEHICLE_FILE"]

#: The distributions a key may be drawn from, each a relative width.
DISTRIBUTIONS = ("normal", "uniform")
#: The run's vehicle file, in its folder.
VEHICLE_FILE = "vehicle.toml"
#: The most a vehicle file may hold (bytes), as the vehicle's reader allows.
MAX_BYTES = 1 << 20


def base_text(path: str | None) -> str:
    """The vehicle file the perturbations start from: ``path`` or the shipped one."""
    if path is None:
        return importlib.resources.files(vehicle_params.__package__).joinpath(
            vehicle_params.DEFAULT_PARAMS).read_text()
    return read_text(path, MAX_BYTES, "vehicle file")


def check_perturb(table: dict, where: str) -> dict:
    """The spec's ``[perturb]`` table checked for its form: {key: (distribution, width)}."""
    out = {}
    for key, value in table.items():
        if not isinstance(value, dict) or len(value) != 1 or \
                next(iter(value)) not in DISTRIBUTIONS:
            raise InputError(f"{where}: [perturb] {key}: give {{normal = S}} or "
                             "{uniform = W} (relative to the file's value)")
        kind, width = next(iter(value.items()))
        if isinstance(width, bool) or not isinstance(width, (int, float)) or \
                not 0 <= width < 1 or not math.isfinite(width):
            raise InputError(f"{where}: [perturb] {key}: {kind} = {width!r}: a relative width "
                             "from 0 to below 1")
        out[key] = (kind, float(width))
    return out


def nominal(text: str, perturb: dict, where: str) -> dict:
    """{key: its value in the vehicle file ``text``}; InputError for a key that is not a
    number of one of its sections."""
    doc = tomllib.loads(text)
    out = {}
    for key in perturb:
        section, _, name = key.partition(".")
        value = doc.get(section, {}).get(name) if isinstance(doc.get(section), dict) else None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where}: [perturb] {key}: not a number of a section of the "
                             "vehicle file (section.name, e.g. body.mass_kg)")
        out[key] = float(value)
    return out


def draw(run_name: str, perturb: dict, nominals: dict) -> dict:
    """{key: the run's value}: the nominal perturbed by a draw seeded by the run's name and
    the key (the same run draws the same on any machine)."""
    out = {}
    for key, (kind, width) in perturb.items():
        seed = int.from_bytes(hashlib.sha256(f"{run_name}:{key}".encode()).digest()[:8], "big")
        rng = np.random.default_rng(seed)
        step = rng.standard_normal() * width if kind == "normal" else rng.uniform(-width, width)
        out[key] = nominals[key] * (1.0 + float(step))
    return out


def perturbed_text(text: str, values: dict) -> str:
    """The vehicle file ``text`` with each ``section.name`` line set to its value (the
    rest, comments included, as it was)."""
    lines = text.splitlines(keepends=True)
    section = None
    for i, line in enumerate(lines):
        head = re.match(r"\s*\[\[?\s*([\w-]+)\s*\]?\]", line)
        if head:
            section = None if line.lstrip().startswith("[[") else head.group(1)
            continue
        m = re.match(r"(\s*)([\w-]+)(\s*=\s*)([^#\n]*?)(\s*(#.*)?)$", line.rstrip("\n"))
        if section and m and f"{section}.{m.group(2)}" in values:
            value = values[f"{section}.{m.group(2)}"]
            lines[i] = (f"{m.group(1)}{m.group(2)}{m.group(3)}{value!r}  # perturbed from "
                        f"{m.group(4)}\n")
    return "".join(lines)
