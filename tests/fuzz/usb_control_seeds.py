"""Seed inputs of the firmware's fuzz_usb_control target (firmware/fuzz/fuzz_usb_control.cpp):
a Linux host enumerating the Teensy 3.5 image's CDC-ACM port and opening it, then asking for
the bootloader at 134 baud in both forms (the 7-byte line coding and the 1-byte one).

An input is a list of operations, each an operation byte and its arguments, as the target
reads them (its step()); this module writes them by name."""

from __future__ import annotations

import struct

RESET, SETUP, LINE_STATE, EP0_OUT, EP0_IN, BULK_OUT, BULK_IN, TASK, APPLICATION = range(9)
SUCCESS = 0                      # an xfer_result_t byte below 0xF0 is XFER_RESULT_SUCCESS
EP0_PACKET = 64
DTR = 1
BOOTLOADER_BAUD = 134

GET_DESCRIPTOR, SET_ADDRESS, SET_CONFIGURATION = 6, 5, 9
DEVICE, CONFIGURATION, STRING = 1, 2, 3
CONFIGURATION_BYTES = 75         # usb_descriptors.cpp: configuration + CDC-ACM function
STRING_BYTES = {0: 4, 1: 18, 2: 54, 3: 66}   # language list, "heliquad", the product, serial
LANG_EN_US = 0x0409
SET_LINE_CODING = 0x20


def setup(bm_request_type: int, b_request: int, w_value: int, w_index: int, w_length: int) -> bytes:
    return bytes((SETUP,)) + struct.pack("<BBHHH", bm_request_type, b_request, w_value, w_index,
                                         w_length)


def get_descriptor(kind: int, index: int, w_length: int, answer: int, lang: int = 0) -> bytes:
    """A GET_DESCRIPTOR with its IN data stage read packet by packet and its status stage."""
    out = setup(0x80, GET_DESCRIPTOR, (kind << 8) | index, lang, w_length) + bytes((TASK,))
    for _ in range(max(1, -(-min(answer, w_length) // EP0_PACKET))):
        out += bytes((EP0_IN, SUCCESS, TASK))
    return out + bytes((EP0_OUT, 0, SUCCESS, TASK))


def no_data(bm_request_type: int, b_request: int, w_value: int, w_index: int = 0) -> bytes:
    """A request without a data stage: the SETUP, then the status stage's IN read."""
    return setup(bm_request_type, b_request, w_value, w_index, 0) + bytes((TASK, EP0_IN, SUCCESS,
                                                                           TASK))


def set_line_coding(data: bytes, w_length: int | None = None) -> bytes:
    """SET_LINE_CODING to the CDC interface with its OUT data stage and status stage."""
    w_length = len(data) if w_length is None else w_length
    return (setup(0x21, SET_LINE_CODING, 0, 0, w_length) + bytes((TASK, EP0_OUT, len(data)))
            + data + bytes((SUCCESS, TASK, EP0_IN, SUCCESS, TASK)))


def line_coding(baud: int) -> bytes:
    """The 7-byte structure: dwDTERate, 1 stop bit, no parity, 8 data bits."""
    return struct.pack("<IBBB", baud, 0, 0, 8)


def linux_enumeration() -> bytes:
    """What Linux's hub driver and cdc_acm do at plug-in, then a terminal opening the port."""
    out = bytes((RESET, TASK)) + get_descriptor(DEVICE, 0, 64, 18)
    out += bytes((RESET, TASK)) + no_data(0x00, SET_ADDRESS, 7)
    out += get_descriptor(DEVICE, 0, 18, 18)
    out += get_descriptor(CONFIGURATION, 0, 9, CONFIGURATION_BYTES)
    out += get_descriptor(CONFIGURATION, 0, CONFIGURATION_BYTES, CONFIGURATION_BYTES)
    out += get_descriptor(STRING, 0, 255, STRING_BYTES[0])
    for index in (2, 1, 3):
        out += get_descriptor(STRING, index, 255, STRING_BYTES[index], LANG_EN_US)
    out += no_data(0x00, SET_CONFIGURATION, 1)
    out += bytes((LINE_STATE, 0, TASK, EP0_IN, SUCCESS, TASK))
    out += set_line_coding(line_coding(9600))
    out += bytes((LINE_STATE, DTR, TASK, EP0_IN, SUCCESS, TASK))
    # A ground station's bytes in, the loop's telemetry out and read by the host.
    out += bytes((BULK_OUT, 8)) + b"\xfd\x09\x00\x00\x00\xff\xbe\x00" + bytes((SUCCESS, TASK))
    out += bytes((APPLICATION,)) + struct.pack("<HB", 280, 64) + bytes((TASK,))
    return out + bytes((BULK_IN, 0, SUCCESS, TASK))


def seed_inputs() -> dict:
    enumerated = linux_enumeration()
    return {
        "linux-enumeration": enumerated,
        "bootloader-134-baud": enumerated + set_line_coding(line_coding(BOOTLOADER_BAUD)),
        "bootloader-1-byte": enumerated + set_line_coding(bytes((BOOTLOADER_BAUD,))),
        "line-coding-135-baud": enumerated + set_line_coding(line_coding(BOOTLOADER_BAUD + 1)),
    }
