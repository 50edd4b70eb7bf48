#include "cpu.hpp"

namespace hq::teensy {

void nvic_enable(int irq, uint8_t priority) {
    reg_at<mk64::NVIC::NVICIP0>(irq) = static_cast<uint8_t>(priority << 4);
    reg_at<mk64::NVIC::NVICISER0>(irq / 32) = 1u << (irq % 32);
}

void nvic_disable(int irq) {
    reg_at<mk64::NVIC::NVICICER0>(irq / 32) = 1u << (irq % 32);
}

}  // namespace hq::teensy
