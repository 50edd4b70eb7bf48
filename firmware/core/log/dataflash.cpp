#include "dataflash.hpp"

#include <cstring>

namespace hq {

// Names, formats, units and multipliers: ArduPilot's (AP_Logger/LogStructure.h for FMT, UNIT,
// MULT, FMTU, PARM, MSG, MODE and EV; ArduCopter's system identification mode for SIDD and
// SIDS, SIDD's fields and units exactly as it logs them); HQSD, HQMT and HQGP are
// heliquad's. A format string holds at most 16 characters, so HQ_SYSID_SAMPLE's fields
// take records written together: HQSD (the sample) and HQMT (its first five motor outputs),
// and for a vehicle of another rotor count than five HQMX (the count and motors 6 to 8), so
// that the paper's vehicle logs no more than five motors a loop.
const LogMessage kLogMessages[] = {
    {LogType::Fmt, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", "-b---", "-----"},
    {LogType::Unit, "UNIT", "QbZ", "TimeUS,Id,Label", "s--", "F--"},
    {LogType::Mult, "MULT", "Qbd", "TimeUS,Id,Mult", "s--", "F--"},
    {LogType::Fmtu, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds", "s---", "F---"},
    {LogType::Parm, "PARM", "QNff", "TimeUS,Name,Value,Default", "s---", "F---"},
    {LogType::Msg, "MSG", "QZ", "TimeUS,Message", "s-", "F-"},
    {LogType::Mode, "MODE", "QMBB", "TimeUS,Mode,ModeNum,Rsn", "s---", "F---"},
    {LogType::Ev, "EV", "QB", "TimeUS,Id", "s-", "F-"},
    {LogType::Sidd, "SIDD", "Qfffffffff", "TimeUS,Time,Targ,F,Gx,Gy,Gz,Ax,Ay,Az", "ss-zkkkooo",
     "F---------"},
    {LogType::Sids, "SIDS", "QBfffffff", "TimeUS,Ax,Mag,FSt,FSp,TFin,TC,TR,TFout", "s--zzssss",
     "F--------"},
    {LogType::Hqsd, "HQSD", "QIBBBBBffffffB", "TimeUS,Seq,Axis,Inj,ESt,Arm,Mode,Exc,ASP,RSP,Rate,Ang,Cmd,Sat",
     "s-------rEEr--", "F-------------"},
    {LogType::Hqmt, "HQMT", "Qfffff", "TimeUS,M1,M2,M3,M4,M5", "s-----", "F-----"},
    {LogType::Hqgp, "HQGP", "QIQ", "TimeUS,Dropped,SinceUS", "s-s", "F-F"},
    {LogType::Hqmx, "HQMX", "QBfff", "TimeUS,MCnt,M6,M7,M8", "s----", "F----"},
};
const size_t kLogMessageCount = sizeof(kLogMessages) / sizeof(kLogMessages[0]);

// ArduPilot's characters for the units and multipliers used above.
const LogUnit kLogUnits[] = {
    {'-', ""}, {'s', "s"}, {'b', "B"}, {'z', "Hz"}, {'k', "deg/s"}, {'o', "m/s/s"},
    {'r', "rad"}, {'E', "rad/s"},
};
const size_t kLogUnitCount = sizeof(kLogUnits) / sizeof(kLogUnits[0]);
const LogMult kLogMults[] = {{'-', 0.0}, {'F', 1e-6}};
const size_t kLogMultCount = sizeof(kLogMults) / sizeof(kLogMults[0]);

size_t df_field_bytes(char format) {
    switch (format) {
        case 'B': case 'b': case 'M': return 1;
        case 'H': case 'h': return 2;
        case 'I': case 'i': case 'f': case 'n': return 4;
        case 'Q': case 'q': case 'd': return 8;
        case 'N': return kDfShortTextLen;
        case 'Z': return kDfTextLen;
        default: return 0;
    }
}

size_t df_record_bytes(const char* format) {
    size_t n = kDfHeaderBytes;
    for (const char* c = format; *c != '\0'; ++c) {
        const size_t b = df_field_bytes(*c);
        if (b == 0) return 0;
        n += b;
    }
    return n;
}

const LogMessage* log_message(LogType type) {
    for (size_t i = 0; i < kLogMessageCount; ++i) {
        if (kLogMessages[i].type == type) return &kLogMessages[i];
    }
    return nullptr;
}

DfRecord& DfRecord::text(const char* s, size_t width) {
    if (!ok_ || n_ + width > capacity_) {
        ok_ = false;
        return *this;
    }
    size_t i = 0;
    for (; s != nullptr && i < width && s[i] != '\0'; ++i) buf_[n_ + i] = static_cast<uint8_t>(s[i]);
    for (; i < width; ++i) buf_[n_ + i] = 0;
    n_ += width;
    return *this;
}

size_t df_fmt_record(const LogMessage& m, uint8_t* buf, size_t capacity) {
    DfRecord r(buf, capacity, LogType::Fmt);
    r.u8(static_cast<uint8_t>(m.type)).u8(static_cast<uint8_t>(df_record_bytes(m.format)));
    r.text(m.name, kDfNameLen).text(m.format, kDfFormatLen).text(m.columns, kDfColumnsLen);
    return r.size();
}

size_t df_fmtu_record(const LogMessage& m, uint64_t time_us, uint8_t* buf, size_t capacity) {
    DfRecord r(buf, capacity, LogType::Fmtu);
    r.u64(time_us).u8(static_cast<uint8_t>(m.type));
    r.text(m.units, kDfShortTextLen).text(m.mults, kDfShortTextLen);
    return r.size();
}

size_t df_unit_record(const LogUnit& u, uint64_t time_us, uint8_t* buf, size_t capacity) {
    DfRecord r(buf, capacity, LogType::Unit);
    r.u64(time_us).u8(static_cast<uint8_t>(u.id)).text(u.label, kDfTextLen);
    return r.size();
}

size_t df_mult_record(const LogMult& m, uint64_t time_us, uint8_t* buf, size_t capacity) {
    DfRecord r(buf, capacity, LogType::Mult);
    r.u64(time_us).u8(static_cast<uint8_t>(m.id)).f64(m.multiplier);
    return r.size();
}

}  // namespace hq
