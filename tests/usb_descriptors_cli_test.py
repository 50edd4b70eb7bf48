"""`heliquad usb-descriptors`: the image enumerated in the emulated chip, its descriptors
printed decoded and written as the host read them (read back here by an independent parser,
usb-protocol), and the inputs it refuses in one line (exit 2): no image, a file that is not
an ELF or not an ARM one, an image without a USB port, an --out folder that holds files."""

from __future__ import annotations

import pathlib
import shutil
import sys

import pytest
from elftools.elf.elffile import ELFFile

from heliquad.host.cli.parser import main
from heliquad.sim.base.firmware_facts import USB_IDENTITY
from heliquad.sim.chip import Image

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from teensy_image import image  # noqa: E402

THUMB_RETURN = bytes.fromhex("7047")                    # bx lr


def run(capsys, *argv):
    rc = main(["usb-descriptors", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def one_error(err: str, *words) -> bool:
    lines = err.strip().splitlines()
    return len(lines) == 1 and lines[0].startswith("heliquad usb-descriptors: error: ") and \
        all(w in lines[0] for w in words)


def _descriptors(raw: bytes):
    """(type, bytes) of each descriptor in a configuration's bytes."""
    at = 0
    while at < len(raw):
        yield raw[at + 1], raw[at:at + raw[at]]
        at += raw[at]


@pytest.mark.pil
def test_the_files_parse_with_usb_protocol_and_match_the_print(tmp_path, capsys):
    standard = pytest.importorskip("usb_protocol.types.descriptors.standard")
    out_dir = tmp_path / "usb"
    rc, out, err = run(capsys, "--image", image().elf, "--out", out_dir)
    assert rc == 0 and err == "", err
    assert sorted(p.name for p in out_dir.iterdir()) == ["config.bin", "device.bin"]
    device, config = (out_dir / "device.bin").read_bytes(), (out_dir / "config.bin").read_bytes()
    lines = out.splitlines()
    assert lines[0].startswith(f"{image().elf}: enumerated as Linux does (10 control transfers")

    dev = standard.DeviceDescriptor.parse(device)
    release = int(f"{100 * dev.bcdDevice:.0f}", 16)             # usb-protocol reads BCD as 1.0
    assert (dev.idVendor, dev.idProduct) == (USB_IDENTITY.vid, USB_IDENTITY.pid)
    assert lines[1] == (f"device: USB {dev.bcdUSB:.2f}, VID 0x{dev.idVendor:04X}, PID "
                        f"0x{dev.idProduct:04X}, release 0x{release:04X}, "
                        f"class 0x{dev.bDeviceClass:02X}/0x{dev.bDeviceSubclass:02X}/"
                        f"0x{dev.bDeviceProtocol:02X}, EP0 {dev.bMaxPacketSize0} bytes")
    assert f"manufacturer {USB_IDENTITY.manufacturer!r}, product {USB_IDENTITY.product!r}" \
        in lines[2]

    cfg = standard.ConfigurationDescriptor.parse(config[:9])
    assert cfg.wTotalLength == len(config)
    assert lines[3] == (f"configuration {cfg.bConfigurationValue}: {len(config)} bytes, "
                        f"attributes 0x{config[7]:02X}, {2 * config[8]} mA")
    expected, associations = [], []
    names = iter(["header", "call management", "abstract control management", "union"])
    for kind, d in _descriptors(config[9:]):
        if kind == 4:
            i = standard.InterfaceDescriptor.parse(d)
            expected.append(f"  interface {i.bInterfaceNumber}.{i.bAlternateSetting}: class "
                            f"0x{i.bInterfaceClass:02X}/0x{i.bInterfaceSubclass:02X}/"
                            f"0x{i.bInterfaceProtocol:02X}")
        elif kind == 5:
            e = standard.EndpointDescriptor.parse(d)
            kind_name = ("control", "isochronous", "bulk", "interrupt")[e.bmAttributes & 3]
            direction = "in" if e.bEndpointAddress & 0x80 else "out"
            expected.append(f"    endpoint 0x{e.bEndpointAddress:02X} {direction} {kind_name}, "
                            f"{e.wMaxPacketSize} bytes, interval {e.bInterval}")
        elif kind == 0x24:          # CDC functional, in the order CDC-ACM lists them
            expected.append(f"    CDC {next(names)}: {d[3:].hex()}")
        elif kind == 0x0B:
            associations.append(f"  interface association: interfaces {d[2]}-{d[2] + d[3] - 1}, "
                                f"class 0x{d[4]:02X}/0x{d[5]:02X}/0x{d[6]:02X}")
    assert next(names, None) is None and len(associations) == 1
    assert lines[4:-1] == expected + associations
    assert lines[-1] == (f"wrote {out_dir / 'device.bin'} (18 bytes) and "
                         f"{out_dir / 'config.bin'} ({len(config)} bytes)")


@pytest.mark.pil
def test_an_image_without_a_usb_port_is_refused(tmp_path, capsys):
    """The image with UsbCdcSerial::begin returning at once: the port never attaches."""
    patched = tmp_path / "no-usb.elf"
    shutil.copyfile(image().elf, patched)
    address = Image(patched).symbol("hq::teensy::UsbCdcSerial::begin").address
    with open(patched, "r+b") as fh:
        segment = next(s for s in ELFFile(fh).iter_segments() if s["p_type"] == "PT_LOAD"
                       and s["p_vaddr"] <= address < s["p_vaddr"] + s["p_filesz"])
        fh.seek(segment["p_offset"] + address - segment["p_vaddr"])
        fh.write(THUMB_RETURN)
    out_dir = tmp_path / "new"
    rc, out, err = run(capsys, "--image", patched, "--out", out_dir)
    assert rc == 2 and out == ""
    assert one_error(err, str(patched), "no USB device attached", "without a USB port")
    assert not out_dir.exists(), "a failed run leaves no folder behind"


def test_no_default_image_says_how_to_get_one(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HQ_TEENSY35_ELF", str(tmp_path / "missing.elf"))
    rc, out, err = run(capsys)
    assert rc == 2 and out == ""
    assert one_error(err, "missing.elf", "cmake --preset teensy35", "or give --image ELF")


@pytest.mark.parametrize("make, words", [
    (lambda d: d / "absent.elf", ["absent.elf", "No such file"]),
    (lambda d: d, ["is a folder, not an ELF image"]),
    (lambda d: (d / "fw.hex").write_text(":00000001FF\n") and d / "fw.hex",
     ["fw.hex", "not an ELF file", "not its .hex"]),
    (lambda d: (d / "cut.elf").write_bytes(b"\x7fELF\x01\x01") and d / "cut.elf",
     ["cut.elf", "a damaged ELF", "not a Teensy 3.5 image"]),
    (lambda d: pathlib.Path(sys.executable).resolve(), ["not a Teensy 3.5 image", "ARM"]),
])
def test_files_that_are_not_an_image_are_refused(tmp_path, capsys, make, words):
    path = make(tmp_path)
    out_dir = tmp_path / "out"
    rc, out, err = run(capsys, "--image", path, "--out", out_dir)
    assert rc == 2 and out == ""
    assert one_error(err, *words), err
    assert not out_dir.exists(), "a failed run leaves no folder behind"


def test_an_out_folder_with_files_in_it_is_refused_before_anything_runs(tmp_path, capsys):
    out_dir = tmp_path / "earlier"
    out_dir.mkdir()
    (out_dir / "device.bin").write_bytes(b"mine")
    rc, out, err = run(capsys, "--image", tmp_path / "absent.elf", "--out", out_dir)
    assert rc == 2 and out == ""
    assert one_error(err, str(out_dir), "is not empty", "give another --out")
    assert (out_dir / "device.bin").read_bytes() == b"mine"


def test_help_says_what_it_reads_and_writes(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["usb-descriptors", "--help"])
    out = capsys.readouterr().out
    assert stop.value.code == 0
    for words in ("as Linux does", "device.bin", "config.bin", "new or empty", "--image ELF",
                  "HQ_TEENSY35_ELF", "exit 2"):
        assert words in out, words
