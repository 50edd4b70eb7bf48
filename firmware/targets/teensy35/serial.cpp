#include "serial.hpp"

#include <atomic>
#include <cstring>

#include "clock.hpp"
#include "cpu.hpp"
#include "mk64f12.hpp"

namespace hq::teensy {

using namespace hq::mk64;

namespace {

constexpr uint8_t kHwFifo = 8;          // UART0's TX and RX FIFOs hold 8 bytes
constexpr uint8_t kTxWater = 2;         // TDRE (and the interrupt) while at most this many wait

// Single producer, single consumer: main writes tx_head and reads rx_tail, the interrupt
// the other two. Indices run freely; masks pick the slot. The buffers themselves are not
// volatile, so signal fences order them against the index that publishes them (release
// before a producer's index store, acquire after a consumer's index load).
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
    UART0::TWFIFO::write(UART0::TWFIFO::TXWATER(kTxWater));   // refill when two bytes remain
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
    // Into the ring in at most two pieces (where it wraps): a copy, not a loop a byte.
    const uint32_t at = head & (kTxRing - 1);
    const size_t first = n < kTxRing - at ? n : kTxRing - at;
    std::memcpy(&g_uart.tx[at], data, first);
    std::memcpy(&g_uart.tx[0], data + first, n - first);
    std::atomic_signal_fence(std::memory_order_release);
    g_uart.tx_head = head + static_cast<uint32_t>(n);
    IrqGuard guard;
    UART0::C2::set(UART0::C2::TIE);
    return n;
}

size_t Uart0Serial::read(uint8_t* data, size_t n) {
    uint32_t tail = g_uart.rx_tail;
    const uint32_t head = g_uart.rx_head;
    std::atomic_signal_fence(std::memory_order_acquire);
    size_t got = 0;
    while (got < n && tail != head) data[got++] = g_uart.rx[tail++ & (kRxRing - 1)];
    std::atomic_signal_fence(std::memory_order_release);
    g_uart.rx_tail = tail;
    return got;
}

uint32_t Uart0Serial::rx_overruns() const { return g_uart.rx_overruns; }


namespace {
void push_rx(uint8_t b) {
    const uint32_t head = g_uart.rx_head;
    if (head - g_uart.rx_tail < Uart0Serial::kRxRing) {
        g_uart.rx[head & (Uart0Serial::kRxRing - 1)] = b;
        std::atomic_signal_fence(std::memory_order_release);
        g_uart.rx_head = head + 1;
    } else {
        g_uart.rx_overruns = g_uart.rx_overruns + 1;
    }
}
}  // namespace

}  // namespace hq::teensy

// UART0 status interrupt. RDRF and TDRE are latched flags: RDRF clears only when S1 is read
// with it set and then D is read, TDRE only when S1 is read and then D is written, each with
// the FIFO count moving past its watermark. So S1 is read right before the D access that
// should clear the flag (the last read of a drain, the top-up write that passes the
// watermark): reading S1 once at entry and draining bytes that arrived later would leave RDRF
// set over an empty FIFO and the interrupt firing back to back, starving the loop.
extern "C" void UART0_RX_TX_IRQHandler() {
    using namespace hq::teensy;
    using namespace hq::mk64;
    // Receive: every byte the FIFO holds now, S1 read before the last one.
    const uint8_t avail = UART0::RCFIFO::read();
    if (avail > 0) {
        for (uint8_t i = 1; i < avail; ++i) push_rx(UART0::D::read());
        const uint8_t s1 = UART0::S1::read();
        push_rx(UART0::D::read());
        if (s1 & UART0::S1::OR) g_uart.rx_overruns = g_uart.rx_overruns + 1;
    } else if (UART0::S1::read() & (UART0::S1::RDRF | UART0::S1::OR)) {
        // A flag left set over an empty FIFO: a dummy read (it underflows the FIFO), then
        // flush and clear the underflow, so the interrupt cannot fire again for nothing.
        read_for_effect(UART0::D::ref());
        UART0::CFIFO::write(UART0::CFIFO::RXFLUSH);
        UART0::SFIFO::write(UART0::SFIFO::RXUF);
    }
    // Transmit: top the FIFO up from the ring; with the ring empty, stop the interrupt. The
    // FIFO's count is read once: it only falls while the handler writes (the shifter takes
    // bytes), so the room it leaves is never overfilled. S1 is read right before the write
    // that takes the count past the watermark, the one that clears TDRE (every peripheral
    // access costs bus cycles: two per byte were most of the handler's time).
    // Two plain copy loops around that S1 read, not a test of the count at every byte.
    if (UART0::C2::read() & UART0::C2::TIE) {
        uint32_t tail = g_uart.tx_tail;
        const uint32_t head = g_uart.tx_head;
        std::atomic_signal_fence(std::memory_order_acquire);
        const uint32_t queued = UART0::TCFIFO::read();
        const uint32_t room = queued < kHwFifo ? kHwFifo - queued : 0;
        const uint32_t n = head - tail < room ? head - tail : room;
        const uint32_t below = queued < kTxWater ? kTxWater - queued : 0;   // up to the mark
        const uint32_t first = n < below ? n : below;
        const uint32_t end = tail + n;
        for (const uint32_t mark = tail + first; tail != mark; ++tail)
            UART0::D::write(g_uart.tx[tail & (Uart0Serial::kTxRing - 1)]);
        if (tail != end && queued + first == kTxWater) read_for_effect(UART0::S1::ref());
        for (; tail != end; ++tail) UART0::D::write(g_uart.tx[tail & (Uart0Serial::kTxRing - 1)]);
        g_uart.tx_tail = tail;
        if (tail == head) UART0::C2::clear(UART0::C2::TIE);
    }
}
