#include "logger.hpp"

#ifndef HQ_FW_VERSION_MAJOR
#error "the build defines HQ_FW_VERSION_MAJOR, _MINOR and _PATCH (firmware/CMakeLists.txt)"
#endif

namespace hq {

namespace {

#define HQ_LOG_STR2(x) #x
#define HQ_LOG_STR(x) HQ_LOG_STR2(x)
// The log's first MSG, as ArduPilot's logs begin with the firmware's name and version.
constexpr const char* kVersionText = "heliquad " HQ_LOG_STR(HQ_FW_VERSION_MAJOR) "." HQ_LOG_STR(
    HQ_FW_VERSION_MINOR) "." HQ_LOG_STR(HQ_FW_VERSION_PATCH);

constexpr float kDegPerRad = 57.29577951308232f;
// HQMT's motors: the paper's vehicle's five; HQMX has the count and the rest when it differs.
constexpr int kHqmtMotors = 5;

// ArduPilot's SID_AXIS numbers for the same experiments: 1-3 input angle, 7-9 rate, 10-12
// mixer (roll, pitch, yaw); 0 (none of ArduPilot's) for a motor injection, which HQSD's
// injection names.
uint8_t systemid_axis(Injection injection, Axis axis) {
    if (injected_rotor(injection) != kNoRotor) return 0;
    const uint8_t base = injection == Injection::Angle ? 1 : (injection == Injection::Rate ? 7 : 10);
    return static_cast<uint8_t>(base + static_cast<uint8_t>(axis));
}

}  // namespace

// --- step side -------------------------------------------------------------------------------

bool Logger::push(const uint8_t* data, size_t n, uint32_t records, uint64_t now_us) {
    if (gap_dropped_ > 0) {
        uint8_t gap[kDfHeaderBytes + 20];
        DfRecord g(gap, sizeof gap, LogType::Hqgp);
        g.u64(now_us).u32(gap_dropped_).u64(gap_since_us_);
        if (g.size() + n > kRingBytes - ring_.used() || !ring_.push(gap, g.size())) {
            gap_dropped_ += records;
            counters_.dropped += records;
            return false;
        }
        ++counters_.records;
        gap_dropped_ = 0;
    }
    if (!ring_.push(data, n)) {
        if (gap_dropped_ == 0) gap_since_us_ = now_us;
        gap_dropped_ += records;
        counters_.dropped += records;
        return false;
    }
    counters_.records += records;
    return true;
}

void Logger::loop(const LoopStatus& st, const Excitation& exc, float loop_rate_hz) {
    if (st.armed && !armed_) on_arming(st);
    if (!armed_) return;
    log_notices(st);
    if (!st.armed) {
        on_disarm(st);
        return;
    }
    log_mode(st);
    log_experiment(st, exc, loop_rate_hz);
    log_sample(st, exc);
}

// A new log, or the last one continues when the service has not ended it yet (still open,
// or not even begun).
void Logger::on_arming(const LoopStatus& st) {
    armed_ = true;
    const bool continues = end_wanted_ && (open_ || served_ != arms_);
    end_wanted_ = false;
    if (!continues) {
        start_us_ = st.time_us;
        ++arms_;
    }
    uint8_t buf[kDfHeaderBytes + 9];
    DfRecord r(buf, sizeof buf, LogType::Ev);
    r.u64(st.time_us).u8(kLogEventArmed);
    push(buf, r.size(), 1, st.time_us);
    mode_ = st.mode;
    uint8_t m[kDfHeaderBytes + 11];
    DfRecord mr(m, sizeof m, LogType::Mode);
    mr.u64(st.time_us).u8(static_cast<uint8_t>(st.mode)).u8(static_cast<uint8_t>(st.mode)).u8(0);
    push(m, mr.size(), 1, st.time_us);
    exciting_ = false;
}

void Logger::on_disarm(const LoopStatus& st) {
    uint8_t buf[kDfHeaderBytes + 9];
    DfRecord r(buf, sizeof buf, LogType::Ev);
    r.u64(st.time_us).u8(kLogEventDisarmed);
    push(buf, r.size(), 1, st.time_us);
    armed_ = false;
    end_mark_ = ring_.head();
    end_wanted_ = true;
}

void Logger::log_notices(const LoopStatus& st) {
    for (int i = 0; i < st.notice_count; ++i) {
        char words[kDfTextLen] = {};
        notice_words(st.notice[i], words, sizeof words);
        log_text(words, sizeof words, st.time_us);
    }
}

void Logger::text(const char* words, size_t len, uint64_t now_us) {
    if (armed_) log_text(words, len, now_us);
}

void Logger::log_text(const char* words, size_t len, uint64_t now_us) {
    char field[kDfTextLen] = {};
    for (size_t i = 0; i < len && i < kDfTextLen && words[i] != '\0'; ++i) field[i] = words[i];
    uint8_t buf[kDfHeaderBytes + 8 + kDfTextLen];
    DfRecord r(buf, sizeof buf, LogType::Msg);
    r.u64(now_us).text(field, kDfTextLen);
    push(buf, r.size(), 1, now_us);
}

void Logger::log_mode(const LoopStatus& st) {
    if (st.mode == mode_) return;
    mode_ = st.mode;
    uint8_t buf[kDfHeaderBytes + 11];
    DfRecord r(buf, sizeof buf, LogType::Mode);
    r.u64(st.time_us).u8(static_cast<uint8_t>(st.mode)).u8(static_cast<uint8_t>(st.mode)).u8(0);
    push(buf, r.size(), 1, st.time_us);
}

// SIDS at an excitation's start: ArduPilot's set-up fields (the fades and the full-amplitude
// part in s, the band in Hz: one frequency for a sine, the lowest and highest harmonic of a
// multisine, a chirp's start and stop). A start is a loop excited after one that was not, or after one that ended an
// excitation (an on-board program starts its next step in the loop after the last ended,
// with no idle loop between).
void Logger::log_experiment(const LoopStatus& st, const Excitation& exc, float loop_rate_hz) {
    const bool now = st.excitation_state != ExcitationState::Idle;
    const bool started = now && (!exciting_ || ended_);
    exciting_ = now;
    ended_ = st.excitation_ended;
    if (!started) return;
    exc_start_us_ = st.time_us;
    const ExcitationConfig& c = exc.config();
    const bool multi = c.signal == Signal::Multisine;
    const float f0 = exc.actual_freq_hz();
    const float dt = 1.0f / loop_rate_hz;
    const float fade_s = static_cast<float>(exc.fade_samples()) * dt;
    const float total_s = static_cast<float>(exc.total_samples()) * dt;
    uint8_t buf[kDfHeaderBytes + 8 + 1 + 7 * 4];
    DfRecord r(buf, sizeof buf, LogType::Sids);
    r.u64(st.time_us).u8(systemid_axis(c.injection, c.axis)).f32(c.amplitude);
    if (is_chirp(c.signal)) {                 // the sweep's start and stop, as ArduPilot's
        r.f32(c.freq_hz).f32(c.freq_stop_hz);
    } else {
        r.f32(multi ? f0 * lowest_order(c) : f0).f32(multi ? f0 * highest_order(c) : f0);
    }
    r.f32(fade_s).f32(total_s - 2.0f * fade_s).f32(total_s).f32(fade_s);
    push(buf, r.size(), 1, st.time_us);
}

// One loop's sample: SIDD, HQSD, HQMT (and HQMX) in one piece (all or none).
void Logger::log_sample(const LoopStatus& st, const Excitation& exc) {
    const LoopState& x = st.state;
    const uint64_t t = st.time_us;
    uint8_t buf[4 * kDfHeaderBytes + 4 * 8 + 9 * 4 + 4 + 5 + 6 * 4 + 1 + 1 + kMaxRotors * 4];
    DfRecord d(buf, sizeof buf, LogType::Sidd);
    const bool on = st.excitation_state != ExcitationState::Idle;
    d.u64(t).f32(on ? static_cast<float>(t - exc_start_us_) * 1e-6f : 0.0f).f32(x.excitation);
    d.f32(on ? exc.output_frequency_hz() : 0.0f);
    d.f32(x.rate.x * kDegPerRad).f32(x.rate.y * kDegPerRad).f32(x.rate.z * kDegPerRad);
    d.f32(x.accel.x).f32(x.accel.y).f32(x.accel.z);
    const SysidSample s = sysid_sample(st);
    DfRecord h(buf + d.size(), sizeof buf - d.size(), LogType::Hqsd);
    h.u64(t).u32(st.loop_index).u8(static_cast<uint8_t>(st.exc_axis));
    h.u8(static_cast<uint8_t>(st.exc_injection)).u8(static_cast<uint8_t>(st.excitation_state));
    h.u8(st.armed ? 1 : 0).u8(static_cast<uint8_t>(st.mode)).f32(x.excitation);
    h.f32(s.angle_sp).f32(s.rate_sp).f32(s.rate).f32(s.angle).f32(s.axis_cmd).u8(x.saturation);
    const size_t n = d.size() + h.size();
    DfRecord m(buf + n, sizeof buf - n, LogType::Hqmt);
    m.u64(t);
    for (int i = 0; i < kHqmtMotors; ++i) m.f32(x.motor[i]);
    if (x.rotor_count == kHqmtMotors) {
        push(buf, n + m.size(), 3, t);
        return;
    }
    const size_t k = n + m.size();
    DfRecord e(buf + k, sizeof buf - k, LogType::Hqmx);
    e.u64(t).u8(x.rotor_count);
    for (int i = kHqmtMotors; i < kMaxRotors; ++i) e.f32(x.motor[i]);
    push(buf, k + e.size(), 4, t);
}

void Logger::param_changed(int index, float value, float default_value, uint64_t now_us) {
    if (!armed_) return;
    uint8_t buf[kDfHeaderBytes + 8 + kDfShortTextLen + 8];
    DfRecord r(buf, sizeof buf, LogType::Parm);
    r.u64(now_us).text(param_info(index).name, kDfShortTextLen).f32(value).f32(default_value);
    push(buf, r.size(), 1, now_us);
}

// --- service side ----------------------------------------------------------------------------

size_t Logger::header_record(uint32_t i, const Params& params, uint8_t* buf, size_t cap) const {
    const uint32_t n = static_cast<uint32_t>(kLogMessageCount);
    const uint32_t units = static_cast<uint32_t>(kLogUnitCount);
    const uint32_t mults = static_cast<uint32_t>(kLogMultCount);
    if (i < n) return df_fmt_record(kLogMessages[i], buf, cap);
    i -= n;
    if (i < units) return df_unit_record(kLogUnits[i], start_us_, buf, cap);
    i -= units;
    if (i < mults) return df_mult_record(kLogMults[i], start_us_, buf, cap);
    i -= mults;
    if (i < n) return df_fmtu_record(kLogMessages[i], start_us_, buf, cap);
    i -= n;
    if (i == 0) {
        DfRecord r(buf, cap, LogType::Msg);
        return r.u64(start_us_).text(kVersionText, kDfTextLen).size();
    }
    const int p = static_cast<int>(i - 1);
    if (p >= kParamCount) return 0;
    DfRecord r(buf, cap, LogType::Parm);
    r.u64(start_us_).text(param_info(p).name, kDfShortTextLen);
    return r.f32(params.get(p)).f32(params.default_value(p)).size();
}

void Logger::write_header(LogSink& sink, const Params& params) {
    uint8_t buf[kDfMaxRecordBytes];
    for (uint32_t i = 0;; ++i) {
        const size_t n = header_record(i, params, buf, sizeof buf);
        if (n == 0 || !take(sink, buf, static_cast<uint32_t>(n))) return;
    }
}

// Into the sink, or nowhere once it refused (no card, a full or failed card): the ring
// still empties, so the step keeps queueing.
bool Logger::take(LogSink& sink, const uint8_t* data, uint32_t n) {
    if (!sink_ok_) return false;
    const uint32_t taken = sink.write(data, n);
    counters_.bytes_written += taken;
    if (taken < n) sink_ok_ = false;
    return sink_ok_;
}

void Logger::drain(LogSink& sink) {
    const bool ending = end_wanted_;
    const uint32_t end = ending ? end_mark_ : ring_.head();
    while (ring_.tail() != end) {
        const uint8_t* data = nullptr;
        const uint32_t n = ring_.contiguous(end, data);
        take(sink, data, n);
        ring_.consume(n);           // only now: the bytes stay put while the sink reads them
    }
    if (ending && end_wanted_ && ring_.tail() == end_mark_) {
        open_ = false;              // first: an arming nested in end_log() starts a new log
        sink.end_log();
    }
}

void Logger::service(LogSink& sink, const Params& params) {
    if (!open_ && served_ != arms_) {
        served_ = arms_;
        open_ = true;
        ++counters_.logs;
        sink_ok_ = sink.begin_log();
        write_header(sink, params);
    }
    if (open_) {
        drain(sink);
    } else {
        ring_.consume(ring_.used());    // nothing is logged between logs
    }
    counters_.card = sink.state();
}

}  // namespace hq
