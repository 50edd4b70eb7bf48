"""Every C++ source reaches the generated MAVLink library through firmware/mavlink/include/
hq_mavlink.hpp, which gives it the table-driven checksum: a source that included
<heliquad/mavlink.h> itself would build the library's slower one into its own code."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WRAPPER = ROOT / "firmware" / "mavlink" / "include" / "hq_mavlink.hpp"
DIRECT = re.compile(r'^\s*#\s*include\s*[<"](heliquad|common|minimal|standard)/[^>"]+[>"]', re.M)


def sources():
    for top in ("firmware", "sim"):
        for path in (ROOT / top).rglob("*"):
            if path.suffix in (".cpp", ".hpp", ".h", ".c") and "third_party" not in path.parts:
                yield path


def test_no_source_includes_the_generated_library_but_the_wrapper():
    found = [f"{p.relative_to(ROOT)}: {m.group(0).strip()}" for p in sources() if p != WRAPPER
             for m in DIRECT.finditer(p.read_text(errors="replace"))]
    assert not found, found


def test_the_wrapper_is_what_the_mavlink_users_include():
    users = [p for p in sources() if "hq_mavlink.hpp" in p.read_text(errors="replace")
             and p != WRAPPER]
    assert len(users) >= 10, [str(p) for p in users]
    assert "#define HAVE_CRC_ACCUMULATE" in WRAPPER.read_text()
