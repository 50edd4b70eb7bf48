"""``--port auto``: the one heliquad board found by its USB identity.

pyserial's listing is replaced by a list of the test's own (none, one, two heliquad boards, a
stock Teensy); boards emulated by ``heliquad board`` are found through their announcements,
in a folder of the test's own (HELIQUAD_BOARDS_DIR), so no board elsewhere on the machine
counts; an announcement counts while a lock on it is held, as its board holds one. The USB
identity is the firmware's (usb_identity.hpp, through the bindings).
"""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import time
import signal
import types

import pytest
import serial.tools.list_ports

import tool_runs
from heliquad import _firmware as fw
from heliquad.host.acquire import ports
from heliquad.host.cli.parser import main
from heliquad.host.records.manifest import read_manifest
from heliquad.sim.base import firmware_facts as facts
from heliquad.sim.base.errors import InputError
from heliquad.sim.rig import announce

#: The emulated chip's unique identification (docs/teensy35-emulator.md) in hexadecimal.
EMULATED_SERIAL = "00004851" "00454D55" "4D4B3634" "00000001"


def usb(device, product="heliquad flight controller", serial_number="0123ABCD",
        vid=0x16C0, pid=0x0483):
    """A port as pyserial's comports() gives it."""
    return types.SimpleNamespace(device=str(device), vid=vid, pid=pid, product=product,
                                 serial_number=serial_number)


@pytest.fixture
def listing(monkeypatch, tmp_path):
    """Set the ports pyserial lists; announcements come from an empty folder of the test's."""
    monkeypatch.setenv(announce.FOLDER_ENV, str(tmp_path / "boards"))
    found = []
    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda *a, **k: list(found))
    return found


def test_the_identity_is_the_firmwares():
    usb = facts.USB_IDENTITY
    assert (usb.vid, usb.pid) == (fw.USB_VID, fw.USB_PID) == (0x16C0, 0x0483)
    assert usb.manufacturer == fw.USB_MANUFACTURER
    assert usb.product == fw.USB_PRODUCT and "heliquad" in usb.product.lower()
    # The emulated chip's serial number: its unique identification, as the image derives it.
    from heliquad.host.commands.board import _usb_serial
    assert _usb_serial("teensy35") == EMULATED_SERIAL
    assert _usb_serial("host") == announce.HOST_BUILD_SERIAL
    assert facts.usb_serial_number([0xFEDCBA98, 0, 0x10, 0xA]) == \
        "FEDCBA98" "00000000" "00000010" "0000000A"


def test_none(listing, capsys, tmp_path):
    listing.append(usb("/dev/ttyS0", product=None, vid=None, pid=None))
    assert main(["params", "--port", "auto", "list"]) == 2
    err = tool_runs.one_line(capsys.readouterr().err)
    assert err == "heliquad params: error: --port auto: no heliquad board found among the " \
                  f"USB devices and the boards announced in {tmp_path / 'boards'}; or give " \
                  "--port DEVICE"


def test_one(listing, tmp_path, capsys):
    device = tmp_path / "ttyACM0"
    device.touch()
    listing += [usb("/dev/ttyS0", product=None, vid=None, pid=None), usb(device)]
    assert ports.resolve_port("auto") == str(device)
    assert capsys.readouterr().err == \
        f"port auto: {device} (heliquad flight controller, serial 0123ABCD)\n"
    # A named port is taken as it is, with nothing listed or said.
    listing.clear()
    assert ports.resolve_port("/dev/ttyUSB3") == "/dev/ttyUSB3"
    assert capsys.readouterr().err == ""


def test_two_are_refused_in_one_line(listing, tmp_path, capsys):
    for name, serial_number in (("ttyACM0", "1111"), ("ttyACM1", "2222")):
        (tmp_path / name).touch()
        listing.append(usb(tmp_path / name, serial_number=serial_number))
    assert main(["log", "--port", "auto", "--out", str(tmp_path / "x.tlog")]) == 2
    err = tool_runs.one_line(capsys.readouterr().err)
    assert "2 heliquad boards found" in err and "choose one with --port DEVICE" in err
    assert f"{tmp_path / 'ttyACM0'} (heliquad flight controller, serial 1111)" in err
    assert f"{tmp_path / 'ttyACM1'} (heliquad flight controller, serial 2222)" in err
    assert not (tmp_path / "x.tlog").exists()


def test_only_a_stock_teensy(listing, tmp_path):
    (tmp_path / "ttyACM0").touch()
    listing.append(usb(tmp_path / "ttyACM0", product="USB Serial"))
    with pytest.raises(InputError) as err:
        ports.resolve_port("auto")
    text = str(err.value)
    assert text.startswith("--port auto: no heliquad board found")
    assert f"a Teensy without heliquad's USB firmware is at {tmp_path / 'ttyACM0'} " \
           "(product 'USB Serial')" in text
    # Beside a heliquad board, a stock Teensy is not a second candidate.
    (tmp_path / "ttyACM1").touch()
    listing.append(usb(tmp_path / "ttyACM1"))
    assert ports.resolve_port("auto") == str(tmp_path / "ttyACM1")


def test_a_board_this_user_cannot_open(listing, monkeypatch):
    listing.append(usb("/dev/ttyACM0"))
    monkeypatch.setattr(ports, "_can_open", lambda device: False)
    with pytest.raises(InputError) as err:
        ports.resolve_port("auto")
    assert "/dev/ttyACM0 is a heliquad board this user cannot open" in str(err.value)
    assert "udev rule of docs/usb.md" in str(err.value)


def test_a_product_the_system_does_not_report_goes_by_the_ids(listing, tmp_path):
    (tmp_path / "COM3").touch()                # Windows' pyserial: no product string
    listing.append(usb(tmp_path / "COM3", product=None, serial_number=None))
    assert ports.resolve_port("auto") == str(tmp_path / "COM3")


def _announce(folder, name, record):
    folder.mkdir(exist_ok=True)
    (folder / name).write_text(record if isinstance(record, str) else json.dumps(record))


def test_bad_and_stale_announcements_are_ignored(listing, tmp_path):
    folder = tmp_path / "boards"
    main_fd, sub_fd = os.openpty()
    try:
        tty = os.ttyname(sub_fd)
        with announce.announced(tty, "SERIAL1", "host") as path:
            good = json.loads(open(path).read())
            assert [p.device for p in announce.announcements()] == [tty]
            dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                                  capture_output=True, text=True, check=True)
            stale = int(dead.stdout)
            _announce(folder, f"board-{stale}.json", dict(good, process=stale))
            _announce(folder, "board-1.json", dict(good, process=1, device=str(tmp_path)))
            _announce(folder, "board-2.json", "{not json")
            _announce(folder, "board-3.json", dict(good, process=3, vid="0x16c0"))
            _announce(folder, "board-4.json", dict(good, process=4, extra=1))
            _announce(folder, "board-5.json", " " * (announce.MAX_BYTES + 1))
            _announce(folder, "board-6.json", dict(good, process=7))
            (folder / "board-8.json").write_bytes(b"\xff\xfe{}")
            (folder / "board-9.json").mkdir()
            _announce(folder, "notes.txt", json.dumps(good))
            assert [(p.device, p.serial_number, p.source) for p in announce.announcements()] \
                == [(tty, "SERIAL1", "heliquad board")]
            assert ports.resolve_port("auto") == tty
        assert not os.path.exists(path)
    finally:
        os.close(main_fd)
        os.close(sub_fd)


def test_a_folder_of_another_user_is_not_read(listing, tmp_path, monkeypatch):
    main_fd, sub_fd = os.openpty()
    try:
        with announce.announced(os.ttyname(sub_fd), "SERIAL1", "host"):
            assert len(announce.announcements()) == 1
            monkeypatch.setattr(announce, "_uid", lambda: os.getuid() + 1)
            assert announce.announcements() == []
    finally:
        os.close(main_fd)
        os.close(sub_fd)


def test_a_running_board_is_found_and_its_announcement_goes_with_it(tmp_path):
    folder = tmp_path / "boards"
    env = dict(os.environ, **{announce.FOLDER_ENV: str(folder)})
    (tmp_path / "a").mkdir()
    with tool_runs.board_process(tmp_path / "a", env=env) as board:
        (announced,) = list(folder.iterdir())
        assert announced.name == f"board-{board.pid}.json"
        res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "params",
                              "--port", "auto", "get", "RATE_RLL_KC"],
                             capture_output=True, text=True, env=env,
                             timeout=tool_runs.HANG_GUARD_S)
        assert res.returncode == 0, res.stderr
        assert res.stderr == (f"port auto: {tmp_path / 'a' / 'rig'} (heliquad flight "
                              f"controller, serial {announce.HOST_BUILD_SERIAL}, heliquad "
                              "board)\n")
        assert res.stdout.startswith("RATE_RLL_KC ")
    assert board.returncode == 130
    assert not folder.exists()           # the file gone with the board, and its folder


def test_two_running_boards_are_listed_and_refused(tmp_path):
    folder = tmp_path / "boards"
    env = dict(os.environ, **{announce.FOLDER_ENV: str(folder)})
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with tool_runs.running_board(tmp_path / "a", env=env) as a, \
            tool_runs.running_board(tmp_path / "b", env=env) as b:
        res = subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", "params",
                              "--port", "auto", "list"],
                             capture_output=True, text=True, env=env,
                             timeout=tool_runs.HANG_GUARD_S)
        assert res.returncode == 2 and res.stdout == ""
        err = tool_runs.one_line(res.stderr)
        assert "--port auto: 2 heliquad boards found" in err
        assert f"{a} (heliquad flight controller, serial {announce.HOST_BUILD_SERIAL}" in err
        assert f"{b} (heliquad flight controller, serial {announce.HOST_BUILD_SERIAL}" in err
    assert not folder.exists()


def _held(folder, name, record):
    """An announcement whose lock the test holds, as its board would: the descriptor."""
    _announce(folder, name, record)
    fd = os.open(folder / name, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return fd


@pytest.fixture
def pty(listing):
    """A pty's terminal path, in the listing's empty announcement world."""
    main_fd, sub_fd = os.openpty()
    yield os.ttyname(sub_fd)
    os.close(main_fd)
    os.close(sub_fd)


def test_links_fifos_and_devices_that_are_no_ptys_of_this_user_are_refused(pty, tmp_path):
    folder = tmp_path / "boards"
    other_fd, other_sub = os.openpty()
    held = []
    try:
        with announce.announced(pty, "SERIAL1", "host") as path:
            good = json.loads(open(path).read())
            (folder / "board-10.json").symlink_to(path)
            (folder / "board-11.json").symlink_to("/dev/tty")
            os.mkfifo(folder / "board-12.json")
            held.append(_held(folder, "board-13.json", dict(good, process=13,
                                                              device="/dev/null")))
            other = os.ttyname(other_sub)           # a pty of another user's
            if os.getuid() == 0:
                os.chown(other, os.getuid() + 1, -1)
            else:
                other = "/dev/ptmx"                 # root's
            held.append(_held(folder, "board-14.json", dict(good, process=14, device=other)))
            held.append(_held(folder, "board-15.json\n", dict(good, process=15)))
            assert [p.device for p in announce.announcements()] == [pty]
            assert ports.resolve_port("auto") == pty
    finally:
        for fd in held + [other_fd, other_sub]:
            os.close(fd)


def test_a_folder_others_may_write_is_not_read(pty, tmp_path, capsys):
    folder = tmp_path / "boards"
    with announce.announced(pty, "SERIAL1", "host"):
        assert len(announce.announcements()) == 1
        folder.chmod(0o777)
        assert announce.announcements() == []
        # A board does not announce into it: it says so in one line and runs on.
        with announce.announced(pty, "SERIAL2", "host") as second:
            assert second is None
        assert capsys.readouterr().err == f"heliquad board: not announced in {folder} (group " \
            "or other may write it); --port auto will not find this board\n"
        folder.chmod(0o700)
    assert not folder.exists()


def test_a_stale_announcement_is_removed_and_a_locked_one_used(pty, tmp_path):
    folder = tmp_path / "boards"
    folder.mkdir(mode=0o700)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, sys; f = open(sys.argv[1]); "
         "fcntl.flock(f, fcntl.LOCK_EX); print(flush=True); sys.stdin.read()",
         str(folder / "board-7.json")], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        _announce(folder, "board-7.json", dict(_record(pty), process=7))
        holder.stdout.readline()                    # it holds the lock, as a board does
        assert [p.device for p in announce.announcements()] == [pty]
        assert (folder / "board-7.json").exists()
    finally:
        holder.communicate(b"", timeout=tool_runs.HANG_GUARD_S)
    # Its holder gone (a board killed outright), its number and pty may be anyone's.
    assert announce.announcements() == []
    assert not (folder / "board-7.json").exists()
    assert folder.exists()                         # a folder a board did not make stays


def _record(device):
    return {"format": announce.FORMAT, "version": announce.VERSION, "process": 1,
            "device": device, **facts.USB_IDENTITY._asdict(),
            "serial_number": "SERIAL1", "firmware": "host"}


def test_the_folder_is_absolute_and_a_failed_write_leaves_nothing(pty, tmp_path, monkeypatch,
                                                                  capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(announce.FOLDER_ENV, "relative")
    assert announce.folder() == str(tmp_path / "relative")

    def refuse(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", refuse)
    with announce.announced(pty, "SERIAL1", "host") as path:
        assert path is None
    assert "(No space left on device); --port auto will not find this board" in \
        capsys.readouterr().err
    assert list((tmp_path / "relative").iterdir()) == []


def test_a_sweep_records_that_auto_found_an_emulated_board(tmp_path):
    folder = tmp_path / "boards"
    env = dict(os.environ, **{announce.FOLDER_ENV: str(folder)})
    (tmp_path / "a").mkdir()
    out = tmp_path / "sweep"
    with tool_runs.running_board(tmp_path / "a", env=env):
        sweep = tool_runs.cli("sweep", "--axis", "roll", "--port", "auto", "--freqs-hz", 0.5,
                              "--out", out, env=env)
        try:
            assert sweep.stdout.readline().startswith("sweep: roll, ")
            assert sweep.stdout.readline() == (
                "port auto found: a board emulated by heliquad board (serial "
                f"{announce.HOST_BUILD_SERIAL}, firmware host), not a real one\n")
            deadline = time.monotonic() + tool_runs.HANG_GUARD_S
            while not (out / "manifest.json").exists() and time.monotonic() < deadline:
                time.sleep(0.05)                    # written before the hover starts
        finally:
            sweep.send_signal(signal.SIGINT)
            sweep.communicate(timeout=tool_runs.HANG_GUARD_S)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["source"] == {"kind": "port", "port": str(tmp_path / "a" / "rig"),
                                  "baud": 921600}
    assert manifest["port_found"] == {"source": "heliquad board", "firmware": "host",
                                      "serial_number": announce.HOST_BUILD_SERIAL}
    read_manifest(out / "manifest.json")          # its schema holds it
    assert list(manifest)[:4] == ["axis", "inject", "source", "port_found"]
