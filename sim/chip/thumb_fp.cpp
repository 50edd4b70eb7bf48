// The engine's FPv4-SP instructions (thumb.hpp): decoding and execution. Arithmetic runs on
// the host's IEEE single precision in FPSCR's rounding mode (this file is compiled with
// -frounding-math), wrapped in the architecture's rules the host does not share: NaN
// operand priority and quieting, the default NaN (0x7FC00000; DN), flush-to-zero of
// denormal inputs and of results tiny before rounding (FZ), FPNeg applied to NaNs too.
// The cumulative exception flags are not kept (thumb.hpp).
#include <cfenv>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include "chip/thumb.hpp"

namespace hqsim::thumb {

namespace {

constexpr uint32_t kSign = 0x80000000u, kDefaultNaN = 0x7FC00000u, kQuiet = 0x00400000u;

inline float F(uint32_t b) { float x; std::memcpy(&x, &b, 4); return x; }
inline uint32_t B(float x) { uint32_t b; std::memcpy(&b, &x, 4); return b; }
inline bool is_nan(uint32_t b) { return (b & ~kSign) > 0x7F800000u; }
inline bool is_snan(uint32_t b) { return is_nan(b) && !(b & kQuiet); }
inline bool is_denormal(uint32_t b) { return !(b & 0x7F800000u) && (b & 0x007FFFFFu); }

struct Mode {
    bool fz, dn;
    unsigned rmode;
    explicit Mode(uint32_t fpscr)
        : fz(fpscr >> 24 & 1), dn(fpscr >> 25 & 1), rmode(fpscr >> 22 & 3) {}
    uint32_t in(uint32_t b) const { return fz && is_denormal(b) ? (b & kSign) : b; }
    uint32_t nan(uint32_t b) const { return dn ? kDefaultNaN : (b | kQuiet); }
};

const int kHostRounding[4] = {FE_TONEAREST, FE_UPWARD, FE_DOWNWARD, FE_TOWARDZERO};

// The host computes f() in FPSCR's rounding mode.
template <typename Fn>
inline auto rounded(unsigned rmode, Fn f) -> decltype(f()) {
    if (rmode == 0) return f();
    const int old = std::fegetround();
    std::fesetround(kHostRounding[rmode]);
    const auto r = f();
    std::fesetround(old);
    return r;
}

// The NaN rules of two operands: a signalling NaN first (a, then b), then a quiet one.
inline bool nans2(const Mode& m, uint32_t a, uint32_t b, uint32_t& r) {
    if (!is_nan(a) && !is_nan(b)) return false;
    if (is_snan(a)) r = m.nan(a);
    else if (is_snan(b)) r = m.nan(b);
    else if (is_nan(a)) r = m.nan(a);
    else r = m.nan(b);
    return true;
}

// A host result to the architecture's: an invalid operation's NaN is the default NaN; a
// result whose exact value `exact` is tiny (below 2^-126) is zero under FZ.
inline uint32_t result(const Mode& m, float host, double exact) {
    const uint32_t r = B(host);
    if (is_nan(r)) return kDefaultNaN;
    if (m.fz && exact != 0.0 && std::fabs(exact) < 0x1p-126) return exact < 0 ? kSign : 0;
    return r;
}

enum Arith : uint8_t { ADD, SUB, MUL, DIV };

inline bool normal(uint32_t b) { return ((b >> 23) & 0xFF) - 1u < 0xFEu; }

constexpr uint32_t kFz = 1u << 24, kModeBits = kFz | (3u << 22);    // FZ, RMode

// The host's result f() where it is the architecture's, in round-to-nearest: without FZ, any
// result but a NaN (a NaN operand gives a NaN, which takes the NaN rules; denormals the host
// takes as the architecture does); with FZ, normal operands and a result that is normal and
// not the smallest normal (which may have been tiny before rounding).
template <typename Fn, typename... U>
HQ_INLINE bool fast(uint32_t fpscr, uint32_t& r, Fn f, U... operands) {
    const uint32_t fz_rmode = fpscr & kModeBits;
    if (__builtin_expect(fz_rmode == 0, 1)) {
        r = B(f());
        return !is_nan(r);
    }
    if (fz_rmode != kFz || !(normal(operands) && ...)) return false;
    r = B(f());
    return normal(r) && (r & ~kSign) != 0x00800000u;
}

__attribute__((noinline)) uint32_t arith_slow(const Mode& m, Arith op, uint32_t a, uint32_t b) {
    a = m.in(a);
    b = m.in(b);
    uint32_t r;
    if (nans2(m, a, b, r)) return r;
    const float x = F(a), y = F(b);
    const double dx = x, dy = y;
    switch (op) {
        case ADD: return result(m, rounded(m.rmode, [&] { return x + y; }), dx + dy);
        case SUB: return result(m, rounded(m.rmode, [&] { return x - y; }), dx - dy);
        case MUL: return result(m, rounded(m.rmode, [&] { return x * y; }), dx * dy);
        default: return result(m, rounded(m.rmode, [&] { return x / y; }), dx / dy);
    }
}

// The host's a OP b where it is the architecture's (fast()): r, else false.
template <Arith OP>
HQ_INLINE bool arith_fast(uint32_t fpscr, uint32_t a, uint32_t b, uint32_t& r) {
    const float x = F(a), y = F(b);
    const auto host = [x, y] {
        switch (OP) {
            case ADD: return x + y;
            case SUB: return x - y;
            case MUL: return x * y;
            default: return x / y;
        }
    };
    return fast(fpscr, r, host, a, b);
}

template <Arith OP>
HQ_INLINE uint32_t arith(uint32_t fpscr, uint32_t a, uint32_t b) {
    uint32_t r;
    return arith_fast<OP>(fpscr, a, b, r) ? r : arith_slow(Mode(fpscr), OP, a, b);
}

inline uint32_t neg(uint32_t a) { return a ^ kSign; }

// FPMulAdd(addend, op1, op2): one rounding.
__attribute__((noinline)) uint32_t muladd_slow(const Mode& m, uint32_t addend, uint32_t a,
                                               uint32_t b) {
    addend = m.in(addend);
    a = m.in(a);
    b = m.in(b);
    const bool inf_zero = ((a & ~kSign) == 0x7F800000u && !(b & ~kSign)) ||
                          (!(a & ~kSign) && (b & ~kSign) == 0x7F800000u);
    if (is_nan(addend) || is_nan(a) || is_nan(b)) {
        if (is_nan(addend) && !is_snan(addend) && inf_zero) return kDefaultNaN;
        if (is_snan(addend)) return m.nan(addend);
        if (is_snan(a)) return m.nan(a);
        if (is_snan(b)) return m.nan(b);
        if (is_nan(addend)) return m.nan(addend);
        if (is_nan(a)) return m.nan(a);
        return m.nan(b);
    }
    const float x = F(a), y = F(b), z = F(addend);
    const float host = rounded(m.rmode, [&] { return std::fmaf(x, y, z); });
    return result(m, host, std::fma(double{x}, double{y}, double{z}));
}

HQ_INLINE bool muladd_fast(uint32_t fpscr, uint32_t addend, uint32_t a, uint32_t b,
                           uint32_t& r) {
    const float x = F(a), y = F(b), z = F(addend);
    return fast(fpscr, r, [x, y, z] { return std::fmaf(x, y, z); }, addend, a, b);
}

// --- handlers ---------------------------------------------------------------------------
// o.rd, o.rn, o.rm: S register numbers; o.x: the variant.

// Each handler and its fast form (threaded_try): the host's results where they are the
// architecture's (fast()), else false with nothing changed, the handler then run out of line.
template <Arith OP, bool NEG>          // VNMUL: NEG
HQ_INLINE bool v_arith_try(Thumb& t, const Op& o) {
    uint32_t r;
    if (!arith_fast<OP>(t.fpscr_, t.s_[o.rn], t.s_[o.rm], r)) return false;
    t.s_[o.rd] = NEG ? neg(r) : r;
    return true;
}
template <Arith OP, bool NEG>
void v_arith(Thumb& t, const Op& o) {
    const uint32_t r = arith<OP>(t.fpscr_, t.s_[o.rn], t.s_[o.rm]);
    t.s_[o.rd] = NEG ? neg(r) : r;
}

// VMLA VMLS VNMLA VNMLS: X bit0 negate the product, bit1 negate the accumulator.
template <unsigned X>
HQ_INLINE bool v_mac_try(Thumb& t, const Op& o) {
    const uint32_t fpscr = t.fpscr_;
    uint32_t p, r;
    if (!arith_fast<MUL>(fpscr, t.s_[o.rn], t.s_[o.rm], p)) return false;
    if (X & 1) p = neg(p);
    const uint32_t d = (X & 2) ? neg(t.s_[o.rd]) : t.s_[o.rd];
    if (!arith_fast<ADD>(fpscr, d, p, r)) return false;
    t.s_[o.rd] = r;
    return true;
}
template <unsigned X>
void v_mac(Thumb& t, const Op& o) {
    const uint32_t fpscr = t.fpscr_;
    uint32_t p = arith<MUL>(fpscr, t.s_[o.rn], t.s_[o.rm]);
    if (X & 1) p = neg(p);
    const uint32_t d = (X & 2) ? neg(t.s_[o.rd]) : t.s_[o.rd];
    t.s_[o.rd] = arith<ADD>(fpscr, d, p);
}

// VFMA VFMS VFNMA VFNMS: X bit0 negate op1 (Sn), bit1 negate the addend (Sd).
template <unsigned X>
HQ_INLINE bool v_fma_try(Thumb& t, const Op& o) {
    const uint32_t a = (X & 1) ? neg(t.s_[o.rn]) : t.s_[o.rn];
    const uint32_t d = (X & 2) ? neg(t.s_[o.rd]) : t.s_[o.rd];
    uint32_t r;
    if (!muladd_fast(t.fpscr_, d, a, t.s_[o.rm], r)) return false;
    t.s_[o.rd] = r;
    return true;
}
template <unsigned X>
void v_fma(Thumb& t, const Op& o) {
    const uint32_t a = (X & 1) ? neg(t.s_[o.rn]) : t.s_[o.rn];
    const uint32_t d = (X & 2) ? neg(t.s_[o.rd]) : t.s_[o.rd];
    const uint32_t b = t.s_[o.rm];
    uint32_t r;
    if (!muladd_fast(t.fpscr_, d, a, b, r)) r = muladd_slow(Mode(t.fpscr_), d, a, b);
    t.s_[o.rd] = r;
}

HQ_INLINE void v_mov(Thumb& t, const Op& o) { t.s_[o.rd] = t.s_[o.rm]; }
HQ_INLINE void v_abs(Thumb& t, const Op& o) { t.s_[o.rd] = t.s_[o.rm] & ~kSign; }
HQ_INLINE void v_neg(Thumb& t, const Op& o) { t.s_[o.rd] = t.s_[o.rm] ^ kSign; }
HQ_INLINE void v_imm(Thumb& t, const Op& o) { t.s_[o.rd] = o.imm; }

void v_sqrt(Thumb& t, const Op& o) {
    const Mode m(t.fpscr_);
    const uint32_t a = m.in(t.s_[o.rm]);
    if (is_nan(a)) { t.s_[o.rd] = m.nan(a); return; }
    if (!(a & ~kSign)) { t.s_[o.rd] = a; return; }
    if (a & kSign) { t.s_[o.rd] = kDefaultNaN; return; }
    const float x = F(a);
    t.s_[o.rd] = B(rounded(m.rmode, [&] { return std::sqrt(x); }));
}

template <bool ZERO>                        // compare with zero
HQ_INLINE void v_cmp(Thumb& t, const Op& o) {
    uint32_t a = t.s_[o.rd], b = ZERO ? 0 : t.s_[o.rm];
    if (__builtin_expect(t.fpscr_ & kFz, 0)) {
        const Mode m(t.fpscr_);
        a = m.in(a);
        b = m.in(b);
    }
    uint32_t nzcv;
    if (is_nan(a) || is_nan(b)) nzcv = 0x3;
    else if (F(a) == F(b)) nzcv = 0x6;
    else if (F(a) < F(b)) nzcv = 0x8;
    else nzcv = 0x2;
    t.fpscr_ = (t.fpscr_ & 0x0FFFFFFFu) | (nzcv << 28);
}

// Float to integer: x bit0 signed, bit1 round toward zero (else FPSCR's mode); o.y fraction
// bits, o.sn the integer's size (16 or 32).
uint32_t to_fixed(const Mode& m, uint32_t a, bool is_signed, bool toward_zero, unsigned fbits,
                  unsigned size) {
    a = m.in(a);
    if (is_nan(a)) return 0;
    const double v = std::ldexp(static_cast<double>(F(a)), static_cast<int>(fbits));
    double r;
    switch (toward_zero ? 3 : m.rmode) {
        case 0: r = std::nearbyint(v); break;
        case 1: r = std::ceil(v); break;
        case 2: r = std::floor(v); break;
        default: r = std::trunc(v); break;
    }
    const double lo = is_signed ? -std::ldexp(1.0, static_cast<int>(size - 1)) : 0.0;
    const double hi = is_signed ? std::ldexp(1.0, static_cast<int>(size - 1)) - 1
                                : std::ldexp(1.0, static_cast<int>(size)) - 1;
    if (r < lo) r = lo;
    if (r > hi) r = hi;
    const int64_t i = static_cast<int64_t>(r);
    if (size == 16) {
        return is_signed ? static_cast<uint32_t>(static_cast<int32_t>(static_cast<int16_t>(i)))
                         : static_cast<uint32_t>(i & 0xFFFF);
    }
    return static_cast<uint32_t>(i);
}

void v_to_int(Thumb& t, const Op& o) {
    const Mode m(t.fpscr_);
    t.s_[o.rd] = to_fixed(m, t.s_[o.rm], o.x & 1, o.x & 2, o.y, o.sn);
}

// Integer (o.y fraction bits, o.sn size) to float, rounded in FPSCR's mode; x: 1 signed.
void v_from_int(Thumb& t, const Op& o) {
    const Mode m(t.fpscr_);
    const uint32_t v = t.s_[o.rm];
    double x;
    if (o.sn == 16) x = o.x ? double(static_cast<int16_t>(v)) : double(v & 0xFFFF);
    else x = o.x ? double(static_cast<int32_t>(v)) : double(v);
    x = std::ldexp(x, -static_cast<int>(o.y));
    t.s_[o.rd] = B(rounded(m.rmode, [&] { return static_cast<float>(x); }));
}

HQ_INLINE void v_to_core(Thumb& t, const Op& o) { t.r_[o.rd] = t.s_[o.rn]; }
HQ_INLINE void v_from_core(Thumb& t, const Op& o) { t.s_[o.rn] = t.r_[o.rd]; }
HQ_INLINE void v_to_core2(Thumb& t, const Op& o) {
    t.r_[o.rd] = t.s_[o.rm];
    t.r_[o.ra] = t.s_[o.rm + 1];
}
HQ_INLINE void v_from_core2(Thumb& t, const Op& o) {
    t.s_[o.rm] = t.r_[o.rd];
    t.s_[o.rm + 1] = t.r_[o.ra];
}
HQ_INLINE void v_mrs(Thumb& t, const Op& o) {
    if (o.rd == 15) {
        const uint32_t f = t.fpscr_ >> 28;
        t.n_ = f >> 3; t.z_ = (f >> 2) & 1; t.c_ = (f >> 1) & 1; t.v_ = f & 1;
    } else {
        t.r_[o.rd] = t.fpscr_;
    }
}
void v_msr(Thumb& t, const Op& o) { t.fpscr_ = t.r_[o.rd] & Thumb::kFpscrKept; }

// n words between memory at a and S[first]: a load takes effect only once every word was
// read (a fault part-way leaves the S registers as they were), a store stops at the fault.
template <bool LOAD>
bool v_transfer(Thumb& t, uint32_t a, unsigned first, unsigned n) {
    if (uint8_t* p = t.sram_block(a, 4 * n, !LOAD)) {        // all in SRAM: straight
        for (unsigned i = 0; i < n; ++i, p += 4) {
            if constexpr (LOAD) __builtin_memcpy(&t.s_[first + i], p, 4);
            else __builtin_memcpy(p, &t.s_[first + i], 4);
        }
        return true;
    }
    if constexpr (LOAD) {
        uint32_t v[32];
        for (unsigned i = 0; i < n; ++i) {
            if (!t.load<4>(a + 4 * i, v[i], true)) return false;
        }
        for (unsigned i = 0; i < n; ++i) t.s_[first + i] = v[i];
    } else {
        for (unsigned i = 0; i < n; ++i) {
            if (!t.store<4>(a + 4 * i, t.s_[first + i], true)) return false;
        }
    }
    return true;
}

// VLDR/VSTR: o.rd the first S register, o.x 2 registers (a D register), o.imm the offset.
HQ_INLINE uint32_t v_address(const Thumb& t, const Op& o) {
    return (o.rn == 15 ? ((t.r_[15] + 4) & ~3u) : t.r_[o.rn]) + o.imm;
}
template <bool LOAD, unsigned n>
HQ_INLINE void v_ldst(Thumb& t, const Op& o) {
    const uint32_t a = v_address(t, o);
    if constexpr (n == 1 && LOAD) {
        uint32_t v;
        if (t.load<4>(a, v, true)) t.s_[o.rd] = v;
    } else if constexpr (n == 1) {
        t.store<4>(a, t.s_[o.rd], true);
    } else {
        v_transfer<LOAD>(t, a, o.rd, n);
    }
}
// One word in SRAM or flash only (threaded_try).
template <bool LOAD>
HQ_INLINE bool v_ldst_try(Thumb& t, const Op& o) {
    const uint32_t a = v_address(t, o);
    if constexpr (!LOAD) return t.store_fast<4>(a, t.s_[o.rd]);
    uint32_t v;
    if (!t.load_fast<4>(a, v)) return false;
    t.s_[o.rd] = v;
    return true;
}

// VLDM/VSTM: o.imm words from S[o.rd]; o.x writeback; o.y decrement before.
template <bool LOAD>
void v_multiple(Thumb& t, const Op& o) {
    const uint32_t base = t.r_[o.rn], n = o.imm;
    const uint32_t start = o.y ? base - 4 * n : base;
    if (!v_transfer<LOAD>(t, start, o.rd, n)) return;
    if (o.x) t.r_[o.rn] = o.y ? start : base + 4 * n;
}

inline uint32_t bits(uint32_t v, unsigned hi, unsigned lo) {
    return (v >> lo) & ((1u << (hi - lo + 1)) - 1);
}
inline uint8_t u8(uint32_t v) { return static_cast<uint8_t>(v); }

uint32_t expand_imm(uint32_t imm8) {
    const uint32_t b6 = (imm8 >> 6) & 1;
    const uint32_t exp = ((b6 ^ 1) << 7) | (b6 ? 0x7Cu : 0) | ((imm8 >> 4) & 3);
    return ((imm8 >> 7) << 31) | (exp << 23) | ((imm8 & 0xF) << 19);
}

bool decode_other(Op& op, uint16_t h1, uint16_t h2) {   // opc1 = 1x11: the rest
    const unsigned opc2 = bits(h1, 3, 0), opc3 = bits(h2, 7, 6);
    if (!(opc3 & 1)) {
        op.imm = expand_imm((opc2 << 4) | bits(h2, 3, 0));
        op.fn = v_imm;
        return true;
    }
    switch (opc2) {
        case 0: op.fn = opc3 == 1 ? v_mov : v_abs; return true;
        case 1: op.fn = opc3 == 1 ? v_neg : v_sqrt; op.cyc = opc3 == 1 ? 1 : 14; return true;
        case 4: case 5:
            op.fn = opc2 == 5 ? v_cmp<true> : v_cmp<false>;
            op.x = u8(opc2 == 5);
            return !(opc2 == 5 && bits(h2, 5, 5)) && !(opc2 == 5 && bits(h2, 3, 0));
        case 8:
            op.fn = v_from_int;
            op.x = u8(bits(h2, 7, 7));
            op.sn = 32;
            return true;
        case 12: case 13:
            op.fn = v_to_int;
            op.x = u8((opc2 & 1) | (bits(h2, 7, 7) << 1));
            op.sn = 32;
            return true;
        case 10: case 11: case 14: case 15: {       // fixed point, in place in Sd
            const unsigned size = bits(h2, 7, 7) ? 32 : 16;
            const unsigned imm = (bits(h2, 3, 0) << 1) | bits(h2, 5, 5);
            if (imm > size) return false;
            op.y = u8(size - imm);
            op.sn = u8(size);
            op.rm = op.rd;
            const bool is_unsigned = bits(h1, 0, 0);
            if (opc2 >= 14) {
                op.fn = v_to_int;
                op.x = u8((is_unsigned ? 0 : 1) | 2);
            } else {
                op.fn = v_from_int;
                op.x = u8(!is_unsigned);
            }
            return true;
        }
        default: return false;
    }
}

bool decode_data(Op& op, uint16_t h1, uint16_t h2) {
    op.rd = u8((bits(h2, 15, 12) << 1) | bits(h1, 6, 6));
    op.rn = u8((bits(h1, 3, 0) << 1) | bits(h2, 7, 7));
    op.rm = u8((bits(h2, 3, 0) << 1) | bits(h2, 5, 5));
    const unsigned opc1 = (bits(h1, 7, 7) << 2) | bits(h1, 5, 4), o = bits(h2, 6, 6);
    op.cyc = 1;
    switch (opc1) {
        case 0: op.fn = o ? v_mac<1> : v_mac<0>; op.cyc = 3; return true;      // VMLA VMLS
        case 1: op.fn = o ? v_mac<3> : v_mac<2>; op.cyc = 3; return true;      // VNMLS VNMLA
        case 2: op.fn = o ? v_arith<MUL, true> : v_arith<MUL, false>; return true; // VNMUL
        case 3: op.fn = o ? v_arith<SUB, false> : v_arith<ADD, false>; return true;
        case 4: op.fn = v_arith<DIV, false>; op.cyc = 14; return !o;
        case 5: op.fn = o ? v_fma<3> : v_fma<2>; op.cyc = 3; return true;      // VFNMS VFNMA
        case 6: op.fn = o ? v_fma<1> : v_fma<0>; op.cyc = 3; return true;      // VFMA VFMS
        default: return decode_other(op, h1, h2);
    }
}

bool decode_load_store(Op& op, uint16_t h1, uint16_t h2) {
    const bool p = bits(h1, 8, 8), u = bits(h1, 7, 7), w = bits(h1, 5, 5), l = bits(h1, 4, 4);
    const bool dbl = bits(h2, 8, 8);
    const unsigned vd = bits(h2, 15, 12), d = bits(h1, 6, 6), imm8 = bits(h2, 7, 0);
    op.rn = u8(bits(h1, 3, 0));
    op.rd = u8(dbl ? ((d << 4) | vd) * 2 : (vd << 1) | d);
    if (p && !w) {                                          // VLDR VSTR
        op.imm = u ? imm8 * 4 : 0u - imm8 * 4;
        op.x = dbl;
        op.fn = l ? (dbl ? v_ldst<true, 2> : v_ldst<true, 1>)
                  : (dbl ? v_ldst<false, 2> : v_ldst<false, 1>);
        op.cyc = 2;
        return op.rd + (dbl ? 2 : 1) <= 32 && (l || op.rn != 15);
    }
    if (p == u || op.rn == 15) return false;
    op.imm = dbl ? imm8 : imm8;
    if (dbl && (imm8 & 1)) return false;                   // FLDMX/FSTMX
    op.x = w;
    op.y = p;
    op.fn = l ? v_multiple<true> : v_multiple<false>;
    op.cyc = u8(1 + (dbl ? imm8 / 2 : imm8));
    return imm8 && op.rd + imm8 <= 32;
}

}  // namespace

Handler threaded_fp(Handler fn) {
    static const std::unordered_map<Handler, Handler> m = {
#define HQ_T(h) {h, threaded<h, true>}
#define HQ_TRY(h, fast) {h, threaded_try<h, fast>}
#define HQ_N(h) {h, threaded<h, true, false>}     // never stops
        HQ_TRY((v_arith<ADD, false>), (v_arith_try<ADD, false>)),
        HQ_TRY((v_arith<SUB, false>), (v_arith_try<SUB, false>)),
        HQ_TRY((v_arith<MUL, false>), (v_arith_try<MUL, false>)),
        HQ_TRY((v_arith<MUL, true>), (v_arith_try<MUL, true>)),
        HQ_TRY((v_arith<DIV, false>), (v_arith_try<DIV, false>)),
        HQ_TRY(v_mac<0>, v_mac_try<0>), HQ_TRY(v_mac<1>, v_mac_try<1>),
        HQ_TRY(v_mac<2>, v_mac_try<2>), HQ_TRY(v_mac<3>, v_mac_try<3>),
        HQ_TRY(v_fma<0>, v_fma_try<0>), HQ_TRY(v_fma<1>, v_fma_try<1>),
        HQ_TRY(v_fma<2>, v_fma_try<2>), HQ_TRY(v_fma<3>, v_fma_try<3>), HQ_N(v_mov),
        HQ_N(v_abs), HQ_N(v_neg), HQ_N(v_imm), HQ_N(v_sqrt), HQ_N(v_cmp<false>),
        HQ_N(v_cmp<true>), HQ_N(v_to_int), HQ_N(v_from_int), HQ_N(v_to_core), HQ_N(v_from_core),
        HQ_N(v_to_core2), HQ_N(v_from_core2), HQ_N(v_mrs),
        HQ_T(v_msr), HQ_T((v_ldst<true, 2>)), HQ_T((v_ldst<false, 2>)), HQ_T(v_multiple<true>),
        HQ_TRY((v_ldst<true, 1>), v_ldst_try<true>),
        HQ_TRY((v_ldst<false, 1>), v_ldst_try<false>),
        HQ_T(v_multiple<false>),
#undef HQ_T
#undef HQ_TRY
#undef HQ_N
    };
    const auto it = m.find(fn);
    return it == m.end() ? nullptr : it->second;
}

bool decode_fp(Op& op, uint16_t h1, uint16_t h2) {
    if ((h1 >> 12) != 0xE || bits(h2, 11, 9) != 5) return false;
    op.flags |= kFp;
    op.cyc = 1;
    const unsigned top = bits(h1, 11, 8);
    if (top == 0xE && !bits(h2, 4, 4)) return !bits(h2, 8, 8) && decode_data(op, h1, h2);
    if (top == 0xE) {                                       // 32-bit transfers
        if (bits(h2, 8, 8) || bits(h2, 6, 5) || bits(h2, 3, 0)) return false;
        const unsigned a = bits(h1, 7, 5);
        op.rd = u8(bits(h2, 15, 12));
        if (a == 0) {
            op.rn = u8((bits(h1, 3, 0) << 1) | bits(h2, 7, 7));
            op.fn = bits(h1, 4, 4) ? v_to_core : v_from_core;
            return op.rd < 13;
        }
        if (a == 7 && bits(h1, 3, 0) == 1) {
            op.fn = bits(h1, 4, 4) ? v_mrs : v_msr;
            return op.rd != 13 && (op.rd != 15 || bits(h1, 4, 4));
        }
        return false;
    }
    if ((h1 & 0xFFE0) == 0xEC40) {                          // two core registers
        op.rd = u8(bits(h2, 15, 12));
        op.ra = u8(bits(h1, 3, 0));
        const unsigned m = bits(h2, 5, 5), vm = bits(h2, 3, 0);
        op.rm = u8(bits(h2, 8, 8) ? ((m << 4) | vm) * 2 : (vm << 1) | m);
        const bool to_core = bits(h1, 4, 4);
        op.fn = to_core ? v_to_core2 : v_from_core2;
        return bits(h2, 7, 6) == 0 && bits(h2, 4, 4) && op.rm + 2 <= 32 && op.rd < 13 &&
               op.ra < 13 && !(to_core && op.rd == op.ra);
    }
    if ((top & 0xE) == 0xC && (h1 & 0xFFA0) != 0xEC00) return decode_load_store(op, h1, h2);
    return false;
}

}  // namespace hqsim::thumb
