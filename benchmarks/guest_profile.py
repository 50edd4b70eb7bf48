"""Profile: where the Teensy image's own instructions go in a PIL loop, by function, over each
link: what the board's firmware asks of the emulator, before the emulator's cost per
instruction.

Flies benchmarks/pil_speed.py's experiment (``heliquad sil``: roll, mixer injection, a 1 Hz
sine of 0.05) with the drop-in's chip on the unicorn CPU, which can report every block it
runs: a ``sitecustomize`` this tool writes into a temporary folder on the drop-in's
PYTHONPATH counts the blocks from the board's boot to its exit (every frame in the drop-in's
Python path, HQ_PIL_FRAMES=python, so the hook sees them all) and writes them to a file. Each
block's instructions are decoded once (capstone, Thumb-2) and charged to the function of the
image's symbol table that holds it; loops are counted by the entries of the flight
controller's step. The engine runs the same instruction stream (tests/chip_cpus_test.py
compares the two); a block cut short by an interrupt is charged whole, so the figures are a
little high, by at most a block per exception.

    python benchmarks/guest_profile.py [--cycles 10] [--link usb] [--top 30] [--elf PATH]

Prints, per link: guest instructions a loop, exceptions taken a loop (by exception number),
and the functions that take the most, with their share. Needs unicorn, capstone (unicorn's
own dependency) and pyelftools. Never a test; the figures do not depend on the machine's
speed.
"""

from __future__ import annotations

import argparse
import bisect
import collections
import json
import os
import pathlib
import sys
import tempfile

import pil_speed           # this script's folder: the experiment profiled, its CPU and links
from pil_speed import CPU_VARIABLE, FRAMES_VARIABLE, LINKS

OUT_VARIABLE = "HQ_GUEST_PROFILE_OUT"   # where the drop-in writes its counts
#: The flight controller's step, entered once a loop (hq_step_outputs, where the drop-in
#: stops, is entered twice: the stop ends unicorn's block).
LOOP_SYMBOL = "_ZN2hq16FlightController4stepERKNS_7RcInputERNS_9LoopInboxE"


def image(elf: str) -> tuple:
    """``(starts, functions, sections)``: the image's function symbols sorted by address (the
    Thumb bit off) as ``(name, size)``, and its loaded sections as ``(address, bytes)``."""
    from elftools.elf.elffile import ELFFile        # only this tool reads the symbol table
    with open(elf, "rb") as fh:
        f = ELFFile(fh)
        found = {}
        for sym in f.get_section_by_name(".symtab").iter_symbols():
            if sym["st_info"]["type"] == "STT_FUNC" and sym["st_size"]:
                found[sym["st_value"] & ~1] = (sym.name, sym["st_size"])
        sections = [(sec["sh_addr"], sec.data()) for sec in f.iter_sections()
                    if sec["sh_flags"] & 2 and sec["sh_type"] == "SHT_PROGBITS"]  # SHF_ALLOC
    starts = sorted(found)
    return starts, [found[a] for a in starts], sections


def code_at(sections, address: int, size: int) -> bytes:
    for base, data in sections:
        if base <= address and address + size <= base + len(data):
            return data[address - base:address - base + size]
    raise SystemExit(f"a block at 0x{address:08x} is in no section of the image")


#: Run in the drop-in (written as its sitecustomize, which Python imports at start-up): once
#: its board has booted, count the blocks its CPU enters; at exit, write them to the file
#: the variable names.
DROP_IN_HOOK = """
import atexit, collections, json, os
from heliquad.sim.chip.pil import board as _board

_boot = _board.PilBoard.boot


def _counted_boot(self, *args, **kwargs):
    result = _boot(self, *args, **kwargs)
    from unicorn import UC_HOOK_BLOCK
    blocks = collections.Counter()
    machine = self.machine
    before = collections.Counter(machine.exception_counts)
    machine.uc.hook_add(UC_HOOK_BLOCK, lambda uc, a, n, _: blocks.update(((a, n),)))
    machine.uc.ctl_flush_tb()       # blocks translated before the hook would not report

    def dump():
        taken = collections.Counter(machine.exception_counts)
        taken.subtract(before)
        with open(os.environ[%r], "w") as fh:
            json.dump({"blocks": [[a, n, c] for (a, n), c in blocks.items()],
                       "exceptions": dict(+taken)}, fh)
    atexit.register(dump)
    return result


_board.PilBoard.boot = _counted_boot
"""


def experiment_blocks(elf: str, link: str, cycles: int) -> tuple:
    """``(blocks, exceptions)``: how often each ``(address, size)`` block ran in the drop-in
    through benchmarks/pil_speed.py's experiment over ``link``, and the exceptions taken, by
    name, from the board's boot to its exit."""
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "blocks.json"
        (pathlib.Path(tmp) / "sitecustomize.py").write_text(DROP_IN_HOOK % OUT_VARIABLE)
        env = {CPU_VARIABLE: "unicorn", FRAMES_VARIABLE: "python", OUT_VARIABLE: str(out),
               "PYTHONPATH": os.pathsep.join(filter(None, (tmp, os.environ.get("PYTHONPATH"))))}
        saved = {k: os.environ.get(k) for k in env}
        os.environ.update(env)
        try:
            pil_speed.run("teensy35", link, cycles, elf, str(pathlib.Path(tmp) / "run"))
        finally:
            for k, v in saved.items():
                os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)
        found = json.loads(out.read_text())
    return {(a, n): c for a, n, c in found["blocks"]}, found["exceptions"]


def profile(elf: str, link: str, cycles: int, top: int) -> None:
    from capstone import CS_ARCH_ARM, CS_MODE_MCLASS, CS_MODE_THUMB, Cs   # unicorn's own

    blocks, taken = experiment_blocks(elf, link, cycles)
    starts, names, sections = image(elf)
    loop_mark = starts[[n for n, _ in names].index(LOOP_SYMBOL)]
    loops = sum(c for (a, _), c in blocks.items() if a == loop_mark)
    if not loops:
        raise SystemExit(f"the image never reached {LOOP_SYMBOL}: no loop to profile")
    cs = Cs(CS_ARCH_ARM, CS_MODE_THUMB | CS_MODE_MCLASS)
    per_function = collections.Counter()
    total = 0
    for (address, size), runs in blocks.items():
        n = sum(1 for _ in cs.disasm_lite(code_at(sections, address, size), address))
        i = bisect.bisect_right(starts, address) - 1
        inside = i >= 0 and address < starts[i] + names[i][1]
        per_function[names[i][0] if inside else f"0x{address:08x}"] += n * runs
        total += n * runs
    print(f"\n{link}: {loops} loops from the boot on; {total / loops:,.0f} guest instructions "
          "a loop; exceptions a loop (by number): "
          + ", ".join(f"{name} {count / loops:.1f}" for name, count in
                      sorted(taken.items(), key=lambda kv: -kv[1])))
    for name, n in per_function.most_common(top):
        print(f"  {n / loops:9,.0f}  {100 * n / total:5.1f} %  {name}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cycles", type=int, default=10,
                   help="the experiment's sine cycles at 1 Hz (default 10)")
    p.add_argument("--top", type=int, default=30, help="functions listed (default 30)")
    p.add_argument("--link", choices=LINKS, action="append",
                   help="a link to profile; repeat for both (default both)")
    p.add_argument("--elf", help="the Teensy image (default: the installed or in-tree one)")
    args = p.parse_args()
    if args.cycles < 1 or args.top < 1:
        p.error("--cycles and --top must be at least 1")
    from heliquad.sim.base.firmware_image import teensy35_image  # the installed image's path

    elf = args.elf or str(teensy35_image("elf"))
    print(f"image: {elf}; the experiment: {args.cycles} cycles of a 1 Hz sine")
    for link in args.link or LINKS:
        profile(elf, link, args.cycles, args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
