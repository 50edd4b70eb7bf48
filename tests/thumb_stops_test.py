"""The engine's run() (sim/chip/thumb.hpp): each stop reason, where the PC is left, what a
bus call sees (the accessing instruction's PC and the cycles before it), the decoded-code
cache dropped by stores into SRAM code and by the owner's writes, an encoding the engine
does not know. Hand-assembled code in SRAM."""

import struct

import pytest

from heliquad._simcore import ThumbEngine

CODE = 0x2000_0000
PERIPHERAL = 0x4000_0000


def _engine(*halfwords, regs=None):
    e = ThumbEngine()
    e.write(CODE, b"".join(struct.pack("<H", h) for h in halfwords))
    e.set_reg(13, 0x2001_0000)
    for n, v in (regs or {}).items():
        e.set_reg(n, v)
    e.set_reg(15, CODE)
    return e


@pytest.mark.parametrize("code, stop, pc_after", [
    ((0xBF30,), "wfi", CODE + 2),                   # WFI: after it
    ((0xBE00,), "bkpt", CODE),                      # BKPT: before it
    ((0xDF05,), "svc", CODE + 2),                   # SVC #5: after it
    ((0xDE00,), "undefined", CODE),                 # UDF
    ((0xE851, 0x0F00), "undefined", CODE),          # LDREX: not known to the engine
    ((0xB672,), "mask_changed", CODE + 2),          # CPSID i
])
def test_stop_reasons_of_single_instructions(code, stop, pc_after):
    e = _engine(*code)
    assert e.run(1000, 10) == stop
    assert e.pc == pc_after
    if stop == "svc":
        assert e.svc_number == 5
    if stop == "mask_changed":
        assert e.primask == 1
    if stop == "undefined":
        assert e.stop_detail and e.instructions == 0


def test_a_bus_call_sees_the_accessing_instruction_and_the_cycles_before_it():
    e = _engine(0x2101, 0x6810, 0x6810, regs={2: PERIPHERAL})   # movs r1,#1; ldr r0,[r2] x2
    e.cycles = 100
    seen = []

    def read(address, size):
        seen.append((address, size, e.pc, e.cycles))
        if len(seen) == 2:
            e.request_stop()
        return 0x1234

    e.set_bus(read, lambda a, s, v: True)
    assert e.run(10_000, 100) == "requested"
    assert seen == [(PERIPHERAL, 4, CODE + 2, 101), (PERIPHERAL, 4, CODE + 4, 103)]
    assert e.pc == CODE + 6 and e.reg(0) == 0x1234 and e.cycles == 105


def test_nothing_at_an_address_is_a_bus_fault_before_the_instruction():
    e = _engine(0x6810, regs={2: PERIPHERAL + 8})
    e.set_bus(lambda a, s: None, lambda a, s, v: False)
    assert e.run(1000, 10) == "bus_fault"
    assert e.fault_address == PERIPHERAL + 8 and e.pc == CODE and e.instructions == 0


def test_unaligned_accesses_the_m4_refuses_and_ccr_unalign_trp():
    e = _engine(0xE9D2, 0x0100, regs={2: CODE + 0x102})          # ldrd r0, r1, [r2]
    assert e.run(1000, 10) == "unaligned" and e.fault_address == CODE + 0x102
    e = _engine(0x6810, 0xBE00, regs={2: CODE + 0x101})          # ldr r0, [r2]
    assert e.run(1000, 10) == "bkpt"
    e = _engine(0x6810, 0xBE00, regs={2: CODE + 0x101})
    e.unalign_trap = True
    assert e.run(1000, 10) == "unaligned" and e.pc == CODE


def test_division_by_zero_gives_zero_or_stops_with_ccr_div_0_trp():
    e = _engine(0xFBB1, 0xF0F2, 0xBE00, regs={0: 7, 1: 5, 2: 0})  # udiv r0, r1, r2
    assert e.run(1000, 10) == "bkpt" and e.reg(0) == 0
    e = _engine(0xFBB1, 0xF0F2, 0xBE00, regs={0: 7, 1: 5, 2: 0})
    e.div0_trap = True
    assert e.run(1000, 10) == "div_by_zero" and e.pc == CODE and e.reg(0) == 7


def test_exc_return_to_the_pc_stops_with_its_value_the_pc_not_taken():
    e = _engine(0x4770, regs={14: 0xFFFF_FFF9})                  # bx lr
    e.ipsr = 15
    assert e.run(1000, 10) == "exc_return"
    assert e.exc_return == 0xFFFF_FFF9 and e.pc == CODE and e.instructions == 1
    e = _engine(0xBD01, regs={13: 0x2001_0000})                   # pop {r0, pc}
    e.write(0x2001_0000, struct.pack("<II", 42, 0xFFFF_FFE9))
    assert e.run(1000, 10) == "exc_return" and e.exc_return == 0xFFFF_FFE9
    assert e.reg(0) == 42 and e.reg(13) == 0x2001_0008


def test_an_interworking_branch_to_an_even_address_stops():
    e = _engine(0x4700, regs={0: 0x1000})                         # bx r0
    assert e.run(1000, 10) == "inv_state" and e.pc == 0x1000


def test_an_fp_instruction_without_the_fpu_stops_before_it():
    e = _engine(0xEE30, 0x0A81)                                   # vadd.f32 s0, s1, s2
    e.fpu_enabled = False
    assert e.run(1000, 10) == "no_fpu" and e.pc == CODE and e.control & 4 == 0
    e.fpu_enabled = True
    e.fpdscr = 0x0300_0000                                        # DN, FZ for new contexts
    assert e.run(1000, 1) == "limit" and e.control & 4 and e.fpscr == 0x0300_0000


def test_a_stop_address_stops_before_it_and_the_next_run_goes_through():
    e = _engine(0xBF00, 0xBF00, 0xBF00, 0xBE00)
    e.add_stop_address(CODE + 4)
    assert e.run(1000, 10) == "stop_address" and e.pc == CODE + 4
    assert e.run(1000, 10) == "bkpt" and e.pc == CODE + 6


def test_deadline_and_limit_stop_at_instruction_boundaries():
    e = _engine(*([0xBF00] * 8 + [0xE7F7]))                       # nops; b back
    assert e.run(5, 100) == "deadline" and e.cycles == 5 and e.pc == CODE + 10
    e.cycles = 0
    assert e.run(1 << 40, 3) == "limit" and e.instructions == 8


def test_a_store_into_decoded_sram_code_and_an_owner_write_drop_the_decoded_code():
    # str r1, [r2]; movs r0, #1; bkpt  -- then the store rewrites "movs r0, #1; bkpt"
    e = _engine(0x6011, 0x2001, 0xBE00, regs={1: 0xBE00_2001, 2: CODE + 2})
    assert e.run(1000, 10) == "bkpt" and e.reg(0) == 1
    e.set_reg(1, 0xBE00_2007)                                     # movs r0, #7; bkpt
    e.set_reg(15, CODE)
    assert e.run(1000, 10) == "bkpt" and e.reg(0) == 7
    e.write(CODE + 2, struct.pack("<H", 0x2009))                  # the owner: movs r0, #9
    e.set_reg(1, 0xBE00_2009)
    e.set_reg(15, CODE)
    assert e.run(1000, 10) == "bkpt" and e.reg(0) == 9
    e.write(0x1000, struct.pack("<HH", 0x2003, 0xBE00))           # flash programmed
    e.set_reg(15, 0x1000)
    assert e.run(1000, 10) == "bkpt" and e.reg(0) == 3
    e.write(0x1000, struct.pack("<H", 0x2004))
    e.set_reg(15, 0x1000)
    assert e.run(1000, 10) == "bkpt" and e.reg(0) == 4


def test_an_isb_stops_after_it_only_while_the_owner_watches_for_one():
    e = _engine(0xF3BF, 0x8F6F, 0xF3BF, 0x8F6F, 0xBE00)           # isb; isb; bkpt
    e.stop_on_isb = True
    assert e.run(1000, 10) == "isb" and e.pc == CODE + 4 and e.instructions == 1
    e.stop_on_isb = False
    assert e.run(1000, 10) == "bkpt" and e.instructions == 2


def test_a_deadline_brought_forward_by_a_bus_call_stops_at_the_next_boundary():
    # ldr r0,[r2]; nop x6 -- the read brings the deadline forward to "now"
    e = _engine(0x6810, *([0xBF00] * 6), regs={2: PERIPHERAL})
    e.set_bus(lambda a, s: e.lower_deadline(e.cycles) or 7, lambda a, s, v: True)
    assert e.run(1000, 100) == "deadline"
    assert e.pc == CODE + 2 and e.reg(0) == 7 and e.instructions == 1


def test_fetching_from_flash_past_its_fetch_limit_is_a_fetch_from_nothing():
    e = ThumbEngine()
    e.write(0x1000, struct.pack("<HH", 0xBF00, 0xBE00))           # nop; bkpt in flash
    e.set_reg(15, 0x1000)
    e.flash_fetch_limit = 0                                       # being programmed
    assert e.run(1000, 10) == "bus_fault" and e.fault_address == 0x1000
    e.flash_fetch_limit = 512 * 1024
    assert e.run(1000, 10) == "bkpt" and e.pc == 0x1002


def test_a_run_stopped_just_before_a_stop_address_for_another_reason_stops_there_next():
    e = _engine(0xBF00, 0xBF00, 0xBE00)                           # nop; nop; bkpt
    e.add_stop_address(CODE + 2)
    assert e.run(1, 10) == "deadline" and e.pc == CODE + 2        # at it, not yet reported
    assert e.run(1000, 10) == "stop_address" and e.pc == CODE + 2
    assert e.run(1000, 10) == "bkpt"


def test_an_owners_pc_write_makes_a_stop_address_stop_again_but_a_handler_does_not():
    e = _engine(0xBF00, 0xBF00, 0xBE00)                           # nop; nop; bkpt
    e.add_stop_address(CODE + 2)
    assert e.run(1000, 10) == "stop_address" and e.pc == CODE + 2
    e.set_reg(15, CODE)                                           # the owner starts again
    assert e.run(1000, 10) == "stop_address" and e.pc == CODE + 2
    e.jump(CODE + 0x10)                                           # a handler runs elsewhere
    e.jump(CODE + 2)                                              # and returns to it
    assert e.run(1000, 10) == "bkpt"


def test_a_request_from_a_bus_call_inside_an_it_block_stops_after_it_the_block_going_on():
    # cmp r0,r0; itt eq; ldreq r1,[r2]; moveq r3,#1; bkpt -- once decoded, then again
    e = _engine(0x4280, 0xBF04, 0x6811, 0x2301, 0xBE00, regs={2: PERIPHERAL})
    e.set_bus(lambda a, s: 0, lambda a, s, v: True)
    assert e.run(1000, 100) == "bkpt"
    seen = []

    def read(address, size):
        seen.append((e.pc, e.cycles))
        e.request_stop()
        return 0x55

    e.set_bus(read, lambda a, s, v: True)
    e.set_reg(15, CODE)
    e.set_reg(3, 0)
    e.cycles = 0
    assert e.run(1000, 100) == "requested"
    assert seen == [(CODE + 4, 2)]
    assert e.pc == CODE + 6 and e.reg(1) == 0x55 and e.cycles == 4 and e.itstate != 0
    assert e.run(1000, 100) == "bkpt" and e.reg(3) == 1 and e.itstate == 0


def test_what_a_bus_call_changes_holds_from_the_next_instruction():
    # in flash: ldr r0,[r2]; nop; bkpt -- run once (decoded), then again with a read that
    # starts programming the flash (fetch limit 0)
    e = ThumbEngine()
    e.write(0x1000, struct.pack("<HHH", 0x6810, 0xBF00, 0xBE00))
    e.set_reg(2, PERIPHERAL)
    e.set_bus(lambda a, s: 1, lambda a, s, v: True)
    e.set_reg(15, 0x1000)
    assert e.run(1000, 10) == "bkpt"
    e.set_bus(lambda a, s: setattr(e, "flash_fetch_limit", 0) or 1, lambda a, s, v: True)
    e.set_reg(15, 0x1000)
    assert e.run(1000, 10) == "bus_fault" and e.fault_address == 0x1002 and e.reg(0) == 1
    # ldr r0,[r2]; vmov.f32 s0,s1; bkpt -- then with a read that takes the FPU away (CPACR)
    e = _engine(0x6810, 0xEEB0, 0x0A60, 0xBE00, regs={2: PERIPHERAL})
    e.control = 4
    e.set_bus(lambda a, s: 1, lambda a, s, v: True)
    assert e.run(1000, 10) == "bkpt"
    e.set_bus(lambda a, s: setattr(e, "fpu_enabled", False) or 1, lambda a, s, v: True)
    e.set_reg(15, CODE)
    assert e.run(1000, 10) == "no_fpu" and e.pc == CODE + 2
