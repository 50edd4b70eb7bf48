// The FlightController's on-board program (program.hpp): set, read and cleared over the link
// while disarmed, kept in its own storage, loaded and checked at start-up, and run by the
// pilot's program switch (channel 7) through the Supervisor's excitation rules.
#include "flight_controller.hpp"

namespace hq {

namespace {

static_assert(kProgramRecordBytes <= ParamStorage::kMaxBytes, "a program's record fits its store");

}  // namespace

// The stored program, each step checked against the bounds the loaded parameters set. A
// record that fails its checks, or a step out of bounds, is no program, and says so.
void FlightController::load_program() {
    program_.clear();
    if (config_.program_storage == nullptr) return;
    uint8_t record[kProgramRecordBytes];
    size_t n = 0;
    const StoreStatus st = config_.program_storage->load(record, sizeof(record), n);
    if (st == StoreStatus::Empty) return;
    if (st != StoreStatus::Ok || !program_.decode(record, n)) {
        notice(MAV_SEVERITY_WARNING, "program: stored record damaged; none loaded");
        return;
    }
    ExcitationConfig step;
    for (int i = 0; i < program_.steps(); ++i) {
        if (!program_.step(i, step) || supervisor_.check_excitation_bounds(step) != Reason::None) {
            program_.clear();
            notice(MAV_SEVERITY_WARNING, "program: a stored step out of bounds; none loaded");
            return;
        }
    }
}

ProgramReport FlightController::program_report() const {
    ProgramReport r;
    r.count = program_.steps();
    r.state = program_runner_.running() ? ProgramState::Running
              : program_.steps() > 0    ? ProgramState::Stored
                                        : ProgramState::None;
    r.step = program_runner_.step();
    return r;
}

LoopAnswer FlightController::answer_program(const LoopRequest& r, const ExcitationConfig& step) {
    LoopAnswer a;
    if (r.kind == RequestKind::ProgramRead) {
        a.program = program_report();
        a.program.step = static_cast<uint8_t>(r.value);
        return a;
    }
    if (supervisor_.armed()) {
        a.reason = Reason::Armed;
    } else if (r.kind == RequestKind::ProgramClear) {
        Program none;
        program_in_.reset();
        if (save_program(none)) program_ = none;
        else a.verdict = Verdict::Failed;
    } else {
        return set_program_step(r, step);
    }
    if (a.reason != Reason::None) {
        a.verdict = Verdict::Refused;
        notice(MAV_SEVERITY_WARNING, reason_text(a.reason));
    }
    a.program = program_report();
    return a;
}

// One step of a new program: checked as it comes, the program replacing the stored one only
// once its last step is in and it is stored (a refused step drops the new one: whole or
// nothing; the old one stays).
LoopAnswer FlightController::set_program_step(const LoopRequest& r, const ExcitationConfig& step) {
    LoopAnswer a;
    const auto index = static_cast<uint8_t>(r.value);
    Reason why = supervisor_.check_excitation_bounds(step);
    if (why == Reason::None && r.param_index >= 0 && r.param_index <= 255) {
        why = program_in_.add(index, static_cast<uint8_t>(r.param_index), step);
    } else if (why == Reason::None) {
        why = Reason::ProgramOrder;
    }
    if (why != Reason::None) {
        program_in_.reset();
        a.verdict = Verdict::Refused;
        a.reason = why;
        notice(MAV_SEVERITY_WARNING, reason_text(why));
    } else if (program_in_.complete()) {
        if (save_program(program_in_.program())) program_ = program_in_.program();
        else a.verdict = Verdict::Failed;
        program_in_.reset();
    }
    a.program = program_report();
    a.program.step = index;
    return a;
}

// Disarmed only (the link's rule): on flash this blocks. False: not stored, the old kept.
bool FlightController::save_program(const Program& program) {
    if (config_.program_storage == nullptr) {
        notice(MAV_SEVERITY_INFO, "program: no storage; kept until restart");
        return true;
    }
    uint8_t record[kProgramRecordBytes];
    const size_t n = program.encode(record, sizeof(record));
    const bool ok = n > 0 && config_.program_storage->save(record, n);
    notice(ok ? MAV_SEVERITY_INFO : MAV_SEVERITY_CRITICAL,
           ok ? "program: saved" : "program: save failed; the old one kept");
    return ok;
}

void FlightController::run_program(const RcInput& rc, uint64_t now_us) {
    program_event(program_runner_.update(rc, program_, supervisor_, now_us));
}

// What the program did this step: HQ_PROGRAM_STATUS, and its words.
void FlightController::program_event(const ProgramEvent& e) {
    if (!e.happened) return;
    status_.program_changed = true;
    status_.program_report = program_report();
    status_.program_report.step = e.step;
    status_.program_report.reason = e.reason;
    if (!e.ended) {
        if (e.step == 0) notice(MAV_SEVERITY_INFO, "program started by channel 7");
    } else if (e.reason == Reason::None) {
        notice(MAV_SEVERITY_INFO, "program finished: every step ran");
    } else if (e.announce) {
        notice(MAV_SEVERITY_WARNING, reason_text(e.reason));
    }
}

}  // namespace hq
