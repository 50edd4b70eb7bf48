#include "program.hpp"

#include "crc32.hpp"
#include "rc.hpp"

namespace hq {

namespace {

constexpr uint32_t kMagic = 0x31475148u;          // "HQG1" in memory order
constexpr size_t kHeaderBytes = 5;                // magic, step count
constexpr size_t kStepBytes = 16;                 // axis, injection, signal, harmonic count,
                                                  // frequency, amplitude, cycles, fade cycles
constexpr size_t kHarmonicBytes = 10;             // order, amplitude, phase
constexpr size_t kCrcBytes = 4;
static_assert(kHeaderBytes + kStepBytes + kMaxHarmonics * kHarmonicBytes + kCrcBytes <=
                  kProgramRecordBytes,
              "a multisine step with every harmonic fits a record");

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

void Program::clear() {
    Writer w{bytes_, sizeof(bytes_)};
    w.bytes(kMagic, 4);
    w.bytes(0, 1);
    n_ = w.n;
}

void Program::cut(size_t n, uint8_t count) {
    if (n < kHeaderBytes || n > n_) return;
    n_ = n;
    bytes_[kCountAt] = count;
}

bool Program::append(const ExcitationConfig& step) {
    if (steps() >= kMaxProgramSteps) return false;
    Writer w{bytes_ + n_, sizeof(bytes_) - n_};
    write_step(w, step);
    if (!w.ok) return false;
    n_ += w.n;
    ++bytes_[kCountAt];
    return true;
}

bool Program::step(int i, ExcitationConfig& out) const {
    Reader r{bytes_, n_, kHeaderBytes};
    for (int k = 0; k <= i && k < steps(); ++k) {
        if (!read_step(r, out)) return false;
        if (k == i) return true;
    }
    return false;
}

size_t Program::encode(uint8_t* out, size_t capacity) const {
    if (n_ + kCrcBytes > capacity) return 0;
    __builtin_memcpy(out, bytes_, n_);
    Writer w{out + n_, kCrcBytes};
    w.bytes(crc32(out, n_), 4);
    return n_ + kCrcBytes;
}

bool Program::decode(const uint8_t* data, size_t n) {
    clear();
    if (n < kHeaderBytes + kCrcBytes || n - kCrcBytes > sizeof(bytes_)) return false;
    Reader crc{data + n - kCrcBytes, kCrcBytes};
    if (crc.bytes(4) != crc32(data, n - kCrcBytes)) return false;
    Reader r{data, n - kCrcBytes};
    const uint32_t magic = r.bytes(4);
    const uint32_t count = r.bytes(1);            // none: a cleared program, stored as such
    if (magic != kMagic || count > static_cast<uint32_t>(kMaxProgramSteps)) return false;
    ExcitationConfig c;
    for (uint32_t i = 0; i < count; ++i) {
        if (!read_step(r, c)) return false;
    }
    if (r.at != r.n) return false;                 // bytes left over: not a record of ours
    __builtin_memcpy(bytes_, data, r.n);
    n_ = r.n;
    return true;
}

Reason ProgramBuilder::add(uint8_t index, uint8_t count, const ExcitationConfig& step) {
    const uint8_t taken = program_.steps();
    if (index > 0 && index + 1 == taken && count == count_) {
        program_.cut(last_at_, index);             // sent again (its answer lost): replaced
    } else if (index == 0) {
        reset();
    }
    if (count == 0 || count > kMaxProgramSteps || index != program_.steps() ||
        (index > 0 && count != count_)) {
        reset();
        return Reason::ProgramOrder;
    }
    const size_t at = program_.size();
    if (!program_.append(step)) {
        reset();
        return Reason::ProgramOrder;
    }
    last_at_ = at;
    count_ = count;
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
    else if (program.steps() == 0) refused = Reason::NoProgram;
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
    ExcitationConfig c;
    const Reason r = program.step(step_, c) ? sup.start_program_step(c, now_us)
                                            : Reason::NoProgram;
    if (r != Reason::None) return end(r, false);             // the refusal is announced
    ProgramEvent e;
    e.happened = true;
    e.step = step_;
    return e;
}

ProgramEvent ProgramRunner::step_ended(Reason why, const Program& program) {
    if (!running_) return ProgramEvent{};
    if (why != Reason::Finished) return end(why, false);     // the Supervisor said why
    if (step_ + 1 < program.steps()) {
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
