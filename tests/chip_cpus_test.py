"""The emulated chip's two CPUs (sim/chip/cpu.py: unicorn and the engine's own) fly the image
alike: the same experiment in the processor in the loop over USB logs the same samples, bit
for bit, on both.

What may differ is only when an interrupt lands inside the loop: the engine takes it at the
first instruction boundary at or after its cycle, unicorn at the next translated block's, a
few instructions later. The loop's own measure of its step then moves by the handlers'
cycles that fall inside or outside it (a fraction of a percent of the step); nothing the
control law computes depends on it.
"""

import pytest

from firmwares import image_for
from heliquad.host.acquire.experiment import run_sil
from heliquad.sim.chip import EmulationError
from heliquad.sim.chip.cpu import CPU_VARIABLE, CPUS, chosen_cpu
from heliquad.sim.rig.setup import SilConfig

#: The step's largest cycle count may move by an interrupt handler's worth: the image's
#: longest (the USB controller's) is under 2 000 cycles of the 600 000 a loop has.
STEP_CYCLES_TOLERANCE = 2_000


def _fly(cpu: str, out: str, monkeypatch):
    monkeypatch.setenv(CPU_VARIABLE, cpu)        # the drop-in's chip inherits it
    cfg = SilConfig(axis="roll", inject="mixer", freq_hz=2.0, amplitude=0.05, cycles=6,
                    fade_cycles=1, firmware_link="usb", **image_for("teensy35"))
    return run_sil(cfg, out, progress=lambda *_: None)


def _summary_figures(summary: str) -> dict:
    """'1100 loops, ... step cycles median 93022 max 139753 of 600000, 0 overruns' -> ints."""
    words = summary.replace(",", "").split()
    return {"loops": int(words[words.index("loops") - 1]),
            "median": int(words[words.index("median") + 1]),
            "max": int(words[words.index("max") + 1]),
            "overruns": int(words[words.index("overruns") - 1])}


@pytest.mark.pil
def test_both_cpus_log_the_same_samples_of_the_same_experiment(tmp_path, monkeypatch):
    runs = {cpu: _fly(cpu, str(tmp_path / cpu), monkeypatch) for cpu in CPUS}
    unicorn, engine = runs["unicorn"], runs["engine"]
    assert unicorn.stopped is None and engine.stopped is None
    assert engine.samples == unicorn.samples > 500 and engine.seq_gaps == unicorn.seq_gaps == 0
    assert engine.frames == unicorn.frames
    with open(unicorn.csv_path) as a, open(engine.csv_path) as b:
        assert a.read() == b.read(), "the logged samples differ between the CPUs"
    figures = {cpu: _summary_figures(r.firmware_summary) for cpu, r in runs.items()}
    assert figures["engine"]["loops"] == figures["unicorn"]["loops"] == engine.frames
    assert figures["engine"]["overruns"] == figures["unicorn"]["overruns"] == 0
    assert abs(figures["engine"]["median"] - figures["unicorn"]["median"]) <= STEP_CYCLES_TOLERANCE
    assert abs(figures["engine"]["max"] - figures["unicorn"]["max"]) <= STEP_CYCLES_TOLERANCE


def test_the_cpu_is_chosen_by_argument_then_environment(monkeypatch):
    monkeypatch.delenv(CPU_VARIABLE, raising=False)
    assert chosen_cpu() == "engine"
    monkeypatch.setenv(CPU_VARIABLE, "unicorn")
    assert chosen_cpu() == "unicorn" and chosen_cpu("engine") == "engine"
    monkeypatch.setenv(CPU_VARIABLE, "qemu")
    with pytest.raises(EmulationError, match="no CPU 'qemu'.*unicorn, engine"):
        chosen_cpu()
