"""A study's summary figures and its page (``DIR/index.html``): the errors against the
simulator's truth by each factor's values, how honest the reported sigmas are, and rig time
against accuracy; then the table itself. Drawn with bare matplotlib figures (no backend
chosen: :func:`~heliquad.host.present.figure.new_figure`)."""

from __future__ import annotations

import html
import os

import numpy as np

from ..present.figure import new_figure
from ..records.figures import save_figure
from ..records.output import atomic_write
from .runs import FINISHED
from .table import TABLE, rows

__all__ = ["write_page", "FIGURES", "PAGE"]

#: The figures' folder in the study's, and the page.
FIGURES, PAGE = "figures", "index.html"
#: The errors each factor's figure shows: column, its label.
ERRORS = (("points_worst_db", "worst point error (dB)"),
          ("model_worst_db", "recommended model's worst error (dB)"))


def write_page(records: list, spec, out: str) -> list:
    """Write the figures and the page for ``records``; the paths written."""
    os.makedirs(os.path.join(out, FIGURES), exist_ok=True)
    done = [r for r in records if r.get("status") == FINISHED]
    paths = []
    if done:
        paths += [_by_factor(done, spec.factor_names, out), _coverage(done, out),
                  _rig_time(done, spec.factor_names, out)]
    page = os.path.join(out, PAGE)
    with atomic_write(page) as fh:
        fh.write(_html(records, spec, [os.path.relpath(p, out) for p in paths]))
    return [*paths, page]


def _levels(done, name):
    """A factor's values among ``done``, in the order first met, as text."""
    seen = []
    for r in done:
        v = _text(r["factors"].get(name))
        if v not in seen:
            seen.append(v)
    return seen


def _text(value) -> str:
    return " ".join(map(str, value)) if isinstance(value, list) else str(value)


def _values(done, column):
    return np.array([np.nan if r.get(column) is None else float(r[column]) for r in done])


def _by_factor(done, factor_names, out) -> str:
    """One column of panels per factor with more than one value: each error's spread
    (box plot) by the factor's values."""
    varied = [n for n in factor_names if len(_levels(done, n)) > 1] or list(factor_names[:1])
    fig, axes = new_figure(len(ERRORS), max(1, len(varied)), squeeze=False,
                           figsize=(3.2 * max(1, len(varied)) + 1, 6))
    for j, name in enumerate(varied):
        levels = _levels(done, name)
        for i, (column, label) in enumerate(ERRORS):
            ax = axes[i][j]
            groups = [v[np.isfinite(v)] for v in (
                _values([r for r in done if _text(r["factors"].get(name)) == lv], column)
                for lv in levels)]
            ax.boxplot([g if g.size else [np.nan] for g in groups], tick_labels=levels)
            ax.set_xlabel(name)
            if j == 0:
                ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
    fig.suptitle("Errors against the simulator's truth, by factor")
    path = os.path.join(out, FIGURES, "errors_by_factor.png")
    save_figure(fig, path, dpi=100)
    return path


def _coverage(done, out) -> str:
    """How honest the reported sigmas are: each run's RMS of error/sigma (1 when the sigma
    is the error's size) and its share of points within one and two sigmas."""
    fig, axes = new_figure(1, 2, figsize=(9, 3.6))
    z = _values(done, "points_rms_error_over_sigma")
    z = z[np.isfinite(z)]
    axes[0].hist(z if z.size else [np.nan], bins=20)
    axes[0].axvline(1.0, color="k", ls="--", lw=1)
    axes[0].set_xlabel("RMS of point error / reported sigma")
    axes[0].set_ylabel("runs")
    for column, label in (("within_1_sigma", "within 1 sigma"), ("within_2_sigma",
                                                                  "within 2 sigmas")):
        v = _values(done, column)
        v = np.sort(v[np.isfinite(v)])
        axes[1].step(v, np.arange(1, v.size + 1) / max(v.size, 1), where="post", label=label)
    axes[1].set_xlabel("share of a run's points")
    axes[1].set_ylabel("share of runs at or below")
    axes[1].legend()
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle("Coverage of the reported sigma")
    path = os.path.join(out, FIGURES, "sigma_coverage.png")
    save_figure(fig, path, dpi=100)
    return path


def _rig_time(done, factor_names, out) -> str:
    """Rig time against the worst point error, a colour per value of the first factor that
    varies (the signal, when it does)."""
    varied = [n for n in factor_names if len(_levels(done, n)) > 1]
    by = "signal" if "signal" in varied else (varied[0] if varied else None)
    fig, ax = new_figure(1, 1, figsize=(6.5, 4.2))
    for level in (_levels(done, by) if by else [None]):
        sel = [r for r in done if by is None or _text(r["factors"].get(by)) == level]
        ax.scatter(_values(sel, "rig_s"), _values(sel, "points_worst_db"), s=14,
                   label=None if by is None else f"{by} {level}")
    ax.set_xlabel("rig time (s, the log's span)")
    ax.set_ylabel("worst point error (dB)")
    if by:
        ax.legend(fontsize="small")
    ax.grid(True, alpha=0.3)
    ax.set_title("Rig time against accuracy")
    path = os.path.join(out, FIGURES, "rig_time_accuracy.png")
    save_figure(fig, path, dpi=100)
    return path


def _html(records, spec, figures) -> str:
    """The page: what the study is, its counts, the figures, the table."""
    table = rows(records, spec.columns)
    failed = sum(r["status"] != FINISHED for r in table)
    head = "".join(f"<th>{html.escape(c)}</th>" for c in (table[0] if table else {}))
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_cell(v))}</td>" for v in r.values())
                   + "</tr>\n" for r in table)
    pictures = "".join(f'<p><img src="{html.escape(p)}" alt="{html.escape(p)}"></p>\n'
                       for p in figures)
    return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>heliquad study: "
            f"{html.escape(os.path.basename(spec.path))}</title>\n<style>body{{font-family:"
            "sans-serif} table{border-collapse:collapse;font-size:12px} td,th{border:1px "
            "solid #ccc;padding:2px 4px}</style></head><body>\n"
            f"<h1>Study {html.escape(os.path.basename(spec.path))}</h1>\n"
            f"<p>{html.escape(spec.description)}</p>\n"
            f"<p>{len(spec.runs)} runs in the spec; {len(table)} over, {failed} of them "
            f"failed. The table: <a href=\"{TABLE}.csv\">{TABLE}.csv</a>, "
            f"<a href=\"{TABLE}.parquet\">{TABLE}.parquet</a>.</p>\n{pictures}"
            f"<table><tr>{head}</tr>\n{body}</table>\n</body></html>\n")


def _cell(value) -> str:
    if value is None:
        return ""
    return f"{value:.4g}" if isinstance(value, float) else str(value)
