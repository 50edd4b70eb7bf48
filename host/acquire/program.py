"""The board's on-board identification program from the host (``heliquad program``): a
sweep's plan as the board's program steps, and HQ_PROGRAM's set, show and clear over the
telemetry link (docs/link-contract.md).

The firmware keeps one program, run by the pilot's channel 7 with no host attached
(docs/safety.md). A set sends every step in order (HQ_PROGRAM STEP, index and count), each
answered by HQ_PROGRAM_STATUS: the board checks each step against the excitation's own
bounds as it comes and takes the program only once its last step is in and stored, so a
refused step leaves the old program in place. A show reads the steps back one by one; a
clear forgets the program. Set and clear are refused while the board is armed.
"""

from __future__ import annotations

import dataclasses

from ...sim.base import dialect as names
from ...sim.base.errors import BoardRefused, InputError
from ...sim.base.firmware_facts import MAX_PROGRAM_STEPS
from .excitation import UNITS, command_line_amplitude
from .link import reason_text
from .exchange import Exchange

__all__ = ["ProgramStep", "ProgramClient", "program_steps", "step_text"]


@dataclasses.dataclass(frozen=True)
class ProgramStep:
    """One excitation of a program, in the firmware's units (HQ_EXCITATION's layout);
    ``harmonics``: a multisine's ``((order, amplitude, phase_rad), ...)``, None for a sine."""
    axis: str
    inject: str
    freq_hz: float
    amplitude: float
    cycles: int
    fade_cycles: int
    harmonics: tuple | None = None


def program_steps(plan) -> list[ProgramStep]:
    """A sweep's plan (:class:`~heliquad.host.acquire.sweep.SweepPlan`, fixed amplitudes) as
    the board's steps: one per frequency, or the multisine's one (InputError for more than
    the board holds)."""
    if len(plan.freqs_hz) > MAX_PROGRAM_STEPS:
        raise InputError(f"--freqs-hz: {len(plan.freqs_hz)} frequencies; a program has at most "
                         f"{MAX_PROGRAM_STEPS} steps")
    ms = plan.multisine
    if ms is not None:
        return [ProgramStep(plan.axis, plan.inject, ms.base_hz, ms.peak, ms.periods,
                            ms.fade_cycles, tuple(tuple(h) for h in ms.harmonics()))]
    return [ProgramStep(plan.axis, plan.inject, f, a, plan.cycles, plan.fade_cycles)
            for f, a in zip(plan.freqs_hz, plan.amplitudes)]


def step_text(number: int, step: ProgramStep) -> str:
    """One step in a line, its amplitude in the command line's units: ``3  roll mixer  sine
    1.25 Hz  amplitude 0.25  8 cycles, fade 2`` (``amplitude 5 deg`` at the angle)."""
    if step.harmonics is None:
        what = f"sine {step.freq_hz:.4g} Hz"
    else:
        orders = [h[0] for h in step.harmonics]
        what = (f"multisine on {step.freq_hz:.4g} Hz, {len(orders)} harmonics "
                f"{orders[0]}-{orders[-1]}")
    amplitude = f"{command_line_amplitude(step.inject, step.amplitude):.4g}"
    if step.inject != "mixer":
        amplitude += f" {UNITS[step.inject]}"
    return (f"{number:>3}  {step.axis} {step.inject}  {what}  amplitude {amplitude}  "
            f"{step.cycles} cycles, fade {step.fade_cycles}")


class ProgramClient(Exchange):
    """HQ_PROGRAM's set, show and clear (:class:`~heliquad.host.acquire.exchange.Exchange`'s
    waits and retries); ``progress`` is told each step a set sends."""

    messages = ("HQ_PROGRAM", "HQ_PROGRAM_STATUS", "HEARTBEAT")
    silent_hint = ("is the board running, with a firmware that keeps on-board programs, on "
                   "this link?")

    def __init__(self, link, progress=None, **waits):
        super().__init__(link, progress, **waits)
        self.statuses: list = []                 # HQ_PROGRAM_STATUS since the last request
        self.steps: dict[int, ProgramStep] = {}  # the board's steps read back

    def _handle(self, m) -> None:
        if m.get_type() == "HQ_PROGRAM_STATUS":
            self.statuses.append(m)
            return
        mav = self.link.mav_module
        harmonics = None
        if m.signal == mav.HQ_SIGNAL_MULTISINE:
            harmonics = tuple((o, a, p) for o, a, p in zip(m.harmonic, m.harmonic_amp,
                                                          m.harmonic_phase) if o)
        self.steps[int(m.index)] = ProgramStep(
            _name(names.AXES, m.axis), _name(names.INJECTIONS, m.injection), float(m.freq_hz),
            float(m.amplitude), int(m.cycles), int(m.fade_cycles), harmonics)

    def _answer(self, action: int, index: int):
        """The HQ_PROGRAM_STATUS answering ``action`` (for ``index``), or None yet."""
        return next((s for s in self.statuses if s.action == action and s.index == index), None)

    def _request(self, send, action: int, index: int, what: str, also=lambda got: True):
        """``send()`` until its HQ_PROGRAM_STATUS has come (and ``also(status)``)."""
        self.statuses.clear()

        def done():
            got = self._answer(action, index)
            return got is not None and also(got)
        self._ask(send, done, what)
        return self._answer(action, index)

    def set(self, steps: list[ProgramStep]) -> None:
        """Every step in order; BoardRefused naming the step and the board's reason."""
        mav = self.link.mav_module
        for i, s in enumerate(steps):
            got = self._request(
                lambda i=i, s=s: self.link.program_step(i, len(steps), s.axis, s.inject, s.freq_hz,
                                                        s.amplitude, s.cycles, s.fade_cycles,
                                                        s.harmonics),
                mav.HQ_PROGRAM_STEP, i, f"program step {i + 1} of {len(steps)} (HQ_PROGRAM)")
            if not got.accepted:
                why = reason_text(got.reason) if got.reason else "it could not store it"
                raise BoardRefused(f"the board refused step {i + 1} of {len(steps)} "
                                   f"({s.freq_hz:.4g} Hz): {why}; its program is unchanged")
            self.progress(f"  step {i + 1} of {len(steps)} taken")

    def show(self) -> list[ProgramStep]:
        """The board's program, step by step (empty: none stored)."""
        mav = self.link.mav_module
        self.steps = {}
        count, i = 1, 0
        while i < count:
            got = self._request(lambda i=i: self.link.program_request("read", i),
                                mav.HQ_PROGRAM_READ, i, f"reading program step {i + 1} (HQ_PROGRAM)",
                                also=lambda got, i=i: i >= got.count or i in self.steps)
            count = int(got.count)
            i += 1
        return [self.steps[k] for k in range(count)]

    def clear(self) -> None:
        """Forget the board's program; BoardRefused with the board's reason."""
        mav = self.link.mav_module
        got = self._request(lambda: self.link.program_request("clear"), mav.HQ_PROGRAM_CLEAR, 0,
                            "clearing the program (HQ_PROGRAM)")
        if not got.accepted:
            why = reason_text(got.reason) if got.reason else "it could not store that"
            raise BoardRefused(f"the board refused to clear its program: {why}")


def _name(named: dict, value: int) -> str:
    """A dialect value's name among ``named`` (``{"roll": 0, ...}``), or the number."""
    return next((k for k, v in named.items() if v == value), str(value))
