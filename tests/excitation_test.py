"""The firmware's sine excitation (firmware/core/excitation.cpp)."""

import math

import numpy as np
import pytest

from heliquad import _firmware as fw
from heliquad.sim.base.firmware_facts import LOOP_RATE_HZ as LOOP_HZ


def config(freq, amp=1.0, cycles=10, fade=1, axis=fw.Axis.ROLL, inj=fw.Injection.MIXER):
    c = fw.ExcitationConfig()
    c.freq_hz, c.amplitude, c.cycles, c.fade_cycles, c.axis, c.injection = freq, amp, cycles, fade, axis, inj
    return c


@pytest.mark.parametrize("requested, period", [(1.0, 200), (0.15, 1333), (4.5, 44), (4.8, 42),
                                               (1.234, 162)])
def test_integer_period_and_exact_frequency(requested, period):
    ex = fw.Excitation()
    assert ex.start(config(requested), LOOP_HZ)
    assert ex.period_samples == period
    assert ex.actual_freq_hz == pytest.approx(LOOP_HZ / period, rel=1e-6)


def test_signal_is_periodic_with_fades_and_full_cycles_between():
    ex = fw.Excitation()
    ex.start(config(2.0, amp=0.3, cycles=4, fade=2), LOOP_HZ)
    n = ex.period_samples
    assert ex.total_samples == n * (4 + 2 * 2)
    values, measuring = [], []
    while ex.active:
        measuring.append(ex.measuring)
        values.append(ex.next())
    values = np.array(values[:ex.total_samples])
    k = np.arange(values.size)
    full = 0.3 * np.sin(2 * math.pi * (k % n) / n)
    mid = slice(2 * n, 6 * n)
    np.testing.assert_allclose(values[mid], full[mid], atol=1e-6)
    assert values[0] == 0.0 and abs(values[-1]) < 1e-3
    assert np.all(np.abs(values[:2 * n]) <= np.abs(full[:2 * n]) + 1e-7)
    assert sum(measuring) == 4 * n
    assert ex.next() == 0.0 and not ex.active


@pytest.mark.parametrize("freq, cycles", [(0.0, 10), (-1.0, 10), (60.0, 10), (1.0, 0)])
def test_impossible_requests_are_refused(freq, cycles):
    ex = fw.Excitation()
    assert not ex.start(config(freq, cycles=cycles), LOOP_HZ)
    assert not ex.active and ex.next() == 0.0


def test_stop():
    ex = fw.Excitation()
    ex.start(config(1.0), LOOP_HZ)
    ex.next()
    ex.stop()
    assert not ex.active and ex.next() == 0.0


def _run(ex):
    """The values and measuring flags of the rest of an excitation."""
    values, measuring = [], []
    while ex.active:
        measuring.append(ex.measuring)
        values.append(ex.next())
    return np.array(values), measuring


@pytest.mark.parametrize("after, measured", [
    (0, 1),               # in the fade-in: one full-amplitude cycle still runs
    (2 * 50, 1),          # at the first measured sample: that cycle completes
    (2 * 50 + 1, 1),
    (3 * 50, 1),          # on a cycle's boundary: the fade-out starts there
    (3 * 50 + 7, 2),      # mid-cycle: the cycle under way completes
])
def test_finish_completes_the_cycle_under_way_then_fades_out(after, measured):
    ex = fw.Excitation()
    ex.start(config(4.0, amp=0.5, cycles=20, fade=2), LOOP_HZ)
    n = ex.period_samples
    assert n == 50
    head = [ex.next() for _ in range(after)]
    assert ex.finish()
    assert ex.config.cycles == measured and ex.total_samples == n * (measured + 4)
    rest, measuring = _run(ex)
    values = np.r_[head, rest]
    assert values.size == n * (measured + 4)
    k = np.arange(values.size)
    full = 0.5 * np.sin(2 * math.pi * (k % n) / n)
    # the fade-out is the planned one: the same envelope as an excitation of `measured` cycles
    planned = fw.Excitation()
    planned.start(config(4.0, amp=0.5, cycles=measured, fade=2), LOOP_HZ)
    np.testing.assert_allclose(values, _run(planned)[0], atol=1e-7)
    np.testing.assert_allclose(values[2 * n:(2 + measured) * n], full[2 * n:(2 + measured) * n],
                               atol=1e-6)
    assert abs(values[-1]) < 1e-3


def test_finish_in_the_fade_out_or_idle_changes_nothing():
    ex = fw.Excitation()
    ex.start(config(4.0, cycles=3, fade=1), LOOP_HZ)
    total = ex.total_samples
    for _ in range(total - 10):
        ex.next()
    assert ex.finish() and ex.total_samples == total and ex.config.cycles == 3
    _run(ex)
    assert not ex.finish() and not ex.active


# --- multisine ------------------------------------------------------------------------------

def multisine(harmonics, base=0.5, peak=None, cycles=3, fade=1):
    """A multisine config; ``peak`` defaults to the sum's true peak (computed in double)."""
    c = config(base, cycles=cycles, fade=fade)
    c.signal = fw.Signal.MULTISINE
    c.harmonics = harmonics
    if peak is None:
        n = round(LOOP_HZ / base)
        k = np.arange(n)
        peak = max(abs(sum(a * np.sin(2 * np.pi * h * k / n + p) for h, a, p in harmonics)))
    c.amplitude = peak
    return c


def play(ex):
    values = []
    while ex.active:
        values.append(ex.next())
    return np.array(values)


def test_a_multisine_is_the_sum_of_its_harmonics_with_exact_phases_and_its_fades():
    lines = [(3, 0.2, 0.0), (7, 0.1, 1.0), (20, 0.05, -2.5)]
    ex = fw.Excitation()
    assert ex.start(multisine(lines, base=0.5, cycles=3, fade=2), LOOP_HZ)
    n = ex.period_samples
    assert n == 400
    fade = 2 * math.ceil(400 / 3)                  # two cycles of the lowest line
    assert ex.fade_samples == fade and ex.total_samples == 3 * n + 2 * fade
    values = play(ex)
    k = np.arange(values.size)
    full = sum(a * np.sin(2 * np.pi * h * k / n + p) for h, a, p in lines)
    # Full amplitude between the fades, to float precision; periodic with period N.
    mid = slice(fade, fade + 3 * n)
    np.testing.assert_allclose(values[mid], full[mid], atol=2e-6)
    np.testing.assert_allclose(values[fade:fade + n], values[fade + n:fade + 2 * n], atol=1e-6)
    # The fades start and end at zero and stay below the full signal.
    assert values[0] == 0.0 and abs(values[-1]) < 1e-3
    assert np.all(np.abs(values[:fade]) <= np.abs(full[:fade]) + 1e-6)
    assert not ex.peak_exceeded


def test_a_multisine_split_into_groups_gives_each_group_its_own_harmonics():
    """Injection.MOTORS: harmonic i to group i mod groups; the parts add up to the value."""
    lines = [(2, 0.1, 0.0), (3, 0.1, 0.5), (5, 0.1, 1.0), (7, 0.1, 1.5), (11, 0.1, 2.0)]
    ex = fw.Excitation()
    assert ex.start(multisine(lines, base=0.5, cycles=2, peak=0.2), LOOP_HZ)
    n, fade = ex.period_samples, ex.fade_samples
    values, parts = [], []
    while ex.active:
        value, part = ex.next_groups(3)
        values.append(value)
        parts.append(part)
    parts = np.array(parts)
    np.testing.assert_allclose(parts.sum(axis=1), values, atol=1e-6)
    k = np.arange(len(values))[fade:fade + 2 * n]
    for g in range(3):
        own = [(h, a, p) for i, (h, a, p) in enumerate(lines) if i % 3 == g]
        full = sum(a * np.sin(2 * np.pi * h * k / n + p) for h, a, p in own)
        np.testing.assert_allclose(parts[fade:fade + 2 * n, g], full, atol=2e-6)
    assert not ex.peak_exceeded          # each group's sum within 0.2; the whole is not


def test_a_group_beyond_the_declared_peak_stops_the_split_multisine():
    lines = [(2, 0.15, 0.0), (3, 0.01, 0.0), (5, 0.15, 0.0)]      # group 0: lines 2 and 5
    ex = fw.Excitation()
    assert ex.start(multisine(lines, base=0.5, cycles=2, peak=0.16), LOOP_HZ)
    while ex.active:
        ex.next_groups(2)
    assert ex.peak_exceeded


@pytest.mark.parametrize("lines, why", [
    ([(5, 0.1, 0.0), (5, 0.1, 0.0)], "repeated order"),
    ([(7, 0.1, 0.0), (5, 0.1, 0.0)], "not increasing"),
    ([(0, 0.1, 0.0), (5, 0.1, 0.0)], "order 0"),
    ([(5, 0.1, 0.0), (101, 0.1, 0.0)], "fewer than 4 samples per cycle"),
    ([(5, math.nan, 0.0)], "amplitude NaN"),
    ([(5, -0.1, 0.0)], "negative amplitude"),
    ([(5, 0.1, math.inf)], "phase infinite"),
    ([], "no harmonics"),
])
def test_a_multisine_with_impossible_harmonics_does_not_start(lines, why):
    ex = fw.Excitation()
    assert not ex.start(multisine(lines, base=0.5, peak=1.0), LOOP_HZ), why
    assert not ex.active


def test_a_declared_peak_below_the_signal_rms_is_refused():
    lines = [(3, 0.2, 0.0), (5, 0.2, 1.0)]
    rms = math.sqrt(2 * 0.2 ** 2 / 2)
    ex = fw.Excitation()
    assert not ex.start(multisine(lines, peak=0.95 * rms), LOOP_HZ)
    assert ex.start(multisine(lines, peak=rms), LOOP_HZ)      # possible: checked as it plays


def test_a_sample_beyond_the_declared_peak_is_never_output_and_stops_the_excitation():
    lines = [(3, 0.2, 0.0), (5, 0.2, 1.0)]
    true_peak = multisine(lines).amplitude
    ex = fw.Excitation()
    assert ex.start(multisine(lines, peak=0.8 * true_peak, fade=1), LOOP_HZ)
    values = play(ex)
    assert ex.peak_exceeded and not ex.active
    assert values.size < ex.total_samples
    assert np.max(np.abs(values)) <= 0.8 * true_peak * (1 + 1e-3)
    assert values[-1] == 0.0                       # the offending sample was not output
    # The true peak declared: it plays to the end.
    assert ex.start(multisine(lines, fade=1), LOOP_HZ)
    assert play(ex).size == ex.total_samples and not ex.peak_exceeded


def test_the_host_design_s_declared_peak_holds_in_the_firmware_s_float_arithmetic():
    from heliquad.host.acquire import multisine as design
    from heliquad.host.records import paper

    for band in paper.BANDS_HZ.values():
        ms = design.design(band, 0.25)
        c = multisine(ms.harmonics(), base=ms.base_hz, peak=ms.peak, cycles=ms.periods)
        ex = fw.Excitation()
        assert ex.start(c, LOOP_HZ) and ex.period_samples == ms.period_samples
        assert ex.fade_samples == ms.fade_samples
        values = play(ex)
        assert not ex.peak_exceeded and values.size == ex.total_samples
        assert np.max(np.abs(values)) == pytest.approx(ms.peak, rel=1e-3)


# --- chirp ----------------------------------------------------------------------------------

def chirp(start=0.5, stop=4.5, sweep_s=20.0, amp=0.3, fade=2, law=fw.Signal.CHIRP):
    c = config(start, amp=amp, cycles=1, fade=fade)
    c.signal, c.freq_stop_hz, c.sweep_s = law, stop, sweep_s
    return c


def frequencies(ex):
    """Each sample's frequency, then its value, to the excitation's end."""
    f, values = [], []
    while ex.active:
        f.append(ex.frequency_hz)
        values.append(ex.next())
    return np.array(f), np.array(values)


@pytest.mark.parametrize("law", [fw.Signal.CHIRP, fw.Signal.CHIRP_LINEAR])
def test_a_chirp_sweeps_its_band_at_full_amplitude_between_fades_held_at_its_ends(law):
    ex = fw.Excitation()
    assert ex.start(chirp(law=law), LOOP_HZ)
    fade = 2 * math.ceil(LOOP_HZ / 0.5)                  # two cycles of the lower end
    sweep = int(20.0 * LOOP_HZ)
    assert (ex.fade_samples, ex.total_samples) == (fade, sweep + 2 * fade)
    assert ex.actual_freq_hz == 0.5                      # as given: a chirp has no period
    measuring = []
    f, values = [], []
    while ex.active:
        measuring.append(ex.measuring)
        f.append(ex.frequency_hz)
        values.append(ex.next())
    f, values = np.array(f), np.array(values)
    assert sum(measuring) == sweep and measuring.index(True) == fade
    np.testing.assert_allclose(f[:fade], 0.5, rtol=1e-6)
    np.testing.assert_allclose(f[-fade:], 4.5, rtol=1e-6)           # the stop frequency
    tau = np.arange(sweep) / LOOP_HZ / 20.0
    law_f = 0.5 * 9.0 ** tau if law == fw.Signal.CHIRP else 0.5 + 4.0 * tau
    np.testing.assert_allclose(f[fade:fade + sweep], law_f, rtol=1e-5)
    # phase continuous: the value is the sine of the integrated frequency
    phase = np.concatenate([[0.0], np.cumsum(f.astype(float) / LOOP_HZ)[:-1]])
    np.testing.assert_allclose(values[fade:fade + sweep],
                               0.3 * np.sin(2 * np.pi * phase[fade:fade + sweep]), atol=2e-5)
    assert np.max(np.abs(values)) <= np.float32(0.3) and values[0] == 0.0 and abs(values[-1]) < 1e-3


def test_a_downward_chirp_and_its_early_finish_fade_out_at_the_frequency_reached():
    ex = fw.Excitation()
    assert ex.start(chirp(start=4.0, stop=1.0, sweep_s=10.0, fade=1), LOOP_HZ)
    fade = math.ceil(LOOP_HZ / 1.0)
    for _ in range(fade + 1000):                        # 5 s into the sweep
        ex.next()
    reached = ex.frequency_hz
    assert reached == pytest.approx(4.0 * 0.25 ** 0.5, rel=1e-4)
    assert ex.finish()
    f, values = frequencies(ex)
    assert f.size == fade and np.allclose(f, reached)
    assert abs(values[-1]) < 1e-3 and not ex.active


@pytest.mark.parametrize("change, ok", [
    ({}, True),
    ({"stop": 0.5}, False),                # no sweep: its ends are one frequency
    ({"stop": 0.0}, False), ({"stop": math.nan}, False), ({"stop": 60.0}, False),
    ({"sweep_s": 0.0}, False), ({"sweep_s": -1.0}, False), ({"sweep_s": math.inf}, False),
    ({"cycles": 2}, False),                # one sweep
    ({"fade": 0}, False),                  # a fade of at least a cycle (no 0/0 envelope)
])
def test_an_impossible_chirp_does_not_start(change, ok):
    c = chirp(**{k: v for k, v in change.items() if k != "cycles"})
    assert c.fade_cycles == change.get("fade", 2)
    if "cycles" in change:
        c.cycles = change["cycles"]
    ex = fw.Excitation()
    assert ex.start(c, LOOP_HZ) is ok and ex.active is ok
