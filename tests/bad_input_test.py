"""Bad or odd input to every subcommand: one line on stderr that starts with ``heliquad``, exit
code 2 (or the code the command documents), no traceback, no hang, and nothing created or
changed in the folder it ran in (the files that were there are byte for byte the same; a
refused command adds none).

Each case names the files it uses; they are made in the case's own folder from FILES (text,
bytes, or a function of the session's sweep folder, which is one small SIL sweep of the tf
plant, identified and validated once per session). Almost every case is refused before any
firmware starts; the few that must start one are marked in their group's comment.
"""

from __future__ import annotations

import json
import math
import pathlib
import shlex
import shutil
import subprocess
import sys

import pytest
from pymavlink import DFReader

from fat32_image import Fat32Image
from log_protocol_test import card_with_logs, wait_armed
from tool_runs import running_board

# --- files the cases use -------------------------------------------------------------------

POINTS_HEADER = "omega_rad_s,magnitude,phase_rad"
GOOD_ROWS = [(1, 1, -0.5), (2, 0.8, -1), (4, 0.5, -1.5), (8, 0.2, -2), (16, 0.05, -2.5)]


def points(rows=GOOD_ROWS, header=POINTS_HEADER):
    return header + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)


def scaled_points(omega_factor=1.0, mag_factor=1.0):
    return points([(w * omega_factor, m * mag_factor, p) for w, m, p in GOOD_ROWS])


def run_csv(n=400, dt=0.005, u=lambda k: math.sin(k / 10), y=lambda k: 0.5 * math.sin(k / 10),
            t0=0.0):
    return "t_s,u,y\n" + "".join(f"{t0 + k * dt!r},{u(k)!r},{y(k)!r}\n" for k in range(n))


GAINS = {"rate": {"roll": [2.4, 0.44, 0.05], "pitch": [2.4, 0.44, 0.05], "yaw": [7.4, 0.4, 0.04]},
         "angle": {"roll": [1.5, 0.1], "pitch": [1.5, 0.1]}}
MODEL = {"order": [0, 2], "num": [28.19], "den": [1.0, 5.13, 22.93], "delay_s": 0.0,
         "stable": True, "degenerate": False, "metrics": {"J": 1.0, "rms": 0.01}}


def models(*changes, axis="roll", **top):
    """A MODELS.json with one model, ``changes`` applied to it, ``top`` to the document."""
    model = dict(MODEL)
    for change in changes:
        model.update(change)
    return json.dumps({"models": [model], "recommended": 0, "axis": axis, **top})


def gains(**changes):
    doc = json.loads(json.dumps(GAINS))
    for path, value in changes.items():
        section, _, axis = path.partition("_")
        if value is None:
            doc[section].pop(axis) if axis else doc.pop(section)
        elif axis:
            doc[section][axis] = value
        else:
            doc[section] = value
    return json.dumps(doc)


VEHICLE = (pathlib.Path(__file__).resolve().parents[1] / "sim" / "plant" / "vehicle.toml").read_text()


def vehicle(old, new):
    """The shipped vehicle file with one line's start ``old`` replaced by ``new``."""
    lines = VEHICLE.splitlines()
    hits = [i for i, line in enumerate(lines) if line.startswith(old)]
    assert len(hits) == 1, old
    lines[hits[0]] = new
    return "\n".join(lines) + "\n"


def rotor(n, old, new):
    """The shipped vehicle file with, in its ``n``-th [[rotors]] table, the line starting
    ``old`` replaced by ``new``."""
    lines = VEHICLE.splitlines()
    starts = [i for i, line in enumerate(lines) if line == "[[rotors]]"] + [len(lines)]
    hits = [i for i in range(starts[n - 1], starts[n]) if lines[i].startswith(old)]
    assert len(hits) == 1, (n, old)
    lines[hits[0]] = new
    return "\n".join(lines) + "\n"


def rotors(count):
    """The shipped vehicle file with ``count`` upright rotors on a 0.3 m circle instead of its own."""
    tables = "".join(
        f"[[rotors]]\nposition_m = [{0.3 * math.cos(k):.6f}, {0.3 * math.sin(k):.6f}, 0.0]\n"
        "thrust_axis = [0.0, 0.0, -1.0]\nspin = 1\nmax_thrust_n = 9.0\nmax_speed_rad_s = 2930.0\n"
        "torque_per_thrust_m = 0.0076\nrotor_inertia_kg_m2 = 1.2e-5\ntime_constant_s = 0.03\n\n"
        for k in range(count))
    return VEHICLE[:VEHICLE.index("\n[[rotors]]") + 1] + tables + VEHICLE[VEHICLE.index("[rig]"):]


def hex_image(fsec=0xFE, sp=0x2002_0000, reset=0x411, beyond=False):
    """A small Intel HEX image that passes (or, as asked, fails) flash's checks."""
    import io

    from intelhex import IntelHex

    ih = IntelHex()
    for a, b in enumerate(sp.to_bytes(4, "little") + reset.to_bytes(4, "little")):
        ih[a] = b
    for a, b in enumerate([0xFF] * 12 + [fsec, 0xF9, 0xFF, 0xFF]):
        ih[0x400 + a] = b
    for a in range(0x410, 0x420):
        ih[a] = 0x70
    if beyond:
        ih[0x90000] = 1
    out = io.StringIO()
    ih.write_hex_file(out)
    return out.getvalue()


# Sweep folders: copies of the session's sweep (manifest.json and sweep.tlog, or everything
# identify and validate wrote) with one thing damaged.

def sweep(edit=None, tlog=None, drop=(), full=False, replace=None):
    def make(dest, session):
        dest.mkdir()
        for p in session.iterdir():
            if full or p.name in ("manifest.json", "sweep.tlog"):
                shutil.copy(p, dest / p.name)
        if edit is not None:
            doc = json.loads((dest / "manifest.json").read_text())
            edit(doc)
            (dest / "manifest.json").write_text(json.dumps(doc))
        if tlog is not None:
            (dest / "sweep.tlog").write_bytes(tlog((dest / "sweep.tlog").read_bytes()))
        for name, content in (replace or {}).items():
            target = dest / name
            target.unlink(missing_ok=True)
            if content is None:
                target.mkdir()
            else:
                target.write_bytes(content.encode() if isinstance(content, str) else content)
        for name in drop:
            (dest / name).unlink()
    return make


def freq(i, **changes):
    def edit(doc):
        for k, v in changes.items():
            if v is None:
                doc["frequencies"][i].pop(k)
            else:
                doc["frequencies"][i][k] = v
    return edit


def top(**changes):
    def edit(doc):
        for k, v in changes.items():
            if v is None:
                doc.pop(k)
            else:
                doc[k] = v
    return edit


def flip(data, at=1000):
    data = bytearray(data)
    data[at] ^= 0x10
    return bytes(data)


# The session sweep's on-board log (board.BIN beside its folder, read from its card), cut,
# flipped or with garbage put in, before its second excitation (so one frequency is left) or
# after its last (both left).

def _records(session) -> list:
    """(offset, type, HQSD's excitation state or None) of each record of the session's log."""
    log = DFReader.DFReader_binary(str(session.parent / "board.BIN"))
    out = []
    while (m := log.recv_msg()) is not None:
        out.append((log.offset - m.fmt.len, m.get_type(), getattr(m, "ESt", None)))
    return out


def _at(records, where) -> int:
    """The offset of an HQSD record: 50 loops into the second excitation (``mid``), or
    10 loops after the last one's last (``tail``); of the first SIDS (``sids``)."""
    if where == "sids":
        return next(o for o, kind, _ in records if kind == "SIDS")
    if where == "mid":
        second = [i for i, (_, kind, _) in enumerate(records) if kind == "SIDS"][1]
        return [o for o, kind, _ in records[second:] if kind == "HQSD"][50]
    last = max(i for i, (_, kind, state) in enumerate(records) if kind == "HQSD" and state)
    return [o for o, kind, _ in records[last:] if kind == "HQSD"][10]


def board_log(where=None, damage=None):
    """The session's .BIN with ``damage`` (``cut``: mid-record, ``flip``: a record's first
    byte, ``garbage``: bytes put in; ``boundary``: cut at a record's start) at ``where``."""
    def make(dest, session):
        data = (session.parent / "board.BIN").read_bytes()
        at = _at(_records(session), where) if where else 0
        if damage == "cut":
            data = data[:at + 9]
        elif damage == "boundary":
            data = data[:at]
        elif damage == "flip":
            data = flip(data, at)
        elif damage == "garbage":
            data = data[:at] + bytes(range(256)) * 4 + data[at:]
        dest.write_bytes(data)
    return make


def board_folder(*names):
    def make(dest, session):
        dest.mkdir()
        for name in names:
            board_log("tail", "flip")(dest / name, session)
    return make


def session_copy(name):
    def make(dest, session):
        shutil.copy(session / name, dest)
    return make


def parent_folder(dest, session):
    """A folder of axis folders (report's other form), one of them damaged."""
    dest.mkdir()
    sweep(full=True)(dest / "roll", session)
    sweep(full=True, replace={"models.json": "7"})(dest / "pitch", session)


def old_run(dest, session):
    """A run ``old`` whose log exists (sil --out old would write old.tlog)."""
    dest.with_suffix(".tlog").write_bytes(b"an earlier run's log")


def folder(dest, session):
    dest.mkdir()


def full_folder(dest, session):
    dest.mkdir()
    (dest / "x").write_text("x")


FILES = {
    "ok.params": b"RATE_RLL_KC 2.5\n",
    # plain damage, any command
    "binary.dat": b"\x00\x01\x02\xff" * 16,
    "empty.dat": b"",
    "nul.dat": b"\x00" * 64,
    "latin1.csv": "omega_rad_s,magnitude,phase_rad\n1,1,caf\xe9\n".encode("latin-1"),
    "adir": folder,
    "full": full_folder,
    # POINTS.csv
    "points.csv": points(),
    "p_header.csv": POINTS_HEADER + "\n",
    "p_nan.csv": points([(1, 1, 0), (2, "nan", -1), (4, 0.5, -1.5)]),
    "p_inf.csv": points([(1, 1, 0), (2, 0.8, "inf"), (4, 0.5, -1.5)]),
    "p_1e999.csv": points([(1, 1, 0), (2, "1e999", -1), (4, 0.5, -1.5)]),
    "p_text.csv": points([(1, 1, 0), (2, "abc", -1), (4, 0.5, -1.5)]),
    "p_hexfloat.csv": points([(1, 1, 0), ("0x10", 0.8, -1), (4, 0.5, -1.5)]),
    "p_short_row.csv": POINTS_HEADER + "\n1,1,0\n2,0.8\n4,0.5,-1.5\n",
    "p_long_row.csv": POINTS_HEADER + "\n1,1,0\n2,0.8,-1,5,6,7\n4,0.5,-1.5\n",
    "p_semicolon.csv": "omega_rad_s;magnitude;phase_rad\n1;1;0\n2;0.8;-1\n",
    "p_missing_col.csv": "omega_rad_s,magnitude\n1,1\n2,0.8\n",
    "p_dup_col.csv": "omega_rad_s,magnitude,phase_rad,omega_rad_s\n1,1,0,1\n2,0.8,-1,2\n",
    "p_nul.csv": POINTS_HEADER + "\n1,1,0\n2,\x00,-1\n",
    "p_longfield.csv": POINTS_HEADER + "\n1,1," + "9" * 200_000 + "\n",
    "p_zero_omega.csv": points([(0, 1, 0)] + GOOD_ROWS[1:]),
    "p_neg_omega.csv": points([(-1, 1, 0)] + GOOD_ROWS[1:]),
    "p_dup_omega.csv": points(GOOD_ROWS[:2] + [GOOD_ROWS[1]] + GOOD_ROWS[2:]),
    "p_decreasing.csv": points(GOOD_ROWS[::-1]),
    "p_tiny_omega.csv": scaled_points(omega_factor=1e-300),
    "p_huge_omega.csv": scaled_points(omega_factor=1e300),
    "p_denormal.csv": points([(5e-324, 1, 0), (1e-323, 0.9, -0.1), (2e-323, 0.8, -0.2)]),
    "p_wide_span.csv": points([(1e-3, 1, 0), (1, 0.8, -1), (1e4, 0.5, -1.5)]),
    "p_near_dup.csv": points([(1, 1, -0.5), (1 + 1e-15, 1, -0.5), (2, 0.8, -1), (4, 0.5, -1.5)]),
    "p_mag_zero.csv": points([(1, 0, 0)] + GOOD_ROWS[1:]),
    "p_mag_db.csv": points([(w, 20 * math.log10(m), p) for w, m, p in GOOD_ROWS]),
    "p_mag_tiny.csv": scaled_points(mag_factor=1e-300),
    "p_mag_huge.csv": scaled_points(mag_factor=1e300),
    "p_phase_huge.csv": points([(1, 1, 1e300)] + GOOD_ROWS[1:]),
    "p_sigma_neg.csv": points([(w, m, p, -0.1) for w, m, p in GOOD_ROWS], POINTS_HEADER + ",sigma"),
    "p_sigma_nan.csv": points([(w, m, p, "nan") for w, m, p in GOOD_ROWS], POINTS_HEADER + ",sigma"),
    "p_coh_2.csv": points([(w, m, p, 2) for w, m, p in GOOD_ROWS], POINTS_HEADER + ",coherence"),
    "p_coh_neg.csv": points([(w, m, p, -1) for w, m, p in GOOD_ROWS], POINTS_HEADER + ",coherence"),
    "p_coh_ru.csv": points([(w, m, p, 0.9, 1.5) for w, m, p in GOOD_ROWS],
                           POINTS_HEADER + ",coherence_ry,coherence_ru"),
    "p_one.csv": points(GOOD_ROWS[:1]),
    "p_four.csv": points(GOOD_ROWS[:4]),
    "p_many.csv": points([(1 + k * 1e-3, 1, 0) for k in range(10_001)]),
    # RUN.csv
    "run.csv": run_csv(),
    "r_header.csv": "t_s,u,y\n",
    "r_two.csv": "t_s,u,y\n0,1,1\n0.005,1,1\n",
    "r_missing_col.csv": "t_s,u\n0,1\n0.005,2\n0.01,3\n",
    "r_nan.csv": run_csv(u=lambda k: float("nan") if k == 7 else math.sin(k / 10)),
    "r_inf.csv": run_csv(y=lambda k: float("inf") if k == 7 else math.sin(k / 10)),
    "r_text.csv": "t_s,u,y\n0,1,1\n0.005,one,1\n0.01,1,1\n",
    "r_backwards.csv": "t_s,u,y\n0,1,1\n0.005,0,1\n0.004,1,1\n0.01,0,1\n",
    "r_nonuniform.csv": run_csv(n=50) + "1,0,0\n",
    "r_constant.csv": run_csv(u=lambda k: 1.0, y=lambda k: 1.0),
    "r_zero.csv": run_csv(u=lambda k: 0.0, y=lambda k: 0.0),
    "r_huge.csv": run_csv(u=lambda k: 1e300 * math.sin(k / 10), y=lambda k: 1e300 * math.sin(k / 10)),
    "r_tiny_dt.csv": run_csv(dt=1e-300),
    "r_huge_t.csv": run_csv(t0=1e300, dt=1e290),
    "r_hours.csv": run_csv(dt=1e4),
    # MODELS.json
    "models.json": "{bad json",
    "m_list.json": "[1, 2, 3]",
    "m_null.json": "null",
    "m_string.json": '"models"',
    "m_truncated.json": models()[:40],
    "m_nested.json": "[" * 100_000 + "]" * 100_000,
    "m_latin1.json": models().replace("roll", "r\xf6ll").encode("latin-1"),
    "m_empty_obj.json": "{}",
    "m_models_empty.json": '{"models": []}',
    "m_models_obj.json": '{"models": {"0": {}}}',
    "m_model_list.json": '{"models": [[28.19], [1, 5.13, 22.93]]}',
    "m_no_den.json": json.dumps({"models": [{"order": [0, 2], "num": [1]}], "axis": "roll"}),
    "m_nan.json": models().replace("28.19", "NaN"),
    "m_infinity.json": models().replace("22.93", "Infinity"),
    "m_1e999.json": models().replace("5.13", "1e999"),
    "m_1e308.json": models({"num": [1e308]}),
    "m_bigint.json": models().replace("28.19", "1" * 400),
    "m_longint.json": models().replace("28.19", "1" * 5000),
    "m_string_coef.json": models({"num": ["28.19"]}),
    "m_bool_coef.json": models({"num": [True]}),
    "m_improper.json": models({"order": [3, 1], "num": [1, 1, 1, 1], "den": [1, 1]}),
    "m_order_mismatch.json": models({"num": [1, 2, 3]}),
    "m_order_13.json": models({"order": [0, 13]}),
    "m_order_text.json": models({"order": "0/2"}),
    "m_order_float.json": models({"order": [0, 2.5]}),
    "m_den_leading0.json": models({"den": [0, 5.13, 22.93]}),
    "m_delay_neg.json": models({"delay_s": -0.1}),
    "m_delay_huge.json": models({"delay_s": 1e6}),
    "m_delay_text.json": models({"delay_s": "0.1"}),
    "m_stable_text.json": models({"stable": "yes"}),
    "m_metrics_text.json": models({"metrics": {"J": "good"}}),
    "m_poles_bad.json": models({"poles": [[1, 2, 3]]}),
    "m_rec_5.json": models(recommended=5),
    "m_rec_text.json": models(recommended="0"),
    "m_rec_neg.json": models(recommended=-1),
    "m_axis_bad.json": models(axis="up"),
    "m_axis_none.json": json.dumps({"models": [MODEL], "recommended": 0}),
    "m_log_bad.json": models(log={"skipped_bytes": "many"}),
    "m_skipped_bad.json": models(skipped_frequencies=[1, 2]),
    "m_fast_pole.json": models({"den": [1.0, 1e8, 1e9]}),
    "m_fast_zero.json": models({"order": [1, 2], "num": [1, 1e8], "den": [1.0, 5.13, 22.93]}),
    "m_huge_gain.json": models({"num": [1e20]}),
    "m_tiny_gain.json": models({"num": [1e-20]}),
    "m_wide_coef.json": models({"order": [0, 12], "num": [1.0],
                                "den": [1.0] + [10.0 ** (4 * k) for k in range(1, 13)]}),
    # tune's MODELS.json: with a band, none recommended, the recommended one unstable
    "t_good.json": models(band_rad_s=[1.0, 20.0]),
    "t_no_rec.json": models(band_rad_s=[1.0, 20.0], recommended=None),
    "t_unstable.json": models({"den": [1.0, -5.13, 22.93], "stable": False,
                               "poles": [[2.565, 3.99], [2.565, -3.99]]}, band_rad_s=[1.0, 20.0]),
    # gains files (with a good MODELS.json)
    "good_models.json": models(),
    "g_list.json": "[2.4, 0.44, 0.05]",
    "g_empty_obj.json": "{}",
    "g_no_rate.json": gains(rate=None),
    "g_rate_short.json": gains(rate_roll=[2.4, 0.44]),
    "g_rate_neg.json": gains(rate_roll=[-2.4, 0.44, 0.05]),
    "g_rate_zero_kc.json": gains(rate_roll=[0, 0.44, 0.05]),
    "g_rate_nan.json": gains(rate_roll=[2.4, 0.44, 0.05]).replace("0.44", "NaN", 1),
    "g_rate_text.json": gains(rate_roll=["2.4", 0.44, 0.05]),
    "g_rate_huge.json": gains(rate_roll=[1e300, 0.44, 0.05]),
    "g_rate_obj.json": gains(rate_roll={"Kc": 2.4}),
    "g_no_roll.json": gains(rate_roll=None),
    "g_no_angle.json": gains(angle=None),
    "g_angle_long.json": gains(angle_roll=[1.5, 0.1, 0.2]),
    "g_angle_yaw.json": gains(angle_yaw=[1.5, 0.1]),
    "g_typo.json": json.dumps({"rates": GAINS["rate"], "angle": GAINS["angle"]}),
    "g_axis_typo.json": gains(rate_rol=[2.4, 0.44, 0.05]),
    # vehicle parameter files (TOML)
    "t_bad.toml": "[body\nmass_kg = 1\n",
    # RC scripts (sim/rig/rc_script.py)
    "rc_bad_time.rc": "0.5 5=2000\nsoon 3=1400\n",
    "rc_bad_channel.rc": "0.5 9=2000\n",
    "rc_bad_pulse.rc": "0.5 5=5000\n",
    "rc_comments.rc": "# nothing but a comment\n",
    "rc_ok.rc": "0.5 5=2000\n1 3=1400\n",
    "t_nul.toml": "[body]\nmass_kg = \x00\n",
    "t_latin1.toml": VEHICLE.replace("# heliquad", "# h\xe9liquad").encode("latin-1"),
    "t_no_section.toml": VEHICLE.replace("[rig]", "[rig_]"),
    "t_section_value.toml": "body = 5\n" + VEHICLE[VEHICLE.index("\n[[rotors]]") + 1:],
    "t_missing_key.toml": vehicle("mass_kg", ""),
    "t_unit_key.toml": vehicle("mass_kg", "mass_g = 930"),
    "t_newline_key.toml": vehicle("mass_kg", 'mass_kg = 0.93\n"a\\nb" = 1'),
    "t_extra_section.toml": VEHICLE + "\n[battery]\ncells = 4\n",
    "t_nan.toml": vehicle("mass_kg", "mass_kg = nan"),
    "t_inf.toml": vehicle("mass_kg", "mass_kg = inf"),
    "t_negative.toml": vehicle("mass_kg", "mass_kg = -0.93"),
    "t_huge.toml": vehicle("mass_kg", "mass_kg = 1e300"),
    "t_bigint.toml": vehicle("mass_kg", "mass_kg = " + "9" * 400),
    "t_text.toml": vehicle("mass_kg", 'mass_kg = "heavy"'),
    "t_bool.toml": vehicle("mass_kg", "mass_kg = true"),
    "t_inertia_zero.toml": vehicle("inertia_kg_m2", "inertia_kg_m2 = [0.0118, 0, 0.0226]"),
    "t_inertia_short.toml": vehicle("inertia_kg_m2", "inertia_kg_m2 = [0.0118, 0.0118]"),
    "t_spin.toml": rotor(1, "spin", "spin = 2"),
    "t_spin0.toml": rotor(5, "spin", "spin = 0"),
    "t_rotor_missing.toml": rotor(3, "max_speed_rad_s", ""),
    "t_rotor_unknown.toml": rotor(2, "max_thrust_n", "max_thrust_n = 9.0\nmax_thrust_kg = 0.9"),
    "t_rotor_same_place.toml": rotor(4, "position_m", "position_m = [0.3048, 0.0, 0.0]"),
    "t_rotor_zero_thrust.toml": rotor(3, "max_thrust_n", "max_thrust_n = 0"),
    "t_rotor_negative_thrust.toml": rotor(5, "max_thrust_n", "max_thrust_n = -9.0"),
    "t_axis_long.toml": rotor(1, "thrust_axis", "thrust_axis = [0.0, 0.0, -2.0]"),
    "t_axis_zero.toml": rotor(2, "thrust_axis", "thrust_axis = [0.0, 0.0, 0.0]"),
    "t_axis_short.toml": rotor(2, "thrust_axis", "thrust_axis = [0.0, 0.34, 0.90]"),
    "t_axis_text.toml": rotor(2, "thrust_axis", 'thrust_axis = "up"'),
    "t_rotors_9.toml": rotors(9),
    "t_rotors_1.toml": rotors(1),
    "t_rotors_0.toml": rotors(0),
    "t_rotors_table.toml": rotors(1).replace("[[rotors]]", "[rotors]"),
    "t_rotors_six.toml": (pathlib.Path(__file__).resolve().parent / "data" / "six_rotors.toml").read_text(),
    "t_rotors_3.toml": rotors(3),
    "t_heavy.toml": vehicle("mass_kg", "mass_kg = 9.3"),
    "t_latency_float.toml": vehicle("dmp_latency_samples", "dmp_latency_samples = 1.5"),
    "t_latency_huge.toml": vehicle("dmp_latency_samples", "dmp_latency_samples = 9000000000000"),
    "t_bias.toml": vehicle("gyro_bias_deg_s", "gyro_bias_deg_s = [0.2, -1e9, 0.1]"),
    "t_fast_rotor.toml": rotor(2, "time_constant_s", "time_constant_s = 0.0005"),
    "t_friction.toml": vehicle("hinge_friction_n_m", "hinge_friction_n_m = 1.0"),
    "t_rotor_momentum.toml": vehicle("rotor_inertia_kg_m2 = 4.6e-4", "rotor_inertia_kg_m2 = 90.0"),
    # sweep folders (identify reads manifest.json and sweep.tlog; report everything)
    "s_no_manifest": sweep(drop=("manifest.json",)),
    "s_manifest_dir": sweep(replace={"manifest.json": None}),
    "s_manifest_empty": sweep(replace={"manifest.json": ""}),
    "s_manifest_binary": sweep(replace={"manifest.json": b"\xff\xfe\x00manifest"}),
    "s_manifest_list": sweep(replace={"manifest.json": "[]"}),
    "s_manifest_cut": sweep(replace={"manifest.json": '{"axis": "roll", "inject": "mix'}),
    "s_no_axis": sweep(top(axis=None)),
    "s_axis_bad": sweep(top(axis="sideways")),
    "s_axis_number": sweep(top(axis=0)),
    "s_inject_bad": sweep(top(inject="motor")),
    "s_yaw_angle": sweep(top(axis="yaw", inject="angle")),
    "s_no_freqs": sweep(top(frequencies=None)),
    "s_freqs_obj": sweep(top(frequencies={"1": {}})),
    "s_freq_text": sweep(freq(0, requested_hz="2")),
    "s_freq_negative": sweep(freq(0, requested_hz=-2.0)),
    "s_freq_nan": sweep(freq(0, freq_hz=float("nan"))),
    "s_freq_inf": sweep(freq(0, freq_hz=float("inf"))),
    "s_ok_no_freq_hz": sweep(freq(0, freq_hz=None)),
    "s_ok_no_window": sweep(freq(1, start_us=None)),
    "s_period_zero": sweep(freq(0, period_samples=0)),
    "s_period_float": sweep(freq(0, period_samples=100.5)),
    "s_period_huge": sweep(freq(0, period_samples=10**9)),
    "s_window_backwards": sweep(freq(0, start_us=9_000_000, end_us=1_000_000)),
    "s_start_huge": sweep(freq(0, start_us=10**30)),
    "s_start_negative": sweep(freq(0, start_us=-5)),
    "s_samples_negative": sweep(freq(0, samples=-1)),
    "s_status_number": sweep(freq(0, status=1)),
    "s_messages_bad": sweep(freq(0, messages="oops")),
    "s_signal_bad": sweep(top(signal="square")),
    "s_ms_no_orders": sweep(freq(0, signal="multisine")),
    "s_ms_orders_down": sweep(freq(0, signal="multisine", orders=[9, 3])),
    "s_ms_orders_high": sweep(freq(0, signal="multisine", orders=[3, 10**6])),
    "s_ms_orders_text": sweep(freq(0, signal="multisine", orders="3 5")),
    "s_tlog_parent": sweep(top(tlog="../sweep.tlog")),
    "s_tlog_absolute": sweep(top(tlog="/etc/passwd")),
    "s_tlog_number": sweep(top(tlog=5)),
    "s_aborted_number": sweep(top(aborted=3)),
    "s_complete_text": sweep(top(complete="yes")),
    "s_limits_text": sweep(top(limits={"max_angle_deg": "80"})),
    "s_other_axis": sweep(top(axis="pitch")),
    "s_no_tlog": sweep(drop=("sweep.tlog",)),
    "s_tlog_dir": sweep(replace={"sweep.tlog": None}),
    "s_tlog_empty": sweep(tlog=lambda d: b""),
    "s_tlog_garbage": sweep(tlog=lambda d: bytes(range(256)) * 64),
    "s_tlog_head": sweep(tlog=lambda d: d[:100]),
    "s_tlog_two_thirds": sweep(tlog=lambda d: d[:len(d) * 2 // 3]),
    "s_tlog_flipped": sweep(tlog=flip),
    # identified sweep folders (report)
    "f_models_list": sweep(full=True, replace={"models.json": "[]"}),
    "f_models_bad_num": sweep(full=True, replace={"models.json": models({"num": "x"})}),
    "f_models_cut": sweep(full=True, replace={"models.json": models()[:30]}),
    "f_models_dir": sweep(full=True, replace={"models.json": None}),
    "f_models_replay": sweep(full=True, replace={"models.json": models(replay={
        "model": 0, "points": [{"freq_hz": 1.0, "periods": 8, "nrmse": -0.1}]})}),
    "f_models_truth": sweep(full=True, replace={"models.json": models(sil_truth={
        "points": [{"freq_hz": 1.0, "error_over_sigma": "far"}], "points_worst_db": 0.1,
        "points_worst_deg": 1.0})}),
    "f_points_ry": sweep(full=True, replace={
        "points.csv": "omega_rad_s,magnitude,phase_rad,coherence_ry\n12.57,0.18,-2.7,1.2\n"}),
    "f_manifest_bad": sweep(top(frequencies=[{"requested_hz": "2"}]), full=True),
    "f_validation_list": sweep(full=True, replace={"validation.json": "[]"}),
    "f_validation_no_stable": sweep(full=True, replace={"validation.json": '{"loops": {}}'}),
    "f_validation_no_step": sweep(full=True, replace={"validation.json": '{"loops": {}, "stable": true}'}),
    "f_validation_loops_text": sweep(full=True, replace={"validation.json": '{"loops": "x", "stable": false}'}),
    "f_validation_binary": sweep(full=True, replace={"validation.json": b"\x89PNG\r\n"}),
    "f_validation_measured": sweep(full=True, replace={"validation.json": json.dumps({
        "loops": {}, "stable": False, "measured_loop": {
            "loop": "input", "injection": "mixer",
            "points": [{"freq_hz": "one", "magnitude_db": 3.0, "phase_deg": -120.0}]}})}),
    "f_validation_truth": sweep(full=True, replace={"validation.json": json.dumps({
        "loops": {}, "stable": False,
        "truth_loops": {"rate": {"gain_crossovers": [{"in_band": True}]}}})}),
    "f_table_text": sweep(full=True, replace={"points_table.csv": "not,a\ntable\n"}),
    "f_table_coherence": sweep(full=True, replace={
        "points_table.csv": "freq_hz,omega_rad_s,magnitude,phase_deg,real,imag,coherence\n"
                            "2,12.57,0.18,-156,-0.17,-0.07,2.5\n"}),
    "f_table_nan": sweep(full=True, replace={
        "points_table.csv": "freq_hz,omega_rad_s,magnitude,phase_deg,real,imag,coherence\n"
                            "nan,12.57,0.18,-156,-0.17,-0.07,0.9\n"}),
    "f_table_dir": sweep(full=True, replace={"points_table.csv": None}),
    "f_parent": parent_folder,
    "session_models.json": session_copy("models.json"),
    # logs
    "text.tlog": "this is not a telemetry log\n",
    "json.tlog": models(),
    "cut.tlog": lambda dest, session: dest.write_bytes((session / "sweep.tlog").read_bytes()[:7]),
    "flipped.tlog": lambda dest, session: dest.write_bytes(flip((session / "sweep.tlog").read_bytes())),
    "old.tlog": b"an earlier flight \x00\x01\x02" * 50,
    "old": old_run,
    # on-board logs
    "b_cut_tail.BIN": board_log("tail", "cut"),
    "b_flip_tail.BIN": board_log("tail", "flip"),
    "b_garbage_tail.BIN": board_log("tail", "garbage"),
    "b_cut_mid.BIN": board_log("mid", "cut"),
    "b_flip_mid.BIN": board_log("mid", "flip"),
    "b_garbage_mid.BIN": board_log("mid", "garbage"),
    "b_no_excitation.BIN": board_log("sids", "boundary"),
    "b_header.BIN": lambda dest, session: dest.write_bytes(
        (session.parent / "board.BIN").read_bytes()[:300]),
    "text.BIN": "this is not an on-board log\n",
    "empty.BIN": b"",
    "b_folder": board_folder("00000001.BIN"),
    "b_two": board_folder("00000001.BIN", "00000002.BIN"),
    # DMP firmware sources and files
    "syntax.py": "dmpMemory = [1, 2,\n",
    "call.py": "dmpMemory = bytes(1929)\ndmpConfig = [0] * 192\ndmpUpdates = [0] * 47\n",
    "short.py": "dmpMemory = [" + "0, " * 10 + "]\n",
    "big_values.py": "dmpMemory = [" + "256, " * 1929 + "]\n",
    "nothing.py": "x = 1\n",
    "latin1.py": "# caf\xe9\ndmpMemory = []\n".encode("latin-1"),
    "fake.whl": b"PK\x03\x04 not really a zip",
    "bare.bin": bytes(1929),
    "short.bin": b"HQDM\x01\x00",
    "crc.bin": b"HQDM\x01\x00\x01\x00\x03\x00\x03\x00\x00\x00\x00\x00" + b"\x00" * 7,
    "old.bin": b"earlier dmp file",
    # flash images
    "ok.hex": hex_image(),
    "secured.hex": hex_image(fsec=0x00),
    "bad_sp.hex": hex_image(sp=0x1234),
    "bad_reset.hex": hex_image(reset=0x410),
    "beyond.hex": hex_image(beyond=True),
    "checksum.hex": hex_image().replace(":00000001FF", ":00000001FE"),
    "text.hex": "hello, board\n",
    # study specs: a good one (refused only for its options), and bad ones
    "study.toml": '[factors]\naxis = ["roll"]\nseed = [1, 2]\n',
    "study_unknown.toml": '[factors]\naxis = ["roll"]\nwind = [1, 2]\n',
    "study_empty.toml": '[factors]\naxis = ["roll"]\nseed = []\n',
    "study_lines.toml": '[factors]\naxis = ["roll"]\nlines = [1]\n[sweep]\nsignal = "multisine"\n',
    "study_out.toml": '[factors]\naxis = ["roll"]\nout = ["elsewhere"]\n',
    "study_table.toml": '[factors]\naxis = ["roll"]\n[wind]\nspeed = 3\n',
    "study_plan.toml": '[factors]\naxis = ["yaw"]\n[sweep]\nsignal = "multisine"\nrig-time = 12\n',
    "study_seed.toml": '[factors]\naxis = ["roll"]\nseed = {first = 1}\n',
}


# --- the cases ------------------------------------------------------------------------------

def case(args, says="", code=2):
    """``args`` to heliquad; ``says``: words the one line must hold; ``code``: exit code."""
    return pytest.param(args, says, code, id=args)


SIL = "sil --freq-hz 1 --amplitude 0.05"
VALIDATE = "validate good_models.json --axis roll"

CASES = [
    # fsf: damaged, empty and binary RUN.csv files, folders, numbers out of range
    case("fsf binary.dat --out p.csv", "not UTF-8"),
    case("fsf missing.csv --out p.csv", "no such file"),
    case("fsf adir --out p.csv", "is a folder"),
    case("fsf empty.dat --out p.csv", "empty file"),
    case("fsf nul.dat --out p.csv", "nul.dat"),
    case("fsf r_header.csv --out p.csv", "no data rows"),
    case("fsf r_two.csv --out p.csv", "only 2 samples"),
    case("fsf r_missing_col.csv --out p.csv", "missing column"),
    case("fsf r_nan.csv --out p.csv", "column u has NaN"),
    case("fsf r_inf.csv --out p.csv", "column y has NaN or infinity"),
    case("fsf r_text.csv --out p.csv", "one"),
    case("fsf r_backwards.csv --out p.csv", "does not increase"),
    case("fsf r_nonuniform.csv --out p.csv", "not uniformly sampled"),
    case("fsf r_constant.csv --out p.csv", "constant"),
    case("fsf r_zero.csv --out p.csv", "r_zero.csv"),
    case("fsf r_huge.csv --out p.csv", "data row 2"),
    case("fsf r_tiny_dt.csv --out p.csv", "sampling rate"),
    case("fsf r_huge_t.csv --out p.csv", "t_s"),
    case("fsf r_hours.csv --out p.csv", "sampling rate"),
    case("fsf points.csv --out p.csv", "missing column"),
    case("fsf latin1.csv --out p.csv", "not UTF-8"),
    case("fsf run.csv --freq-hz 0 --out p.csv", "--freq-hz"),
    case("fsf run.csv --freq-hz nan --out p.csv", "--freq-hz"),
    case("fsf run.csv --freq-hz -1 --out p.csv", "--freq-hz"),
    case("fsf run.csv --freq-hz 150 --out p.csv", "Nyquist"),
    case("fsf run.csv --freq-hz 1 --freq-hz 2 --freq-hz 3 --out p.csv", "--freq-hz given 3 times"),
    case("fsf run.csv --harmonics 0 --out p.csv", "harmonics"),
    case("fsf run.csv --harmonics 999 --out p.csv", "harmonics"),
    case("fsf run.csv --discard-periods -1 --out p.csv", "discard"),
    case("fsf run.csv --discard-periods 100000 --out p.csv", "periods"),
    case("fsf run.csv --discard-periods 1e9 --out p.csv", "--discard-periods"),
    case("fsf run.csv run.csv --out p.csv", "both at"),
    case("fsf run.csv --orders 1 2 --out p.csv", "--orders needs --freq-hz"),
    case("fsf run.csv --freq-hz 1 --orders 2 1 --out p.csv", "strictly increasing"),
    case("fsf run.csv --freq-hz 1 --orders 1 3 --harmonics 2 --out p.csv", "--harmonics is for sine"),
    case("fsf run.csv --freq-hz 0.3 --orders 1 2 --out p.csv", "not a whole number"),
    case("fsf run.csv --freq-hz 1 --orders 0 --out p.csv", "--orders"),
    case("fsf run.csv --freq-hz 1 --orders 60 --out p.csv", "4 per cycle"),
    case("fsf run.csv --freq-hz 1 --orders 1 2 --out p.csv", "exact base frequency"),
    case("fsf run.csv --freq-hz 1 --orders 1 2 --discard-periods 5 --out p.csv", "too short"),
    case("fsf run.csv --out adir", "adir"),
    case("fsf run.csv --out binary.dat/p.csv", "binary.dat/p.csv"),
    case("fsf run.csv --out /proc/p.csv", "/proc/p.csv"),
    case("fsf r_nan.csv --out points.csv", "column u has NaN"),
    case("fsf run.csv", "--out"),
    case("fsf --out p.csv", "RUN.csv"),
    # fit: damaged POINTS.csv, extreme omegas and magnitudes, orders, unwritable outputs
    case("fit binary.dat --order 0/2 --json m.json", "not UTF-8"),
    case("fit missing.csv --json m.json", "no such file"),
    case("fit adir --json m.json", "is a folder"),
    case("fit empty.dat --json m.json", "empty file"),
    case("fit nul.dat --json m.json", "nul.dat"),
    case("fit latin1.csv --json m.json", "not UTF-8"),
    case("fit p_header.csv --json m.json", "no data rows"),
    case("fit p_nan.csv --json m.json", "NaN"),
    case("fit p_inf.csv --json m.json", "NaN or infinity"),
    case("fit p_1e999.csv --json m.json", "NaN or infinity"),
    case("fit p_text.csv --json m.json", "abc"),
    case("fit p_hexfloat.csv --json m.json", "0x10"),
    case("fit p_short_row.csv --json m.json", "data row 2 has 2 fields"),
    case("fit p_long_row.csv --json m.json", "data row 2 has 6 fields"),
    case("fit p_semicolon.csv --json m.json", "missing column"),
    case("fit p_missing_col.csv --json m.json", "phase_rad"),
    case("fit p_dup_col.csv --json m.json", "appears twice"),
    case("fit p_nul.csv --json m.json", "p_nul.csv"),
    case("fit p_longfield.csv --json m.json", "p_longfield.csv"),
    case("fit p_zero_omega.csv --json m.json", "omega_rad_s"),
    case("fit p_neg_omega.csv --json m.json", "omega_rad_s"),
    case("fit p_dup_omega.csv --json m.json", "does not increase at data row 3"),
    case("fit p_decreasing.csv --json m.json", "does not increase"),
    case("fit p_tiny_omega.csv --json m.json", "omega_rad_s at data row 1"),
    case("fit p_huge_omega.csv --json m.json", "omega_rad_s at data row 1"),
    case("fit p_denormal.csv --json m.json", "omega_rad_s at data row 1"),
    case("fit p_wide_span.csv --json m.json", "decades"),
    case("fit p_mag_zero.csv --json m.json", "magnitude at data row 1"),
    case("fit p_mag_db.csv --json m.json", "not dB"),
    case("fit p_mag_tiny.csv --json m.json", "magnitude"),
    case("fit p_mag_huge.csv --json m.json", "magnitude"),
    case("fit p_phase_huge.csv --json m.json", "phase_rad"),
    case("fit p_sigma_neg.csv --json m.json", "sigma"),
    case("fit p_sigma_nan.csv --json m.json", "sigma"),
    case("fit p_coh_2.csv --json m.json", "coherence"),
    case("fit p_coh_neg.csv --json m.json", "coherence"),
    case("fit p_coh_ru.csv --json m.json --plot b.png", "coherence_ru at data row 1"),
    case("fit p_one.csv --json m.json", "too few"),
    case("fit p_many.csv --json m.json", "at most"),
    case("fit points.csv --order x --json m.json", "form M/N"),
    case("fit points.csv --order 0/40 --json m.json", "above 12"),
    case("fit points.csv --order 0/0 --json m.json", "at least 1"),
    case("fit points.csv --order 3/2 --json m.json", "improper"),
    case("fit points.csv --order -1/2 --json m.json", "--order"),
    case("fit p_four.csv --order 2/4 --delay --json m.json", "needs at least 5 points"),
    case("fit points.csv --weights sigma --json m.json", "no sigma column"),
    case("fit points.csv --weights coherence --json m.json", "no coherence column"),
    case("fit points.csv --weights magic --json m.json", "--weights"),
    case("fit p_nan.csv --json good_models.json", "NaN"),
    case("fit points.csv --json good_models.json --plot binary.dat/b.png", "binary.dat/b.png"),
    case("fit points.csv", "--json"),
    case("fit points.csv --json adir", "adir"),
    case("fit points.csv --json binary.dat/m.json", "binary.dat/m.json"),
    case("fit points.csv --json /proc/m.json", "/proc/m.json"),
    case("fit points.csv --json m.json --mat binary.dat/m.mat", "binary.dat/m.mat"),
    case("fit points.csv --json m.json --plot binary.dat/b.png", "binary.dat/b.png"),
    case("fit points.csv --json m.json --plot adir", "adir"),
    case("fit points.csv --order 0/2 --json m.json --plot b.xyz", ".xyz is not an image format"),
    case("fit points.csv --json m.json --mat m.mat --plot b.png.txt", ".txt is not an image"),
    # sil: numbers out of range or not finite, absurd plants, damaged vehicle files, outputs
    case(f"{SIL.replace('1 ', '1e-9 ', 1)} --out o", "excitation band"),
    case("sil --freq-hz nan --amplitude 0.05 --out o", "--freq-hz"),
    case("sil --freq-hz inf --amplitude 0.05 --out o", "--freq-hz"),
    case("sil --freq-hz -1 --amplitude 0.05 --out o", "--freq-hz"),
    case("sil --freq-hz 60 --amplitude 0.05 --out o", "excitation band"),
    case("sil --freq-hz one --amplitude 0.05 --out o", "--freq-hz"),
    case("sil --freq-hz 1 --amplitude nan --out o", "--amplitude"),
    case("sil --freq-hz 1 --amplitude -1 --out o", "--amplitude"),
    case("sil --freq-hz 1 --amplitude 0 --out o", "--amplitude"),
    case("sil --freq-hz 1 --amplitude 5 --out o", "--amplitude"),
    case("sil --freq-hz 1 --amplitude 500 --inject rate --out o", "--amplitude"),
    case(f"{SIL} --cycles 0 --out o", "--cycles"),
    case(f"{SIL} --cycles 70000 --out o", "--cycles"),
    case("sil --freq-hz 0.06 --amplitude 0.05 --cycles 100 --out o", "fewer --cycles"),
    case(f"{SIL} --cycles 1.5 --out o", "--cycles"),
    case(f"{SIL} --fade-cycles 0 --out o", "--fade-cycles"),
    case(f"{SIL} --seed -1 --plant vehicle --out o", "--seed"),
    case(f"{SIL} --seed 99999999999 --out o", "--seed"),
    case(f"{SIL} --num nan --out o", "--num"),
    case(f"{SIL} --num 1 --den inf 1 --out o", "--den"),
    case(f"{SIL} --num 1 --den 0 0 --out o", "leading coefficient"),
    case(f"{SIL} --num 1 --den 0 1 --out o", "leading coefficient of the denominator"),
    case(f"{SIL} --num 0 1 --den 1 1 --out o", "leading coefficient of the numerator"),
    case(f"{SIL} --num 0 --den 1 1 --out o", "numerator is zero"),
    case(f"{SIL} --num 1 2 3 --den 1 1 --out o", "not proper"),
    case(f"{SIL} --num 1 --den 1 --out o", "degree 1"),
    case(f"{SIL} --num 1 --den 1 1 1 1 1 1 1 1 1 1 1 1 1 1 --out o", "degree 1 to 12"),
    case(f"{SIL} --num 1 --den 1e-300 1 --out o", "beyond"),
    case(f"{SIL} --num 1 --den 1 1e300 --out o", "beyond"),
    # a negative number in exponent form is a value, not an unknown option
    case(f"{SIL} --num 1 --den 1 -1e5 --out o", "a pole at 1e+05 rad/s is faster"),
    case(f"{SIL} --num 1e200 --den 1e-200 1 --out o", "beyond"),
    case(f"{SIL} --num 1e300 --den 1 5 --out o", "beyond"),
    case(f"{SIL} --num 1e10 --den 1 5 --out o", "gain"),
    case(f"{SIL} --num 1 --den 1 -3000 --out o", "Nyquist"),
    case(f"{SIL} --num 1e-300 --den 1 5 --out o", "gain"),
    case(f"{SIL} --num 1 --den 1 2000 --out o", "Nyquist"),
    case(f"{SIL} --num 1 --den 1 0 1000000 --out o", "Nyquist"),
    case(f"{SIL} --loop-hz 1 --out o", "Nyquist"),
    case(f"{SIL} --loop-hz 0 --out o", "--loop-hz"),
    case(f"{SIL} --loop-hz 3000 --out o", "--loop-hz"),
    case(f"{SIL} --collective 5 --out o", "--collective"),
    case(f"{SIL} --collective -0.1 --out o", "--collective"),
    case(f"{SIL} --params models.json --plant vehicle --out o", "not valid TOML"),
    case(f"{SIL} --params binary.dat --plant vehicle --out o", "not UTF-8 text"),
    case(f"{SIL} --params missing.toml --plant vehicle --out o", "missing.toml"),
    case(f"{SIL} --params adir --plant vehicle --out o", "adir"),
    case(f"{SIL} --params empty.dat --plant vehicle --out o", "empty file"),
    case(f"{SIL} --params t_bad.toml --plant vehicle --out o", "not valid TOML"),
    case(f"{SIL} --params t_nul.toml --plant vehicle --out o", "not valid TOML"),
    case(f"{SIL} --params t_latin1.toml --plant vehicle --out o", "not UTF-8 text"),
    case(f"{SIL} --params t_nan.toml --plant vehicle --out o", "body.mass_kg"),
    case(f"{SIL} --params t_huge.toml --plant vehicle --out o", "body.mass_kg"),
    case(f"{SIL} --params t_bigint.toml --plant vehicle --out o", "body.mass_kg"),
    case(f"{SIL} --params t_fast_rotor.toml --plant vehicle --out o", "fastest mode"),
    case(f"{SIL} --params t_friction.toml --plant vehicle --out o", "fastest mode"),
    case(f"{SIL} --params t_spin0.toml --plant vehicle --out o", "rotors[5].spin must be 1 or -1"),
    case(f"{SIL} --params t_rotor_missing.toml --plant vehicle --out o",
         "missing key rotors[3].max_speed_rad_s"),
    case(f"{SIL} --params t_rotor_unknown.toml --plant vehicle --out o",
         "unknown key rotors[2].max_thrust_kg (expected rotors[2].max_thrust_n"),
    case(f"{SIL} --params t_rotor_same_place.toml --plant vehicle --out o",
         "rotors[4].position_m is rotors[2]'s"),
    case(f"{SIL} --params t_rotor_zero_thrust.toml --plant vehicle --out o",
         "rotors[3].max_thrust_n must be positive"),
    case(f"{SIL} --params t_rotor_negative_thrust.toml --plant vehicle --out o",
         "rotors[5].max_thrust_n must be positive"),
    case(f"{SIL} --params t_axis_long.toml --plant vehicle --out o",
         "rotors[1].thrust_axis must be a unit vector"),
    case(f"{SIL} --params t_axis_zero.toml --plant vehicle --out o",
         "rotors[2].thrust_axis must be a unit vector"),
    case(f"{SIL} --params t_axis_short.toml --plant vehicle --out o", "got length 0.962"),
    case(f"{SIL} --params t_axis_text.toml --plant vehicle --out o", "rotors[2].thrust_axis"),
    case(f"{SIL} --params t_rotors_9.toml --plant vehicle --out o", "2 to 8 rotors"),
    case(f"{SIL} --params t_rotors_1.toml --plant vehicle --out o", "2 to 8 rotors"),
    case(f"{SIL} --params t_rotors_0.toml --plant vehicle --out o", "missing the rotors"),
    case(f"{SIL} --params t_rotors_table.toml --plant vehicle --out o",
         "rotors must be [[rotors]] tables"),
    case(f"{SIL} --params t_rotors_3.toml --plant vehicle --out o",
         "the firmware's allocation flies 4 to 8 rotors"),
    case(f"{SIL} --params t_heavy.toml --plant vehicle --out o",
         "the firmware cannot fly this geometry (allocation: hover needs rotor"),
    case(f"{SIL} --plant vehicle --loop-hz 1 --out o", "fastest mode"),
    case(f"{SIL} --plant vehicle --rig pitch --out o", "only pitch is free"),
    case(f"{SIL} --turbulence light --out o", "--plant vehicle"),
    case(f"{SIL} --out no/such/folder/run", "does not exist"),
    case(f"{SIL} --out binary.dat/run", "does not exist"),
    case(f"{SIL} --fault bogus@1 --out o", "bogus"),
    case(f"{SIL} --fault silent@-1 --out o", "silent@-1"),
    case(f"{SIL} --fault nack@1:nan --out o", "nack@1:nan"),
    case(f"{SIL} --fault reset@inf --out o", "reset@inf"),
    case(f"{SIL} --axis yaw --inject angle --out o", "rate-only"),
    case(f"{SIL} --firmware bogus --out o", "--firmware"),
    case(f"{SIL} --axis sideways --out o", "--axis"),
    case(SIL, "--out"),
    # sil that starts the firmware: an existing log is never written over
    case(f"{SIL} --out old", "exists"),
    # board: absurd plants, numbers, a telemetry path that exists
    case("board --telemetry t --param-store adir", "adir is a folder, not a parameter store"),
    case("board --telemetry t --param-store nodir/p.bin", "nodir does not exist"),
    case(f"{SIL} --out o --param-store adir", "adir is a folder"),
    case(f"{SIL} --out o --rc-script rc_bad_time.rc", "line 2: 'soon' is not a time"),
    case(f"{SIL} --out o --rc-script rc_comments.rc", "no changes"),
    case(f"{SIL} --out o --rc-script binary.dat", "not UTF-8 text"),
    case(f"{SIL} --out o --rc-script adir", "is a folder"),
    case(f"{SIL} --out o --rc-script empty.dat", "empty file"),
    case("board --telemetry t --rc-script rc_bad_channel.rc", "channel 9 is not one of 1-8"),
    case("board --telemetry t --rc-script rc_bad_pulse.rc", "pulse 5000 us is outside"),
    case("board --telemetry t --rc-script missing.rc", "missing.rc: no such file"),
    case("sweep --sil --axis roll --rc-script nul.dat --out s", "nul.dat"),
    case("sweep --axis roll --port /dev/null --rc-script rc_comments.rc --out s", "no changes"),
    case("sweep --axis roll --port /dev/null --rc-script rc_ok.rc --out s",
         "--rc-script needs --sil"),
    case("board --telemetry t --rc-script rc_ok.rc --disarmed", "leave out --disarmed"),
    case("sweep --axis roll --port /dev/null --param-store p.bin --out o", "--param-store needs --sil"),
    case("board --telemetry t --duration-s -1", "--duration-s"),
    case("board --telemetry t --duration-s nan", "--duration-s"),
    case("board --telemetry t --duration-s 0", "--duration-s"),
    case("board --telemetry t --collective 2", "--collective"),
    case("board --telemetry t --loop-hz 0", "--loop-hz"),
    case("board --telemetry t --num 1 --den 0 1", "leading coefficient"),
    case("board --telemetry t --num 1 2 3 --den 1 1", "not proper"),
    case("board --telemetry t --num 1 --den 1 5000", "Nyquist"),
    case("board --telemetry t --num 1e10 --den 1 5", "gain"),
    case("board --telemetry t --num inf", "--num"),
    case("board --telemetry t --plant bogus", "--plant"),
    case("board --telemetry t --plant vehicle --rig pitch", "only pitch is free"),
    case("board --telemetry t --turbulence light", "need --plant vehicle"),
    case("board --telemetry t --plant vehicle --params t_nan.toml", "body.mass_kg"),
    case("board --telemetry t --num 0 1 --den 1 1", "leading coefficient of the numerator"),
    case("board --telemetry t --num 1 --den 1 1 1 1 1 1 1 1 1 1 1 1 1 1", "degree 1 to 12"),
    case("board --telemetry t --loop-hz 1", "Nyquist"),
    case("board --telemetry binary.dat --duration-s 1", "exists"),
    case("board --telemetry t --sd-image adir", "--sd-image: adir is a folder, not a card image"),
    case("board --telemetry t --sd-image nowhere/card.img", "does not exist"),
    case("board --telemetry t --sd-faults no_card", "--sd-faults needs --sd-image"),
    case("board --telemetry t --sd-image c.img --sd-faults frobnicate", "no card fault 'frobnicate'"),
    case("board --telemetry t --sd-image c.img --sd-faults busy_for_us=x", "not NAME or NAME=N"),
    case("board --telemetry t --sd-image c.img --sd-faults ,no_card", "not NAME or NAME=N"),
    case("board --telemetry t --sd-image c.img --sd-faults no_card --firmware teensy35",
         "only the host firmware"),
    case(f"{SIL} --sd-image adir --out o", "is a folder, not a card image"),
    case(f"{SIL} --sd-faults write_protected --out o", "--sd-faults needs --sd-image"),
    case("sweep --axis roll --port /dev/null --sd-image c.img --out s", "need --sil"),
    case("sweep --axis roll --port /dev/null --sd-faults no_card --out s", "need --sil"),
    case("sweep --sil --axis roll --firmware teensy35 --sd-image c.img --sd-faults no_card "
         "--out s", "only the host firmware"),
    case("sweep --sil --axis roll --sd-faults no_card --out s", "--sd-faults needs --sd-image"),
    case("board --telemetry t --sd-image c.img --sd-faults busy_for_us=18446744073709551616",
         "at most 18446744073709551615"),
    case("board --telemetry adir --duration-s 1", "exists"),
    # validate: damaged MODELS.json (JSON and schema), absurd models, gains files, outputs
    case("validate models.json", "not valid JSON"),
    case("validate binary.dat", "not UTF-8"),
    case("validate empty.dat", "empty file"),
    case("validate nul.dat", "not valid JSON"),
    case("validate points.csv", "not valid JSON"),
    case("validate missing.json", "no such file"),
    case("validate adir", "is a folder"),
    case("validate m_list.json", "must be a JSON object"),
    case("validate m_null.json", "must be a JSON object"),
    case("validate m_string.json", "must be a JSON object"),
    case("validate m_truncated.json", "not valid JSON"),
    case("validate m_nested.json", "nested too deeply"),
    case("validate m_latin1.json", "not UTF-8"),
    case("validate m_empty_obj.json", "models is missing"),
    case("validate m_models_empty.json", "models must have 1 to"),
    case("validate m_models_obj.json", "models must be a list"),
    case("validate m_model_list.json", "models[0] must be a JSON object"),
    case("validate m_no_den.json", "models[0].den is missing"),
    case("validate m_nan.json", "models[0].num[0] must be a finite number"),
    case("validate m_infinity.json", "models[0].den[2]"),
    case("validate m_1e999.json", "models[0].den[1]"),
    case("validate m_1e308.json", "beyond"),
    case("validate m_bigint.json", "400-digit"),
    case("validate m_longint.json", "too long"),
    case("validate m_string_coef.json", "models[0].num[0]"),
    case("validate m_bool_coef.json", "models[0].num[0]"),
    case("validate m_improper.json", "improper"),
    case("validate m_order_mismatch.json", "must have 1 coefficients"),
    case("validate m_order_13.json", "models[0].order[1]"),
    case("validate m_order_text.json", "models[0].order"),
    case("validate m_order_float.json", "whole number"),
    case("validate m_den_leading0.json", "den[0] must not be 0"),
    case("validate m_delay_neg.json", "delay_s"),
    case("validate m_delay_huge.json", "delay_s"),
    case("validate m_delay_text.json", "delay_s"),
    case("validate m_stable_text.json", "stable must be true or false"),
    case("validate m_metrics_text.json", "metrics.J"),
    case("validate m_poles_bad.json", "poles[0]"),
    case("validate m_rec_5.json", "recommended"),
    case("validate m_rec_text.json", "recommended"),
    case("validate m_rec_neg.json", "recommended"),
    case("validate m_axis_bad.json", "axis must be one of"),
    case("validate m_axis_none.json", "--axis"),
    case("validate m_log_bad.json", "log.skipped_bytes"),
    case("validate m_skipped_bad.json", "skipped_frequencies[0]"),
    case("validate m_fast_pole.json --axis roll", "pole"),
    case("validate m_fast_zero.json --axis roll", "zero"),
    case("validate m_huge_gain.json --axis roll", "gain"),
    case("validate m_tiny_gain.json --axis roll", "gain"),
    case("validate m_wide_coef.json --axis roll", "beyond"),
    # tune: models it cannot design on, options out of range or not finite, a spec no
    # gains meet, two files of one axis
    case("tune t_no_rec.json --out o", "no recommended model"),
    case("tune t_unstable.json --out o", "is unstable"),
    case("tune good_models.json --out o", "band_rad_s"),
    case("tune m_nan.json --out o", "must be a finite number"),
    case("tune missing.json --out o", "no such file"),
    case("tune t_good.json", "--out"),
    case("tune t_good.json --out o --phase-margin nan", "--phase-margin"),
    case("tune t_good.json --out o --gain-margin inf", "--gain-margin"),
    case("tune t_good.json --out o --phase-margin 90", "--phase-margin"),
    case("tune t_good.json --out o --max-command 2", "--max-command"),
    case("tune t_good.json --out o --phase-margin 89 --min-crossover 500", "cannot be met"),
    case("tune t_good.json --out o --phase-margin 89", "cannot be met"),
    case("tune t_good.json t_good.json --out o", "both of roll"),
    case("verify --sil missing", "not a folder"),
    case("verify --sil t_good.json", "not a folder"),
    case("verify --sil adir", "has no tune.json"),
    case("verify adir", "--sil"),
    case("verify --sil adir --axis up", "--axis"),
    case("verify --sil adir --rig-time -1", "--rig-time"),
    case("verify --port udpin:0.0.0.0:14550 adir --param-store p.bin", "need --sil"),
    case("validate good_models.json --model 3", "no model 3"),
    case("validate good_models.json --model -1", "--model"),
    case("validate good_models.json --axis up", "--axis"),
    case("validate good_models.json --seed -1", "--seed"),
    case("validate good_models.json --turbulence hurricane", "--turbulence"),
    case(f"{VALIDATE} --gains missing.json", "no such file"),
    case(f"{VALIDATE} --gains adir", "is a folder"),
    case(f"{VALIDATE} --gains binary.dat", "not UTF-8"),
    case(f"{VALIDATE} --gains empty.dat", "empty file"),
    case(f"{VALIDATE} --gains models.json", "not valid JSON"),
    case(f"{VALIDATE} --gains g_list.json", "must be a JSON object"),
    case(f"{VALIDATE} --gains g_empty_obj.json", "rate is missing"),
    case(f"{VALIDATE} --gains g_no_rate.json", "rate is missing"),
    case(f"{VALIDATE} --gains g_rate_short.json", "rate.roll must be a list of 3"),
    case(f"{VALIDATE} --gains g_rate_neg.json", "rate.roll[0] (Kc)"),
    case(f"{VALIDATE} --gains g_rate_zero_kc.json", "rate.roll[0] (Kc)"),
    case(f"{VALIDATE} --gains g_rate_nan.json", "rate.roll[1] (tau_I_s)"),
    case(f"{VALIDATE} --gains g_rate_text.json", "rate.roll[0] (Kc)"),
    case(f"{VALIDATE} --gains g_rate_huge.json", "rate.roll[0] (Kc)"),
    case(f"{VALIDATE} --gains g_rate_obj.json", "rate.roll"),
    case(f"{VALIDATE} --gains g_no_roll.json", "rate.roll is missing"),
    case(f"{VALIDATE} --gains g_no_angle.json", "angle.roll is missing"),
    case(f"{VALIDATE} --gains g_angle_long.json", "angle.roll must be a list of 2"),
    case(f"{VALIDATE} --gains g_angle_yaw.json", "angle.yaw is not a known key"),
    case(f"{VALIDATE} --gains g_typo.json", "rates is not a known key"),
    case(f"{VALIDATE} --gains g_axis_typo.json", "rate.rol is not a known key"),
    case(f"{VALIDATE} --out binary.dat", "binary.dat"),
    case(f"{VALIDATE} --out binary.dat/v", "binary.dat/v"),
    case(f"{VALIDATE} --out /proc/v", "/proc/v"),
    case("validate m_nan.json --out adir", "models[0].num[0]"),
    case("validate", "MODELS.json"),
    # log: ports that are not ports, outputs that exist or cannot be written
    case("log --port /dev/null --baud -1 --out l.tlog --duration-s 0.1", "--baud"),
    case("log --port /dev/null --out l.tlog --duration-s nan", "--duration-s"),
    case("log --port /dev/null --out l.tlog --duration-s 0", "--duration-s"),
    case("log --port missing --out l.tlog", "missing"),
    case("log --port /dev/null --out l.tlog --duration-s 0.1", "/dev/null"),
    case("log --port binary.dat --out l.tlog --duration-s 0.1", "binary.dat"),
    case("log --port adir --out l.tlog --duration-s 0.1", "adir"),
    case("log --port missing --out old.tlog", "missing"),
    case("log --port /dev/null --out old.tlog --duration-s 0.1", "/dev/null"),
    case("log --port /dev/null --baud abc --out l.tlog", "--baud"),
    case("log --port /dev/null --out adir --duration-s 0.1", "/dev/null"),
    case("log --port /dev/null", "--out"),
    # log and sweep over a network: addresses that are not ones, schemes heliquad does not open
    case("log --port tcp:127.0.0.1 --out l.tlog", "expected tcp:HOST:PORT"),
    case("log --port udpin:0.0.0.0:0 --out l.tlog", "the port must be a number from 1 to 65535"),
    case("log --port udpout:127.0.0.1:x --out l.tlog", "not 'x'"),
    case("log --port uds:/tmp/x --out l.tlog", "unknown connection uds:"),
    case("sweep --port tcp:a:b:c --axis roll --out s", "expected tcp:HOST:PORT"),
    case("sweep --port udpin:300.1.1.1:14550 --axis roll --out s", "cannot open udpin:300.1.1.1:14550"),
    # params: ports, names, values and files refused before (or at) the link
    case("params --port /dev/null list", "/dev/null"),
    case("params --port missing get A", "missing"),
    case("params --port tcp:127.0.0.1 list", "expected tcp:HOST:PORT"),
    case("params --port /dev/null get 'bad name'", "not a parameter name"),
    case("params --port /dev/null set A nan", "not a finite number"),
    case("params --port /dev/null set A", "VALUE"),
    case("params --port /dev/null save points.csv", "points.csv exists: heliquad never writes over"),
    case("params --port /dev/null load binary.dat", "binary.dat: not UTF-8"),
    case("params --port /dev/null load points.csv", "points.csv, line 1: 3 fields"),
    case("params --port /dev/null load missing.params", "no such file"),
    case("params --port /dev/null load empty.dat", "empty"),
    case("params list", "--port"),
    case("effectiveness --out e", "required: DIR"),
    case("effectiveness missing --out e", "needs a per-rotor run on every rig"),
    case("effectiveness missing missing missing --out e", "missing: no such file"),
    case("effectiveness points.csv points.csv points.csv --out e", "not a DataFlash log"),
    case("effectiveness missing missing missing", "required: --out"),
    case("params from-vehicle missing.toml --out out.params", "missing.toml: no such file"),
    case("params from-vehicle t_bad.toml --out out.params", "not valid TOML"),
    case("params from-vehicle t_rotor_missing.toml --out out.params",
         "missing key rotors[3].max_speed_rad_s"),
    case("params from-vehicle t_rotor_same_place.toml --out out.params",
         "rotors[4].position_m is rotors[2]'s"),
    case("params from-vehicle t_rotor_zero_thrust.toml --out out.params",
         "rotors[3].max_thrust_n must be positive"),
    case("params from-vehicle t_axis_short.toml --out out.params",
         "rotors[2].thrust_axis must be a unit vector"),
    case("params from-vehicle t_spin0.toml --out out.params", "rotors[5].spin must be 1 or -1"),
    case("params from-vehicle t_rotors_9.toml --out out.params", "a vehicle has 2 to 8 rotors"),
    case("params from-vehicle t_rotors_1.toml --out out.params", "a vehicle has 2 to 8 rotors"),
    case("params from-vehicle t_rotors_six.toml --out points.csv",
         "points.csv exists: heliquad never writes over"),
    case("params from-vehicle t_rotors_six.toml", "--out"),
    case("params --port /dev/null frobnicate", "invalid choice"),
    # logs: ports, log numbers and output files refused before (or at) the link; a missing
    # log, an armed board and a silent one: LIVE_LOG_CASES below (they need a board)
    case("logs --port /dev/null list", "/dev/null"),
    case("logs --port missing erase", "missing"),
    case("logs --port tcp:127.0.0.1 list", "expected tcp:HOST:PORT"),
    case("logs --port /dev/null download 0", "N"),
    case("logs --port /dev/null download 65536", "N"),
    case("logs --port /dev/null download x", "N"),
    case("logs --port /dev/null download", "N"),
    case("logs --port /dev/null download 1 --out points.csv", "points.csv exists: heliquad never writes over"),
    case("logs --port /dev/null download 1 --out adir", "adir exists"),
    case("logs --port /dev/null download 1 --out nodir/l.BIN", "nodir"),
    case("logs list", "--port"),
    case("logs --port /dev/null frobnicate", "invalid choice"),
    # program: ports, actions and the sweep's design options refused before the link
    case("program --port /dev/null show", "/dev/null"),
    case("program --port missing clear", "missing"),
    case("program --port tcp:127.0.0.1 show", "expected tcp:HOST:PORT"),
    case("program show", "--port"),
    case("program --port /dev/null frobnicate", "invalid choice"),
    case("program --port /dev/null set", "--axis"),
    case("program --port /dev/null set --axis roll --cycles 0", "--cycles"),
    case("program --port /dev/null set --axis roll --freqs-hz nan", "--freqs-hz"),
    case("program --port /dev/null set --axis roll --amplitude -1", "--amplitude"),
    case("program --port /dev/null set --axis yaw --inject angle", "yaw is rate-only"),
    case("program --port /dev/null set --axis roll --target-sigma 0.1", "unrecognized"),
    case("program --port /dev/null set --axis roll --swing-deg 5", "unrecognized"),
    case("program --port /dev/null set --axis roll --lines 10", "add --signal multisine"),
    case("program --port /dev/null set --axis roll --signal multisine --cycles 4",
         "--cycles shape a dwell"),
    case("program --port /dev/null set --axis roll --freqs-hz " + " ".join(["1"] * 25),
         "at most 24 steps"),
    # mavlink-dialect: an output that is not a folder, a Python that is not one
    case("mavlink-dialect --out binary.dat", "exists and is not a folder"),
    case("mavlink-dialect --python missing --out d", "--python missing: cannot run it"),
    case("mavlink-dialect --python adir --install", "--python adir: cannot run it"),
    case("mavlink-dialect --python points.csv", "--python points.csv: cannot run it"),
    case("mavlink-dialect --out", "expected one argument"),
    case("mavlink-dialect --frobnicate", "unrecognized"),
    # tlog: damaged, empty, binary, folders; a damaged log is read with a warning (exit 0)
    case("tlog binary.dat", "no MAVLink record"),
    case("tlog .", "is a directory"),
    case("tlog adir", "is a directory"),
    case("tlog missing.tlog", "No such file"),
    case("tlog empty.dat", "empty"),
    case("tlog /dev/null", "empty"),
    case("tlog text.tlog", "no MAVLink record"),
    case("tlog json.tlog", "no MAVLink record"),
    case("tlog cut.tlog", "no MAVLink record"),
    case("tlog flipped.tlog", "is damaged", code=0),
    case("tlog points.csv", "no MAVLink record"),
    case("tlog", "FILE.tlog"),
    # sweep: numbers, plants, vehicle files, folders that are not new (refused up front)
    case("sweep --sil --axis roll --cycles 0 --out s", "--cycles"),
    case("sweep --sil --axis roll --cycles 70000 --out s", "--cycles"),
    case("sweep --sil --axis roll --freqs-hz nan --out s", "--freqs-hz"),
    case("sweep --sil --axis roll --freqs-hz 1e-9 --out s", "excitation band"),
    case("sweep --sil --axis roll --freqs-hz 1 60 --out s", "excitation band"),
    case("sweep --sil --axis roll --freqs-hz 0 --out s", "--freqs-hz"),
    case("sweep --sil --axis roll --tuning-band --freqs-hz 1 2 --out s", "give one"),
    case("sweep --sil --axis roll --inject motors --tuning-band --freqs-hz 1 2 --out s",
         "give one"),
    case("sweep --sil --axis roll --amplitude nan --out s", "--amplitude"),
    case("sweep --sil --axis roll --amplitude 5 --out s", "--amplitude"),
    case("sweep --sil --axis roll --amplitude -1 --out s", "--amplitude"),
    case("sweep --sil --axis roll --signal square --out s", "--signal"),
    case("sweep --sil --axis roll --signal multisine --cycles 4 --out s", "--cycles shape a dwell"),
    case("sweep --sil --axis roll --signal multisine --swing-deg 5 --out s", "shape a dwell"),
    case("sweep --sil --axis roll --lines 10 --out s", "add --signal multisine"),
    case("sweep --sil --axis roll --signal multisine --lines 17 --out s", "--lines"),
    case("sweep --sil --axis roll --signal multisine --lines 1 --out s", "--lines"),
    case("sweep --sil --axis roll --signal multisine --rig-time 400 --out s", "--rig-time"),
    case("sweep --sil --axis roll --signal multisine --rig-time nan --out s", "--rig-time"),
    case("sweep --sil --axis yaw --signal multisine --rig-time 20 --out s", "needs more than 20 s"),
    case("sweep --sil --axis roll --signal multisine --freqs-hz 2 --out s", "band's two edges"),
    case("sweep --sil --axis roll --signal multisine --freqs-hz 0.01 4 --out s", "needs more than 60 s"),
    case("sweep --sil --axis roll --signal multisine --freqs-hz 0.04 4 --rig-time 300 --out s",
         "excitation band"),
    case("sweep --sil --axis roll --signal multisine --amplitude 1.5 --out s", "--amplitude"),
    case("sweep --sil --axis roll --seed -1 --out s", "--seed"),
    case("sweep --port /dev/null --baud -1 --axis roll --out s", "--baud"),
    case("sweep --port /dev/null --baud 0 --axis roll --out s", "--baud"),
    case("sweep --sil --port /dev/null --axis roll --out s", "not allowed with"),
    case("sweep --axis roll --out s", "--sil"),
    case("sweep --sil --out s", "--axis"),
    case("sweep --sil --axis yaw --inject angle --out s", "rate-only"),
    case("sweep --sil --axis roll --params points.csv --out .", "not empty"),
    case("sweep --sil --axis roll --out full", "not empty"),
    case("sweep --sil --axis roll --out binary.dat", "not a folder"),
    case("sweep --sil --axis roll --out binary.dat/s", "binary.dat/s"),
    case("sweep --port /dev/null --axis roll --fault silent@1 --out s", "--fault needs --sil"),
    case("sweep --port /dev/null --axis roll --firmware teensy35 --out s", "--firmware needs --sil"),
    case("sweep --port /dev/null --axis roll --out s", "/dev/null"),
    case("sweep --port binary.dat --axis roll --out s", "binary.dat"),
    case("sweep --sil --axis roll --plant tf --num 1 --den 0 1 --out s", "leading coefficient"),
    case("sweep --sil --axis roll --plant tf --num 1 1 1 --den 1 1 --out s", "not proper"),
    case("sweep --sil --axis roll --plant tf --num 1 --den 1 1e4 --out s", "Nyquist"),
    case("sweep --sil --axis roll --plant tf --num 1e-9 --den 1 5 --out s", "gain"),
    case("sweep --sil --axis roll --params t_no_section.toml --out s", "missing section [rig]"),
    case("sweep --sil --axis roll --params t_section_value.toml --out s", "body must be a section"),
    case("sweep --sil --axis roll --params t_missing_key.toml --out s", "missing key body.mass_kg"),
    case("sweep --sil --axis roll --params t_unit_key.toml --out s", "expected body.mass_kg"),
    case("sweep --sil --axis roll --params t_newline_key.toml --out s", "unknown key"),
    case("sweep --sil --axis roll --params t_extra_section.toml --out s", "unknown section [battery]"),
    case("sweep --sil --axis roll --params t_inf.toml --out s", "body.mass_kg"),
    case("sweep --sil --axis roll --params t_negative.toml --out s", "body.mass_kg"),
    case("sweep --sil --axis roll --params t_text.toml --out s", "body.mass_kg"),
    case("sweep --sil --axis roll --params t_bool.toml --out s", "body.mass_kg"),
    case("sweep --sil --axis roll --params t_inertia_zero.toml --out s", "body.inertia_kg_m2"),
    case("sweep --sil --axis roll --params t_inertia_short.toml --out s", "body.inertia_kg_m2"),
    case("sweep --sil --axis roll --params t_spin.toml --out s", "rotors[1].spin"),
    case("sweep --sil --axis roll --params t_spin0.toml --out s", "rotors[5].spin"),
    case("sweep --sil --axis roll --params t_axis_zero.toml --out s", "rotors[2].thrust_axis"),
    case("sweep --sil --axis roll --params t_rotors_9.toml --out s", "2 to 8 rotors"),
    case("sweep --sil --axis roll --params t_rotors_3.toml --out s", "4 to 8 rotors"),
    case("sweep --port udpin:0.0.0.0:14550 --axis roll --load-params ok.params --out s",
         "--load-params needs --sil"),
    case("sweep --sil --axis roll --load-params missing.params --out s", "missing.params"),
    case("demo --axes roll --load-params missing.params --out d", "missing.params"),
    case("board --load-params missing.params --duration-s 1", "missing.params"),
    case("board --plant vehicle --params t_rotors_3.toml --duration-s 1", "4 to 8 rotors"),
    case("sweep --sil --axis roll --params t_latency_float.toml --out s", "imu.dmp_latency_samples"),
    case("sweep --sil --axis roll --params t_latency_huge.toml --out s", "imu.dmp_latency_samples"),
    case("sweep --sil --axis roll --params t_bias.toml --out s", "imu.gyro_bias_deg_s"),
    case("sweep --sil --axis roll --params t_rotor_momentum.toml --out s", "fastest mode"),
    case("sweep --sil --axis roll --params adir --out s", "adir"),
    case("sweep --sil --axis roll --fault link@x --out s", "link@x"),
    case("sweep --sil --axis roll --fault nack@1:-1 --out s", "nack@1:-1"),
    # identify: damaged sweep folders (manifest schema, logs missing, empty, cut, mixed up)
    case("identify binary.dat", "not a folder"),
    case("identify missing", "not a folder"),
    case("identify .", "no manifest.json"),
    case("identify s_no_manifest", "no manifest.json"),
    case("identify s_manifest_dir", "is a folder"),
    case("identify s_manifest_empty", "empty file"),
    case("identify s_manifest_binary", "not UTF-8"),
    case("identify s_manifest_list", "must be a JSON object"),
    case("identify s_manifest_cut", "not valid JSON"),
    case("identify s_no_axis", "axis is missing"),
    case("identify s_axis_bad", "axis must be one of"),
    case("identify s_axis_number", "axis must be a string"),
    case("identify s_inject_bad", "inject must be one of"),
    case("identify s_yaw_angle", "yaw"),
    case("identify s_no_freqs", "frequencies is missing"),
    case("identify s_freqs_obj", "frequencies must be a list"),
    case("identify s_freq_text", "frequencies[0].requested_hz"),
    case("identify s_freq_negative", "frequencies[0].requested_hz"),
    case("identify s_freq_nan", "frequencies[0].freq_hz"),
    case("identify s_freq_inf", "frequencies[0].freq_hz"),
    case("identify s_ok_no_freq_hz", "frequencies[0].freq_hz is missing"),
    case("identify s_ok_no_window", "frequencies[1].start_us is missing"),
    case("identify s_period_zero", "frequencies[0].period_samples"),
    case("identify s_period_float", "frequencies[0].period_samples"),
    case("identify s_period_huge", "loop rate"),
    case("identify s_window_backwards", "frequencies[0].end_us is before start_us"),
    case("identify s_start_huge", "frequencies[0].start_us"),
    case("identify s_start_negative", "frequencies[0].start_us"),
    case("identify s_samples_negative", "frequencies[0].samples"),
    case("identify s_status_number", "frequencies[0].status must be a string"),
    case("identify s_messages_bad", "frequencies[0].messages must be a list"),
    case("identify s_signal_bad", "signal"),
    case("identify s_ms_no_orders", "frequencies[0].orders is missing"),
    case("identify s_ms_orders_down", "strictly increasing"),
    case("identify s_ms_orders_high", "fewer than 4 samples per cycle"),
    case("identify s_ms_orders_text", "frequencies[0].orders"),
    case("identify s_tlog_parent", "tlog must be a file name"),
    case("identify s_tlog_absolute", "tlog must be a file name"),
    case("identify s_tlog_number", "tlog must be a string"),
    case("identify s_aborted_number", "aborted"),
    case("identify s_complete_text", "complete"),
    case("identify s_limits_text", "limits.max_angle_deg"),
    case("identify s_other_axis", "not of one session"),
    case("identify s_no_tlog", "sweep.tlog is missing"),
    case("identify s_tlog_dir", "sweep.tlog"),
    case("identify s_tlog_empty", "0 frequency(ies)"),
    case("identify s_tlog_garbage", "0 frequency(ies)"),
    case("identify s_tlog_head", "0 frequency(ies)"),
    case("identify s_tlog_two_thirds", "1 frequency(ies)"),
    case("identify s_no_manifest --order 0/2", "no manifest.json"),
    case("identify s_tlog_empty --order 2-4", "form M/N"),
    case("identify", "DIR"),
    # identify on a board's log: the part before the damage, or nothing usable left
    case("identify b_cut_mid.BIN", "1 frequency(ies)"),
    case("identify b_flip_mid.BIN", "1 frequency(ies)"),
    case("identify b_garbage_mid.BIN", "1 frequency(ies)"),
    case("identify b_no_excitation.BIN", "no excitation in the log"),
    case("identify b_header.BIN", "no excitation in the log"),
    case("identify text.BIN", "not a DataFlash log"),
    case("identify empty.BIN", "empty file"),
    case("identify missing.BIN", "no such file"),
    case("identify b_two", "give one of them"),
    # identify that runs (the log's damage is skipped with a one-line warning, exit 0)
    case("identify s_tlog_flipped", "the log is damaged", code=0),
    case("identify b_cut_tail.BIN", "the log is damaged", code=0),
    case("identify b_flip_tail.BIN", "the log is damaged", code=0),
    case("identify b_garbage_tail.BIN", "the log is damaged", code=0),
    case("identify b_folder", "the log is damaged", code=0),
    # report: damaged folders, models, validation, tables; unwritable or folder outputs
    case("report missing", "not a folder"),
    case("report binary.dat", "not a folder"),
    case("report .", "no models.json"),
    case("report adir", "no models.json"),
    case("report f_models_list", "must be a JSON object"),
    case("report f_models_bad_num", "models[0].num must be a list"),
    case("report f_models_cut", "not valid JSON"),
    case("report f_models_dir", "is a folder"),
    case("report f_models_replay", "replay.points[0].nrmse"),
    case("report f_models_truth", "sil_truth.points[0].error_over_sigma"),
    case("report f_points_ry", "coherence_ry at data row 1"),
    case("report f_manifest_bad", "frequencies[0].requested_hz"),
    case("report f_validation_list", "validation.json"),
    case("report f_validation_no_stable", "stable is missing"),
    case("report f_validation_no_step", "step is missing"),
    case("report f_validation_loops_text", "loops must be a JSON object"),
    case("report f_validation_measured", "measured_loop.points[0].freq_hz"),
    case("report f_validation_truth", "truth_loops.rate.gain_crossovers[0].omega_rad_s is missing"),
    case("report f_validation_binary", "not UTF-8"),
    case("report f_table_text", "missing column"),
    case("report f_table_coherence", "coherence at data row 1"),
    case("report f_table_nan", "column freq_hz has NaN"),
    case("report f_table_dir", "is a folder"),
    case("report f_parent", "pitch/models.json"),
    case("report s_tlog_flipped --out binary.dat/r.html", "binary.dat/r.html"),
    case("report s_tlog_flipped --out /proc/r.html", "/proc/r.html"),
    case("report s_tlog_flipped --out adir", "adir"),
    case("report f_models_list --out points.csv", "must be a JSON object"),
    case("report", "DIR"),
    # demo: outputs that exist, seeds and axes (all refused before any firmware starts)
    case("demo --out binary.dat", "not a folder"),
    case("demo --out full", "not empty"),
    case("demo --out points.csv", "not a folder"),
    case("demo --out binary.dat/demo", "binary.dat/demo"),
    case("demo --seed -1 --out d", "--seed"),
    case("demo --seed 99999999999 --out d", "--seed"),
    case("demo --seed abc --out d", "--seed"),
    case("demo --axes up --out d", "--axes"),
    case("demo --axes roll --out full", "not empty"),
    case("demo --firmware bogus --out d", "--firmware"),
    case("demo --turbulence gale --out d", "--turbulence"),
    # sweep's design options: out of range, or given with what they do not go with
    case("sweep --sil --axis roll --target-sigma 0 --out s", "--target-sigma"),
    case("sweep --sil --axis roll --target-sigma 2 --out s", "--target-sigma"),
    case("sweep --sil --axis roll --max-cycles 3 --out s", "--max-cycles"),
    case("sweep --sil --axis roll --swing-deg 90 --out s", "--swing-deg"),
    case("sweep --sil --axis roll --swing-deg nan --out s", "--swing-deg"),
    case("sweep --sil --axis roll --cycles 8 --max-cycles 20 --out s", "one or the other"),
    case("sweep --sil --axis roll --amplitude 0.5 --swing-deg 5 --out s", "--swing-deg"),
    # dmp-image: sources that are not the mpu6050 package's, outputs that cannot be written
    case("dmp-image binary.dat", "--out"),
    case("dmp-image --source binary.dat --out dmp.bin", "binary.dat"),
    case("dmp-image --source missing.py --out dmp.bin", "missing.py"),
    case("dmp-image --source adir --out dmp.bin", "adir"),
    case("dmp-image --source empty.dat --out dmp.bin", "no dmpMemory"),
    case("dmp-image --source syntax.py --out dmp.bin", "syntax.py"),
    case("dmp-image --source call.py --out dmp.bin", "dmpMemory is not a list of numbers"),
    case("dmp-image --source short.py --out dmp.bin", "dmpMemory has 10 entries"),
    case("dmp-image --source big_values.py --out dmp.bin", "each 0..255"),
    case("dmp-image --source nothing.py --out dmp.bin", "no dmpMemory"),
    case("dmp-image --source latin1.py --out dmp.bin", "latin1.py"),
    case("dmp-image --source fake.whl --out dmp.bin", "fake.whl"),
    case("dmp-image --source missing.whl --out dmp.bin", "missing.whl"),
    case("dmp-image --source short.py --out old.bin", "dmpMemory has 10"),
    case("dmp-image --source short.py --out binary.dat/dmp.bin", "binary.dat/dmp.bin"),
    case("dmp-image --source short.py --out adir", "adir"),
    # a damaged DMP file: refused in one line before the firmware starts
    case(f"{SIL} --dmp-image bare.bin --out o", "bare"),
    case(f"{SIL} --dmp-image old.bin --out o", "no HQDM magic"),
    case("sweep --sil --axis roll --dmp-image old.bin --out s", "no HQDM magic"),
    case("sweep --sil --axis roll --dmp-image missing.bin --out s", "missing.bin"),
    case("board --dmp-image empty.dat --duration-s 1", "no HQDM magic"),
    # flash: images that are not Teensy 3.5 images, or would secure the chip; no loader
    case("flash binary.dat", "not an Intel HEX"),
    case("flash --check-only binary.dat", "not an Intel HEX"),
    case("flash --check-only missing.hex", "no such file"),
    case("flash --check-only adir", "is a folder"),
    case("flash --check-only empty.dat", "no data"),
    case("flash --check-only text.hex", "not an Intel HEX"),
    case("flash --check-only checksum.hex", "not an Intel HEX"),
    case("flash --check-only secured.hex", "would secure the chip"),
    case("flash --check-only bad_sp.hex", "stack pointer"),
    case("flash --check-only bad_reset.hex", "reset vector"),
    case("flash --check-only beyond.hex", "beyond"),
    case("flash --check-only points.csv", "not an Intel HEX"),
    case("flash ok.hex --loader no-such-loader", "no-such-loader not found"),
    case("flash ok.hex --loader adir", "not found"),
    case("usb-descriptors --image binary.dat", "not an ELF file"),
    case("usb-descriptors --image empty.dat", "not an ELF file"),
    case("usb-descriptors --image ok.hex", "give the image's .elf, not its .hex"),
    case("usb-descriptors --image missing.elf", "such file"),
    case("usb-descriptors --image adir", "is a folder"),
    case("usb-descriptors --frobnicate", "unrecognized"),
    # sd-image: sizes a FAT32 card cannot have, a folder or a missing folder for the file
    case("sd-image --size 12Q card.img", "not a size"),
    case("sd-image --size 1000 card.img", "512-byte blocks"),
    case("sd-image --size 1M card.img", "40 MiB to 32 GiB"),
    case("sd-image --size 64G card.img", "40 MiB to 32 GiB"),
    case("sd-image --size -5 card.img", "not a size"),
    case("sd-image adir", "is a folder"),
    case("sd-image nofolder/card.img", "nofolder"),
    case("sd-image", "required"),
    case("sd-image card.img --frobnicate", "unrecognized"),
    # study: bad specs, a scheduler that does not answer (refused before any folder is made)
    case("study missing.toml --out s", "no such file"),
    case("study binary.dat --out s", "not utf-8"),
    case("study points.csv --out s", "not valid toml"),
    case("study study_unknown.toml --out s", "unknown factor 'wind'"),
    case("study study_empty.toml --out s", "the grid is empty"),
    case("study study_lines.toml --out s", "--lines: 1 is outside 2..16"),
    case("study study_out.toml --out s", "out is set by the study itself"),
    case("study study_table.toml --out s", "unknown table 'wind'"),
    case("study study_plan.toml --out s", "a multisine over 0.15-1.6 hz needs more than 12 s"),
    case("study study_seed.toml --out s", "{first = n, count = m}"),
    case("study study.toml --out s --workers 0", "--workers"),
    case("study study.toml --out s --workers 2 --scheduler tcp://127.0.0.1:1", "not allowed"),
    case("study study.toml --out s --scheduler tcp://127.0.0.1:1", "no answer"),
    case("study study.toml", "required"),
    # every subcommand: an unknown option, no subcommand
    case("fsf run.csv --out p.csv --frobnicate", "unrecognized"),
    case("fit points.csv --json m.json --frobnicate", "unrecognized"),
    case("validate good_models.json --frobnicate", "unrecognized"),
    case("report . --frobnicate", "unrecognized"),
    case("identify . --frobnicate", "unrecognized"),
    case("tlog x --frobnicate", "unrecognized"),
    case("frobnicate", "invalid choice"),
    case("", "required"),
]


# --- running them ---------------------------------------------------------------------------

@pytest.fixture(scope="session")
def session(tmp_path_factory):
    """One small SIL sweep of the tf plant (2 frequencies), identified and validated; its
    on-board log beside it (board.BIN, read from its card)."""
    out = tmp_path_factory.mktemp("bad_input") / "roll"
    card = out.parent / "card.img"
    for args in (["sweep", "--sil", "--axis", "roll", "--plant", "tf", "--freqs-hz", "2", "4",
                  "--cycles", "3", "--sd-image", card, "--out", out], ["identify", out],
                 ["validate", out / "models.json"]):
        res = heliquad(*args)
        assert res.returncode == 0, (args, res.stderr)
    (out.parent / "board.BIN").write_bytes(Fat32Image(card).read("LOGS/00000001.BIN"))
    return out


def heliquad(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=120, cwd=cwd)


def _materialise(args, where, session):
    for token in args:
        name = token.split("/")[0]
        if name in FILES and not (where / name).exists() and name:
            content = FILES[name]
            if callable(content):
                content(where / name, session)
            else:
                (where / name).write_bytes(content.encode() if isinstance(content, str) else content)


def _snapshot(path):
    return {p.relative_to(path): (p.read_bytes() if p.is_file() else None)
            for p in sorted(path.rglob("*"))}


@pytest.mark.parametrize("args, says, code", CASES)
def test_bad_input_is_one_line_and_changes_nothing(args, says, code, session, tmp_path):
    argv = shlex.split(args)
    _materialise(argv, tmp_path, session)
    before = _snapshot(tmp_path)
    res = heliquad(*argv, cwd=tmp_path)
    _assert_one_line(res, says, code)
    after = _snapshot(tmp_path)
    assert {k: v for k, v in after.items() if k in before} == before     # nothing changed
    if code == 2:
        assert after == before                                           # nothing created


def _assert_one_line(res, says, code) -> None:
    lines = res.stderr.strip().splitlines()
    assert res.returncode == code, (res.returncode, res.stdout[-500:], res.stderr[-2000:])
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("heliquad"), lines[0]
    assert says.lower() in lines[0].lower(), lines[0]


# logs against a running board, the cases that need one (heliquad board, the host firmware
# serving the two logs of its card, or no card): a log it does not have, the board armed, a
# board that serves no logs. The folder the command runs in is left as it was.
LIVE_LOG_CASES = [
    pytest.param(("--disarmed", "--sd-image"), "download 3", "the board has no log 3", 2,
                 id="logs download 3, a log the board does not have"),
    pytest.param(("--sd-image",), "list", "the board is armed", 1,
                 id="logs list, the board armed"),
    pytest.param(("--sd-image",), "erase", "the board is armed", 1,
                 id="logs erase, the board armed"),
    pytest.param(("--disarmed",), "list", "no answer to the log list request", 1,
                 id="logs list, a board that serves no logs"),
]


@pytest.mark.parametrize("board_args, action, says, code", LIVE_LOG_CASES)
def test_logs_against_a_live_board_is_one_line_and_changes_nothing(board_args, action, says,
                                                                   code, tmp_path):
    rig, work = (tmp_path / name for name in ("rig", "work"))
    for folder in (rig, work):
        folder.mkdir()
    card = tmp_path / "card.img"
    card_with_logs(card, {1: b"log" * 100, 2: b"log" * 200})
    if board_args[-1] == "--sd-image":
        board_args += (card,)
    with running_board(rig, *board_args) as board:
        if "--disarmed" not in board_args:
            wait_armed(board)
        before = _snapshot(work)
        res = heliquad("logs", "--port", board, *shlex.split(action), cwd=work)
    _assert_one_line(res, says, code)
    assert _snapshot(work) == before


def test_the_corpus_covers_every_subcommand():
    from heliquad.host.commands import COMMANDS

    names = set(COMMANDS)
    counts = {n: sum(1 for p in CASES if p.values[0].split(" ")[0] == n) for n in names}
    assert all(counts[n] >= 5 for n in names), counts
    assert len(CASES) >= 300
