"""What every reader of host/records shares (docs/file-formats.md, its opening paragraphs):
a headed CSV table of numbers (:func:`read_table`, :func:`first_bad`), a JSON document
checked against its schema (:func:`read_json`, :mod:`.schema`), the size bounds of both,
a user's text cut short for a one-line message (:func:`short`), and a checked document
as its record's dataclass (:func:`record_of`). Each reader raises
:class:`InputError` with one line naming the file and the key or row at fault.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import warnings

import numpy as np

from ...sim.base.errors import InputError
from ...sim.base.userfiles import read_text

__all__ = ["MAX_CSV_BYTES", "MAX_JSON_BYTES", "read_table", "first_bad", "short", "read_json",
           "record_of"]

#: The largest CSV file read (a long RUN.csv at 200 Hz is a few MB).
MAX_CSV_BYTES = 256 * 2**20
#: The largest JSON file read (heliquad's own are a few kB; a manifest grows with frequencies).
MAX_JSON_BYTES = 16 * 2**20


def read_table(path, required, optional=(), what="CSV file"):
    """Read a headed CSV of numbers; returns {column: array} for required + present optional.
    Required columns must be finite; optional ones may hold nan (a value not known)."""
    text = read_text(path, MAX_CSV_BYTES, what)
    try:
        fh = io.StringIO(text, newline="")
        names = [h.strip() for h in next(csv.reader(fh))]
        missing = [c for c in required if c not in names]
        if missing:
            raise InputError(f"{path}: missing column(s) {','.join(missing)}; header has "
                             f"{short(','.join(names)) or 'nothing'} (expected "
                             f"{','.join(required)})")
        twice = sorted({c for c in names if c and names.count(c) > 1})
        if twice:
            raise InputError(f"{path}: column {twice[0]} appears twice in the header")
        wanted = list(required) + [c for c in optional if c in names]
        _check_row_lengths(path, text.splitlines()[1:], len(names))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")      # "empty input file" from numpy
            data = np.loadtxt(fh, delimiter=",", usecols=[names.index(c) for c in wanted],
                              ndmin=2, dtype=float)
    except csv.Error as exc:
        raise InputError(f"{path}: not a CSV file ({exc})") from None
    except ValueError as exc:
        if isinstance(exc, InputError):
            raise
        first = str(exc).splitlines()[0] if str(exc) else "malformed row"
        raise InputError(f"{path}: {short(first)} (data rows count from 1 after the "
                         "header)") from None
    if data.shape[0] == 0:
        raise InputError(f"{path}: no data rows after the header")
    table = {c: data[:, i] for i, c in enumerate(wanted)}
    for c in required:
        bad = np.flatnonzero(~np.isfinite(table[c]))
        if bad.size:
            raise InputError(f"{path}: column {c} has NaN or infinity at data row {bad[0] + 1}")
    return table


def _check_row_lengths(path, rows, n) -> None:
    """Every data row has as many fields as the header (numpy would quietly ignore extra
    ones in columns it does not read)."""
    for i, row in enumerate(rows, 1):
        if row.strip() and not row.lstrip().startswith("#") and row.count(",") != n - 1:
            raise InputError(f"{path}: data row {i} has {row.count(',') + 1} fields; the header "
                             f"has {n}")


def short(text: str, limit: int = 80) -> str:
    """A value or text for a one-line message: control characters escaped, cut at ``limit``."""
    text = text.encode("unicode_escape").decode("ascii") if not text.isprintable() else text
    return text if len(text) <= limit else text[:limit - 3] + "..."


def first_bad(path, column, values, ok, what) -> None:
    """InputError naming the first data row of ``column`` whose value is not ``ok``."""
    bad = np.flatnonzero(~ok)
    if bad.size:
        raise InputError(f"{path}: {column} at data row {bad[0] + 1} is {values[bad[0]]:g}; "
                         f"it must be {what}")


def read_json(path, what: str, schema):
    """A JSON file checked against ``schema`` (:mod:`.schema`); InputError in one line naming
    the file (and the key at fault) for anything else."""
    text = read_text(path, MAX_JSON_BYTES, what)
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno} column "
                         f"{exc.colno}): not a {what}") from None
    except RecursionError:
        raise InputError(f"{path}: JSON nested too deeply: not a {what}") from None
    except ValueError:                       # an integer of thousands of digits
        raise InputError(f"{path}: a number too long to read: not a {what}") from None
    return schema.check(path, "", doc)


def record_of(cls, doc: dict, **fields):
    """The record ``cls`` (a dataclass) of a checked document: its keys that are fields of
    ``cls`` (others a newer or older writer added are left), then ``fields`` over them."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{**{k: v for k, v in doc.items() if k in names}, **fields})
