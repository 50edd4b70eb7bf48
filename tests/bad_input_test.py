"""Bad or odd input to every subcommand: one line on stderr, exit code 2, no traceback, no
hang, and nothing created or changed in the folder it ran in. The start of the corpus the
host tool is held to (more cases are added with each fix)."""

import shlex
import subprocess
import sys

import pytest

POINTS = ("omega_rad_s,magnitude,phase_rad\n1,1,-0.5\n2,0.8,-1\n4,0.5,-1.5\n8,0.2,-2\n"
          "16,0.05,-2.5\n")

CASES = [
    # sil: numbers out of range, not finite, or beyond what the firmware accepts
    "sil --freq-hz 1e-9 --amplitude 0.05 --out o",
    "sil --freq-hz nan --amplitude 0.05 --out o",
    "sil --freq-hz inf --amplitude 0.05 --out o",
    "sil --freq-hz -1 --amplitude 0.05 --out o",
    "sil --freq-hz 60 --amplitude 0.05 --out o",
    "sil --freq-hz one --amplitude 0.05 --out o",
    "sil --freq-hz 1 --amplitude nan --out o",
    "sil --freq-hz 1 --amplitude -1 --out o",
    "sil --freq-hz 1 --amplitude 0 --out o",
    "sil --freq-hz 1 --amplitude 5 --out o",
    "sil --freq-hz 1 --amplitude 500 --inject rate --out o",
    "sil --freq-hz 1 --amplitude 0.05 --cycles 0 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --cycles 70000 --out o",
    "sil --freq-hz 0.06 --amplitude 0.05 --cycles 100 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --cycles 1.5 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --fade-cycles 0 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --seed -1 --plant vehicle --out o",
    "sil --freq-hz 1 --amplitude 0.05 --seed 99999999999 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --num nan --out o",
    "sil --freq-hz 1 --amplitude 0.05 --num 1 --den inf 1 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --num 1 --den 0 0 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --loop-hz 0 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --collective 5 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --collective -0.1 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --params models.json --plant vehicle --out o",
    "sil --freq-hz 1 --amplitude 0.05 --params binary.dat --plant vehicle --out o",
    "sil --freq-hz 1 --amplitude 0.05 --out no/such/folder/run",
    "sil --freq-hz 1 --amplitude 0.05 --fault bogus@1 --out o",
    "sil --freq-hz 1 --amplitude 0.05 --axis yaw --inject angle --out o",
    # sweep
    "sweep --sil --axis roll --cycles 0 --out s",
    "sweep --sil --axis roll --cycles 70000 --out s",
    "sweep --sil --axis roll --freqs-hz nan --out s",
    "sweep --sil --axis roll --freqs-hz 1e-9 --out s",
    "sweep --sil --axis roll --freqs-hz 1 60 --out s",
    "sweep --sil --axis roll --amplitude nan --out s",
    "sweep --sil --axis roll --amplitude 5 --out s",
    "sweep --sil --axis roll --seed -1 --out s",
    "sweep --port /dev/null --baud -1 --axis roll --out s",
    "sweep --port /dev/null --baud 0 --axis roll --out s",
    "sweep --sil --port /dev/null --axis roll --out s",
    "sweep --axis roll --out s",
    # fsf, fit, validate
    "fsf binary.dat --out p.csv",
    "fsf missing.csv --out p.csv",
    "fit binary.dat --order 0/2",
    "fit points.csv --order x",
    "fit points.csv --order 0/40",
    "validate models.json",
    "validate binary.dat",
    "validate points.csv",
    "validate missing.json",
    "validate models.json --model -1",
    # identify, report, tlog, log
    "identify binary.dat",
    "identify .",
    "report missing",
    "report .",
    "tlog binary.dat",
    "tlog .",
    "tlog missing.tlog",
    "log --port /dev/null --baud -1 --out l.tlog --duration-s 0.1",
    "log --port /dev/null --out l.tlog --duration-s nan",
    "log --port /dev/null --out l.tlog --duration-s 0",
    "log --port missing --out l.tlog",
    # board, dmp-image, flash
    "board --telemetry t --duration-s -1",
    "board --telemetry t --collective 2",
    "dmp-image binary.dat",
    "flash --image binary.dat",
]


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "points.csv").write_text(POINTS)
    (tmp_path / "models.json").write_text("{bad json")
    (tmp_path / "binary.dat").write_bytes(b"\x00\x01\x02\xff" * 16)
    return tmp_path


def _snapshot(path):
    return {p.name: (p.read_bytes() if p.is_file() else None) for p in path.iterdir()}


@pytest.mark.parametrize("case", CASES)
def test_bad_input_is_one_line_and_changes_nothing(case, folder):
    before = _snapshot(folder)
    res = subprocess.run([sys.executable, "-m", "heliquad.host.cli", *shlex.split(case)],
                         capture_output=True, text=True, timeout=120, cwd=folder)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2, (res.returncode, res.stdout[-500:], res.stderr[-2000:])
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("heliquad"), lines[0]
    assert _snapshot(folder) == before
