// The FlightController's requests (loop_exchange.hpp): arming, mode, excitation, parameter
// sets and the parameter store, each answered in the order it came, and the parameters'
// loading, applying and saving. The link decided what each message asks; here the loop
// decides whether it may.
#include "flight_controller.hpp"

#include "boot_report.hpp"

namespace hq {

namespace {

// Parameters are saved once they have not changed for this long (a ground station's
// "param load" sends dozens in a row: one save, not dozens of flash erases).
constexpr uint64_t kSaveQuietUs = 500000;

}  // namespace

void FlightController::answer(LoopInbox& inbox, const RcInput& rc, uint64_t now_us) {
    for (int i = 0; i < inbox.count; ++i) {
        inbox.answer[i] = answer_one(inbox.request[i], inbox.excitation, rc, now_us);
        inbox.answer[i].notices_end = status_.notice_count;
    }
}

LoopAnswer FlightController::answer_one(const LoopRequest& r, const ExcitationConfig& start,
                                        const RcInput& rc, uint64_t now_us) {
    LoopAnswer a;
    switch (r.kind) {
        case RequestKind::Heartbeat:
            supervisor_.heartbeat(r.sysid, r.compid, r.mav_type, now_us);
            return a;
        case RequestKind::Arm:
            a.reason = supervisor_.arm_command(rc, now_us, r.who);
            break;
        case RequestKind::Disarm:
            supervisor_.disarm_command();
            return a;
        case RequestKind::SetMode:
            a.reason = supervisor_.set_mode(r.value);
            break;
        case RequestKind::ParamSet:
            return answer_param_set(r, now_us);
        case RequestKind::Storage:
            a.verdict = supervisor_.armed() ? Verdict::Refused : storage_action(r.value, clock_.micros());
            return a;
        case RequestKind::Bootloader:
            return answer_bootloader();
        case RequestKind::ProgramStep:
        case RequestKind::ProgramClear:
        case RequestKind::ProgramRead:
            return answer_program(r, start);
        default:
            return answer_excitation(r, start, now_us);
    }
    a.verdict = a.reason == Reason::None ? Verdict::Accepted : Verdict::Refused;
    return a;
}

// The target's bootloader (the Teensy's USB host set 134 baud): never while armed, which is
// refused and said; disarmed, the motors are already at their stop pulse and stay there.
LoopAnswer FlightController::answer_bootloader() {
    LoopAnswer a;
    if (supervisor_.armed()) {
        a.verdict = Verdict::Refused;
        notice(MAV_SEVERITY_WARNING, "bootloader refused: armed (disarm first)");
        return a;
    }
    status_.bootloader = true;
    notice(MAV_SEVERITY_NOTICE, "entering the bootloader: disarmed, motors stopped");
    return a;
}

LoopAnswer FlightController::answer_excitation(const LoopRequest& r,
                                              const ExcitationConfig& start, uint64_t now_us) {
    LoopAnswer a;
    if (program_runner_.running() && r.kind != RequestKind::ExcitationStop) {
        // The pilot's switch holds the program: a host's start or finish is refused (a STOP
        // still stops it, below).
        a.reason = Reason::ProgramRunning;
        supervisor_.refuse_excitation(a.reason);
        a.verdict = Verdict::Refused;
    } else if (r.kind == RequestKind::ExcitationStop) {
        supervisor_.stop_excitation();
        program_event(program_runner_.stop(Reason::StopCommand));
        a.reason = Reason::StopCommand;
    } else if (r.kind == RequestKind::ExcitationFinish) {
        supervisor_.finish_excitation();             // the answer carries the new length
    } else if (r.kind == RequestKind::ExcitationStart) {
        a.reason = supervisor_.start_excitation(start, now_us, r.who);
        if (a.reason != Reason::None) a.verdict = Verdict::Refused;
    } else {
        // An action this firmware does not know: refused, and nothing else changes (a
        // running excitation goes on; only STOP stops one).
        a.reason = Reason::BadAction;
        supervisor_.refuse_excitation(a.reason);
        a.verdict = Verdict::Refused;
    }
    a.excitation = excitation_report();
    return a;
}

ExcitationReport FlightController::excitation_report() const {
    const Excitation& ex = supervisor_.excitation();
    ExcitationReport r;
    r.state = ex.state();
    r.axis = ex.config().axis;
    r.injection = ex.config().injection;
    r.signal = ex.config().signal;
    r.actual_freq_hz = ex.actual_freq_hz();
    r.period_samples = ex.period_samples();
    r.total_samples = ex.total_samples();
    r.fade_samples = ex.fade_samples();
    return r;
}

LoopAnswer FlightController::answer_param_set(const LoopRequest& r, uint64_t now_us) {
    LoopAnswer a;
    a.set = !r.param_type_ok ? SetResult::Type
                             : params_.set(r.param_index, r.param_value, supervisor_.armed(),
                                           supervisor_.excitation().active());
    if (a.set == SetResult::Unchanged) return a;
    if (a.set != SetResult::Ok) {
        a.verdict = Verdict::Refused;
        return a;
    }
    apply_params(param_info(r.param_index).flags, now_us);
    logger_.param_changed(r.param_index, params_.get(r.param_index),
                          params_.default_value(r.param_index), now_us);
    params_dirty_ = true;
    params_changed_us_ = now_us;
    return a;
}

// MAV_CMD_PREFLIGHT_STORAGE's parameter action: read the stored values again, save now, or
// back to the defaults (saved like any change). Refused: an action it does not know;
// Failed: a save that did not store.
Verdict FlightController::storage_action(uint32_t action, uint64_t now_us) {
    if (action == PARAM_READ_PERSISTENT) {
        params_.reset();
        int bad_index = -1;
        SetResult bad_result = SetResult::Range;
        load_params(bad_index, bad_result);
    } else if (action == PARAM_WRITE_PERSISTENT) {
        return save_params() ? Verdict::Accepted : Verdict::Failed;
    } else if (action == PARAM_RESET_FACTORY_DEFAULT || action == PARAM_RESET_ALL_DEFAULT) {
        params_.reset();
        params_dirty_ = true;
        params_changed_us_ = now_us;
    } else {
        return Verdict::Refused;
    }
    apply_params(kParamEsc | kParamImu | kParamGeometry, now_us);
    return Verdict::Accepted;
}

// What the store gave (and, when a stored value was refused, the first such and why: it keeps
// its default); a notice for an empty or corrupt store or a refused value (boot_report.hpp's
// words).
ParamsFinding FlightController::load_params(int& bad_index, SetResult& bad_result) {
    if (config_.storage == nullptr) return ParamsFinding::NoStorage;    // nothing to say
    uint8_t record[ParamStorage::kMaxBytes];
    size_t n = 0;
    const StoreStatus st = config_.storage->load(record, sizeof(record), n);
    LoadReport r;
    if (st == StoreStatus::Ok) r = params_.decode(record, n);
    ParamsFinding found = ParamsFinding::Loaded;
    if (st == StoreStatus::Corrupt || r.status == LoadReport::Status::Corrupt) {
        found = ParamsFinding::Corrupt;
    } else if (r.status == LoadReport::Status::Empty) {
        found = ParamsFinding::Empty;
    } else if (r.out_of_range > 0) {
        found = ParamsFinding::OutOfRange;
        bad_index = r.first_bad;
        bad_result = r.first_bad_result;
    }
    if (announced(found)) notice(params_notice(found, bad_index, bad_result));
    return found;
}

// The parameters' values into the parts that fly with them. The gains and bounds take
// effect at once (the PID keeps its integral term, so a gain change is bumpless); the ESC
// endpoints and the IMU's path only when `changed` says so, and only while disarmed (the
// protocol refuses them while armed).
void FlightController::apply_params(uint8_t changed, uint64_t now_us) {
    const Tunables& t = params_.values();
    cascade_.set_gains(t.gains);
    supervisor_.set_limits(t.safety);
    if (supervisor_.armed()) return;
    if (changed & kParamEsc) motors_.set_endpoints(t.esc);
    if (changed & kParamGeometry) configure_allocation();
    if (changed & kParamImu) {
        imu_init_ = init_imu();
        supervisor_.imu_initialised(now_us, imu_timeout_for(imu_.sample_rate_hz()));
    }
}

// The allocation from the geometry parameters (disarmed: the protocol refuses them while
// armed). A geometry it refuses leaves it refusing (zero thrust) and arming refused, said.
void FlightController::configure_allocation() {
    const bool ok = allocation_.configure(allocation_geometry(params_.values().geometry));
    supervisor_.set_geometry(ok, allocation_.count());
    // The rotors the vehicle has (the motors past them get their stop pulse); a refused
    // geometry flies none, so its count is only what the parameters say.
    status_.state.rotor_count = params_.values().geometry.count;
    if (!ok) notice(MAV_SEVERITY_WARNING, allocation_.reason());
}

void FlightController::save_params_when_due(uint64_t now_us) {
    if (params_dirty_ && !supervisor_.armed() && now_us - params_changed_us_ >= kSaveQuietUs) {
        save_params();
    }
}

// Only while disarmed: on flash this blocks for tens of milliseconds.
bool FlightController::save_params() {
    params_dirty_ = false;
    if (config_.storage == nullptr) {
        notice(MAV_SEVERITY_INFO, "params: no storage; kept until restart");
        return false;
    }
    uint8_t record[Params::kRecordBytes];
    const size_t n = params_.encode(record, sizeof(record));
    const bool ok = config_.storage->save(record, n);
    notice(ok ? MAV_SEVERITY_INFO : MAV_SEVERITY_CRITICAL,
                    ok ? "params: saved" : "params: save failed; not stored");
    return ok;
}

}  // namespace hq
