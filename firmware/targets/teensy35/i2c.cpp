#include "i2c.hpp"

#include "clock.hpp"
#include "cpu.hpp"
#include "loop_timer.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {
constexpr uint32_t kSda = 3, kScl = 2;    // PTB3, PTB2
constexpr uint32_t kSdaBit = 1u << kSda, kSclBit = 1u << kScl;

// A wait's timeout in cycles of the clock now running, taken once before the wait polls.
uint32_t timeout_cycles(uint32_t timeout_us) { return timeout_us * (core_hz() / 1000000u); }
}  // namespace

// The byte-done wake-up. wait_byte() sleeps with IICIE set; the level (IICIF and IICIE)
// wakes it and this handler masks IICIE so the level drops and the handler does not run
// again before the waiter has seen IICIF. The flag itself is left for the waiter to clear.
extern "C" void I2C0_IRQHandler() {
    I2C0::C1::clear(I2C0::C1::IICIE);
}

void I2c0Bus::mux_i2c() {
    // ALT2 = I2C0; open drain, slow slew, high drive.
    const uint32_t pcr = PORTB::PCR2::MUX(2) | PORTB::PCR2::ODE | PORTB::PCR2::SRE |
                         PORTB::PCR2::DSE;
    PORTB::PCR2::write(pcr);
    PORTB::PCR3::write(pcr);
}

void I2c0Bus::begin() {
    SIM::SCGC5::set(SIM::SCGC5::PORTB);
    SIM::SCGC4::set(SIM::SCGC4::I2C0);
    I2C0::C1::write(0);
    I2C0::F::write(kFrequencyDivider);
    I2C0::FLT::write(I2C0::FLT::FLT_(kGlitchFilter));
    I2C0::S::write(I2C0::S::IICIF | I2C0::S::ARBL);
    I2C0::C1::write(I2C0::C1::IICEN);
    mux_i2c();
    nvic_enable(irq::I2C0, kIrqPriority);
}

// Both waits test the flag once more after the time is up: an interrupt that held the CPU
// past the timeout must not turn a finished byte into a bus recovery mid-transfer.
bool I2c0Bus::wait_byte() {
    const uint32_t t0 = cycles32(), budget = timeout_cycles(kByteTimeoutUs);
    // Sleep only once the loop tick runs: SysTick is then the wake-up that comes even when
    // the bus never answers. Before it (the IMU start-up) the wait polls.
    const bool sleep = LoopTimer::ticking();
    while (!(I2C0::S::read() & I2C0::S::IICIF)) {
        if (cycles32() - t0 > budget) {
            if (!(I2C0::S::read() & I2C0::S::IICIF)) return false;
            break;
        }
        if (sleep) {
            // As in LoopTimer::wait(): masked, WFI still wakes on the pending I2C0 (or any
            // other) interrupt, so a byte that ends between the check and the WFI cannot be
            // slept through. Unmasking lets the handler run; the loop then checks again.
            irq_disable();
            if (!(I2C0::S::read() & I2C0::S::IICIF)) {
                I2C0::C1::set(I2C0::C1::IICIE);
                wfi();
            }
            irq_enable();
            isb();
        }
    }
    I2C0::S::write(I2C0::S::IICIF);          // write-one-to-clear
    return true;
}

// A STOP takes one SCL period (2.7 us): this wait polls. Sleeping on it would need the
// stop-detect interrupt (FLT[SSIE]), which shares IICIF with the byte flag.
bool I2c0Bus::wait_idle() {
    const uint32_t t0 = cycles32(), budget = timeout_cycles(kByteTimeoutUs);
    while (I2C0::S::read() & I2C0::S::BUSY) {
        if (cycles32() - t0 > budget) return !(I2C0::S::read() & I2C0::S::BUSY);
    }
    return true;
}

I2c0Bus::Result I2c0Bus::send(uint8_t byte) {
    I2C0::D::write(byte);
    if (!wait_byte()) return Result::Timeout;
    const uint8_t s = I2C0::S::read();
    if (s & I2C0::S::ARBL) {
        I2C0::S::write(I2C0::S::ARBL);
        return Result::Lost;
    }
    return (s & I2C0::S::RXAK) ? Result::Nack : Result::Ok;
}

bool I2c0Bus::start(uint8_t address_byte) {
    if (!wait_idle()) {
        fail(Result::Timeout);
        return false;
    }
    I2C0::C1::write(I2C0::C1::IICEN | I2C0::C1::MST | I2C0::C1::TX);   // START
    const Result r = send(address_byte);
    return r == Result::Ok ? true : fail(r);
}

void I2c0Bus::stop() {
    I2C0::C1::write(I2C0::C1::IICEN);        // MST 1 -> 0: STOP
    wait_idle();
}

bool I2c0Bus::fail(Result r) {
    if (r == Result::Nack) {
        ++nacks_;
        stop();
        return false;
    }
    if (r == Result::Lost) ++arbitration_lost_;
    else ++timeouts_;
    I2C0::C1::write(I2C0::C1::IICEN);
    recover();
    return false;
}

void I2c0Bus::recover() {
    ++recoveries_;
    I2C0::C1::write(0);
    // GPIO: SCL driven as an open-drain output, SDA read.
    SIM::SCGC5::set(SIM::SCGC5::PORTB);
    PORTB::PCR2::write(PORTB::PCR2::MUX(1) | PORTB::PCR2::ODE);
    PORTB::PCR3::write(PORTB::PCR3::MUX(1) | PORTB::PCR3::ODE);
    GPIOB::PSOR::write(kSclBit | kSdaBit);
    GPIOB::PDDR::write((GPIOB::PDDR::read() | kSclBit) & ~kSdaBit);
    TeensyClock clock;
    for (int i = 0; i < 9 && !(GPIOB::PDIR::read() & kSdaBit); ++i) {
        GPIOB::PCOR::write(kSclBit);
        clock.delay_us(5);
        GPIOB::PSOR::write(kSclBit);
        clock.delay_us(5);
    }
    // STOP by hand: SDA low then high while SCL is high.
    GPIOB::PDDR::set(kSdaBit);
    GPIOB::PCOR::write(kSdaBit);
    clock.delay_us(5);
    GPIOB::PSOR::write(kSdaBit);
    clock.delay_us(5);
    GPIOB::PDDR::clear(kSclBit | kSdaBit);
    I2C0::C1::write(I2C0::C1::IICEN);
    I2C0::S::write(I2C0::S::IICIF | I2C0::S::ARBL);   // no stale flag for the next transfer
    mux_i2c();
}

bool I2c0Bus::write(uint8_t address, uint8_t reg, const uint8_t* data, size_t n) {
    if (!start(static_cast<uint8_t>(address << 1))) return false;
    Result r = send(reg);
    for (size_t i = 0; r == Result::Ok && i < n; ++i) r = send(data[i]);
    if (r != Result::Ok) return fail(r);
    stop();
    return true;
}

bool I2c0Bus::read(uint8_t address, uint8_t reg, uint8_t* data, size_t n) {
    if (n == 0) return true;
    if (!start(static_cast<uint8_t>(address << 1))) return false;
    Result r = send(reg);
    if (r != Result::Ok) return fail(r);
    I2C0::C1::set(I2C0::C1::RSTA);                                     // repeated START
    r = send(static_cast<uint8_t>((address << 1) | 1u));
    if (r != Result::Ok) return fail(r);
    // Receive: TX off; with one byte to read, NACK it at once.
    I2C0::C1::write(static_cast<uint8_t>(I2C0::C1::IICEN | I2C0::C1::MST |
                                         (n == 1 ? I2C0::C1::TXAK : 0)));
    read_for_effect(I2C0::D::ref());                   // dummy read: clocks in the first byte
    for (size_t i = 0; i < n; ++i) {
        if (!wait_byte()) return fail(Result::Timeout);
        if (i + 1 == n) {
            I2C0::C1::write(I2C0::C1::IICEN);   // STOP before reading the last byte
        } else if (i + 2 == n) {
            I2C0::C1::set(I2C0::C1::TXAK);      // the next (last) byte gets a NACK
        }
        data[i] = I2C0::D::read();
    }
    wait_idle();
    return true;
}

}  // namespace hq::teensy
