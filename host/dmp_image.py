"""``heliquad dmp-image``: extract the MPU6050 DMP firmware image for the build.

The MotionApps 2.0 image (1929 bytes) is InvenSense's and is not in this repository. The
MIT-licensed PyPI package ``mpu6050`` (0.0.3) ships it as the list ``dmpMemory`` in
``mpu6050/MPUConstants.py``. That package imports ``smbus`` when imported, so the list is read
from the source text with ``ast`` instead. The source may be the installed package, the wheel
file, or the .py file itself.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.metadata
import zipfile

from .errors import InputError

__all__ = ["DMP_IMAGE_SIZE", "read_dmp_image", "add_dmp_image_parser"]

#: MotionApps 2.0: MPU6050_DMP_CODE_SIZE.
DMP_IMAGE_SIZE = 1929
MEMBER = "mpu6050/MPUConstants.py"


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
        except (OSError, KeyError, zipfile.BadZipFile) as exc:
            raise InputError(f"{source}: cannot read {MEMBER} ({exc})") from None
    try:
        with open(source) as fh:
            return fh.read()
    except OSError as exc:
        raise InputError(f"{source}: {exc.strerror}") from None


def read_dmp_image(source: str | None = None) -> bytes:
    """The DMP memory image from ``MPUConstants.dmpMemory`` (checked: 1929 bytes, 0..255)."""
    tree = ast.parse(_source_text(source))
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "dmpMemory"
                                                for t in node.targets):
            values = ast.literal_eval(node.value)
            if len(values) != DMP_IMAGE_SIZE or not all(0 <= v <= 255 for v in values):
                raise InputError(f"dmpMemory has {len(values)} entries; expected "
                                 f"{DMP_IMAGE_SIZE} bytes")
            return bytes(values)
    raise InputError("no dmpMemory list found in the source")


def add_dmp_image_parser(sub, fmt) -> None:
    p = sub.add_parser("dmp-image", help="extract the MPU6050 DMP image for the firmware build",
                       description=__doc__ + """
Build the firmware with it:  pip install . -Ccmake.define.HQ_DMP_IMAGE=$PWD/dmp.bin
or pass it at run time:      heliquad sil ... --dmp-image dmp.bin
""", formatter_class=fmt)
    p.add_argument("--source", metavar="FILE",
                   help="mpu6050 wheel (.whl) or MPUConstants.py (default: the installed package)")
    p.add_argument("--out", required=True, metavar="DMP.bin")
    p.set_defaults(func=_cmd)


def _cmd(args) -> int:
    image = read_dmp_image(args.source)
    with open(args.out, "wb") as fh:
        fh.write(image)
    print(f"wrote {len(image)} bytes to {args.out} (sha256 {hashlib.sha256(image).hexdigest()[:16]})")
    return 0
