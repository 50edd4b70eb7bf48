// The engine's CPU: an ARMv7-M (Cortex-M4F) Thumb-2 interpreter with a pre-decoded
// instruction cache, written from the ARMv7-M Architecture Reference Manual's semantics.
// One of the emulated chip's two CPUs (sim/chip/cpu.py; the native core runs on it in
// mk64_engine.cpp): tests/thumb_engine_test.py proves it equal to unicorn instruction by
// instruction, benchmarks/thumb_speed.py measures it.
//
// Memory: flash (512 KiB at 0) and SRAM (192 KiB at 0x1FFF0000) are byte arrays the engine
// owns; every other address goes to the owner's Bus. Each halfword address of flash and SRAM
// has one decoded record (Op), filled the first time the PC reaches it; a store into SRAM
// holding decoded code drops that page's records (a bit per 256-byte page), and the owner
// calls invalidate() when it programs the flash.
//
// Time: every instruction costs the cycles of sim/chip/timing.py's model (condition-blind:
// an instruction failing its IT condition costs the same), counted before it runs, so a bus
// access sees cycles() = the cycles before the accessing instruction and pc() = its address.
//
// Not modelled: the FPSCR cumulative exception flags (IOC DZC OFC UFC IDC IXC; the image
// reads FPSCR only through VMRS APSR_nzcv), the DSP extension's GE flags and SIMD
// instructions, exclusives, and anything the image does not contain (an unknown encoding
// stops the run as Undefined).
#pragma once

#include <cstdint>
#include <string>
#include <unordered_set>
#include <vector>

// A handler that each threaded<> wrapper holds in its own body (the compiler would call some).
#define HQ_INLINE inline __attribute__((always_inline))

namespace hqsim::thumb {

constexpr uint32_t kFlashBase = 0x00000000, kFlashSize = 512 * 1024;
constexpr uint32_t kSramBase = 0x1FFF0000, kSramSize = 192 * 1024;
constexpr unsigned kPageShift = 8;                  // invalidation granule of decoded SRAM code

// Why run() returned.
enum class Stop : uint8_t {
    Deadline,       // cycles reached the deadline (at an instruction boundary)
    Limit,          // the instruction limit was reached
    Wfi,            // after a WFI
    Bkpt,           // before a BKPT (PC at it)
    Svc,            // after an SVC (svc_number())
    Undefined,      // before an encoding the engine does not know or that is UNPREDICTABLE
    BusFault,       // before an access to nothing (fault_address())
    Unaligned,      // before an unaligned access the architecture or CCR.UNALIGN_TRP forbids
    DivByZero,      // before an SDIV/UDIV by zero with CCR.DIV_0_TRP
    InvState,       // after an interworking branch to an even address (EPSR.T would be 0)
    ExcReturn,      // an EXC_RETURN value reached the PC (exc_return()); the branch retired,
                    // the PC left at the branch
    NoFpu,          // before an FP instruction while fpu_enabled is off (the owner: NOCP)
    MaskChanged,    // after a CPS or MSR that wrote PRIMASK, FAULTMASK or BASEPRI
    StopAddress,    // before the instruction at a stop address (once: the next run that
                    // reaches it without having left it goes through)
    Requested,      // after the instruction whose bus access called request_stop()
    Isb,            // after an ISB, while stop_on_isb
};

const char* stop_name(Stop s);

// The owner's view of everything outside flash and SRAM. Returning false: nothing there
// (the run stops with BusFault). Inside a call the owner may read pc()/cycles() and call
// request_stop().
class Bus {
public:
    virtual ~Bus() = default;
    virtual bool read(uint32_t address, unsigned size, uint32_t& value) = 0;
    virtual bool write(uint32_t address, unsigned size, uint32_t value) = 0;
};

class Thumb;
struct Op;
using Handler = void (*)(Thumb&, const Op&);

// One decoded instruction.
struct Op {
    Handler fn = nullptr;       // nullptr: not decoded yet
    Handler next = nullptr;     // fn, then on to the next instruction (threaded<fn>), or none
    uint32_t imm = 0;
    uint8_t rd = 0, rn = 0, rm = 0, ra = 0;     // operands (FP: register numbers)
    uint8_t size = 0;           // 2 or 4 bytes
    uint8_t cyc = 0;            // cycles charged
    uint8_t cyc_it = 0;         // cycles charged inside an IT block (the model's conditional branch)
    uint8_t flags = 0;          // kFp | kStopAt | kSetFlags...
    uint8_t st = 0, sn = 0;     // shift type and amount / misc
    uint8_t x = 0, y = 0;       // misc
};

enum OpFlags : uint8_t {
    kFp = 1,                // an FP instruction (needs fpu_enabled; sets CONTROL.FPCA)
    kStopAt = 2,            // a stop address
    kSetFlags = 4,          // sets APSR flags
    kSetFlagsOutsideIt = 8, // a 16-bit encoding that sets flags only outside an IT block
};

class Thumb {
public:
    Thumb();
    void set_bus(Bus* bus) { bus_ = bus; }

    // Runs until a stop. The deadline may be brought forward during the run (from a bus
    // call: lower_deadline()); the run then stops at the next instruction boundary past it.
    Stop run(uint64_t deadline_cycles, uint64_t max_instructions);
    void lower_deadline(uint64_t cycles) {
        if (cycles < deadline_) deadline_ = cycles;
        if (cycles < chain_end_) chain_end_ = cycles;
    }
    void request_stop() { pending_ |= kPendRequested; }

    // --- state ---------------------------------------------------------------------------
    uint32_t reg(unsigned n) const { return r_[n]; }
    // An owner's write of the PC (set_reg(15, ...)) starts afresh: a stop address there stops
    // the next run. jump() moves the PC as exception entry and return do, keeping the stop
    // address last reported (a run that comes back to it after a handler goes through it).
    void set_reg(unsigned n, uint32_t v);
    void jump(uint32_t pc) { r_[15] = pc & ~1u; }
    // Exception entry and return: as jump(), and the stop address the interrupted code was
    // to go through is kept for its return (a stop inside the handler, at its first
    // instruction for one, must not make the interrupted code stop a second time there).
    void enter_exception(uint32_t handler);
    void return_from_exception(uint32_t pc);
    uint32_t pc() const { return r_[15]; }
    uint32_t apsr() const;              // N Z C V Q in bits 31..27
    void set_apsr(uint32_t v);
    uint32_t itstate() const { return it_; }
    void set_itstate(uint32_t v) { it_ = v & 0xFF; }
    uint32_t xpsr() const;              // APSR | IT/ICI | T | IPSR
    void set_xpsr(uint32_t v);
    uint32_t msp() const { return psp_active() ? sp_other_ : r_[13]; }
    uint32_t psp() const { return psp_active() ? r_[13] : sp_other_; }
    void set_msp(uint32_t v);
    void set_psp(uint32_t v);
    uint32_t control() const { return control_; }
    void set_control(uint32_t v);
    uint32_t ipsr() const { return ipsr_; }
    void set_ipsr(uint32_t v);          // handler mode is ipsr != 0 (SP is MSP there)
    bool handler_mode() const { return ipsr_ != 0; }
    uint32_t primask = 0, faultmask = 0, basepri = 0;
    uint32_t sreg(unsigned n) const { return s_[n]; }
    void set_sreg(unsigned n, uint32_t v) { s_[n] = v; }
    uint32_t fpscr() const { return fpscr_; }
    void set_fpscr(uint32_t v) { fpscr_ = v & kFpscrKept; }

    bool fpu_enabled = true;    // CPACR grants CP10/CP11
    // FPCCR.ASPEN and FPDSCR: the first FP instruction with CONTROL.FPCA clear (a new FP
    // context, e.g. in a handler) sets FPCA and FPSCR = FPDSCR (its mode bits; N Z C V
    // cleared, as unicorn does).
    bool aspen = true;
    uint32_t fpdscr = 0;
    bool stop_on_isb = false;   // stop after each ISB (Stop::Isb)
    // Instructions are fetched from flash below this address: the owner sets it to 0 while
    // the flash is being programmed, and a fetch from flash then stops the run as a fetch
    // from nothing (BusFault with fault_address() = the PC), which the owner reports as the
    // read collision it is.
    uint32_t flash_fetch_limit = kFlashSize;
    bool div0_trap = false;     // CCR.DIV_0_TRP
    bool unalign_trap = false;  // CCR.UNALIGN_TRP

    uint64_t cycles() const { return cycles_; }
    void set_cycles(uint64_t c) { cycles_ = c; }
    uint64_t instructions() const { return icount_; }
    void set_instructions(uint64_t n) { icount_ = n; }
    uint32_t fault_address() const { return fault_address_; }
    uint32_t exc_return() const { return exc_return_; }
    uint32_t svc_number() const { return svc_number_; }
    const std::string& stop_detail() const { return detail_; }

    // --- memory --------------------------------------------------------------------------
    uint8_t* flash() { return flash_.data(); }
    uint8_t* sram() { return sram_.data(); }
    bool sram_has_code(uint32_t off, uint32_t n) const {
        for (uint32_t p = off >> kPageShift; p <= (off + n - 1) >> kPageShift; ++p) {
            if (code_pages_[p]) return true;
        }
        return false;
    }
    // [a, a + n) in SRAM, a word-aligned, and for a store no decoded code there: its bytes,
    // for a block transfer straight to or from them (LDM/STM, VLDM/VSTM); else nullptr.
    uint8_t* sram_block(uint32_t a, uint32_t n, bool store) {
        const uint32_t so = a - kSramBase;
        if ((a & 3) || so >= kSramSize || n > kSramSize - so) return nullptr;
        if (store && sram_has_code(so, n)) return nullptr;
        return sram_.data() + so;
    }
    // Owner writes (flash programming, loading code): bytes copied, decoded code dropped.
    void write_memory(uint32_t address, const uint8_t* data, size_t n);
    bool read_memory(uint32_t address, uint8_t* out, size_t n) const;
    void invalidate(uint32_t address, uint32_t length);
    void add_stop_address(uint32_t address);
    void clear_stop_addresses();

    // The decoded record at an address (decoding it): for tests of the cost model.
    const Op* decoded(uint32_t address);

    // --- for the handlers (public so the decode/execute files reach them) -----------------
    static constexpr uint32_t kFpscrKept = 0xF7C00000;  // NZCV AHP DN FZ RMode
    enum : uint8_t { kPendBefore = 1, kPendAfter = 2, kPendRequested = 4 };
    uint32_t r_[16] = {};
    uint32_t n_ = 0, z_ = 0, c_ = 0, v_ = 0, q_ = 0;
    uint32_t it_ = 0;
    uint32_t npc_ = 0;
    bool in_it_ = false;
    uint32_t s_[32] = {};
    uint32_t fpscr_ = 0;
    uint32_t control_ = 0, ipsr_ = 0, sp_other_ = 0;
    uint8_t pending_ = 0;
    const Op* cur_ = nullptr;           // the instruction a chain of handlers stopped at
    // A chain of handlers runs while cycles_ < chain_end_ (the deadline; the instruction
    // limit and a bound on the chain's length, as every chained instruction costs a cycle
    // at least), past no Op whose flags meet chain_mask_ (kStopAt; kFp while an FP
    // instruction needs the run loop's ExecuteFPCheck), fetching below fetch_limit_. What
    // changes those ends the chain (break_chain()): a bus call (the owner may change anything
    // there), IT, MSR CONTROL.
    uint64_t chain_end_ = 0;
    uint8_t chain_mask_ = 0;
    uint32_t fetch_limit_ = 0;
    uint32_t it_stop_ = 0;              // a chain stopped in an IT block: its next IT | 0x100
    void break_chain() { chain_end_ = 0; }
    uint64_t deadline_ = 0, limit_ = 0;
    uint64_t icount_ = 0;               // apart from cycles_: two scalar adds, not one vector
    Stop pending_stop_ = Stop::Deadline;
    uint32_t fault_address_ = 0, exc_return_ = 0, svc_number_ = 0;
    std::string detail_;

    bool psp_active() const { return ipsr_ == 0 && (control_ & 2); }
    bool privileged() const { return ipsr_ != 0 || !(control_ & 1); }
    void stop_before(Stop s) { pending_ |= kPendBefore; pending_stop_ = s; }
    void stop_after(Stop s) { pending_ |= kPendAfter; pending_stop_ = s; }
    void undefined(const char* why);
    void bx_write_pc(uint32_t v);       // BX/BLX/LDR PC/POP PC/LDM PC
    void branch_to(uint32_t v) { npc_ = v & ~1u; }

    // Memory access from instructions: false after setting a stop (the handler returns).
    template <unsigned N> bool load(uint32_t a, uint32_t& v, bool must_align = false);
    template <unsigned N> bool store(uint32_t a, uint32_t v, bool must_align = false);
    // The same for an aligned access to SRAM or flash only (a store not over decoded code):
    // false, nothing done, for any other.
    template <unsigned N> bool load_fast(uint32_t a, uint32_t& v);
    template <unsigned N> bool store_fast(uint32_t a, uint32_t v);

    Op* lookup(uint32_t pc);
    uint64_t cycles_ = 0;
    // decoded records, one per halfword of flash and SRAM, each array with one more at its
    // end (never decoded: a chain running straight past the end stops there)
    std::vector<Op> fcache_, scache_;

private:
    Stop finish(const Op& op, uint32_t next_it);
    void decode(uint32_t pc, Op& op);
    void drop_page(uint32_t page);
    void sram_code_written(uint32_t off, unsigned n);
    bool bus_read(uint32_t a, unsigned n, uint32_t& v);
    bool bus_write(uint32_t a, unsigned n, uint32_t v);
    bool align_fault(uint32_t a, unsigned n, bool must_align);

    std::vector<uint8_t> flash_, sram_;
    std::vector<uint8_t> code_pages_;       // SRAM pages holding decoded code
    std::unordered_set<uint32_t> stops_;
    // The stop address the run last stopped at, until its instruction runs or the owner
    // writes the PC: a run that reaches it first goes through it (after a handler too), one
    // that stopped for another reason just before it stops there.
    static constexpr uint32_t kNoResume = 1;        // odd: never an instruction's address
    uint32_t resume_at_ = kNoResume;
    // resume_at_ of each interrupted level, innermost last (the NVIC nests at most as many
    // levels as it has priorities; past kResumeLevels the oldest are forgotten).
    static constexpr unsigned kResumeLevels = 32;
    uint32_t saved_resume_[kResumeLevels] = {};
    unsigned resume_depth_ = 0;
    Bus* bus_ = nullptr;
};

// Decoding (thumb_decode.cpp): fills op for the instruction at pc (hw1, hw2 its halfwords).
void decode_instruction(Op& op, uint32_t pc, uint16_t hw1, uint16_t hw2);
Handler threaded_fp(Handler fn);        // thumb_fp.cpp: threaded<fn> of an FP handler
void it_start(Thumb& t, const Op& o);   // thumb.cpp: an IT instruction's chain handler

inline __attribute__((always_inline)) Op* Thumb::lookup(uint32_t pc) {
    Op* op;
    if (pc < flash_fetch_limit && pc < kFlashSize) op = &fcache_[pc >> 1];
    else if (pc - kSramBase < kSramSize) op = &scache_[(pc - kSramBase) >> 1];
    else return nullptr;
    if (__builtin_expect(!op->fn, 0)) decode(pc, *op);
    return op;
}

// Threaded dispatch: H, then (nothing to stop for, the chain's ends not reached) the
// instruction retired and the next one's handler called from here, a jump from each
// handler's own site (its branch predicted per handler, not from the run loop's one call).
// Back to the run loop for anything else. STRAIGHT: H never writes the PC (decided per Op at
// decode time), so the next PC is this one's plus its size and the next Op the one after
// this in the same array (each array ends with an Op never decoded, which ends a chain).
// Otherwise H sees npc_ = the next instruction's address and may change it (a branch).
//
// STOPS false: H never stops the run (no bus call, no fault, no stop_*: data processing,
// FP arithmetic and moves), so nothing to check for after it.
//
// threaded_try<H, TRY> (a straight Op): TRY is H's fast form, which does the instruction
// only if nothing can stop it (no bus call: an access to SRAM or flash; no FP rule beyond
// the host's) and else changes nothing and returns false; then threaded<H> runs it, out of
// line (the fast path then needs no registers kept over a call).

// The instruction retired (PC, cycles, count) and the next one's chain handler called.
template <bool STRAIGHT>
HQ_INLINE void retire_and_next(Thumb& t, const Op& o, uint32_t pc0) {
    const uint32_t pc = STRAIGHT ? pc0 + o.size : t.npc_;
    t.r_[15] = pc;
    const uint64_t c = t.cycles_ + o.cyc;
    t.cycles_ = c;
    ++t.icount_;
    if (__builtin_expect(c >= t.chain_end_, 0)) return;
    const Op* n;
    if (STRAIGHT) {
        n = &o + (o.size >> 1);
    } else if (pc < t.fetch_limit_) {
        n = &t.fcache_[pc >> 1];
    } else if (pc - kSramBase < kSramSize) {
        n = &t.scache_[(pc - kSramBase) >> 1];
    } else {
        return;
    }
    const Handler f = n->next;
    if (__builtin_expect(!f || (n->flags & t.chain_mask_), 0)) return;
    f(t, *n);
}

template <Handler H, bool STRAIGHT, bool STOPS = true>
void threaded(Thumb& t, const Op& o) {
    const uint32_t pc0 = t.r_[15];
    if (!STRAIGHT) t.npc_ = pc0 + o.size;
    H(t, o);
    if (STOPS && __builtin_expect(t.pending_ != 0, 0)) {
        if (STRAIGHT) t.npc_ = pc0 + o.size;
        t.cur_ = &o;
        return;
    }
    retire_and_next<STRAIGHT>(t, o, pc0);
}

template <Handler H>
__attribute__((noinline)) void threaded_slow(Thumb& t, const Op& o) {
    threaded<H, true>(t, o);
}

using Try = bool (*)(Thumb&, const Op&);
template <Handler H, Try TRY>
void threaded_try(Thumb& t, const Op& o) {
    const uint32_t pc0 = t.r_[15];
    if (__builtin_expect(!TRY(t, o), 0)) return threaded_slow<H>(t, o);
    retire_and_next<true>(t, o, pc0);
}

template <unsigned N>
inline bool Thumb::load(uint32_t a, uint32_t& v, bool must_align) {
    if ((a & (N - 1)) && align_fault(a, N, must_align)) return false;
    const uint32_t so = a - kSramBase;
    if (so <= kSramSize - N) {
        v = 0;
        __builtin_memcpy(&v, sram_.data() + so, N);
        return true;
    }
    if (a <= kFlashSize - N) {
        v = 0;
        __builtin_memcpy(&v, flash_.data() + a, N);
        return true;
    }
    return bus_read(a, N, v);
}

template <unsigned N>
HQ_INLINE bool Thumb::load_fast(uint32_t a, uint32_t& v) {
    if (a & (N - 1)) return false;
    const uint32_t so = a - kSramBase;
    const uint8_t* p;
    if (so <= kSramSize - N) p = sram_.data() + so;
    else if (a <= kFlashSize - N) p = flash_.data() + a;
    else return false;
    v = 0;
    __builtin_memcpy(&v, p, N);
    return true;
}

template <unsigned N>
HQ_INLINE bool Thumb::store_fast(uint32_t a, uint32_t v) {
    const uint32_t so = a - kSramBase;
    if ((a & (N - 1)) || so > kSramSize - N || code_pages_[so >> kPageShift]) return false;
    __builtin_memcpy(sram_.data() + so, &v, N);
    return true;
}

template <unsigned N>
inline bool Thumb::store(uint32_t a, uint32_t v, bool must_align) {
    if ((a & (N - 1)) && align_fault(a, N, must_align)) return false;
    const uint32_t so = a - kSramBase;
    if (so <= kSramSize - N) {
        __builtin_memcpy(sram_.data() + so, &v, N);
        if (code_pages_[so >> kPageShift] | code_pages_[(so + N - 1) >> kPageShift]) {
            sram_code_written(so, N);
        }
        return true;
    }
    return bus_write(a, N, v);
}

}  // namespace hqsim::thumb
