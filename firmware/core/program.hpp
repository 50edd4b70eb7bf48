// The on-board identification program: a sweep stored on the board (docs/safety.md,
// docs/link-contract.md), run with no host attached, started and held by the pilot's
// program switch (channel 7).
//
// - A program is up to kMaxProgramSteps excitations (ExcitationConfig, the HQ_EXCITATION
//   layout), run one after another. It is set whole or not at all (ProgramBuilder: the steps
//   come in order; the last one completes it), each step checked against the excitation's
//   own bounds (Supervisor::check_excitation_bounds) as it arrives.
// - A Program is kept as its record (RAM holds bytes, not decoded steps), the same bytes its
//   own storage holds (the HAL's ParamStorage interface): magic, step count, each step's
//   fields (a multisine's harmonics only as many as it has), CRC-32 of all that; a record
//   that fails any check is no program.
// - ProgramRunner runs it: the switch's low-to-high move while armed starts step 0 (a switch
//   found high does not start: the arm switch's edge rule); each step is an excitation the
//   Supervisor starts and watches with every rule of a host's, except that the held switch
//   takes the place of the host's heartbeat; a step that finished starts the next in the
//   following loop (the fade-in is the settling, as the host's sweep has it); releasing the
//   switch, a disarm or any stop of a step ends the program with that reason.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../hal/rc_input.hpp"
#include "excitation.hpp"
#include "supervisor.hpp"

namespace hq {

// The most steps a program has: the host's dwell sweeps have 15 frequencies by default.
constexpr int kMaxProgramSteps = 24;
// The most bytes a program's record has, CRC included: 24 sine steps take 397, a multisine
// of 16 harmonics 185 (its steps are kept as the record, so RAM holds the bytes, not the
// decoded steps).
constexpr size_t kProgramRecordBytes = 512;

// Where the program is (HQ_PROGRAM_STATE).
enum class ProgramState : uint8_t {
    None = HQ_PROGRAM_STATE_NONE,
    Stored = HQ_PROGRAM_STATE_STORED,
    Running = HQ_PROGRAM_STATE_RUNNING,
};

// The program as the link reports it (HQ_PROGRAM_STATUS).
struct ProgramReport {
    ProgramState state = ProgramState::None;
    uint8_t step = 0;              // the step answered, started or ended in
    uint8_t count = 0;             // steps stored
    Reason reason = Reason::None;
};

// A program, kept as its record's bytes (no steps: none, or cleared).
class Program {
public:
    Program() { clear(); }
    void clear();
    uint8_t steps() const { return bytes_[kCountAt]; }
    // Step i decoded into out; false when there is no such step.
    bool step(int i, ExcitationConfig& out) const;
    // One more step at the end; false (nothing added) when it would not fit.
    bool append(const ExcitationConfig& step);
    // The record (with its CRC) into out, at most capacity: its length, 0 when it does not fit.
    size_t encode(uint8_t* out, size_t capacity) const;
    // A stored record: false (and no program) when it fails its checks.
    bool decode(const uint8_t* data, size_t n);
    // Its bytes so far, and back to that length with that many steps (the builder's repeat).
    size_t size() const { return n_; }
    void cut(size_t n, uint8_t count);

private:
    static constexpr size_t kCountAt = 4;
    static constexpr size_t kCrcBytes = 4;
    uint8_t bytes_[kProgramRecordBytes - kCrcBytes];   // magic, count, steps (not the CRC)
    size_t n_ = 0;
};

// A program arriving step by step: whole or not at all.
class ProgramBuilder {
public:
    // Step `index` of `count`; Reason::None when taken (the last one taken, sent again, takes
    // its place). A step out of order (or a count that changed, none, more than
    // kMaxProgramSteps, or steps that do not fit a record) is ProgramOrder and drops what came.
    Reason add(uint8_t index, uint8_t count, const ExcitationConfig& step);
    // The program is complete (its last step taken).
    bool complete() const { return count_ > 0 && program_.steps() == count_; }
    const Program& program() const { return program_; }
    void reset() {
        program_.clear();
        count_ = 0;
    }

private:
    Program program_{};
    size_t last_at_ = 0;            // where the last step taken begins (a repeat replaces it)
    uint8_t count_ = 0;
};

// What the runner did in a loop, for the link (HQ_PROGRAM_STATUS) and the notices.
struct ProgramEvent {
    bool happened = false;
    bool ended = false;            // the program ended (reason: why; None: every step ran)
    bool announce = false;         // its reason still needs a STATUSTEXT
    Reason reason = Reason::None;
    uint8_t step = 0;              // the step started, or the one it ended in
};

class ProgramRunner {
public:
    // Before the Supervisor's update: the switch's edge starts the program, its release ends
    // it, a disarm between steps ends it, and the step after a finished one starts.
    ProgramEvent update(const RcInput& rc, const Program& program, Supervisor& sup,
                        uint64_t now_us);
    // The Supervisor ended the running step with `why` (take_excitation_end): the next step
    // is due when it finished, else the program ends with that reason (already announced).
    ProgramEvent step_ended(Reason why, const Program& program);
    // A host's STOP: the program ends (the Supervisor stopped the step).
    ProgramEvent stop(Reason why);
    bool running() const { return running_; }
    uint8_t step() const { return step_; }

private:
    ProgramEvent start_step(const Program& program, Supervisor& sup, uint64_t now_us);
    ProgramEvent end(Reason why, bool announce);
    enum class SwitchPos : uint8_t { Unknown, Low, High };
    SwitchPos switch_ = SwitchPos::Unknown;
    bool running_ = false, next_due_ = false;
    uint8_t step_ = 0;
};

}  // namespace hq
