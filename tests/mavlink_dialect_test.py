"""``heliquad mavlink-dialect``: pymavlink's own tools decode heliquad's logs with the module
it makes. Hermetic: the install goes into a copy of pymavlink on a private PYTHONPATH, never
into the real site-packages."""

import json
import os
import subprocess
import sys
import time

import pymavlink
import pytest

from heliquad.host.records.tlog import read_tlog
from heliquad.sim.base.dialect import dialect
from private_pymavlink import private_pymavlink as make_private_pymavlink

REAL_V20 = os.path.join(os.path.dirname(pymavlink.__file__), "dialects", "v20")


def heliquad(*args, env=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=600, env=env)


@pytest.fixture(scope="module")
def sil_log(tmp_path_factory):
    """A heliquad .tlog: a short SIL run (every message the firmware sends in a run)."""
    run = tmp_path_factory.mktemp("sil") / "run"
    before = time.time()
    res = heliquad("sil", "--freq-hz", 2, "--amplitude", 0.05, "--cycles", 2,
                   "--fade-cycles", 1, "--out", run)
    after = time.time()
    assert res.returncode == 0, res.stderr
    return run.with_suffix(".tlog"), (before, after)


@pytest.fixture
def private_pymavlink(tmp_path):
    """A copy of the installed pymavlink in its own folder, and the environment that makes
    Python import it instead of the real one."""
    pymavlink_dir, env = make_private_pymavlink(tmp_path / "site")
    env.pop("MAVLINK20", None)          # as a user's shell has it: pymavlink starts in v1.0
    return pymavlink_dir, env


def dumped_rows(pymavlink_dir, env, log):
    """pymavlink's mavlogdump.py --dialect heliquad --format json on a log, one object per
    message (``meta``: type, timestamp in s; ``data``: the fields)."""
    res = subprocess.run([sys.executable, str(pymavlink_dir / "tools" / "mavlogdump.py"),
                          "--dialect", "heliquad", "--format", "json", str(log)],
                         capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr
    return [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]



def test_installed_dialect_lets_mavlogdump_decode_a_heliquad_log(private_pymavlink, sil_log):
    # After --install, mavlogdump.py --dialect heliquad decodes every record of a heliquad
    # log, heliquad's own messages field by field as heliquad's reader does.
    pymavlink_dir, env = private_pymavlink
    sil_log, (before, after) = sil_log
    real_before = sorted(os.listdir(REAL_V20))
    res = heliquad("mavlink-dialect", "--install", env=env)
    assert res.returncode == 0, res.stderr
    v20 = pymavlink_dir / "dialects" / "v20"
    assert f"installed heliquad.py into {v20}" in res.stdout
    assert (v20 / "heliquad.py").is_file() and (v20 / "heliquad.xml").is_file()
    assert (pymavlink_dir / "dialects" / "v10" / "heliquad.py").is_file()
    assert sorted(os.listdir(REAL_V20)) == real_before          # the real one untouched

    rows = dumped_rows(pymavlink_dir, env, sil_log)
    dumped = [(r["meta"]["type"], r["data"]) for r in rows]
    ours = read_tlog(str(sil_log), dialect())
    assert [t for t, _ in dumped] == [m.get_type() for _, m in ours]      # no BAD_DATA
    samples = [d for t, d in dumped if t == "HQ_SYSID_SAMPLE"]
    ours_samples = [m for _, m in ours if m.get_type() == "HQ_SYSID_SAMPLE"]
    assert len(samples) > 200
    assert [(d["time_us"], d["seq"], d["excitation"]) for d in samples] == \
        [(m.time_us, m.seq, m.excitation) for m in ours_samples]
    status = [d for t, d in dumped if t == "HQ_EXCITATION_STATUS"]
    assert status and status[-1]["freq_hz"] == pytest.approx(2.0, rel=0.05)
    # The SIL log's stamps: the run's start on the wall clock plus simulated time, so the
    # tool shows when the run was made (not 1970).
    stamps = [r["meta"]["timestamp"] for r in rows if r["meta"]["type"] == "HQ_SYSID_SAMPLE"]
    starts = {round(s * 1e6) - d["time_us"] for s, d in zip(stamps, samples)}
    assert len(starts) == 1 or max(starts) - min(starts) <= 1          # float seconds
    assert before * 1e6 <= min(starts) <= after * 1e6


#: Reads a log with pymavlink's mavutil as a user's script does, the dialect named only by
#: MAVLINK_DIALECT: the HQ_SYSID_SAMPLE count and the module that decoded them.
COUNT_SAMPLES = """
import sys
from pymavlink import mavutil
log = mavutil.mavlink_connection(sys.argv[1])
count = 0
while log.recv_match(type="HQ_SYSID_SAMPLE") is not None:
    count += 1
print(count, mavutil.mavlink.__name__)
"""


def test_installed_dialect_serves_pymavlink_started_in_mavlink_1(private_pymavlink, sil_log,
                                                                  tmp_path):
    # Without MAVLINK20 in the environment pymavlink loads dialects/v10 first: with
    # MAVLINK_DIALECT=heliquad its import failed, and so did mavgraph.py --dialect heliquad
    # (which never sets MAVLINK20). With the MAVLink 1 module installed beside the v20 one
    # both read the log, pymavlink moving to the v20 module at its first MAVLink 2 frame.
    pymavlink_dir, env = private_pymavlink
    sil_log, _ = sil_log
    assert heliquad("mavlink-dialect", "--install", env=env).returncode == 0
    samples = sum(m.get_type() == "HQ_SYSID_SAMPLE" for _, m in read_tlog(str(sil_log), dialect()))
    res = subprocess.run([sys.executable, "-c", COUNT_SAMPLES, str(sil_log)], capture_output=True,
                         text=True, timeout=600, env=dict(env, MAVLINK_DIALECT="heliquad"))
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == [str(samples), "pymavlink.dialects.v20.heliquad"]

    # mavgraph.py's time axis uses Axes.plot_date, which matplotlib 3.9 deprecated and later
    # releases removed (pymavlink's defect, not the dialect's): --xaxis plots against a field.
    picture = tmp_path / "rate.png"
    res = subprocess.run([sys.executable, str(pymavlink_dir / "tools" / "mavgraph.py"),
                          "--dialect", "heliquad", "--output", str(picture),
                          "--xaxis", "HQ_SYSID_SAMPLE.time_us", str(sil_log),
                          "HQ_SYSID_SAMPLE.rate"],
                         capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_folder_holds_the_dialect_and_a_module_that_matches_the_firmware(tmp_path):
    # --out DIR: the XML, the definitions it includes, and a module with the firmware's
    # messages (ids and CRC seeds, so the same bytes decode); a second run changes nothing,
    # and a file there that holds something else is never written over.
    import importlib.util

    out = tmp_path / "dialect"
    res = heliquad("mavlink-dialect", "--out", out)
    assert res.returncode == 0, res.stderr
    assert sorted(os.listdir(out)) == sorted(["heliquad.xml", "common.xml", "standard.xml",
                                              "minimal.xml", "heliquad.py", "v10"])
    assert os.listdir(out / "v10") == ["heliquad.py"]
    spec = importlib.util.spec_from_file_location("heliquad_dialect_copy", out / "heliquad.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    firmware = dialect()
    hq = {i: c for i, c in firmware.mavlink_map.items() if c.msgname.startswith("HQ_")}
    assert len(hq) >= 5
    for msgid, cls in hq.items():
        assert module.mavlink_map[msgid].msgname == cls.msgname
        assert module.mavlink_map[msgid].crc_extra == cls.crc_extra

    assert heliquad("mavlink-dialect", "--out", out).returncode == 0     # same files: fine
    (out / "heliquad.xml").write_text("my edits")
    res = heliquad("mavlink-dialect", "--out", out)
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert f"{out / 'heliquad.xml'} exists and holds something else" in res.stderr
    assert (out / "heliquad.xml").read_text() == "my edits"


def test_a_python_without_pymavlink_or_none_is_one_line(tmp_path):
    bare = tmp_path / "bare-python"
    bare.write_text(f"#!/bin/sh\nexec {sys.executable} -S \"$@\"\n")      # no site-packages
    bare.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    for python, says in ((bare, f"--python {bare}: it has no pymavlink"),
                         (tmp_path / "nope", f"--python {tmp_path / 'nope'}: cannot run it")):
        res = heliquad("mavlink-dialect", "--install", "--python", python, env=env)
        assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
        assert says in res.stderr and "Traceback" not in res.stderr
