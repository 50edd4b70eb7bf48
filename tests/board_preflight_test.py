"""``heliquad board`` given parameter values before it flies: a --load-params file's gains
and a --params vehicle file's geometry are set on the simulated board (in lockstep, the
pilot landed) and, with --param-store, saved by its firmware; a value the board refuses ends
the run in one line before it flies. Each run stops on its own (--duration-s): nothing
here races the board's real-time loop; its parameters are read back from the store by a
firmware started on it, over the parameter protocol."""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

from firmwares import start
from heliquad.host.acquire.param_protocol import decode_value
from heliquad.sim.plant.rotor_geometry import geometry_params
from heliquad.sim.plant.vehicle_params import load_params
from params_test import Client

OTHER_VEHICLE = pathlib.Path(__file__).parent / "data" / "other_vehicle.toml"


def _board(tmp_path, *args):
    """``heliquad board`` for a twentieth of a second, disarmed, its parameters in a store."""
    return subprocess.run(
        [sys.executable, "-m", "heliquad.host.cli.parser", "board", "--disarmed", "--duration-s", "0.05",
         "--telemetry", str(tmp_path / "rig"), "--param-store", str(tmp_path / "store.bin"),
         *args], capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)


def _stored(tmp_path) -> dict:
    """The values a firmware started on the board's store reads, by name."""
    with start("host", params_file=str(tmp_path / "store.bin")) as fw:
        c = Client(fw)
        values = {name: decode_value(m.param_value, m.param_type)      # INT32s bytewise
                  for name, m in c.fetch().items()}
        c.close()
    return values


def test_load_params_are_on_the_board_before_it_flies(tmp_path):
    gains = tmp_path / "gains.params"
    gains.write_text("# Vehicle-Id Component-Id Name Value Type\n"
                     "1\t1\tRATE_RLL_KC\t1.75\t9\n1\t1\tANG_PIT_KC\t4.5\t9\n")
    r = _board(tmp_path, "--load-params", str(gains))
    assert r.returncode == 0, r.stderr
    assert "set 2 parameters of gains.params on the board" in r.stdout
    values = _stored(tmp_path)
    assert values["RATE_RLL_KC"] == pytest.approx(1.75)
    assert values["ANG_PIT_KC"] == pytest.approx(4.5)
    assert values["RATE_PIT_KC"] == pytest.approx(2.386, rel=1e-6)     # the rest untouched


def test_a_vehicle_file_gives_the_board_its_geometry(tmp_path):
    r = _board(tmp_path, "--plant", "vehicle", "--params", str(OTHER_VEHICLE))
    assert r.returncode == 0, r.stderr
    values = _stored(tmp_path)
    want = geometry_params(load_params(str(OTHER_VEHICLE)))
    assert want and all(values[g.name] == pytest.approx(g.value, rel=1e-6, abs=1e-7)
                        for g in want)


def test_a_refused_value_ends_the_run_in_one_line_before_it_flies(tmp_path):
    bad = tmp_path / "bad.params"
    bad.write_text("1\t1\tRATE_RLL_KC\t999\t9\n")
    r = _board(tmp_path, "--load-params", str(bad))
    assert r.returncode in (1, 2)
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "refused" in lines[0] and "RATE_RLL_KC" in lines[0], r.stderr
    assert "Traceback" not in r.stderr
    assert "board running" not in r.stdout
    assert not os.path.exists(tmp_path / "rig")          # the port is gone with the board
