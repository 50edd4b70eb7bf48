// The engine's integer instructions (thumb.hpp): one handler per operation and form, their
// operands decoded into the Op record by thumb_decode.cpp (the only file including this).
#pragma once

#include "chip/thumb.hpp"

namespace hqsim::thumb {

bool condition_passed(const Thumb& t, unsigned cond);        // thumb.cpp

namespace ops {

enum Shift : uint8_t { LSL, LSR, ASR, ROR, RRX };

// R[n] as an operand: the PC reads as the instruction's address + 4.
inline uint32_t R(const Thumb& t, unsigned n) { return t.r_[n] + (n == 15 ? 4 : 0); }
inline bool setflags(const Thumb& t, const Op& o) {
    return (o.flags & kSetFlags) || ((o.flags & kSetFlagsOutsideIt) && !t.in_it_);
}
inline void nz(Thumb& t, uint32_t r) {
    t.n_ = r >> 31;
    t.z_ = r == 0;
}

inline uint32_t shift_c(uint32_t v, unsigned type, unsigned n, uint32_t& carry) {
    if (type == RRX) {
        const uint32_t r = (carry << 31) | (v >> 1);
        carry = v & 1;
        return r;
    }
    if (n == 0) return v;
    switch (type) {
        case LSL:
            if (n < 32) { carry = (v >> (32 - n)) & 1; return v << n; }
            carry = n == 32 ? (v & 1) : 0;
            return 0;
        case LSR:
            if (n < 32) { carry = (v >> (n - 1)) & 1; return v >> n; }
            carry = n == 32 ? (v >> 31) : 0;
            return 0;
        case ASR:
            if (n < 32) {
                carry = (v >> (n - 1)) & 1;
                return static_cast<uint32_t>(static_cast<int32_t>(v) >> n);
            }
            carry = v >> 31;
            return carry ? 0xFFFFFFFFu : 0;
        default: {
            const unsigned m = n & 31;
            const uint32_t r = m ? ((v >> m) | (v << (32 - m))) : v;
            carry = r >> 31;
            return r;
        }
    }
}

inline uint32_t add_with_carry(Thumb& t, uint32_t x, uint32_t y, uint32_t cin, bool sf) {
    const uint64_t u = uint64_t{x} + y + cin;
    const uint32_t r = static_cast<uint32_t>(u);
    if (sf) {
        nz(t, r);
        t.c_ = static_cast<uint32_t>(u >> 32);
        t.v_ = ((x ^ r) & (y ^ r)) >> 31;
    }
    return r;
}

enum Dp : uint8_t { AND, EOR, ORR, ORN, BIC, MOV, MVN, ADD, ADC, SUB, SBC, RSB, TST, TEQ, CMP,
                    CMN };
// modified immediate, shifted register, shift by register, register unshifted (LSL #0)
enum Src : uint8_t { IMM, REG, REGREG, REG0 };
// Flags set per the Op at run time (any operand may be the PC, any Rd), or known at decode
// time for an Op in a chain (outside IT blocks; no operand and no Rd the PC): NOFLAGS, FLAGS.
enum FlagMode : uint8_t { RUNTIME, NOFLAGS, FLAGS };

// Data processing: Rd = Rn op operand2. Src IMM: o.imm (o.x: the immediate's carry out is its
// bit 31); REG: R[rm] shifted by (st, sn); REGREG: R[rn] shifted (st) by R[rm]<7:0> (MOV).
template <Dp OP, Src SRC, FlagMode FM = RUNTIME>
HQ_INLINE void dp(Thumb& t, const Op& o) {
    const auto reg = [&t](unsigned n) { return FM == RUNTIME ? R(t, n) : t.r_[n]; };
    uint32_t carry = t.c_;
    uint32_t b;
    if constexpr (SRC == IMM) {
        b = o.imm;
        if (o.x) carry = b >> 31;
    } else if constexpr (SRC == REG) {
        b = shift_c(reg(o.rm), o.st, o.sn, carry);
    } else if constexpr (SRC == REG0) {
        b = reg(o.rm);
    } else {
        b = shift_c(t.r_[o.rn], o.st, t.r_[o.rm] & 0xFF, carry);
    }
    const bool sf = FM == RUNTIME ? setflags(t, o) : FM == FLAGS;
    const uint32_t a = (OP == MOV || OP == MVN) ? 0 : reg(o.rn);
    uint32_t r = 0;
    bool logical = true;
    switch (OP) {
        case AND: case TST: r = a & b; break;
        case EOR: case TEQ: r = a ^ b; break;
        case ORR: r = a | b; break;
        case ORN: r = a | ~b; break;
        case BIC: r = a & ~b; break;
        case MOV: r = b; break;
        case MVN: r = ~b; break;
        case ADD: case CMN: r = add_with_carry(t, a, b, 0, sf); logical = false; break;
        case ADC: r = add_with_carry(t, a, b, t.c_, sf); logical = false; break;
        case SUB: case CMP: r = add_with_carry(t, a, ~b, 1, sf); logical = false; break;
        case SBC: r = add_with_carry(t, a, ~b, t.c_, sf); logical = false; break;
        case RSB: r = add_with_carry(t, ~a, b, 1, sf); logical = false; break;
    }
    if (logical && sf) {
        nz(t, r);
        t.c_ = carry;
    }
    if constexpr (OP == TST || OP == TEQ || OP == CMP || OP == CMN) return;
    if (FM == RUNTIME && o.rd == 15) t.branch_to(r);
    else t.r_[o.rd] = r;
}

// --- loads and stores ---------------------------------------------------------------------
enum Mode : uint8_t { OFF, PRE, POST, REGOFF, LIT };
enum Kind : uint8_t { LDR, LDRB, LDRH, LDRSB, LDRSH, STR, STRB, STRH };

// Address modes: OFF R[rn]+imm; PRE the same with writeback; POST R[rn], then R[rn]+imm;
// REGOFF R[rn] + (R[rm] << sn); LIT Align(PC,4)+imm. imm is signed (two's complement). Rn is
// never the PC but in LIT, nor a stored Rt (the decoder's UNDEFINED forms).
// TRY (an Op that does not write the PC): only an aligned access to SRAM or flash (no SRAM
// holding decoded code for a store); false, nothing changed, for any other (threaded_try's slow
// path then runs ldst).
template <Kind K, Mode M, bool TRY = false>
HQ_INLINE bool ldst_access(Thumb& t, const Op& o) {
    constexpr unsigned N = (K == LDR || K == STR)                    ? 4
                           : (K == LDRH || K == LDRSH || K == STRH) ? 2
                                                                    : 1;
    uint32_t a;
    if constexpr (M == LIT) a = ((t.r_[15] + 4) & ~3u) + o.imm;
    else if constexpr (M == REGOFF) a = t.r_[o.rn] + (t.r_[o.rm] << o.sn);
    else if constexpr (M == POST) a = t.r_[o.rn];
    else a = t.r_[o.rn] + o.imm;
    if constexpr (K >= STR) {
        const uint32_t v = t.r_[o.rd];
        if (!(TRY ? t.store_fast<N>(a, v) : t.store<N>(a, v))) return false;
    } else {
        uint32_t v;
        // LDR PC: aligned
        if (!(TRY ? t.load_fast<N>(a, v) : t.load<N>(a, v, K == LDR && o.rd == 15))) return false;
        if constexpr (K == LDRSB) v = static_cast<uint32_t>(static_cast<int8_t>(v));
        if constexpr (K == LDRSH) v = static_cast<uint32_t>(static_cast<int16_t>(v));
        if constexpr (M == PRE) t.r_[o.rn] = a;
        if constexpr (M == POST) t.r_[o.rn] = a + o.imm;
        if (!TRY && K == LDR && o.rd == 15) t.bx_write_pc(v);     // TRY: never Rt = PC
        else t.r_[o.rd] = v;
        return true;
    }
    if constexpr (M == PRE) t.r_[o.rn] = a;
    if constexpr (M == POST) t.r_[o.rn] = a + o.imm;
    return true;
}
template <Kind K, Mode M>
HQ_INLINE void ldst(Thumb& t, const Op& o) { ldst_access<K, M>(t, o); }
template <Kind K, Mode M>
HQ_INLINE bool ldst_try(Thumb& t, const Op& o) { return ldst_access<K, M, true>(t, o); }

// LDRD/STRD: rd, ra the pair; o.x: 0 offset, 1 pre-indexed, 2 post-indexed, 3 literal.
template <bool LOAD>
void ldst_dual(Thumb& t, const Op& o) {
    uint32_t base = o.x == 3 ? ((t.r_[15] + 4) & ~3u) : t.r_[o.rn];
    const uint32_t a = o.x == 2 ? base : base + o.imm;
    if constexpr (LOAD) {
        uint32_t lo, hi;
        if (!t.load<4>(a, lo, true) || !t.load<4>(a + 4, hi, true)) return;
        if (o.x == 1 || o.x == 2) t.r_[o.rn] = base + o.imm;
        t.r_[o.rd] = lo;
        t.r_[o.ra] = hi;
    } else {
        if (!t.store<4>(a, t.r_[o.rd], true) || !t.store<4>(a + 4, t.r_[o.ra], true)) return;
        if (o.x == 1 || o.x == 2) t.r_[o.rn] = base + o.imm;
    }
}

// LDM/STM: o.imm the register list, o.x writeback, o.y decrement before.
template <bool LOAD>
void ldst_multiple(Thumb& t, const Op& o) {
    const uint32_t list = o.imm;
    const uint32_t n = o.sn;                    // registers in the list
    const uint32_t base = t.r_[o.rn];
    const uint32_t start = o.y ? base - 4 * n : base;
    const uint32_t end = o.y ? base - 4 * n : base + 4 * n;
    uint32_t a = start;
    // all in SRAM (a store not over decoded code): straight to the array
    if (uint8_t* p = t.sram_block(start, 4 * n, !LOAD)) {
        if constexpr (LOAD) {
            if (o.x) t.r_[o.rn] = end;
            for (uint32_t l = list & 0x7FFF; l; l &= l - 1) {
                __builtin_memcpy(&t.r_[__builtin_ctz(l)], p, 4);
                p += 4;
            }
            if (list & 0x8000) {
                uint32_t pc;
                __builtin_memcpy(&pc, p, 4);
                t.bx_write_pc(pc);
            }
        } else {
            for (uint32_t l = list & 0x7FFF; l; l &= l - 1) {
                __builtin_memcpy(p, &t.r_[__builtin_ctz(l)], 4);
                p += 4;
            }
            if (o.x) t.r_[o.rn] = end;
        }
        return;
    }
    if constexpr (LOAD) {
        uint32_t vals[16];
        for (unsigned i = 0; i < 16; ++i) {
            if (!(list >> i & 1)) continue;
            if (!t.load<4>(a, vals[i], true)) return;
            a += 4;
        }
        if (o.x) t.r_[o.rn] = end;
        for (unsigned i = 0; i < 15; ++i) {
            if (list >> i & 1) t.r_[i] = vals[i];
        }
        if (list & 0x8000) t.bx_write_pc(vals[15]);
    } else {
        for (unsigned i = 0; i < 15; ++i) {
            if (!(list >> i & 1)) continue;
            if (!t.store<4>(a, t.r_[i], true)) return;
            a += 4;
        }
        if (o.x) t.r_[o.rn] = end;
    }
}

// --- branches -----------------------------------------------------------------------------
inline void b_cond(Thumb& t, const Op& o) {
    if (condition_passed(t, o.x)) t.branch_to(t.r_[15] + 4 + o.imm);
}
// The same with its condition (o.x) known at decode time.
template <unsigned COND>
HQ_INLINE bool passed(const Thumb& t) {
    bool r;
    switch (COND >> 1) {
        case 0: r = t.z_; break;
        case 1: r = t.c_; break;
        case 2: r = t.n_; break;
        case 3: r = t.v_; break;
        case 4: r = t.c_ && !t.z_; break;
        case 5: r = t.n_ == t.v_; break;
        case 6: r = !t.z_ && t.n_ == t.v_; break;
        default: r = true; break;
    }
    return (COND & 1) && COND != 15 ? !r : r;
}
template <unsigned COND>
HQ_INLINE void b_if(Thumb& t, const Op& o) {
    if (passed<COND>(t)) t.branch_to(t.r_[15] + 4 + o.imm);
}
inline void b(Thumb& t, const Op& o) { t.branch_to(t.r_[15] + 4 + o.imm); }
inline void bl(Thumb& t, const Op& o) {
    t.r_[14] = t.npc_ | 1;
    t.branch_to(t.r_[15] + 4 + o.imm);
}
inline void bx(Thumb& t, const Op& o) { t.bx_write_pc(R(t, o.rm)); }
inline void blx(Thumb& t, const Op& o) {
    const uint32_t target = R(t, o.rm);
    t.r_[14] = t.npc_ | 1;
    t.bx_write_pc(target);
}
inline void cbz(Thumb& t, const Op& o) {
    if ((t.r_[o.rn] == 0) != (o.x != 0)) t.branch_to(t.r_[15] + 4 + o.imm);
}
template <bool HALF>
void tb(Thumb& t, const Op& o) {
    uint32_t off;
    const uint32_t base = R(t, o.rn);
    if (HALF ? !t.load<2>(base + 2 * t.r_[o.rm], off) : !t.load<1>(base + t.r_[o.rm], off)) {
        return;
    }
    t.branch_to(t.r_[15] + 4 + 2 * off);
}

// --- everything else ----------------------------------------------------------------------
inline void nop(Thumb&, const Op&) {}
inline void it(Thumb& t, const Op& o) {       // in a chain: it_start (thumb.cpp)
    t.it_ = o.imm;
    t.break_chain();
}
inline void wfi(Thumb& t, const Op&) { t.stop_after(Stop::Wfi); }
// ISB: a stop after it only while the owner watches for one (the FPU-enable check).
inline void isb(Thumb& t, const Op&) {
    if (t.stop_on_isb) t.stop_after(Stop::Isb);
}
inline void bkpt(Thumb& t, const Op&) { t.stop_before(Stop::Bkpt); }
inline void svc(Thumb& t, const Op& o) {
    t.svc_number_ = o.imm;
    t.stop_after(Stop::Svc);
}
inline void udf(Thumb& t, const Op&) { t.undefined("undefined instruction"); }
inline void unknown(Thumb& t, const Op&) { t.undefined("encoding not known to the engine"); }

inline void cps(Thumb& t, const Op& o) {   // o.x: disable; o.y: I, F bits
    if (!t.privileged()) return;
    if (o.y & 2) t.primask = o.x;
    if ((o.y & 1) && (o.x == 0 || t.ipsr_ != 2)) t.faultmask = o.x;
    t.stop_after(Stop::MaskChanged);
}

inline void mrs(Thumb& t, const Op& o) {
    const unsigned sysm = o.imm;
    uint32_t v = 0;
    if (sysm < 8) {
        if (sysm & 1) v |= t.ipsr_;
        if (!(sysm & 4)) v |= t.apsr();
    } else if (t.privileged() || sysm == 20) {
        switch (sysm) {
            case 8: v = t.msp(); break;
            case 9: v = t.psp(); break;
            case 16: v = t.primask; break;
            case 17: case 18: v = t.basepri; break;
            case 19: v = t.faultmask; break;
            case 20: v = t.control_; break;
            default: break;
        }
    }
    t.r_[o.rd] = v;
}

inline void msr(Thumb& t, const Op& o) {
    const unsigned sysm = o.imm;
    const uint32_t v = t.r_[o.rn];
    if (sysm < 8) {
        if (!(sysm & 4) && (o.x & 2)) {
            t.n_ = v >> 31; t.z_ = (v >> 30) & 1; t.c_ = (v >> 29) & 1; t.v_ = (v >> 28) & 1;
            t.q_ = (v >> 27) & 1;
        }
        return;
    }
    if (!t.privileged()) return;
    switch (sysm) {
        case 8: t.set_msp(v); return;
        case 9: t.set_psp(v); return;
        case 16: t.primask = v & 1; break;
        case 17: t.basepri = v & 0xFF; break;
        case 18:
            if ((v & 0xFF) && ((v & 0xFF) < t.basepri || t.basepri == 0)) t.basepri = v & 0xFF;
            break;
        case 19: if (t.ipsr_ != 2) t.faultmask = v & 1; break;
        case 20:                        // nPRIV, FPCA; SPSEL in thread mode only
            t.set_control(t.ipsr_ == 0 ? (v & 7) : ((t.control_ & 2) | (v & 5)));
            t.break_chain();            // FPCA: the chain's kFp mask
            return;
        default: return;
    }
    t.stop_after(Stop::MaskChanged);
}

inline void movw(Thumb& t, const Op& o) { t.r_[o.rd] = o.imm; }
inline void movt(Thumb& t, const Op& o) { t.r_[o.rd] = (t.r_[o.rd] & 0xFFFF) | (o.imm << 16); }
inline void adr(Thumb& t, const Op& o) { t.r_[o.rd] = ((t.r_[15] + 4) & ~3u) + o.imm; }
inline void addw(Thumb& t, const Op& o) { t.r_[o.rd] = R(t, o.rn) + o.imm; }

inline void mul(Thumb& t, const Op& o) {
    const uint32_t r = t.r_[o.rn] * t.r_[o.rm];
    t.r_[o.rd] = r;
    if (setflags(t, o)) nz(t, r);
}
inline void mla(Thumb& t, const Op& o) { t.r_[o.rd] = t.r_[o.rn] * t.r_[o.rm] + t.r_[o.ra]; }
inline void mls(Thumb& t, const Op& o) { t.r_[o.rd] = t.r_[o.ra] - t.r_[o.rn] * t.r_[o.rm]; }
// Long multiplies: rd the low half, ra the high half; o.x: 1 signed, o.y: 1 accumulate.
inline void mull(Thumb& t, const Op& o) {
    uint64_t r = o.x ? static_cast<uint64_t>(int64_t{static_cast<int32_t>(t.r_[o.rn])} *
                                             static_cast<int32_t>(t.r_[o.rm]))
                     : uint64_t{t.r_[o.rn]} * t.r_[o.rm];
    if (o.y) r += (uint64_t{t.r_[o.ra]} << 32) | t.r_[o.rd];
    t.r_[o.rd] = static_cast<uint32_t>(r);
    t.r_[o.ra] = static_cast<uint32_t>(r >> 32);
}
template <bool SIGNED>
void div(Thumb& t, const Op& o) {
    const uint32_t n = t.r_[o.rn], m = t.r_[o.rm];
    if (m == 0) {
        if (t.div0_trap) {
            t.stop_before(Stop::DivByZero);
            return;
        }
        t.r_[o.rd] = 0;
        return;
    }
    if (SIGNED) {
        const int32_t a = static_cast<int32_t>(n), d = static_cast<int32_t>(m);
        t.r_[o.rd] = (a == INT32_MIN && d == -1) ? n : static_cast<uint32_t>(a / d);
    } else {
        t.r_[o.rd] = n / m;
    }
}

// Bit fields: o.x lsb, o.y width (UBFX/SBFX) or msb (BFI/BFC).
inline void ubfx(Thumb& t, const Op& o) {
    const uint32_t v = t.r_[o.rn] >> o.x;
    t.r_[o.rd] = o.y >= 32 ? v : v & ((1u << o.y) - 1);
}
inline void sbfx(Thumb& t, const Op& o) {
    const uint32_t v = t.r_[o.rn] << (32 - o.x - o.y);
    t.r_[o.rd] = static_cast<uint32_t>(static_cast<int32_t>(v) >> (32 - o.y));
}
inline void bfi(Thumb& t, const Op& o) {       // rn == 15: BFC
    const unsigned width = o.y - o.x + 1;
    const uint32_t mask = (width >= 32 ? 0xFFFFFFFFu : ((1u << width) - 1)) << o.x;
    const uint32_t src = o.rn == 15 ? 0 : t.r_[o.rn] << o.x;
    t.r_[o.rd] = (t.r_[o.rd] & ~mask) | (src & mask);
}
// Extends: o.x 0 UXTB 1 UXTH 2 SXTB 3 SXTH; o.sn the rotation; rn 15: no addend.
inline void extend(Thumb& t, const Op& o) {
    const uint32_t v0 = t.r_[o.rm];
    const uint32_t v = o.sn ? ((v0 >> o.sn) | (v0 << (32 - o.sn))) : v0;
    uint32_t r;
    switch (o.x) {
        case 0: r = v & 0xFF; break;
        case 1: r = v & 0xFFFF; break;
        case 2: r = static_cast<uint32_t>(static_cast<int8_t>(v)); break;
        default: r = static_cast<uint32_t>(static_cast<int16_t>(v)); break;
    }
    t.r_[o.rd] = (o.rn == 15 ? 0 : t.r_[o.rn]) + r;
}
inline void rev(Thumb& t, const Op& o) { t.r_[o.rd] = __builtin_bswap32(t.r_[o.rm]); }
inline void rev16(Thumb& t, const Op& o) {
    const uint32_t v = t.r_[o.rm];
    t.r_[o.rd] = ((v & 0x00FF00FF) << 8) | ((v >> 8) & 0x00FF00FF);
}
inline void revsh(Thumb& t, const Op& o) {
    const uint32_t v = t.r_[o.rm];
    t.r_[o.rd] = static_cast<uint32_t>(
        static_cast<int16_t>(static_cast<uint16_t>(((v & 0xFF) << 8) | ((v >> 8) & 0xFF))));
}
inline void clz(Thumb& t, const Op& o) {
    const uint32_t v = t.r_[o.rm];
    t.r_[o.rd] = v ? static_cast<uint32_t>(__builtin_clz(v)) : 32;
}
inline void rbit(Thumb& t, const Op& o) {
    uint32_t v = t.r_[o.rm], r = 0;
    for (int i = 0; i < 32; ++i, v >>= 1) r = (r << 1) | (v & 1);
    t.r_[o.rd] = r;
}

}  // namespace ops
}  // namespace hqsim::thumb
