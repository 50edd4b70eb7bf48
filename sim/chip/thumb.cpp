// The engine's CPU (thumb.hpp): state, memory, the decoded-instruction cache and the run loop.
#include "chip/thumb.hpp"

#include <cstring>

namespace hqsim::thumb {

const char* stop_name(Stop s) {
    static const char* const names[] = {
        "deadline", "limit", "wfi", "bkpt", "svc", "undefined", "bus_fault", "unaligned",
        "div_by_zero", "inv_state", "exc_return", "no_fpu", "mask_changed", "stop_address",
        "requested", "isb"};
    return names[static_cast<unsigned>(s)];
}

Thumb::Thumb()
    : fcache_(kFlashSize / 2 + 1), scache_(kSramSize / 2 + 1), flash_(kFlashSize, 0xFF),
      sram_(kSramSize, 0), code_pages_((kSramSize >> kPageShift) + 1, 0) {}

void Thumb::set_reg(unsigned n, uint32_t v) {
    r_[n & 15] = (n == 15 || n == 13) ? (v & ~(n == 15 ? 1u : 3u)) : v;
    if ((n & 15) == 15) {
        resume_at_ = kNoResume;
        resume_depth_ = 0;
    }
}

void Thumb::enter_exception(uint32_t handler) {
    if (resume_depth_ == kResumeLevels) {           // forget the oldest level
        for (unsigned i = 1; i < kResumeLevels; ++i) saved_resume_[i - 1] = saved_resume_[i];
        --resume_depth_;
    }
    saved_resume_[resume_depth_++] = resume_at_;
    resume_at_ = kNoResume;
    jump(handler);
}

void Thumb::return_from_exception(uint32_t pc) {
    resume_at_ = resume_depth_ ? saved_resume_[--resume_depth_] : kNoResume;
    jump(pc);
}

uint32_t Thumb::apsr() const {
    return (n_ << 31) | (z_ << 30) | (c_ << 29) | (v_ << 28) | (q_ << 27);
}

void Thumb::set_apsr(uint32_t v) {
    n_ = v >> 31;
    z_ = (v >> 30) & 1;
    c_ = (v >> 29) & 1;
    v_ = (v >> 28) & 1;
    q_ = (v >> 27) & 1;
}

uint32_t Thumb::xpsr() const {
    return apsr() | ((it_ & 3) << 25) | ((it_ >> 2) << 10) | (1u << 24) | ipsr_;
}

void Thumb::set_xpsr(uint32_t v) {
    set_apsr(v);
    it_ = ((v >> 25) & 3) | (((v >> 10) & 0x3F) << 2);
    set_ipsr(v & 0x1FF);
}

void Thumb::set_msp(uint32_t v) { (psp_active() ? sp_other_ : r_[13]) = v & ~3u; }
void Thumb::set_psp(uint32_t v) { (psp_active() ? r_[13] : sp_other_) = v & ~3u; }

void Thumb::set_control(uint32_t v) {
    const bool was = psp_active();
    control_ = v & 7;
    if (was != psp_active()) std::swap(r_[13], sp_other_);
}

void Thumb::set_ipsr(uint32_t v) {
    const bool was = psp_active();
    ipsr_ = v & 0x1FF;
    if (was != psp_active()) std::swap(r_[13], sp_other_);
}

void Thumb::undefined(const char* why) {
    detail_ = why;
    stop_before(Stop::Undefined);
}

void Thumb::bx_write_pc(uint32_t v) {
    if ((v >> 28) == 0xF) {
        exc_return_ = v;
        npc_ = r_[15];
        stop_after(Stop::ExcReturn);
    } else {
        npc_ = v & ~1u;
        if (!(v & 1)) {
            fault_address_ = v;
            stop_after(Stop::InvState);
        }
    }
}

bool Thumb::align_fault(uint32_t a, unsigned n, bool must_align) {
    if (!must_align && !unalign_trap) return false;
    fault_address_ = a;
    detail_ = std::to_string(n) + "-byte access at an unaligned address";
    stop_before(Stop::Unaligned);
    return true;
}

bool Thumb::bus_read(uint32_t a, unsigned n, uint32_t& v) {
    break_chain();
    v = 0;
    if (bus_ && bus_->read(a, n, v)) return true;
    fault_address_ = a;
    detail_ = "read of nothing";
    stop_before(Stop::BusFault);
    return false;
}

bool Thumb::bus_write(uint32_t a, unsigned n, uint32_t v) {
    break_chain();
    if (bus_ && bus_->write(a, n, v)) return true;
    fault_address_ = a;
    detail_ = "write to nothing";
    stop_before(Stop::BusFault);
    return false;
}

// --- the decoded-instruction cache ------------------------------------------------------

void Thumb::drop_page(uint32_t page) {
    code_pages_[page] = 0;
    const uint32_t first = (page << kPageShift) / 2;
    const uint32_t end = std::min<uint32_t>(first + (1u << kPageShift) / 2, kSramSize / 2);
    for (uint32_t i = first; i < end; ++i) scache_[i].fn = scache_[i].next = nullptr;
    if (first) scache_[first - 1].fn = scache_[first - 1].next = nullptr;   // across the edge
}

void Thumb::sram_code_written(uint32_t off, unsigned n) {
    for (uint32_t p = off >> kPageShift; p <= (off + n - 1) >> kPageShift; ++p) {
        if (code_pages_[p]) drop_page(p);
    }
}

void Thumb::invalidate(uint32_t address, uint32_t length) {
    if (!length) return;
    const uint64_t end = uint64_t{address} + length;
    for (uint64_t a = address & ~1u; a < end; a += 2) {
        if (a < kFlashSize) {
            fcache_[a / 2].fn = fcache_[a / 2].next = nullptr;
            if (a >= 2) fcache_[a / 2 - 1].fn = fcache_[a / 2 - 1].next = nullptr;
        } else if (a - kSramBase < kSramSize) {
            sram_code_written(static_cast<uint32_t>(a - kSramBase), 2);
        }
    }
}

void Thumb::write_memory(uint32_t address, const uint8_t* data, size_t n) {
    const uint32_t so = address - kSramBase;
    if (n && so < kSramSize && n <= kSramSize - so) {       // SRAM (a DMA, an exception frame)
        std::memcpy(sram_.data() + so, data, n);
        if (sram_has_code(so, static_cast<uint32_t>(n))) {
            sram_code_written(so, static_cast<unsigned>(n));
        }
        return;
    }
    for (size_t i = 0; i < n; ++i) {
        const uint32_t a = address + static_cast<uint32_t>(i);
        if (a < kFlashSize) flash_[a] = data[i];
        else if (a - kSramBase < kSramSize) sram_[a - kSramBase] = data[i];
    }
    invalidate(address, static_cast<uint32_t>(n));
}

bool Thumb::read_memory(uint32_t address, uint8_t* out, size_t n) const {
    const uint32_t so = address - kSramBase;
    if (so < kSramSize && n <= kSramSize - so) {
        std::memcpy(out, sram_.data() + so, n);
        return true;
    }
    if (address < kFlashSize && n <= kFlashSize - address) {
        std::memcpy(out, flash_.data() + address, n);
        return true;
    }
    for (size_t i = 0; i < n; ++i) {
        const uint32_t a = address + static_cast<uint32_t>(i);
        if (a < kFlashSize) out[i] = flash_[a];
        else if (a - kSramBase < kSramSize) out[i] = sram_[a - kSramBase];
        else return false;
    }
    return true;
}

void Thumb::add_stop_address(uint32_t address) {
    stops_.insert(address & ~1u);
    invalidate(address & ~1u, 2);
}

void Thumb::clear_stop_addresses() {
    for (uint32_t a : stops_) invalidate(a, 2);
    stops_.clear();
}

__attribute__((noinline)) void Thumb::decode(uint32_t pc, Op& op) {
    uint8_t bytes[4] = {0xFF, 0xFF, 0xFF, 0xFF};
    read_memory(pc, bytes, 2);
    read_memory(pc + 2, bytes + 2, 2);
    const uint16_t hw1 = static_cast<uint16_t>(bytes[0] | (bytes[1] << 8));
    const uint16_t hw2 = static_cast<uint16_t>(bytes[2] | (bytes[3] << 8));
    op = Op{};
    decode_instruction(op, pc, hw1, hw2);
    if (stops_.count(pc)) op.flags |= kStopAt;
    if (pc - kSramBase < kSramSize) {
        const uint32_t off = pc - kSramBase;
        code_pages_[off >> kPageShift] = 1;
        code_pages_[(off + op.size - 1) >> kPageShift] = 1;
    }
}

const Op* Thumb::decoded(uint32_t address) { return lookup(address & ~1u); }

// --- the run loop -------------------------------------------------------------------------

namespace {
// Bit nzcv of kCondPass[cond]: the condition passes with flags N Z C V = nzcv (bits 3..0).
constexpr uint16_t cond_mask(unsigned cond) {
    uint16_t m = 0;
    for (unsigned f = 0; f < 16; ++f) {
        const bool n = f & 8, z = f & 4, c = f & 2, v = f & 1;
        bool r = false;
        switch (cond >> 1) {
            case 0: r = z; break;
            case 1: r = c; break;
            case 2: r = n; break;
            case 3: r = v; break;
            case 4: r = c && !z; break;
            case 5: r = n == v; break;
            case 6: r = !z && n == v; break;
            default: r = true; break;
        }
        if ((cond & 1) && cond != 15) r = !r;
        if (r) m = static_cast<uint16_t>(m | (1u << f));
    }
    return m;
}
constexpr uint16_t kCondPass[16] = {
    cond_mask(0), cond_mask(1), cond_mask(2), cond_mask(3), cond_mask(4), cond_mask(5),
    cond_mask(6), cond_mask(7), cond_mask(8), cond_mask(9), cond_mask(10), cond_mask(11),
    cond_mask(12), cond_mask(13), cond_mask(14), cond_mask(15)};
}  // namespace

bool condition_passed(const Thumb& t, unsigned cond) {
    const unsigned f = (t.n_ << 3) | (t.z_ << 2) | (t.c_ << 1) | t.v_;
    return (kCondPass[cond & 15] >> f) & 1;
}

// --- IT blocks in a chain ----------------------------------------------------------------
// The IT instruction hands on to its block's instructions, each run as the run loop runs one
// inside a block (its condition, its handler fn with in_it_, the cost inside a block, the IT
// state advanced), then on to the next: in the block, or past it (its chain handler). What
// the run loop must see (a stop address, an FP instruction while the FP context needs its
// ExecuteFPCheck) ends the chain before that instruction, as in threaded<>.
namespace {
inline uint32_t it_advance(uint32_t it) {
    return (it & 7) ? ((it & 0xE0) | ((it << 1) & 0x1F)) : 0;
}

void it_block(Thumb& t, const Op& o) {
    t.npc_ = t.r_[15] + o.size;
    const uint32_t next_it = it_advance(t.it_);
    if (condition_passed(t, t.it_ >> 4)) {
        t.in_it_ = true;
        o.fn(t, o);
        t.in_it_ = false;
        if (__builtin_expect(t.pending_ != 0, 0)) {
            t.cur_ = &o;
            t.it_stop_ = next_it | 0x100;
            return;
        }
    }
    const uint32_t pc = t.npc_;
    t.r_[15] = pc;
    const uint64_t c = t.cycles_ + o.cyc_it;
    t.cycles_ = c;
    ++t.icount_;
    t.it_ = next_it;
    if (c >= t.chain_end_) return;
    const Op* n;
    if (pc < t.fetch_limit_) n = &t.fcache_[pc >> 1];
    else if (pc - kSramBase < kSramSize) n = &t.scache_[(pc - kSramBase) >> 1];
    else return;
    if (!n->next || (n->flags & t.chain_mask_)) return;
    if (next_it) it_block(t, *n);
    else n->next(t, *n);
}
}  // namespace

void it_start(Thumb& t, const Op& o) {
    t.it_ = o.imm;
    t.r_[15] += o.size;
    const uint64_t c = t.cycles_ + o.cyc;
    t.cycles_ = c;
    ++t.icount_;
    if (c >= t.chain_end_) return;
    const Op* n = &o + (o.size >> 1);
    if (!n->next || (n->flags & t.chain_mask_)) return;
    it_block(t, *n);
}

Stop Thumb::run(uint64_t deadline_cycles, uint64_t max_instructions) {
    const uint64_t limit = icount_ + max_instructions;
    deadline_ = deadline_cycles;
    limit_ = limit;
    pending_ = 0;
    in_it_ = false;
    Op* op = nullptr;
    for (;;) {
        if (cycles_ >= deadline_) return Stop::Deadline;
        if (icount_ >= limit) return Stop::Limit;
        const uint32_t pc = r_[15];
        op = lookup(pc);
        if (__builtin_expect(!op, 0)) {
            fault_address_ = pc;
            detail_ = "instruction fetch from nothing";
            return Stop::BusFault;
        }
        npc_ = pc + op->size;
        if (__builtin_expect(op->flags & (kStopAt | kFp), 0)) {
            if (op->flags & kStopAt) {
                if (pc != resume_at_) {
                    resume_at_ = pc;
                    return Stop::StopAddress;
                }
                resume_at_ = kNoResume;             // reported: this run goes through it
            }
            if ((op->flags & kFp) && !it_) {        // ExecuteFPCheck (in IT: below)
                if (!fpu_enabled) return Stop::NoFpu;
                if (!(control_ & 4)) {
                    control_ |= 4;
                    if (aspen) fpscr_ = fpdscr & 0x07C00000u;
                }
            }
        }
        if (__builtin_expect(it_ == 0, 1) && op->next) {
            cur_ = op;
            // the chain's ends (thumb.hpp): at most 256 instructions, and none past the limit
            chain_end_ = std::min(deadline_, cycles_ + std::min<uint64_t>(256, limit - icount_));
            chain_mask_ = kStopAt | (fpu_enabled && (control_ & 4) ? 0 : kFp);
            fetch_limit_ = std::min(flash_fetch_limit, kFlashSize);
            // a limit inside the flash: each instruction from here (a straight run of a chain
            // would not see it)
            if (fetch_limit_ != 0 && fetch_limit_ != kFlashSize) break_chain();
            op->next(*this, *op);                   // retires it and maybe more (threaded)
            if (__builtin_expect(pending_ != 0, 0)) {
                const uint32_t in_it = it_stop_;
                it_stop_ = 0;
                return finish(*cur_, in_it);
            }
            continue;
        }
        if (__builtin_expect(it_ == 0, 1)) {
            op->fn(*this, *op);                     // the IT instruction sets it_ itself
            if (__builtin_expect(pending_ != 0, 0)) return finish(*op, 0);
            r_[15] = npc_;
            cycles_ += op->cyc;
            ++icount_;
            continue;
        }
        // inside an IT block: the condition, ExecuteFPCheck only when it passes, the cost
        // the model charges inside a block, the IT state advanced
        const uint32_t next_it = it_advance(it_);
        if (condition_passed(*this, it_ >> 4)) {
            if (op->flags & kFp) {
                if (!fpu_enabled) return Stop::NoFpu;
                if (!(control_ & 4)) {
                    control_ |= 4;
                    if (aspen) fpscr_ = fpdscr & 0x07C00000u;
                }
            }
            in_it_ = true;
            op->fn(*this, *op);
            in_it_ = false;
            if (__builtin_expect(pending_ != 0, 0)) return finish(*op, next_it | 0x100);
        }
        r_[15] = npc_;
        cycles_ += op->cyc_it;
        ++icount_;
        it_ = next_it;
    }
}

// A handler asked to stop: before the instruction (nothing retires) or after it.
Stop Thumb::finish(const Op& op, uint32_t next_it) {
    const uint8_t p = pending_;
    pending_ = 0;
    if (p & kPendBefore) return pending_stop_;
    r_[15] = npc_;
    cycles_ += (next_it & 0x100) ? op.cyc_it : op.cyc;
    ++icount_;
    if (next_it & 0x100) it_ = next_it & 0xFF;
    return (p & kPendAfter) ? pending_stop_ : Stop::Requested;
}

}  // namespace hqsim::thumb
