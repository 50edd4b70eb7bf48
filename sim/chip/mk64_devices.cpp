// The emulated peripherals the flight loop uses all the time: DWT_CYCCNT, SysTick, UART0,
// I2C0 with the MPU6050, FTM0/FTM3 and the watchdog; and the flash module (FTFE), whose
// status a parameter save polls hundreds of thousands of times. Their behaviour is documented
// where their Python views live (sim/chip/scs.py, uart.py, i2c.py, ftm.py, wdog.py, ftfe.py);
// register offsets and bits come from the SVD tables through Python (Layout), never typed here.
#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <stdexcept>
#include <type_traits>

#include "chip/mk64_core.hpp"
#include "core/mpu6050.hpp"
#include "sensor/mpu6050_emulator.hpp"

namespace hqsim::mk64 {

namespace {
constexpr uint64_t kNever = uint64_t{1} << 40;     // a rate of 0: the event never comes
constexpr int kBitsPerByte = 9;

// Word-wide registers accessed with any width: the bytes of the word at address & ~3.
uint32_t merge_word(uint32_t old, uint32_t address, unsigned size, uint64_t value, uint32_t& mask) {
    const uint32_t shift = 8 * (address & 3);
    const uint64_t width = size >= 4 ? 0xFFFFFFFFull : ((uint64_t{1} << (8 * size)) - 1);
    mask = static_cast<uint32_t>(width << shift);
    return (old & ~mask) | (static_cast<uint32_t>(value << shift) & mask);
}

uint64_t extract(uint32_t word, uint32_t address, unsigned size) {
    const uint64_t width = size >= 4 ? 0xFFFFFFFFull : ((uint64_t{1} << (8 * size)) - 1);
    return (word >> (8 * (address & 3))) & width;
}

int shift_of(uint32_t mask) {
    int s = 0;
    while (mask && !(mask & 1)) {
        mask >>= 1;
        ++s;
    }
    return s;
}
}  // namespace

uint32_t Layout::operator[](const std::string& name) const {
    auto it = k.find(name);
    if (it == k.end()) throw std::invalid_argument("register layout has no " + name);
    return it->second;
}

// -- DWT --------------------------------------------------------------------------------------
bool Dwt::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    const uint32_t a = address & ~3u;
    if (a == cyccnt_address) {
        out = extract(cyccnt(c.now()), address, size);
    } else if (a == ctrl_address) {
        out = extract(ctrl, address, size);
    } else {
        return false;
    }
    return true;
}

bool Dwt::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    const uint32_t a = address & ~3u;
    const uint64_t now = c.now();
    uint32_t mask = 0;
    if (a == ctrl_address) {
        const uint32_t v = merge_word(ctrl, address, size, value, mask);
        ctrl = ctrl_reset | (v & 1u);           // only CYCCNTENA is modelled
        sync(now);
    } else if (a == cyccnt_address) {
        base_value = merge_word(cyccnt(now), address, size, value, mask);
        since = running() ? static_cast<int64_t>(now) : -1;
    } else {
        return false;
    }
    return true;
}

// -- GPIO inputs -------------------------------------------------------------------------------
bool GpioInputs::read(uint32_t address, unsigned size, uint64_t& out) const {
    for (const Port& p : ports) {
        if ((address & ~3u) == p.address) {
            out = extract(p.value, address, size);
            return true;
        }
    }
    return false;
}

void GpioInputs::set(uint32_t address, uint32_t value) {
    Port* p = port(address);
    if (!p) {
        ports.push_back({address, value});
        p = &ports.back();
    }
    p->published = value;
    p->value = (value & ~p->held) | (p->held_value & p->held);
}

GpioInputs::Port* GpioInputs::port(uint32_t address) {
    for (Port& p : ports) {
        if (p.address == address) return &p;
    }
    return nullptr;
}

void GpioInputs::hold(Port& p, uint32_t bit, bool level) {
    p.held |= bit;
    p.held_value = level ? (p.held_value | bit) : (p.held_value & ~bit);
    p.value = level ? (p.value | bit) : (p.value & ~bit);
}

void GpioInputs::release(Port& p, uint32_t bit) {
    p.held &= ~bit;
    p.value = (p.value & ~bit) | (p.published & bit);
}

void GpioInputs::release_all() {
    for (Port& p : ports) {
        p.held = p.held_value = 0;
        p.value = p.published;
    }
}

// -- GPIO outputs ------------------------------------------------------------------------------
bool GpioOutputs::write(uint32_t address, unsigned size, uint64_t value) const {
    if (size != 4) return false;
    const uint32_t v = static_cast<uint32_t>(value);
    for (const Port& p : ports) {
        if (address < p.base || address >= p.base + 0x10) continue;
        uint32_t pdor = p.pdor;
        switch (address - p.base) {
            case 0x0: pdor = v; break;              // PDOR
            case 0x4: pdor |= v; break;             // PSOR
            case 0x8: pdor &= ~v; break;            // PCOR
            case 0xC: pdor ^= v; break;             // PTOR
            default: return false;
        }
        return pdor == p.pdor;
    }
    return false;
}

void GpioOutputs::set(uint32_t base, uint32_t pdor) {
    for (Port& p : ports) {
        if (p.base == base) {
            p.pdor = pdor;
            return;
        }
    }
    ports.push_back({base, pdor});
}

// -- pin edges driven from outside --------------------------------------------------------------
void PinEdges::add(Core& c, uint64_t cycle, bool level, std::vector<Pin> pins) {
    size_t i = edges.size();
    while (i > 0 && edges[i - 1].cycle > cycle) --i;
    edges.insert(edges.begin() + static_cast<ptrdiff_t>(i), Edge{cycle, level, std::move(pins)});
    if (i == 0) schedule(c);
}

void PinEdges::schedule(Core& c) {
    if (event) c.cancel(event);
    event = edges.empty() ? 0 : c.at(edges.front().cycle, Ev::PinEdge, false);
}

void PinEdges::fire(Core& c) {
    event = 0;
    const Edge edge = std::move(edges.front());
    edges.erase(edges.begin());
    for (const Pin& pin : edge.pins) {
        GpioInputs::Port* port = c.gpio_in.port(pin.pdir);
        if (!port) continue;
        const bool was = (port->value & pin.bit) != 0;
        c.gpio_in.hold(*port, pin.bit, edge.level);
        bool later = false;                  // another edge on this pin is still to come
        for (const Edge& e : edges) {
            for (const Pin& q : e.pins) later = later || (q.pdir == pin.pdir && q.bit == pin.bit);
        }
        if (!later) c.gpio_in.release(*port, pin.bit);
        if (was != edge.level && pin.ftm3_channel >= 0 && c.ftm3.ready) {
            c.ftm3.edge(c, pin.ftm3_channel, edge.level);
        }
    }
    schedule(c);
}

void PinEdges::reset(Core& c) {
    edges.clear();
    event = 0;                           // the core's reset dropped the events
    c.gpio_in.release_all();
}

// -- SysTick ----------------------------------------------------------------------------------
uint32_t SysTick::value(uint64_t now) const {
    if (zero_at < 0) return stopped_value;
    const uint64_t z = static_cast<uint64_t>(zero_at);
    if (now <= z) return static_cast<uint32_t>(z - now);
    const uint64_t period = uint64_t{rvr} + 1;
    const uint64_t r = (now - z) % period;
    return static_cast<uint32_t>(r ? period - r : 0);
}

void SysTick::schedule(Core& c) {
    if (event) c.cancel(event);
    event = zero_at >= 0 ? c.at(static_cast<uint64_t>(zero_at), Ev::SysTick, false) : 0;
}

void SysTick::on_zero(Core& c) {
    event = 0;
    csr |= 1u << 16;                        // COUNTFLAG
    wraps.push_back(static_cast<uint64_t>(zero_at));
    if (wraps.size() > 64) wraps.pop_front();
    if (csr & 2) c.pend(15);
    if (rvr == 0) {                         // a reload of 0 stops the counter
        stopped_value = 0;
        zero_at = -1;
        return;
    }
    zero_at += static_cast<int64_t>(rvr) + 1;
    schedule(c);
}

uint32_t SysTick::read_reg(uint32_t offset, uint64_t now) {
    if (offset == 0x0) {
        const uint32_t v = csr | (1u << 2);
        csr &= ~(1u << 16);                 // COUNTFLAG clears on read
        return v;
    }
    if (offset == 0x4) return rvr;
    if (offset == 0x8) return value(now);
    return calib;
}

void SysTick::write_reg(Core& c, uint32_t offset, uint32_t v, uint64_t now) {
    const int64_t t = static_cast<int64_t>(now);
    if (offset == 0x0) {
        const bool was = enabled();
        csr = (csr & (1u << 16)) | (v & 0x3u) | (1u << 2);
        if (enabled() && !was) {
            const uint32_t current = stopped_value;
            zero_at = current ? t + current : t + 1 + rvr;
            if (current == 0 && rvr == 0) zero_at = -1;
            schedule(c);
        } else if (was && !enabled()) {
            stopped_value = value(now);
            zero_at = -1;
            schedule(c);
        }
    } else if (offset == 0x4) {
        rvr = v & 0xFFFFFFu;
        if (enabled() && zero_at < 0 && rvr) {
            zero_at = t + 1 + rvr;
            schedule(c);
        }
    } else if (offset == 0x8) {             // any write clears the counter and COUNTFLAG
        csr &= ~(1u << 16);
        if (enabled()) {
            zero_at = rvr ? t + 1 + rvr : -1;
            schedule(c);
        } else {
            stopped_value = 0;
        }
    }
}

bool SysTick::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    const uint32_t a = address & ~3u;
    if (a < base || a >= base + 0x10) return false;
    out = extract(read_reg(a - base, c.now()), address, size);
    return true;
}

bool SysTick::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    const uint32_t a = address & ~3u;
    if (a < base || a >= base + 0x10) return false;
    const uint64_t now = c.now();
    // Byte and halfword writes merge into the word; CSR's merge must not read (and clear)
    // COUNTFLAG.
    const uint32_t old = a == base ? csr : read_reg(a - base, now);
    uint32_t mask = 0;
    write_reg(c, a - base, merge_word(old, address, size, value, mask), now);
    return true;
}

// -- UART0 ------------------------------------------------------------------------------------
void Uart::setup() {
    oBDH = L["BDH"]; oBDL = L["BDL"]; oC1 = L["C1"]; oC2 = L["C2"]; oS1 = L["S1"];
    oC3 = L["C3"]; oD = L["D"]; oC4 = L["C4"]; oPFIFO = L["PFIFO"]; oCFIFO = L["CFIFO"];
    oSFIFO = L["SFIFO"]; oTWFIFO = L["TWFIFO"]; oTCFIFO = L["TCFIFO"]; oRWFIFO = L["RWFIFO"];
    oRCFIFO = L["RCFIFO"]; oED = L["ED"];
    TIE = L["C2.TIE"]; TCIE = L["C2.TCIE"]; RIE = L["C2.RIE"]; ILIE = L["C2.ILIE"];
    TE = L["C2.TE"]; RE = L["C2.RE"];
    TDRE = L["S1.TDRE"]; TC = L["S1.TC"]; RDRF = L["S1.RDRF"]; IDLE = L["S1.IDLE"];
    OR = L["S1.OR"];
    S1_CLEARED_BY_D = IDLE | OR | L["S1.NF"] | L["S1.FE"] | L["S1.PF"];
    SBR_HIGH = L["BDH.SBR"]; SBNS = L["BDH.SBNS"]; M = L["C1.M"]; BRFA = L["C4.BRFA"];
    ORIE = L["C3.ORIE"]; TXFE = L["PFIFO.TXFE"]; RXFE = L["PFIFO.RXFE"];
    TXFLUSH = L["CFIFO.TXFLUSH"]; RXFLUSH = L["CFIFO.RXFLUSH"];
    CFIFO_ENABLES = L["CFIFO.RXUFE"] | L["CFIFO.TXOFE"] | L["CFIFO.RXOFE"];
    TXEMPT = L["SFIFO.TXEMPT"]; RXEMPT = L["SFIFO.RXEMPT"]; TXOF = L["SFIFO.TXOF"];
    RXUF = L["SFIFO.RXUF"];
    SFIFO_W1C = RXUF | TXOF | L["SFIFO.RXOF"];
    FIFO_CODE = L["FIFO_CODE"];
    ready = true;
}

void Uart::reset(Core&) {
    v.assign(L.reset.begin(), L.reset.end());
    tx.clear();
    rx.clear();
    rx_queue.clear();
    sent.clear();
    notes.clear();
    shifting = -1;
    shift_start = shift_frame = 0;
    tx_event = rx_event = idle_event = 0;
    bdh_buffer = v[oBDH];
    s1_seen = 0;
    rdrf = false;
    flags = 0;
    overruns = tx_overflows = 0;
    line_rxtx = line_err = false;
}

double Uart::baud(const Core& c) const {
    const uint32_t sbr = ((v[oBDH] & SBR_HIGH) << 8) | v[oBDL];
    const uint32_t brfa = v[oC4] & BRFA;
    if (sbr == 0) return 0.0;
    return c.core_hz() / (16 * (sbr + brfa / 32.0));    // UART0 runs from the core clock
}

int Uart::frame_bits() const {
    const int data = (v[oC1] & M) ? 9 : 8;
    const int stop = (v[oBDH] & SBNS) ? 2 : 1;
    return 1 + data + stop;
}

uint64_t Uart::frame_cycles(const Core& c) const {
    // Kept for the registers and clock it was computed from (a byte's time is asked for
    // every byte; they change at set-up).
    const FrameKey key{v[oBDH], v[oBDL], v[oC4], v[oC1], c.core_hz()};
    if (key == frame_key_) return frame_cycles_;
    const double b = baud(c);
    uint64_t cycles = kNever;
    if (b != 0.0) {
        const double n = std::nearbyint(frame_bits() * c.core_hz() / b);   // half to even
        cycles = std::max<uint64_t>(1, static_cast<uint64_t>(n));
    }
    frame_key_ = key;
    frame_cycles_ = cycles;
    return cycles;
}

size_t Uart::rx_water() const {
    return (v[oPFIFO] & RXFE) ? std::max<size_t>(1, v[oRWFIFO]) : 1;
}

bool Uart::tdre() const {
    const size_t water = (v[oPFIFO] & TXFE) ? v[oTWFIFO] : 0;
    return tx.size() <= water;
}

uint8_t Uart::s1() const {
    return static_cast<uint8_t>((tdre() ? TDRE : 0) | (tc() ? TC : 0) | (rdrf ? RDRF : 0) | flags);
}

void Uart::update_irq(Core& c) {
    catch_up(c, c.now());
    const uint8_t c2 = v[oC2], s = s1();
    const bool rxtx = ((c2 & TIE) && (s & TDRE)) || ((c2 & TCIE) && (s & TC)) ||
                      ((c2 & RIE) && (s & RDRF)) || ((c2 & ILIE) && (s & IDLE));
    const bool err = (v[oC3] & ORIE) && (s & OR);
    if (rxtx != line_rxtx || err != line_err) {
        line_rxtx = rxtx;
        line_err = err;
        c.set_irq(irq_rxtx, rxtx);
        c.set_irq(irq_err, err);
    }
}

void Uart::kick(Core& c) {
    if (shifting >= 0 || !(v[oC2] & TE) || tx.empty()) return;
    shifting = tx.front();
    tx.pop_front();
    shift_start = c.now();
    shift_frame = frame_cycles(c);
    ensure_tx_event(c);
}

void Uart::catch_up(Core& c, uint64_t now) {
    while (shifting >= 0 && shift_start + shift_frame <= now) {
        const uint64_t left = shift_start + shift_frame;
        if (shifting != kPreamble) sent.emplace_back(left, static_cast<uint8_t>(shifting));
        shifting = -1;
        if ((v[oC2] & TE) && !tx.empty()) {          // back to back, from the cycle it left
            shifting = tx.front();
            tx.pop_front();
            shift_start = left;
            shift_frame = frame_cycles(c);
        }
    }
}

uint64_t Uart::next_tx_change(const Core& c) const {
    if (shifting < 0) return 0;
    const uint64_t first = shift_start + shift_frame;
    if (!(v[oC2] & TE)) return first;                 // the shifter stops after this frame
    const size_t water = (v[oPFIFO] & TXFE) ? v[oTWFIFO] : 0;
    const uint64_t frame = frame_cycles(c);
    if ((v[oC2] & TIE) && tx.size() > water) {       // each frame leaving takes one byte
        return first + (tx.size() - water - 1) * frame;
    }
    return first + tx.size() * frame;
}

void Uart::ensure_tx_event(Core& c) {
    if (tx_event) return;
    const uint64_t due = next_tx_change(c);
    if (due) tx_event = c.at(due, Ev::UartTx);
}

void Uart::reschedule_tx(Core& c) {
    if (tx_event) c.cancel(tx_event);
    tx_event = 0;
    ensure_tx_event(c);
}

std::string Uart::take_sent_bytes() {
    std::string out;
    out.reserve(sent.size());
    for (const auto& s : sent) out.push_back(static_cast<char>(s.second));
    sent.clear();
    return out;
}

void Uart::shifted(Core& c) {
    tx_event = 0;
    catch_up(c, c.now());
    update_irq(c);
    ensure_tx_event(c);
}

void Uart::receive(Core& c, const uint8_t* data, size_t n) {
    rx_queue.insert(rx_queue.end(), data, data + n);
    if (!rx_event && !rx_queue.empty()) rx_event = c.at(c.now() + frame_cycles(c), Ev::UartRx);
}

void Uart::arrived(Core& c) {
    rx_event = 0;
    const uint8_t byte = rx_queue.front();
    rx_queue.pop_front();
    if (v[oC2] & RE) {
        if (rx.size() >= rx_depth()) {
            flags |= OR;
            ++overruns;
        } else {
            rx.push_back(byte);
            latch_rdrf();
        }
    }
    if (idle_event) c.cancel(idle_event);
    idle_event = c.at(c.cycles_ + frame_cycles(c), Ev::UartIdle);
    if (!rx_queue.empty()) rx_event = c.at(c.cycles_ + frame_cycles(c), Ev::UartRx);
    update_irq(c);
}

void Uart::idle(Core& c) {
    idle_event = 0;
    flags |= IDLE;
    update_irq(c);
}

uint8_t Uart::read_reg(Core& c, uint32_t o) {
    catch_up(c, c.now());
    if (o == oS1) {
        const uint8_t s = s1();
        s1_seen = static_cast<uint8_t>(s & (S1_CLEARED_BY_D | RDRF));
        return s;
    }
    if (o == oD) {
        uint8_t value = 0;
        if (!rx.empty()) {
            value = rx.front();
            rx.pop_front();
        } else {
            v[oSFIFO] |= RXUF;
        }
        if (s1_seen) {
            if ((s1_seen & RDRF) && rx.size() < rx_water()) rdrf = false;
            flags &= static_cast<uint8_t>(~(s1_seen & ~RDRF));
            s1_seen = 0;
        }
        update_irq(c);
        return value;
    }
    if (o == oPFIFO) {
        return static_cast<uint8_t>((v[oPFIFO] & (TXFE | RXFE)) | (FIFO_CODE << 4) | FIFO_CODE);
    }
    if (o == oSFIFO) {
        return static_cast<uint8_t>((v[oSFIFO] & SFIFO_W1C) | (tx.empty() ? TXEMPT : 0) |
                                    (rx.empty() ? RXEMPT : 0));
    }
    if (o == oTCFIFO) return static_cast<uint8_t>(tx.size());
    if (o == oRCFIFO) return static_cast<uint8_t>(rx.size());
    return v[o];
}

void Uart::write_reg(Core& c, uint32_t o, uint8_t value) {
    if (o == oS1 || o == oED || o == oTCFIFO || o == oRCFIFO) return;    // read-only
    catch_up(c, c.now());
    if (o == oBDH) {
        bdh_buffer = value;                      // buffered until BDL
    } else if (o == oBDL) {
        v[oBDH] = bdh_buffer;
        v[oBDL] = value;
    } else if (o == oD) {
        if (tx.size() >= tx_depth()) {
            v[oSFIFO] |= TXOF;
            ++tx_overflows;
        } else {
            tx.push_back(value);
        }
        kick(c);
        update_irq(c);
    } else if (o == oC2) {
        const uint8_t old = v[oC2];
        v[oC2] = value;
        if ((value & TE) && !(old & TE) && shifting < 0) {     // a preamble (idle frame) first
            shifting = kPreamble;
            shift_start = c.now();
            shift_frame = frame_cycles(c);
        }
        reschedule_tx(c);                        // TIE may move the change: first, then a
        kick(c);                                 // byte started now schedules its own
        update_irq(c);
    } else if (o == oC3) {
        v[oC3] = value;
        update_irq(c);
    } else if (o == oPFIFO) {
        if (v[oC2] & (TE | RE)) {
            notes.emplace_back(c.instructions_now(),
                               "UART0_PFIFO written with TE or RE set (the manual allows changing "
                               "the FIFO enables only with both clear)");
        }
        v[oPFIFO] = static_cast<uint8_t>(value & (TXFE | RXFE));
        reschedule_tx(c);
        update_irq(c);
    } else if (o == oCFIFO) {
        if (value & TXFLUSH) tx.clear();
        if (value & RXFLUSH) rx.clear();
        v[oCFIFO] = static_cast<uint8_t>(value & CFIFO_ENABLES);
        reschedule_tx(c);
        update_irq(c);
    } else if (o == oSFIFO) {
        v[oSFIFO] &= static_cast<uint8_t>(~(value & SFIFO_W1C));
    } else if (o == oTWFIFO) {
        v[oTWFIFO] = value;
        reschedule_tx(c);
        update_irq(c);
    } else if (o == oRWFIFO) {
        v[oRWFIFO] = value;
        latch_rdrf();
        update_irq(c);
    } else {
        v[o] = value;
    }
}

namespace {
// An access of any width is split onto the registers it covers, low address first, as
// sim/chip/peripheral.py's RegisterDevice does: a register read whole and the bytes taken from
// it, a part written merged into the register's stored value (so 8-bit registers see one
// access per byte). An offset no register occupies makes the whole access the caller's (a bus
// fault in Python). A write that resets the chip ends the access there.
bool covered(const Layout& L, uint32_t address, unsigned size) {
    if (address < L.base || address + size > L.base + L.span) return false;
    for (unsigned i = 0; i < size; ++i) {
        if (L.reg_at[address - L.base + i] < 0) return false;
    }
    return true;
}

uint64_t ones(unsigned bytes) { return bytes >= 8 ? ~uint64_t{0} : (uint64_t{1} << (8 * bytes)) - 1; }

template <typename Device>
bool read_regs(Device& d, Core& c, uint32_t address, unsigned size, uint64_t& out) {
    if (!covered(d.L, address, size)) return false;
    out = 0;
    for (unsigned done = 0; done < size;) {
        const uint32_t at = address - d.L.base + done;
        const uint32_t reg = static_cast<uint32_t>(d.L.reg_at[at]);
        const unsigned shift = at - reg;
        const unsigned take = std::min<unsigned>(d.L.width[reg] - shift, size - done);
        const uint64_t full = d.read_reg(c, reg);
        out |= ((full >> (8 * shift)) & ones(take)) << (8 * done);
        done += take;
    }
    return true;
}

template <typename Device>
bool write_regs(Device& d, Core& c, uint32_t address, unsigned size, uint64_t value) {
    if (!covered(d.L, address, size)) return false;
    using Value = std::remove_reference_t<decltype(d.v[0])>;
    for (unsigned done = 0; done < size && !c.reset_pending();) {
        const uint32_t at = address - d.L.base + done;
        const uint32_t reg = static_cast<uint32_t>(d.L.reg_at[at]);
        const unsigned shift = at - reg;
        const unsigned take = std::min<unsigned>(d.L.width[reg] - shift, size - done);
        const uint64_t part = (value >> (8 * done)) & ones(take);
        const uint64_t mask = ones(take) << (8 * shift);
        const uint64_t merged = (uint64_t{d.v[reg]} & ~mask) | (part << (8 * shift));
        d.write_reg(c, reg, static_cast<Value>(merged));
        done += take;
    }
    return true;
}
}  // namespace

bool Uart::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    return read_regs(*this, c, address, size, out);
}

bool Uart::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    return write_regs(*this, c, address, size, value);
}

// -- the MPU6050 on the bus -------------------------------------------------------------------
void MpuSlave::start(Core& c, bool read) {
    flush(c);
    if (read) {
        read_reg = pointer;
        read_bytes.clear();
    } else {
        pointer_set = false;
    }
}

bool MpuSlave::write_byte(uint8_t byte) {
    if (!pointer_set) {
        pointer = byte;
        pointer_set = true;
    } else {
        pending.push_back(byte);
    }
    return true;
}

namespace {
bool auto_increments(int reg) {
    return reg != hq::mpu6050::FIFO_R_W && reg != hq::mpu6050::MEM_R_W;
}
}  // namespace

uint8_t MpuSlave::read_byte() {
    const int reg = pointer >= 0 ? pointer : 0;
    uint8_t value = 0;
    emu->read(hq::mpu6050::kAddress, static_cast<uint8_t>(reg), &value, 1);
    read_bytes.push_back(value);
    if (auto_increments(reg)) pointer = (reg + 1) & 0x7F;
    return value;
}

void MpuSlave::flush(Core& c) {
    const double now = c.seconds(c.now());
    if (!pending.empty()) {
        emu->write(hq::mpu6050::kAddress, static_cast<uint8_t>(pointer), pending.data(),
                   pending.size());
        if (c.keep_records) log.push_back({now, 'W', pointer, pending});
        if (auto_increments(pointer)) {
            pointer = (pointer + static_cast<int>(pending.size())) & 0x7F;
        }
        pending.clear();
    } else if (!read_bytes.empty()) {
        if (c.keep_records) log.push_back({now, 'R', read_reg, read_bytes});
        read_bytes.clear();
    }
}

// -- I2C0 -------------------------------------------------------------------------------------
void I2c::setup() {
    oC1 = L["C1"]; oS = L["S"]; oD = L["D"]; oF = L["F"]; oFLT = L["FLT"];
    IICEN = L["C1.IICEN"]; IICIE = L["C1.IICIE"]; MST = L["C1.MST"]; TX = L["C1.TX"];
    TXAK = L["C1.TXAK"]; RSTA = L["C1.RSTA"];
    TCF = L["S.TCF"]; BUSY = L["S.BUSY"]; ARBL = L["S.ARBL"]; IICIF = L["S.IICIF"];
    RXAK = L["S.RXAK"];
    STOPF = L["FLT.STOPF"]; SSIE = L["FLT.SSIE"]; STARTF = L["FLT.STARTF"]; SHEN = L["FLT.SHEN"];
    FLT_FLT = L["FLT.FLT"];
    MULT = L["F.MULT"]; MULT_SHIFT = static_cast<uint32_t>(shift_of(MULT)); ICR = L["F.ICR"];
    ready = true;
}

void I2c::reset() {
    v.assign(L.reset.begin(), L.reset.end());
    transfers.clear();
    open = false;
    errors.clear();
    slave = nullptr;
    expect_address = reading = line = false;
    busy_until = event = free_event = 0;
    scl_held = false;
}

double I2c::scl_hz(const Core& c) const {
    const uint32_t mult = (v[oF] & MULT) >> MULT_SHIFT;
    if (mult == 3) return 0.0;
    return c.bus_hz() / ((1u << mult) * scl_divider[v[oF] & ICR]);
}

uint64_t I2c::bit_cycles(const Core& c) const {
    const double hz = scl_hz(c);
    if (hz == 0.0) return kNever;
    return std::max<uint64_t>(1, static_cast<uint64_t>(std::nearbyint(c.core_hz() / hz)));
}

void I2c::update_irq(Core& c) {
    const bool level = (v[oC1] & IICIE) && (v[oS] & IICIF);
    if (level != line) {
        line = level;
        c.set_irq(irq, level);
    }
}

void I2c::hold_scl(Core& c, bool held) {
    scl_held = held;
    if (held) {
        if (event) c.cancel(event);
        if (free_event) c.cancel(free_event);
        event = free_event = 0;
    } else if (!(v[oC1] & MST)) {
        v[oS] &= static_cast<uint8_t>(~BUSY);
    }
}

void I2c::start(Core& c, uint64_t now, bool) {
    if (free_event) {                    // a START before the last STOP finished
        c.cancel(free_event);
        free_event = 0;
    }
    end_transfer(c, now);
    v[oS] |= BUSY;
    busy_until = std::max(busy_until, now) + bit_cycles(c);
    expect_address = true;
    slave = nullptr;
    v[oFLT] |= STARTF;
    if (v[oFLT] & SSIE) flag(c, static_cast<uint8_t>(IICIF));
}

void I2c::stop(Core& c, uint64_t now) {
    end_transfer(c, now);
    expect_address = false;
    slave = nullptr;
    const uint64_t done = std::max(busy_until, now) + bit_cycles(c);
    busy_until = done;
    if (scl_held) return;
    free_event = c.at(done, Ev::I2cFree);
}

void I2c::bus_free(Core& c) {
    free_event = 0;
    v[oS] &= static_cast<uint8_t>(~BUSY);
    v[oFLT] |= STOPF;
    if (v[oFLT] & SSIE) flag(c, static_cast<uint8_t>(IICIF));
}

void I2c::end_transfer(Core& c, uint64_t now) {
    if (open) {
        transfers.back().end_cycle = static_cast<int64_t>(now);
        open = false;
    }
    for (MpuSlave* s : slaves) s->stop(c);
}

void I2c::begin_byte(Core& c, bool receive, int byte, bool ack) {
    const uint64_t now = c.now();
    if (event) {
        errors.emplace_back(c.instructions_now(), "D accessed while a byte was in transfer");
        c.cancel(event);
        event = 0;
    }
    const uint64_t start = std::max(now, busy_until);
    const uint64_t done = start + kBitsPerByte * bit_cycles(c);
    busy_until = done;
    v[oS] &= static_cast<uint8_t>(~TCF);
    if (scl_held) return;
    byte_receive = receive;
    byte_value = byte;
    byte_ack = ack;
    byte_start = start;
    event = c.at(done, Ev::I2cByte);
}

void I2c::finish_byte(Core& c) {
    event = 0;
    if (byte_receive) {
        const uint8_t value = (slave && reading) ? slave->read_byte() : 0xFF;
        v[oD] = value;
        if (open) transfers.back().data.push_back(value);
        v[oS] &= static_cast<uint8_t>(~RXAK);
    } else if (expect_address) {
        expect_address = false;
        const int address = byte_value >> 1;
        const bool read = byte_value & 1;
        MpuSlave* found = nullptr;
        if (pins_connected) {
            for (MpuSlave* s : slaves) {
                if (s->address == address && s->present) {
                    found = s;
                    break;
                }
            }
        }
        if (found) found->start(c, read);
        slave = found;
        reading = read;
        if (c.keep_records) {
            transfers.push_back({address, read, found != nullptr, byte_start, {}, -1,
                                 c.seconds(byte_start)});
            open = true;
        }
        set_rxak(found != nullptr);
    } else {
        bool acked = false;
        if (slave && !reading) {
            acked = slave->write_byte(static_cast<uint8_t>(byte_value));
            if (open) transfers.back().data.push_back(static_cast<uint8_t>(byte_value));
        }
        set_rxak(acked);
    }
    flag(c, static_cast<uint8_t>(TCF | IICIF));
}

uint8_t I2c::read_reg(Core& c, uint32_t o) {
    if (o == oC1) return static_cast<uint8_t>(v[oC1] & ~RSTA);
    if (o == oD) {
        const uint8_t data = v[oD];
        const uint8_t c1 = v[oC1];
        if ((c1 & MST) && !(c1 & TX) && (c1 & IICEN)) begin_byte(c, true, -1, !(c1 & TXAK));
        return data;
    }
    return v[o];
}

void I2c::write_reg(Core& c, uint32_t o, uint8_t value) {
    if (o == oS) {
        v[oS] = static_cast<uint8_t>(v[oS] & ~(value & (ARBL | IICIF)));
        update_irq(c);
    } else if (o == oFLT) {
        const uint8_t keep = static_cast<uint8_t>(v[oFLT] & (STOPF | STARTF) & ~value);
        v[oFLT] = static_cast<uint8_t>((value & (SHEN | SSIE | FLT_FLT)) | keep);
    } else if (o == oC1) {
        const uint8_t old = v[oC1];
        v[oC1] = static_cast<uint8_t>(value & ~RSTA);
        const uint64_t now = c.now();
        if (!(value & IICEN)) {
            if (old & MST) stop(c, now);
            update_irq(c);
            return;
        }
        if ((value & MST) && !(old & MST)) {
            start(c, now, false);
        } else if ((old & MST) && !(value & MST)) {
            stop(c, now);
        } else if ((value & RSTA) && (value & MST)) {
            if (v[oF] & MULT) {
                errors.emplace_back(c.instructions_now(),
                                    "repeated START with F[MULT] != 0 is not generated (e6070)");
            } else {
                start(c, now, true);
            }
        }
        update_irq(c);
    } else if (o == oD) {
        v[oD] = value;
        const uint8_t c1 = v[oC1];
        if ((c1 & MST) && (c1 & TX) && (c1 & IICEN)) begin_byte(c, false, value, false);
    } else {
        v[o] = value;
    }
}

bool I2c::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    return read_regs(*this, c, address, size, out);
}

bool I2c::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    return write_regs(*this, c, address, size, value);
}

// -- FTM0, FTM3 -------------------------------------------------------------------------------
namespace {
int64_t floor_mod(int64_t a, int64_t n) {
    const int64_t r = a % n;
    return r < 0 ? r + n : r;
}

// Python's int(x) of a float (truncation), for the cycle arithmetic the spec states in Python.
int64_t py_int(double x) { return static_cast<int64_t>(x); }

double elapsed(uint64_t now, uint64_t since) {
    return static_cast<double>(static_cast<int64_t>(now - since));
}

uint64_t plus(uint64_t cycle, int64_t n) {
    return static_cast<uint64_t>(static_cast<int64_t>(cycle) + n);
}

std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* fmt, ...) {
    char buf[256];
    va_list args;
    va_start(args, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, args);
    va_end(args);
    return buf;
}
}  // namespace

void Ftm::setup() {
    oSC = L["SC"]; oCNT = L["CNT"]; oMOD = L["MOD"]; oCNTIN = L["CNTIN"]; oSTATUS = L["STATUS"];
    oMODE = L["MODE"]; oCOMBINE = L["COMBINE"];
    for (int ch = 0; ch < kChannels; ++ch) {
        const std::string n = std::to_string(ch);
        oCnSC[ch] = L["C" + n + "SC"];
        oCnV[ch] = L["C" + n + "V"];
        CHnF[ch] = L["STATUS.CH" + n + "F"];
    }
    TOF = L["SC.TOF"]; TOIE = L["SC.TOIE"]; CPWMS = L["SC.CPWMS"]; CLKS = L["SC.CLKS"];
    PS = L["SC.PS"];
    CHF = L["C0SC.CHF"]; CHIE = L["C0SC.CHIE"]; MSB = L["C0SC.MSB"]; MSA = L["C0SC.MSA"];
    ELSB = L["C0SC.ELSB"]; ELSA = L["C0SC.ELSA"];
    CNSC_WRITABLE = CHIE | MSB | MSA | ELSB | ELSA | L["C0SC.DMA"];
    FTMEN = L["MODE.FTMEN"];
    channels_end = oCnV[kChannels - 1] + L.width.at(oCnV[kChannels - 1]);
    ready = true;
}

void Ftm::reset() {
    v = L.reset;
    anchored = false;
    anchor_cycle = 0;
    anchor_count = 0;
    pending.clear();
    captures.clear();
    unmodelled.clear();
    tof_clear = tof_event = 0;
    line = false;
}

double Ftm::clock_hz(const Core& c) const {
    const uint32_t clks = (v[oSC] & CLKS) >> shift_of(CLKS);
    const uint32_t ps = (v[oSC] & PS) >> shift_of(PS);
    double source = 0.0;
    if (clks == 1) {
        source = c.bus_hz();
    } else if (clks == 2) {
        source = c.fixed_hz();
    } else {
        return 0.0;
    }
    return source / (1u << ps);
}

double Ftm::ticks_per_cycle(const Core& c) const {
    const double hz = clock_hz(c);
    return hz != 0.0 ? hz / c.core_hz() : 0.0;
}

int64_t Ftm::period_ticks() const {
    return mod() >= cntin() ? int64_t{mod()} - cntin() + 1 : 0x10000;
}

uint32_t Ftm::count(Core& c, uint64_t now) {
    load_pending(c, now);
    if (!anchored) return v[oCNT] & 0xFFFF;
    const int64_t ticks = py_int(elapsed(now, anchor_cycle) * ticks_per_cycle(c));
    return static_cast<uint32_t>(cntin() + floor_mod(anchor_count - cntin() + ticks, period_ticks()));
}

// The first cycle after `cycle` at which the counter wraps from MOD to CNTIN.
bool Ftm::next_wrap_after(const Core& c, uint64_t cycle, uint64_t& wrap) const {
    const double per_cycle = ticks_per_cycle(c);
    if (!anchored || per_cycle == 0.0) return false;
    const int64_t ticks = py_int(elapsed(cycle, anchor_cycle) * per_cycle);
    const int64_t period = period_ticks();
    const int64_t to_wrap = period - floor_mod(anchor_count - cntin() + ticks, period);
    wrap = plus(anchor_cycle,
                py_int(-py_floordiv(static_cast<double>(-(ticks + to_wrap)), per_cycle)));
    return true;
}

// The first cycle at or after `cycle` at which the running counter steps.
bool Ftm::next_tick(const Core& c, uint64_t cycle, uint64_t& tick) const {
    const double per_cycle = ticks_per_cycle(c);
    if (!anchored || per_cycle == 0.0) return false;
    const double ticks = -py_floordiv(-elapsed(cycle, anchor_cycle) * per_cycle, 1.0);
    tick = plus(anchor_cycle, py_int(-py_floordiv(-ticks, per_cycle)));
    return true;
}

void Ftm::load_pending(const Core& c, uint64_t now) {
    for (size_t i = 0; i < pending.size();) {
        const Pending p = pending[i];
        uint64_t wrap = 0;
        const bool runs = next_wrap_after(c, p.written_at, wrap);
        if (runs && wrap > now) {
            ++i;
            continue;
        }
        pending.erase(pending.begin() + static_cast<long>(i));
        if (p.reg == oMOD && runs) {
            // the new modulus counts from CNTIN at the wrap
            anchor_cycle = wrap;
            anchor_count = cntin();
        }
        v[p.reg] = p.value;
    }
}

void Ftm::buffered(Core& c, uint32_t reg, uint32_t value) {
    const uint64_t now = c.now();
    load_pending(c, now);
    auto it = std::find_if(pending.begin(), pending.end(),
                           [reg](const Pending& p) { return p.reg == reg; });
    if (!anchored) {
        v[reg] = value;
        if (it != pending.end()) pending.erase(it);
    } else if (it != pending.end()) {
        it->value = value;
        it->written_at = now;
    } else {
        pending.push_back({reg, value, now});
    }
}

void Ftm::restart(Core& c, uint64_t now) {
    load_pending(c, now);
    const uint32_t clks = (v[oSC] & CLKS) >> shift_of(CLKS);
    if (clks == 1 || clks == 2) {
        // the count so far runs on from now (at the new rate, from the old anchor)
        const int64_t count0 = anchored ? count(c, now) : (v[oCNT] & 0xFFFF);
        anchored = true;
        anchor_cycle = now;
        anchor_count = count0;
    } else {
        if (anchored) v[oCNT] = count(c, now);
        anchored = false;
    }
    schedule_tof(c);
}

void Ftm::schedule_tof(Core& c) {
    if (tof_event) {
        c.cancel(tof_event);
        tof_event = 0;
    }
    uint64_t wrap = 0;
    if ((v[oSC] & TOIE) && next_wrap_after(c, c.now(), wrap)) tof_event = c.at(wrap, tof_kind);
}

void Ftm::on_tof(Core& c) {
    tof_event = 0;
    v[oSC] |= TOF;
    update_irq(c);
    schedule_tof(c);
}

void Ftm::update_irq(Core& c) {
    bool level = (v[oSC] & TOF) && (v[oSC] & TOIE);
    for (int ch = 0; ch < kChannels; ++ch) {
        const uint32_t sc = v[oCnSC[ch]];
        if ((sc & CHF) && (sc & CHIE)) level = true;
    }
    if (level != line) {
        line = level;
        c.set_irq(irq, level);
    }
}

int Ftm::mode(int ch) const {
    const uint32_t sc = v[oCnSC[ch]];
    if (v[oSC] & CPWMS) return kCenterPwm;
    const int ms = ((sc & MSB) ? 2 : 0) | ((sc & MSA) ? 1 : 0);
    const int els = ((sc & ELSB) ? 2 : 0) | ((sc & ELSA) ? 1 : 0);
    if (ms & 2) return els ? kEdgePwm : kDisabled;
    if (ms == 1) return els ? kOutputCompare : kDisabled;
    static constexpr int kCapture[4] = {kDisabled, kCaptureRising, kCaptureFalling, kCaptureBoth};
    return kCapture[els];
}

bool Ftm::period_s(Core& c, double& out) {
    const double hz = clock_hz(c);
    if (hz == 0.0) return false;
    load_pending(c, c.now());
    out = static_cast<double>(period_ticks()) / hz;
    return true;
}

bool Ftm::pulse_s(Core& c, int ch, double& out) {
    if (mode(ch) != kEdgePwm) return false;
    const double hz = clock_hz(c);
    if (hz == 0.0) return false;
    load_pending(c, c.now());
    const int64_t cnv = v[oCnV[ch]] & 0xFFFF;
    const int64_t ticks = cnv > mod() ? period_ticks() : std::max<int64_t>(0, cnv - cntin());
    out = static_cast<double>(ticks) / hz;
    return true;
}

bool Ftm::commanded_value(Core& c, int ch, uint32_t& out) {
    if (mode(ch) != kEdgePwm) return false;
    load_pending(c, c.now());
    out = v[oCnV[ch]];
    for (const Pending& p : pending) {
        if (p.reg == oCnV[ch]) out = p.value;
    }
    out &= 0xFFFF;
    return true;
}

void Ftm::edge(Core& c, int ch, bool rising) {
    const int m = mode(ch);
    if ((m != kCaptureRising && m != kCaptureFalling && m != kCaptureBoth) || !anchored) return;
    if ((m == kCaptureRising && !rising) || (m == kCaptureFalling && rising)) return;
    const uint64_t now = c.now();
    const uint32_t value = count(c, now);
    v[oCnV[ch]] = value;
    v[oCnSC[ch]] |= CHF;
    if (c.keep_records) captures.push_back({now, ch, value});
    update_irq(c);
}

uint32_t Ftm::read_reg(Core& c, uint32_t o) {
    if (o == oCNT) return count(c, c.now());
    if (o == oSC) {
        if (anchored && !(v[oSC] & TOIE)) {
            // TOF without TOIE is computed when read, not scheduled
            uint64_t wrap = 0;
            if (next_wrap_after(c, std::max(tof_clear, anchor_cycle), wrap) && wrap <= c.now()) {
                v[oSC] |= TOF;
            }
        }
        return v[oSC];
    }
    if (o == oSTATUS) {
        uint32_t status = 0;
        for (int ch = 0; ch < kChannels; ++ch) {
            if (v[oCnSC[ch]] & CHF) status |= CHnF[ch];
        }
        return status;
    }
    return v[o];
}

void Ftm::write_reg(Core& c, uint32_t o, uint32_t value) {
    for (int ch = 0; ch < kChannels; ++ch) {
        if (o == oCnSC[ch]) {
            const uint32_t chf = (value & CHF) ? (v[o] & CHF) : 0;   // CHF: cleared by writing 0
            v[o] = (value & CNSC_WRITABLE) | chf;
            update_irq(c);
            return;
        }
        if (o == oCnV[ch]) {
            buffered(c, o, value & 0xFFFF);
            return;
        }
    }
    const uint64_t now = c.now();
    if (o == oCNT) {
        v[oCNT] = cntin();
        if (anchored) {
            anchor_cycle = now;
            anchor_count = cntin();
        }
        schedule_tof(c);
    } else if (o == oSC) {
        const uint32_t old = v[oSC];
        const uint32_t tof = (value & TOF) ? (old & TOF) : 0;     // TOF: cleared by writing 0
        if (!tof) tof_clear = now;
        v[oSC] = (value & ~TOF) | tof;
        if ((old ^ value) & (CLKS | PS | TOIE)) restart(c, now);
        if (value & CPWMS) unmodelled.emplace_back("center-aligned PWM (CPWMS)");
        update_irq(c);
    } else if (o == oMOD) {
        buffered(c, oMOD, value & 0xFFFF);
        schedule_tof(c);
    } else if (o == oCNTIN) {
        v[oCNTIN] = value & 0xFFFF;
    } else if (o == oMODE) {
        v[oMODE] = value;
        if (value & FTMEN) unmodelled.emplace_back("MODE[FTMEN] = 1 (enhanced synchronisation)");
    } else if (o == oSTATUS) {
        for (int ch = 0; ch < kChannels; ++ch) {
            if (!(value & CHnF[ch])) v[oCnSC[ch]] &= ~CHF;
        }
        update_irq(c);
    } else if (o == oCOMBINE) {
        v[oCOMBINE] = value;
        if (value) unmodelled.emplace_back("combined / dual-edge channel modes");
    } else {
        v[o] = value;
    }
}

bool Ftm::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    if (!covered(L, address, size)) return false;
    const uint32_t offset = address - L.base;
    if (offset >= oCnSC[0] && offset < channels_end) load_pending(c, c.now());
    return read_regs(*this, c, address, size, out);
}

bool Ftm::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    return write_regs(*this, c, address, size, value);
}

// -- WDOG -------------------------------------------------------------------------------------
void Wdog::setup() {
    oSTCTRLH = L["STCTRLH"]; oSTCTRLL = L["STCTRLL"]; oTOVALH = L["TOVALH"]; oTOVALL = L["TOVALL"];
    oWINH = L["WINH"]; oWINL = L["WINL"]; oREFRESH = L["REFRESH"]; oUNLOCK = L["UNLOCK"];
    oTMROUTH = L["TMROUTH"]; oTMROUTL = L["TMROUTL"]; oRSTCNT = L["RSTCNT"]; oPRESC = L["PRESC"];
    WDOGEN = L["STCTRLH.WDOGEN"]; CLKSRC = L["STCTRLH.CLKSRC"];
    ALLOWUPDATE = L["STCTRLH.ALLOWUPDATE"]; INTFLG = L["STCTRLL.INTFLG"];
    PRESCVAL = L["PRESC.PRESCVAL"];
    ready = true;
}

void Wdog::reset() {
    v = L.reset;
    first_unlock = unlocked_at = first_refresh = -1;
    written.clear();
    disabled = false;
    disabled_instruction = disabled_cycle = 0;
    ignored.clear();
    log.clear();
    timeout_event = window_event = started = 0;
    window_after_unlock = false;
}

namespace {
uint64_t bus_cycles_to_core(uint32_t n, uint64_t start, double ratio) {
    return start + static_cast<uint64_t>(std::nearbyint(n * ratio));     // half to even
}

double bus_elapsed(int64_t since, uint64_t now, double ratio) {
    return static_cast<double>(static_cast<int64_t>(now) - since) / ratio;
}

double bus_ratio(const Core& c) { return c.core_hz() / c.bus_hz(); }
}  // namespace

uint32_t Wdog::prescale() const { return (v[oPRESC] & PRESCVAL) >> shift_of(PRESCVAL); }

double Wdog::timeout_s(double bus_hz) const {
    const uint64_t toval = (uint64_t{v[oTOVALH]} << 16) | v[oTOVALL];
    return static_cast<double>(toval * (prescale() + 1)) / clock_hz(bus_hz);
}

// At reset the core's clocks are not yet the chip's (its tree is set up after the devices
// reset), so Python gives the ones of the tree the chip resets to.
void Wdog::power_on(Core& c, double core_hz, double bus_hz) {
    window_after_unlock = false;
    window_event = c.at(bus_cycles_to_core(wct, 0, core_hz / bus_hz), Ev::WdogWindow);
    arm_timeout(c, bus_hz);
}

void Wdog::arm_timeout(Core& c, double bus_hz) {
    if (timeout_event) {
        c.cancel(timeout_event);
        timeout_event = 0;
    }
    if (!enabled()) return;
    started = c.now();
    timeout_event = c.at(c.cycles_after(timeout_s(bus_hz), started), Ev::WdogTimeout);
}

void Wdog::expired(Core& c) {
    timeout_event = 0;
    c.chip_reset("WDOG", format("watchdog timeout (%.3f s) while enabled", timeout_s(c.bus_hz())));
}

void Wdog::window(Core& c) {
    window_event = 0;
    if (!window_after_unlock) {
        if (first_unlock < 0 && unlocked_at < 0) {
            c.chip_reset("WDOG", format("no unlock sequence within the WCT (%u bus clocks) after "
                                        "reset", wct));
        }
    } else if (written.empty()) {
        c.chip_reset("WDOG", "no configuration register written within the WCT after the unlock");
    }
}

uint32_t Wdog::count(const Core& c) const {
    if (!enabled()) return 0;
    const double seconds = elapsed(c.now(), started) / c.core_hz();
    return static_cast<uint32_t>(py_int(seconds * clock_hz(c.bus_hz()) / (prescale() + 1)));
}

void Wdog::ignore(Core& c, uint32_t offset, uint32_t value, std::string why) {
    ignored.push_back({c.instructions_now(), offset, value, std::move(why)});
}

void Wdog::write_once(Core& c, uint32_t o, uint32_t value) {
    const uint64_t now = c.now();
    if (unlocked_at < 0) {
        ignore(c, o, value, "not unlocked");
    } else if (bus_elapsed(unlocked_at, now, bus_ratio(c)) > wct) {
        ignore(c, o, value, "WCT after the unlock has passed");
    } else if (std::find(written.begin(), written.end(), o) != written.end()) {
        ignore(c, o, value, "already written once since the unlock");
    } else {
        written.push_back(o);
        const bool was_enabled = enabled();
        v[o] = value;
        if (o == oSTCTRLH && was_enabled && !enabled() && !disabled) {
            disabled = true;
            disabled_instruction = c.instructions_now();
            disabled_cycle = now;
        }
        arm_timeout(c, c.bus_hz());
    }
}

uint32_t Wdog::read_reg(Core& c, uint32_t o) {
    if (o == oTMROUTH) return (count(c) >> 16) & 0xFFFF;
    if (o == oTMROUTL) return count(c) & 0xFFFF;
    return v[o];
}

void Wdog::write_reg(Core& c, uint32_t o, uint32_t value) {
    const uint64_t now = c.now();
    if (o == oUNLOCK) {
        if (!(v[oSTCTRLH] & ALLOWUPDATE)) {
            ignore(c, o, value, "ALLOWUPDATE is clear");
        } else if (value == unlock[0]) {
            first_unlock = static_cast<int64_t>(now);
        } else if (value == unlock[1] && first_unlock >= 0) {
            const double apart = bus_elapsed(first_unlock, now, bus_ratio(c));
            if (apart > gap) {
                c.chip_reset("WDOG", format("unlock words %.0f bus clocks apart (at most %u)",
                                            apart, gap));
                return;
            }
            first_unlock = -1;
            unlocked_at = static_cast<int64_t>(now);
            written.clear();
            if (window_event) c.cancel(window_event);
            window_after_unlock = true;
            window_event = c.at(bus_cycles_to_core(wct, now, bus_ratio(c)), Ev::WdogWindow);
        } else {
            c.chip_reset("WDOG", format("invalid unlock sequence: 0x%04X written to WDOG_UNLOCK",
                                        value));
        }
    } else if (o == oREFRESH) {
        if (value == refresh[0]) {
            first_refresh = static_cast<int64_t>(now);
        } else if (value == refresh[1] && first_refresh >= 0 &&
                   bus_elapsed(first_refresh, now, bus_ratio(c)) <= gap) {
            first_refresh = -1;
            arm_timeout(c, c.bus_hz());
        } else {
            c.chip_reset("WDOG", format("invalid refresh sequence (0x%04X)", value));
        }
    } else if (o == oSTCTRLL) {
        if (value & INTFLG) v[oSTCTRLL] &= ~INTFLG;             // write 1 to clear
    } else if (o == oRSTCNT) {
        v[oRSTCNT] &= ~value;                                   // write 1 to clear
    } else if (o == oSTCTRLH || o == oTOVALH || o == oTOVALL || o == oWINH || o == oWINL ||
               o == oPRESC) {
        write_once(c, o, value);
    } else if (o != oTMROUTH && o != oTMROUTL) {
        v[o] = value;
    }
}

bool Wdog::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    return read_regs(*this, c, address, size, out);
}

bool Wdog::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    if (!covered(L, address, size)) return false;
    const uint32_t reg = static_cast<uint32_t>(L.reg_at[address - L.base]);
    if (c.keep_records) log.push_back({c.instructions_now(), c.now(), reg, value});
    if (reg == oUNLOCK && size != 2) {
        c.chip_reset("WDOG", format("%u-bit write to WDOG_UNLOCK: the sequence is two 16-bit "
                                    "writes", 8 * size));
        return true;
    }
    return write_regs(*this, c, address, size, value);
}

}  // namespace hqsim::mk64

// -- FTFE -------------------------------------------------------------------------------------
namespace hqsim::mk64 {

namespace {
constexpr uint8_t kProgramPhrase = 0x07, kEraseSector = 0x09;
constexpr uint32_t kPhrase = 8;
// Program Phrase: the phrase's byte k (address + k) is written to FCCOB kPhraseOrder[k]
// (the FCCOB group is big-endian within each longword: FCCOB4..7 hold bytes 3..0, FCCOB8..B
// bytes 7..4), so a longword store to FCCOB7's address or FCCOBB's lands in address order.
constexpr int kPhraseOrder[kPhrase] = {7, 6, 5, 4, 11, 10, 9, 8};
}  // namespace

void Ftfe::setup() {
    oFSTAT = L["FSTAT"]; oFCNFG = L["FCNFG"]; oFSEC = L["FSEC"]; oFOPT = L["FOPT"];
    oFPROT3 = L["FPROT3"]; oFPROT2 = L["FPROT2"]; oFPROT1 = L["FPROT1"]; oFPROT0 = L["FPROT0"];
    oFEPROT = L["FEPROT"]; oFDPROT = L["FDPROT"];
    static const char* const names[12] = {"FCCOB0", "FCCOB1", "FCCOB2", "FCCOB3", "FCCOB4",
                                          "FCCOB5", "FCCOB6", "FCCOB7", "FCCOB8", "FCCOB9",
                                          "FCCOBA", "FCCOBB"};
    for (int i = 0; i < 12; ++i) oFCCOB[i] = L[names[i]];
    CCIF = L["FSTAT.CCIF"]; RDCOLERR = L["FSTAT.RDCOLERR"]; ACCERR = L["FSTAT.ACCERR"];
    FPVIOL = L["FSTAT.FPVIOL"]; MGSTAT0 = L["FSTAT.MGSTAT0"];
    FCNFG_WRITABLE = L["FCNFG.CCIE"] | L["FCNFG.RDCOLLIE"] | L["FCNFG.ERSAREQ"] |
                     L["FCNFG.ERSSUSP"];
    ready = true;
}

// A reset abandons a running command (its event went with the core's queue): the cells it
// was changing keep what they held. The protection and security bytes load from the flash
// configuration field (backdoor key 0-7, FPROT3..0 8-11, FSEC, FOPT, FEPROT, FDPROT 12-15).
void Ftfe::reset(Core& c) {
    v.assign(L.reset.begin(), L.reset.end());
    busy = false;
    done_event = 0;
    command = 0;
    address = 0;
    log.clear();
    notes.clear();
    uint8_t field[16];
    if (!c.mem_read(config, field, sizeof field)) std::fill(field, field + 16, uint8_t{0xFF});
    v[oFPROT3] = field[8]; v[oFPROT2] = field[9]; v[oFPROT1] = field[10]; v[oFPROT0] = field[11];
    v[oFSEC] = field[12]; v[oFOPT] = field[13]; v[oFEPROT] = field[14]; v[oFDPROT] = field[15];
    v[oFSTAT] = static_cast<uint8_t>(CCIF);          // the reset sequence has completed
}

// FPROT: one bit per 1/32 of the program flash, 0 = protected; FPROT0 holds regions 31..24.
bool Ftfe::protected_range(uint32_t lo, uint32_t n) const {
    const uint32_t prot = uint32_t{v[oFPROT0]} << 24 | uint32_t{v[oFPROT1]} << 16 |
                          uint32_t{v[oFPROT2]} << 8 | v[oFPROT3];
    const uint32_t region = flash_size / 32;
    for (uint32_t r = lo / region; r <= (lo + n - 1) / region; ++r) {
        if (!(prot >> r & 1u)) return true;
    }
    return false;
}

// The command check the module makes at launch: ACCERR for a command not modelled, an
// address outside the program flash or not aligned (a phrase: 8 bytes; Erase Flash Sector:
// 16 bytes, anywhere in the sector); FPVIOL for a protected target.
uint8_t Ftfe::launch_check(uint8_t code, uint32_t at) const {
    if (code == kEraseSector) {
        if ((at & 0xFu) || at >= flash_size) return static_cast<uint8_t>(ACCERR);
        if (protected_range(at & ~(sector - 1), sector)) return static_cast<uint8_t>(FPVIOL);
        return 0;
    }
    if (code == kProgramPhrase) {
        if ((at & (kPhrase - 1)) || at >= flash_size) return static_cast<uint8_t>(ACCERR);
        if (protected_range(at, kPhrase)) return static_cast<uint8_t>(FPVIOL);
        return 0;
    }
    return static_cast<uint8_t>(ACCERR);
}

void Ftfe::launch(Core& c) {
    command = v[oFCCOB[0]];
    address = uint32_t{v[oFCCOB[1]]} << 16 | uint32_t{v[oFCCOB[2]]} << 8 | v[oFCCOB[3]];
    for (uint32_t k = 0; k < kPhrase; ++k) data[k] = v[oFCCOB[kPhraseOrder[k]]];
    started = c.now();
    v[oFSTAT] &= static_cast<uint8_t>(~MGSTAT0);
    const uint8_t error = launch_check(command, address);
    if (error) {
        v[oFSTAT] |= error;
        if (c.keep_records) log.push_back({started, started, command, address, v[oFSTAT]});
        return;
    }
    busy = true;
    v[oFSTAT] &= static_cast<uint8_t>(~CCIF);
    const double seconds = command == kEraseSector ? erase_sector_s : program_phrase_s;
    done_event = c.at(c.cycles_after(seconds, started), Ev::FtfeDone);
    if (c.keep_records) log.push_back({started, 0, command, address, 0});
}

// The command's effect, when it completes. Programming can only clear bits (the cells keep
// old AND new); a phrase that does not then read as asked fails the module's verify
// (MGSTAT0). The manual forbids programming a phrase twice between erases: noted.
void Ftfe::complete(Core& c) {
    done_event = 0;
    busy = false;
    if (command == kEraseSector) {
        const std::vector<uint8_t> erased(sector, 0xFF);
        c.mem_write(address & ~(sector - 1), erased.data(), sector);
    } else {
        uint8_t cells[kPhrase];
        c.mem_read(address, cells, kPhrase);
        bool blank = true, verified = true;
        for (uint32_t k = 0; k < kPhrase; ++k) {
            blank = blank && cells[k] == 0xFF;
            cells[k] &= data[k];
            verified = verified && cells[k] == data[k];
        }
        c.mem_write(address, cells, kPhrase);
        if (!blank) {
            notes.emplace_back(c.now(), format("Program Phrase at 0x%06X: the phrase was not "
                                               "erased (the manual allows one program per erase)",
                                               address));
        }
        if (!verified) v[oFSTAT] |= static_cast<uint8_t>(MGSTAT0);
    }
    ++changes;
    v[oFSTAT] |= static_cast<uint8_t>(CCIF);
    if (c.keep_records && !log.empty() && log.back().end == 0) {
        log.back().end = c.now();
        log.back().fstat = v[oFSTAT];
    }
}

std::string Ftfe::collision(uint32_t pc) {
    v[oFSTAT] |= static_cast<uint8_t>(RDCOLERR);
    return format("instruction fetch from program flash at 0x%08X while a flash command runs "
                  "(0x%02X at 0x%06X, launched at cycle %llu, CCIF = 0): ",
                  pc, command, address, static_cast<unsigned long long>(started)) +
           "a read collision (FTFE_FSTAT.RDCOLERR; on the chip the fetched bits are undefined). "
           "Code that launches a command and waits for CCIF must run from RAM with interrupts "
           "masked";
}

uint32_t Ftfe::read_reg(Core&, uint32_t o) { return v[o]; }

void Ftfe::write_reg(Core& c, uint32_t o, uint8_t value) {
    if (o == oFSTAT) {
        const uint8_t before = v[oFSTAT];
        v[oFSTAT] &= static_cast<uint8_t>(~(value & (RDCOLERR | ACCERR | FPVIOL)));
        if ((value & CCIF) && !busy) {
            if (before & (ACCERR | FPVIOL)) {
                notes.emplace_back(c.now(), "command launched with ACCERR or FPVIOL set: not "
                                            "launched (clear them first)");
            } else {
                launch(c);
            }
        }
    } else if (o == oFCNFG) {
        v[o] = static_cast<uint8_t>((v[o] & ~FCNFG_WRITABLE) | (value & FCNFG_WRITABLE));
        if (value & FCNFG_WRITABLE) {
            notes.emplace_back(c.now(), format("FCNFG = 0x%02X: the command-complete and "
                                               "read-collision interrupts and erase suspend are "
                                               "not modelled", value));
        }
    } else if (o == oFPROT3 || o == oFPROT2 || o == oFPROT1 || o == oFPROT0 || o == oFEPROT ||
               o == oFDPROT) {
        v[o] &= value;                 // in normal mode protection can only be added
    } else if (o != oFSEC && o != oFOPT) {
        if (busy) {
            notes.emplace_back(c.now(), format("FCCOB write (offset 0x%X) while a command runs: "
                                               "ignored", o));
        } else {
            v[o] = value;
        }
    }
}

bool Ftfe::read(Core& c, uint32_t address_, unsigned size, uint64_t& out) {
    return read_regs(*this, c, address_, size, out);
}

bool Ftfe::write(Core& c, uint32_t address_, unsigned size, uint64_t value) {
    return write_regs(*this, c, address_, size, value);
}

}  // namespace hqsim::mk64
