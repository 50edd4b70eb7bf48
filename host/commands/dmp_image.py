"""``heliquad dmp-image``: extract the MPU6050's DMP firmware for the build.

The MotionApps 2.0 DMP firmware is InvenSense's and is not in this repository. It has three
parts, and a real chip needs all of them: the image (1929 bytes), the configuration table
(``dmpConfig``, 192 bytes) and the update table (``dmpUpdates``, 47 bytes). The MIT-licensed
PyPI package ``mpu6050`` (0.0.3) ships them as lists in ``mpu6050/MPUConstants.py``
(``dmpMemory``, ``dmpConfig``, ``dmpUpdates``). That package imports ``smbus`` when imported,
so the lists are read from the source text with ``ast`` instead. The source may be the
installed package, the wheel file, or the .py file itself.

The output is one file holding all three parts: magic, version, sizes and a CRC-32, then the
parts (docs/file-formats.md, "DMP firmware file"). A bare 1929-byte image written by earlier
versions is refused with a message to regenerate it.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.metadata
import struct
import zipfile
import zlib
from dataclasses import dataclass

from ...sim.base.errors import InputError

__all__ = ["DMP_IMAGE_SIZE", "DMP_CONFIG_SIZE", "DMP_UPDATES_SIZE", "DmpFirmware",
           "read_dmp_firmware", "pack_dmp_file", "unpack_dmp_file", "read_dmp_file",
           "table_entries", "add_parser"]

#: MotionApps 2.0: MPU6050_DMP_CODE_SIZE, MPU6050_DMP_CONFIG_SIZE, MPU6050_DMP_UPDATES_SIZE.
DMP_IMAGE_SIZE = 1929
DMP_CONFIG_SIZE = 192
DMP_UPDATES_SIZE = 47
#: The update table's entries (MotionApps writes them at four points of its sequence).
DMP_UPDATE_COUNT = 7
#: The one special command of the configuration table: 0x01, INT_ENABLE = 0x32.
SPECIAL_INT_ENABLE = 0x01
MEMBER = "mpu6050/MPUConstants.py"

# The file: magic, version, image/config/updates sizes (uint16 LE), CRC-32 (uint32 LE) of the
# first 12 bytes and everything after the header; then the three parts.
MAGIC = b"HQDM"
VERSION = 1
HEADER = struct.Struct("<4sHHHHI")
#: Limits the firmware's readers share (8 banks of DMP memory; tables of at most 1024 bytes).
MAX_IMAGE = 2048
MAX_TABLE = 1024


@dataclass(frozen=True)
class DmpFirmware:
    image: bytes
    config: bytes
    updates: bytes


def table_entries(table: bytes, *, specials: bool) -> list[tuple[int, int, bytes | int]]:
    """A MotionApps table's entries as (bank, offset, data) for memory writes and
    (bank, offset, code) for special commands (length 0). Raises InputError when the table
    does not parse to its end, or has a special command where none is allowed or an unknown
    one."""
    entries, pos = [], 0
    while pos < len(table):
        if pos + 3 > len(table):
            raise InputError(f"table entry at byte {pos} is cut short")
        bank, offset, length = table[pos:pos + 3]
        body = table[pos + 3:pos + 3 + max(length, 1)]
        if len(body) < max(length, 1):
            raise InputError(f"table entry at byte {pos} runs past the end ({length} bytes)")
        if length == 0:
            if not specials or body[0] != SPECIAL_INT_ENABLE:
                raise InputError(f"table entry at byte {pos}: special command {body[0]:#04x} "
                                 "is not MotionApps 2.0's")
            entries.append((bank, offset, body[0]))
        else:
            if bank * 256 + offset + length > MAX_IMAGE:
                raise InputError(f"table entry at byte {pos} writes past the DMP memory")
            entries.append((bank, offset, bytes(body)))
        pos += 3 + max(length, 1)
    return entries


def _check(fw: DmpFirmware) -> DmpFirmware:
    if not 1 <= len(fw.image) <= MAX_IMAGE:
        raise InputError(f"DMP image has {len(fw.image)} bytes; expected 1..{MAX_IMAGE}")
    for name, table, specials in (("configuration", fw.config, True),
                                  ("update", fw.updates, False)):
        if not 3 <= len(table) <= MAX_TABLE:
            raise InputError(f"DMP {name} table has {len(table)} bytes; expected 3..{MAX_TABLE}")
        try:
            entries = table_entries(table, specials=specials)
        except InputError as exc:
            raise InputError(f"DMP {name} table: {exc}") from None
        if name == "update" and len(entries) != DMP_UPDATE_COUNT:
            raise InputError(f"DMP update table has {len(entries)} entries; MotionApps 2.0 has "
                             f"{DMP_UPDATE_COUNT}")
    return fw


def pack_dmp_file(fw: DmpFirmware) -> bytes:
    """The file's bytes (docs/file-formats.md)."""
    _check(fw)
    payload = fw.image + fw.config + fw.updates
    head = HEADER.pack(MAGIC, VERSION, len(fw.image), len(fw.config), len(fw.updates), 0)[:12]
    crc = zlib.crc32(payload, zlib.crc32(head))
    return head + struct.pack("<I", crc) + payload


def unpack_dmp_file(data: bytes, name: str = "DMP firmware file") -> DmpFirmware:
    """The three parts of a file's bytes; InputError, in one line, for anything else (a bare
    image of the old format says to regenerate it)."""
    if data[:4] != MAGIC:
        if len(data) == DMP_IMAGE_SIZE:
            raise InputError(f"{name} is a bare {DMP_IMAGE_SIZE}-byte DMP image (the old format, "
                             "without the MotionApps configuration): regenerate it with "
                             "heliquad dmp-image")
        raise InputError(f"{name} is not a heliquad DMP firmware file (no HQDM magic): make one "
                         "with heliquad dmp-image")
    if len(data) < HEADER.size:
        raise InputError(f"{name} is shorter than its {HEADER.size}-byte header")
    _, version, n_image, n_config, n_updates, crc = HEADER.unpack_from(data)
    if version != VERSION:
        raise InputError(f"{name} is version {version}; this heliquad reads version {VERSION} "
                         "(regenerate it with heliquad dmp-image)")
    if len(data) != HEADER.size + n_image + n_config + n_updates:
        raise InputError(f"{name} has {len(data)} bytes; its header says "
                         f"{HEADER.size + n_image + n_config + n_updates} (truncated?)")
    payload = data[HEADER.size:]
    if zlib.crc32(payload, zlib.crc32(data[:12])) != crc:
        raise InputError(f"{name}: CRC-32 mismatch (damaged)")
    fw = DmpFirmware(payload[:n_image], payload[n_image:n_image + n_config],
                     payload[n_image + n_config:])
    try:
        return _check(fw)
    except InputError as exc:
        raise InputError(f"{name}: {exc}") from None


def read_dmp_file(path: str) -> DmpFirmware:
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror}") from None
    return unpack_dmp_file(data, path)


def _source_text(source: str | None) -> str:
    if source is None:
        try:
            files = importlib.metadata.files("mpu6050") or []
        except importlib.metadata.PackageNotFoundError:
            raise InputError("package mpu6050 is not installed: pip install mpu6050==0.0.3 "
                             "--no-deps, or give --source") from None
        match = [f for f in files if str(f).replace("\\", "/").endswith(MEMBER)]
        if not match:
            raise InputError(f"installed mpu6050 has no {MEMBER}")
        return match[0].read_text()
    if source.endswith(".whl"):
        try:
            with zipfile.ZipFile(source) as whl:
                return whl.read(MEMBER).decode()
        except (OSError, KeyError, zipfile.BadZipFile, UnicodeDecodeError) as exc:
            raise InputError(f"{source}: cannot read {MEMBER} "
                             f"({exc.strerror if isinstance(exc, OSError) else exc})") from None
    try:
        with open(source, encoding="utf-8") as fh:
            return fh.read()
    except OSError as exc:
        raise InputError(f"{source}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise InputError(f"{source}: not UTF-8 text: not a Python source file") from None


def _list(tree: ast.AST, name: str, size: int) -> bytes:
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name
                                                for t in node.targets):
            try:
                values = ast.literal_eval(node.value)
            except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
                raise InputError(f"{name} is not a list of numbers") from None
            if not isinstance(values, (list, tuple)):
                raise InputError(f"{name} is not a list of numbers")
            if len(values) != size or not all(type(v) is int and 0 <= v <= 255 for v in values):
                raise InputError(f"{name} has {len(values)} entries; expected {size} bytes "
                                 "(each 0..255)")
            return bytes(values)
    raise InputError(f"no {name} list found in the source")


def read_dmp_firmware(source: str | None = None) -> DmpFirmware:
    """The MotionApps 2.0 image and tables from ``MPUConstants`` (checked: 1929, 192 and 47
    bytes, the tables parse, seven updates)."""
    text = _source_text(source)
    try:
        tree = ast.parse(text)
    except (SyntaxError, ValueError) as exc:           # ValueError: a NUL byte
        raise InputError(f"{source or MEMBER}: not Python source "
                         f"({exc.msg if isinstance(exc, SyntaxError) else exc})") from None
    except (MemoryError, RecursionError):
        raise InputError(f"{source or MEMBER}: nested too deeply to read") from None
    try:
        return _read_parts(tree)
    except InputError as exc:
        raise InputError(f"{source or MEMBER}: {exc}") from None


def _read_parts(tree) -> DmpFirmware:
    return _check(DmpFirmware(_list(tree, "dmpMemory", DMP_IMAGE_SIZE),
                              _list(tree, "dmpConfig", DMP_CONFIG_SIZE),
                              _list(tree, "dmpUpdates", DMP_UPDATES_SIZE)))


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("dmp-image", help="extract the MPU6050 DMP firmware for the firmware build",
                       description=__doc__ + """
Build the firmware with it:  pip install . -Ccmake.define.HQ_DMP_IMAGE=$PWD/dmp.bin
or pass it at run time:      heliquad sil ... --dmp-image dmp.bin
""", formatter_class=fmt)
    p.add_argument("--source", metavar="FILE",
                   help="mpu6050 wheel (.whl) or MPUConstants.py (default: the installed package)")
    p.add_argument("--out", required=True, metavar="DMP.bin")
    p.set_defaults(func=_cmd)


def _cmd(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.output import atomic_write, check_output

    check_output(args.out, "--out")
    fw = read_dmp_firmware(args.source)
    data = pack_dmp_file(fw)
    with atomic_write(args.out, "wb") as fh:
        fh.write(data)
    print(f"wrote {len(data)} bytes to {args.out}: image {len(fw.image)}, configuration "
          f"{len(fw.config)}, updates {len(fw.updates)} bytes "
          f"(sha256 {hashlib.sha256(data).hexdigest()[:16]})")
    return 0
