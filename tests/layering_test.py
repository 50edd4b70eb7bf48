"""Imports go one way: the simulator (sim/) is the layer below the host tool (host/) and never
imports it, and no module of either imports, directly or through others, a module that
imports it back. Read from the sources (every import statement, at module level or inside a
function), so a lazy import cannot hide a cycle."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = {"host": "heliquad.host", "sim": "heliquad.sim"}


def _modules():
    """{module name: source path} of every Python module in host/ and sim/."""
    out = {}
    for folder, package in PACKAGES.items():
        for path in (ROOT / folder).rglob("*.py"):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join((package, *parts))] = path
    return out


def _imports(name: str, path: pathlib.Path, known) -> set:
    """The heliquad modules ``name`` imports (a package's names resolved to its modules)."""
    is_package = path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            # ``from P import m`` of a submodule m depends on m; of a name, on P itself
            targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in known else module
                       for a in node.names]
        else:
            continue
        found.update(t for t in targets if t in known)
    found.discard(name)
    return found


def _graph():
    known = _modules()
    return {name: _imports(name, path, known) for name, path in known.items()}


def test_the_simulator_never_imports_the_host_tool():
    offenders = sorted(f"{m} imports {t}" for m, targets in _graph().items()
                       if m.startswith("heliquad.sim") for t in targets
                       if t.startswith("heliquad.host"))
    assert not offenders, offenders


def test_no_import_cycle():
    graph = _graph()
    state, cycles = {}, []

    def visit(node, stack):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == "open":
                cycles.append(" -> ".join(stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not cycles, cycles


def test_the_graph_is_read_from_the_sources():
    # The scan itself must see real edges, or the two tests above pass vacuously.
    graph = _graph()
    assert "heliquad.sim.base.dialect" in graph["heliquad.host.acquire.link"]
    assert "heliquad.host.acquire.session" in graph["heliquad.host.acquire.experiment"]
    assert "heliquad.sim.base.errors" in graph["heliquad.host.cli.parser"]
