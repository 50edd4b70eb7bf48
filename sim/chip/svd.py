"""The MK64F12 SVD: where to find it, how to read it, and the generated register tables.

The register tables the models use (``regmap.py``) are generated from NXP's (Freescale's)
CMSIS-SVD description of the MK64F12, never typed by hand. The SVD is not in this repository:
it ships inside pyOCD (``pyocd/debug/svd/svd_data.zip`` -> ``MK64F12.svd``, BSD-3-Clause).
:func:`find_svd` looks for it in this order:

1. ``$HQ_MK64_SVD``: a path to ``MK64F12.svd``, to ``svd_data.zip`` or to a pyOCD wheel;
2. an installed ``pyocd`` package.

Regenerate the tables (after adding a peripheral to :data:`MODELLED`)::

    python -m heliquad.sim.chip.svd --write         # or: python sim/chip/svd.py --write

``tests/teensy35_boot_test.py`` regenerates them in memory and compares with the committed
file whenever an SVD is found.
"""

from __future__ import annotations

import argparse
import importlib.resources as resources
import io
import os
import pathlib
import sys
import xml.etree.ElementTree as ET
import zipfile

SVD_NAME = "MK64F12.svd"
SVD_ZIP_MEMBER = "pyocd/debug/svd/svd_data.zip"
ENV_VAR = "HQ_MK64_SVD"

# The peripherals whose registers the emulator models or initialises (SVD names). The
# Cortex-M4 core blocks the SVD does not describe (DWT, CoreDebug) are in registers.py.
MODELLED = (
    "SIM", "WDOG", "MCG", "OSC", "PMC", "SMC", "RCM", "MPU",
    "PORTA", "PORTB", "PORTC", "PORTD", "PORTE",
    "GPIOA", "GPIOB", "GPIOC", "GPIOD", "GPIOE",
    "I2C0", "UART0", "FTM0", "FTM3", "PIT", "USB0", "SDHC",
    "SystemControl", "SysTick", "NVIC", "MCM", "FTFE", "FMC",
)

REGMAP_PATH = pathlib.Path(__file__).with_name("regmap.py")


class SvdNotFound(LookupError):
    pass


def _svd_from_zip_bytes(data: bytes) -> bytes:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return z.read(SVD_NAME)


def read_svd_bytes(path: os.PathLike | str) -> bytes:
    """The SVD's bytes from an .svd file, pyOCD's svd_data.zip, or a pyOCD wheel."""
    path = pathlib.Path(path)
    if path.suffix == ".svd":
        return path.read_bytes()
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        if SVD_NAME in names:                       # svd_data.zip itself
            return z.read(SVD_NAME)
        if SVD_ZIP_MEMBER in names:                 # a pyOCD wheel
            return _svd_from_zip_bytes(z.read(SVD_ZIP_MEMBER))
    raise SvdNotFound(f"{path}: holds neither {SVD_NAME} nor {SVD_ZIP_MEMBER}")


def find_svd() -> bytes:
    """The MK64F12 SVD's bytes, or SvdNotFound saying where it looked."""
    env = os.environ.get(ENV_VAR)
    if env:
        if not pathlib.Path(env).exists():
            raise SvdNotFound(f"${ENV_VAR}={env} does not exist")
        return read_svd_bytes(env)
    try:
        data = resources.files("pyocd.debug.svd").joinpath("svd_data.zip").read_bytes()
        return _svd_from_zip_bytes(data)
    except (ModuleNotFoundError, FileNotFoundError, KeyError):
        pass
    raise SvdNotFound(f"no MK64F12 SVD: set ${ENV_VAR} to MK64F12.svd, pyOCD's svd_data.zip "
                      "or a pyOCD wheel (pip download pyocd==0.46.0 --no-deps), or install pyocd")


def _int(text: str | None, default: int = 0) -> int:
    if text is None:
        return default
    text = text.strip().lower()
    return int(text, 0) if not text.startswith("#") else int(text[1:], 2)


def parse(svd: bytes, names=MODELLED) -> dict:
    """{peripheral: (base, {register: (offset, bits, reset, {field: (lsb, width)})})}.

    Arrays (``dim``) are expanded: FTM's ``C%sSC`` becomes C0SC..C7SC. Only the named
    peripherals are kept.
    """
    root = ET.fromstring(svd)
    out = {}
    for p in root.iter("peripheral"):
        name = p.findtext("name")
        if name not in names:
            continue
        if p.get("derivedFrom"):
            raise ValueError(f"{name}: derived peripherals are not handled")
        base = _int(p.findtext("baseAddress"))
        regs = {}
        for r in p.findall("registers/register"):
            rname = r.findtext("name")
            offset = _int(r.findtext("addressOffset"))
            bits = _int(r.findtext("size"), 32)
            reset = _int(r.findtext("resetValue"))
            fields = {f.findtext("name"): (_int(f.findtext("bitOffset")), _int(f.findtext("bitWidth")))
                      for f in r.findall("fields/field")}
            dim = r.findtext("dim")
            if dim is None:
                regs[rname] = (offset, bits, reset, fields)
                continue
            step = _int(r.findtext("dimIncrement"))
            index = r.findtext("dimIndex")
            labels = index.split(",") if index and "," in index else [str(i) for i in range(_int(dim))]
            for i, label in enumerate(labels):
                regs[rname.replace("%s", label)] = (offset + i * step, bits, reset, fields)
        out[name] = (base, regs)
    missing = set(names) - set(out)
    if missing:
        raise ValueError(f"not in the SVD: {sorted(missing)}")
    return out


HEADER = '''"""Register tables of the MK64F12, generated from NXP's CMSIS-SVD (MK64F12.svd v{version}).

Do not edit: regenerate with ``python -m heliquad.sim.chip.svd --write``. For each modelled
peripheral: base address and, per register, (offset, width in bits, reset value,
{{field: (lsb, width)}}); and the IRQ number of every interrupt.

Derived from MK64F12.svd, Copyright (c) Freescale Semiconductor, Inc., under the
BSD-3-Clause licence that file carries:
{licence}
"""

# fmt: off
PERIPHERALS = '''


def interrupts(svd: bytes) -> dict:
    """{interrupt name: IRQ number} for every interrupt the SVD declares (all peripherals)."""
    root = ET.fromstring(svd)
    out = {}
    for irq in root.iter("interrupt"):
        out[irq.findtext("name")] = _int(irq.findtext("value"))
    return out


def render(svd: bytes) -> str:
    root = ET.fromstring(svd)
    licence = (root.findtext("licenseText") or "").replace("\\n", "\n").strip()
    licence = "\n".join("    " + line.strip() for line in licence.splitlines())
    lines = ["{"]
    for name, (base, regs) in sorted(parse(svd).items()):
        lines.append(f"    {name!r}: (0x{base:08X}, {{")
        for rname, (offset, bits, reset, fields) in sorted(regs.items(), key=lambda kv: (kv[1][0], kv[0])):
            fs = ", ".join(f"{f!r}: ({lsb}, {width})" for f, (lsb, width) in fields.items())
            lines.append(f"        {rname!r}: (0x{offset:04X}, {bits}, 0x{reset:X}, {{{fs}}}),")
        lines.append("    }),")
    lines.append("}")
    lines.append("")
    lines.append("# IRQ numbers (exception number - 16) of every interrupt the SVD declares.")
    lines.append("INTERRUPTS = {")
    for name, number in sorted(interrupts(svd).items(), key=lambda kv: kv[1]):
        lines.append(f"    {name!r}: {number},")
    lines.append("}")
    return HEADER.format(version=root.findtext("version"), licence=licence) + "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Regenerate sim/chip/regmap.py from the SVD")
    parser.add_argument("--svd", help="MK64F12.svd, svd_data.zip or a pyOCD wheel")
    parser.add_argument("--write", action="store_true", help=f"write {REGMAP_PATH.name}")
    args = parser.parse_args(argv)
    svd = read_svd_bytes(args.svd) if args.svd else find_svd()
    text = render(svd)
    if args.write:
        REGMAP_PATH.write_text(text)
        print(f"wrote {REGMAP_PATH}")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
