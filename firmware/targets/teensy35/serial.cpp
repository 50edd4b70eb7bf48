#include "serial.hpp"

#include "clock.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {

constexpr uint8_t kHwFifo = 8;          // UART0's TX and RX FIFOs hold 8 bytes

// Single producer, single consumer: main writes tx_head and reads rx_tail, the interrupt
// the other two. Indices run freely; masks pick the slot.
struct Rings {
    uint8_t tx[Uart0Serial::kTxRing];
    uint8_t rx[Uart0Serial::kRxRing];
    volatile uint32_t tx_head = 0, tx_tail = 0, rx_head = 0, rx_tail = 0;
    volatile uint32_t rx_overruns = 0;
};
Rings g_uart;

static_assert((Uart0Serial::kTxRing & (Uart0Serial::kTxRing - 1)) == 0, "power of two");
static_assert((Uart0Serial::kRxRing & (Uart0Serial::kRxRing - 1)) == 0, "power of two");

}  // namespace

bool uart_divisor(uint32_t clock_hz, uint32_t baud, uint16_t& sbr, uint8_t& brfa) {
    if (baud == 0) return false;
    // Divisor in 1/32 steps: 32 f / (16 baud) = 2 f / baud, rounded.
    const uint64_t div32 = (2ull * clock_hz + baud / 2) / baud;
    if (div32 < 32 || div32 >= (8192ull << 5)) return false;
    sbr = static_cast<uint16_t>(div32 >> 5);
    brfa = static_cast<uint8_t>(div32 & 31u);
    const uint64_t actual_x32 = 2ull * clock_hz * 32 / div32;     // 32 x actual baud
    const uint64_t want_x32 = 32ull * baud;
    const uint64_t err = actual_x32 > want_x32 ? actual_x32 - want_x32 : want_x32 - actual_x32;
    return err * 50 <= want_x32;                                   // within 2 %
}

bool Uart0Serial::begin(uint32_t baud) {
    uint16_t sbr = 0;
    uint8_t brfa = 0;
    if (!uart_divisor(core_hz(), baud, sbr, brfa)) return false;
    SIM::SCGC5::set(SIM::SCGC5::PORTB);
    SIM::SCGC4::set(SIM::SCGC4::UART0);
    UART0::C2::write(0);
    UART0::BDH::write(UART0::BDH::SBR(sbr >> 8));       // BDH first: BDL's write latches both
    UART0::BDL::write(static_cast<uint8_t>(sbr & 0xFF));
    UART0::C4::write(UART0::C4::BRFA(brfa));
    UART0::C1::write(0);                                // 8N1
    UART0::PFIFO::write(UART0::PFIFO::TXFE | UART0::PFIFO::RXFE);
    UART0::CFIFO::write(UART0::CFIFO::TXFLUSH | UART0::CFIFO::RXFLUSH);
    UART0::TWFIFO::write(UART0::TWFIFO::TXWATER(2));    // refill when two bytes remain
    UART0::RWFIFO::write(UART0::RWFIFO::RXWATER(1));
    // ALT3 = UART0; RX with a pull-up (an unplugged cable reads idle, not noise).
    PORTB::PCR16::write(PORTB::PCR16::MUX(3) | PORTB::PCR16::PE | PORTB::PCR16::PS);
    PORTB::PCR17::write(PORTB::PCR17::MUX(3) | PORTB::PCR17::DSE | PORTB::PCR17::SRE);
    UART0::C2::write(UART0::C2::TE | UART0::C2::RE | UART0::C2::RIE);
    nvic_enable(irq::UART0_RX_TX, 8);
    return true;
}

size_t Uart0Serial::write(const uint8_t* data, size_t n) {
    const uint32_t head = g_uart.tx_head;
    const uint32_t used = head - g_uart.tx_tail;
    if (n > kTxRing - used) return 0;                   // refused whole
    for (size_t i = 0; i < n; ++i) g_uart.tx[(head + i) & (kTxRing - 1)] = data[i];
    g_uart.tx_head = head + static_cast<uint32_t>(n);
    IrqGuard guard;
    UART0::C2::set(UART0::C2::TIE);
    return n;
}

size_t Uart0Serial::read(uint8_t* data, size_t n) {
    uint32_t tail = g_uart.rx_tail;
    const uint32_t head = g_uart.rx_head;
    size_t got = 0;
    while (got < n && tail != head) data[got++] = g_uart.rx[tail++ & (kRxRing - 1)];
    g_uart.rx_tail = tail;
    return got;
}

uint32_t Uart0Serial::rx_overruns() const { return g_uart.rx_overruns; }
size_t Uart0Serial::tx_pending() const { return g_uart.tx_head - g_uart.tx_tail; }

}  // namespace hq::teensy

extern "C" void UART0_RX_TX_IRQHandler() {
    using namespace hq::teensy;
    using namespace hq::mk64;
    const uint8_t s1 = UART0::S1::read();      // reading S1 first arms the flag clears below
    // Receive: drain the FIFO into the ring; a full ring drops the byte and counts it.
    while (UART0::RCFIFO::read() > 0) {
        const uint8_t b = UART0::D::read();
        const uint32_t head = g_uart.rx_head;
        if (head - g_uart.rx_tail < Uart0Serial::kRxRing) {
            g_uart.rx[head & (Uart0Serial::kRxRing - 1)] = b;
            g_uart.rx_head = head + 1;
        } else {
            g_uart.rx_overruns = g_uart.rx_overruns + 1;
        }
    }
    if (s1 & UART0::S1::OR) g_uart.rx_overruns = g_uart.rx_overruns + 1;
    // Transmit: top the FIFO up from the ring; with the ring empty, stop the interrupt.
    if (UART0::C2::read() & UART0::C2::TIE) {
        uint32_t tail = g_uart.tx_tail;
        const uint32_t head = g_uart.tx_head;
        while (tail != head && UART0::TCFIFO::read() < kHwFifo) {
            UART0::D::write(g_uart.tx[tail++ & (Uart0Serial::kTxRing - 1)]);
        }
        g_uart.tx_tail = tail;
        if (tail == head) UART0::C2::clear(UART0::C2::TIE);
    }
}
