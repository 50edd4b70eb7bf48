// USB0's registers and the host's bulk IN transfers, native (mk64_core.hpp's Usb): the image's
// USB interrupt reads and clears ISTAT, STAT and the endpoint registers a few times a loop, and
// the host (sim/chip/usb_host.py) polls the bulk IN endpoint every 1 ms frame, which the SIE
// NAKs while the firmware has nothing queued and answers with the loop's telemetry otherwise.
// All of that stays here; Python (usb.py, usb_host.py) is called when the host has other work
// or a poll's answer is anything else. The rules are those of the Python models, step for step
// (the reference, Usb::native off): the same events at the same cycles, scheduled in the same
// order, the same bytes.
#include <algorithm>

#include "chip/mk64_core.hpp"

namespace hqsim::mk64 {

namespace {
// usb_host.py's bus timing (USB 2.0: full speed, the packets' bits) and timers.
constexpr double kBitRateHz = 12e6;
constexpr double kFrameS = 1e-3;
constexpr double kTokenBits = 8 + 8 + 11 + 5 + 3;
constexpr double kHandshakeBits = 8 + 8 + 3;
constexpr double kDataOverheadBits = 8 + 8 + 16 + 3;
constexpr double kMaxPacketBits = 8 * 64;
constexpr double kIdleToSleepS = 3e-3;          // usb.py's IDLE_TO_SLEEP_S
// usb.py's BD bits and fields, and the IN token's PID (USB 2.0, table 8-1)
constexpr uint32_t kBdOwn = 0x80, kBdData1 = 0x40, kBdKeep = 0x20, kBdNinc = 0x10,
                   kBdStall = 0x04;
constexpr uint32_t kBdBcShift = 16, kBdBcMask = 0x3FF;
constexpr uint32_t kPidIn = 0x9;
constexpr uint32_t kBdBytes = 8;
constexpr int kEndpoints = 16;
}  // namespace

void Usb::setup() {
    oISTAT = L["ISTAT"]; oINTEN = L["INTEN"]; oERRSTAT = L["ERRSTAT"]; oERREN = L["ERREN"];
    oSTAT = L["STAT"]; oCTL = L["CTL"]; oADDR = L["ADDR"]; oBDTPAGE1 = L["BDTPAGE1"];
    oBDTPAGE2 = L["BDTPAGE2"]; oBDTPAGE3 = L["BDTPAGE3"]; oFRMNUML = L["FRMNUML"];
    oFRMNUMH = L["FRMNUMH"]; oENDPT0 = L["ENDPT0"]; oUSBCTRL = L["USBCTRL"];
    oOBSERVE = L["OBSERVE"]; oCONTROL = L["CONTROL"]; oUSBTRC0 = L["USBTRC0"];
    oPERID = L["PERID"]; oIDCOMP = L["IDCOMP"]; oREV = L["REV"]; oADDINFO = L["ADDINFO"];
    TOKDNE = L["ISTAT.TOKDNE"]; SOFTOK = L["ISTAT.SOFTOK"]; SLEEP = L["ISTAT.SLEEP"];
    CTL_SE0 = L["CTL.SE0"]; CTL_JSTATE = L["CTL.JSTATE"]; CTL_USBENSOFEN = L["CTL.USBENSOFEN"];
    CTL_BUSY = L["CTL.TXSUSPENDTOKENBUSY"]; DPPULLUP = L["CONTROL.DPPULLUPNONOTG"];
    SUSP = L["USBCTRL.SUSP"]; PDE = L["USBCTRL.PDE"]; DPPU = L["OBSERVE.DPPU"];
    DPPD = L["OBSERVE.DPPD"]; DMPD = L["OBSERVE.DMPD"]; RESUME_INT = L["USBTRC0.USB_RESUME_INT"];
    USBRESMEN = L["USBTRC0.USBRESMEN"]; EPTXEN = L["ENDPT0.EPTXEN"];
    EPSTALL = L["ENDPT0.EPSTALL"]; BDTBA = L["BDTPAGE1.BDTBA"];
    ready = true;
}

void Usb::reset_registers() {
    v.assign(L.span, 0);
    for (uint32_t at = 0; at < L.span; ++at) {
        if (L.reg_at[at] == static_cast<int>(at)) v[at] = static_cast<uint8_t>(L.reset[at]);
    }
}

void Usb::reset(Core& c) {
    reset_registers();
    for (auto& e : odd) e[0] = e[1] = 0;
    frame = 0;
    in_reset = false;
    if (sleep_event) c.cancel(sleep_event);
    sleep_event = 0;
    host = Host{};
}

bool Usb::attached(const Core& c) const {
    return c.clocked[Core::kUsb0] && (v[oCONTROL] & DPPULLUP);
}

uint32_t Usb::bdt_base() const {
    return uint32_t{v[oBDTPAGE3]} << 24 | uint32_t{v[oBDTPAGE2]} << 16 |
           uint32_t{v[oBDTPAGE1]} << 8;
}

void Usb::update_irq(Core& c) {
    c.set_irq(irq, (v[oISTAT] & v[oINTEN]) || (v[oUSBTRC0] & RESUME_INT));
}

// usb.py's _idle_watch: ISTAT.SLEEP 3 ms after the last bus activity while enabled.
void Usb::idle_watch(Core& c) {
    if (sleep_event) c.cancel(sleep_event);
    sleep_event = 0;
    if (attached(c) && enabled() && !in_reset) {
        sleep_event = c.at(c.cycles_after(kIdleToSleepS, c.now()), Ev::UsbSleep);
    }
}

void Usb::bus_activity(Core& c) {
    if (suspended() && (v[oUSBTRC0] & USBRESMEN)) {
        v[oUSBTRC0] |= RESUME_INT;
        update_irq(c);
    }
    idle_watch(c);
}

void Usb::sof(Core& c, uint16_t number) {
    frame = number & 0x7FF;
    bus_activity(c);
    if (attached(c) && enabled() && !suspended()) flag(c, SOFTOK);
}

// usb_host.py's frame: the next one scheduled first, the SOF, then when this frame's
// transactions may start and must end.
void Usb::host_frame(Core& c) {
    const uint64_t now = c.now();
    const uint64_t due = std::max(c.cycles_after(kFrameS, now), now);
    host.frame_event = c.at(due, Ev::UsbFrame);
    host.frame = (host.frame + 1) & 0x7FF;
    sof(c, host.frame);
    host.next_sof = due;
    host.sof_end = c.cycles_after(kTokenBits / kBitRateHz, now);
}

// What the SIE would answer the host's bulk IN token now, where usb.py's token() would change
// nothing but the idle timer on the way and its DMA stays in RAM the MPU grants: the device
// answers, the endpoint sends and is not stalled, its current BD is readable; then a NAK (the
// BD is not the SIE's, or CTL.TXSUSPENDTOKENBUSY holds every token but SETUP) or the BD's data
// (readable, and the BD writable for its write-back unless KEEP). Anything else is Python's.
Usb::Answer Usb::in_answer(Core& c, uint32_t& bd_at, uint32_t& word, uint32_t& buffer) const {
    if (!attached(c) || !enabled() || suspended() || !clock_ok || in_reset) return kPython;
    const int ep = host.endpoint;
    if (host.address != (v[oADDR] & 0x7F) || ep >= kEndpoints) return kPython;
    const uint8_t ctl = v[oENDPT0 + 4 * static_cast<uint32_t>(ep)];
    if (!(ctl & EPTXEN) || (ctl & EPSTALL)) return kPython;
    bd_at = bdt_base() | static_cast<uint32_t>(ep) << 5 | 1u << 4 | uint32_t{odd[ep][1]} << 3;
    if (!dma_reads_ram || !in_ram(bd_at, kBdBytes)) return kPython;
    if (!c.read32(bd_at, word) || !c.read32(bd_at + 4, buffer)) return kPython;
    if (!(word & kBdOwn) || (v[oCTL] & CTL_BUSY)) return kNak;
    if (word & kBdStall) return kPython;
    const uint32_t bc = (word >> kBdBcShift) & kBdBcMask;
    const uint32_t span = bc == 0 ? 0 : (word & kBdNinc) ? 1 : bc;
    if (span && !in_ram(buffer, span)) return kPython;
    if (!(word & kBdKeep) && !(dma_writes_ram && in_ram(bd_at, 4))) return kPython;
    return kData;
}

// usb_host.py's _pump with only the bulk IN poll to make (the gate Python opened), and its
// _transact for it: true when done here, false when Python must pump.
bool Usb::pump(Core& c) {
    if (!native || !host.gate) return false;
    if (host.in_flight) return true;
    if (v[oISTAT] & TOKDNE) {
        host.waiting = true;
        return true;
    }
    if (host.nak_frame == host.frame) return true;
    uint32_t bd_at = 0, word = 0, buffer = 0;
    const Answer answer = in_answer(c, bd_at, word, buffer);
    if (answer == kPython) return false;
    const uint64_t now = std::max(c.now(), host.sof_end);
    const double worst = kTokenBits + kDataOverheadBits + kMaxPacketBits + kHandshakeBits;
    if (c.cycles_after(worst / kBitRateHz, now) >= host.next_sof) return true;   // frame full
    bus_activity(c);                        // the token
    double bits = kTokenBits + kHandshakeBits;
    host.flight_data = answer == kData;
    if (host.flight_data) {
        send_in(c, bd_at, word, buffer);
        bits += kDataOverheadBits + 8.0 * static_cast<double>(host.flight_bytes.size());
    }
    host.in_flight = true;
    host.flight_generation = host.generation;
    c.at(c.cycles_after(bits / kBitRateHz, now), Ev::UsbFinish);
    return true;
}

// The SIE's ACK: the BD's bytes (NINC: its first, BC times) with its DATA0/1.
void Usb::send_in(Core& c, uint32_t bd_at, uint32_t word, uint32_t buffer) {
    const uint32_t bc = (word >> kBdBcShift) & kBdBcMask;
    host.flight_bd = bd_at;
    host.flight_word = word;
    host.flight_ep = host.endpoint;
    host.flight_odd = odd[host.endpoint][1];
    host.flight_bytes.assign(bc, '\0');
    if (bc && (word & kBdNinc)) {
        char b = 0;
        c.mem_read(buffer, &b, 1);
        host.flight_bytes.assign(bc, b);
    } else if (bc) {
        c.mem_read(buffer, host.flight_bytes.data(), bc);
    }
}

// usb.py's complete() for it: the BD written back (unless KEEP), the ODD pointer flipped,
// STAT and TOKDNE.
void Usb::complete_in(Core& c) {
    const uint32_t word = host.flight_word;
    const uint32_t n = static_cast<uint32_t>(host.flight_bytes.size());
    if (!(word & kBdKeep)) {
        const uint32_t back = (word & kBdData1) | kPidIn << 2 | n << kBdBcShift;
        const uint8_t b[4] = {static_cast<uint8_t>(back), static_cast<uint8_t>(back >> 8),
                              static_cast<uint8_t>(back >> 16), static_cast<uint8_t>(back >> 24)};
        c.mem_write(host.flight_bd, b, 4);
    }
    const uint32_t ep = host.flight_ep, odd_was = host.flight_odd;
    odd[ep][1] = static_cast<uint8_t>(odd_was ^ 1);
    v[oSTAT] = static_cast<uint8_t>(ep << 4 | 1u << 3 | odd_was << 2);
    flag(c, TOKDNE);
}

// A poll made here has crossed the bus (usb_host.py's _finish for it): what Python must do
// then (Core::PyCall), if anything. A data packet whose BD the MPU no longer lets the USB
// controller write back (it changed meanwhile) has Python check the write-back (usb.py's
// fault, or the rest here: end_data).
int Usb::finish(Core& c) {
    host.in_flight = false;
    if (host.flight_data) {
        if (!(host.flight_word & kBdKeep) && !(dma_writes_ram && in_ram(host.flight_bd, 4))) {
            return Core::kUsbWriteBack;
        }
        return end_data(c);
    }
    if (host.job && host.generation == host.flight_generation) {
        host.in_nak = true;
        host.in_nak_cycle = static_cast<int64_t>(c.now());
        host.nak_frame = host.frame;
    }
    return pump(c) ? Core::kNoCall : Core::kUsbPump;
}

int Usb::end_data(Core& c) {
    complete_in(c);
    if (host.job && host.generation == host.flight_generation) {
        host.in_nak = false;
        if (static_cast<bool>(host.flight_word & kBdData1) != host.toggle) {
            ++host.toggle_errors;           // ACKed and dropped: the device sends it again
        } else {
            host.silences = 0;
            took_packet();
        }
    }
    return pump(c) ? Core::kNoCall : Core::kUsbPump;
}

// usb_host.py's bulk IN job takes a packet: the bytes, the next DATA0/1, a short packet ends
// the frame's polls, and a reader that stopped reading ends the job.
void Usb::took_packet() {
    host.received += host.flight_bytes;
    host.toggle = !host.toggle;
    if (host.flight_bytes.size() < host.max_packet) host.nak_frame = host.frame;
    if (!host.reading) {
        host.job = false;
        host.gate = false;
    }
}

void Usb::pump_soon(Core& c) {
    host.gate = false;
    c.at(c.now(), Ev::UsbPump);
}

void Usb::tokens_free(Core& c) {
    if (!host.waiting) return;
    host.waiting = false;
    c.at(c.now(), Ev::UsbPump);
}

// Byte accesses to a register, while native; the rest (the registers whose writes attach,
// detach, reset the module or restart the idle timer, wider accesses, holes) is Python's.
bool Usb::reg_offset(uint32_t address, unsigned size, uint32_t& o) const {
    if (!native || size != 1 || address < L.base) return false;
    o = address - L.base;
    return o < L.span && L.reg_at[o] == static_cast<int>(o);
}

bool Usb::read(Core& c, uint32_t address, unsigned size, uint64_t& out) {
    uint32_t o = 0;
    if (!reg_offset(address, size, o)) return false;
    if (o == oCTL) {
        out = v[o] | (attached(c) ? (in_reset ? CTL_SE0 : CTL_JSTATE) : 0);
    } else if (o == oOBSERVE) {
        const bool pde = v[oUSBCTRL] & PDE;
        out = ((v[oCONTROL] & DPPULLUP) ? DPPU : 0) | (pde ? (DPPD | DMPD) : 0);
    } else if (o == oFRMNUML) {
        out = frame & 0xFF;
    } else if (o == oFRMNUMH) {
        out = (frame >> 8) & 0x7;
    } else {
        out = v[o];
    }
    return true;
}

bool Usb::write(Core& c, uint32_t address, unsigned size, uint64_t value) {
    uint32_t o = 0;
    if (!reg_offset(address, size, o)) return false;
    if (o == oCTL || o == oCONTROL || o == oUSBCTRL || o == oUSBTRC0) return false;
    const uint8_t b = static_cast<uint8_t>(value);
    if (o == oISTAT) {
        const bool was_busy = v[o] & TOKDNE;
        v[o] &= static_cast<uint8_t>(~b);
        update_irq(c);
        if (was_busy && !(v[o] & TOKDNE)) tokens_free(c);
    } else if (o == oERRSTAT) {
        v[o] &= static_cast<uint8_t>(~b);
    } else if (o == oINTEN) {
        v[o] = b;
        update_irq(c);
    } else if (o == oBDTPAGE1) {
        v[o] = b & BDTBA;
    } else if (o == oPERID || o == oIDCOMP || o == oREV || o == oADDINFO || o == oSTAT ||
               o == oFRMNUML || o == oFRMNUMH || o == oOBSERVE) {
        // read only (PERID, IDCOMP, REV, ADDINFO, STAT, FRMNUM, OBSERVE): the write is ignored
    } else {
        v[o] = b;
    }
    return true;
}

}  // namespace hqsim::mk64
