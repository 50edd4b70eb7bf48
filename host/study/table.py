"""A study's table of results: one row per run that is over, its factors then its figures
(docs/studies.md, "The table"), as Parquet (pyarrow) and CSV, each written atomically."""

from __future__ import annotations

import json
import os

import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from ..records.output import atomic_write

__all__ = ["rows", "write_table", "COLUMNS", "TABLE"]

#: The table's files in the study's folder (without their extension).
TABLE = "study"
#: The figures' columns, in order, after the run's name, status, error and factors: name ->
#: its type (the columns' units: docs/studies.md).
COLUMNS = {
    "seed": pa.int64(), "complete": pa.bool_(), "points": pa.int64(),
    "points_worst_db": pa.float64(), "points_worst_deg": pa.float64(),
    "points_rms_db": pa.float64(), "points_rms_deg": pa.float64(),
    "points_rms_error_over_sigma": pa.float64(), "within_1_sigma": pa.float64(),
    "within_2_sigma": pa.float64(), "model_worst_db": pa.float64(),
    "model_worst_deg": pa.float64(), "recommended": pa.string(), "quality": pa.string(),
    "model_num": pa.string(), "model_den": pa.string(), "model_delay_s": pa.float64(),
    "gain_margin_db": pa.float64(), "phase_margin_deg": pa.float64(), "rig_s": pa.float64(),
    "excited_s": pa.float64(),
    "validated_stable": pa.bool_(), "validated_gain_margin_db": pa.float64(),
    "validated_phase_margin_deg": pa.float64(), "truth_gain_margin_db": pa.float64(),
    "truth_phase_margin_deg": pa.float64(), "step_overshoot_pct": pa.float64(),
    "step_settling_s": pa.float64(), "turbulence_angle_rms_deg": pa.float64(),
    "tuned_meets_spec": pa.bool_(), "tuned_gains": pa.string(),
    "tuned_gain_margin_db": pa.float64(), "tuned_phase_margin_deg": pa.float64(),
    "sweep_s": pa.float64(), "identify_s": pa.float64(), "validate_s": pa.float64(),
    "tune_s": pa.float64(), "run_s": pa.float64(), "verdicts": pa.string(),
    "started_at": pa.float64(), "attempt": pa.int64(), "worker": pa.string(),
    "commands": pa.string()}
#: Columns held as JSON text in the table (lists in the record).
AS_JSON = ("model_num", "model_den", "tuned_gains")


def rows(records: list, factor_names) -> list:
    """The table's rows (dicts, in the columns' order) of ``records``, in their order (the
    spec's)."""
    out = []
    for rec in records:
        row = {"run": rec["run"], "status": rec.get("status"), "error": rec.get("error")}
        for name in factor_names:        # the factors, then the perturbed vehicle numbers
            row[name] = _factor(rec.get("factors", {}).get(name,
                                                          rec.get("perturbed", {}).get(name)))
        for name in COLUMNS:
            value = rec.get(name)
            if name in AS_JSON and value is not None:
                value = json.dumps(value)
            elif name == "commands" and value is not None:
                value = " && ".join(value)
            row[name] = value
        out.append(row)
    return out


def _factor(value):
    """A factor's value as a cell: a list (several frequencies) as its words."""
    if isinstance(value, list):
        return " ".join(map(str, value))
    return value


def _factor_type(values) -> pa.DataType:
    """A factor column's type: numbers when every value is one, else text."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.bool_()
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.int64()
    if present and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       for v in present):
        return pa.float64()
    return pa.string()


def arrow_table(records: list, factor_names) -> pa.Table:
    """The table as a pyarrow Table (typed columns; a factor's cells made text when mixed)."""
    table_rows = rows(records, factor_names)
    fields = [pa.field("run", pa.string()), pa.field("status", pa.string()),
              pa.field("error", pa.string())]
    for name in factor_names:
        kind = _factor_type([r[name] for r in table_rows])
        if kind == pa.string():
            for r in table_rows:
                r[name] = None if r[name] is None else str(r[name])
        fields.append(pa.field(name, kind))
    fields += [pa.field(name, kind) for name, kind in COLUMNS.items()
               if name not in factor_names]
    schema = pa.schema(fields)
    return pa.Table.from_pylist([{f.name: r.get(f.name) for f in schema} for r in table_rows],
                                schema=schema)


def write_table(records: list, factor_names, out: str) -> tuple:
    """Write ``out/study.parquet`` and ``out/study.csv``; their paths."""
    table = arrow_table(records, factor_names)
    paths = (os.path.join(out, f"{TABLE}.parquet"), os.path.join(out, f"{TABLE}.csv"))
    for path, write in zip(paths, (pq.write_table, pa_csv.write_csv)):
        sink = pa.BufferOutputStream()
        write(table, sink)
        with atomic_write(path, "wb") as fh:
            fh.write(sink.getvalue().to_pybytes())
    return paths
