// Cortex-M4 core helpers for the Teensy 3.5 backends: interrupt masking, barriers, sleep and
// the NVIC. Register addresses come from the generated mk64f12.hpp.
#pragma once

#include <cstdint>

#include "mk64f12.hpp"

namespace hq::teensy {

inline void dsb() { __asm volatile("dsb" ::: "memory"); }
inline void isb() { __asm volatile("isb" ::: "memory"); }
inline void wfi() { __asm volatile("wfi" ::: "memory"); }

// Masks interrupts and returns the previous PRIMASK, for irq_restore().
inline uint32_t irq_save() {
    uint32_t primask;
    __asm volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
    return primask;
}
inline void irq_restore(uint32_t primask) {
    __asm volatile("msr primask, %0" ::"r"(primask) : "memory");
}
inline void irq_enable() { __asm volatile("cpsie i" ::: "memory"); }
inline void irq_disable() { __asm volatile("cpsid i" ::: "memory"); }

// Interrupts masked for the lifetime of the object.
class IrqGuard {
public:
    IrqGuard() : saved_(irq_save()) {}
    ~IrqGuard() { irq_restore(saved_); }
    IrqGuard(const IrqGuard&) = delete;
    IrqGuard& operator=(const IrqGuard&) = delete;

private:
    uint32_t saved_;
};

// Element i of a register array whose first element is Reg0 and whose elements lie
// stride_elements apart (NVIC ISER0..3: 1; FTM CnSC/CnV: 2, since they interleave).
template <typename Reg0>
inline volatile typename Reg0::type& reg_at(int i, int stride_elements = 1) {
    return (&Reg0::ref())[i * stride_elements];
}

// Reads a register for its side effect only (a flag clear, the I2C dummy read): a plain
// `(void)reg;` on a volatile reference is not a read in C++.
inline uint8_t read_for_effect(volatile uint8_t& reg) {
    const uint8_t v = reg;
    return v;
}

// Priority 0 (highest) .. 15; the MK64 implements the top four bits of each priority byte.
void nvic_enable(int irq, uint8_t priority);
// The interrupt no longer reaches the core (its pending flag and priority are kept).
void nvic_disable(int irq);

}  // namespace hq::teensy
