"""The log files on a card image (firmware/core/log/log_files.*, docs/sd-card.md), through the
bindings: logs written and read back by FatFs and by a second reader (tests/fat32_image.py),
`fsck.fat -n` after writes and after power cuts, the numbering and LASTLOG.TXT, and each of
the card-image file's faults (no card, write-protected, full, failing, busy)."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from heliquad import _firmware as fw
from heliquad.host.cli.parser import main
from heliquad.host.records.card_image import parse_size
from heliquad.sim.base.errors import InputError
from fat32_image import Fat32Image

State = fw.CardState
FSCK = shutil.which("fsck.fat")
needs_fsck = pytest.mark.skipif(FSCK is None, reason="fsck.fat (dosfstools) is not installed")
#: What `fsck.fat -n` may say after a power cut or a write the card refused, and why it is
#: harmless: clusters FatFs had
#: taken for a log's data whose size or FAT entries never reached the card (lost clusters,
#: a chain longer than the size), FSINFO's free count (a hint FatFs rewrites), the second FAT
#: behind the first (FatFs writes FAT 1, then FAT 2). Nothing else: no cross-linked or bad
#: chains, no damaged directory.
FSCK_AFTER_POWER_CUT = (
    r"fsck\.fat \d.*", r".*: \d+ files, \d+/\d+ clusters", r"Free cluster summary wrong.*",
    r"\s*Auto-correcting\.", r"\s*Leaving it unchanged\.",
    r"\d+ unused clusters?.*", r"Reclaimed \d+ unused clusters?.*",
    r".*File size is \d+ bytes, cluster chain length is > \d+ bytes\.",
    r"\s*Truncating file to \d+ bytes\.", r"FATs differ but appear to be intact\..*",
    r"\s*Using first FAT\.", r"/LOGS/\d{8}\.BIN",
    r"\s*Leaving filesystem unchanged\.", r"\s*",
)


def fsck(image) -> tuple[int, str]:
    run = subprocess.run([FSCK, "-n", str(image)], capture_output=True, text=True, check=False)
    return run.returncode, run.stdout + run.stderr


def assert_fsck_accepts(image) -> str:
    """fsck.fat -n finds the card clean, or says only what FSCK_AFTER_POWER_CUT allows; what
    it said when not clean ("" when clean)."""
    rc, out = fsck(image)
    if rc == 0:
        return ""
    assert rc == 1, out
    bad = [line for line in out.splitlines()
           if not any(re.fullmatch(p, line) for p in FSCK_AFTER_POWER_CUT)]
    assert not bad, out
    return out


@pytest.fixture(scope="module")
def blank(tmp_path_factory):
    """A fresh card image of the smallest size, made once and copied per test."""
    path = tmp_path_factory.mktemp("card") / "blank.img"
    assert fw.make_card_image(str(path), fw.MIN_CARD_IMAGE_BYTES) == ""
    return path


@pytest.fixture
def image(blank, tmp_path):
    path = tmp_path / "card.img"
    shutil.copyfile(blank, path)
    return path


def payload(log: int, n: int) -> bytes:
    return bytes((log * 7 + i * 13) & 0xFF for i in range(n))


def write_logs(card, sizes, chunk=3000):
    """Writes one log per size in chunks, syncing through the service every chunk."""
    for k, size in enumerate(sizes, start=1):
        assert card.begin_log()
        data = payload(k, size)
        for at in range(0, size, chunk):
            assert card.write(data[at:at + chunk]) == len(data[at:at + chunk])
            card.advance_us(fw.LOG_SYNC_PERIOD_US)
            card.service()
        card.end_log()


def test_logs_are_written_and_read_back_by_fatfs_and_by_a_second_reader(image):
    card = fw.CardFiles(str(image))
    assert card.mount() == State.OK
    sizes = [10_000, 1, 70_001]
    write_logs(card, sizes)
    assert card.count() == 3
    assert [card.info(i) for i in range(4)] == [(1, 10_000, 0), (2, 1, 0), (3, 70_001, 0), None]
    assert card.read(3, 0, 80_000) == payload(3, 70_001)
    assert card.read(3, 70_000, 10) == payload(3, 70_001)[-1:]
    assert card.read(3, 70_001, 10) == b""
    assert card.read(4, 0, 10) is None
    del card
    fat = Fat32Image(image)
    assert fat.listdir() == ["LASTLOG.TXT", "LOGS"]
    assert fat.listdir("LOGS") == ["00000001.BIN", "00000002.BIN", "00000003.BIN"]
    assert fat.read("LASTLOG.TXT") == b"3\r\n"
    for k, size in enumerate(sizes, start=1):
        assert fat.read(f"LOGS/{k:08d}.BIN") == payload(k, size)


@needs_fsck
def test_fsck_finds_a_card_clean_after_writes_and_an_erase(image):
    card = fw.CardFiles(str(image))
    card.mount()
    write_logs(card, [50_000, 20_000])
    assert fsck(image)[0] == 0, fsck(image)[1]
    assert card.erase_all()
    assert card.count() == 0
    assert card.begin_log() and card.last_log == 1       # the numbering starts again
    card.end_log()
    del card
    assert fsck(image)[0] == 0, fsck(image)[1]


def test_the_next_number_comes_from_lastlog_or_the_largest_log_present(image):
    card = fw.CardFiles(str(image))
    card.mount()
    write_logs(card, [100, 100])
    del card
    card = fw.CardFiles(str(image))
    card.mount()
    assert card.last_log == 2
    assert card.begin_log() and card.last_log == 3
    card.end_log()
    del card
    # LASTLOG.TXT damaged in place ("3\r\n" -> "x\r\n"): the largest log present counts.
    data = bytearray(image.read_bytes())
    at = Fat32Image(image).offset("LASTLOG.TXT")
    assert data[at:at + 3] == b"3\r\n"
    data[at] = ord("x")
    image.write_bytes(bytes(data))
    card = fw.CardFiles(str(image))
    card.mount()
    assert card.last_log == 3
    assert card.begin_log() and card.last_log == 4


def test_no_card_takes_no_log_and_lists_none(tmp_path):
    card = fw.CardFiles(str(tmp_path / "absent.img"))
    assert card.mount() == State.NO_CARD
    assert not card.begin_log() and card.write(b"x") == 0 and card.count() == 0
    assert card.state == State.NO_CARD


def test_a_card_set_as_missing_is_no_card(image):
    card = fw.CardFiles(str(image))
    card.set_faults(no_card=True)
    assert card.mount() == State.NO_CARD


def test_a_write_protected_card_takes_no_log_but_lists_its_logs(image):
    card = fw.CardFiles(str(image))
    card.mount()
    write_logs(card, [1000])
    del card
    card = fw.CardFiles(str(image))
    card.set_faults(write_protected=True)
    assert card.mount() == State.WRITE_PROTECTED
    assert not card.begin_log()
    assert card.count() == 1 and card.read(1, 0, 2000) == payload(1, 1000)


@needs_fsck
def test_a_full_card_stops_the_log_at_its_last_byte_losing_at_most_a_cluster(image):
    card = fw.CardFiles(str(image))
    card.mount()
    # Writes past a block 200 blocks into the data area fail, as on a card that is full.
    card.set_faults(writable_blocks=Fat32Image(image).data_at // 512 + 200)
    assert card.begin_log()
    taken = sum(card.write(payload(1, 4096)) for _ in range(100))
    assert card.state == State.FULL and 0 < taken < 100 * 4096
    assert card.write(b"more") == 0
    card.end_log()
    assert not card.begin_log()
    assert card.count() == 1 and card.read(1, 0, 8) == payload(1, 4096)[:8]
    del card
    assert_fsck_accepts(image)
    fat = Fat32Image(image)
    assert fat.listdir("LOGS") == ["00000001.BIN"]
    got = fat.read("LOGS/00000001.BIN")
    assert got == (payload(1, 4096) * 100)[:len(got)]
    card = fw.CardFiles(str(image))             # an erase makes room: the card is Ok again
    card.mount()
    card.set_faults(writable_blocks=Fat32Image(image).data_at // 512 + 200)
    assert card.begin_log() and card.write(payload(2, 10**6)) < 10**6 and card.state == State.FULL
    assert card.erase_all() and card.state == State.OK and card.count() == 0


@needs_fsck
def test_a_volume_filled_to_its_last_cluster_is_full_and_clean(image):
    card = fw.CardFiles(str(image))
    card.mount()
    assert card.begin_log()
    chunk = payload(1, 256 * 1024)
    taken = n = card.write(chunk)
    while n == len(chunk):
        n = card.write(chunk)
        taken += n
    assert card.state == State.FULL and taken > fw.MIN_CARD_IMAGE_BYTES * 9 // 10
    card.end_log()
    assert not card.begin_log() and card.info(0) == (1, taken, 0)
    del card
    rc, out = fsck(image)
    assert rc == 0, out
    assert re.search(r"(\d+)/\1 clusters", out), out      # every cluster in use


def test_failing_writes_fail_the_card(image):
    card = fw.CardFiles(str(image))
    card.mount()
    card.set_faults(failing_writes=True)
    assert not card.begin_log()
    assert card.state == State.FAILED


def test_a_busy_card_waits_through_the_hook_one_loop_step_per_poll(image):
    card = fw.CardFiles(str(image))
    card.mount()
    card.set_faults(busy_after_write_us=250_000)
    assert card.begin_log()
    before_us, polls = card.now_us, card.busy_polls
    assert card.write(payload(1, 512 * 8)) == 512 * 8
    card.end_log()
    assert card.state == State.OK
    assert card.busy_polls - polls >= 250_000 // 5000     # a 200 Hz step per poll, 250 ms each
    assert card.now_us - before_us >= 250_000
    assert card.read(1, 0, 10_000) == payload(1, 512 * 8)


def cut_run(image, cut_after: int) -> tuple[list[tuple[bytes, int]], int]:
    """Three logs written with syncs until the power goes after `cut_after` block writes (0:
    never); returns each begun log's bytes taken with how many of them a sync confirmed, and
    the blocks written."""
    card = fw.CardFiles(str(image))
    card.mount()
    card.set_faults(power_cut_after_writes=cut_after)
    logs = []
    for k in range(1, 4):
        if not card.begin_log():
            break
        data, synced = b"", 0
        for _ in range(6):
            data += payload(k, 1500)[:card.write(payload(k, 1500))]
            card.advance_us(fw.LOG_SYNC_PERIOD_US)
            card.service()
            if card.state != State.OK:
                break
            synced = len(data)
        card.end_log()
        logs.append((data, synced if card.state != State.OK else len(data)))
        if card.state != State.OK:
            break
    return logs, card.blocks_written


@needs_fsck
def test_power_cuts_leave_fsck_content_and_every_log_readable_to_its_last_sync(image, tmp_path):
    card = fw.CardFiles(str(image))
    assert card.mount() == State.OK          # LOGS/ made: the runs start from the same card
    del card
    run = tmp_path / "run.img"
    shutil.copyfile(image, run)
    logs, total = cut_run(run, 0)
    assert len(logs) == 3 and total > 40
    for cut in range(1, total, max(1, total // 40)):
        shutil.copyfile(image, run)
        logs, _ = cut_run(run, cut)
        assert_fsck_accepts(run)
        fat = Fat32Image(run)
        card = fw.CardFiles(str(run))
        assert card.mount() == State.OK
        for k, (data, synced) in enumerate(logs, start=1):
            name = f"{k:08d}.BIN"
            if name not in fat.listdir("LOGS"):
                assert synced == 0, (cut, k)
                continue
            got = fat.read("LOGS/" + name)
            assert len(got) >= synced and data.startswith(got), (cut, k)
            assert card.read(k, 0, 20_000) == got, (cut, k)
        del card


def test_sd_image_makes_a_card_the_file_layer_mounts(tmp_path, capsys):
    image = tmp_path / "card.img"
    image.write_bytes(b"old")
    assert main(["sd-image", "--size", "48M", str(image)]) == 0
    assert f"wrote {image}: a FAT32 card image of {48 << 20} bytes" in capsys.readouterr().out
    assert image.stat().st_size == 48 << 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["card.img"]   # no temporary left
    assert Fat32Image(image).listdir() == []
    card = fw.CardFiles(str(image))
    assert card.mount() == State.OK and card.count() == 0
    del card
    if FSCK:
        assert fsck(image)[0] == 0


def test_sd_image_sizes(tmp_path):
    assert parse_size("64M") == 64 << 20 and parse_size("1G") == 1 << 30
    assert parse_size(str(41943040)) == 40 << 20 and parse_size("65536K") == 64 << 20
    for bad in ("", "12Q", "1.5G", "-1M"):
        with pytest.raises(InputError, match="not a size"):
            parse_size(bad)
    with pytest.raises(InputError, match="512-byte blocks"):
        parse_size(str((48 << 20) + 100))
    with pytest.raises(InputError, match="40 MiB to 32 GiB"):
        parse_size("33G")
