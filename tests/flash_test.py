"""`heliquad flash`: the image is checked before the loader ever sees it, and the loader is
run exactly as PJRC's command-line loader expects for a Teensy 3.5."""

from __future__ import annotations

import pathlib
import stat
import sys

import pytest
from intelhex import IntelHex

from heliquad.host.cli.parser import main

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from teensy_image import image  # noqa: E402


def make_image(path, *, sp=0x2002_0000, reset=0x411, fsec=0xFE, extra=None, config=True):
    ih = IntelHex()
    for i, b in enumerate(sp.to_bytes(4, "little") + reset.to_bytes(4, "little")):
        ih[i] = b
    for a in range(8, 0x400):
        ih[a] = 0
    if config:
        for i, b in enumerate(bytes([0xFF] * 12 + [fsec, 0xF9, 0xFF, 0xFF])):
            ih[0x400 + i] = b
    for a in range(0x410, 0x420):
        ih[a] = 0x70
    for a, b in (extra or {}).items():
        ih[a] = b
    ih.write_hex_file(str(path))
    return path


def fake_loader(tmp_path, exit_code=0):
    """A stand-in for teensy_loader_cli that records its arguments."""
    record = tmp_path / "loader-args"
    script = tmp_path / "fake_loader"
    script.write_text(f"#!/bin/sh\nprintf '%s\\n' \"$@\" > {record}\nexit {exit_code}\n")
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return script, record


def run(capsys, *argv):
    rc = main(["flash", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def test_check_only_reports_a_valid_image(tmp_path, capsys):
    hexfile = make_image(tmp_path / "ok.hex")
    rc, out, err = run(capsys, hexfile, "--check-only")
    assert rc == 0 and err == ""
    assert "FSEC 0xFE (unsecure)" in out and "stack 0x20020000" in out


def test_the_built_image_passes_the_check(capsys):
    img = image()
    rc, out, _ = run(capsys, img.hex, "--check-only")
    assert rc == 0 and "% of the Teensy 3.5's flash" in out


@pytest.mark.parametrize("kwargs, why", [
    ({"fsec": 0xFF}, "would secure the chip"),
    ({"fsec": 0xFD}, "would secure the chip"),
    ({"extra": {0x8_0000: 1}}, "beyond the Teensy 3.5's 512 KiB"),
    ({"config": False}, "no vector table or flash configuration field"),
    ({"sp": 0x1000_0000}, "initial stack pointer"),
    ({"sp": 0x2001_FFFC}, "initial stack pointer"),                # not 8-aligned
    ({"reset": 0x410}, "not a Thumb address"),
    ({"reset": 0x9001}, "not a Thumb address"),
])
def test_images_that_would_harm_or_not_boot_are_refused(tmp_path, capsys, kwargs, why):
    loader, record = fake_loader(tmp_path)
    hexfile = make_image(tmp_path / "bad.hex", **kwargs)
    rc, out, err = run(capsys, hexfile, "--loader", loader)
    assert rc == 2 and why in err and len(err.strip().splitlines()) == 1
    assert not record.exists(), "the loader must not run"


def test_a_file_that_is_not_intel_hex_is_refused(tmp_path, capsys):
    bad = tmp_path / "x.hex"
    bad.write_text("hello\n")
    rc, _, err = run(capsys, bad, "--check-only")
    assert rc == 2 and "not an Intel HEX file" in err
    rc, _, err = run(capsys, tmp_path / "missing.hex", "--check-only")
    assert rc == 2 and "no such file" in err


def test_the_loader_runs_with_the_teensy35_arguments(tmp_path, capsys):
    loader, record = fake_loader(tmp_path)
    hexfile = make_image(tmp_path / "ok.hex")
    rc, out, err = run(capsys, hexfile, "--loader", loader)
    assert rc == 0, err
    assert record.read_text().split() == ["--mcu=TEENSY35", "-w", "-s", "-v", str(hexfile)]
    assert "flashed" in out
    assert "reboots into its bootloader by itself" in out and "press the program button" in out


def test_no_soft_reboot_leaves_the_button_to_the_user(tmp_path, capsys):
    """--no-soft-reboot: the loader without -s (it then only waits for the bootloader)."""
    loader, record = fake_loader(tmp_path)
    hexfile = make_image(tmp_path / "ok.hex")
    rc, out, err = run(capsys, hexfile, "--loader", loader, "--no-soft-reboot")
    assert rc == 0, err
    assert record.read_text().split() == ["--mcu=TEENSY35", "-w", "-v", str(hexfile)]
    assert "reboots into its bootloader" not in out
    assert "press the program button on the Teensy" in out and "flashed" in out


def test_check_only_runs_no_loader_whatever_the_reboot_option(tmp_path, capsys):
    loader, record = fake_loader(tmp_path)
    hexfile = make_image(tmp_path / "ok.hex")
    for extra in ((), ("--no-soft-reboot",)):
        rc, out, err = run(capsys, hexfile, "--check-only", "--loader", loader, *extra)
        assert rc == 0 and err == "" and "running:" not in out
    assert not record.exists(), "the loader must not run"


def test_a_failing_loader_fails_the_command(tmp_path, capsys):
    loader, _ = fake_loader(tmp_path, exit_code=1)
    rc, _, err = run(capsys, make_image(tmp_path / "ok.hex"), "--loader", loader)
    assert rc == 1 and "failed (exit 1)" in err


def test_a_missing_loader_says_how_to_get_it(tmp_path, capsys):
    rc, _, err = run(capsys, make_image(tmp_path / "ok.hex"), "--loader",
                     "no-such-loader-here")
    assert rc == 2 and "apt-get install teensy-loader-cli" in err


def test_no_default_image_says_how_to_get_it(tmp_path, capsys, monkeypatch):
    # Wherever the finder would look, nothing: HQ_TEENSY35_ELF is authoritative when set.
    loader, record = fake_loader(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HQ_TEENSY35_ELF", str(tmp_path / "missing.elf"))
    rc, _, err = run(capsys, "--loader", loader)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "missing.hex" in err and "cmake --preset teensy35" in err
    assert "apt-get install gcc-arm-none-eabi" in err and "or give HEX" in err
    assert not record.exists(), "the loader must not run"


def test_the_default_image_is_the_finders(tmp_path, capsys, monkeypatch):
    """No HEX: the .hex the finder names (here beside $HQ_TEENSY35_ELF), checked and flashed."""
    loader, record = fake_loader(tmp_path)
    hexfile = make_image(tmp_path / "fw.hex")
    monkeypatch.setenv("HQ_TEENSY35_ELF", str(tmp_path / "fw.elf"))
    rc, out, err = run(capsys, "--loader", loader)
    assert rc == 0, err
    assert record.read_text().split() == ["--mcu=TEENSY35", "-w", "-s", "-v", str(hexfile)]
    assert out.startswith(f"{hexfile}: ")
