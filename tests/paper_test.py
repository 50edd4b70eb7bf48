"""The paper's published figures (host/records/paper.py, restated in docs/paper.md) against what the
firmware flies: the cascade gains are defined once, in the firmware
(``CascadeGains::paper_defaults()``); host/records/paper.py keeps the published numbers as the
reference, and these tests tie the two."""

import pathlib

import pytest

from heliquad import _firmware as fw
from heliquad.host.records import paper
from heliquad.host.records.gains import Gains, firmware_gains, load_gains
from heliquad.sim.base.dialect import AXES

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"
#: Single precision: a decimal with a few digits is within half an ulp, 2^-24 relative.
FLOAT32 = 2.0 ** -24


@pytest.mark.parametrize("axis", AXES)
def test_the_firmware_flies_the_papers_gains(axis):
    g = fw.CascadeGains.paper_defaults()
    rate = g.rate(fw.Axis(AXES[axis]))
    assert (rate.kc, rate.tau_i_s, rate.tau_d_s) == pytest.approx(paper.RATE_GAINS[axis],
                                                                  rel=FLOAT32)
    if axis not in paper.ANGLE_GAINS:
        with pytest.raises(ValueError, match="no angle loop"):
            g.angle(fw.Axis(AXES[axis]))
        return
    angle = g.angle(fw.Axis(AXES[axis]))
    assert (angle.kc, angle.tau_d_s) == pytest.approx(paper.ANGLE_GAINS[axis], rel=FLOAT32)
    assert angle.tau_i_s == 0.0                      # PD: no integral


@pytest.mark.parametrize("axis", AXES)
def test_the_recorded_gains_read_as_the_papers(axis):
    # What a sweep's manifest and a validation record (the firmware's single-precision
    # values, as their shortest decimals) is the paper's table, digit for digit.
    expected = Gains(paper.RATE_GAINS[axis], paper.ANGLE_GAINS.get(axis))
    assert firmware_gains(axis) == expected
    assert load_gains(axis) == expected


def test_docs_state_the_papers_gains():
    text = (DOCS / "paper.md").read_text()
    for axis, (kc, tau_i, tau_d) in paper.RATE_GAINS.items():
        assert f"| {axis} | {kc} | {tau_i} | {tau_d} |" in text
    for axis, (kc, tau_d) in paper.ANGLE_GAINS.items():
        assert f"| {axis} | {kc} | {tau_d} |" in text
