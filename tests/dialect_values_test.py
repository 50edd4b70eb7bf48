"""One definition per dialect value.

firmware/mavlink/heliquad.xml (with the common.xml it includes) is the only place where an
enum's numbers, its entries' names and its messages' array lengths are written. Python takes
them from the generated module (``heliquad._mavlink``, and the names of sim/base/dialect.py), C++
from the generated headers. These tests check what each language exposes against the XML,
and scan the sources (not generated code, not build folders) for a hand copy:

Python (host/, sim/, benchmarks/, the test helpers that are not test modules):
  * a tuple or list that starts with an enum's first names in value order
    (``("roll", "pitch", "yaw")``) or holds them and nothing else
    (``("mixer", "rate", "angle")``), or a dict pairing its names with numbers
    (``{"roll": 0, ...}``);
  * a number given to, compared with or defaulted for an enum-valued message field or a
    variable named after one (``kind = 0``, ``m.severity <= 4``, ``imu_fault=0``);
  * a constant named after an entry (``MAV_CMD_COMPONENT_ARM_DISARM = 400``,
    ``SENSOR_NONE = 0``);
  * a number whose comment names an entry of that value or an array field of that length
    (``6, 8  # MAV_TYPE_GCS, ...``, ``168  # HQ_SENSOR_FRAME.fifo``).
C++ (firmware/, sim/):
  * an enum with number initialisers of which two or more are a dialect enum's entries
    by name and value (``enum class FifoKind { None = 0, Dmp = 1, Raw = 2 }``);
  * a number whose comment (that line or the one above) names an entry of that value or an
    array field of that length;
  * an enum-valued field, or a variable named ``kind`` or ``fault``, compared with a number.
Data keyed by the names (the paper's bands and gains per axis) is allowed, and must name
every entry of its enum.
"""

from __future__ import annotations

import ast
import functools
import io
import pathlib
import re
import subprocess
import sys
import tokenize
import xml.etree.ElementTree as ET

import pytest

from heliquad import _firmware as fw
from heliquad.host.acquire import excitation, link
from heliquad.host.records import paper
from heliquad.sim.base import dialect as names
from heliquad.sim.base.dialect import dialect
from heliquad.sim.plant import vehicle
from heliquad.sim.rig import faults

ROOT = pathlib.Path(__file__).resolve().parent.parent
XML = ROOT / "firmware" / "mavlink" / "heliquad.xml"
MAV = dialect()
#: Copies still to remove, per file: the commands' argparse choices and checks of axis and
#: injection names. They switch to sim/base/dialect.py's names once the command line reports a
#: missing dialect module while it builds its parser (the choices then need the module). A new
#: copy in these files fails, and so does one fewer (lower the count).
PENDING = {}


def xml_enums() -> dict:
    """{enum: {entry: value}} as firmware/mavlink/heliquad.xml writes them."""
    root = ET.parse(XML).getroot()
    return {e.get("name"): {x.get("name"): int(x.get("value")) for x in e.iter("entry")}
            for e in root.iter("enum")}


@functools.cache
def all_enums() -> dict:
    """{enum: {entry: value}} of the whole generated dialect (common.xml's too)."""
    return {enum: {e.name: value for value, e in entries.items()
                   if not e.name.endswith("_ENUM_END")}
            for enum, entries in MAV.enums.items()}


def entry_values() -> dict:
    """{entry: value} of every entry of the dialect (the names are unique across enums)."""
    return {name: value for enum in all_enums().values() for name, value in enum.items()}


# --- what each language exposes is the XML ----------------------------------------------------

def test_python_has_every_entry_of_the_xml():
    for enum, entries in xml_enums().items():
        generated = {e.name: v for v, e in MAV.enums[enum].items()
                     if not e.name.endswith("_ENUM_END")}
        assert generated == entries, enum
        assert {name: getattr(MAV, name) for name in entries} == entries, enum


def test_the_tools_names_are_the_dialects():
    xml = xml_enums()
    for attr, enum in names.NAMED_ENUMS.items():
        prefix = enum + "_"
        expected = {n[len(prefix):].lower(): v for n, v in xml[enum].items()}
        assert dict(getattr(names, attr)) == expected, attr
        assert getattr(link, attr) is getattr(names, attr)
    assert names.enum_values("HQ_SENSOR_KIND") == {"none": 0, "dmp": 1, "raw": 2}


@pytest.mark.parametrize("cls, enum", [(fw.Axis, "HQ_AXIS"), (fw.Injection, "HQ_INJECTION"),
                                       (fw.FlightMode, "HQ_MODE"),
                                       (fw.ExcitationState, "HQ_EXCITATION_STATE"),
                                       (fw.SensorMode, "HQ_SENSOR_KIND")])
def test_the_firmware_enums_are_the_dialects(cls, enum):
    members = {name.lower(): int(member) for name, member in cls.__members__.items()}
    assert members == names.enum_values(enum)


def test_a_missing_dialect_module_is_one_line_where_it_is_needed(tmp_path):
    # The names are made on first use: the command line imports without the generated module;
    # its parser offers the dialect's axis and injection names, so building it reports the
    # module's absence, in one line.
    script = ("import sys; sys.modules['heliquad._mavlink'] = None\n"
              "from heliquad.host.acquire import link\nfrom heliquad.host.cli import parser\n"
              "sys.exit(parser.main(sys.argv[1:]))")
    run = subprocess.run([sys.executable, "-c", script, "sweep", "--axis", "roll", "--sil",
                          "--out", str(tmp_path / "out")], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 2, run.stderr
    assert run.stderr.splitlines() == [
        "heliquad: error: the MAVLink dialect module is missing: reinstall heliquad "
        "(pip install .) so the build generates it"]


def test_data_keyed_by_the_names_names_every_entry():
    axes, injections = set(names.AXES), set(names.INJECTIONS)
    for table in (paper.BANDS_HZ, paper.MODELS, paper.CHOSEN_ORDER, paper.RATE_GAINS):
        assert set(table) == axes
    assert set(paper.ANGLE_GAINS) == axes - {"yaw"}           # yaw has no angle loop
    # The axis sweeps' injection points; the per-rotor ones (motor1..8, motors) are driven
    # through the link directly (motor_injection_test).
    per_rotor = {i for i in injections if i.startswith("motor")}
    assert per_rotor == {f"motor{n}" for n in range(1, 9)} | {"motors"}
    assert set(link.INPUT_OUTPUT) == injections - per_rotor
    assert set(excitation.UNITS) == injections - per_rotor
    assert set(excitation.DEFAULT_SETPOINT) == injections - per_rotor - {"mixer"}   # at the mixer
    assert vehicle.RIGS == (*names.AXES, "free")
    imu = {k.replace("-", "_") for k in faults.KINDS} - {"link"}     # link: the host's own
    assert imu == set(names.enum_values("HQ_IMU_FAULT")) - {"none"}


# --- Python sources ----------------------------------------------------------------------------

#: The messages heliquad sends or reads besides its own (docs/link-contract.md).
COMMON_MESSAGES = ("HEARTBEAT", "STATUSTEXT", "COMMAND_LONG", "COMMAND_ACK", "SET_MODE")


@functools.cache
def enum_fields() -> set:
    """The names of the enum-valued fields of the messages heliquad uses, and ``kind`` (what
    the code calls fifo_kind and sensor_kind)."""
    used = {m.get("name") for m in ET.parse(XML).getroot().iter("message")}
    used |= set(COMMON_MESSAGES)
    return {f for cls in MAV.mavlink_map.values() if cls.msgname in used
            for f in cls.fieldenums_by_name} | {"kind"}


@functools.cache
def name_lists() -> list:
    """Each heliquad enum's lower-case names in value order (sim/base/dialect.py's names)."""
    return [list(names.enum_values(enum)) for enum in xml_enums()]


def _int(node) -> bool:
    return (isinstance(node, ast.Constant) and isinstance(node.value, int)
            and not isinstance(node.value, bool))


def _leaf(node) -> str | None:
    """The last identifier of a name or attribute (``m.severity`` -> ``severity``)."""
    if isinstance(node, ast.Name):
        return node.id
    return node.attr if isinstance(node, ast.Attribute) else None


def _strings(node) -> list:
    return [e.value if isinstance(e, ast.Constant) and isinstance(e.value, str) else None
            for e in node.elts]


def _collection_copy(node, lists) -> bool:
    """A tuple, list or set that starts with an enum's first two names in value order, or
    holds its names and nothing else; a dict pairing two or more of one enum's names with
    numbers, either way round."""
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        items = _strings(node)
        return any(len(items) >= 2 and (items[:2] == order[:2] or set(items) == set(order))
                   for order in lists)
    if isinstance(node, ast.Dict):
        pairs = list(zip(node.keys, node.values))
        for order in lists:
            named = [(k, v) for k, v in pairs if isinstance(k, ast.Constant) and k.value in order]
            if len(named) >= 2 and all(_int(v) for _, v in named):
                return True
            named = [(k, v) for k, v in pairs if isinstance(v, ast.Constant) and v.value in order]
            if len(named) >= 2 and all(_int(k) for k, _ in named):
                return True
    return False


def _assigned(node):
    """(target, value) pairs of an assignment, tuples unpacked position by position."""
    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
    for target in targets:
        value = node.value
        if isinstance(target, ast.Tuple) and isinstance(value, ast.Tuple):
            yield from zip(target.elts, value.elts)
        elif value is not None:
            yield target, value


def _value_copies(node, fields, entries) -> list:
    """Numbers standing for a dialect value in this node: why each is a copy."""
    found = []
    if isinstance(node, ast.Compare):
        sides = [node.left, *node.comparators]
        if any(_int(s) for s in sides) and any(_leaf(s) in fields for s in sides):
            found.append("an enum-valued field compared with a number")
    elif isinstance(node, (ast.Assign, ast.AnnAssign)):
        for target, value in _assigned(node):
            leaf = _leaf(target)
            if _int(value) and leaf in fields:
                found.append(f"{leaf} set to a number")
            elif _int(value) and (leaf in entries or f"HQ_{leaf}" in entries):
                found.append(f"{leaf}: a dialect entry written as a number")
    elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
        spec = node.args
        args = spec.posonlyargs + spec.args
        defaults = list(zip(args[len(args) - len(spec.defaults):], spec.defaults))
        defaults += [(a, d) for a, d in zip(spec.kwonlyargs, spec.kw_defaults) if d is not None]
        found += [f"{a.arg} defaults to a number" for a, d in defaults
                  if a.arg in fields and _int(d)]
    elif isinstance(node, ast.keyword):
        if node.arg in fields - {"axis"} and _int(node.value):   # axis=: numpy's keyword
            found.append(f"{node.arg}= a number")
    return found


def _comment_copies(text, entries, arrays) -> list:
    """Line numbers whose code has a number and whose comment names a dialect entry, or an
    array field (``MESSAGE.field``) of the length written there."""
    found = []
    numbers, comments = {}, {}
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.NUMBER and re.fullmatch(r"\d+", tok.string):
            numbers.setdefault(tok.start[0], set()).add(int(tok.string))
        elif tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string
    for line, comment in comments.items():
        if line in numbers and _names_a_value(comment, numbers[line], entries, arrays):
            found.append(line)
    return found


def _names_a_value(comment, numbers, entries, arrays) -> bool:
    """The comment names an entry whose value is one of the numbers, or an array field whose
    length is."""
    if any(entries.get(word) in numbers
           for word in re.findall(r"\b[A-Z][A-Z0-9_]{3,}\b", comment)):
        return True
    return any(arrays.get(field) in numbers
               for field in re.findall(r"\b([A-Z][A-Z0-9_]+\.[a-z_0-9]+)\b", comment))


@functools.cache
def array_lengths() -> dict:
    """{"MESSAGE.field": length} of every array field of the dialect's messages."""
    out = {}
    for cls in MAV.mavlink_map.values():
        for field, n in zip(cls.ordered_fieldnames, cls.array_lengths):
            if n:
                out[f"{cls.msgname}.{field}"] = n
    return out


def python_copies(text: str) -> list:
    """Every hand copy of a dialect value in a Python source: ``line: why``."""
    lists, fields = name_lists(), enum_fields()
    entries = entry_values()
    found = []
    for node in ast.walk(ast.parse(text)):
        if _collection_copy(node, lists):
            found.append(f"{node.lineno}: a copy of an enum's names")
        found += [f"{node.lineno}: {why}" for why in _value_copies(node, fields, entries)]
    found += [f"{line}: a number beside a dialect name in its comment"
              for line in _comment_copies(text, entries, array_lengths())]
    return found


def python_sources() -> list:
    files = [p for folder in ("host", "sim", "benchmarks") for p in (ROOT / folder).rglob("*.py")]
    files += [p for p in (ROOT / "tests").rglob("*.py") if not p.name.endswith("_test.py")]
    return sorted(files)


def test_no_hand_copy_in_python():
    offenders = []
    for path in python_sources():
        rel = path.relative_to(ROOT).as_posix()
        copies = python_copies(path.read_text())
        if rel in PENDING:
            assert len(copies) == PENDING[rel], f"{rel}: {copies}"
            continue
        offenders += [f"{rel}:{c}" for c in copies]
    assert not offenders, ("write these with the generated dialect's names (heliquad._mavlink, "
                           "sim/base/dialect.py), not as copies:\n" + "\n".join(offenders))


# --- C++ sources -------------------------------------------------------------------------------

ENUM = re.compile(r"\benum\s+(?:class\s+)?\w+\s*(?::\s*[\w:]+\s*)?\{([^}]*)\}", re.S)
ENUMERATOR = re.compile(r"\b([A-Z]\w*)\s*=\s*(\d+)\b")
COMPARED = re.compile(r"\b(\w+)\s*[!=]=\s*(\d+)\b")


def snake(name: str) -> str:
    """``StopCommand`` -> ``STOP_COMMAND``."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).upper()


def _enum_copies(code) -> list:
    """Enums of which two or more number-initialised enumerators are one dialect enum's
    entries, by name and value."""
    found = []
    for match in ENUM.finditer(code):
        members = {snake(n): int(v) for n, v in ENUMERATOR.findall(match.group(1))}
        for enum, short in short_names().items():
            same = [n for n, v in members.items() if short.get(n) == v]
            if len(same) >= 2:
                found.append(f"{code.count(chr(10), 0, match.start()) + 1}: enum copies {enum}")
                break
    return found


@functools.cache
def short_names() -> dict:
    """{enum: {"STOP_COMMAND": value, ...}}: every dialect enum's entries without their shared
    prefix (sim/base/dialect.py's names, upper case), as a C++ enumerator would spell them."""
    return {enum: {name.upper(): v for name, v in names.enum_values(enum).items()}
            for enum in MAV.enums}


def cpp_copies(text: str) -> list:
    """Every hand copy of a dialect value in a C++ source: ``line: why``."""
    entries = entry_values()
    arrays, fields = array_lengths(), enum_fields() | {"fault"}
    found = _enum_copies(re.sub(r"//[^\n]*", "", text))
    lines = text.splitlines()
    for i, line in enumerate(lines):
        code, _, comment = line.partition("//")
        numbers = {int(n) for n in re.findall(r"(?<![\w.])(\d+)(?![\w.])", code)}
        above = lines[i - 1].strip() if i else ""
        if above.startswith("//"):
            comment += " " + above
        if numbers and comment and _names_a_value(comment, numbers, entries, arrays):
            found.append(f"{i + 1}: a number beside a dialect name in its comment")
        if any(name in fields for name, _ in COMPARED.findall(code)):
            found.append(f"{i + 1}: an enum-valued field compared with a number")
    return found


def cpp_sources() -> list:
    files = [p for folder in ("firmware", "sim") for ext in ("*.hpp", "*.cpp")
             for p in (ROOT / folder).rglob(ext)]
    # The MK64F12 register header is generated from NXP's SVD (registers, not the dialect).
    return sorted(p for p in files if p.name != "mk64f12.hpp")


def test_no_hand_copy_in_cpp():
    offenders = [f"{path.relative_to(ROOT).as_posix()}:{c}"
                 for path in cpp_sources() for c in cpp_copies(path.read_text())]
    assert not offenders, ("use the generated headers' constants (HQ_*, MAV_*, "
                           "MAVLINK_MSG_*_FIELD_*_LEN), not copies:\n" + "\n".join(offenders))


# --- the scans themselves ----------------------------------------------------------------------

#: Copies each scan must find: the ones these sources had.
PYTHON_COPIES = [
    'AXES = {"roll": 0, "pitch": 1, "yaw": 2}',
    'INJECTIONS = {"angle": 0, "rate": 1, "mixer": 2}',
    'NAMES = {0: "idle", 1: "fading"}',
    'RIGS = ("roll", "pitch", "yaw", "free")',
    'i = ["angle", "rate", "mixer"].index(inject)',
    'p.add_argument("--mode", choices=("angle", "rate"))',
    "kind = 0",
    "self.frame, self.kind, self.reply = 0, 0, None",
    "ok = m.severity <= 4",
    "ok = reply.mode == 2",
    "def step(self, imu_fault: int = 0): pass",
    "link.step(t, fifo_kind=1)",
    "MAV_CMD_COMPONENT_ARM_DISARM = 400",
    "SENSOR_NONE, SENSOR_DMP, SENSOR_RAW = 0, 1, 2",
    "mav.heartbeat_send(6, 8, 0, 0, 0)  # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID",
    "FIFO_CAPACITY = 168            # HQ_SENSOR_FRAME.fifo",
]
CPP_COPIES = [
    "enum class FifoKind : uint8_t { None = 0, Dmp = 1, Raw = 2 };",
    "enum class Axis : uint8_t { Roll = 0, Pitch = 1, Yaw = 2 };",
    "enum class Severity : uint8_t { Critical = 2, Warning = 4, Notice = 5, Info = 6 };",
    "enum class Reason : uint8_t {\n    None = 0,\n    Finished = 1,\n};",
    "constexpr size_t kFifoCapacity = 168;        // HQ_SENSOR_FRAME.fifo",
    "// STATUSTEXT.text is 50 characters, NUL-terminated when shorter.\n"
    "constexpr size_t kStatusTextLen = 50;",
    "    if (kind == 3) chip.power_on_reset();",
]
#: What is no copy.
PYTHON_CLEAN = [
    'BANDS_HZ = {"roll": (0.5, 4.5), "pitch": (0.5, 4.8), "yaw": (0.15, 1.6)}',
    'KINDS = {"silent": True, "nack": True, "reset": False}',
    "x = np.std(a, axis=0)",
    "kind = mav.HQ_SENSOR_NONE",
    'columns = ("angle_sp", "rate_sp", "rate", "angle")',
    "n = 4  # four arm rotors",
]
CPP_CLEAN = [
    "enum class ArmSource : uint8_t { None = 0, RcSwitch = 1, Command = 2 };",
    "enum class Axis : uint8_t { Roll = HQ_AXIS_ROLL, Pitch = HQ_AXIS_PITCH };",
    "constexpr int kMotors = 5;   // 0 central, 1 front, 2 right, 3 back, 4 left",
    "uint8_t sensor_clipped = 0;  // HQ_SATURATION_GYRO / _ACCEL bits of the last IMU sample",
    "if (fault == HQ_IMU_FAULT_RESET) chip_.power_on_reset();",
]


@pytest.mark.parametrize("scan, source", [(python_copies, s) for s in PYTHON_COPIES]
                         + [(cpp_copies, s) for s in CPP_COPIES])
def test_the_scans_find_a_copy(scan, source):
    assert scan(source + "\n")


@pytest.mark.parametrize("scan, source", [(python_copies, s) for s in PYTHON_CLEAN]
                         + [(cpp_copies, s) for s in CPP_CLEAN])
def test_the_scans_pass_what_is_no_copy(scan, source):
    assert scan(source + "\n") == []
