"""The SD card on the host build (heliquad-fw-host --sd-image, docs/sd-card.md): a card image
made FAT32 when the file is missing, the card's state on its start-up lines, LOGS/ on the card,
and a vehicle that arms and flies whatever the card's state (no card, write-protected, full,
failing: logging is not a flight safety item)."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from heliquad import _firmware as fw
from heliquad.sim.base.errors import FirmwareError
from heliquad.sim.rig.lockstep import HostFirmware
from fat32_image import Fat32Image
from firmware_rig import FirmwareRig


class CardFirmware(HostFirmware):
    """heliquad-fw-host with a card image and the faults given."""

    def __init__(self, image, faults: str = ""):
        self.card_args = ["--sd-image", str(image)] + (["--sd-faults", faults] if faults else [])
        super().__init__()

    def command(self) -> list:
        return super().command() + self.card_args


def fly(image, faults: str = "") -> list:
    """Start the firmware on the card, arm and hover; its start-up lines."""
    with CardFirmware(image, faults) as firmware:
        rig = FirmwareRig(firmware)
        try:
            assert rig.hover().armed
        finally:
            rig.close()
        return firmware.startup_lines


def test_a_missing_image_becomes_a_fresh_fat32_card_with_logs_folder(tmp_path):
    image = tmp_path / "card.img"
    lines = fly(image)
    assert "card: ok" in lines and lines[-1] == "ready"
    assert image.stat().st_size == fw.DEFAULT_CARD_IMAGE_BYTES
    fat = Fat32Image(image)                   # the hover armed: its log is the first
    assert fat.listdir() == ["LASTLOG.TXT", "LOGS"] and fat.listdir("LOGS") == ["00000001.BIN"]
    assert fat.read("LASTLOG.TXT") == b"1\r\n"
    if shutil.which("fsck.fat"):
        run = subprocess.run(["fsck.fat", "-n", str(image)], capture_output=True, text=True)
        assert run.returncode == 0, run.stdout


@pytest.mark.parametrize("faults, says", [
    ("no_card", "card: no card"),
    ("write_protected", "card: write-protected"),
    ("writable_blocks=1", "card: full"),
    ("failing_writes", "card: failed"),
])
def test_the_vehicle_arms_whatever_the_card_and_its_state_is_said(tmp_path, faults, says):
    image = tmp_path / "card.img"
    assert fw.make_card_image(str(image), fw.MIN_CARD_IMAGE_BYTES) == ""
    assert says in fly(image, faults)


def test_no_sd_image_is_no_card_line_at_all(tmp_path):
    with HostFirmware() as firmware:
        assert not [line for line in firmware.startup_lines if line.startswith("card:")]


def test_an_unknown_fault_or_a_folder_is_refused_in_one_line(tmp_path):
    with pytest.raises(FirmwareError, match="unknown --sd-faults fault frobnicate"):
        CardFirmware(tmp_path / "card.img", "frobnicate")
    with pytest.raises(FirmwareError, match="is a folder, not a card image"):
        CardFirmware(tmp_path)
    with pytest.raises(FirmwareError, match="No such file or directory"):
        CardFirmware(tmp_path / "missing" / "card.img")
