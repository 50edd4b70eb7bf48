"""How fast the engine's CPU (heliquad._simcore.ThumbEngine, sim/chip/thumb.hpp) runs the
image's code, against unicorn without hooks and unicorn with a native block hook counting
blocks (the least heliquad's time keeping needs of unicorn), measured in the same run.

A driver in SRAM calls one of the image's functions once per input (inputs from an array;
pointer arguments at a fixed block of random floats), CALLS times, then stops at a BKPT;
each of the three runs it from the same state. Prints ns per guest instruction (the
engine's count, which the tests prove equal to unicorn's) for each and the ratios, the
median of REPEATS runs (the machine is shared and noisy). No pass/fail.

    python benchmarks/thumb_speed.py [--calls N] [--repeats N]
"""

from __future__ import annotations

import argparse
import ctypes
import random
import statistics
import struct
import time

from unicorn.unicorn_py3 import unicorn as binding

from heliquad._simcore import UnicornBlockCounter
from heliquad.sim.base.firmware_image import teensy35_image
from heliquad.sim.chip.image import Image
from heliquad.sim.chip.thumb_twin import SRAM_SIZE, Twin

DRIVER = 0x2000_0000
INPUTS = 0x2000_1000
DATA = 0x1FFF_8000
STACK = 0x2001_F000
#: name -> (short name, float arguments, pointer arguments, an integer argument)
FUNCTIONS = {
    "sinf": ("sinf", 1, 0, False),
    "cosf": ("cosf", 1, 0, False),
    "atan2f": ("atan2f", 2, 0, False),
    "expf": ("expf", 1, 0, False),
    "logf": ("logf", 1, 0, False),
    "_ZN2hq3Pid6updateEfff": ("Pid::update", 3, 1, False),
    "_ZN2hq19ComplementaryFilter6updateERKNS_4Vec3ES3_fb": ("ComplementaryFilter::update", 1,
                                                            3, True),
    "_ZN2hq8to_eulerERKNS_4QuatE": ("to_euler", 0, 1, False),
}
# The driver: r0-r2 = r6, r9, r10 (pointers), r3 = 1; s0-s2 from [r4]; blx r7; r4 += 12;
# r5 -= 1; loop; bkpt.
_DRIVER = (0x4630, 0x4649, 0x4652, 0x2301, 0xED94, 0x0A00, 0xEDD4, 0x0A01, 0xED94, 0x1A02,
           0x47B8, 0x340C, 0x3D01, 0xD1F1, 0xBE00)
BKPT = DRIVER + 2 * (len(_DRIVER) - 1)


def _floats(rng, n, lo=-3.0, hi=3.0) -> bytes:
    return b"".join(struct.pack("<f", rng.uniform(lo, hi)) for _ in range(n))


def _twin(segments, calls, rng, hooked=False):
    twin = Twin(segments, bytes(SRAM_SIZE), step_hook=False)
    twin.write(DRIVER, b"".join(struct.pack("<H", h) for h in _DRIVER))
    twin.write(INPUTS, _floats(rng, 3 * calls))
    twin.write(DATA, _floats(rng, 64, 0.01, 2.0))
    counter = None
    if hooked:
        # the unicorn binding's library and engine handle, as sim/chip/machine.py takes them
        counter = UnicornBlockCounter()
        counter.install(ctypes.cast(binding.uclib.uc_hook_add, ctypes.c_void_p).value,
                        twin.uc._uch.value)
    return twin, counter


def _start(twin, function, calls):
    r = [0] * 16
    r[4], r[5], r[6], r[7] = INPUTS, calls, DATA, function | 1
    r[9], r[10], r[13], r[15] = DATA + 64, DATA + 128, STACK, DRIVER
    twin.set_state({"r": r, "apsr": 0, "it": 0, "s": [0] * 32, "fpscr": 0, "control": 4,
                    "primask": 0, "basepri": 0, "faultmask": 0})


def _time_engine(twin, function, calls):
    _start(twin, function, calls)
    e = twin.engine
    e.instructions = 0
    t0 = time.perf_counter()
    stop = e.run(1 << 62, 1 << 40)
    elapsed = time.perf_counter() - t0
    assert stop == "bkpt" and e.pc == BKPT, (stop, hex(e.pc))
    return elapsed, e.instructions


def _time_unicorn(twin, function, calls):
    _start(twin, function, calls)
    t0 = time.perf_counter()
    twin.uc.emu_start(DRIVER | 1, BKPT)
    return time.perf_counter() - t0


def measure(segments, function, calls, repeats, seed=1):
    """{kind: median ns per instruction}, instructions per run, blocks per run."""
    plain, _ = _twin(segments, calls, random.Random(seed))
    hooked, counter = _twin(segments, calls, random.Random(seed), hooked=True)
    _time_engine(plain, function, calls)                     # warm: decode, translate
    _time_unicorn(plain, function, calls)
    _time_unicorn(hooked, function, calls)
    times = {"engine": [], "unicorn": [], "unicorn+block hook": []}
    instructions = 0
    counter.blocks = 0
    for _ in range(repeats):
        elapsed, instructions = _time_engine(plain, function, calls)
        times["engine"].append(elapsed)
        times["unicorn"].append(_time_unicorn(plain, function, calls))
        times["unicorn+block hook"].append(_time_unicorn(hooked, function, calls))
    blocks = counter.blocks // repeats
    return ({k: statistics.median(v) * 1e9 / instructions for k, v in times.items()},
            instructions, blocks)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=2000, help="calls per run (default 2000)")
    ap.add_argument("--repeats", type=int, default=7, help="runs per figure (median; 7)")
    args = ap.parse_args()
    image = Image(teensy35_image("elf"))
    print(f"{'function':30s} {'insn/call':>9s} {'insn/blk':>8s} {'engine':>8s} {'unicorn':>8s}"
          f" {'uc+hook':>8s}  ns/instruction; unicorn/engine, uc+hook/engine")
    total = {"engine": 0.0, "unicorn": 0.0, "unicorn+block hook": 0.0}
    total_n = 0
    for name, (short, *_) in FUNCTIONS.items():
        ns, n, blocks = measure(image.segments, image.symbol(name).address, args.calls,
                                args.repeats)
        for k in total:
            total[k] += ns[k] * n
        total_n += n
        print(f"{short:30s} {n / args.calls:9.1f} {n / max(blocks, 1):8.2f} {ns['engine']:8.2f} "
              f"{ns['unicorn']:8.2f} {ns['unicorn+block hook']:8.2f}  "
              f"{ns['unicorn'] / ns['engine']:5.1f}x {ns['unicorn+block hook'] / ns['engine']:5.1f}x")
    avg = {k: v / total_n for k, v in total.items()}
    print(f"{'all (instruction-weighted)':30s} {'':9s} {'':8s} {avg['engine']:8.2f} "
          f"{avg['unicorn']:8.2f} {avg['unicorn+block hook']:8.2f}  "
          f"{avg['unicorn'] / avg['engine']:5.1f}x {avg['unicorn+block hook'] / avg['engine']:5.1f}x")


if __name__ == "__main__":
    main()
