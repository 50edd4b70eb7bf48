"""A closed-loop validation kept in its folder: validation.json (the record,
host/records/validation.py) and, when the cascade is stable, validation.png (its figure,
host/present/validation.py), for ``heliquad validate`` and the demo."""

from __future__ import annotations

import os

from ..present.validation import write_validation
from ..records.validation import write_validation_json
from ..validate.closed_loop import validation_record

__all__ = ["save_validation"]


def save_validation(folder, report, traces) -> list:
    """Write ``validation.json`` (:func:`~heliquad.host.validate.closed_loop.validation_record`
    of ``report``) and, when the cascade is stable, ``validation.png`` into ``folder``;
    returns the file names written."""
    os.makedirs(folder, exist_ok=True)
    write_validation_json(os.path.join(folder, "validation.json"), validation_record(report))
    if not report["stable"]:
        return ["validation.json"]
    write_validation(os.path.join(folder, "validation.png"), report, traces)
    return ["validation.json", "validation.png"]
