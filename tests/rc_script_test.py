"""The simulated pilot as a script (sim/rig/rc_script.py, ``--rc-script`` on board, sil and
sweep --sil): what a script's lines mean, what is refused, and that the firmware arms and
disarms when the script says, frame for frame, on the simulated rig."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from heliquad.sim.base.errors import InputError
from heliquad.sim.rig.rc_script import LANDED_US, parse_rc_script, read_rc_script
from heliquad.sim.rig.setup import BOOT_FRAMES, SilConfig, rc_block

LOOP_HZ = 200.0


def test_before_its_first_line_the_pilot_is_landed_and_each_line_holds_from_its_time():
    s = parse_rc_script("# arm, hover, then land\n0.2 5=2000\n0.5 3=1400 7=1900\n"
                        "1.5 3=1000 5=1000  # down\n")
    rows = s.rows(0, 400, LOOP_HZ)
    assert tuple(rows[0]) == LANDED_US == (1500, 1500, 1000, 1500, 1000, 1500, 0, 0)
    assert tuple(rows[39]) == LANDED_US                     # 0.195 s: not yet
    assert rows[40][4] == 2000 and rows[40][2] == 1000      # 0.2 s: the arm switch only
    assert (rows[100][[2, 4, 6]] == [1400, 2000, 1900]).all()
    assert (rows[300][[2, 4, 6]] == [1000, 1000, 1900]).all()   # channel 7 holds
    # the same rows whichever block a frame falls in
    assert (np.vstack([s.rows(0, 37, LOOP_HZ), s.rows(37, 363, LOOP_HZ)]) == rows).all()


def test_lines_in_any_order_and_at_equal_times_the_later_line_wins():
    s = parse_rc_script("1.0 5=2000\n0.5 5=1100\n1.0 5=1200\n")
    assert [s.row(f, LOOP_HZ)[4] for f in (0, 100, 199, 200)] == [1000, 1100, 1100, 1200]


def test_without_a_script_the_rig_keeps_its_own_pilot():
    assert (rc_block(0, 60, 0.4) == rc_block(0, 60, 0.4, None, LOOP_HZ)).all()
    assert rc_block(BOOT_FRAMES + 1, 1, 0.4)[0][4] == 2000


@pytest.mark.parametrize("text, words", [
    ("x 5=2000", "line 1: 'x' is not a time in seconds"),
    ("0 5=2000\n1 9=2000", "line 2: '9=2000': channel 9 is not one of 1-8"),
    ("1 0=2000", "channel 0 is not one of 1-8"),
    ("1 5=700", "pulse 700 us is outside 800-2200 us (0: no pulse)"),
    ("1 5=2201", "pulse 2201 us is outside 800-2200 us"),
    ("-1 5=2000", "time -1 must be a finite number of seconds, 0 or more"),
    ("inf 5=2000", "time inf must be a finite number"),
    ("1", "line 1: a time with no CH=US after it"),
    ("1 5", "'5': expected CH=US"),
    ("1 5=2000.5", "channel and pulse must be whole numbers"),
    ("# only a comment\n\n", "no changes: every line is blank or a comment"),
], ids=["time", "channel", "channel-0", "short-pulse", "long-pulse", "negative", "infinite",
        "no-change", "no-equals", "fraction", "empty"])
def test_a_bad_line_is_refused_by_its_number(text, words):
    with pytest.raises(InputError, match=words.replace("(", r"\(").replace(")", r"\)")):
        parse_rc_script(text)


def test_no_pulse_is_a_pulse_of_zero(tmp_path):
    f = tmp_path / "lost.rc"
    f.write_text("2 3=0 1=0\n")
    assert tuple(read_rc_script(f).row(400, LOOP_HZ))[:3] == (0, 1500, 0)
    with pytest.raises(InputError, match="missing.rc: no such file"):
        read_rc_script(tmp_path / "missing.rc")


def _armed_by_time(cfg, tmp_path, seconds):
    """HQ_SYSID_SAMPLE's (time_us, armed) over ``seconds`` of a SilSession with ``cfg``."""
    from heliquad.host.acquire.session import SilSession

    out = []
    session = SilSession(cfg, str(tmp_path / "run.tlog"))
    try:
        while session.frame < seconds * LOOP_HZ:
            for m in session.advance():
                if m.get_type() == "HQ_SYSID_SAMPLE":
                    out.append((m.time_us, m.armed))
    finally:
        session.close()
    return out


def _changes(samples):
    return [(t, a) for (t, a), (_, before) in zip(samples[1:], samples) if a != before]


def test_the_firmware_arms_and_disarms_when_the_script_says(tmp_path):
    """Arm switch up at 0.5 s, down at 2.0 s: the vehicle is armed from the first loop that
    sees the switch (the throttle low) to the first that sees it down, and with no script
    line after, stays disarmed; the throttle raised meanwhile changes nothing of that."""
    script = parse_rc_script("0.5 5=2000\n1.0 3=1400\n2.0 5=1000 3=1000\n")
    samples = _armed_by_time(SilConfig(rc_script=script), tmp_path, 3.0)
    assert samples[0][1] == 0
    changes = _changes(samples)
    assert [a for _, a in changes] == [1, 0]
    # each within two loops of its line (the switch's pulse is read the loop after it
    # changes, and the host build stamps a loop with its frame's time)
    assert 500_000 <= changes[0][0] <= 510_000
    assert 2_000_000 <= changes[1][0] <= 2_010_000


def _sweep(tmp_path, name, script_text):
    script = tmp_path / f"{name}.rc"
    script.write_text(script_text)
    out = tmp_path / name
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "sweep", "--axis", "roll", "--sil",
                          "--plant", "tf", "--freqs-hz", "2", "--rc-script", str(script),
                          "--out", str(out)], capture_output=True, text=True, timeout=600)
    return res, json.loads((out / "manifest.json").read_text())


def test_a_sweep_flies_the_scripts_pilot_and_records_the_script(tmp_path):
    """A script that arms and raises the throttle: the sweep measures its point and its
    manifest records the script; one that only raises the throttle leaves the vehicle
    disarmed, and the firmware refuses the excitation, as it would with that pilot."""
    res, manifest = _sweep(tmp_path, "arms", "0.2 5=2000\n0.3 3=1400\n")
    assert res.returncode == 0, res.stderr
    assert manifest["complete"]
    assert manifest["source"]["rc_script"] == [[0.2, {"5": 2000}], [0.3, {"3": 1400}]]
    res, manifest = _sweep(tmp_path, "never", "0.2 3=1400\n")
    assert res.returncode == 1 and "the vehicle is disarmed" in res.stderr
    assert not manifest["complete"]
    assert manifest["aborted"].startswith("refused by the firmware: the vehicle is disarmed")
