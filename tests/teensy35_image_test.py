"""The Teensy 3.5 image as built by the CMake preset: what the chip and the loader need of it.

Read with the emulator's ELF loader (heliquad.sim.chip.image, pyelftools underneath) and
intelhex, never by running it (tests/teensy35_boot_test.py runs it in the emulated MK64FX512). A wrong byte here bricks a board or leaves an interrupt on the
default handler, so each fact the boot ROM, the bootloader or the NVIC relies on is pinned.
"""

from __future__ import annotations

import os
import pathlib
import re
import shutil
import subprocess
import sys

import pytest
from elftools.elf.elffile import ELFFile
from intelhex import IntelHex

from heliquad.sim.chip import svd
from heliquad.sim.chip.image import Image

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from teensy_image import ROOT, image  # noqa: E402

FLASH_SIZE = 0x8_0000
SRAM_LOW, SRAM_TOP = 0x1FFF_0000, 0x2002_0000
VECTOR_COUNT = 16 + 86
# Exception and IRQ numbers of the MK64FX512 (vector = 16 + IRQ).
SYSTICK, I2C0, UART0_RX_TX, USB0, FTM3 = 15, 16 + 24, 16 + 31, 16 + 53, 16 + 71
RESERVED = (7, 8, 9, 10, 13)


@pytest.fixture(scope="module")
def img():
    return image()


@pytest.fixture(scope="module")
def loaded(img):
    return Image(img.elf)


@pytest.fixture(scope="module")
def elf(img, loaded):
    # Build attributes: the one thing the loader does not read.
    with open(img.elf, "rb") as fh:
        attrs = {}
        for sub in ELFFile(fh).get_section_by_name(".ARM.attributes").iter_subsections():
            for subsub in sub.iter_subsubsections():
                for a in subsub.iter_attributes():
                    attrs[a.tag] = a.value
    # Symbols at their addresses (functions without the Thumb bit); vector words as stored.
    return {"symbols": {name: sym.address for name, sym in loaded.symbols.items()},
            "sections": loaded.sections, "attrs": attrs,
            "vectors": [loaded.word(4 * i) for i in range(VECTOR_COUNT)]}


@pytest.fixture(scope="module")
def hexfile(img):
    ih = IntelHex()
    ih.loadhex(str(img.hex))
    return ih


def test_flash_configuration_field_leaves_the_chip_unsecured(hexfile):
    field = bytes(hexfile[a] for a in range(0x400, 0x410))
    assert field[:12] == b"\xff" * 12, "backdoor key and FPROT erased: nothing write-protected"
    fsec, fopt, feprot, fdprot = field[12:]
    assert fsec & 0b11 == 0b10, f"FSEC 0x{fsec:02X}: SEC must be 0b10 (unsecure)"
    assert fsec == 0xFE
    assert fopt == 0xF9, "FOPT: normal boot (LPBOOT 1), EzPort off, NMI pin off"
    assert (feprot, fdprot) == (0xFF, 0xFF)


def test_everything_lies_in_the_512_kib_flash(hexfile):
    addresses = hexfile.addresses()
    assert min(addresses) == 0 and max(addresses) < FLASH_SIZE


def test_hex_holds_exactly_the_elf_load_image(img, loaded):
    """The .hex is the ELF's loadable bytes (text, then .data's initial values), nothing else."""
    assert loaded.compare_hex(img.hex) == []


def test_the_parameter_sectors_hold_nothing_of_the_image(elf, hexfile):
    """The top two 4 KiB sectors are the parameter storage's, the two below them the on-board
    program's (mk64fx512.ld): nothing is linked there. The function that launches a flash
    command and waits for it runs from RAM: it is in .data, copied there at start-up."""
    sym = elf["symbols"]
    assert (sym["hq_param_flash_start"], sym["hq_param_flash_end"]) == (0x7E000, FLASH_SIZE)
    assert (sym["hq_program_flash_start"], sym["hq_program_flash_end"]) == (0x7C000, 0x7E000)
    assert max(hexfile.addresses()) < sym["hq_program_flash_start"]
    data_addr, data_size, _, _ = elf["sections"][".data"]
    assert SRAM_LOW <= data_addr <= sym["hq_ftfe_run"] < data_addr + data_size


def test_initial_stack_pointer_is_the_top_of_sram_and_8_aligned(elf):
    sp = elf["vectors"][0]
    assert SRAM_LOW < sp <= SRAM_TOP and sp % 8 == 0
    assert sp == elf["symbols"]["_estack"] == SRAM_TOP


def test_reset_vector_is_a_thumb_address_of_reset_handler_in_text(elf):
    reset = elf["vectors"][1]
    text_addr, text_size, _, _ = elf["sections"][".text"]
    assert reset & 1, "Thumb bit"
    assert reset == elf["symbols"]["Reset_Handler"] | 1    # ELF symbols of Thumb code carry bit 0
    assert text_addr <= (reset & ~1) < text_addr + text_size


def test_vector_slots_point_at_the_intended_handlers(elf):
    v, sym = elf["vectors"], elf["symbols"]
    assert v[SYSTICK] == sym["SysTick_Handler"] | 1
    assert v[UART0_RX_TX] == sym["UART0_RX_TX_IRQHandler"] | 1
    assert v[FTM3] == sym["FTM3_IRQHandler"] | 1
    assert v[I2C0] == sym["I2C0_IRQHandler"] | 1
    assert v[USB0] == sym["USB0_IRQHandler"] | 1
    assert v[3] == sym["HardFault_Handler"] | 1
    for i in RESERVED:
        assert v[i] == 0, f"reserved vector {i}"
    used = {SYSTICK, I2C0, UART0_RX_TX, USB0, FTM3}
    default = sym["Default_Handler"] | 1
    for i in range(16, VECTOR_COUNT):
        if i not in used:
            assert v[i] == default, f"IRQ {i - 16} not on Default_Handler"
    # A handler with a C++ name would leave its slot on the default: check the names exist
    # unmangled (they are the ones above) and that nothing else claims to be one.
    assert not [n for n in sym if n.startswith("_Z") and "IRQHandler" in n]


def test_vector_table_and_flash_configuration_sit_where_the_chip_reads_them(elf):
    assert elf["symbols"]["hq_vectors"] == 0
    assert elf["symbols"]["hq_flash_config"] == 0x400


def test_elf_is_cortex_m4_with_single_precision_hard_float(elf):
    a = elf["attrs"]
    assert a["TAG_CPU_NAME"] == "7E-M"
    assert a["TAG_CPU_ARCH"] == 13            # v7E-M
    assert a["TAG_CPU_ARCH_PROFILE"] == ord("M")
    assert a["TAG_FP_ARCH"] == 6              # VFPv4-D16
    assert a["TAG_ABI_VFP_ARGS"] == 1         # arguments in VFP registers: hard float
    assert a["TAG_ABI_HARDFP_USE"] == 1       # single precision only


def _size_a(path) -> dict[str, int]:
    out = subprocess.run(["arm-none-eabi-size", "-A", str(path)], capture_output=True,
                         text=True, check=True).stdout
    sizes = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0].startswith(".") and parts[1].isdigit():
            sizes[parts[0]] = int(parts[1])
    return sizes


#: An input section's line in the link map: name (or on the line before), address, size,
#: object.
_MAP_LINE = re.compile(r"^ (\.\S+)?\s+0x([0-9a-f]+)\s+0x([0-9a-f]+)\s+(\S+)$")


def _map_flash_bytes(map_path, obj: str) -> int:
    """Flash bytes (code, constants, initial data) the link placed from object ``obj``
    (matched at the end of the map's object name), from the image's link map."""
    text = pathlib.Path(map_path).read_text()
    text = text[text.index("Linker script and memory map"):]
    total, name = 0, None
    for line in text.splitlines():
        alone = re.match(r"^ (\.\S+)$", line)
        if alone:
            name = alone.group(1)
            continue
        m = _MAP_LINE.match(line)
        if m:
            section = m.group(1) or name
            name = None
            if (m.group(4).endswith(obj) and section.startswith((".text", ".rodata", ".data"))
                    and int(m.group(2), 16) != 0):
                total += int(m.group(3), 16)
    return total


def test_flash_and_static_ram_stay_within_budget(img):
    """Flash <= 96 KiB plus FatFs's own code, static RAM <= 24 KiB (of 512 / 192). With the
    USB stack and its second MAVLink link the image was about 76 KiB and 19 KiB; the bounds
    left room for the on-board logger and program, and FatFs (the vendored library, its
    code as linked, from the link map) comes on top; not room for another unmeasured
    growth."""
    s = _size_a(img.elf)
    flash = s[".text"] + s.get(".ARM.exidx", 0) + s.get(".data", 0)
    ram = s.get(".data", 0) + s.get(".bss", 0)
    fatfs = _map_flash_bytes(img.elf.with_suffix(".map"), "(ff.c.obj)")
    print(f"flash {flash} B (FatFs {fatfs} B), static RAM {ram} B")
    assert 4000 < fatfs < 12000, "FatFs's code not found in the link map"
    assert flash <= 96 * 1024 + fatfs, s
    assert ram <= 24 * 1024, s


def test_no_heap_and_no_exception_machinery_in_the_image(elf):
    names = set(elf["symbols"])
    for forbidden in ("malloc", "free", "_sbrk", "_Znwj", "_ZdlPv", "__cxa_allocate_exception",
                      "__cxa_throw", "abort", "_write", "__cxa_atexit"):
        assert forbidden not in names, forbidden


def test_a_heap_call_fails_the_link(img, tmp_path):
    """Linked exactly as the image is (the build's own link command), one `new` breaks it."""
    cmd = img.link_command.read_text().strip()
    probe = tmp_path / "probe.cpp"
    probe.write_text("int* hq_probe() { return new int(1); }\n"
                     "extern \"C\" int* hq_probe_keep = hq_probe();\n")
    obj = tmp_path / "probe.o"
    subprocess.run(["arm-none-eabi-g++", "-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16",
                    "-mfloat-abi=hard", "-fno-exceptions", "-fno-rtti", "-c", str(probe),
                    "-o", str(obj)], check=True)
    out = tmp_path / "probe.elf"
    cmd = re.sub(r"-o \S+", f"-o {out}", cmd)
    cmd = cmd.replace("-Wl,--gc-sections", "")          # keep the probe
    cmd += f" {obj} -Wl,-u,hq_probe_keep"
    res = subprocess.run(cmd, shell=True, cwd=img.link_command.parents[2], capture_output=True,
                         text=True)
    assert res.returncode != 0, "a heap allocation linked"
    assert "_sbrk" in res.stderr or "operator new" in res.stderr or "_Znwj" in res.stderr, res.stderr


def test_core_library_has_no_writable_data(img):
    """The core keeps no globals: every object's state lives in its owner."""
    total = subprocess.run(["arm-none-eabi-size", "-t", str(img.core_lib)], capture_output=True,
                           text=True, check=True).stdout.splitlines()[-1].split()
    text, data, bss = map(int, total[:3])
    assert text > 0 and data == 0 and bss == 0, total


def test_teensy_loader_reads_the_hex_and_reports_its_usage(img, hexfile):
    loader = shutil.which("teensy_loader_cli")
    if loader is None:
        message = "teensy_loader_cli not found: apt-get install teensy-loader-cli"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    # Without a board (and without -w) it reads the file, reports, and fails to open a device.
    res = subprocess.run([loader, "--mcu=TEENSY35", "-v", str(img.hex)], capture_output=True,
                         text=True, timeout=60, stdin=subprocess.DEVNULL)
    out = res.stdout + res.stderr
    m = re.search(r'Read "[^"]+": (\d+) bytes, ([\d.]+)% usage', out)
    assert m, out
    assert int(m.group(1)) == len(hexfile.addresses())
    assert float(m.group(2)) == pytest.approx(100 * len(hexfile.addresses()) / FLASH_SIZE, abs=0.06)


def test_no_peripheral_address_is_typed_by_hand():
    """Peripheral addresses come from the generated mk64f12.hpp only."""
    folder = ROOT / "firmware" / "targets" / "teensy35"
    pattern = re.compile(r"0x(4[0-9A-Fa-f]{3}_?[0-9A-Fa-f]{4}|E000_?[0-9A-Fa-f]{4})\b")
    offenders = []
    for path in sorted(folder.glob("*.[ch]pp")):
        if path.name == "mk64f12.hpp":
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line.split("//")[0]):
                offenders.append(f"{path.name}:{n}: {line.strip()}")
    assert not offenders, offenders


def test_register_header_is_what_the_svd_generates():
    try:
        svd.find_svd()              # where the generator looks: $HQ_MK64_SVD, then pyocd
    except svd.SvdNotFound as exc:
        if os.environ.get("CI"):
            pytest.fail(str(exc))
        pytest.skip(str(exc))
    gen = ROOT / "firmware" / "targets" / "teensy35" / "gen_registers.py"
    res = subprocess.run([sys.executable, str(gen), "--check"], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr


def test_register_header_carries_the_svd_licence():
    text = (ROOT / "firmware" / "targets" / "teensy35" / "mk64f12.hpp").read_text()
    assert "GENERATED by firmware/targets/teensy35/gen_registers.py" in text
    assert "Redistribution and use in source and binary forms" in text
