"""The records of a closed-loop validation on disk: ``validation.json`` and its figure."""

from __future__ import annotations

import os

from ..records.output import write_json
from ..validate.closed_loop import validation_record
from .plot import write_validation

__all__ = ["save_validation"]


def save_validation(folder, report, traces) -> list:
    """Write ``validation.json`` (:func:`validation_record`) and, when the cascade is
    stable, ``validation.png`` into ``folder``; returns the file names written."""
    os.makedirs(folder, exist_ok=True)
    write_json(os.path.join(folder, "validation.json"), validation_record(report))
    if not report["stable"]:
        return ["validation.json"]
    write_validation(os.path.join(folder, "validation.png"), report, traces)
    return ["validation.json", "validation.png"]
