"""What the emulated chip's native core does at the pins without calling into Python: the RC
receiver's pulses on FTM3's capture pins (Teensy35.rc_capture_pulses through
Mk64Core.pin_edge) and GPIO writes that leave the outputs as they are (the image sets its LED
again every loop). Each must be what the Python pin model would have done."""

from __future__ import annotations

import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import teensy35_boot_test as boot  # noqa: E402

from heliquad.sim.chip import Teensy35  # noqa: E402
from heliquad.sim.chip.teensy35 import PINS, RC_PINS  # noqa: E402

#: The MK64FX512's SRAM: SRAM_L and SRAM_U, 192 KiB.
SRAM = (0x1FFF0000, 0x30000)
#: Receiver frames: every channel, widths from one end of the range to the other, some
#: ending on the same FTM3 count (the same fall).
FRAMES = [{0: 1500, 1: 1000, 2: 2000, 3: 1234, 4: 1999, 5: 1001, 6: 1500},
          {0: 1100, 1: 1900, 2: 1500, 3: 1500, 4: 1000, 5: 2000, 6: 1750},
          {0: 1501, 2: 1502, 4: 1503, 6: 1504}]


def booted() -> Teensy35:
    boot.require_image()
    pytest.importorskip("heliquad._firmware")
    board = Teensy35(boot.IMAGE)
    assert board.run_to_loop(1, instructions=boot.BOOT_BUDGET).reason == "loop"
    return board


def fly_frames(board: Teensy35, frames) -> None:
    for widths in frames:
        board.rc_capture_pulses(widths)
        board.run(seconds=20e-3)                  # a 50 Hz receiver's frame


def test_rc_pulses_the_core_drives_are_the_pin_models_to_the_last_byte_of_ram():
    # The same receiver frames twice: through the pin model (which a second listener to the
    # pins' edges forces: the core must not bypass a listener) and through the core. The
    # capture interrupt reads each pin's level in PDIR to tell a rise from a fall, so a
    # level the core got wrong would show in what the image keeps in RAM.
    runs = {}
    for native in (False, True):
        board = booted()
        heard = []
        if not native:
            board.chip.ports.edge_listeners.append(lambda *edge: heard.append(edge))
        before = board.machine.counts()["python_events"]
        fly_frames(board, FRAMES * 2)
        events = board.machine.counts()["python_events"] - before
        captures = list(board.chip.ftm3.captures)
        runs[native] = (captures, board.machine.now(), board.machine.read(*SRAM))
        assert board.machine.core.pin_edges_pending == 0
        pulses = 2 * sum(len(w) for w in FRAMES)
        assert len(captures) == 2 * pulses          # a rise and a fall captured per pulse
        if native:
            assert events == 0                      # no edge called into Python
        else:
            assert len(heard) == 2 * pulses and events >= 2 * len(FRAMES)
    assert runs[True][0] == runs[False][0]
    assert runs[True][1] == runs[False][1]
    assert runs[True][2] == runs[False][2]


def test_a_pin_already_driven_high_keeps_its_pulses_in_the_pin_model():
    # The core drives a pulse only from a low pin: one held high from outside goes the pin
    # model's way (its rise is no edge), and its level there stays what was driven.
    board = booted()
    letter, bit = PINS[RC_PINS[0]]
    board.chip.ports.drive(letter, bit, 1)
    before = board.machine.counts()["python_events"]
    fly_frames(board, FRAMES[:1])
    assert board.machine.counts()["python_events"] > before
    assert board.chip.ports.level(letter, bit) == 0         # the pulse's fall released it


def test_gpio_writes_that_change_nothing_stay_native_and_the_led_still_blinks():
    # Disarmed, the image blinks its LED (500 ms on, 500 ms off) and sets it again every
    # loop. Only the writes that change it may reach the pin model, and every change must.
    from heliquad.sim.sensor.mpu6050_packets import raw_packet

    board = booted()
    m = board.machine
    sample = raw_packet([0.01, -0.02, 0.005], [0.0, 0.0, -9.80665])
    start = m.counts()["python_accesses"]
    for _ in range(440):                                    # 2.2 s of loops
        board.mpu.emu.push_fifo(sample, False)
        assert board.run_to_loop(board.loops + 1, instructions=1_000_000).reason == "loop"
    changes = board.led_changes()
    late = [(t, level) for t, level in changes if t > changes[0][0] + 0.01]
    assert len(late) >= 4
    gaps = [b[0] - a[0] for a, b in zip(late, late[1:])]
    assert all(abs(g - 0.5) < 0.006 for g in gaps), gaps     # a loop's 5 ms, and a little
    assert [level for _, level in late] == [late[0][1] ^ (i & 1) for i in range(len(late))]
    assert m.counts()["python_accesses"] - start <= len(changes)
