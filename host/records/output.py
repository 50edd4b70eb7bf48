"""Writing the host tool's files (docs/file-formats.md: "Writing" and "A full disk", under
the sweep folder): atomic writes (a temporary file beside the target, renamed over it once
whole), JSON documents, new output folders, and the checks, made before any work, that an
output file or folder can be written. Every writer of host/records (and every other file
the tool writes) goes through :func:`atomic_write`; a record kept as a dataclass becomes its
JSON document through :func:`document`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import tempfile

from ...sim.base.errors import DiskFull, InputError, no_room

__all__ = ["check_output", "check_output_folder", "atomic_write", "write_json",
           "document", "NULLABLE", "new_output_folder"]

#: A record's field (dataclass metadata) written as null when None; any other field that is
#: None is left out of the document.
NULLABLE = {"null": True}


def _temporary_beside(path):
    """(fd, name) of a new temporary file in ``path``'s folder; InputError if there is none."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        return tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise _write_error(path, exc) from None


def check_output(path, option: str) -> None:
    """Refuse, before any work is done, an output file that could not be written: a folder,
    or a name whose folder is missing, is a file, or takes no new file (tried with a
    temporary file, removed again)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        raise InputError(f"{option} {path}: is a folder; give a file name")
    fd, tmp = _temporary_beside(path)
    os.close(fd)
    os.unlink(tmp)


def check_output_folder(path, option: str) -> None:
    """As :func:`check_output`, for an output folder that may not exist yet: it, or the
    nearest folder above it that exists, must be a folder that takes new files."""
    given = os.fspath(path)
    where = os.path.abspath(given)
    while not os.path.lexists(where):
        where = os.path.dirname(where)
    if not os.path.isdir(where):
        raise InputError(f"{option} {given}: {where} is a file, not a folder")
    try:
        check_output(os.path.join(where, ".heliquad-probe"), option)
    except InputError:
        raise InputError(f"{option} {given}: cannot write into {where}") from None


@contextlib.contextmanager
def atomic_write(path, mode: str = "w"):
    """A file object for ``path`` that replaces it only once everything is written: the
    data goes to a temporary file beside it, is flushed to the disk, and is renamed over
    ``path`` at the end. A failure (a full disk, an exception while writing) leaves the old
    file as it was and no temporary file behind; a write that finds no room raises
    :class:`DiskFull` naming ``path``, any other OSError an InputError."""
    path = os.fspath(path)
    fd, tmp = _temporary_beside(path)
    try:
        with os.fdopen(fd, mode, **({} if "b" in mode else {"newline": ""})) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _write_error(path, exc) from None
        raise


def _write_error(path, exc: OSError) -> Exception:
    """What a failed write of ``path`` is reported as: no room is :class:`DiskFull`, anything
    else an InputError naming the file."""
    if no_room(exc):
        return DiskFull.from_os_error(path, exc)
    return InputError(f"cannot write {path}: {exc.strerror or exc}")


def write_json(path, doc) -> None:
    """``doc`` as indented JSON, atomically (:func:`atomic_write`); numbers that are not
    finite are written as null (JSON has none, and the readers refuse Python's NaN)."""
    with atomic_write(path) as fh:
        json.dump(_finite_or_null(doc), fh, indent=2)
        fh.write("\n")


def document(record, absent=None) -> dict:
    """A record (a dataclass) as its JSON document: its fields in their order, each whose
    value is ``absent`` (the record's "not in the file": None, or a marker of its own when
    None is written as null) left out unless its metadata is :data:`NULLABLE`."""
    return {f.name: getattr(record, f.name) for f in dataclasses.fields(record)
            if getattr(record, f.name) is not absent or f.metadata.get("null")}


def _finite_or_null(doc):
    if isinstance(doc, float):
        return doc if math.isfinite(doc) else None
    if isinstance(doc, dict):
        return {k: _finite_or_null(v) for k, v in doc.items()}
    if isinstance(doc, (list, tuple)):
        return [_finite_or_null(v) for v in doc]
    return doc


#: zlib's level for the PNGs heliquad writes: 1 writes a figure's picture in about a quarter

def new_output_folder(path, what: str) -> bool:
    """Make ``path`` the folder ``what`` records into: it may be new or empty, never one that
    holds earlier records (an InputError says so before anything starts). True when this
    call created it (so that a run that records nothing can remove it again)."""
    path = os.fspath(path)
    if os.path.isdir(path) and os.listdir(path):
        raise InputError(f"{path} is not empty: {what} goes into a new (or empty) folder, so no "
                         "earlier record is overwritten or mixed with it; give another --out")
    if os.path.lexists(path) and not os.path.isdir(path):
        raise InputError(f"{path} exists and is not a folder: give another --out")
    created = not os.path.isdir(path)
    os.makedirs(path, exist_ok=True)
    return created

