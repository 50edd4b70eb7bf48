"""A study's spec (a TOML file): its factors, the options every run shares, and the runs
they make, each with a deterministic name and seed.

The spec (docs/studies.md)::

    [factors]                  # every combination of these values is a run
    axis = ["roll", "yaw"]
    signal = ["dwell", "multisine"]
    turbulence = ["light", "severe"]
    seed = [1, 2, 3]           # or {first = 1, count = 100}

    [[grid]]                   # optional: products of their own, [factors] filling the rest
    turbulence = ["none"]      # "none": the option left out (the command's default), as
    seed = [1]                 # a factor that neither the grid nor [factors] gives

    [sweep]                    # heliquad sweep's options, for every run
    lines = 8
    [identify]                 # heliquad identify's options, for every run
    delay = false
    [validate]                 # optional: heliquad validate on identify's models
    turbulence = "severe"
    [tune]                     # optional: heliquad tune on them (empty: its defaults)

A factor is an option of ``heliquad sweep`` (or, failing that, of identify, validate or
tune, in that order) by its long name; what the commands' options are comes from the caller
(the commands' parsers), so a factor means what the option means on the command line.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import re
import tomllib
from dataclasses import dataclass, field

from ...sim.base.errors import InputError
from .perturb import base_text, check_perturb, draw, nominal, perturbed_text

__all__ = ["Run", "Spec", "load_spec", "parse_spec", "STEPS", "OPTIONAL_STEPS", "LEFT_OUT",
           "MAX_SEED"]

#: The commands a run makes, in order, and the tables of the spec that give their options.
STEPS = ("sweep", "identify", "validate", "tune")
#: The steps a run makes only when the spec asks for them: its table (empty for the
#: command's defaults), or a factor of theirs.
OPTIONAL_STEPS = ("validate", "tune")
#: A factor's value that leaves its option out (the command's default: no turbulence).
LEFT_OUT = "none"
#: The seed derived for a run whose spec gives none: below the sweep's bound.
MAX_SEED = 2**31 - 1
#: Options the study gives each run itself: never a factor or a shared option.
OWN_OPTIONS = frozenset({"sil", "port", "baud", "out", "dir", "mat", "help"})
#: The spec's top-level tables.
TABLES = frozenset({"study", "factors", "grid", "perturb", *STEPS})
#: Characters kept in a run's name (the rest become "_").
NAME_UNSAFE = re.compile(r"[^A-Za-z0-9.+]+")


@dataclass(frozen=True)
class Run:
    """One run: its name (its folder's), its factors (name -> value, the spec's order) and
    each command's options (command -> {option: value}), the seed among the sweep's."""
    name: str
    factors: dict
    options: dict = field(default_factory=dict)
    #: The vehicle's numbers drawn for this run ({section.name: value}, an array's elements
    #: and the rotors' numbers each its own; [perturb], host/study/perturb.py).
    perturb: dict = field(default_factory=dict)

    @property
    def seed(self) -> int:
        return int(self.options["sweep"]["seed"])


@dataclass
class Spec:
    """A parsed spec: where it came from, its description, and its runs in order."""
    path: str
    description: str
    factor_names: tuple
    runs: list
    #: The perturbed vehicle numbers (every number [perturb]'s keys name), each a column of
    #: the table too.
    perturbed: tuple = ()

    @property
    def columns(self) -> tuple:
        """What varies between runs: the factors, then the perturbed numbers."""
        return self.factor_names + self.perturbed


def load_spec(path: str, commands: dict) -> Spec:
    """Read and check the spec at ``path``. ``commands``: {command: its options' long names
    (dashes, no leading --)} for each of :data:`STEPS`."""
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not UTF-8 text (a spec is a TOML file)") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    return parse_spec(doc, commands, path)


def parse_spec(doc: dict, commands: dict, path: str = "spec") -> Spec:
    """The :class:`Spec` of a TOML document already read (see :func:`load_spec`)."""
    unknown = sorted(set(doc) - TABLES)
    if unknown:
        raise InputError(f"{path}: unknown table {unknown[0]!r} (a spec has "
                         f"{', '.join(sorted(TABLES))})")
    study = _table(doc, "study", path)
    factors = _table(doc, "factors", path)
    grids = doc.get("grid", [{}])
    if not isinstance(grids, list) or not all(isinstance(g, dict) for g in grids):
        raise InputError(f"{path}: grid must be an array of tables ([[grid]])")
    shared = {step: {_key(k): v for k, v in _table(doc, step, path).items()} for step in STEPS}
    for step, options in shared.items():
        for name in options:
            _check_option(name, commands, path, f"[{step}]", step)
    names = _factor_names(factors, grids, commands, path)
    made = set(STEPS) - set(OPTIONAL_STEPS) | {step for step in OPTIONAL_STEPS if step in doc} | \
        {_check_option(n, commands, path, "[factors]") for n in names}
    shared = {step: options for step, options in shared.items() if step in made}
    perturb = check_perturb(_table(doc, "perturb", path), path)
    runs, seen = [], set()
    for i, grid in enumerate(grids):
        levels = {**{_key(k): v for k, v in factors.items()},
                  **{_key(k): v for k, v in grid.items()}}
        where = f"grid {i + 1}" if "grid" in doc else "[factors]"
        values = [_levels(levels.get(n, LEFT_OUT), n, path, where) for n in names]
        for combo in itertools.product(*values):
            run = _run(dict(zip(names, combo)), shared, commands, perturb)
            if run.name not in seen:
                seen.add(run.name)
                runs.append(run)
    if not runs:
        raise InputError(f"{path}: the grid is empty: no run to make (a factor with no "
                         "values?)")
    if perturb:
        runs = _drawn(runs, perturb, path)
    perturbed = tuple(dict.fromkeys(n for run in runs for n in run.perturb))
    return Spec(path, str(study.get("description", "")), tuple(names), runs, perturbed)


def _drawn(runs: list, perturb: dict, path: str) -> list:
    """The runs with their vehicle numbers drawn ([perturb]), around each run's vehicle
    file (its sweep's ``params``, else the shipped one)."""
    nominals = {}
    out = []
    for run in runs:
        base = run.options["sweep"].get("params")
        if base not in nominals:
            nominals[base] = nominal(base_text(base), perturb, path)
        out.append(dataclasses.replace(run, perturb=draw(run.name, nominals[base])))
        if len(out) == 1 or out[-2].options["sweep"].get("params") != base:
            try:                                    # each file written as drawn, or refused
                perturbed_text(base_text(base), out[-1].perturb)
            except InputError as exc:
                raise InputError(f"{path}: {exc}") from None
    return out


def _table(doc: dict, name: str, path: str) -> dict:
    value = doc.get(name, {})
    if not isinstance(value, dict):
        raise InputError(f"{path}: {name} must be a table ([{name}])")
    return value


def _key(name: str) -> str:
    """A spec's key as the option's long name: rig_time and rig-time alike."""
    return name.replace("_", "-")


def _check_option(name: str, commands: dict, path: str, where: str, step=None) -> str:
    """The command whose option ``name`` is (the first of :data:`STEPS` that has it, or
    ``step``'s), refused when it is the study's own or no command's."""
    if name in OWN_OPTIONS:
        raise InputError(f"{path}: {where}: {name} is set by the study itself, for each run")
    for command in ([step] if step else STEPS):
        if name in commands[command]:
            return command
    known = ", ".join(sorted(set(commands[step] if step else
                                 set().union(*commands.values())) - OWN_OPTIONS))
    what = "factor" if step is None else f"option of heliquad {step}"
    raise InputError(f"{path}: {where}: unknown {what} {name!r} (known: {known})")


def _factor_names(factors: dict, grids: list, commands: dict, path: str) -> list:
    """Every factor named by [factors] or a grid, in the order first named."""
    names = []
    for table in (factors, *grids):
        for key in table:
            name = _key(key)
            if name not in names:
                _check_option(name, commands, path, "[factors]" if table is factors else
                              "[[grid]]")
                names.append(name)
    return names


def _levels(value, name: str, path: str, where: str) -> list:
    """A factor's values: a list, one value, or (seed) {first = N, count = M}."""
    if isinstance(value, dict):
        if name != "seed" or set(value) - {"first", "count"} or "count" not in value:
            raise InputError(f"{path}: {where}: {name}: a table of values is for seed only: "
                             "{first = N, count = M}")
        first, count = value.get("first", 1), value["count"]
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0
                   for v in (first, count)):
            raise InputError(f"{path}: {where}: seed: first and count must be whole numbers")
        return list(range(first, first + count))
    values = value if isinstance(value, list) else [value]
    if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
        raise InputError(f"{path}: {where}: factor {name!r} repeats a value")
    return values


def _run(factors: dict, shared: dict, commands: dict, perturb: dict) -> Run:
    """The run of one combination of the factors' values: each factor under its command,
    the shared options under theirs; the seed the factor's, else derived from the name."""
    options = {step: dict(opts) for step, opts in shared.items()}
    for name, value in factors.items():
        options[_check_option(name, commands, "spec", "[factors]")][name] = value
    options = {step: {k: v for k, v in opts.items() if v != LEFT_OUT}
               for step, opts in options.items()}
    digest = hashlib.sha256(json.dumps({"options": options, "perturb": perturb} if perturb
                                       else options, sort_keys=True).encode()).hexdigest()
    label = "-".join(NAME_UNSAFE.sub("_", _text(v)).strip("_") or "_" for v in factors.values())
    if "seed" not in options["sweep"]:
        options["sweep"]["seed"] = int(digest[:8], 16) % MAX_SEED
    return Run(f"{label}-{digest[:8]}" if label else digest[:8], factors, options)


def _text(value) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, list):          # a few values, or the first..last and how many
        words = [_text(v) for v in value]
        return "+".join(words) if len(words) <= 3 else f"{words[0]}..{words[-1]}x{len(words)}"
    return f"{value:g}" if isinstance(value, float) else str(value)
