#include "program.hpp"

#include "crc32.hpp"
#include "rc.hpp"

namespace hq {

namespace {

constexpr uint32_t kMagic = 0x31475148u;          // "HQG1" in memory order
constexpr size_t kHeaderBytes = 5;                // magic, step count
constexpr size_t kStepBytes = 16;                 // axis .. fade_cycles
constexpr size_t kHarmonicBytes = 10;             // order, amplitude, phase
constexpr size_t kCrcBytes = 4;

// Little-endian fields, written and read at a cursor that stops at the end.
struct Writer {
    uint8_t* out;
    size_t capacity, n = 0;
    bool ok = true;
    void bytes(uint32_t v, int count) {
        if (n + static_cast<size_t>(count) > capacity) {
            ok = false;
            return;
        }
        for (int i = 0; i < count; ++i) out[n++] = static_cast<uint8_t>(v >> (8 * i));
    }
    void f32(float v) {
        uint32_t u;
        __builtin_memcpy(&u, &v, sizeof(u));
        bytes(u, 4);
    }
};

struct Reader {
    const uint8_t* in;
    size_t n, at = 0;
    bool ok = true;
    uint32_t bytes(int count) {
        if (at + static_cast<size_t>(count) > n) {
            ok = false;
            return 0;
        }
        uint32_t v = 0;
        for (int i = 0; i < count; ++i) v |= uint32_t{in[at++]} << (8 * i);
        return v;
    }
    float f32() {
        const uint32_t u = bytes(4);
        float v;
        __builtin_memcpy(&v, &u, sizeof(v));
        return v;
    }
};

void write_step(Writer& w, const ExcitationConfig& c) {
    w.bytes(static_cast<uint8_t>(c.axis), 1);
    w.bytes(static_cast<uint8_t>(c.injection), 1);
    w.bytes(static_cast<uint8_t>(c.signal), 1);
    const uint8_t harmonics = c.signal == Signal::Multisine ? c.harmonics : 0;
    w.bytes(harmonics, 1);
    w.f32(c.freq_hz);
    w.f32(c.amplitude);
    w.bytes(c.cycles, 2);
    w.bytes(c.fade_cycles, 2);
    for (int i = 0; i < harmonics && i < kMaxHarmonics; ++i) {
        w.bytes(c.harmonic[i].order, 2);
        w.f32(c.harmonic[i].amplitude);
        w.f32(c.harmonic[i].phase_rad);
    }
}

bool read_step(Reader& r, ExcitationConfig& c) {
    c = ExcitationConfig{};
    c.axis = static_cast<Axis>(r.bytes(1));
    c.injection = static_cast<Injection>(r.bytes(1));
    c.signal = static_cast<Signal>(r.bytes(1));
    const uint32_t harmonics = r.bytes(1);
    c.freq_hz = r.f32();
    c.amplitude = r.f32();
    c.cycles = static_cast<uint16_t>(r.bytes(2));
    c.fade_cycles = static_cast<uint16_t>(r.bytes(2));
    if (harmonics > static_cast<uint32_t>(kMaxHarmonics)) return false;
    c.harmonics = static_cast<uint8_t>(harmonics);
    for (uint32_t i = 0; i < harmonics; ++i) {
        c.harmonic[i].order = static_cast<uint16_t>(r.bytes(2));
        c.harmonic[i].amplitude = r.f32();
        c.harmonic[i].phase_rad = r.f32();
    }
    return r.ok;
}

}  // namespace

size_t encode_program(const Program& program, uint8_t* out, size_t capacity) {
    Writer w{out, capacity};
    w.bytes(kMagic, 4);
    w.bytes(program.steps, 1);
    for (int i = 0; i < program.steps && i < kMaxProgramSteps; ++i) write_step(w, program.step[i]);
    if (!w.ok) return 0;
    w.bytes(crc32(out, w.n), 4);
    return w.ok ? w.n : 0;
}

bool decode_program(const uint8_t* data, size_t n, Program& program) {
    program.steps = 0;
    if (n < kHeaderBytes + kCrcBytes) return false;
    Reader crc{data + n - kCrcBytes, kCrcBytes};
    if (crc.bytes(4) != crc32(data, n - kCrcBytes)) return false;
    Reader r{data, n - kCrcBytes};
    const uint32_t magic = r.bytes(4);
    const uint32_t steps = r.bytes(1);
    // No steps: a cleared program, stored as such.
    if (magic != kMagic || steps > static_cast<uint32_t>(kMaxProgramSteps)) return false;
    for (uint32_t i = 0; i < steps; ++i) {
        if (!read_step(r, program.step[i])) return false;
    }
    if (r.at != r.n) return false;                 // bytes left over: not a record of ours
    program.steps = static_cast<uint8_t>(steps);
    return true;
}

Reason ProgramBuilder::add(uint8_t index, uint8_t count, const ExcitationConfig& step) {
    if (index > 0 && index + 1 == next_ && count == program_.steps) {
        program_.step[index] = step;           // sent again (its answer lost): the same step
        return Reason::None;
    }
    if (index == 0) reset();
    if (count == 0 || count > kMaxProgramSteps || index != next_ ||
        (index > 0 && count != program_.steps)) {
        reset();
        return Reason::ProgramOrder;
    }
    program_.steps = count;
    program_.step[index] = step;
    ++next_;
    return Reason::None;
}

ProgramEvent ProgramRunner::update(const RcInput& rc, const Program& program, Supervisor& sup,
                                   uint64_t now_us) {
    const RcThresholds& t = sup.limits().rc;
    const bool live = rc.age_us <= sup.limits().rc_timeout_us;
    const bool high = live && switch_high(rc, rc::kProgram, t);
    const bool edge = high && switch_ == SwitchPos::Low;
    // As the arm switch: a lost link forgets the position, so only a new move starts.
    switch_ = high ? SwitchPos::High
              : live && switch_low(rc, rc::kProgram, t) ? SwitchPos::Low : SwitchPos::Unknown;
    if (running_) {
        if (!high) {
            const bool stepping = sup.program_owns_excitation();
            sup.end_program_step(Reason::ProgramSwitch);        // announced by the Supervisor
            return end(Reason::ProgramSwitch, !stepping);
        }
        if (!sup.armed()) return end(Reason::Disarmed, false);   // the disarm said why
        return next_due_ ? start_step(program, sup, now_us) : ProgramEvent{};
    }
    if (!edge) return ProgramEvent{};
    Reason refused = Reason::None;
    if (!sup.armed()) refused = Reason::Disarmed;
    else if (program.steps == 0) refused = Reason::NoProgram;
    else if (sup.excitation().active()) refused = Reason::Busy;
    if (refused != Reason::None) {
        sup.refuse_excitation(refused);
        ProgramEvent e;
        e.happened = e.ended = true;
        e.reason = refused;
        return e;
    }
    running_ = true;
    step_ = 0;
    return start_step(program, sup, now_us);
}

ProgramEvent ProgramRunner::start_step(const Program& program, Supervisor& sup, uint64_t now_us) {
    next_due_ = false;
    const Reason r = sup.start_program_step(program.step[step_], now_us);
    if (r != Reason::None) return end(r, false);             // the refusal is announced
    ProgramEvent e;
    e.happened = true;
    e.step = step_;
    return e;
}

ProgramEvent ProgramRunner::step_ended(Reason why, const Program& program) {
    if (!running_) return ProgramEvent{};
    if (why != Reason::Finished) return end(why, false);     // the Supervisor said why
    if (step_ + 1 < program.steps) {
        ++step_;
        next_due_ = true;
        return ProgramEvent{};
    }
    return end(Reason::None, false);
}

ProgramEvent ProgramRunner::stop(Reason why) {
    return running_ ? end(why, false) : ProgramEvent{};
}

ProgramEvent ProgramRunner::end(Reason why, bool announce) {
    running_ = next_due_ = false;
    ProgramEvent e;
    e.happened = e.ended = true;
    e.announce = announce;
    e.reason = why;
    e.step = step_;
    return e;
}

}  // namespace hq
