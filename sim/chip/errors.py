"""The errors the emulated chip raises: something it cannot continue from
(:class:`EmulationError`), a fault the chip would take (:class:`Fault`), a reset it would
perform (:class:`ChipReset`). Shared by the machine and the CPUs under it (``cpu.py``)."""

from __future__ import annotations


class EmulationError(RuntimeError):
    """Something the emulated chip cannot continue from."""


class Fault(EmulationError):
    """A fault the chip would raise (BusFault, UsageFault, MemManage, ...). The harness stops
    instead of entering the fault handler, so a test sees the cause and the instruction."""

    def __init__(self, kind: str, message: str, pc: int | None = None, address: int | None = None):
        self.kind, self.pc, self.address = kind, pc, address
        super().__init__(f"{kind}: {message}")


class ChipReset(EmulationError):
    """A reset the chip would perform (watchdog, SYSRESETREQ)."""

    def __init__(self, source: str, message: str):
        self.source = source
        super().__init__(f"reset by {source}: {message}")
