// The engine's decoder (thumb.hpp): one Thumb or Thumb-2 instruction into an Op record, its
// handler (thumb_int.hpp; FP in thumb_fp.cpp), operands and the cycles sim/chip/timing.py's
// model charges for it. An encoding it does not know decodes to a handler that stops the run
// as Undefined.
#include "chip/thumb_int.hpp"

#include <array>
#include <unordered_map>
#include <utility>

namespace hqsim::thumb {

bool decode_fp(Op& op, uint16_t hw1, uint16_t hw2);     // thumb_fp.cpp

namespace {

using namespace ops;

inline uint32_t bits(uint32_t v, unsigned hi, unsigned lo) {
    return (v >> lo) & ((1u << (hi - lo + 1)) - 1);
}
inline uint32_t sext(uint32_t v, unsigned nbits) {
    const uint32_t m = 1u << (nbits - 1);
    return (v ^ m) - m;
}
inline uint8_t u8(uint32_t v) { return static_cast<uint8_t>(v); }

void set(Op& op, Handler fn, uint8_t cyc = 1) {
    op.fn = fn;
    op.cyc = cyc;
}

// Data processing of the given kind into op (operands already set).
template <Src S>
Handler dp_handler(unsigned opc) {
    switch (opc) {
        case AND: return dp<AND, S>;
        case EOR: return dp<EOR, S>;
        case ORR: return dp<ORR, S>;
        case ORN: return dp<ORN, S>;
        case BIC: return dp<BIC, S>;
        case MOV: return dp<MOV, S>;
        case MVN: return dp<MVN, S>;
        case ADD: return dp<ADD, S>;
        case ADC: return dp<ADC, S>;
        case SUB: return dp<SUB, S>;
        case SBC: return dp<SBC, S>;
        case RSB: return dp<RSB, S>;
        case TST: return dp<TST, S>;
        case TEQ: return dp<TEQ, S>;
        case CMP: return dp<CMP, S>;
        default: return dp<CMN, S>;
    }
}

template <Mode M>
Handler ldst_handler(Kind k) {
    switch (k) {
        case LDR: return ldst<LDR, M>;
        case LDRB: return ldst<LDRB, M>;
        case LDRH: return ldst<LDRH, M>;
        case LDRSB: return ldst<LDRSB, M>;
        case LDRSH: return ldst<LDRSH, M>;
        case STR: return ldst<STR, M>;
        case STRB: return ldst<STRB, M>;
        default: return ldst<STRH, M>;
    }
}

void load_store(Op& op, Kind k, Mode m, unsigned rt, unsigned rn, uint32_t imm) {
    op.rd = u8(rt);
    op.rn = u8(rn);
    op.imm = imm;
    switch (m) {
        case OFF: op.fn = ldst_handler<OFF>(k); break;
        case PRE: op.fn = ldst_handler<PRE>(k); break;
        case POST: op.fn = ldst_handler<POST>(k); break;
        case REGOFF: op.fn = ldst_handler<REGOFF>(k); break;
        default: op.fn = ldst_handler<LIT>(k); break;
    }
    op.cyc = (k == LDR && rt == 15) ? 4 : 2;
}

void multiple(Op& op, bool load, unsigned rn, uint32_t list, bool wback, bool db) {
    op.fn = load ? ldst_multiple<true> : ldst_multiple<false>;
    op.rn = u8(rn);
    op.imm = list;
    op.x = wback;
    op.y = db;
    unsigned n = 0;
    for (uint32_t l = list; l; l &= l - 1) ++n;
    op.sn = u8(n);
    op.cyc = u8(1 + n + ((list & 0x8000) ? 2 : 0));
    if (!list || (!load && (list & 0xA000)) || (list & 0x2000) ||
        (load && (list & 0xC000) == 0xC000)) {
        op.fn = unknown;
    }
}

// --- 16-bit ---------------------------------------------------------------------------------

void decode16_dp(Op& op, uint16_t h) {      // 010000: the register-to-register operations
    static const Dp kOps[16] = {AND, EOR, MOV, MOV, MOV, ADC, SBC, MOV, TST, RSB, CMP, CMN,
                                ORR, MOV, BIC, MVN};
    const unsigned opc = bits(h, 9, 6), rm = bits(h, 5, 3), rdn = bits(h, 2, 0);
    op.rd = op.rn = u8(rdn);
    op.rm = u8(rm);
    op.flags = kSetFlagsOutsideIt;
    if (opc == 2 || opc == 3 || opc == 4 || opc == 7) {        // LSL LSR ASR ROR by register
        static const uint8_t kShift[8] = {0, 0, LSL, LSR, ASR, 0, 0, ROR};
        op.st = kShift[opc];
        op.rn = u8(rdn);
        set(op, dp<MOV, REGREG>);
        return;
    }
    if (opc == 13) {                                         // MULS
        op.rn = u8(rm);
        op.rm = u8(rdn);
        set(op, mul);
        return;
    }
    if (opc == 9) {                                          // RSBS Rd, Rn, #0
        op.rn = u8(rm);
        op.imm = 0;
        set(op, dp<RSB, IMM>);
        return;
    }
    if (kOps[opc] == TST || kOps[opc] == CMP || kOps[opc] == CMN) op.flags = kSetFlags;
    set(op, dp_handler<REG>(kOps[opc]));
}

void decode16_misc(Op& op, uint16_t h) {    // 1011 xxxx
    const unsigned sub = bits(h, 11, 8);
    if (sub == 0) {                                          // ADD/SUB SP, SP, #imm7*4
        op.rd = op.rn = 13;
        op.imm = bits(h, 6, 0) * 4;
        set(op, dp_handler<IMM>(bits(h, 7, 7) ? SUB : ADD));
    } else if ((sub & 5) == 1) {                             // CBZ / CBNZ
        op.rn = u8(bits(h, 2, 0));
        op.imm = (bits(h, 9, 9) << 6) | (bits(h, 7, 3) << 1);
        op.x = u8(bits(h, 11, 11));
        set(op, cbz, 2);
    } else if (sub == 2) {                                   // SXTH SXTB UXTH UXTB
        static const uint8_t kExt[4] = {3, 2, 1, 0};
        op.rd = u8(bits(h, 2, 0));
        op.rm = u8(bits(h, 5, 3));
        op.rn = 15;
        op.x = kExt[bits(h, 7, 6)];
        set(op, extend);
    } else if ((sub & 0xE) == 4) {                           // PUSH
        multiple(op, false, 13, bits(h, 7, 0) | (bits(h, 8, 8) << 14), true, true);
    } else if ((sub & 0xE) == 0xC) {                         // POP
        multiple(op, true, 13, bits(h, 7, 0) | (bits(h, 8, 8) << 15), true, false);
    } else if ((h & 0xFFE8) == 0xB660) {                     // CPS
        op.y = u8(bits(h, 2, 0));
        op.x = u8(bits(h, 4, 4));
        set(op, bits(h, 2, 0) & 3 ? cps : unknown);
    } else if (sub == 0xA && bits(h, 7, 6) != 2) {           // REV REV16 REVSH
        op.rd = u8(bits(h, 2, 0));
        op.rm = u8(bits(h, 5, 3));
        const unsigned k = bits(h, 7, 6);
        set(op, k == 0 ? rev : k == 1 ? rev16 : revsh);
    } else if (sub == 0xE) {                                 // BKPT
        op.imm = bits(h, 7, 0);
        set(op, bkpt);
    } else if (sub == 0xF) {
        if (bits(h, 3, 0)) {                                 // IT
            op.imm = bits(h, 7, 0);
            set(op, bits(h, 7, 4) == 15 ? unknown : it);
        } else {
            const unsigned hint = bits(h, 7, 4);
            set(op, hint == 3 ? wfi : hint <= 4 ? nop : unknown);
        }
    } else {
        set(op, unknown);
    }
}

void decode16(Op& op, uint32_t pc, uint16_t h) {
    op.size = 2;
    const unsigned top = bits(h, 15, 11);
    const unsigned r0 = bits(h, 2, 0), r3 = bits(h, 5, 3), r6 = bits(h, 8, 6);
    if (top <= 2) {                                           // LSL LSR ASR #imm5
        op.rd = u8(r0);
        op.rm = u8(r3);
        op.st = u8(top);
        unsigned n = bits(h, 10, 6);
        if (top != 0 && n == 0) n = 32;
        op.sn = u8(n);
        op.flags = kSetFlagsOutsideIt;
        set(op, dp<MOV, REG>);
    } else if (top == 3) {                                    // ADD/SUB reg, imm3
        op.rd = u8(r0);
        op.rn = u8(r3);
        op.flags = kSetFlagsOutsideIt;
        const bool sub = bits(h, 9, 9);
        if (bits(h, 10, 10)) {
            op.imm = r6;
            set(op, dp_handler<IMM>(sub ? SUB : ADD));
        } else {
            op.rm = u8(r6);
            set(op, dp_handler<REG>(sub ? SUB : ADD));
        }
    } else if (top <= 7) {                                    // MOV CMP ADD SUB #imm8
        static const Dp kOps[4] = {MOV, CMP, ADD, SUB};
        op.rd = op.rn = u8(bits(h, 10, 8));
        op.imm = bits(h, 7, 0);
        op.flags = top == 5 ? kSetFlags : kSetFlagsOutsideIt;
        set(op, dp_handler<IMM>(kOps[top - 4]));
    } else if (bits(h, 15, 10) == 0x10) {
        decode16_dp(op, h);
    } else if (bits(h, 15, 10) == 0x11) {                     // hi registers, BX, BLX
        const unsigned opc = bits(h, 9, 8);
        const unsigned rd = r0 | (bits(h, 7, 7) << 3), rm = bits(h, 6, 3);
        op.rd = op.rn = u8(rd);
        op.rm = u8(rm);
        if (opc == 0) set(op, dp<ADD, REG>, rd == 15 ? 3 : 1);
        else if (opc == 1) { op.flags = kSetFlags; set(op, dp<CMP, REG>); }
        else if (opc == 2) set(op, dp<MOV, REG>, rd == 15 ? 3 : 1);
        else {
            set(op, bits(h, 7, 7) ? blx : bx, 3);
            op.cyc_it = 2;
            if (r0) op.fn = unknown;
        }
    } else if (top == 9) {                                    // LDR literal
        load_store(op, LDR, LIT, bits(h, 10, 8), 15, bits(h, 7, 0) * 4);
    } else if (bits(h, 15, 12) == 5) {                        // register offset
        static const Kind kKinds[8] = {STR, STRH, STRB, LDRSB, LDR, LDRH, LDRB, LDRSH};
        load_store(op, kKinds[bits(h, 11, 9)], REGOFF, r0, r3, 0);
        op.rm = u8(r6);
    } else if (bits(h, 15, 13) == 3) {                        // STR/LDR(B) #imm5
        const bool byte = bits(h, 12, 12), load = bits(h, 11, 11);
        const Kind k = byte ? (load ? LDRB : STRB) : (load ? LDR : STR);
        load_store(op, k, OFF, r0, r3, bits(h, 10, 6) * (byte ? 1 : 4));
    } else if (bits(h, 15, 12) == 8) {                        // STRH/LDRH #imm5
        load_store(op, bits(h, 11, 11) ? LDRH : STRH, OFF, r0, r3, bits(h, 10, 6) * 2);
    } else if (bits(h, 15, 12) == 9) {                        // STR/LDR SP-relative
        load_store(op, bits(h, 11, 11) ? LDR : STR, OFF, bits(h, 10, 8), 13,
                   bits(h, 7, 0) * 4);
    } else if (top == 0x14) {                                 // ADR
        op.rd = u8(bits(h, 10, 8));
        op.imm = bits(h, 7, 0) * 4;
        set(op, adr);
    } else if (top == 0x15) {                                 // ADD Rd, SP, #imm8*4
        op.rd = u8(bits(h, 10, 8));
        op.rn = 13;
        op.imm = bits(h, 7, 0) * 4;
        set(op, dp<ADD, IMM>);
    } else if (bits(h, 15, 12) == 0xB) {
        decode16_misc(op, h);
    } else if (bits(h, 15, 12) == 0xC) {                      // STM / LDM
        const unsigned rn = bits(h, 10, 8), list = bits(h, 7, 0);
        const bool load = bits(h, 11, 11);
        multiple(op, load, rn, list, !load || !(list >> rn & 1), false);
    } else if (bits(h, 15, 12) == 0xD) {
        const unsigned cond = bits(h, 11, 8);
        if (cond == 14) set(op, udf);
        else if (cond == 15) { op.imm = bits(h, 7, 0); set(op, svc); }
        else {
            op.x = u8(cond);
            op.imm = sext(bits(h, 7, 0) << 1, 9);
            set(op, b_cond, 2);
        }
    } else if (top == 0x1C) {                                 // B
        op.imm = sext(bits(h, 10, 0) << 1, 12);
        set(op, b, 3);
        op.cyc_it = 2;
    } else {
        set(op, unknown);
    }
    (void)pc;
}

// --- 32-bit ---------------------------------------------------------------------------------

uint32_t thumb_expand_imm(uint32_t imm12, bool& carry_from_bit31) {
    const uint32_t b = imm12 & 0xFF;
    carry_from_bit31 = false;
    if (!(imm12 >> 10)) {
        switch (bits(imm12, 9, 8)) {
            case 0: return b;
            case 1: return b * 0x00010001u;
            case 2: return b * 0x01000100u;
            default: return b * 0x01010101u;
        }
    }
    const uint32_t v = 0x80 | (imm12 & 0x7F);
    const unsigned rot = bits(imm12, 11, 7);
    carry_from_bit31 = true;
    return (v >> rot) | (v << (32 - rot));
}

// Data processing, modified immediate (imm) or shifted register: op field, S, Rn, Rd.
bool dp32_common(Op& op, unsigned opc, bool s, unsigned rn, unsigned rd, Handler (*pick)(unsigned)) {
    op.rd = u8(rd);
    op.rn = u8(rn);
    if (s) op.flags = kSetFlags;
    static const int kMap[16] = {AND, BIC, ORR, ORN, EOR, -1, -1, -1, ADD, -1, ADC, SBC, -1,
                                 SUB, RSB, -1};
    int d = kMap[opc];
    if (d < 0) return false;
    if (rd == 15 && s) {
        if (d == AND) d = TST;
        else if (d == EOR) d = TEQ;
        else if (d == ADD) d = CMN;
        else if (d == SUB) d = CMP;
        else return false;
    } else if (rd == 15 || rd == 13) {
        if (!(rd == 13 && (d == ADD || d == SUB) && rn == 13)) return false;
    }
    if (rn == 15) {
        if (d == ORR) d = MOV;
        else if (d == ORN) d = MVN;
        else return false;
    }
    op.fn = pick(static_cast<unsigned>(d));
    op.cyc = 1;
    return true;
}

void decode_branch_misc(Op& op, uint16_t h1, uint16_t h2) {
    const unsigned op1 = bits(h2, 14, 12);
    const uint32_t s = bits(h1, 10, 10), j1 = bits(h2, 13, 13), j2 = bits(h2, 11, 11);
    if ((op1 & 5) == 1 || (op1 & 5) == 5) {                  // B T4, BL
        const uint32_t i1 = !(j1 ^ s), i2 = !(j2 ^ s);
        op.imm = sext((s << 24) | (i1 << 23) | (i2 << 22) | (bits(h1, 9, 0) << 12) |
                          (bits(h2, 10, 0) << 1), 25);
        set(op, (op1 & 4) ? bl : b, 3);
        op.cyc_it = 2;
        return;
    }
    if ((op1 & 5) != 0) { set(op, unknown); return; }
    if (bits(h1, 9, 7) != 7) {                                // B T3 conditional
        op.x = u8(bits(h1, 9, 6));
        op.imm = sext((s << 20) | (j2 << 19) | (j1 << 18) | (bits(h1, 5, 0) << 12) |
                          (bits(h2, 10, 0) << 1), 21);
        set(op, b_cond, 2);
        return;
    }
    const unsigned o = bits(h1, 10, 4);
    if ((o & 0x7E) == 0x38) {                                 // MSR
        op.rn = u8(bits(h1, 3, 0));
        op.imm = bits(h2, 7, 0);
        op.x = u8(bits(h2, 11, 10));
        set(op, msr, 2);
        if (op.x != 2) op.fn = unknown;         // the DSP extension's GE bits: not modelled
    } else if ((o & 0x7E) == 0x3E) {                          // MRS
        op.rd = u8(bits(h2, 11, 8));
        op.imm = bits(h2, 7, 0);
        set(op, mrs, 2);
    } else if (o == 0x3A) {                                   // hints
        const unsigned hint = bits(h2, 7, 0);
        if (bits(h2, 10, 8)) set(op, unknown);
        else set(op, hint == 3 ? wfi : hint <= 4 ? nop : unknown);
    } else if (o == 0x3B) {                                   // DSB DMB ISB
        const unsigned k = bits(h2, 7, 4);
        set(op, k == 6 ? isb : nop, k == 6 ? 3 : 1);
        if (k < 4 || k > 6) op.fn = unknown;
    } else if (o == 0x7F && op1 == 2) {
        set(op, udf);
    } else {
        set(op, unknown);
    }
}

void decode_plain_imm(Op& op, uint16_t h1, uint16_t h2) {
    const unsigned o = bits(h1, 8, 4), rn = bits(h1, 3, 0), rd = bits(h2, 11, 8);
    const uint32_t imm12 = (bits(h1, 10, 10) << 11) | (bits(h2, 14, 12) << 8) | bits(h2, 7, 0);
    const unsigned lsb = (bits(h2, 14, 12) << 2) | bits(h2, 7, 6), w = bits(h2, 4, 0);
    op.rd = u8(rd);
    op.rn = u8(rn);
    switch (o) {
        case 0: case 10:                                       // ADDW SUBW ADR
            op.imm = o ? 0u - imm12 : imm12;
            set(op, rn == 15 ? adr : addw);
            break;
        case 4: case 12:                                       // MOVW MOVT
            op.imm = (rn << 12) | imm12;
            set(op, o == 4 ? movw : movt);
            break;
        case 20: case 28:                                      // SBFX UBFX
            op.x = u8(lsb);
            op.y = u8(w + 1);
            set(op, o == 28 ? ubfx : sbfx);
            if (lsb + w + 1 > 32) op.fn = unknown;
            break;
        case 22:                                               // BFI BFC
            op.x = u8(lsb);
            op.y = u8(w);
            set(op, bfi);
            if (w < lsb) op.fn = unknown;
            break;
        default: set(op, unknown); return;
    }
    if (rd == 15 || (rd == 13 && !((o == 0 || o == 10) && rn == 13))) op.fn = unknown;
}

void decode_load_store(Op& op, uint16_t h1, uint16_t h2) {
    const bool load = bits(h1, 4, 4), sign = bits(h1, 8, 8);
    const unsigned size = bits(h1, 6, 5), rn = bits(h1, 3, 0), rt = bits(h2, 15, 12);
    static const Kind kLoads[2][3] = {{LDRB, LDRH, LDR}, {LDRSB, LDRSH, LDR}};
    static const Kind kStores[3] = {STRB, STRH, STR};
    if (size == 3 || (!load && sign) || (sign && size == 2)) { set(op, unknown); return; }
    const Kind k = load ? kLoads[sign][size] : kStores[size];
    if (load && rt == 15 && size != 2) { set(op, nop); return; }    // PLD, PLI: hints
    if (rn == 15) {
        if (!load) { set(op, unknown); return; }
        const uint32_t imm = bits(h2, 11, 0);
        load_store(op, k, LIT, rt, 15, bits(h1, 7, 7) ? imm : 0u - imm);
        return;
    }
    if (bits(h1, 7, 7)) {
        load_store(op, k, OFF, rt, rn, bits(h2, 11, 0));
    } else if (bits(h2, 11, 11)) {
        const bool p = bits(h2, 10, 10), u = bits(h2, 9, 9), w = bits(h2, 8, 8);
        const uint32_t imm = u ? bits(h2, 7, 0) : 0u - bits(h2, 7, 0);
        if (p && u && !w) { set(op, unknown); return; }          // LDRT etc.
        if (!p && !w) { set(op, unknown); return; }
        load_store(op, k, !p ? POST : w ? PRE : OFF, rt, rn, imm);
        if (w && rn == rt) op.fn = unknown;
    } else if (bits(h2, 11, 6) == 0) {
        load_store(op, k, REGOFF, rt, rn, 0);
        op.rm = u8(bits(h2, 3, 0));
        op.sn = u8(bits(h2, 5, 4));
    } else {
        set(op, unknown);
        return;
    }
    if (rt == 15 && k != LDR) op.fn = unknown;
}

void decode_dual_table(Op& op, uint16_t h1, uint16_t h2) {
    const unsigned rn = bits(h1, 3, 0);
    if (bits(h1, 8, 4) == 0x0D && bits(h2, 7, 5) == 0) {            // TBB TBH
        op.rn = u8(rn);
        op.rm = u8(bits(h2, 3, 0));
        set(op, bits(h2, 4, 4) ? tb<true> : tb<false>, 4);
        return;
    }
    const bool p = bits(h1, 8, 8), u = bits(h1, 7, 7), w = bits(h1, 5, 5), l = bits(h1, 4, 4);
    if (!p && !w) { set(op, unknown); return; }               // exclusives: not modelled
    op.rd = u8(bits(h2, 15, 12));
    op.ra = u8(bits(h2, 11, 8));
    op.rn = u8(rn);
    op.imm = u ? bits(h2, 7, 0) * 4 : 0u - bits(h2, 7, 0) * 4;
    op.x = u8(rn == 15 ? 3 : !p ? 2 : w ? 1 : 0);
    set(op, l ? ldst_dual<true> : ldst_dual<false>, 3);
    if ((rn == 15 && (!l || w)) || (w && (rn == op.rd || rn == op.ra)) || op.rd == 13 ||
        op.rd == 15 || op.ra == 13 || op.ra == 15 || (l && op.rd == op.ra)) {
        op.fn = unknown;
    }
}

void decode_dp_reg(Op& op, uint16_t h1, uint16_t h2) {
    const unsigned o1 = bits(h1, 7, 4), o2 = bits(h2, 7, 4);
    op.rd = u8(bits(h2, 11, 8));
    op.rn = u8(bits(h1, 3, 0));
    op.rm = u8(bits(h2, 3, 0));
    if (o2 == 0 && o1 < 8) {                                  // shifts by register
        op.st = u8(o1 >> 1);
        if (o1 & 1) op.flags = kSetFlags;
        set(op, dp<MOV, REGREG>);
    } else if ((o2 & 8) && o1 < 6 && o1 != 2 && o1 != 3) {    // extends
        static const uint8_t kExt[6] = {3, 1, 0, 0, 2, 0};
        op.x = kExt[o1];
        op.sn = u8(bits(h2, 5, 4) * 8);
        set(op, extend);
    } else if ((o1 & 0xC) == 8 && (o2 & 0xC) == 8 && bits(h1, 3, 0) == bits(h2, 3, 0)) {
        const unsigned k = (bits(h1, 5, 4) << 2) | bits(h2, 5, 4);
        switch (k) {
            case 4: set(op, rev); break;
            case 5: set(op, rev16); break;
            case 6: set(op, rbit); break;
            case 7: set(op, revsh); break;
            case 12: set(op, clz); break;
            default: set(op, unknown); break;
        }
    } else {
        set(op, unknown);
    }
}

void decode_mul(Op& op, uint16_t h1, uint16_t h2) {
    op.rn = u8(bits(h1, 3, 0));
    op.rm = u8(bits(h2, 3, 0));
    op.rd = u8(bits(h2, 11, 8));
    op.ra = u8(bits(h2, 15, 12));
    const unsigned o1 = bits(h1, 6, 4), o2 = bits(h2, 7, 4);
    if (bits(h1, 8, 7) == 2) {                                // 0110: MUL MLA MLS
        if (o1 != 0 || o2 > 1) set(op, unknown);
        else if (o2 == 1) set(op, mls, 2);
        else if (op.ra == 15) set(op, mul);
        else set(op, mla, 2);
        return;
    }
    if ((o1 == 1 || o1 == 3) && o2 == 15) {                   // SDIV UDIV
        set(op, o1 == 1 ? div<true> : div<false>, 7);
        return;
    }
    if (o2 == 0 && (o1 == 0 || o1 == 2 || o1 == 4 || o1 == 6)) {
        std::swap(op.rd, op.ra);                              // rd: RdLo, ra: RdHi
        op.x = u8(o1 == 0 || o1 == 4);
        op.y = u8(o1 >= 4);
        set(op, mull);
        if (op.rd == op.ra) op.fn = unknown;
        return;
    }
    set(op, unknown);
}

void decode32(Op& op, uint16_t h1, uint16_t h2) {
    op.size = 4;
    const unsigned op1 = bits(h1, 12, 11), op2 = bits(h1, 10, 4);
    if (op1 == 1) {
        if ((op2 & 0x64) == 0) {                               // LDM/STM
            const unsigned o = bits(h1, 8, 7);
            if (o != 1 && o != 2) { set(op, unknown); return; }
            const unsigned list = h2 & ~0x2000u;
            multiple(op, bits(h1, 4, 4), bits(h1, 3, 0), list, bits(h1, 5, 5), o == 2);
            if (h2 & 0x2000) op.fn = unknown;
            if (op.x && (list >> bits(h1, 3, 0) & 1)) op.fn = unknown;
        } else if ((op2 & 0x64) == 4) {
            decode_dual_table(op, h1, h2);
        } else if ((op2 & 0x60) == 0x20) {                     // shifted register
            const unsigned type = bits(h2, 5, 4);
            const unsigned n = (bits(h2, 14, 12) << 2) | bits(h2, 7, 6);
            op.rm = u8(bits(h2, 3, 0));
            op.st = u8(type == ROR && n == 0 ? unsigned{RRX} : type);
            op.sn = u8((type == LSR || type == ASR) && n == 0 ? 32 : n);
            if (!dp32_common(op, bits(h1, 8, 5), bits(h1, 4, 4), bits(h1, 3, 0),
                             bits(h2, 11, 8), dp_handler<REG>) || op.rm == 15) {
                set(op, unknown);
            }
        } else {
            if (!decode_fp(op, h1, h2)) set(op, unknown);
        }
    } else if (op1 == 2) {
        if (h2 & 0x8000) {
            decode_branch_misc(op, h1, h2);
        } else if (!(op2 & 0x20)) {                            // modified immediate
            bool c31;
            const uint32_t imm12 = (bits(h1, 10, 10) << 11) | (bits(h2, 14, 12) << 8) |
                                   bits(h2, 7, 0);
            op.imm = thumb_expand_imm(imm12, c31);
            op.x = c31;
            if (!dp32_common(op, bits(h1, 8, 5), bits(h1, 4, 4), bits(h1, 3, 0),
                             bits(h2, 11, 8), dp_handler<IMM>)) {
                set(op, unknown);
            }
        } else {
            decode_plain_imm(op, h1, h2);
        }
    } else {
        if ((op2 & 0x71) == 0 || (op2 & 0x67) == 1 || (op2 & 0x67) == 3 || (op2 & 0x67) == 5) {
            decode_load_store(op, h1, h2);
        } else if ((op2 & 0x70) == 0x20) {
            decode_dp_reg(op, h1, h2);
        } else if ((op2 & 0x78) == 0x30 || (op2 & 0x78) == 0x38) {
            decode_mul(op, h1, h2);
        } else if (op2 & 0x40) {
            if (!decode_fp(op, h1, h2)) set(op, unknown);
        } else {
            set(op, unknown);
        }
    }
}

// --- threaded<fn> of each integer handler --------------------------------------------------

// The chain handlers of a handler fn: threaded<fn, true> (the Op never writes the PC),
// threaded<fn, false>; for data processing the forms specialised for an Op in a chain
// (FlagMode), [operand unshifted][sets flags], and which operands may not be the PC there.
struct Chained {
    Handler straight = nullptr, branchy = nullptr;
    Handler fast[2][2] = {};
    bool rn_operand = false, rm_operand = false;
};
using Map = std::unordered_map<Handler, Chained>;

template <Handler... H>
void add(Map& m) {
    (m.emplace(H, Chained{threaded<H, true>, threaded<H, false>}), ...);
}
template <Dp OP, Src S>
void add_dp_one(Map& m) {
    constexpr Src S0 = S == REG ? REG0 : S;
    Chained c{threaded<dp<OP, S>, true>, threaded<dp<OP, S>, false>,
              {{threaded<dp<OP, S, NOFLAGS>, true, false>,
                threaded<dp<OP, S, FLAGS>, true, false>},
               {threaded<dp<OP, S0, NOFLAGS>, true, false>,
                threaded<dp<OP, S0, FLAGS>, true, false>}}};
    c.rn_operand = S != REGREG && OP != MOV && OP != MVN;
    c.rm_operand = S == REG;
    m.emplace(dp<OP, S>, c);
}
template <Src S, size_t... I>
void add_dp(Map& m, std::index_sequence<I...>) {
    (add_dp_one<static_cast<Dp>(I), S>(m), ...);
}
template <Kind K, Mode M>
void add_ldst_one(Map& m) {         // a straight one: its fast form first (threaded_try)
    m.emplace(ldst<K, M>, Chained{threaded_try<ldst<K, M>, ldst_try<K, M>>,
                                  threaded<ldst<K, M>, false>});
}
template <Mode M, size_t... I>
void add_ldst(Map& m, std::index_sequence<I...>) {
    (add_ldst_one<static_cast<Kind>(I), M>(m), ...);
}

const Map& threaded_int() {
    static const Map m = [] {
        Map r;
        add_dp<IMM>(r, std::make_index_sequence<16>());
        add_dp<REG>(r, std::make_index_sequence<16>());
        add_dp<REGREG>(r, std::make_index_sequence<16>());
        add_ldst<OFF>(r, std::make_index_sequence<8>());
        add_ldst<PRE>(r, std::make_index_sequence<8>());
        add_ldst<POST>(r, std::make_index_sequence<8>());
        add_ldst<REGOFF>(r, std::make_index_sequence<8>());
        add_ldst<LIT>(r, std::make_index_sequence<8>());
        add<ldst_dual<true>, ldst_dual<false>, ldst_multiple<true>, ldst_multiple<false>,
            b_cond, b, bl, bx, blx, cbz, tb<true>, tb<false>, nop, mrs, movw, movt, adr, addw,
            mul, mla, mls, mull, div<true>, div<false>, ubfx, sbfx, bfi, extend, rev, rev16,
            revsh, clz, rbit>(r);
        return r;
    }();
    return m;
}

// B<cond> with its condition known: threaded<b_if<cond>> by condition.
template <size_t... C>
constexpr std::array<Handler, 16> conditional_branches(std::index_sequence<C...>) {
    return {threaded<b_if<C>, false>...};
}
constexpr auto kBranchIf = conditional_branches(std::make_index_sequence<16>());

// The chain handler of an integer Op (it, fn's handlers).
Handler chained(const Op& op, const Chained& c, bool writes_pc) {
    if (op.fn == b_cond) return kBranchIf[op.x & 15];
    if (writes_pc) return c.branchy;
    if (c.fast[0][0] && !(c.rn_operand && op.rn == 15) && !(c.rm_operand && op.rm == 15)) {
        const bool unshifted = op.st == LSL && op.sn == 0;
        return c.fast[unshifted][(op.flags & (kSetFlags | kSetFlagsOutsideIt)) != 0];
    }
    return c.straight;
}

// Whether the integer instruction in op may write the PC: the branches, a destination of
// R15 (data processing, LDR; for the rest an UNPREDICTABLE form: the PC is what the old
// dispatch left, the next instruction's), a POP or LDM of the PC.
bool may_write_pc(const Op& op) {
    static const Handler kBranches[] = {b_cond, b, bl, bx, blx, cbz, tb<true>, tb<false>};
    for (Handler h : kBranches) {
        if (op.fn == h) return true;
    }
    return op.rd == 15 || (op.fn == ldst_multiple<true> && (op.imm & 0x8000));
}

}  // namespace

void decode_instruction(Op& op, uint32_t pc, uint16_t hw1, uint16_t hw2) {
    if ((hw1 >> 11) >= 0x1D) decode32(op, hw1, hw2);
    else decode16(op, pc, hw1);
    if (!op.fn) op.fn = unknown;
    if (!op.cyc_it) op.cyc_it = op.cyc;
    const auto it = threaded_int().find(op.fn);
    if (op.fn == ops::it) {
        op.next = it_start;
    } else if (it != threaded_int().end()) {
        op.next = chained(op, it->second, may_write_pc(op));
    } else {
        op.next = threaded_fp(op.fn);
    }
    if (!op.cyc) op.next = nullptr;         // a chain's length is bounded by its cycles
}

}  // namespace hqsim::thumb
