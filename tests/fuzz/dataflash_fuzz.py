"""Fuzz target: identify's reading of a .BIN, heliquad's own or an ArduPilot SystemID log
(host/records/bin_log.py, host/records/ardupilot_log.py, host/campaign/bin_sweep.py,
host/campaign/ardupilot_sweep.py).

    python tests/fuzz/dataflash_fuzz.py CORPUS_DIR -max_total_time=60     (needs atheris)

Input layout: byte 0 chooses the mode (bit 0: 0 raw, 1 structured); the rest is the file as
it is (raw) or a recipe (structured): an ArduPilot SystemID log written by
tests/ardupilot_dataflash.py from the recipe's numbers (SID_AXIS, band, loops, the rate
controller's values, a time step that may go back), then, if the recipe says so, bytes
from the recipe overwritten or inserted at a place it names.

Contract checked per input (the file is written to one temporary file per process):
- reading it as identify does (the log opened, then its SystemID segments as sweeps for an
  ArduPilot log, or heliquad's own log read up to its damage and taken as its sweep) returns
  or raises InputError, never anything else;
- a structured log left whole, of SID_AXIS 10 with a rising time and a chirp that sweeps
  (with an amplitude of at least MIN_WHOLE_AMP), gives one sweep of the roll axis at the mixer with every loop in it.
"""

from __future__ import annotations

import atexit
import math
import os
import struct
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))        # tests/: the log writer

from ardupilot_dataflash import DataFlashWriter  # noqa: E402

from heliquad.host.campaign import ardupilot_sweep, bin_sweep  # noqa: E402
from heliquad.host.records import ardupilot_log, bin_log  # noqa: E402
from heliquad.sim.base.errors import InputError  # noqa: E402

STRUCTURED = 0x01
SCRATCH_DIR = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None
_scratch = None
_RECIPE = struct.Struct("<BBBHhfB")      # axis, f_start*10, f_stop, loops, step, amp, damage
#: The least amplitude a whole log's chirp has. Below it the logged excitation (float32) is
#: subnormal or zero at many loops, so its non-zero part may not span the band: identify's
#: refusal ("zero throughout", "not a sweep") is then right, not a defect.
MIN_WHOLE_AMP = 1e-6


def _scratch_file() -> str:
    """The process's temporary .BIN (a name ending so), removed at exit."""
    global _scratch
    if _scratch is None:
        fd, _scratch = tempfile.mkstemp(prefix="dataflash_fuzz-", suffix=".BIN", dir=SCRATCH_DIR)
        os.close(fd)
        atexit.register(os.remove, _scratch)
    return _scratch


def read(content: bytes):
    """identify's reading of a .BIN holding ``content``: the sweeps of an ArduPilot log, or
    heliquad's log's sweep; InputError as identify would say it."""
    path = _scratch_file()
    with open(path, "wb") as fh:
        fh.write(content)
    opened = bin_log.open_log(path)
    if bin_log.is_ardupilot_log(opened[0]):
        sweeps, _, _ = ardupilot_sweep.ardupilot_sweeps(path, opened)
        return sweeps
    return [bin_sweep.log_sweep(bin_log.read_bin(path, opened), path)]


def structured_log(recipe: bytes) -> tuple:
    """``(the log's bytes, whether it is whole and should read as one roll sweep, loops)``
    from a recipe (module docstring)."""
    head = recipe[:_RECIPE.size].ljust(_RECIPE.size, b"\0")
    axis, start10, stop, loops, step, amp, damage = _RECIPE.unpack(head)
    rest = recipe[_RECIPE.size:]
    start = max(start10, 1) / 10.0
    loops = 20 + loops % 600
    amp = amp if math.isfinite(amp) else 0.0
    w = DataFlashWriter()
    w.write("MSG", TimeUS=1, Message="ArduCopter V4.5.7")
    w.write("SIDS", TimeUS=10, Ax=axis % 16, Mag=amp, FSt=start, FSp=float(stop), TFin=0.5,
            TC=0.0, TR=loops * 0.0025, TFout=0.5)
    t = 100_000_000
    for k in range(loops):
        f = start * (max(stop, 1) / start) ** (k / loops)
        t += 2500 if step >= 0 or k % 50 else step
        w.write("SIDD", TimeUS=t, Time=k * 0.0025, Targ=amp * math.sin(2 * math.pi * f * k
                                                                         * 0.0025), F=f)
        w.write("RATE", TimeUS=t + 40, R=float(rest[k % len(rest)]) if rest else 1.0,
                ROut=amp * math.sin(k / 3.0), P=0.1, POut=0.01)
        w.write("ATT", TimeUS=t + 70, Roll=1.0, Yaw=180.0)
    data = bytearray(w.data)
    if damage & 1 and rest:
        at = (damage * 7919) % len(data)
        if damage & 2:
            data[at:at] = rest
        else:
            data[at:at + len(rest)] = rest
    whole = not (damage & 1 and rest) and step >= 0 and axis % 16 == 10 and \
        stop >= 2 * start and abs(amp) >= MIN_WHOLE_AMP
    return bytes(data), whole, loops


def check(data: bytes) -> int:
    """Run the contract on one input; the sweeps read (0 when refused)."""
    if data[:1] and data[0] & STRUCTURED:
        content, whole, loops = structured_log(data[1:])
    else:
        content, whole, loops = data[1:], False, 0
    try:
        sweeps = read(content)
    except InputError:
        assert not whole, "a whole structured log was refused"
        return 0
    if whole:
        (_, manifest, samples), = sweeps
        assert (manifest["axis"], manifest["inject"]) == ("roll", "mixer")
        assert samples.size + manifest["frequencies"][0]["lost"] <= loops
    return len(sweeps)


def test_one_input(data: bytes) -> None:
    check(data)


def seed_inputs() -> dict:
    """A whole roll chirp, one with its time stepping back, one with a damaged record."""
    good = _RECIPE.pack(10, 5, 4, 400, 0, 0.2, 0)
    return {"structured-roll": bytes((STRUCTURED,)) + good,
            "structured-back": bytes((STRUCTURED,)) + _RECIPE.pack(10, 5, 4, 400, -3000, 0.2, 0),
            "structured-damaged": bytes((STRUCTURED,)) + _RECIPE.pack(10, 5, 4, 300, 0, 0.2, 1)
            + b"\xa3\x95\x80garbage",
            "raw-roll": b"\0" + structured_log(good)[0]}


def main(argv: list) -> None:
    import atheris
    from fuzz_input import instrument
    instrument(atheris, (ardupilot_log, bin_log, ardupilot_sweep, bin_sweep))
    atheris.Setup(argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
