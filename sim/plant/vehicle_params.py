"""Vehicle parameters: one documented TOML file a user copies and edits (sim/plant/vehicle.toml).

The body, the rig, the turbulence and the IMU are sections; the rotors are a list of
``[[rotors]]`` tables, one per rotor (rotor 1, the central rotor, first), each with its place,
thrust axis, spin and figures. Every key carries its unit in its name; the loader checks that
every expected key is there, that there are no others (a key in another unit, ``mass_g`` say,
is refused with the expected name), and that values have the right shape and sign. Errors
name the file and the key on one line (:class:`heliquad.sim.base.errors.InputError`).
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib.resources
import math
import tomllib

from heliquad import _simcore

from ..base.errors import InputError
from ..base.userfiles import read_text

__all__ = ["VehicleParams", "RotorParams", "RigParams", "BodyParams", "TurbulenceParams",
           "ImuParams", "load_params", "DEFAULT_PARAMS", "MIN_ROTORS", "MAX_ROTORS"]

DEFAULT_PARAMS = "vehicle.toml"


@dataclasses.dataclass(frozen=True)
class BodyParams:
    mass_kg: float
    inertia_kg_m2: tuple
    drag_n_s_m: float


@dataclasses.dataclass(frozen=True)
class RotorParams:
    """One rotor (docs/vehicle-model.md): its hub's place and thrust axis in body FRD, its spin
    (+1 counter-clockwise seen from the side its thrust points to), thrust and speed range,
    drag torque, inertia and speed lag."""

    position_m: tuple
    thrust_axis: tuple
    spin: int
    max_thrust_n: float
    max_speed_rad_s: float
    torque_per_thrust_m: float
    rotor_inertia_kg_m2: float
    time_constant_s: float

    @property
    def thrust_coeff(self) -> float:
        """k_T in T = k_T w^2, N/(rad/s)^2."""
        return self.max_thrust_n / self.max_speed_rad_s ** 2


@dataclasses.dataclass(frozen=True)
class RigParams:
    hinge_damping_n_m_s_rad: float
    hinge_friction_n_m: float


@dataclasses.dataclass(frozen=True)
class TurbulenceParams:
    altitude_m: float
    span_m: float
    rotational_damping_n_m_s_rad: float


@dataclasses.dataclass(frozen=True)
class ImuParams:
    gyro_noise_deg_s_rt_hz: float
    accel_noise_ug_rt_hz: float
    noise_bandwidth_hz: float
    gyro_bias_deg_s: tuple
    dmp_latency_samples: float


@dataclasses.dataclass(frozen=True)
class VehicleParams:
    body: BodyParams
    rotors: tuple                       # RotorParams, rotor 1 (the central rotor) first
    rig: RigParams
    turbulence: TurbulenceParams
    imu: ImuParams
    source: str = DEFAULT_PARAMS


# (section, class, {key: (kind, limit)}); kinds: "pos" in (0, limit], "nonneg" in [0, limit],
# "spin" +/-1, "vec3pos" three numbers in (0, limit], "vec3" three numbers within +/-limit,
# "axis" three numbers of length 1 within AXIS_TOLERANCE (kept normalised), "count" a whole
# number in [0, limit]. The limits are far beyond any multirotor: a value past one is a typing
# error or another unit.
_SCHEMA = (
    ("body", BodyParams, {"mass_kg": ("pos", 1e3), "inertia_kg_m2": ("vec3pos", 1e3),
                          "drag_n_s_m": ("nonneg", 1e4)}),
    ("rig", RigParams, {"hinge_damping_n_m_s_rad": ("nonneg", 1e4),
                        "hinge_friction_n_m": ("nonneg", 1e4)}),
    ("turbulence", TurbulenceParams, {"altitude_m": ("pos", 1e4), "span_m": ("pos", 1e3),
                                      "rotational_damping_n_m_s_rad": ("nonneg", 1e4)}),
    ("imu", ImuParams, {"gyro_noise_deg_s_rt_hz": ("nonneg", 1e3),
                        "accel_noise_ug_rt_hz": ("nonneg", 1e6),
                        "noise_bandwidth_hz": ("pos", 1e4), "gyro_bias_deg_s": ("vec3", 2000.0),
                        "dmp_latency_samples": ("count", 100)}),
)
#: Each [[rotors]] table's keys, in RotorParams's order.
_ROTOR_KEYS = {"position_m": ("vec3", 100.0), "thrust_axis": ("axis", 1.0), "spin": ("spin", 1),
               "max_thrust_n": ("pos", 1e5), "max_speed_rad_s": ("pos", 1e5),
               "torque_per_thrust_m": ("pos", 10.0), "rotor_inertia_kg_m2": ("pos", 100.0),
               "time_constant_s": ("pos", 10.0)}
#: A vehicle is a central rotor and 1 to 7 more (the simulator core's room: MAX_ROTORS).
MIN_ROTORS, MAX_ROTORS = 2, _simcore.MAX_ROTORS
#: How far a thrust axis's length may be from 1 (a hand-typed unit vector of 3 digits is this
#: close); the loader scales it to length 1.
AXIS_TOLERANCE = 1e-3
#: Two rotors closer than this share a place: a typing error.
MIN_SPACING_M = 1e-3


def _number(x) -> bool:
    """A finite number (a TOML integer too long for a double is not)."""
    if not isinstance(x, (int, float)) or isinstance(x, bool):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def _check(path, key, kind, limit, value):
    where = f"{path}: {key}"
    if kind in ("pos", "nonneg", "count"):
        if not _number(value) or (kind == "count" and not isinstance(value, int)):
            raise InputError(f"{where} must be a {'whole ' if kind == 'count' else ''}number, "
                             f"got {_shown(value)}")
        if kind == "pos" and value <= 0:
            raise InputError(f"{where} must be positive, got {_shown(value)}")
        if kind != "pos" and value < 0:
            raise InputError(f"{where} must not be negative, got {_shown(value)}")
        if value > limit:
            raise InputError(f"{where} must be at most {limit:g}, got {_shown(value)}")
        return int(value) if kind == "count" else float(value)
    if kind == "spin":
        if value not in (1, -1) or isinstance(value, bool):
            raise InputError(f"{where} must be 1 or -1, got {_shown(value)}")
        return int(value)
    if not isinstance(value, list) or len(value) != 3 or not all(_number(v) for v in value):
        raise InputError(f"{where} must be a list of 3 numbers, got {_shown(value)}")
    if kind == "vec3pos" and not all(0 < v <= limit for v in value):
        raise InputError(f"{where} must be in (0, {limit:g}], got {value}")
    if kind == "vec3" and not all(abs(v) <= limit for v in value):
        raise InputError(f"{where} must be within +/-{limit:g}, got {value}")
    if kind == "axis":
        length = math.hypot(*value)
        if abs(length - 1.0) > AXIS_TOLERANCE:
            raise InputError(f"{where} must be a unit vector (length 1 within "
                             f"{AXIS_TOLERANCE:g}), got length {length:.6g}")
        return tuple(float(v) / length for v in value)
    return tuple(float(v) for v in value)


def _shown(value) -> str:
    """A value for a one-line message: short, on one line."""
    text = repr(value)
    if isinstance(value, int) and len(text) > 20:
        return f"a {len(text)}-digit number"
    return text if len(text) <= 40 else text[:37] + "..."


#: The largest parameter file read (the shipped one is 4 kB).
MAX_BYTES = 2**20


def _read_toml(path) -> dict:
    """The TOML document of a file a user gave; InputError naming it for anything else."""
    text = read_text(path, MAX_BYTES, "vehicle file (TOML)")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({str(exc).splitlines()[0]})") from None


def load_params(path: str | None = None) -> VehicleParams:
    """Load and check a vehicle file (default: the shipped sim/plant/vehicle.toml)."""
    if path is None:
        doc = tomllib.loads(importlib.resources.files(__package__).joinpath(
            DEFAULT_PARAMS).read_text())
        path = DEFAULT_PARAMS
    else:
        doc = _read_toml(path)
    sections = {}
    for name, cls, keys in _SCHEMA:
        table = doc.get(name)
        if table is None:
            raise InputError(f"{path}: missing section [{name}]")
        if not isinstance(table, dict):
            raise InputError(f"{path}: {name} must be a section [{name}], got {_shown(table)}")
        sections[name] = cls(**_values(path, name, table, keys))
    extra = set(doc) - {name for name, _, _ in _SCHEMA} - {"rotors"}
    if extra:
        name = sorted(extra)[0]
        hint = " (the rotors are [[rotors]] tables, one per rotor)" if "rotor" in name else ""
        raise InputError(f"{path}: unknown section [{_key(name)}]{hint}")
    return VehicleParams(rotors=_rotors(path, doc.get("rotors")), **sections, source=str(path))


def _values(path, name: str, table: dict, keys: dict) -> dict:
    """The checked values of one table of the file (a section, or one rotor's table)."""
    for key in table:
        if key not in keys:
            close = difflib.get_close_matches(key, keys, n=1, cutoff=0.5)
            hint = f" (expected {name}.{close[0]}: units are part of the key)" if close else ""
            raise InputError(f"{path}: unknown key {name}.{_key(key)}{hint}")
    values = {}
    for key, (kind, limit) in keys.items():
        if key not in table:
            raise InputError(f"{path}: missing key {name}.{key}")
        values[key] = _check(path, f"{name}.{key}", kind, limit, table[key])
    return values


def _rotors(path, tables) -> tuple:
    """The [[rotors]] tables as RotorParams: 2 to 8 of them, each in its own place. In
    messages they are rotors[1] (the central rotor) to rotors[n], in the file's order."""
    if tables is None:
        raise InputError(f"{path}: missing the rotors (one [[rotors]] table each)")
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise InputError(f"{path}: rotors must be [[rotors]] tables, one per rotor, "
                         f"got {_shown(tables)}")
    if not MIN_ROTORS <= len(tables) <= MAX_ROTORS:
        raise InputError(f"{path}: {len(tables)} [[rotors]] tables: a vehicle has "
                         f"{MIN_ROTORS} to {MAX_ROTORS} rotors (a central rotor and up to "
                         f"{MAX_ROTORS - 1} more)")
    rotors = tuple(RotorParams(**_values(path, f"rotors[{i}]", t, _ROTOR_KEYS))
                   for i, t in enumerate(tables, 1))
    for j, rotor in enumerate(rotors, 1):
        for i, other in enumerate(rotors[:j - 1], 1):
            if math.dist(rotor.position_m, other.position_m) < MIN_SPACING_M:
                raise InputError(f"{path}: rotors[{j}].position_m is rotors[{i}]'s (two rotors "
                                 f"must be at least {1e3 * MIN_SPACING_M:g} mm apart)")
    return rotors


def _key(key: str) -> str:
    """A key of the file as a one-line message names it."""
    return key if key.isprintable() and len(key) <= 40 else _shown(key)
