// ArduPilot's DataFlash log format (the .BIN that pymavlink's DFReader and mavlogdump.py read):
// the encoding only, no I/O. A record is the two bytes 0xA3 0x95, the message's type, then its
// fields packed little-endian, as the message's format characters say. The log describes
// itself: an FMT record (type 128) per message gives its type, length, name (4 characters),
// format (16) and column names (64); UNIT and MULT records name the unit and multiplier
// characters, and an FMTU record per message gives its fields' units and multipliers.
//
// Format characters (ArduPilot's AP_Logger/LogStructure.h; those this firmware writes):
//   B uint8  b int8  H uint16  h int16  I uint32  i int32  Q uint64  q int64
//   f float  d double  M uint8 flight mode  n char[4]  N char[16]  Z char[64]
// Every message this firmware logs is in kLogMessages (docs/file-formats.md lists them).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace hq {

constexpr uint8_t kDfHead1 = 0xA3, kDfHead2 = 0x95;
constexpr size_t kDfHeaderBytes = 3;          // the two head bytes and the type
constexpr size_t kDfNameLen = 4, kDfFormatLen = 16, kDfColumnsLen = 64;
constexpr size_t kDfTextLen = 64;             // Z
constexpr size_t kDfShortTextLen = 16;        // N

// The message types this firmware writes (any value but FMT's 128 would do: each is
// described by its FMT record).
enum class LogType : uint8_t {
    Fmt = 128, Unit = 129, Mult = 130, Fmtu = 131, Parm = 132, Msg = 133, Mode = 134,
    Ev = 135, Sidd = 136, Sids = 137, Hqsd = 138, Hqmt = 139, Hqgp = 140, Hqmx = 141,
};

// One message: its FMT and FMTU contents. units and mults have one character per field
// (kLogUnits, kLogMults; '-' none).
struct LogMessage {
    LogType type;
    const char* name;
    const char* format;
    const char* columns;
    const char* units;
    const char* mults;
};

struct LogUnit {
    char id;
    const char* label;
};
struct LogMult {
    char id;
    double multiplier;
};

extern const LogMessage kLogMessages[];
extern const size_t kLogMessageCount;
extern const LogUnit kLogUnits[];
extern const size_t kLogUnitCount;
extern const LogMult kLogMults[];
extern const size_t kLogMultCount;

// The bytes of one field of this format character; 0 for one this encoder does not write.
size_t df_field_bytes(char format);
// A whole record of this format string (the header included); 0 when a character is unknown.
size_t df_record_bytes(const char* format);
const LogMessage* log_message(LogType type);

// Packs one record into a caller's buffer: begin with the type, then each field in order.
// A record longer than the buffer is marked bad (ok() false) and never written.
// The fields are copied in the machine's byte order, which is the format's on both targets
// (Cortex-M4 and x86-64): a sample costs the step a few hundred instructions, not thousands.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "DataFlash fields are little-endian");
class DfRecord {
public:
    DfRecord(uint8_t* buf, size_t capacity, LogType type) : buf_(buf), capacity_(capacity) {
        const uint8_t head[kDfHeaderBytes] = {kDfHead1, kDfHead2, static_cast<uint8_t>(type)};
        put(head, sizeof head);
    }
    DfRecord& u8(uint8_t v) { return put(&v, 1); }
    DfRecord& u16(uint16_t v) { return put(&v, 2); }
    DfRecord& u32(uint32_t v) { return put(&v, 4); }
    DfRecord& u64(uint64_t v) { return put(&v, 8); }
    DfRecord& f32(float v) { return put(&v, 4); }
    DfRecord& f64(double v) { return put(&v, 8); }
    // A text field of `width` bytes (n, N, Z): zero-padded, cut at `width`.
    DfRecord& text(const char* s, size_t width);
    size_t size() const { return ok_ ? n_ : 0; }
    bool ok() const { return ok_; }

private:
    DfRecord& put(const void* v, size_t bytes) {
        if (!ok_ || n_ + bytes > capacity_) {
            ok_ = false;
            return *this;
        }
        std::memcpy(buf_ + n_, v, bytes);
        n_ += bytes;
        return *this;
    }
    uint8_t* buf_;
    size_t capacity_, n_ = 0;
    bool ok_ = true;
};

// The longest record this firmware writes (FMT's).
constexpr size_t kDfMaxRecordBytes = kDfHeaderBytes + 2 + kDfNameLen + kDfFormatLen + kDfColumnsLen;

// The FMT record describing `m` into buf (kDfMaxRecordBytes); its length.
size_t df_fmt_record(const LogMessage& m, uint8_t* buf, size_t capacity);
// The FMTU record giving m's units and multipliers; its length.
size_t df_fmtu_record(const LogMessage& m, uint64_t time_us, uint8_t* buf, size_t capacity);
size_t df_unit_record(const LogUnit& u, uint64_t time_us, uint8_t* buf, size_t capacity);
size_t df_mult_record(const LogMult& m, uint64_t time_us, uint8_t* buf, size_t capacity);

}  // namespace hq
