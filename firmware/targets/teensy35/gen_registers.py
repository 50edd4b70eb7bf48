#!/usr/bin/env python3
"""Generate firmware/targets/teensy35/mk64f12.hpp from the MK64F12 SVD.

No peripheral address in the Teensy 3.5 backends is typed by hand: every register the target
uses is emitted here from NXP's CMSIS-SVD description of the MK64F12 family (the MK64FX512 on
the Teensy 3.5 is one of them), plus the few ARMv7-M debug registers the SVD leaves out
(armv7m_debug.svd beside this script, written from the ARMv7-M Architecture Reference Manual).

Where the SVD comes from: the PyPI wheel of pyocd ships it as
pyocd/debug/svd/svd_data.zip -> MK64F12.svd (BSD-3-Clause; its licence text is copied into
the generated header). Any of these works as --svd:
  * the .svd file itself,
  * svd_data.zip,
  * the pyocd wheel (.whl),
  * nothing: the installed pyocd package is searched.

    python firmware/targets/teensy35/gen_registers.py [--svd PATH] [--out PATH] [--check]

--check compares instead of writing and exits 1 when the committed header is stale. The
output is deterministic (same SVD, same bytes), which tests/teensy35_image_test.py relies on.

What is emitted, per register: a struct deriving from Reg<T, address> (read/write/set/clear
of the volatile register), with its RESET_VALUE where the SVD gives one, one constant per single-bit field (its mask) and, per
multi-bit field, NAME_SHIFT, NAME_MASK and NAME(value) placing a value in the field.
Register arrays (C%sSC, PCR%s, ...) are expanded (C0SC..C7SC). IRQ numbers go into
namespace irq.
"""

from __future__ import annotations

import argparse
import io
import pathlib
import re
import sys
import xml.etree.ElementTree as ET
import zipfile

HERE = pathlib.Path(__file__).resolve().parent
DEFAULT_OUT = HERE / "mk64f12.hpp"
SUPPLEMENT = HERE / "armv7m_debug.svd"
SVD_MEMBER = "MK64F12.svd"
WHEEL_MEMBER = "pyocd/debug/svd/svd_data.zip"

# The peripherals the Teensy 3.5 backends use (and the flash configuration field's layout).
PERIPHERALS = (
    "SIM", "WDOG", "MCG", "OSC", "PORTB", "PORTC", "PORTD", "GPIOB", "GPIOC", "GPIOD", "I2C0", "UART0", "FTM0",
    "FTM3", "PIT", "SystemControl", "SysTick", "NVIC", "FTFE_FlashConfig", "RCM",
    "CoreDebug", "DWT",
)
# Interrupts the backends install handlers for (all IRQ numbers are emitted anyway).
C_TYPES = {8: "uint8_t", 16: "uint16_t", 32: "uint32_t"}


class SvdError(Exception):
    pass


def _int(text: str | None, default: int | None = None) -> int:
    if text is None:
        if default is None:
            raise SvdError("missing number in the SVD")
        return default
    text = text.strip().lower()
    if text.startswith("#"):
        return int(text[1:], 2)
    return int(text, 0)


def read_svd_bytes(source: str | None) -> bytes:
    """The SVD's bytes from a path (.svd, svd_data.zip, pyocd wheel) or the installed pyocd."""
    if source is None:
        try:
            import importlib.util
            spec = importlib.util.find_spec("pyocd")
        except (ImportError, ValueError):
            spec = None
        if spec is None or not spec.submodule_search_locations:
            raise SvdError("no --svd given and pyocd is not installed "
                           "(pip download pyocd==0.46.0 --no-deps, then --svd the wheel)")
        source = str(pathlib.Path(list(spec.submodule_search_locations)[0])
                     / "debug" / "svd" / "svd_data.zip")
    path = pathlib.Path(source)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SvdError(f"{source}: {exc.strerror}") from None
    if not zipfile.is_zipfile(io.BytesIO(data)):
        return data
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        names = zf.namelist()
        if WHEEL_MEMBER in names:
            with zipfile.ZipFile(io.BytesIO(zf.read(WHEEL_MEMBER))) as inner:
                return inner.read(SVD_MEMBER)
        if SVD_MEMBER in names:
            return zf.read(SVD_MEMBER)
    raise SvdError(f"{source}: holds neither {WHEEL_MEMBER} nor {SVD_MEMBER}")


def _registers(periph: ET.Element, base: int, default_size: int):
    """(name, address, size_bits, reset value or None, [(field, offset, width)]) for every
    register, arrays expanded."""
    out = []
    regs = periph.find("registers")
    if regs is None:
        return out
    for reg in regs.findall("register"):
        name = reg.findtext("name")
        offset = _int(reg.findtext("addressOffset"))
        size = _int(reg.findtext("size"), default_size)
        reset = reg.findtext("resetValue")
        reset = None if reset is None else _int(reset)
        fields = []
        fnode = reg.find("fields")
        for f in (fnode.findall("field") if fnode is not None else []):
            fields.append((f.findtext("name"), _int(f.findtext("bitOffset")),
                           _int(f.findtext("bitWidth"))))
        dim = reg.findtext("dim")
        if dim is None:
            out.append((name, base + offset, size, reset, fields))
            continue
        step = _int(reg.findtext("dimIncrement"))
        index = reg.findtext("dimIndex")
        labels = (index.split(",") if index and "," in index
                  else [str(i) for i in range(_int(dim))])
        for i, label in enumerate(labels):
            out.append((name.replace("%s", label.strip()), base + offset + i * step, size, reset,
                        fields))
    return out


def parse(svd: bytes, supplement: bytes | None = None):
    """{peripheral: (base, description, registers)}, {irq name: number}, licence text."""
    roots = [ET.fromstring(svd)]
    if supplement is not None:
        roots.append(ET.fromstring(supplement))
    periphs: dict[str, tuple[int, str, list]] = {}
    irqs: dict[str, int] = {}
    licence = (roots[0].findtext("licenseText") or "").replace("\\n", "\n")
    for root in roots:
        default_size = _int(root.findtext("size"), 32)
        nodes = {p.findtext("name"): p for p in root.iter("peripheral")}
        for name, node in nodes.items():
            base = _int(node.findtext("baseAddress"))
            src = nodes[node.get("derivedFrom")] if node.get("derivedFrom") else node
            desc = " ".join((node.findtext("description") or src.findtext("description")
                             or "").split())
            periphs[name] = (base, desc, _registers(src, base, default_size))
            for irq in node.findall("interrupt"):
                irqs[irq.findtext("name")] = _int(irq.findtext("value"))
    return periphs, irqs, licence


def _ident(name: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return "_" + name if name[0].isdigit() else name


def generate(svd: bytes, supplement: bytes | None = None) -> str:
    periphs, irqs, licence = parse(svd, supplement)
    missing = [p for p in PERIPHERALS if p not in periphs]
    if missing:
        raise SvdError(f"the SVD lacks {', '.join(missing)}")
    lines = [
        "// GENERATED by firmware/targets/teensy35/gen_registers.py from NXP's MK64F12 SVD",
        "// (version in the SVD header below) and armv7m_debug.svd. Do not edit: regenerate.",
        "//",
        "// The register descriptions are derived from the MK64F12 SVD, distributed under this",
        "// licence:",
        "//",
    ]
    lines += ["//   " + ln.rstrip() if ln.strip() else "//" for ln in licence.strip().splitlines()]
    lines += [
        "",
        "#pragma once",
        "",
        "#include <cstdint>",
        "",
        "namespace hq::mk64 {",
        "",
        "// One memory-mapped register: T is its width, A its address.",
        "template <typename T, uint32_t A>",
        "struct Reg {",
        "    using type = T;",
        "    static constexpr uint32_t address = A;",
        "    static volatile T& ref() { return *reinterpret_cast<volatile T*>(uintptr_t{A}); }",
        "    static T read() { return ref(); }",
        "    static void write(T v) { ref() = v; }",
        "    static void set(T bits) { ref() = static_cast<T>(ref() | bits); }",
        "    static void clear(T bits) { ref() = static_cast<T>(ref() & static_cast<T>(~bits)); }",
        "};",
        "",
    ]
    for pname in PERIPHERALS:
        base, desc, regs = periphs[pname]
        lines.append(f"// {pname}: {desc}" if desc else f"// {pname}")
        lines.append(f"namespace {_ident(pname)} {{")
        lines.append(f"constexpr uint32_t BASE = 0x{base:08X}u;")
        for rname, addr, size, reset, fields in regs:
            ctype = C_TYPES.get(size)
            if ctype is None:
                raise SvdError(f"{pname}.{rname}: register size {size}")
            rid = _ident(rname)
            body = []
            if reset is not None:
                body.append(f"    static constexpr {ctype} RESET_VALUE = 0x{reset:X}u;")
            for fname, off, width in fields:
                fid = _ident(fname)
                if fid == rid:
                    fid += "_"
                mask = ((1 << width) - 1) << off
                if width == 1:
                    body.append(f"    static constexpr {ctype} {fid} = 0x{mask:X}u;")
                else:
                    body.append(f"    static constexpr uint32_t {fid}_SHIFT = {off};")
                    body.append(f"    static constexpr {ctype} {fid}_MASK = 0x{mask:X}u;")
                    body.append(f"    static constexpr {ctype} {fid}(uint32_t v) {{ return "
                                f"static_cast<{ctype}>((v << {off}) & 0x{mask:X}u); }}")
            head = f"struct {rid} : Reg<{ctype}, 0x{addr:08X}u> {{"
            if body:
                lines.append(head)
                lines += body
                lines.append("};")
            else:
                lines.append(head + "};")
        lines.append(f"}}  // namespace {_ident(pname)}")
        lines.append("")
    lines.append("// Interrupt numbers (vector = 16 + IRQ).")
    lines.append("namespace irq {")
    for name, num in sorted(irqs.items(), key=lambda kv: (kv[1], kv[0])):
        lines.append(f"constexpr int {_ident(name)} = {num};")
    lines.append(f"constexpr int kCount = {max(irqs.values()) + 1};")
    lines.append("}  // namespace irq")
    lines.append("")
    lines.append("}  // namespace hq::mk64")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--svd", help="MK64F12.svd, svd_data.zip or the pyocd wheel "
                                  "(default: the installed pyocd)")
    ap.add_argument("--out", default=str(DEFAULT_OUT), help="header to write")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 if the header differs from what the SVD gives")
    args = ap.parse_args(argv)
    try:
        text = generate(read_svd_bytes(args.svd), SUPPLEMENT.read_bytes())
    except (SvdError, ET.ParseError) as exc:
        print(f"gen_registers: {exc}", file=sys.stderr)
        return 2
    out = pathlib.Path(args.out)
    if args.check:
        current = out.read_text() if out.exists() else ""
        if current != text:
            print(f"gen_registers: {out} is stale; regenerate it", file=sys.stderr)
            return 1
        return 0
    out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
