"""The standard USB descriptors a host reads at enumeration (USB 2.0 chapter 9.6) and the CDC
functional descriptors (CDC 1.2, 5.2.3), parsed into a small record: what the device says it
is (VID, PID, bcdUSB, EP0's packet size, its strings) and what its configuration holds
(interfaces with class, subclass and protocol, their endpoints, the CDC functional
descriptors). A descriptor that does not parse is an ``InputError`` naming its offset."""

from __future__ import annotations

import dataclasses
import struct

from ..base.errors import InputError

DEVICE, CONFIGURATION, STRING, INTERFACE, ENDPOINT = 1, 2, 3, 4, 5
INTERFACE_ASSOCIATION = 0x0B
CS_INTERFACE = 0x24                 # class-specific interface descriptor (CDC 1.2, table 12)
DEVICE_LENGTH, CONFIGURATION_LENGTH = 18, 9
TRANSFER_TYPES = ("control", "isochronous", "bulk", "interrupt")
CDC_SUBTYPES = {0x00: "header", 0x01: "call management", 0x02: "abstract control management",
                0x06: "union"}


@dataclasses.dataclass(frozen=True)
class Device:
    bcd_usb: int
    device_class: int
    device_subclass: int
    device_protocol: int
    ep0_max_packet: int
    vid: int
    pid: int
    bcd_device: int
    i_manufacturer: int
    i_product: int
    i_serial: int
    configurations: int


@dataclasses.dataclass(frozen=True)
class Endpoint:
    address: int
    attributes: int
    max_packet: int
    interval: int

    @property
    def transfer_type(self) -> str:
        return TRANSFER_TYPES[self.attributes & 3]

    @property
    def direction(self) -> str:
        return "in" if self.address & 0x80 else "out"


@dataclasses.dataclass(frozen=True)
class Functional:
    """A CDC functional descriptor: its subtype and the bytes after it."""
    subtype: int
    data: bytes

    @property
    def name(self) -> str:
        return CDC_SUBTYPES.get(self.subtype, f"subtype 0x{self.subtype:02X}")


@dataclasses.dataclass(frozen=True)
class Interface:
    number: int
    alternate: int
    interface_class: int
    interface_subclass: int
    interface_protocol: int
    endpoints: tuple
    functional: tuple


@dataclasses.dataclass(frozen=True)
class Configuration:
    value: int
    total_length: int
    attributes: int
    max_power_ma: int
    interfaces: tuple
    associations: tuple             # (first interface, count, class, subclass, protocol)


@dataclasses.dataclass(frozen=True)
class Identity:
    """All a host read: the device, its configuration and its strings by index."""
    device: Device
    configuration: Configuration
    strings: dict


def parse_device(data: bytes) -> Device:
    if len(data) < DEVICE_LENGTH or data[0] != DEVICE_LENGTH or data[1] != DEVICE:
        raise InputError(f"device descriptor: {len(data)} bytes {data[:2].hex()}..., not an "
                         "18-byte descriptor of type 1")
    f = struct.unpack("<BBHBBBBHHHBBBB", data[:DEVICE_LENGTH])
    return Device(f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9], f[10], f[11], f[12], f[13])


def _walk(data: bytes):
    """(offset, type, bytes) of each descriptor in a configuration's bytes."""
    at = 0
    while at < len(data):
        length = data[at]
        if length < 2 or at + length > len(data):
            raise InputError(f"configuration descriptor: a descriptor of length {length} at "
                             f"offset {at} runs past its {len(data)} bytes")
        yield at, data[at + 1], data[at:at + length]
        at += length


def parse_configuration(data: bytes) -> Configuration:
    if len(data) < CONFIGURATION_LENGTH or data[1] != CONFIGURATION:
        raise InputError("configuration descriptor: not a descriptor of type 2")
    _, _, total, _, value, _, attributes, power = struct.unpack("<BBHBBBBB",
                                                                data[:CONFIGURATION_LENGTH])
    if total != len(data):
        raise InputError(f"configuration descriptor: wTotalLength {total}, {len(data)} bytes read")
    interfaces, associations, current = [], [], None
    for at, kind, d in _walk(data[CONFIGURATION_LENGTH:]):
        if kind == INTERFACE:
            current = {"head": d, "endpoints": [], "functional": []}
            interfaces.append(current)
        elif kind == ENDPOINT and current is not None and len(d) >= 7:
            address, attrs, mps, interval = struct.unpack("<BBHB", d[2:7])
            current["endpoints"].append(Endpoint(address, attrs, mps & 0x7FF, interval))
        elif kind == CS_INTERFACE and current is not None and len(d) >= 3:
            current["functional"].append(Functional(d[2], bytes(d[3:])))
        elif kind == INTERFACE_ASSOCIATION and len(d) >= 8:
            associations.append(tuple(d[2:7]))
    return Configuration(value, total, attributes, 2 * power, tuple(
        Interface(i["head"][2], i["head"][3], i["head"][5], i["head"][6], i["head"][7],
                  tuple(i["endpoints"]), tuple(i["functional"])) for i in interfaces),
        tuple(associations))


def parse_string(data: bytes) -> str:
    if len(data) < 2 or data[1] != STRING or data[0] > len(data) or data[0] % 2:
        raise InputError(f"string descriptor: {data[:2].hex()} is not a string descriptor")
    return data[2:data[0]].decode("utf-16-le")


def parse_languages(data: bytes) -> tuple:
    if len(data) < 2 or data[1] != STRING:
        raise InputError("string descriptor 0: not a string descriptor")
    body = data[2:data[0]]
    return struct.unpack(f"<{len(body) // 2}H", body[:len(body) // 2 * 2])


def describe(identity: Identity) -> list:
    """The record as lines of text (what a command prints)."""
    d, c = identity.device, identity.configuration
    name = {i: identity.strings.get(i, "") for i in (d.i_manufacturer, d.i_product, d.i_serial)}
    lines = [f"device: USB {d.bcd_usb >> 8}.{(d.bcd_usb >> 4) & 0xF}{d.bcd_usb & 0xF}, "
             f"VID 0x{d.vid:04X}, PID 0x{d.pid:04X}, release 0x{d.bcd_device:04X}, "
             f"class 0x{d.device_class:02X}/0x{d.device_subclass:02X}/0x{d.device_protocol:02X}, "
             f"EP0 {d.ep0_max_packet} bytes",
             f"  manufacturer {name[d.i_manufacturer]!r}, product {name[d.i_product]!r}, "
             f"serial {name[d.i_serial]!r}",
             f"configuration {c.value}: {c.total_length} bytes, attributes "
             f"0x{c.attributes:02X}, {c.max_power_ma} mA"]
    for i in c.interfaces:
        lines.append(f"  interface {i.number}.{i.alternate}: class 0x{i.interface_class:02X}/"
                     f"0x{i.interface_subclass:02X}/0x{i.interface_protocol:02X}")
        lines += [f"    CDC {f.name}: {f.data.hex()}" for f in i.functional]
        lines += [f"    endpoint 0x{e.address:02X} {e.direction} {e.transfer_type}, "
                  f"{e.max_packet} bytes, interval {e.interval}" for e in i.endpoints]
    return lines
