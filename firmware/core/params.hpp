// Parameters: every value the firmware flies with that a user may change without reflashing
// (gains, excitation limits, failsafe bounds, ESC endpoints, RC thresholds, stick scaling,
// the IMU's data path, the telemetry radio's baud rate),
// as the MAVLink parameter protocol names them, with their units and ranges, and their
// stored form. No I/O: the FlightController answers the protocol and owns the storage.
//
// Rules (docs/parameters.md lists every parameter):
//   - A value outside its range, not a normal float (NaN, infinite, denormal; 0 is taken), not
//     whole for an integer parameter, between 0 and kMinTimeConstantS for a time constant
//     (0: off), or not one of kSerialBauds for a baud rate is refused and the old value
//     stays; so is a PARAM_SET whose type does not fit.
//   - While an excitation runs nothing may change (a record is of one controller); while
//     armed only the gains may change; everything else waits for disarm. A baud rate takes
//     effect at the next start-up (the target begins its UART after loading them).
//   - The stored record is name-keyed (a CRC-32 of each name), so a firmware that adds or
//     drops a parameter still reads the others; it ends in a CRC-32 of the whole record. A
//     record that fails its checks gives the defaults, a stored value out of range gives
//     that parameter's default; both are reported.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../hal/motors.hpp"
#include "allocation.hpp"
#include "crc32.hpp"
#include "controllers.hpp"
#include "rc.hpp"
#include "supervisor.hpp"

namespace hq {

// Which IMU data path init() sets up (IMU_PATH).
enum class ImuPath : uint8_t { Dmp = 0, Raw = 1 };

// The baud rates SER_TEL1_BAUD takes: the standard ones from 9600 up (a SiK radio's 57600
// and 115200 among them) and 1 Mbaud. The core knows no clock: a target with a UART checks
// at compile time that it makes every one (teensy35: main.cpp, uart_divisor in serial.hpp).
constexpr uint32_t kSerialBauds[] = {9600,   19200,  38400,  57600,  115200,
                                     230400, 460800, 500000, 921600, 1000000};
// SER_TEL1_BAUD's default: a 3.3 V USB-serial cable's rate, fast enough for every stream.
constexpr uint32_t kDefaultTel1Baud = 921600;

// The vehicle's rotors as parameters, named as PX4's control allocation names them
// (CA_ROTOR_COUNT, CA_ROTORn_PX/PY/PZ/AX/AY/AZ/CT/KM; docs/parameters.md): rotor 0 is the
// central one, rotors at and beyond `count` are not used. Body FRD, origin at the centre of
// mass. The defaults are the paper's vehicle as the mixer flew it: the central rotor and four
// arm rotors at 0.3048 m on azimuths 0, 90, 180 and 270 deg (front, right, back, left), each
// canted 20 deg about its arm against the central rotor's reaction torque, the arms' own
// reaction torques not used (KM 0).
enum RotorField : uint8_t { kPx, kPy, kPz, kAx, kAy, kAz, kCt, kKm, kRotorFields };
struct GeometryParams {
    static constexpr float kSin20 = 0.342020143f, kCos20 = 0.939692621f;   // the 20 deg cant
    uint8_t count = 5;                   // CA_ROTOR_COUNT, kMinRotors..kMaxRotors
    float hover_thrust_n = 9.1202f;      // CA_HOVER_THRUST: the weight, 0.930 kg x g
    // Per rotor: position m, thrust axis (unit), largest thrust N, moment ratio m signed by
    // spin (positive: counter-clockwise seen from where the thrust points).
    float rotor[kMaxRotors][kRotorFields] = {
        {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, -1.0f, 25.0f, 0.017f},
        {0.3048f, 0.0f, 0.0f, 0.0f, -kSin20, -kCos20, 9.0f, 0.0f},
        {0.0f, 0.3048f, 0.0f, kSin20, 0.0f, -kCos20, 9.0f, 0.0f},
        {-0.3048f, 0.0f, 0.0f, 0.0f, kSin20, -kCos20, 9.0f, 0.0f},
        {0.0f, -0.3048f, 0.0f, -kSin20, 0.0f, -kCos20, 9.0f, 0.0f},
        {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, -1.0f, 0.0f, 0.0f},
        {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, -1.0f, 0.0f, 0.0f},
        {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, -1.0f, 0.0f, 0.0f},
    };
};
// The allocation's geometry from the parameters (KM's sign is the spin).
AllocationGeometry allocation_geometry(const GeometryParams& g);

// Everything a parameter sets. The defaults are the flight values of each part.
struct Tunables {
    CascadeGains gains = CascadeGains::paper_defaults();
    SafetyLimits safety{};
    StickLimits sticks{};
    EscEndpoints esc{};
    ImuPath imu_path = ImuPath::Dmp;   // DMP when the build has its firmware, else raw
    uint32_t tel1_baud = kDefaultTel1Baud;   // the telemetry radio's UART (teensy35: UART0)
    GeometryParams geometry{};
};

enum ParamFlag : uint8_t {
    kParamInteger = 1,    // MAV_PARAM_TYPE_INT32: whole values only
    kParamArmedOk = 2,    // may change while armed (the gains)
    kParamImu = 4,        // takes effect when the IMU is next initialised (done at once, disarmed)
    kParamEsc = 8,        // an ESC endpoint: the motors are told at once (disarmed)
    kParamTimeConstant = 16,  // 0 (off) or at least kMinTimeConstantS (pid.hpp)
    kParamBaud = 32,      // one of kSerialBauds only
    kParamRestart = 64,   // takes effect at the next start-up (a set says so)
    kParamGeometry = 128, // the vehicle's geometry: the allocation is computed again (disarmed)
};

constexpr size_t kParamNameLen = 16;

// One parameter, as param_info() gives it (by value: the CA_ROTORn_* names are built).
struct ParamInfo {
    char name[kParamNameLen + 1];   // at most 16 characters (PARAM_VALUE.param_id)
    const char* units;    // as the docs print them
    float min, max;       // inclusive
    uint8_t flags;
    int16_t index;        // its param_index
    float get(const Tunables& t) const;
    void set(Tunables& t, float value) const;
};

// The parameters with a table entry each, then CA_ROTORn_* by rotor, in RotorField's order.
constexpr int kTableParams = 54;
constexpr int kParamCount = kTableParams + kMaxRotors * kRotorFields;

ParamInfo param_info(int index);
// The index of a name given as a PARAM_* message's 16-character field (NUL-terminated when
// shorter); -1 when there is no such parameter.
int param_index(const char* name, size_t len = kParamNameLen);

enum class SetResult : uint8_t {
    Ok = 0,
    Unknown,         // no such parameter
    Range,           // not a normal float (0 is), or outside [min, max]
    NotInteger,      // an integer parameter given a fraction
    Armed,           // only the gains may change while armed
    Excitation,      // nothing changes while an excitation runs
    Unchanged,       // the value it has (after rounding to its type): taken, nothing changes
    BelowFloor,      // a time constant between 0 (off) and kMinTimeConstantS
    Type,            // a PARAM_SET whose MAV_PARAM_TYPE does not fit the parameter
    NotBaud,         // a baud rate that is not one of kSerialBauds
};

// A PARAM_SET's value as the type it names says to read it (docs/parameters.md). False when
// the type does not fit the parameter: a real parameter takes MAV_PARAM_TYPE_REAL32 only (an
// integer type's bytes would be taken as a float's: 1 as 1.4e-45); an integer parameter takes
// REAL32 (the number itself, as MAVProxy and pymavlink send it) or an 8-, 16- or 32-bit
// integer type, byte-wise or C-cast.
bool decode_param_value(const ParamInfo& info, float raw, uint8_t type, float& value);

// What a stored record held.
struct LoadReport {
    enum class Status : uint8_t { Ok, Empty, Corrupt } status = Status::Empty;
    int loaded = 0;          // values taken from the record
    int out_of_range = 0;    // stored values refused (their defaults kept)
    int first_bad = -1;      // the first of those
    SetResult first_bad_result = SetResult::Range;   // why it was refused (set()'s words)
};

class Params {
public:
    Params() : values_(defaults()) {}

    const Tunables& values() const { return values_; }
    // The values a parameter has until it is set (constant: in flash on the target).
    static const Tunables& defaults();
    float get(int index) const;
    float default_value(int index) const;
    SetResult set(int index, float value, bool armed, bool exciting);
    void reset() { values_ = defaults(); }

    // The record saved to ParamStorage: its length, 0 if capacity is too small.
    size_t encode(uint8_t* out, size_t capacity) const;
    // Takes the values of a stored record (status Empty: n == 0).
    LoadReport decode(const uint8_t* data, size_t n);
    static constexpr size_t kRecordBytes = 8 + 8 * kParamCount + 4;

private:
    Tunables values_;
};

// "params: no NAME", or "params: no index N" for a request by index (empty name), for a
// parameter this firmware lacks: STATUSTEXT, at most 27 characters.
void unknown_param_text(const char* name, int index, char* out, size_t capacity);

// "NAME out of range [min, max]" and the like, for STATUSTEXT (at most 49 characters); for
// Ok, "NAME set", and "NAME set; restart to apply" for a parameter read only at start-up.
void set_result_text(SetResult result, int index, char* out, size_t capacity);

}  // namespace hq
