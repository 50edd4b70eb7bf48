"""The Teensy 3.5 image in the install, and the one finder of it (heliquad.sim.base.firmware_image).

Three parts:

* The finder's order and its error, on images laid out in temporary folders.
* The CMake side (firmware/cmake/teensy35_image.cmake), configured on its own in a small
  project: without a complete ARM toolchain the install goes on and says why in one line,
  HQ_TEENSY_IMAGE=ON makes that an error, OFF never builds.
* The installed package: its RECORD holds the .elf and .hex, a fresh interpreter outside any
  checkout finds them, `heliquad flash` defaults to them, and they are the teensy35 preset's
  build of this tree byte for byte. Without an installed image these skip (the install had
  no toolchain), except in CI (CI set), which installs with HQ_TEENSY_IMAGE=ON.
"""

from __future__ import annotations

import importlib.metadata
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

from heliquad.sim.base import firmware_image
from heliquad.sim.base.firmware_image import ImageNotFound, teensy35_image
from heliquad.sim.rig.lockstep import FirmwareError

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from teensy_image import ROOT, image  # noqa: E402

PACKAGES = "apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi libstdc++-arm-none-eabi-dev"
ELF, HEX = "heliquad-fw-teensy35.elf", "heliquad-fw-teensy35.hex"


def skip_or_fail(message: str):
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


# ---------------------------------------------------------------- the finder's order -------

def put(folder: pathlib.Path, *names: str) -> pathlib.Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_bytes(f"{folder}/{name}".encode())
    return folder


def make_checkout(root: pathlib.Path, built: bool = True) -> pathlib.Path:
    (root / "firmware" / "targets" / "teensy35").mkdir(parents=True)
    (root / "CMakePresets.json").write_text("{}")
    if built:
        put(root / "build" / "teensy35", ELF, HEX)
    return root


@pytest.fixture
def layout(tmp_path, monkeypatch):
    """A package portion and a checkout of our own, nothing else: the module's own checkout
    and the real package are out of sight, the current directory is an empty folder."""
    monkeypatch.delenv("HQ_TEENSY35_ELF", raising=False)
    portion = tmp_path / "site-packages" / "heliquad"
    portion.mkdir(parents=True)
    monkeypatch.setattr(firmware_image, "_package_portions", lambda: [str(portion)])
    source = tmp_path / "source"
    source.mkdir()
    monkeypatch.setattr(firmware_image, "_SOURCE_ROOT", source)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    return {"portion": portion, "source": source, "cwd": elsewhere, "tmp": tmp_path}


def test_the_environment_variable_comes_first(layout, monkeypatch):
    put(layout["portion"] / "firmware" / "teensy35", ELF, HEX)
    own = put(layout["tmp"] / "mine", "fw.elf", "fw.hex")
    monkeypatch.setenv("HQ_TEENSY35_ELF", str(own / "fw.elf"))
    assert teensy35_image() == own / "fw.elf"
    assert teensy35_image("hex") == own / "fw.hex"          # the .hex beside the named .elf


def test_then_the_installed_image_then_the_checkouts_build(layout):
    make_checkout(layout["source"])
    installed = put(layout["portion"] / "firmware" / "teensy35", ELF, HEX)
    assert teensy35_image("elf") == installed / ELF
    assert teensy35_image("hex") == installed / HEX
    for name in (ELF, HEX):
        (installed / name).unlink()
    assert teensy35_image("elf") == layout["source"] / "build" / "teensy35" / ELF
    assert teensy35_image("hex") == layout["source"] / "build" / "teensy35" / HEX


def test_the_installed_image_is_found_in_any_portion_of_the_namespace(layout, monkeypatch):
    """An editable install's namespace has two portions: site-packages and the checkout."""
    second = put(layout["tmp"] / "other" / "heliquad" / "firmware" / "teensy35", ELF)
    monkeypatch.setattr(firmware_image, "_package_portions",
                        lambda: [str(layout["portion"]), str(second.parents[1])])
    assert teensy35_image() == second / ELF


def test_the_current_directory_counts_only_when_it_is_a_checkout(layout, monkeypatch):
    put(layout["cwd"] / "build" / "teensy35", ELF)             # a build folder, no checkout
    with pytest.raises(ImageNotFound):
        teensy35_image()
    checkout = make_checkout(layout["tmp"] / "clone")
    monkeypatch.chdir(checkout)
    assert teensy35_image() == checkout / "build" / "teensy35" / ELF


def test_a_checkout_without_a_build_is_passed_over(layout, monkeypatch):
    make_checkout(layout["source"], built=False)
    clone = make_checkout(layout["tmp"] / "clone")
    monkeypatch.chdir(clone)
    assert teensy35_image() == clone / "build" / "teensy35" / ELF


def one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text and text.strip() == text
    return text


def test_nothing_found_says_in_one_line_how_to_get_it(layout):
    make_checkout(layout["source"], built=False)
    with pytest.raises(ImageNotFound) as caught:
        teensy35_image("hex")
    text = one_line(caught.value)
    assert isinstance(caught.value, FirmwareError)            # the CLI's firmware errors
    assert HEX in text
    assert PACKAGES in text and "reinstall heliquad" in text
    assert "cmake --preset teensy35 && cmake --build --preset teensy35" in text


def test_a_variable_pointing_nowhere_is_an_error_not_a_fallback(layout, monkeypatch):
    put(layout["portion"] / "firmware" / "teensy35", ELF, HEX)
    nowhere = layout["tmp"] / "nowhere" / "fw.elf"
    monkeypatch.setenv("HQ_TEENSY35_ELF", str(nowhere))
    for kind, path in (("elf", nowhere), ("hex", nowhere.with_suffix(".hex"))):
        with pytest.raises(ImageNotFound) as caught:
            teensy35_image(kind)
        text = one_line(caught.value)
        assert f"no Teensy 3.5 image at {path} " in text and "HQ_TEENSY35_ELF" in text
        assert PACKAGES in text and "cmake --preset teensy35" in text


def test_an_unknown_kind_is_refused(layout):
    with pytest.raises(ValueError, match="kind"):
        teensy35_image("bin")


# ----------------------------------------------------------- the CMake side, on its own ------

CMAKE_PROJECT = """cmake_minimum_required(VERSION 3.20)
project(probe NONE)
include("{module}")
"""


def configure(tmp_path: pathlib.Path, *defines: str, path: str | None = None):
    """Configure a project that only includes teensy35_image.cmake; PATH is `path` (and
    CMake's system folders are not searched), so the ARM toolchain is there or not at will.
    (exit code, output)."""
    cmake, make = shutil.which("cmake"), shutil.which("make")
    if cmake is None or make is None:
        skip_or_fail("cmake and make are needed")
    src = tmp_path / "src"
    src.mkdir(parents=True, exist_ok=True)
    module = ROOT / "firmware" / "cmake" / "teensy35_image.cmake"
    (src / "CMakeLists.txt").write_text(CMAKE_PROJECT.format(module=module.as_posix()))
    env = dict(os.environ)
    if path is not None:
        env["PATH"] = path
    res = subprocess.run([cmake, "-S", str(src), "-B", str(tmp_path / "bin"),
                          "-G", "Unix Makefiles", f"-DCMAKE_MAKE_PROGRAM={make}",
                          "-DCMAKE_FIND_USE_CMAKE_SYSTEM_PATH=OFF",
                          f"-DPython3_EXECUTABLE={sys.executable}", *defines],
                         capture_output=True, text=True, env=env, timeout=120)
    return res.returncode, res.stdout + res.stderr


def flat(output: str) -> str:
    """CMake wraps error messages: one space between words."""
    return " ".join(output.split())


def fake_compiler(folder: pathlib.Path, newlib: bool, headers: bool) -> str:
    """An arm-none-eabi-g++ that has newlib-nano or not, the C++ headers or not."""
    folder.mkdir()
    script = folder / "arm-none-eabi-g++"
    libc = str(folder / "libc_nano.a") if newlib else "libc_nano.a"   # gcc's "not found"
    script.write_text("#!/bin/sh\ncase \"$*\" in\n"
                      f"  *-print-file-name=libc_nano.a*) echo {libc} ;;\n"
                      f"  *-fsyntax-only*) exit {0 if headers else 1} ;;\n"
                      "  *) exit 1 ;;\nesac\n")
    script.chmod(0o755)
    return str(folder)


def heliquad_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if "heliquad:" in line]


def test_no_toolchain_the_install_goes_on_with_one_line_saying_why(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    rc, out = configure(tmp_path, path=str(empty))
    assert rc == 0, out
    lines = heliquad_lines(out)
    assert len(lines) == 1, out
    assert "not built (arm-none-eabi-g++ not found)" in lines[0]
    assert PACKAGES in lines[0] and "reinstall heliquad" in lines[0]


def test_no_toolchain_with_the_image_required_is_a_configure_error(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    rc, out = configure(tmp_path, "-DHQ_TEENSY_IMAGE=ON", path=str(empty))
    assert rc != 0
    assert "HQ_TEENSY_IMAGE=ON but arm-none-eabi-g++ not found" in flat(out)
    assert PACKAGES in flat(out)


@pytest.mark.parametrize("newlib, headers, why", [
    (False, True, "has no newlib-nano (libc_nano.a)"),
    (True, False, "has no C++ standard headers"),
])
def test_a_partial_toolchain_is_named_not_half_built(tmp_path, newlib, headers, why):
    bindir = fake_compiler(tmp_path / "bin-fake", newlib=newlib, headers=headers)
    rc, out = configure(tmp_path, path=bindir)
    assert rc == 0, out
    lines = heliquad_lines(out)
    assert len(lines) == 1 and why in lines[0] and PACKAGES in lines[0], out
    rc, out = configure(tmp_path, "-DHQ_TEENSY_IMAGE=ON", path=bindir)
    assert rc != 0 and why in flat(out)


def test_off_never_builds_and_a_wrong_value_is_refused(tmp_path):
    rc, out = configure(tmp_path, "-DHQ_TEENSY_IMAGE=OFF")
    assert rc == 0 and heliquad_lines(out) == [
        "-- heliquad: the Teensy 3.5 image is not built (HQ_TEENSY_IMAGE=OFF)"], out
    rc, out = configure(tmp_path / "again", "-DHQ_TEENSY_IMAGE=maybe")
    assert rc != 0 and "use AUTO, ON or OFF" in flat(out)


def test_with_the_toolchain_the_image_is_built_with_the_preset(tmp_path):
    if not shutil.which("arm-none-eabi-g++"):
        skip_or_fail(f"arm-none-eabi-g++ not found: {PACKAGES}")
    rc, out = configure(tmp_path, "-DHQ_TEENSY_IMAGE=ON")
    assert rc == 0, out
    assert "building the Teensy 3.5 image with" in out and "(preset teensy35)" in out
    # The image's own build runs the preset, and nothing but the preset decides its flags.
    [recorded] = (tmp_path / "bin").rglob("hq_teensy35_image-cfgcmd.txt")
    command = recorded.read_text()
    assert "--preset;teensy35" in command and "CMAKE_CXX_FLAGS" not in command
    assert f"-DPython3_EXECUTABLE={sys.executable}" in command


# ------------------------------------------------------------------ the installed image -------

def installed_files() -> dict[str, pathlib.Path]:
    """The image's files as the installed distribution records them (its wheel's RECORD)."""
    dist = importlib.metadata.distribution("heliquad")
    found = {}
    for f in dist.files or ():
        if f.parent.as_posix() == "heliquad/firmware/teensy35" and f.name in (ELF, HEX):
            found[f.name] = pathlib.Path(dist.locate_file(f)).resolve()
    if set(found) != {ELF, HEX}:
        skip_or_fail("the installed heliquad has no Teensy 3.5 image (installed without the "
                     f"ARM toolchain: {PACKAGES}, then reinstall heliquad)")
    return found


def test_the_install_records_the_image_in_the_package():
    found = installed_files()
    for name, path in found.items():
        assert path.is_file(), f"{path} is recorded but missing"
        assert path.parent.parts[-3:] == ("heliquad", "firmware", "teensy35")
    assert found[ELF].read_bytes()[:4] == b"\x7fELF"
    assert found[HEX].read_text().startswith(":")


def run_fresh(args: list[str], cwd: pathlib.Path, **env_extra: str):
    """A new interpreter outside any checkout, without HQ_TEENSY35_ELF unless given."""
    env = {k: v for k, v in os.environ.items() if k not in ("HQ_TEENSY35_ELF", "PYTHONPATH")}
    env.update(env_extra)
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120, stdin=subprocess.DEVNULL)


def test_a_fresh_interpreter_finds_the_installed_image(tmp_path):
    found = installed_files()
    res = run_fresh(["-c", "from heliquad.sim.base.firmware_image import teensy35_image as t; "
                           "print(t()); print(t('hex'))"], cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert [pathlib.Path(line).resolve() for line in res.stdout.split()] == [found[ELF], found[HEX]]


def test_flash_defaults_to_the_installed_image(tmp_path):
    found = installed_files()
    res = run_fresh(["-m", "heliquad.host.cli.parser", "flash", "--check-only"], cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    path = res.stdout.split(": ")[0]
    assert pathlib.Path(path).resolve() == found[HEX]
    res = run_fresh(["-m", "heliquad.host.cli.parser", "flash", "--check-only"], cwd=tmp_path,
                    HQ_TEENSY35_ELF=str(tmp_path / "none.elf"))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "none.hex" in res.stderr and PACKAGES in res.stderr


def differing_sections(a: pathlib.Path, b: pathlib.Path) -> list[str]:
    from elftools.elf.elffile import ELFFile

    with open(a, "rb") as fa, open(b, "rb") as fb:
        ea, eb = ELFFile(fa), ELFFile(fb)
        names = {s.name for s in ea.iter_sections()} | {s.name for s in eb.iter_sections()}
        out = []
        for name in sorted(names):
            sa, sb = ea.get_section_by_name(name), eb.get_section_by_name(name)
            if sa is None or sb is None or sa.data() != sb.data() or sa["sh_addr"] != sb["sh_addr"]:
                out.append(name)
        return out


def test_the_installed_image_is_the_presets_build_byte_for_byte():
    found = installed_files()
    img = image()                      # cmake --preset teensy35 of this tree, into build/teensy35
    if found[ELF].read_bytes() != img.elf.read_bytes():
        pytest.fail(f"the installed {ELF} is not the teensy35 preset's build of {ROOT} "
                    f"(sections differing: {differing_sections(found[ELF], img.elf)}): "
                    "reinstall heliquad after a firmware change (and without HQ_DMP_IMAGE, "
                    "which this preset build has not)")
    assert found[HEX].read_bytes() == img.hex.read_bytes()
