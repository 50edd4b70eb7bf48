// GcsLink's parameter protocol: PARAM_REQUEST_LIST and _READ answered with PARAM_VALUE a few
// per loop, PARAM_SET turned into a loop request and answered with PARAM_VALUE (and
// PARAM_ERROR plus a STATUSTEXT when refused). The values are the loop's (LoopStatus::params);
// the table and its checks are params.hpp's.
#include <cmath>

#include "gcs_link.hpp"
#include "link_util.hpp"

namespace hq {

namespace {

// PARAM_VALUEs sent per loop while a list is being sent: 44 in 22 loops (0.11 s at 200 Hz),
// about 15 kB/s on top of the loop's telemetry.
constexpr int kParamsPerLoop = 2;

void copy_name(char out[kParamNameLen], const char* name) {
    size_t i = 0;
    for (; i < kParamNameLen && name[i] != '\0'; ++i) out[i] = name[i];
    for (; i < kParamNameLen; ++i) out[i] = '\0';
}

// PARAM_VALUE.param_value is a float whatever the type. Integer parameters are sent byte-wise
// (the int32's bytes in the float's, MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE): what
// MAVSDK reads for every autopilot but ArduPilot and QGroundControl for every autopilot but
// ArduPilot (its APM plugin alone converts). docs/ground-stations.md says who reads what.
float encode_param_int(float value) {
    const int32_t i = static_cast<int32_t>(value);       // whole and in range (params.cpp)
    float f;
    __builtin_memcpy(&f, &i, sizeof(f));
    return f;
}

#ifdef MAVLINK_MSG_ID_PARAM_ERROR
// MAV_PARAM_ERROR_TYPE_MISMATCH where the common.xml in use has it, else
// VALUE_OUT_OF_RANGE (the value as sent is not one the parameter takes).
template <typename E, typename = void>
struct TypeMismatch {
    static constexpr uint8_t value = E::MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE;
};
template <typename E>
struct TypeMismatch<E, decltype(void(E::MAV_PARAM_ERROR_TYPE_MISMATCH))> {
    static constexpr uint8_t value = E::MAV_PARAM_ERROR_TYPE_MISMATCH;
};

// PARAM_ERROR's code for a refusal (MAV_PARAM_ERROR).
uint8_t param_error(SetResult r) {
    switch (r) {
        case SetResult::Unknown: return MAV_PARAM_ERROR_DOES_NOT_EXIST;
        case SetResult::Armed:
        case SetResult::Excitation: return MAV_PARAM_ERROR_PERMISSION_DENIED;
        case SetResult::Type: return TypeMismatch<MAV_PARAM_ERROR>::value;
        default: return MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE;     // out of range, not whole
    }
}
#endif

}  // namespace

// A PARAM_SET for us naming a parameter: the loop decides (a value of the wrong type refused).
bool GcsLink::ask_param_set(const mavlink_message_t& msg, LoopRequest& r) const {
    mavlink_param_set_t ps;
    mavlink_msg_param_set_decode(&msg, &ps);
    if (!for_us(ps.target_system, ps.target_component)) return false;
    r.param_index = param_index(ps.param_id);
    if (r.param_index < 0) return false;
    r.kind = RequestKind::ParamSet;
    r.param_type_ok = decode_param_value(param_info(r.param_index), ps.param_value,
                                         ps.param_type, r.param_value);
    return true;
}

void GcsLink::reply_param_read(const Received& in) {
    const int index = in.param_index >= 0 ? (in.param_index < kParamCount ? in.param_index : -1)
                                          : param_index(in.param_id);
    if (index < 0) {
        send_param_error(in, in.param_id, in.param_index, SetResult::Unknown);
        send_unknown_param(in.param_id, in.param_index);
        return;
    }
    params_pending_.set(index);
}

void GcsLink::send_unknown_param(const char* name, int index) {
    char text[kStatusTextLen];
    unknown_param_text(name, index, text, sizeof(text));
    say(MAV_SEVERITY_WARNING, text);
}

// PARAM_SET is answered with PARAM_VALUE: the new value, or the unchanged one, a STATUSTEXT
// saying why, and PARAM_ERROR to the station that asked (MAVSDK and QGroundControl report
// that as the refusal; MAVProxy and pymavlink read the unchanged value). A new value of a
// parameter read only at start-up also gets a STATUSTEXT: "NAME set; restart to apply".
void GcsLink::reply_param_set(const Received& in, const LoopAnswer* a) {
    if (a == nullptr) {                              // no such parameter
        send_param_error(in, in.param_id, -1, SetResult::Unknown);
        send_unknown_param(in.param_id, -1);
        return;
    }
    const int index = inbox_.request[in.request].param_index;
    if (in.param_type == MAV_PARAM_TYPE_REAL32) params_as_float_.set(index);  // as it came
    params_pending_.set(index);
    const bool refused = a->verdict != Verdict::Accepted;
    // A change to a parameter read only at start-up says so ("... set; restart to apply").
    const bool restart = a->set == SetResult::Ok && (param_info(index).flags & kParamRestart);
    if (!refused && !restart) return;                // answered with the value it has
    if (refused) send_param_error(in, in.param_id, index, a->set);
    char text[kStatusTextLen];
    set_result_text(a->set, index, text, sizeof(text));
    say(refused ? MAV_SEVERITY_WARNING : MAV_SEVERITY_NOTICE, text);
}

void GcsLink::send_param_error(const Received& to, const char* name, int index, SetResult why) {
#ifdef MAVLINK_MSG_ID_PARAM_ERROR
    char id[kParamNameLen];
    copy_name(id, name);
    mavlink_message_t out;
    mavlink_msg_param_error_pack_status(config_.system_id, config_.component_id, &tx_status_, &out,
                                        to.sysid, to.compid, id, static_cast<int16_t>(index),
                                        param_error(why));
    send(out);
#else
    (void)to, (void)name, (void)index, (void)why;       // a common.xml without PARAM_ERROR
#endif
}

bool GcsLink::send_param_value(const Tunables& values, int index) {
    const ParamInfo& info = param_info(index);
    char name[kParamNameLen];
    copy_name(name, info.name);
    const bool integer = (info.flags & kParamInteger) != 0;
    const bool as_float = !integer || params_as_float_.test(index);
    const float v = info.get(values);
    mavlink_message_t msg;
    mavlink_msg_param_value_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, name,
        as_float ? v : encode_param_int(v), as_float ? MAV_PARAM_TYPE_REAL32 : MAV_PARAM_TYPE_INT32,
        kParamCount, static_cast<uint16_t>(index));
    return send(msg);
}

void GcsLink::send_params(const Tunables& values) {
    for (int sent = 0, index; sent < kParamsPerLoop && (index = params_pending_.first()) >= 0;
         ++sent) {
        if (!send_param_value(values, index)) return;   // the link is full: next loop
        params_pending_.clear(index);
        params_as_float_.clear(index);
    }
}

}  // namespace hq
