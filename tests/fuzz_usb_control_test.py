"""The firmware's fuzz_usb_control target (the Teensy 3.5 image's USB port on a fake device
controller) built with clang as tests/fuzz/run.py builds it and run over its seed inputs: a
Linux enumeration, both 134-baud bootloader requests and a 135-baud one. Skipped without
clang; what fuzzing found in the vendored TinyUSB is recorded here."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "fuzz"))

import run as fuzz_run  # noqa: E402
import usb_control_seeds as seeds  # noqa: E402

pytestmark = pytest.mark.skipif(
    not all(shutil.which(tool) for tool in ("clang", "clang++", "cmake")),
    reason="needs clang, clang++ and cmake (the firmware fuzz build)")

TARGET = fuzz_run.BY_NAME["usb_control"]
RUN_TIMEOUT_S = 120


@pytest.fixture(scope="module")
def executable(tmp_path_factory):
    work = fuzz_run.Work(tmp_path_factory.mktemp("usb-fuzz"))
    (work.root / "logs").mkdir()
    error = fuzz_run.build_firmware([TARGET], work)
    assert error is None, error
    return work.build / TARGET.executable


def run_inputs(executable: Path, inputs: dict, folder: Path) -> subprocess.CompletedProcess:
    """The target over the inputs (libFuzzer runs each file once), with its per-input line."""
    paths = []
    for label, data in inputs.items():
        path = folder / label
        path.write_bytes(data)
        paths.append(str(path))
    return subprocess.run([str(executable), *paths], capture_output=True, text=True,
                          env={**os.environ, "HQ_FUZZ_USB_LOG": "1"}, timeout=RUN_TIMEOUT_S)


def summary(executable: Path, data: bytes, folder: Path) -> str:
    done = run_inputs(executable, {"input": data}, folder)
    assert done.returncode == 0, done.stderr[-3000:]
    return [line for line in done.stdout.splitlines() if line.startswith("usb:")][-1]


def test_the_seed_inputs_run_clean(executable, tmp_path):
    done = run_inputs(executable, seeds.seed_inputs(), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "ERROR" not in done.stderr and "runtime error" not in done.stderr


@pytest.mark.parametrize("label, bootloader", [
    ("linux-enumeration", 0), ("bootloader-134-baud", 1), ("bootloader-1-byte", 1),
    ("line-coding-135-baud", 0)])
def test_the_seeds_enumerate_open_the_port_and_ask_for_the_bootloader_at_134_baud(
        executable, tmp_path, label, bootloader):
    line = summary(executable, seeds.seed_inputs()[label], tmp_path)
    assert line.startswith(f"usb: mounted 1 open 1 bootloader {bootloader} ")


def test_a_port_closed_by_the_host_is_seen_closed(executable, tmp_path):
    data = seeds.linux_enumeration() + bytes((seeds.LINE_STATE, 0, seeds.TASK, seeds.EP0_IN,
                                              seeds.SUCCESS, seeds.TASK))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 1 open 0 ")


# Found by fuzzing: TinyUSB 0.21.0's usbd.c answers GET_STATUS, GET_CONFIGURATION and
# GET_INTERFACE from a local variable of the function handling the SETUP, whatever the
# request's direction bit says. With the bit clear (host to device) and wLength > 0 the data
# stage is OUT, and when the host's bytes arrive, in a later tud_task, usbd_control_xfer_cb
# copied them (up to 2) to that local's address, long out of scope: the host wrote into the
# loop's stack (ASan: stack-use-after-scope). The port layer's request guard
# (usb_request_guard.cpp) stalls such requests before the stack sees them.
@pytest.mark.parametrize("bm_request_type, b_request, w_index", [
    (0x00, 0, 0), (0x00, 8, 0),           # GET_STATUS, GET_CONFIGURATION of the device
    (0x01, 10, 0),                        # GET_INTERFACE of the CDC interface
    (0x02, 0, 0x82)])                     # GET_STATUS of the bulk IN endpoint
def test_a_get_request_with_an_out_data_stage_is_refused(executable, tmp_path, bm_request_type,
                                                         b_request, w_index):
    data = (seeds.linux_enumeration() + seeds.setup(bm_request_type, b_request, 0, w_index, 2)
            + bytes((seeds.TASK, seeds.EP0_OUT, 2, 0x5A, 0xA5, seeds.SUCCESS, seeds.TASK)))
    done = run_inputs(executable, {"get-request-out": data}, tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]


# Found by fuzzing, a false alarm of the harness: the host sent a 134-baud SET_LINE_CODING's
# data stage, then reset the bus before its status stage. The stack handled the queued OUT
# completion first (and armed the status stage's zero-length IN), then the reset, which
# clears the control transfer: the ACK that applies the line coding never comes, as on the
# chip. The fake host then read that IN on EP0 and counted a status stage of a transfer the
# reset had abandoned; a host sends EP0 tokens only inside a control transfer it began with a
# SETUP, so the fake controller now lets none through after a reset until the next SETUP.
@pytest.mark.parametrize("coding", [seeds.line_coding(seeds.BOOTLOADER_BAUD),
                                    bytes((seeds.BOOTLOADER_BAUD,))])
def test_a_bootloader_request_abandoned_by_a_bus_reset_is_not_applied(executable, tmp_path,
                                                                      coding):
    request = seeds.setup(0x21, seeds.SET_LINE_CODING, 0, 0, len(coding))
    data = (seeds.linux_enumeration() + request
            + bytes((seeds.TASK, seeds.EP0_OUT, len(coding))) + coding
            + bytes((seeds.SUCCESS, seeds.RESET, seeds.TASK, seeds.EP0_IN, seeds.SUCCESS,
                     seeds.TASK)))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 0 open 0 bootloader 0 ")


# The same reset, seen from the device's side: a SETUP the host sent before it reset the bus
# is still queued, and the stack answers it (here when the next SETUP comes). The answer is
# held to that SETUP's wLength, not to nothing: the reset abandons the transfer for the host,
# it does not unsend the request.
def test_a_get_descriptor_answered_after_a_bus_reset_is_held_to_its_own_length(executable,
                                                                               tmp_path):
    get_device = seeds.setup(0x80, seeds.GET_DESCRIPTOR, seeds.DEVICE << 8, 0, 18)
    data = (bytes((seeds.RESET, seeds.TASK)) + get_device + bytes((seeds.RESET,))
            + seeds.setup(0x00, seeds.SET_ADDRESS, 7, 0, 0)
            + bytes((seeds.TASK, seeds.EP0_IN, seeds.SUCCESS, seeds.TASK)))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 0 open 0 bootloader 0 ")


# Found by fuzzing, a false alarm of the harness: a SET_CONFIGURATION still queued at a bus
# reset opens the bulk endpoints after it, and bulk OUT data on one of them reaches a stack
# that no longer maps it to a driver: tud_task's assertion returns with the rest of its queue
# (a GET_DESCRIPTOR's SETUP) kept for the next call. The harness took that call for an empty
# queue, recorded the next SETUP as the request in flight without letting the stack answer
# the queued one first, and held that answer to the new request's length. The harness now
# counts the queue as the stack left it.
def test_a_setup_left_queued_by_an_early_return_of_the_task_is_answered_first(executable,
                                                                              tmp_path):
    get_device = seeds.setup(0x80, seeds.GET_DESCRIPTOR, seeds.DEVICE << 8, 0, 18)
    get_status_out = seeds.setup(0x00, 0, 0, 0, 2)      # the request guard stalls it
    data = (bytes((seeds.RESET, seeds.TASK)) + seeds.setup(0x00, seeds.SET_CONFIGURATION, 1, 0, 0)
            + bytes((seeds.RESET, seeds.TASK, seeds.BULK_OUT, 8)) + bytes(8)
            + bytes((seeds.SUCCESS,)) + get_device + bytes((seeds.TASK,)) + get_status_out
            + bytes((seeds.TASK,)))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 0 open 0 bootloader 0 ")


# Found by fuzzing, a false alarm of the harness: a SET_LINE_CODING with wLength 3 whose data
# stage the fake host ended after 1 byte (0x86). The port reads the line coding by wLength,
# so it took the low byte for a 1-byte request and asked for the bootloader; the harness
# allowed that only for wLength 1. A host sends exactly wLength bytes (USB 2.0, 9.3.5), so
# the harness no longer judges the flag after a short OUT data stage.
def test_a_short_line_coding_data_stage_is_not_judged(executable, tmp_path):
    data = (seeds.linux_enumeration() + seeds.setup(0x21, seeds.SET_LINE_CODING, 0, 0, 3)
            + bytes((seeds.TASK, seeds.EP0_OUT, 1, seeds.BOOTLOADER_BAUD, seeds.SUCCESS,
                     seeds.TASK, seeds.EP0_IN, seeds.SUCCESS, seeds.TASK)))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 1 open 1 ")


# Found by fuzzing, a fault of the port layer: a SET_LINE_CODING of 2 or 3 bytes whose first
# byte is 0x86 asked for the bootloader, the port judging the low byte alone (0x86 0x01 is
# 390 baud). Only the full dwDTERate and the 1-byte form count now (usb_serial.hpp).
@pytest.mark.parametrize("coding", [bytes((seeds.BOOTLOADER_BAUD, 1)),
                                    bytes((seeds.BOOTLOADER_BAUD, 0, 0))])
def test_a_two_or_three_byte_line_coding_does_not_ask_for_the_bootloader(executable, tmp_path,
                                                                         coding):
    data = seeds.linux_enumeration() + seeds.set_line_coding(coding)
    assert summary(executable, data, tmp_path).startswith("usb: mounted 1 open 1 bootloader 0 ")


# Found by fuzzing, a false alarm of the harness: a SET_LINE_CODING of 134 baud sent to the
# device (bmRequestType 0x20) with the CDC interface in wIndex. usbd.c hands a class request to
# the device to the driver of the interface wIndex names, and the CDC driver applies it as one
# sent to the interface: the port's line coding is 134 baud and the board asks for its
# bootloader. The harness knew only 0x21 as SET_LINE_CODING; it now takes both, and requires
# the request from either.
def test_a_line_coding_sent_to_the_device_is_the_interfaces(executable, tmp_path):
    request = seeds.setup(0x20, seeds.SET_LINE_CODING, 0, 0, 7)
    data = (seeds.linux_enumeration() + request
            + bytes((seeds.TASK, seeds.EP0_OUT, 7)) + seeds.line_coding(seeds.BOOTLOADER_BAUD)
            + bytes((seeds.SUCCESS, seeds.TASK, seeds.EP0_IN, seeds.SUCCESS, seeds.TASK)))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 1 open 1 bootloader 1 ")


# A fault of the port layer, found while triaging the finding above: the CDC driver takes
# SET_LINE_CODING whatever its direction bit says; sent device to host (0xA1) its data stage
# gives the host the port's own line coding, and its status stage ran the line-coding check
# with that request's wLength. After 9606 baud (0x2586), such a request with wLength 1 read
# the low byte 0x86 as the 1-byte form and asked for the bootloader, which the host never
# sent. The port now judges only a line coding the host sent (host to device).
@pytest.mark.parametrize("w_length", [1, 7])
def test_a_line_coding_request_sent_device_to_host_does_not_ask_for_the_bootloader(
        executable, tmp_path, w_length):
    earlier = seeds.BOOTLOADER_BAUD if w_length == 7 else 0x2586
    read_back = seeds.setup(0xA1, seeds.SET_LINE_CODING, 0, 0, w_length)
    data = (seeds.linux_enumeration() + seeds.set_line_coding(seeds.line_coding(earlier))
            + bytes((seeds.TASK,)) + read_back
            + bytes((seeds.TASK, seeds.EP0_IN, seeds.SUCCESS, seeds.TASK, seeds.EP0_OUT, 0,
                     seeds.SUCCESS, seeds.TASK)))
    expected = 1 if earlier == seeds.BOOTLOADER_BAUD else 0    # the 134-baud request itself
    assert summary(executable, data, tmp_path).startswith(
        f"usb: mounted 1 open 1 bootloader {expected} ")


# Found by fuzzing, a false alarm of the harness: as in the case above, bulk OUT on an
# endpoint the stack no longer maps makes tud_task return early, here with a GET_STATUS SETUP
# (wLength 1) still queued. Before the host's next SETUP the harness ran the stack only once,
# so that SETUP was recorded as the request in flight while the stack had not yet answered the
# queued one, whose 1-byte answer was then held to the new request's length (0). The loop runs
# the stack at every wake-up until its queue is empty, long before a host gives up on a
# transfer and sends its next SETUP; so does the harness now.
def test_a_setup_queued_behind_an_early_return_is_answered_before_the_next(executable,
                                                                          tmp_path):
    get_status = seeds.setup(0x80, 0, 0, 0, 1)
    get_status_out = seeds.setup(0x00, 0, 0, 0, 0)      # the request guard stalls it
    data = (bytes((seeds.RESET, seeds.TASK)) + seeds.setup(0x00, seeds.SET_CONFIGURATION, 1, 0, 0)
            + bytes((seeds.RESET, seeds.TASK, seeds.BULK_OUT, 0, seeds.SUCCESS)) + get_status
            + get_status_out + bytes((seeds.TASK,)))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 0 open 0 bootloader 0 ")


# Found by fuzzing, a false alarm of the fake controller: a class SET_LINE_CODING to endpoint 0
# (bmRequestType 0x22) before any bus reset, its 1-byte data stage 0x86. Until its first bus
# reset usbd.c's maps from endpoints and interfaces to drivers are all zero, naming the CDC
# driver, which took the request. The chip never receives it: ci_fs's dcd_init enables only
# the bus reset interrupt, and EP0 and the first SETUP's buffer are readied at a bus reset
# (a host resets the port before it talks to a new device). The fake controller now receives
# no SETUP before the first bus reset; after one, the same request is refused.
@pytest.mark.parametrize("reset_first", [False, True])
def test_a_setup_before_the_first_bus_reset_is_not_received(executable, tmp_path, reset_first):
    request = seeds.setup(0x22, seeds.SET_LINE_CODING, 0, 0, 1)
    data = (bytes((seeds.RESET, seeds.TASK)) if reset_first else b"") + request + bytes((
        seeds.TASK, seeds.EP0_OUT, 1, seeds.BOOTLOADER_BAUD, seeds.SUCCESS, seeds.TASK,
        seeds.EP0_IN, seeds.SUCCESS, seeds.TASK))
    assert summary(executable, data, tmp_path).startswith("usb: mounted 0 open 0 bootloader 0 ")
