#include "params.hpp"

#include <cmath>

namespace hq {

namespace {

// Degrees and seconds on the link, radians and microseconds inside. The conversions run in
// double so that a default of pi/4 reads back as 45 and 45 gives the same float as pi/4.
constexpr double kDegPerRad = 57.29577951308232;

float to_deg(float rad) { return static_cast<float>(static_cast<double>(rad) * kDegPerRad); }
float to_rad(float deg) { return static_cast<float>(static_cast<double>(deg) / kDegPerRad); }

// A parameter with an entry of its own in the table (the CA_ROTORn_* are built from kRotor).
struct ParamEntry {
    const char* name;
    const char* units;
    float min, max;
    uint8_t flags;
    float (*get)(const Tunables&);
    void (*set)(Tunables&, float);
};

// --- accessors, one template per kind of field ---------------------------------------------
template <int A, float PidGains::*F>
float rate_get(const Tunables& t) { return t.gains.rate[A].*F; }
template <int A, float PidGains::*F>
void rate_set(Tunables& t, float v) { t.gains.rate[A].*F = v; }
template <int A, float PidGains::*F>
float angle_get(const Tunables& t) { return t.gains.angle[A].*F; }
template <int A, float PidGains::*F>
void angle_set(Tunables& t, float v) { t.gains.angle[A].*F = v; }

template <float SafetyLimits::*F>
float safety_get(const Tunables& t) { return t.safety.*F; }
template <float SafetyLimits::*F>
void safety_set(Tunables& t, float v) { t.safety.*F = v; }
template <float SafetyLimits::*F>
float safety_deg_get(const Tunables& t) { return to_deg(t.safety.*F); }
template <float SafetyLimits::*F>
void safety_deg_set(Tunables& t, float v) { t.safety.*F = to_rad(v); }
template <uint32_t SafetyLimits::*F>
float safety_s_get(const Tunables& t) { return static_cast<float>(t.safety.*F * 1e-6); }
template <uint32_t SafetyLimits::*F>
void safety_s_set(Tunables& t, float v) {
    t.safety.*F = static_cast<uint32_t>(std::lround(static_cast<double>(v) * 1e6));
}
template <int I>
float amp_get(const Tunables& t) { return t.safety.max_amplitude[I]; }
template <int I>
void amp_set(Tunables& t, float v) { t.safety.max_amplitude[I] = v; }
template <int I>
float amp_deg_get(const Tunables& t) { return to_deg(t.safety.max_amplitude[I]); }
template <int I>
void amp_deg_set(Tunables& t, float v) { t.safety.max_amplitude[I] = to_rad(v); }
float fade_get(const Tunables& t) { return t.safety.min_fade_cycles; }
void fade_set(Tunables& t, float v) { t.safety.min_fade_cycles = static_cast<uint16_t>(v); }

template <uint16_t RcThresholds::*F>
float rc_get(const Tunables& t) { return t.safety.rc.*F; }
template <uint16_t RcThresholds::*F>
void rc_set(Tunables& t, float v) { t.safety.rc.*F = static_cast<uint16_t>(v); }

template <float StickLimits::*F>
float stick_get(const Tunables& t) { return to_deg(t.sticks.*F); }
template <float StickLimits::*F>
void stick_set(Tunables& t, float v) { t.sticks.*F = to_rad(v); }

template <int I, bool Max>
float esc_get(const Tunables& t) { return Max ? t.esc.max_us[I] : t.esc.min_us[I]; }
template <int I, bool Max>
void esc_set(Tunables& t, float v) {
    (Max ? t.esc.max_us[I] : t.esc.min_us[I]) = static_cast<uint16_t>(v);
}

float gcs_get(const Tunables& t) { return t.safety.gcs_sysid; }
void gcs_set(Tunables& t, float v) { t.safety.gcs_sysid = static_cast<uint8_t>(v); }

float imu_path_get(const Tunables& t) { return static_cast<float>(t.imu_path); }
void imu_path_set(Tunables& t, float v) { t.imu_path = static_cast<ImuPath>(static_cast<uint8_t>(v)); }

float tel1_baud_get(const Tunables& t) { return static_cast<float>(t.tel1_baud); }
void tel1_baud_set(Tunables& t, float v) { t.tel1_baud = static_cast<uint32_t>(v); }

float rotors_get(const Tunables& t) { return t.geometry.count; }
void rotors_set(Tunables& t, float v) { t.geometry.count = static_cast<uint8_t>(v); }
float hover_get(const Tunables& t) { return t.geometry.hover_thrust_n; }
void hover_set(Tunables& t, float v) { t.geometry.hover_thrust_n = v; }

constexpr uint8_t kGain = kParamArmedOk;
constexpr uint8_t kTime = kParamArmedOk | kParamTimeConstant;
constexpr uint8_t kInt = kParamInteger;
constexpr uint8_t kEsc = kParamInteger | kParamEsc;
constexpr uint8_t kBaud = kParamInteger | kParamBaud | kParamRestart;
constexpr uint8_t kGeometry = kParamGeometry;

#define HQ_RATE(AX, A)                                                                          \
    {"RATE_" AX "_KC", "1/(rad/s)", 0.01f, 50.0f, kGain, rate_get<A, &PidGains::kc>,           \
     rate_set<A, &PidGains::kc>},                                                               \
    {"RATE_" AX "_TI", "s", 0.0f, 100.0f, kTime, rate_get<A, &PidGains::tau_i_s>,               \
     rate_set<A, &PidGains::tau_i_s>},                                                          \
    {"RATE_" AX "_TD", "s", 0.0f, 1.0f, kTime, rate_get<A, &PidGains::tau_d_s>,                 \
     rate_set<A, &PidGains::tau_d_s>},                                                          \
    {"RATE_" AX "_IMAX", "", 0.0f, 1.0f, kGain, rate_get<A, &PidGains::integral_limit>,         \
     rate_set<A, &PidGains::integral_limit>}
#define HQ_ANGLE(AX, A)                                                                         \
    {"ANG_" AX "_KC", "1/s", 0.01f, 20.0f, kGain, angle_get<A, &PidGains::kc>,                  \
     angle_set<A, &PidGains::kc>},                                                              \
    {"ANG_" AX "_TD", "s", 0.0f, 1.0f, kTime, angle_get<A, &PidGains::tau_d_s>,                 \
     angle_set<A, &PidGains::tau_d_s>}
#define HQ_ESC(N, I)                                                                            \
    {"ESC" N "_MIN", "us", 800.0f, 1100.0f, kEsc, esc_get<I, false>, esc_set<I, false>},        \
    {"ESC" N "_MAX", "us", 1500.0f, 2200.0f, kEsc, esc_get<I, true>, esc_set<I, true>}

// The order is the protocol's param_index: append, never reorder (a ground station may
// cache by index within a session; the stored record is keyed by name).
const ParamEntry kParams[kTableParams] = {
    HQ_RATE("RLL", 0), HQ_RATE("PIT", 1), HQ_RATE("YAW", 2),
    HQ_ANGLE("RLL", 0), HQ_ANGLE("PIT", 1),
    {"EXC_MAX_ANG", "deg", 1.0f, 60.0f, 0, amp_deg_get<0>, amp_deg_set<0>},
    {"EXC_MAX_RATE", "deg/s", 1.0f, 300.0f, 0, amp_deg_get<1>, amp_deg_set<1>},
    {"EXC_MAX_MIX", "", 0.01f, 1.0f, 0, amp_get<2>, amp_set<2>},
    {"EXC_MIN_FREQ", "Hz", 0.01f, 10.0f, 0, safety_get<&SafetyLimits::min_freq_hz>,
     safety_set<&SafetyLimits::min_freq_hz>},
    {"EXC_MAX_DUR", "s", 1.0f, 3600.0f, 0, safety_get<&SafetyLimits::max_duration_s>,
     safety_set<&SafetyLimits::max_duration_s>},
    {"EXC_MIN_FADE", "cycles", 1.0f, 100.0f, kInt, fade_get, fade_set},
    {"FS_RC_TIMEOUT", "s", 0.1f, 2.0f, 0, safety_s_get<&SafetyLimits::rc_timeout_us>,
     safety_s_set<&SafetyLimits::rc_timeout_us>},
    {"FS_HOST_TIMEOUT", "s", 0.5f, 10.0f, 0, safety_s_get<&SafetyLimits::host_timeout_us>,
     safety_s_set<&SafetyLimits::host_timeout_us>},
    {"FS_ABORT_ANG", "deg", 10.0f, 90.0f, 0, safety_deg_get<&SafetyLimits::abort_angle_rad>,
     safety_deg_set<&SafetyLimits::abort_angle_rad>},
    {"FS_ABORT_RATE", "deg/s", 30.0f, 1500.0f, 0,
     safety_deg_get<&SafetyLimits::abort_rate_rad_s>, safety_deg_set<&SafetyLimits::abort_rate_rad_s>},
    HQ_ESC("1", 0), HQ_ESC("2", 1), HQ_ESC("3", 2), HQ_ESC("4", 3), HQ_ESC("5", 4),
    {"RC_SW_HIGH", "us", 1550.0f, 1900.0f, kInt, rc_get<&RcThresholds::switch_high_us>,
     rc_set<&RcThresholds::switch_high_us>},
    {"RC_SW_LOW", "us", 1100.0f, 1450.0f, kInt, rc_get<&RcThresholds::switch_low_us>,
     rc_set<&RcThresholds::switch_low_us>},
    {"RC_THR_LOW", "us", 1000.0f, 1300.0f, kInt, rc_get<&RcThresholds::throttle_low_us>,
     rc_set<&RcThresholds::throttle_low_us>},
    {"STK_ANG_MAX", "deg", 5.0f, 60.0f, 0, stick_get<&StickLimits::angle_rad>,
     stick_set<&StickLimits::angle_rad>},
    {"STK_RATE_MAX", "deg/s", 10.0f, 720.0f, 0, stick_get<&StickLimits::rate_rad_s>,
     stick_set<&StickLimits::rate_rad_s>},
    {"STK_YAW_MAX", "deg/s", 10.0f, 360.0f, 0, stick_get<&StickLimits::yaw_rate_rad_s>,
     stick_set<&StickLimits::yaw_rate_rad_s>},
    {"IMU_PATH", "", 0.0f, 1.0f, kInt | kParamImu, imu_path_get, imu_path_set},
    {"MAV_GCS_SYSID", "", 0.0f, 255.0f, kInt, gcs_get, gcs_set},
    {"SER_TEL1_BAUD", "baud", 9600.0f, 1000000.0f, kBaud, tel1_baud_get, tel1_baud_set},
    {"EXC_MAX_MOT", "", 0.01f, 0.5f, 0, amp_get<3>, amp_set<3>},
    HQ_ESC("6", 5), HQ_ESC("7", 6), HQ_ESC("8", 7),
    {"CA_ROTOR_COUNT", "", static_cast<float>(kMinRotors), static_cast<float>(kMaxRotors),
     kGeometry | kParamInteger, rotors_get, rotors_set},
    {"CA_HOVER_THRUST", "N", 0.5f, 500.0f, kGeometry, hover_get, hover_set},
};

// CA_ROTORn_<suffix>, in RotorField's order: each rotor's position, thrust axis, largest
// thrust and signed moment ratio (PX4's names, units and frame).
struct RotorEntry {
    char suffix[3];
    const char* units;
    float min, max;
};
const RotorEntry kRotor[kRotorFields] = {
    {"PX", "m", -2.0f, 2.0f},    {"PY", "m", -2.0f, 2.0f},    {"PZ", "m", -2.0f, 2.0f},
    {"AX", "", -1.0f, 1.0f},     {"AY", "", -1.0f, 1.0f},     {"AZ", "", -1.0f, 1.0f},
    {"CT", "N", 0.0f, 200.0f},   {"KM", "m", -0.5f, 0.5f},
};
constexpr char kRotorPrefix[] = "CA_ROTOR";

constexpr Tunables kDefaults{};

#undef HQ_RATE
#undef HQ_ANGLE
#undef HQ_ESC

constexpr uint32_t kMagic = 0x31505148u;     // "HQP1", little-endian

void put32(uint8_t* p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}
uint32_t get32(const uint8_t* p) {
    return static_cast<uint32_t>(p[0]) | static_cast<uint32_t>(p[1]) << 8 |
           static_cast<uint32_t>(p[2]) << 16 | static_cast<uint32_t>(p[3]) << 24;
}
uint32_t float_bits(float f) {
    uint32_t u;
    static_assert(sizeof(u) == sizeof(f), "IEEE single");
    __builtin_memcpy(&u, &f, sizeof(u));
    return u;
}
float bits_float(uint32_t u) {
    float f;
    __builtin_memcpy(&f, &u, sizeof(f));
    return f;
}

size_t name_length(const char* name, size_t len) {
    size_t n = 0;
    while (n < len && name[n] != '\0') ++n;
    return n;
}

uint32_t name_hash(const char* name) {
    return crc32(reinterpret_cast<const uint8_t*>(name), name_length(name, kParamNameLen));
}

// `value` rounded to the parameter's type (an integer parameter's to the nearest whole number;
// a real one is a float already) equals `current`.
bool same_value(const ParamInfo& p, float value, float current) {
    const float typed = (p.flags & kParamInteger) ? std::round(value) : value;
    return std::isfinite(typed) && typed == current;
}

// A normal float (or 0) within the range: never NaN, infinite or denormal (a denormal gain
// or time constant is no setting anyone means, and 1/tau of one overflows).
bool in_range(const ParamInfo& p, float value) {
    return (value == 0.0f || std::isnormal(value)) && value >= p.min && value <= p.max;
}

bool below_floor(const ParamInfo& p, float value) {
    return (p.flags & kParamTimeConstant) && value != 0.0f && value < kMinTimeConstantS;
}

bool standard_baud(float value) {
    for (uint32_t baud : kSerialBauds) {
        if (value == static_cast<float>(baud)) return true;
    }
    return false;
}

bool not_baud(const ParamInfo& p, float value) {
    return (p.flags & kParamBaud) && !standard_baud(value);
}

bool whole(const ParamInfo& p, float value) {
    return !(p.flags & kParamInteger) || value == std::floor(value);
}

// Why a value is not one the parameter takes (SetResult::Ok when it is), whatever the state.
SetResult value_check(const ParamInfo& p, float value) {
    if (!in_range(p, value)) return SetResult::Range;
    if (below_floor(p, value)) return SetResult::BelowFloor;
    if (!whole(p, value)) return SetResult::NotInteger;
    if (not_baud(p, value)) return SetResult::NotBaud;
    return SetResult::Ok;
}

// Appends text, keeping room for the terminating NUL.
struct Writer {
    char* out;
    size_t capacity, n = 0;
    void put(char c) {
        if (n + 1 < capacity) out[n++] = c;
        out[n] = '\0';
    }
    void put(const char* s, size_t len = 0xFFFF) {
        for (size_t i = 0; i < len && s[i] != '\0'; ++i) put(s[i]);
    }
    // A range bound as the table writes it: whole numbers plain, others with up to four
    // decimals, trailing zeros dropped.
    void number(float v) {
        if (v < 0) {
            put('-');
            v = -v;
        }
        // In 64 bits: a baud rate's bound (1e6) is 1e10 in ten-thousandths.
        const auto scaled = static_cast<uint64_t>(std::llround(static_cast<double>(v) * 1e4));
        char digits[20];
        int k = 0;
        for (uint64_t whole = scaled / 10000; k == 0 || whole > 0; whole /= 10) {
            digits[k++] = static_cast<char>('0' + whole % 10);
        }
        while (k > 0) put(digits[--k]);
        auto frac = static_cast<uint32_t>(scaled % 10000);
        if (frac == 0) return;
        put('.');
        for (uint32_t div = 1000; frac > 0; div /= 10) {
            put(static_cast<char>('0' + frac / div));
            frac %= div;
        }
    }
};

}  // namespace

ParamInfo param_info(int index) {
    ParamInfo p{};
    p.index = static_cast<int16_t>(index);
    Writer w{p.name, sizeof p.name};
    if (index < kTableParams) {
        const ParamEntry& e = kParams[index];
        w.put(e.name);
        p.units = e.units, p.min = e.min, p.max = e.max, p.flags = e.flags;
        return p;
    }
    const int k = index - kTableParams;
    const RotorEntry& e = kRotor[k % kRotorFields];
    w.put(kRotorPrefix);
    w.put(static_cast<char>('0' + k / kRotorFields));
    w.put('_');
    w.put(e.suffix);
    p.units = e.units, p.min = e.min, p.max = e.max, p.flags = kGeometry;
    return p;
}

float ParamInfo::get(const Tunables& t) const {
    if (index < kTableParams) return kParams[index].get(t);
    const int k = index - kTableParams;
    return t.geometry.rotor[k / kRotorFields][k % kRotorFields];
}

void ParamInfo::set(Tunables& t, float value) const {
    if (index < kTableParams) return kParams[index].set(t, value);
    const int k = index - kTableParams;
    t.geometry.rotor[k / kRotorFields][k % kRotorFields] = value;
}

int param_index(const char* name, size_t len) {
    const size_t n = name_length(name, len);
    for (int i = 0; i < kParamCount; ++i) {
        const ParamInfo p = param_info(i);
        size_t k = 0;
        while (k < n && p.name[k] == name[k]) ++k;
        if (k == n && p.name[k] == '\0') return i;
    }
    return -1;
}

AllocationGeometry allocation_geometry(const GeometryParams& g) {
    AllocationGeometry a;
    a.count = g.count;
    a.hover_thrust_n = g.hover_thrust_n;
    for (int i = 0; i < kMaxRotors; ++i) {
        const float* f = g.rotor[i];
        RotorGeometry& r = a.rotor[i];
        r.position_m = Vec3{f[kPx], f[kPy], f[kPz]};
        r.axis = Vec3{f[kAx], f[kAy], f[kAz]};
        r.max_thrust_n = f[kCt];
        r.moment_ratio_m = std::fabs(f[kKm]);
        r.spin = f[kKm] < 0.0f ? -1 : 1;
    }
    return a;
}

const Tunables& Params::defaults() { return kDefaults; }

float Params::get(int index) const { return param_info(index).get(values_); }

float Params::default_value(int index) const { return param_info(index).get(kDefaults); }

SetResult Params::set(int index, float value, bool armed, bool exciting) {
    if (index < 0 || index >= kParamCount) return SetResult::Unknown;
    const ParamInfo p = param_info(index);
    // A set to the value it has changes nothing, so no rule about changes applies (armed,
    // exciting): a ground station re-sending a value it read (MAVProxy's `param load` of an
    // unchanged file, where it misreads an integer) is answered with that value, not refused.
    if (same_value(p, value, get(index))) return SetResult::Unchanged;
    if (exciting) return SetResult::Excitation;
    if (armed && !(p.flags & kParamArmedOk)) return SetResult::Armed;
    const SetResult check = value_check(p, value);
    if (check != SetResult::Ok) return check;
    p.set(values_, value);
    return SetResult::Ok;
}

size_t Params::encode(uint8_t* out, size_t capacity) const {
    if (capacity < kRecordBytes) return 0;
    put32(out, kMagic);
    put32(out + 4, kParamCount);                 // count (16 bits), reserved (16 bits, 0)
    uint8_t* p = out + 8;
    for (int i = 0; i < kParamCount; ++i, p += 8) {
        put32(p, name_hash(param_info(i).name));
        put32(p + 4, float_bits(get(i)));
    }
    put32(p, crc32(out, static_cast<size_t>(p - out)));
    return kRecordBytes;
}

LoadReport Params::decode(const uint8_t* data, size_t n) {
    LoadReport r;
    if (n == 0) return r;                        // Empty
    r.status = LoadReport::Status::Corrupt;
    if (n < 12 || get32(data) != kMagic) return r;
    const uint32_t count = get32(data + 4) & 0xFFFFu;
    if (n != 12 + 8 * static_cast<size_t>(count) || crc32(data, n - 4) != get32(data + n - 4)) {
        return r;
    }
    r.status = LoadReport::Status::Ok;
    uint32_t hashes[kParamCount];
    for (int i = 0; i < kParamCount; ++i) hashes[i] = name_hash(param_info(i).name);
    for (uint32_t e = 0; e < count; ++e) {
        const uint8_t* p = data + 8 + 8 * e;
        const uint32_t h = get32(p);
        for (int i = 0; i < kParamCount; ++i) {
            if (hashes[i] != h) continue;        // a parameter this firmware no longer has
            const float v = bits_float(get32(p + 4));
            const ParamInfo info = param_info(i);
            const SetResult check = value_check(info, v);
            if (check == SetResult::Ok) {
                info.set(values_, v);
                ++r.loaded;
            } else if (r.out_of_range++ == 0) {
                r.first_bad = i;
                r.first_bad_result = check;
            }
            break;
        }
    }
    return r;
}

namespace {

// An integer type's reading of a PARAM_SET's float. Byte-wise (MAVSDK, QGroundControl), the
// value's bytes sit in the float's low bytes and the bits above are the narrow value's zero
// or sign extension; anything else is a C-cast client's (ArduPilot's convention: the number
// itself), whose whole numbers but 0 always have exponent bits above the low 16. For the
// 32-bit types, which have no bits above, every integer parameter lies below 2^23
// (params_test), so a byte-wise value is a denormal float (never whole but 0) and a C-cast
// one's bits a number beyond 2^30: the reading that lands in range is the one meant.
float decode_integer(const ParamInfo& info, float raw, uint8_t type) {
    uint32_t bits;
    __builtin_memcpy(&bits, &raw, sizeof(bits));
    int64_t v;
    uint32_t high;                                     // the bits above the narrow value
    switch (type) {
        case MAV_PARAM_TYPE_UINT8: v = static_cast<uint8_t>(bits), high = 0xFFFFFF00u; break;
        case MAV_PARAM_TYPE_INT8: v = static_cast<int8_t>(bits), high = 0xFFFFFF00u; break;
        case MAV_PARAM_TYPE_UINT16: v = static_cast<uint16_t>(bits), high = 0xFFFF0000u; break;
        case MAV_PARAM_TYPE_INT16: v = static_cast<int16_t>(bits), high = 0xFFFF0000u; break;
        case MAV_PARAM_TYPE_UINT32: v = bits, high = 0; break;
        default: v = static_cast<int32_t>(bits), high = 0; break;          // INT32
    }
    const auto bytewise = static_cast<float>(v);
    if (high != 0) {
        const uint32_t above = bits & high;
        const bool extension = above == 0 || (v < 0 && above == high);
        return extension ? bytewise : raw;
    }
    const bool bytewise_ok = bytewise >= info.min && bytewise <= info.max;
    const bool cast_ok = raw >= info.min && raw <= info.max && raw == std::floor(raw);
    return (!bytewise_ok && cast_ok) ? raw : bytewise;
}

bool integer_type(uint8_t type) {
    return type == MAV_PARAM_TYPE_UINT8 || type == MAV_PARAM_TYPE_INT8 ||
           type == MAV_PARAM_TYPE_UINT16 || type == MAV_PARAM_TYPE_INT16 ||
           type == MAV_PARAM_TYPE_UINT32 || type == MAV_PARAM_TYPE_INT32;
}

}  // namespace

bool decode_param_value(const ParamInfo& info, float raw, uint8_t type, float& value) {
    if (type == MAV_PARAM_TYPE_REAL32) {
        value = raw;
        return true;
    }
    if (!(info.flags & kParamInteger) || !integer_type(type)) return false;
    value = decode_integer(info, raw, type);
    return true;
}

void unknown_param_text(const char* name, int index, char* out, size_t capacity) {
    if (capacity == 0) return;
    out[0] = '\0';
    Writer w{out, capacity};
    w.put("params: no ");
    if (name[0] != '\0' || index < 0) {
        w.put(name, kParamNameLen);                      // not NUL-terminated at 16
        return;
    }
    w.put("index ");
    w.number(static_cast<float>(index));
}

void set_result_text(SetResult result, int index, char* out, size_t capacity) {
    Writer w{out, capacity};
    if (capacity == 0) return;
    out[0] = '\0';
    if (index < 0 || index >= kParamCount) {
        w.put("params: no such parameter");
        return;
    }
    const ParamInfo p = param_info(index);
    w.put(p.name);
    switch (result) {
        case SetResult::Range:
            w.put(" out of range ");
            w.number(p.min);
            w.put("..");
            w.number(p.max);
            break;
        case SetResult::NotInteger: w.put(" takes whole numbers only"); break;
        case SetResult::Armed: w.put(" changes only while disarmed"); break;
        case SetResult::Excitation: w.put(": not while exciting"); break;
        case SetResult::Unknown: w.put(": no such parameter"); break;
        case SetResult::Ok:
            w.put((p.flags & kParamRestart) ? " set; restart to apply" : " set");
            break;
        case SetResult::Unchanged: w.put(" unchanged"); break;
        case SetResult::BelowFloor:
            w.put(" is 0 (off) or at least ");
            w.number(kMinTimeConstantS);
            break;
        case SetResult::Type: w.put(" sent with the wrong type"); break;
        case SetResult::NotBaud: w.put(" not a standard baud rate"); break;
    }
}

}  // namespace hq
