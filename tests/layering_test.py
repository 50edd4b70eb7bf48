"""The floor plan holds: every Python module lives in a room (a package named after what it
holds), and imports go down the floors only. Bottom up, the rooms are

    sim.base < sim.plant < sim.sensor < sim.rig < sim.chip        (heliquad.sim)
    < host.records < host.process < host.estimate < host.acquire
    < host.validate < host.present < host.campaign < host.study < host.commands < host.cli   (heliquad.host)

A module may import modules of its own room and of the rooms below it, never above: so the
simulator never imports the host tool, the shared base (sim.base) imports nothing else of
heliquad's, and the file formats (host.records) import only the shared base. No module
imports, directly or through others, a module that imports it back. docs/architecture.md
says what each room holds.

Read from the sources (every import statement, at module level or inside a function), so a
lazy import cannot hide an edge. Imports nothing from heliquad."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = {"host": "heliquad.host", "sim": "heliquad.sim"}
#: The rooms, bottom up.
ROOMS = ("sim.base", "sim.plant", "sim.sensor", "sim.rig", "sim.chip",
         "host.records", "host.process", "host.estimate", "host.acquire", "host.validate",
         "host.present", "host.campaign", "host.study", "host.commands", "host.cli")
#: The two packages' own ``__init__`` (the version, a docstring): below every room of theirs.
FLOORS = {"heliquad.sim": -2, "heliquad.host": -1}


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


def floor(module: str) -> int:
    """The floor of ``module``'s room (ROOMS' index), or FLOORS' for a package's own
    ``__init__``."""
    if module in FLOORS:
        return FLOORS[module]
    room = ".".join(module.split(".")[1:3])
    return ROOMS.index(room)


def test_every_module_lives_in_a_room():
    loose = sorted(m for m in _modules() if m not in FLOORS
                   and ".".join(m.split(".")[1:3]) not in ROOMS)
    assert not loose, f"modules outside every room (add them to one): {loose}"


def test_imports_go_down_the_floors_only():
    offenders = sorted(f"{m} imports {t}" for m, targets in _graph().items()
                       for t in targets if floor(t) > floor(m))
    assert not offenders, offenders


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


def test_every_command_is_a_module_named_after_it():
    # host/commands/<command>.py, dashes as underscores, each listed in the registry once;
    # the other modules there are the options several commands share (*_options).
    tree = ast.parse((ROOT / "host" / "commands" / "__init__.py").read_text())
    registry = next(ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                    and any(getattr(t, "id", None) == "COMMANDS" for t in n.targets))
    modules = {p.stem for p in (ROOT / "host" / "commands").glob("*.py")}
    options = {m for m in modules if m.endswith("_options")}
    assert {"shared_options", "run_options"} <= options
    assert modules - {"__init__"} - options == {c.replace("-", "_") for c in registry}
    assert len(set(registry)) == len(registry)


def test_the_rules_see_real_edges():
    # The scan itself must see real edges, or the tests above pass vacuously.
    graph = _graph()
    assert "heliquad.sim.base.dialect" in graph["heliquad.host.acquire.link"]
    assert "heliquad.host.acquire.session" in graph["heliquad.host.acquire.experiment"]
    assert "heliquad.sim.base.errors" in graph["heliquad.host.cli.parser"]
    assert floor("heliquad.host.records.tlog") < floor("heliquad.host.acquire.link")
    assert floor("heliquad.sim.base.errors") < floor("heliquad.sim.plant.vehicle")
