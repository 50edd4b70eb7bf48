"""Vehicle parameters perturbed per run (a spec's ``[perturb]`` table, docs/studies.md): each
named number of the vehicle file drawn, for each run, around its value in the file, from a
stated distribution; the run's own vehicle file written into its folder and given to its
sweep (``--params``), so the run is one a user can make again by hand with that file.

A key names numbers of the file (:func:`numbers`): ``section.name`` (``body.mass_kg``), an
array's elements (``body.inertia_kg_m2``, or ``[2]`` for one), the rotors' (``rotors.name``
for each, ``rotors.N.name`` for rotor N from 1); its value ``{normal = S}`` (the nominal
times 1 + S x a standard normal draw) or ``{uniform = W}`` (the nominal times 1 + a uniform
draw in [-W, W]). Each number is drawn on its own, seeded by the run's name and the number's.
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

__all__ = ["check_perturb", "draw", "numbers", "perturbed_text", "DISTRIBUTIONS", "VEHICLE_FILE"]

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
    """{number: (distribution, width, its value in the vehicle file ``text``)} for every
    number the keys of ``perturb`` name (:func:`numbers`); InputError for a key that names
    none."""
    doc = tomllib.loads(text)
    out = {}
    for key, (kind, width) in perturb.items():
        for name, value in numbers(doc, key, where):
            out[name] = (kind, width, value)
    return out


#: A key's last part: a name, and an element of an array (from 0).
_LAST = re.compile(r"([\w-]+)(?:\[(\d+)\])?")


def numbers(doc: dict, key: str, where: str) -> list:
    """``[(number, value)]``: the numbers of the vehicle document ``doc`` a key names, each
    as its own ``section.name``, ``section.name[i]`` (an array's element), ``rotors.N.name``
    (rotor N from 1, as the firmware's motor N) or ``rotors.N.name[i]``. A key without an
    element names every element of an array; ``rotors.name`` every rotor's."""
    parts = key.split(".")
    last = _LAST.fullmatch(parts[-1])
    wrong = InputError(f"{where}: [perturb] {key}: not a number of the vehicle file "
                       "(section.name, section.name[i], rotors.name or rotors.N.name; e.g. "
                       "body.mass_kg, body.inertia_kg_m2[2], rotors.2.max_thrust_n)")
    if last is None or len(parts) not in (2, 3) or (len(parts) == 3 and parts[0] != "rotors"):
        raise wrong
    if parts[0] == "rotors":
        rotors = doc.get("rotors") if isinstance(doc.get("rotors"), list) else []
        picked = range(1, len(rotors) + 1) if len(parts) == 2 else \
            [int(parts[1])] if parts[1].isdigit() and 1 <= int(parts[1]) <= len(rotors) else []
        tables = [(f"rotors.{n}", rotors[n - 1]) for n in picked]
    else:
        tables = [(parts[0], doc.get(parts[0]))]
    name, element = last.group(1), last.group(2)
    if name == "spin":
        raise InputError(f"{where}: [perturb] {key}: a rotor's spin is its direction (1 or "
                         "-1), not a number to perturb")
    out = []
    for prefix, table in tables:
        value = table.get(name) if isinstance(table, dict) else None
        if isinstance(value, list) and element is None:
            out += [(f"{prefix}.{name}[{i}]", v) for i, v in enumerate(value)]
        elif isinstance(value, list) and int(element) < len(value):
            out.append((f"{prefix}.{name}[{element}]", value[int(element)]))
        elif element is None:
            out.append((f"{prefix}.{name}", value))
        else:
            raise wrong
    if not out or any(isinstance(v, bool) or not isinstance(v, (int, float)) for _, v in out):
        raise wrong
    return [(n, float(v)) for n, v in out]


def draw(run_name: str, nominals: dict) -> dict:
    """{number: the run's value}: each nominal perturbed by a draw seeded by the run's name
    and the number (the same run draws the same on any machine). ``nominals``:
    :func:`nominal`'s."""
    out = {}
    for name, (kind, width, value) in nominals.items():
        seed = int.from_bytes(hashlib.sha256(f"{run_name}:{name}".encode()).digest()[:8], "big")
        rng = np.random.default_rng(seed)
        step = rng.standard_normal() * width if kind == "normal" else rng.uniform(-width, width)
        out[name] = value * (1.0 + float(step))
    return out


def perturbed_text(text: str, values: dict) -> str:
    """The vehicle file ``text`` with each number of ``values`` (:func:`numbers`' names) set
    to its value, on its line (an array's line with its elements set); the rest, comments
    included, as it was."""
    lines = text.splitlines(keepends=True)
    section, rotor = None, 0
    for i, line in enumerate(lines):
        head = re.match(r"\s*\[(\[?)\s*([\w-]+)\s*\]?\]", line)
        if head:                    # [section], or [[rotors]] (rotor N), or another array table
            array, name = head.group(1) == "[", head.group(2)
            if array and name == "rotors":
                rotor += 1
                section = f"rotors.{rotor}"
            else:
                section = None if array else name
            continue
        m = re.match(r"(\s*)([\w-]+)(\s*=\s*)([^#\n]*?)(\s*(#.*)?)$", line.rstrip("\n"))
        if not (section and m):
            continue
        name = f"{section}.{m.group(2)}"
        if name in values:
            lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{values[name]!r}  # perturbed " \
                       f"from {m.group(4)}\n"
        elif any(k.startswith(name + "[") for k in values):
            try:
                old = tomllib.loads(f"v = {m.group(4)}")["v"]
            except tomllib.TOMLDecodeError:     # not on one line: said below
                continue
            new = [values.get(f"{name}[{j}]", v) for j, v in enumerate(old)]
            lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{new!r}  # perturbed from " \
                       f"{m.group(4)}\n"
    out = "".join(lines)
    doc = tomllib.loads(out)
    for name, value in values.items():         # each number written where the sim reads it
        if numbers(doc, name, "the run's vehicle file") != [(name, value)]:
            raise InputError(f"[perturb] {name}: its line in the vehicle file could not be "
                             "rewritten (a value over several lines?): give it on one line")
    return out
