"""A writer of ArduPilot DataFlash logs for the tests, from ArduPilot's published format: each
record is 0xA3 0x95, its type, then its fields packed little-endian by its format string;
type 128 (FMT) defines the others (type, length, name, format, column names). The records
here are those ArduCopter's SystemID mode logs, with its field names and formats (ArduPilot's
log message reference): PARM, MSG, MODE, SIDS, SIDD, RATE, ATT."""

import struct

HEAD = b"\xa3\x95"
#: DataFlash format characters: struct codes, and the scale DFReader applies on reading.
CODES = {"b": ("b", 1), "B": ("B", 1), "h": ("h", 1), "H": ("H", 1), "i": ("i", 1),
         "I": ("I", 1), "f": ("f", 1), "d": ("d", 1), "n": ("4s", 1), "N": ("16s", 1),
         "Z": ("64s", 1), "c": ("h", 100), "C": ("H", 100), "e": ("i", 100),
         "E": ("I", 100), "L": ("i", 1), "M": ("B", 1), "q": ("q", 1), "Q": ("Q", 1)}
#: name: (type, format, columns), as ArduCopter 4.5 defines them.
MESSAGES = {
    "FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"),
    "PARM": (64, "QNf", "TimeUS,Name,Value"),
    "MSG": (65, "QZ", "TimeUS,Message"),
    "MODE": (66, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "SIDS": (67, "QBfffffff", "TimeUS,Ax,Mag,FSt,FSp,TFin,TC,TR,TFout"),
    "SIDD": (68, "Qfffffffff", "TimeUS,Time,Targ,F,Gx,Gy,Gz,Ax,Ay,Az"),
    "RATE": (69, "Qfffffffffffff", "TimeUS,RDes,R,ROut,PDes,P,POut,YDes,Y,YOut,ADes,A,AOut,"
                                   "AOutSlew"),
    "ATT": (70, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF"),
}


def _struct(fmt):
    return struct.Struct("<" + "".join(CODES[c][0] for c in fmt))


class DataFlashWriter:
    """Records into a bytearray; FMT for each message is written before its first record."""

    def __init__(self, messages=MESSAGES):
        self.messages = dict(messages)
        self.data = bytearray()
        self.defined = set()
        self.structs = {name: _struct(fmt) for name, (_, fmt, _) in self.messages.items()}
        self.define("FMT")

    def define(self, name):
        mtype, fmt, columns = self.messages[name]
        length = 3 + self.structs[name].size
        self.defined.add(name)
        self._raw("FMT", [mtype, length, name.encode(), fmt.encode(), columns.encode()])

    def write(self, name, **fields):
        if name not in self.defined:
            self.define(name)
        _, fmt, columns = self.messages[name]
        values = []
        for column, code in zip(columns.split(","), fmt):
            v = fields.get(column, "" if code in "nNZ" else 0)
            scale = CODES[code][1]
            if code in "nNZ":
                v = v.encode() if isinstance(v, str) else v
            elif scale != 1:
                v = int(round(v * scale))
            elif code not in "fd":
                v = int(v)
            values.append(v)
        self._raw(name, values)

    def _raw(self, name, values):
        self.data += HEAD + bytes([self.messages[name][0]]) + self.structs[name].pack(*values)

    def save(self, path):
        with open(path, "wb") as fh:
            fh.write(self.data)
        return path
