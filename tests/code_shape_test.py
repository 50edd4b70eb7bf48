"""The code's shape: no Python function in the tool, the simulator, the benchmarks or the
firmware's scripts is longer than MAX_FUNCTION_LINES (a longer one is split into named
pieces, each saying what it does), no module longer than MAX_MODULE_LINES (a longer one
holds more than one concept: each gets a module named after it), the library changes no
process-wide setting that belongs to its caller (numpy's error handling, matplotlib's
backend), and an import inside a function of the tool or the simulator says why it is not at
the module's top.

Reads the sources with ``ast``; imports nothing from heliquad.
"""

from __future__ import annotations

import ast
import io
import pathlib
import tokenize

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: The folders walked (every .py file below each).
FOLDERS = ("host", "sim", "benchmarks", "firmware")
#: A function's length: from its ``def`` line to its last line, docstring and blank lines
#: included (decorators not).
MAX_FUNCTION_LINES = 60
#: "path:function" -> why it may be longer. Empty: every function fits.
EXEMPT: dict[str, str] = {}
#: A module's length, every line counted.
MAX_MODULE_LINES = 500
#: Modules that may be longer, each with why: generated files, and numeric cores that hold
#: one concept whose pieces only make sense together.
LONG_MODULES = {
    "sim/chip/regmap.py": "generated from NXP's SVD (python -m heliquad.sim.chip.svd --write)",
    "sim/chip/machine.py": "the emulated Cortex-M4's core: memory map, time base, exception "
                           "entry and return, one state machine",
    "host/estimate/fsf.py": "the frequency sampling filter: the recursive and batch estimators "
                            "and their closed-loop and multisine forms share one model",
    "host/estimate/fit.py": "transfer-function fitting: Levy, Sanathanan-Koerner and the "
                            "output-error refinement, each starting the next",
}


def long_functions(source: str, path: str = "<source>", limit: int = MAX_FUNCTION_LINES):
    """``(path:line function, lines)`` of every function (nested and methods included)
    longer than ``limit`` lines."""
    found = []
    for node in ast.walk(ast.parse(source, filename=path)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines = node.end_lineno - node.lineno + 1
            if lines > limit:
                found.append((f"{path}:{node.lineno} {node.name}", lines))
    return found


def _sources():
    for folder in FOLDERS:
        yield from sorted((ROOT / folder).rglob("*.py"))


def test_the_walk_reaches_every_folder():
    seen = {path.relative_to(ROOT).parts[0] for path in _sources()}
    assert seen == set(FOLDERS)


def test_the_measure_counts_from_def_to_the_last_line():
    def body(indent, n):
        return [f"{indent}x{i} = {i}" for i in range(n)]

    source = "\n".join(["@decorator", "def fits():", *body("    ", 59), "",
                        "class Holder:", "    def too_long(self):", *body("        ", 58),
                        "        def inner():", "            pass", ""])
    # fits: 60 lines, the limit itself (the decorator does not count); too_long: 61, its
    # nested function included
    assert long_functions(source, "m.py") == [("m.py:64 too_long", 61)]
    assert long_functions(source, "m.py", limit=59) == [("m.py:2 fits", 60),
                                                         ("m.py:64 too_long", 61)]


def test_no_function_is_longer_than_the_limit():
    offenders = []
    for path in _sources():
        rel = path.relative_to(ROOT).as_posix()
        for where, lines in long_functions(path.read_text(), rel):
            name = f"{rel}:{where.split()[-1]}"
            if name not in EXEMPT:
                offenders.append(f"{where}: {lines} lines")
    assert not offenders, (f"functions over {MAX_FUNCTION_LINES} lines; split them into named "
                           "pieces:\n" + "\n".join(offenders))


def test_no_module_is_longer_than_the_limit():
    long = {path.relative_to(ROOT).as_posix(): len(path.read_text().splitlines())
            for path in _sources()}
    offenders = sorted(f"{path}: {n} lines" for path, n in long.items()
                       if n > MAX_MODULE_LINES and path not in LONG_MODULES)
    assert not offenders, (f"modules over {MAX_MODULE_LINES} lines; give each concept a "
                           "module of its own:\n" + "\n".join(offenders))
    assert not {p for p in LONG_MODULES if long.get(p, 0) <= MAX_MODULE_LINES}, \
        "modules in LONG_MODULES that now fit (or are gone): drop them"


def test_every_exemption_is_still_needed():
    long = {f"{path.relative_to(ROOT).as_posix()}:{where.split()[-1]}"
            for path in _sources()
            for where, _ in long_functions(path.read_text(), path.relative_to(ROOT).as_posix())}
    assert not set(EXEMPT) - long, "exempted functions that now fit: drop them from EXEMPT"


#: Calls that change what the whole process does, ``module: attribute``; the library leaves
#: them to the program that uses it (``np.errstate`` is the local form of ``np.seterr``).
PROCESS_WIDE = {"np": "seterr", "numpy": "seterr", "matplotlib": "use"}
LIBRARY_FOLDERS = ("host", "sim")


def process_wide_calls(source: str, path: str = "<source>"):
    found = []
    for node in ast.walk(ast.parse(source, filename=path)):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and isinstance(node.func.value, ast.Name)
                and PROCESS_WIDE.get(node.func.value.id) == node.func.attr):
            found.append(f"{path}:{node.lineno} {node.func.value.id}.{node.func.attr}")
    return found


def test_the_finder_sees_process_wide_calls():
    source = "import numpy as np\nnp.seterr(all='ignore')\nwith np.errstate(all='ignore'):\n" \
             "    pass\nimport matplotlib\nmatplotlib.use('Agg')\n"
    assert process_wide_calls(source, "m.py") == ["m.py:2 np.seterr", "m.py:6 matplotlib.use"]


def test_the_library_sets_nothing_process_wide():
    offenders = [hit for folder in LIBRARY_FOLDERS for path in sorted((ROOT / folder).rglob("*.py"))
                 for hit in process_wide_calls(path.read_text(), path.relative_to(ROOT).as_posix())]
    assert not offenders, ("process-wide settings in the library (use np.errstate locally; "
                           "make figures with matplotlib.figure.Figure):\n" + "\n".join(offenders))


IMPORT_FOLDERS = ("host", "sim")


def _comment_lines(source: str):
    """(lines with a comment, lines that are only a comment), numbered from 1."""
    with_comment, only_comment = set(), set()
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            with_comment.add(tok.start[0])
            if not tok.line[:tok.start[1]].strip():
                only_comment.add(tok.start[0])
    return with_comment, only_comment


def _function_import_blocks(tree):
    """Each run of consecutive import statements inside a function (nested blocks and
    functions included), as a list of statements."""
    blocks = []

    def walk(statements, in_function):
        run = []
        for stmt in statements:
            if in_function and isinstance(stmt, (ast.Import, ast.ImportFrom)):
                run.append(stmt)
                continue
            if run:
                blocks.append(run)
                run = []
            inner = in_function or isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef))
            for field in ("body", "orelse", "finalbody"):
                walk(getattr(stmt, field, []), inner)
            for handler in getattr(stmt, "handlers", []):
                walk(handler.body, inner)
            for case in getattr(stmt, "cases", []):
                walk(case.body, inner)
        if run:
            blocks.append(run)

    walk(tree.body, False)
    return blocks


def unexplained_imports(source: str, path: str = "<source>"):
    """``path:line`` of every import inside a function with no reason beside it: a comment
    on its own lines, or on the line directly above it (one comment line above a run of
    consecutive imports explains the run)."""
    with_comment, only_comment = _comment_lines(source)
    found = []
    for block in _function_import_blocks(ast.parse(source, filename=path)):
        shared = block[0].lineno - 1 in only_comment
        for stmt in block:
            own = any(n in with_comment for n in range(stmt.lineno, stmt.end_lineno + 1))
            if not (shared or own or stmt.lineno - 1 in only_comment):
                found.append(f"{path}:{stmt.lineno}")
    return found


def test_the_finder_sees_unexplained_imports():
    source = "\n".join([
        "import os",                                   # 1: at the top, needs nothing
        "def explained():",
        "    # python-control takes a second",           # 3
        "    import control",
        "    from scipy import signal",                  # 5: the comment above covers it
        "",
        "    import matplotlib  # drawn figures only",   # 7
        "def bare():",
        "    x = 1",
        "    import json",                               # 10
        "    if x:",
        "        import csv",                            # 12: nested block
        "    def inner():",
        "        from . import (a,",                     # 14: multi-line, comment on its end
        "                       b)  # a cycle",
        "        s = '# not a comment'; import re",      # 16: a '#' in a string is none
        "    y = 2",
        "    # a reason for z only",
        "    import z",                                  # 19
        "    import w",                                  # 20: a run, shared comment
        "    y = 3",
        "    # a comment, then code",
        "    y = 4",
        "    import v",                                  # 24
        "class Holder:",
        "    import typing",                             # 26: a class body is no function
        ""])
    assert unexplained_imports(source, "m.py") == ["m.py:10", "m.py:12", "m.py:16", "m.py:24"]


def test_every_import_inside_a_function_says_why():
    offenders = [hit for folder in IMPORT_FOLDERS
                 for path in sorted((ROOT / folder).rglob("*.py"))
                 for hit in unexplained_imports(path.read_text(),
                                                path.relative_to(ROOT).as_posix())]
    assert not offenders, ("imports inside functions with no reason: move them to the "
                           "module's top, or say on the line above why they are not (a "
                           "measured start-up cost, a cycle):\n" + "\n".join(offenders))
