// GcsLink's side of the on-board program (core/program.hpp, docs/link-contract.md): HQ_PROGRAM
// in (a step to store, a clear, a read) as loop requests, answered with HQ_PROGRAM_STATUS (and
// a read's step as an HQ_PROGRAM of the board's), and the program's own moves reported.
#include "gcs_link.hpp"

namespace hq {

static_assert(kMaxProgramSteps < 256, "HQ_PROGRAM's index and count are bytes");
static_assert(sizeof(mavlink_hq_program_t::harmonic) / sizeof(uint16_t) == kMaxHarmonics,
              "HQ_PROGRAM carries kMaxHarmonics harmonics");

bool GcsLink::keep_program(const mavlink_message_t& msg, Received& in) const {
    in.program[0] = mavlink_msg_hq_program_get_action(&msg);
    in.program[1] = mavlink_msg_hq_program_get_index(&msg);
    return for_us(mavlink_msg_hq_program_get_target_system(&msg),
                  mavlink_msg_hq_program_get_target_component(&msg));
}

// STEP's excitation in HQ_EXCITATION's layout (checked by the loop), CLEAR and READ; an
// action this firmware does not know is a read of nothing (answered with the state).
bool GcsLink::ask_program(const mavlink_message_t& msg, LoopRequest& r) {
    mavlink_hq_program_t p;
    mavlink_msg_hq_program_decode(&msg, &p);
    r.value = p.index;
    if (p.action == HQ_PROGRAM_CLEAR) {
        r.kind = RequestKind::ProgramClear;
        return true;
    }
    if (p.action != HQ_PROGRAM_STEP) {
        r.kind = RequestKind::ProgramRead;
        if (p.action != HQ_PROGRAM_READ) r.value = kMaxProgramSteps;    // no such step
        return true;
    }
    r.kind = RequestKind::ProgramStep;
    r.param_index = p.count;
    inbox_.has_excitation = true;
    read_excitation(p, inbox_.excitation);
    return true;
}

// A READ's step (when the board has it) before the status; every action's status.
void GcsLink::reply_program(const Received& in, const LoopAnswer& a) {
    const uint8_t action = in.program[0];
    ExcitationConfig c;
    if (action == HQ_PROGRAM_READ && program_ != nullptr && program_->step(in.program[1], c)) {
        uint16_t order[kMaxHarmonics] = {};
        float amp[kMaxHarmonics] = {}, phase[kMaxHarmonics] = {};
        for (int i = 0; c.signal == Signal::Multisine && i < c.harmonics; ++i) {
            order[i] = c.harmonic[i].order;
            amp[i] = c.harmonic[i].amplitude;
            phase[i] = c.harmonic[i].phase_rad;
        }
        mavlink_message_t out;
        mavlink_msg_hq_program_pack_status(
            config_.system_id, config_.component_id, &tx_status_, &out, in.sysid, in.compid,
            HQ_PROGRAM_STEP, in.program[1], program_->steps(), static_cast<uint8_t>(c.axis),
            static_cast<uint8_t>(c.injection), c.freq_hz, c.amplitude, c.cycles, c.fade_cycles,
            static_cast<uint8_t>(c.signal), order, amp, phase);
        send(out);
    }
    ProgramReport report = a.program;
    report.reason = a.reason;
    send_program_status(action, a.verdict == Verdict::Accepted, report);
}

void GcsLink::send_program_status(uint8_t action, bool accepted, const ProgramReport& report) {
    mavlink_message_t msg;
    mavlink_msg_hq_program_status_pack_status(
        config_.system_id, config_.component_id, &tx_status_, &msg, loop_time_us_, action,
        accepted ? 1 : 0, static_cast<uint8_t>(report.reason), report.step, report.count,
        static_cast<uint8_t>(report.state));
    send(msg);
}

}  // namespace hq
