"""Vehicle parameters: one documented TOML file a user copies and edits (sim/data/vehicle.toml).

Every key carries its unit in its name; the loader checks that every expected key is there,
that there are no others (a key in another unit, ``mass_g`` say, is refused with the
expected name), and that values have the right shape and sign. Errors name the file and the
key on one line (:class:`heliquad.sim.errors.InputError`).
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib.resources
import math
import tomllib

from .errors import InputError

__all__ = ["VehicleParams", "RotorParams", "ArmRotorParams", "RigParams", "BodyParams",
           "TurbulenceParams", "ImuParams",
           "load_params", "DEFAULT_PARAMS"]

DEFAULT_PARAMS = "vehicle.toml"


@dataclasses.dataclass(frozen=True)
class BodyParams:
    mass_kg: float
    inertia_kg_m2: tuple
    drag_n_s_m: float


@dataclasses.dataclass(frozen=True)
class _Rotor:
    """What every rotor has: thrust and speed range, drag torque, inertia, lag."""

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
class RotorParams(_Rotor):
    """The central rotor: +1 spins counter-clockwise seen from above."""

    spin: int


@dataclasses.dataclass(frozen=True)
class ArmRotorParams(_Rotor):
    """The four arm rotors (front, right, back, left) on their canted mounts."""

    arm_length_m: float
    cant_deg: float
    spin: tuple


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
    central_rotor: RotorParams
    arm_rotors: ArmRotorParams
    rig: RigParams
    turbulence: TurbulenceParams
    imu: ImuParams
    source: str = DEFAULT_PARAMS


# (section, class, {key: kind}); kinds: "pos" > 0, "nonneg" >= 0, "spin" +/-1,
# "vec3pos" three positive numbers, "vec3" three numbers, "spin4" four +/-1,
# "angle" in [0, 90) degrees, "count" a whole number >= 0.
_SCHEMA = (
    ("body", BodyParams, {"mass_kg": "pos", "inertia_kg_m2": "vec3pos", "drag_n_s_m": "nonneg"}),
    ("central_rotor", RotorParams, {"max_thrust_n": "pos", "max_speed_rad_s": "pos",
                                    "torque_per_thrust_m": "pos", "rotor_inertia_kg_m2": "pos",
                                    "spin": "spin", "time_constant_s": "pos"}),
    ("arm_rotors", ArmRotorParams, {"arm_length_m": "pos", "cant_deg": "angle",
                                    "max_thrust_n": "pos", "max_speed_rad_s": "pos",
                                    "torque_per_thrust_m": "pos", "rotor_inertia_kg_m2": "pos",
                                    "spin": "spin4", "time_constant_s": "pos"}),
    ("rig", RigParams, {"hinge_damping_n_m_s_rad": "nonneg", "hinge_friction_n_m": "nonneg"}),
    ("turbulence", TurbulenceParams, {"altitude_m": "pos", "span_m": "pos",
                                      "rotational_damping_n_m_s_rad": "nonneg"}),
    ("imu", ImuParams, {"gyro_noise_deg_s_rt_hz": "nonneg", "accel_noise_ug_rt_hz": "nonneg",
                        "noise_bandwidth_hz": "pos", "gyro_bias_deg_s": "vec3",
                        "dmp_latency_samples": "count"}),
)


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _check(path, key, kind, value):
    where = f"{path}: {key}"
    if kind in ("pos", "nonneg", "angle"):
        if not _number(value):
            raise InputError(f"{where} must be a number, got {value!r}")
        if kind == "pos" and value <= 0:
            raise InputError(f"{where} must be positive, got {value}")
        if kind == "nonneg" and value < 0:
            raise InputError(f"{where} must not be negative, got {value}")
        if kind == "angle" and not 0 <= value < 90:
            raise InputError(f"{where} must be in [0, 90) degrees, got {value}")
        return float(value)
    if kind == "spin":
        if value not in (1, -1) or isinstance(value, bool):
            raise InputError(f"{where} must be 1 or -1, got {value!r}")
        return int(value)
    if kind == "count":
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise InputError(f"{where} must be a whole number >= 0, got {value!r}")
        return int(value)
    n = 3 if kind in ("vec3pos", "vec3") else 4
    if not isinstance(value, list) or len(value) != n or not all(_number(v) for v in value):
        raise InputError(f"{where} must be a list of {n} numbers, got {value!r}")
    if kind == "vec3pos" and min(value) <= 0:
        raise InputError(f"{where} must be positive, got {value}")
    if kind == "spin4" and any(v not in (1, -1) for v in value):
        raise InputError(f"{where} entries must be 1 or -1, got {value}")
    return tuple(float(v) if kind in ("vec3pos", "vec3") else int(v) for v in value)


def load_params(path: str | None = None) -> VehicleParams:
    """Load and check a vehicle file (default: the shipped sim/data/vehicle.toml)."""
    if path is None:
        text = importlib.resources.files("heliquad.sim").joinpath("data", DEFAULT_PARAMS).read_text()
        path = DEFAULT_PARAMS
    else:
        try:
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
        except OSError as exc:
            raise InputError(f"{path}: {exc.strerror or exc}") from None
        except UnicodeDecodeError:
            raise InputError(f"{path}: not a text (TOML) file") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    sections = {}
    for name, cls, keys in _SCHEMA:
        table = doc.get(name)
        if not isinstance(table, dict):
            raise InputError(f"{path}: missing section [{name}]")
        for key in table:
            if key not in keys:
                close = difflib.get_close_matches(key, keys, n=1, cutoff=0.5)
                hint = f" (expected {name}.{close[0]}: units are part of the key)" if close else ""
                raise InputError(f"{path}: unknown key {name}.{key}{hint}")
        values = {}
        for key, kind in keys.items():
            if key not in table:
                raise InputError(f"{path}: missing key {name}.{key}")
            values[key] = _check(path, f"{name}.{key}", kind, table[key])
        sections[name] = cls(**values)
    extra = set(doc) - {name for name, _, _ in _SCHEMA}
    if extra:
        raise InputError(f"{path}: unknown section [{sorted(extra)[0]}]")
    return VehicleParams(**sections, source=str(path))
