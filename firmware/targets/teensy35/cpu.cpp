#include "cpu.hpp"

namespace hq::teensy {

namespace {
// NVIC registers are word arrays in the SVD (ISER0..3, ICER0..3, IP0..); index from the first.
inline volatile uint32_t& iser(int word) {
    return (&mk64::NVIC::NVICISER0::ref())[word];
}
inline volatile uint32_t& icer(int word) {
    return (&mk64::NVIC::NVICICER0::ref())[word];
}
inline volatile uint8_t& ipr(int irq) { return (&mk64::NVIC::NVICIP0::ref())[irq]; }
}  // namespace

void nvic_enable(int irq, uint8_t priority) {
    ipr(irq) = static_cast<uint8_t>(priority << 4);
    iser(irq / 32) = 1u << (irq % 32);
}

void nvic_disable(int irq) {
    icer(irq / 32) = 1u << (irq % 32);
    dsb();
    isb();
}

}  // namespace hq::teensy
