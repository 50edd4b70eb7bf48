"""Checks of the JSON documents a user hands the tool (each format's reader is in its own
module of host/records).

A schema is built from small specs (:class:`Num`, :class:`Int`, :class:`Str`, :class:`Bool`,
:class:`Null`, :class:`List`, :class:`Obj`); ``spec.check(path, key, value)`` returns the value
when it fits and otherwise raises :class:`InputError` with one line naming the file and the
key at fault (``frequencies[2].freq_hz``) and what was expected. Numbers must be finite (JSON
has no NaN, but Python's reader accepts ``NaN`` and ``Infinity``, and ``1e999`` reads as
infinity), so every :class:`Num` refuses them.
"""

from __future__ import annotations

import dataclasses
import math

from ...sim.base.errors import InputError

__all__ = ["Num", "Int", "Str", "Bool", "Null", "List", "Seq", "Obj", "fail", "shown"]


def shown(value) -> str:
    """A value as a one-line message shows it: kinds for containers, reprs cut short."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    text = repr(value)
    if isinstance(value, int) and not isinstance(value, bool) and len(text) > 20:
        return f"a {len(text)}-digit number"
    return text if len(text) <= 40 else text[:37] + "..."


def fail(path, key, what, value=dataclasses.MISSING):
    got = "" if value is dataclasses.MISSING else f", got {shown(value)}"
    raise InputError(f"{path}: {key} {what}{got}")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclasses.dataclass(frozen=True)
class Num:
    """A finite number in [lo, hi] (``lo_open``: lo itself excluded)."""
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False

    def describe(self) -> str:
        if math.isinf(self.lo) and math.isinf(self.hi):
            return "a finite number"
        return f"a number in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}]"

    def check(self, path, key, value):
        if not _is_number(value):
            fail(path, key, f"must be {self.describe()}", value)
        try:
            x = float(value)
        except OverflowError:
            x = math.inf
        if not math.isfinite(x) or x < self.lo or x > self.hi or (self.lo_open and x == self.lo):
            fail(path, key, f"must be {self.describe()}", value)
        return value


@dataclasses.dataclass(frozen=True)
class Int(Num):
    """A whole number (JSON without a fraction or exponent) in [lo, hi]."""

    def describe(self) -> str:
        return f"a whole number in [{self.lo:g}, {self.hi:g}]"

    def check(self, path, key, value):
        if not isinstance(value, int) or isinstance(value, bool):
            fail(path, key, f"must be {self.describe()}", value)
        return super().check(path, key, value)


@dataclasses.dataclass(frozen=True)
class Str:
    """A string: one of ``choices`` if given; ``file_name``: a plain name in its folder."""
    choices: tuple = ()
    file_name: bool = False

    def check(self, path, key, value):
        if not isinstance(value, str):
            fail(path, key, "must be a string", value)
        if self.choices and value not in self.choices:
            fail(path, key, f"must be one of {', '.join(self.choices)}", value)
        if self.file_name and (not value or value in (".", "..") or "/" in value
                               or "\\" in value or "\0" in value):
            fail(path, key, "must be a file name in the same folder", value)
        return value


@dataclasses.dataclass(frozen=True)
class Bool:
    def check(self, path, key, value):
        if not isinstance(value, bool):
            fail(path, key, "must be true or false", value)
        return value


@dataclasses.dataclass(frozen=True)
class Null:
    """null, or what ``inner`` accepts."""
    inner: object

    def check(self, path, key, value):
        return None if value is None else self.inner.check(path, key, value)


@dataclasses.dataclass(frozen=True)
class List:
    """A list of ``item``, of ``min_len``..``max_len`` entries."""
    item: object
    min_len: int = 0
    max_len: int = 100_000

    def check(self, path, key, value):
        if not isinstance(value, list):
            fail(path, key, "must be a list", value)
        if not self.min_len <= len(value) <= self.max_len:
            size = (f"{self.min_len}" if self.min_len == self.max_len
                    else f"{self.min_len} to {self.max_len}")
            fail(path, key, f"must have {size} entries", value)
        for i, v in enumerate(value):
            self.item.check(path, f"{key}[{i}]", v)
        return value


class Seq:
    """A list of fixed length: one (label, spec) per position (``rate.roll[0] (Kc)``)."""

    def __init__(self, *items):
        self.items = items

    def check(self, path, key, value):
        if not isinstance(value, list) or len(value) != len(self.items):
            fail(path, key, f"must be a list of {len(self.items)}: "
                 f"[{', '.join(label for label, _ in self.items)}]", value)
        for i, ((label, spec), v) in enumerate(zip(self.items, value)):
            spec.check(path, f"{key}[{i}] ({label})", v)
        return value


@dataclasses.dataclass(frozen=True)
class Obj:
    """An object: ``required`` and ``optional`` keys with their specs; other keys are
    refused when ``strict``, else left unchecked; ``values``: the spec of every other key."""
    required: dict = dataclasses.field(default_factory=dict)
    optional: dict = dataclasses.field(default_factory=dict)
    strict: bool = False
    values: object = None

    def check(self, path, key, value):
        if not isinstance(value, dict):
            fail(path, key or "the file", "must be a JSON object", value)
        prefix = f"{key}." if key else ""
        known = [*self.required, *self.optional]
        if self.strict:                    # first, so that a misspelt key is named as such
            for name in value:
                if name not in known:
                    fail(path, f"{prefix}{_name(name)}", f"is not a known key (known: "
                         f"{', '.join(known)})")
        for name, spec in self.required.items():
            if name not in value:
                fail(path, f"{prefix}{name}", "is missing")
            spec.check(path, f"{prefix}{name}", value[name])
        for name, v in value.items():
            spec = None if name in self.required else self.optional.get(name, self.values)
            if spec is not None:
                spec.check(path, f"{prefix}{_name(name)}", v)
        return value


def _name(key: str) -> str:
    return key if key.isprintable() and len(key) <= 40 else shown(key)
