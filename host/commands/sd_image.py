"""``heliquad sd-image``: a fresh SD card image for the host build (docs/sd-card.md).

The file is a card of 512-byte blocks formatted FAT32 by the firmware's own FatFs (f_mkfs,
through its bindings), the volume at byte 0 with no partition table: give it to
heliquad-fw-host's --sd-image, read it with fsck.fat or mtools, or write it to a card. An
existing FILE is replaced once the new image is complete. Sizes: --size N in bytes, or with K,
M or G (binary multiples); a whole number of blocks from 40 MiB to 32 GiB.
"""

from __future__ import annotations

__all__ = ["add_parser"]


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("sd-image", help="a fresh FAT32 SD card image for the host build",
                       description=__doc__, formatter_class=fmt)
    p.add_argument("--size", metavar="N", default="64M",
                   help="the card's size: bytes, or with K, M or G (default 64M)")
    p.add_argument("file", metavar="FILE", help="the card image to write")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.card_image import parse_size, write_card_image

    size = parse_size(args.size)
    write_card_image(args.file, size)
    print(f"wrote {args.file}: a FAT32 card image of {size} bytes ({size >> 20} MiB)")
    return 0
