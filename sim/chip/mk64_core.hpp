// The emulated MK64FX512's hot path (sim/chip, docs/teensy35-emulator.md): what runs at every
// translated block, every access to the busy peripherals and every interrupt, in C++ so that a
// flight loop costs no Python call per block or register access.
//
// * The unicorn library is not linked: its entry points are taken at run time from the library
//   the Python binding loaded (Uc below), and the hooks are installed as C functions.
// * Time base: cycles and instructions per translated block from a table the Python decoder
//   fills (sim/chip/timing.py states the cycle model; nothing here changes it), exact to the
//   instruction at every peripheral access (the PC is synced there).
// * One event queue for every device, Python's included (a Python event stops the run and
//   Python runs it), so events run in one (cycle, order) sequence whatever side owns them.
// * The NVIC's state, exception entry and return, WFI sleep, and the models of the devices the
//   loop uses all the time: DWT_CYCCNT, SysTick, UART0, I2C0 with the MPU6050 on it, FTM0 and
//   FTM3, and the watchdog; and the flash module (FTFE), whose status a parameter save polls
//   hundreds of thousands of times. Their Python classes are views onto these (one model each).
// * A reset the chip would perform (the watchdog's) stops the run with its cause (kReset);
//   Python raises it as ChipReset.
// * Whatever needs Python (a block not decoded yet, the FPU-enable check until the first FPU
//   instruction, an access to a device modelled in Python, a Python event, a breakpoint, a
//   fault) either calls a C function pointer the Python side made with ctypes (which takes the
//   GIL) or stops the run with a code saying why.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "chip/thumb.hpp"

namespace hq {
class Mpu6050Emulator;
}

namespace hqsim::mk64 {

using u128 = unsigned __int128;

// The unicorn entry points used here, as the library exports them (unicorn.h, 2.1).
struct Uc {
    void* handle = nullptr;
    int (*emu_start)(void*, uint64_t, uint64_t, uint64_t, size_t) = nullptr;
    int (*emu_stop)(void*) = nullptr;
    int (*reg_read)(void*, int, void*) = nullptr;
    int (*reg_write)(void*, int, const void*) = nullptr;
    int (*reg_write2)(void*, int, const void*, size_t*) = nullptr;
    int (*reg_read_batch)(void*, const int*, void**, int) = nullptr;
    int (*reg_write_batch)(void*, const int*, void* const*, int) = nullptr;
    int (*mem_read)(void*, uint64_t, void*, uint64_t) = nullptr;
    int (*mem_write)(void*, uint64_t, const void*, uint64_t) = nullptr;
    int (*hook_add)(void*, size_t*, int, void*, void*, uint64_t, uint64_t, ...) = nullptr;
    int (*mmio_map)(void*, uint64_t, uint64_t, void*, void*, void*, void*) = nullptr;
};

// The register numbers of the core's own CPU (the engine, sim/chip/thumb.hpp), used in place
// of unicorn's when the engine runs the instructions: R0-R15, the special registers, D0-D15
// and S0-S31.
enum EngineReg : int {
    kEngSp = 13, kEngLr = 14, kEngPc = 15, kEngXpsr = 16, kEngEpsr, kEngControl, kEngFpscr,
    kEngPrimask, kEngBasepri, kEngFaultmask, kEngMsp, kEngPsp, kEngApsr, kEngIpsr,
    kEngD0 = 32, kEngS0 = 64, kEngEnd = 96
};

// unicorn's register numbers for the registers the core reads and writes (from arm_const).
struct Regs {
    int r0, r1, r2, r3, r12, lr, pc, sp, xpsr, epsr, control, fpscr, primask, basepri, faultmask;
    int d[8];      // D0-D7: S0-S15 in pairs (S2n the low word), read and written whole
};

// Callbacks into Python (ctypes function pointers; they take the GIL themselves).
struct PyCallbacks {
    int (*decode)(uint64_t address, uint32_t size) = nullptr;        // 0: decoded
    int (*fpu_check)(uint64_t address) = nullptr;                    // 0: stop (a NOCP fault)
    uint64_t (*read)(uint64_t address, uint32_t size) = nullptr;
    void (*write)(uint64_t address, uint32_t size, uint64_t value) = nullptr;
};

// One translated block's costs, from the Python decoder.
struct Block {
    enum : uint32_t { kMaskOp = 1, kIsb = 2, kVfp = 4, kWfi = 8 };
    uint32_t start = 0, size = 0, n = 0, flags = 0;
    uint64_t cycles = 0;
    std::vector<uint32_t> addrs;     // decoded instructions' addresses
    std::vector<uint32_t> cum;       // cycles before each instruction (undecoded included)
    uint32_t index_of(uint32_t pc) const {
        pc &= ~1u;
        for (uint32_t i = 0; i < addrs.size(); ++i) {
            if (addrs[i] == pc) return i;
        }
        return n;
    }
    uint64_t cycles_before(uint32_t pc) const {
        const uint32_t i = index_of(pc);
        return i < addrs.size() ? cum[i] : cycles;
    }
};

enum class Ev : uint8_t {
    Python, TimeLimit, SysTick, UartTx, UartRx, UartIdle, I2cByte, I2cFree, Ftm0Tof, Ftm3Tof,
    WdogTimeout, WdogWindow, FtfeDone, UsbFrame, UsbPump, UsbFinish, UsbSleep, PinEdge
};

// Why run() returned.
enum Run : int {
    kPyEvent = 1, kStop, kBudget, kTime, kSleepForever, kPyError, kUcError, kFault, kBkpt,
    kIntrFault, kReset, kStopAt,
    kCpuStop,       // the engine stopped for its owner's judgement (Core::cpu_stop_)
    kDrained        // what the run waited to leave the board has left (Core::drain_)
};

// What the engine stopped for when the run returns kCpuStop: a fault of the program (a bus
// fault, an unaligned access, a division by zero trapped, an interworking branch to ARM
// state), the first FP instruction (no_fpu: Python judges the CPACR grant), an ISB while
// watched (isb).
struct CpuStop {
    std::string reason, detail;
    uint32_t pc = 0, address = 0;
};

// A fault found natively (exception entry/return); Python raises it.
struct FaultInfo {
    std::string kind, message;
    uint32_t pc = 0, address = 0;
    bool has_address = false;
};

class Core;

constexpr int kExceptions = 16 + 86;        // the MK64F12's: 16 system, 86 IRQs
constexpr uint32_t kIntrUndef = 1;          // QEMU's EXCP_UDEF: an undefined instruction
std::string hex8(uint32_t v);               // "0x%08X"

// The engine's bus when it is the CPU: every access outside flash and SRAM goes to the core
// (Core::engine_access, mk64_engine.cpp).
class EngineBus : public thumb::Bus {
public:
    explicit EngineBus(Core& core) : core_(core) {}
    bool read(uint32_t address, unsigned size, uint32_t& value) override;
    bool write(uint32_t address, unsigned size, uint32_t value) override;

private:
    Core& core_;
};

// Python's float floor division (a // b), step for step as CPython does it: the models' timing
// rules were written with it, and a cycle computed differently would move an event.
double py_floordiv(double a, double b);

// DWT_CTRL/CYCCNT: counts core cycles while DEMCR.TRCENA and CTRL.CYCCNTENA are set.
struct Dwt {
    uint32_t ctrl_address = 0, cyccnt_address = 0, ctrl_reset = 0;
    uint32_t ctrl = 0, base_value = 0;
    int64_t since = -1;            // core cycle at which base_value held; -1: stopped
    bool trcena = false;
    void reset() { ctrl = ctrl_reset; base_value = 0; since = -1; trcena = false; }
    bool running() const { return (ctrl & 1) && trcena; }
    uint32_t cyccnt(uint64_t now) const {
        return since < 0 ? base_value
                         : static_cast<uint32_t>(base_value + (now - static_cast<uint64_t>(since)));
    }
    void sync(uint64_t now) {
        base_value = cyccnt(now);
        since = running() ? static_cast<int64_t>(now) : -1;
    }
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// SYST_CSR/RVR/CVR/CALIB on the core clock (see sim/chip/scs.py's SysTick view).
struct SysTick {
    uint32_t base = 0, calib = 0, csr_reset = 0;
    uint32_t csr = 0, rvr = 0, stopped_value = 0;
    int64_t zero_at = -1;          // next cycle the counter reads 0 (running); -1 stopped
    uint64_t event = 0;
    std::deque<uint64_t> wraps;
    void reset() {
        csr = csr_reset; rvr = 0; stopped_value = 0; zero_at = -1; event = 0; wraps.clear();
    }
    bool enabled() const { return csr & 1; }
    uint32_t value(uint64_t now) const;
    void schedule(Core& c);
    void on_zero(Core& c);
    uint32_t read_reg(uint32_t offset, uint64_t now);
    void write_reg(Core& c, uint32_t offset, uint32_t value, uint64_t now);
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// Register layout and bits of a peripheral, from the SVD tables (Python).
struct Layout {
    uint32_t base = 0, span = 0;
    std::vector<int> reg_at;               // byte offset -> register offset, or -1
    std::vector<uint8_t> width;            // register offset -> its width in bytes
    std::vector<uint32_t> reset;           // register offset -> reset value
    std::unordered_map<std::string, uint32_t> k;   // "REG" offset, "REG.FIELD" mask
    uint32_t operator[](const std::string& name) const;
};

// UART0 at line rate (sim/chip/uart.py's notes describe the model).
struct Uart {
    Layout L;
    bool ready = false;                    // set up (its layout given)
    int irq_rxtx = 0, irq_err = 0, depth = 8;
    // offsets and bits, resolved from L once
    uint32_t oBDH, oBDL, oC1, oC2, oS1, oC3, oD, oC4, oPFIFO, oCFIFO, oSFIFO, oTWFIFO,
        oTCFIFO, oRWFIFO, oRCFIFO, oED;
    uint32_t TIE, TCIE, RIE, ILIE, TE, RE, TDRE, TC, RDRF, IDLE, OR, S1_CLEARED_BY_D, SBR_HIGH,
        SBNS, M, BRFA, ORIE, TXFE, RXFE, TXFLUSH, RXFLUSH, CFIFO_ENABLES, TXEMPT, RXEMPT, TXOF,
        RXUF, SFIFO_W1C, FIFO_CODE;
    std::vector<uint8_t> v;
    std::deque<uint8_t> tx, rx, rx_queue;
    std::vector<std::pair<uint64_t, uint8_t>> sent;   // (cycle, byte), until taken
    int shifting = -1;                                // byte, kPreamble, or -1 (idle)
    static constexpr int kPreamble = 0x100;
    // The shifting frame's start and length: it leaves the pin at shift_start + shift_frame,
    // the FIFO's next byte starts then (catch_up applies that when the state is looked at).
    uint64_t shift_start = 0, shift_frame = 0;
    uint64_t tx_event = 0, rx_event = 0, idle_event = 0;
    uint8_t bdh_buffer = 0, s1_seen = 0;
    bool rdrf = false, line_rxtx = false, line_err = false;
    uint8_t flags = 0;
    uint64_t overruns = 0, tx_overflows = 0;
    std::vector<std::pair<uint64_t, std::string>> notes;

    void setup();
    void reset(Core& c);
    double baud(const Core& c) const;
    int frame_bits() const;
    uint64_t frame_cycles(const Core& c) const;
    // What frame_cycles last computed, and from what (BDH, BDL, C4, C1, the core clock).
    struct FrameKey {
        uint8_t bdh = 0, bdl = 0, c4 = 0, c1 = 0;
        double core_hz = -1.0;
        bool operator==(const FrameKey& o) const {
            return bdh == o.bdh && bdl == o.bdl && c4 == o.c4 && c1 == o.c1 &&
                   core_hz == o.core_hz;
        }
    };
    mutable FrameKey frame_key_;
    mutable uint64_t frame_cycles_ = 0;
    size_t tx_depth() const { return (v[oPFIFO] & TXFE) ? depth : 1; }
    size_t rx_depth() const { return (v[oPFIFO] & RXFE) ? depth : 1; }
    size_t rx_water() const;
    bool tdre() const;
    bool tc() const { return tx.empty() && shifting < 0; }
    uint8_t s1() const;
    void latch_rdrf() { if (rx.size() >= rx_water()) rdrf = true; }
    void update_irq(Core& c);
    void kick(Core& c);
    void shifted(Core& c);
    // The transmitter brought to cycle `now`: every frame that has left the pin by then
    // recorded in `sent` at its own cycle, the next byte of the FIFO started at that cycle.
    // Done wherever the transmitter's state is looked at (a register access, the interrupt
    // line, a drain, Python), so its progress needs no event a byte.
    void catch_up(Core& c, uint64_t now);
    // When the transmitter's state next matters to anyone who does not look at it: TDRE
    // setting while TIE is on, or the last frame leaving (TC, a drain); 0 when idle.
    uint64_t next_tx_change(const Core& c) const;
    // An event at next_tx_change() when none is pending. A pending one may be early (bytes
    // written since only move the change later); it then schedules the next.
    void ensure_tx_event(Core& c);
    void reschedule_tx(Core& c);       // the pending event moved: TIE, the FIFO or its mark changed
    // The bytes in `sent`, forgotten there.
    std::string take_sent_bytes();
    void receive(Core& c, const uint8_t* data, size_t n);
    void arrived(Core& c);
    void idle(Core& c);
    uint8_t read_reg(Core& c, uint32_t offset);
    void write_reg(Core& c, uint32_t offset, uint8_t value);
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// The MPU6050 at the I2C byte level, on the project's register model (Mpu6050Emulator).
struct MpuSlave {
    hq::Mpu6050Emulator* emu = nullptr;
    uint8_t address = 0x68;
    bool present = true;
    int pointer = -1;
    bool pointer_set = false;
    std::vector<uint8_t> pending, read_bytes;
    int read_reg = -1;
    struct Entry { double seconds; char kind; int reg; std::vector<uint8_t> data; };
    std::vector<Entry> log;          // until taken
    void start(Core& c, bool read);
    bool write_byte(uint8_t byte);
    uint8_t read_byte();
    void flush(Core& c);
    void stop(Core& c) { flush(c); }
};

// I2C0 as a byte-level master (sim/chip/i2c.py's notes describe the model).
struct I2c {
    Layout L;
    bool ready = false;
    int irq = 0;
    std::vector<uint32_t> scl_divider;
    uint32_t oC1, oS, oD, oF, oFLT;
    uint32_t IICEN, IICIE, MST, TX, TXAK, RSTA, TCF, BUSY, ARBL, IICIF, RXAK, STOPF, SSIE, STARTF,
        SHEN, FLT_FLT, MULT, MULT_SHIFT, ICR;
    std::vector<uint8_t> v;
    std::vector<MpuSlave*> slaves;
    bool pins_connected = true, scl_held = false;
    struct Transfer {
        int address; bool read, acked; uint64_t start_cycle; std::vector<uint8_t> data;
        int64_t end_cycle; double start_s;
    };
    std::vector<Transfer> transfers;         // until taken; the last may be open
    bool open = false;                       // transfers.back() is the current transfer
    std::vector<std::pair<uint64_t, std::string>> errors;
    MpuSlave* slave = nullptr;
    bool expect_address = false, reading = false, line = false;
    uint64_t busy_until = 0, event = 0, free_event = 0;
    // the byte in flight
    bool byte_receive = false, byte_ack = false;
    int byte_value = 0;
    uint64_t byte_start = 0;

    void setup();
    void reset();
    double scl_hz(const Core& c) const;
    uint64_t bit_cycles(const Core& c) const;
    void update_irq(Core& c);
    void flag(Core& c, uint8_t bits) { v[oS] |= bits; update_irq(c); }
    void hold_scl(Core& c, bool held);
    void start(Core& c, uint64_t now, bool repeated);
    void stop(Core& c, uint64_t now);
    void bus_free(Core& c);
    void end_transfer(Core& c, uint64_t now);
    void begin_byte(Core& c, bool receive, int byte, bool ack);
    void finish_byte(Core& c);
    void set_rxak(bool acked) { if (acked) v[oS] &= ~RXAK; else v[oS] |= RXAK; }
    uint8_t read_reg(Core& c, uint32_t offset);
    void write_reg(Core& c, uint32_t offset, uint8_t value);
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// A FlexTimer (FTM0, FTM3) in up-counting edge-aligned PWM and input capture (sim/chip/ftm.py's
// notes describe the model). The counter is not stepped: it is computed from time, from the
// cycle and count it last started at (the anchor).
struct Ftm {
    Layout L;
    bool ready = false;
    int irq = 0;
    Ev tof_kind = Ev::Ftm0Tof;
    static constexpr int kChannels = 8;
    enum Mode : int {
        kDisabled, kEdgePwm, kOutputCompare, kCaptureRising, kCaptureFalling, kCaptureBoth,
        kCenterPwm
    };
    uint32_t oSC, oCNT, oMOD, oCNTIN, oSTATUS, oMODE, oCOMBINE, oCnSC[kChannels], oCnV[kChannels];
    uint32_t TOF, TOIE, CPWMS, CLKS, PS, CHF, CHIE, MSB, MSA, ELSB, ELSA, CNSC_WRITABLE, FTMEN,
        CHnF[kChannels];
    uint32_t channels_end;                 // CnSC/CnV span [oCnSC[0], channels_end)
    std::vector<uint32_t> v;               // by register offset
    bool anchored = false;                 // the counter runs
    uint64_t anchor_cycle = 0;
    int64_t anchor_count = 0;
    // MOD and CnV writes waiting for the counter's wrap, in the order first written (the
    // order they load in matters: a MOD load moves the anchor the later ones wrap from).
    struct Pending { uint32_t reg, value; uint64_t written_at; };
    std::vector<Pending> pending;
    struct Capture { uint64_t cycle; int channel; uint32_t value; };
    std::vector<Capture> captures;         // until taken (Core::keep_records)
    std::vector<std::string> unmodelled;   // until taken
    uint64_t tof_clear = 0, tof_event = 0;
    bool line = false;

    void setup();
    void reset();
    double clock_hz(const Core& c) const;
    double ticks_per_cycle(const Core& c) const;
    uint32_t cntin() const { return v[oCNTIN] & 0xFFFF; }
    uint32_t mod() const { return v[oMOD] & 0xFFFF; }
    int64_t period_ticks() const;
    uint32_t count(Core& c, uint64_t now);
    bool next_wrap_after(const Core& c, uint64_t cycle, uint64_t& wrap) const;
    bool next_tick(const Core& c, uint64_t cycle, uint64_t& tick) const;
    void load_pending(const Core& c, uint64_t now);
    void buffered(Core& c, uint32_t reg, uint32_t value);
    void restart(Core& c, uint64_t now);
    void schedule_tof(Core& c);
    void on_tof(Core& c);
    void update_irq(Core& c);
    int mode(int ch) const;
    bool period_s(Core& c, double& out);
    bool pulse_s(Core& c, int ch, double& out);
    bool commanded_value(Core& c, int ch, uint32_t& out);
    void edge(Core& c, int ch, bool rising);
    uint32_t read_reg(Core& c, uint32_t offset);
    void write_reg(Core& c, uint32_t offset, uint32_t value);
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// The watchdog (sim/chip/wdog.py's notes describe the model). Its timings are in bus clocks
// and are worked out with the clocks of the moment; its constants (the unlock and refresh
// words, the WCT, the LPO's rate) come from Python with the layout.
struct Wdog {
    Layout L;
    bool ready = false;
    uint32_t wct = 0, gap = 0, unlock[2] = {0, 0}, refresh[2] = {0, 0};
    double lpo_hz = 0.0;
    uint32_t oSTCTRLH, oSTCTRLL, oTOVALH, oTOVALL, oWINH, oWINL, oREFRESH, oUNLOCK, oTMROUTH,
        oTMROUTL, oRSTCNT, oPRESC;
    uint32_t WDOGEN, CLKSRC, ALLOWUPDATE, INTFLG, PRESCVAL;
    std::vector<uint32_t> v;               // by register offset
    int64_t first_unlock = -1, unlocked_at = -1, first_refresh = -1;   // cycles; -1 none
    std::vector<uint32_t> written;         // write-once registers written since the unlock
    bool disabled = false;
    uint64_t disabled_instruction = 0, disabled_cycle = 0;
    struct Ignored { uint64_t instruction; uint32_t reg, value; std::string why; };
    std::vector<Ignored> ignored;
    struct Write { uint64_t instruction, cycle; uint32_t reg; uint64_t value; };
    std::vector<Write> log;                // until taken (Core::keep_records)
    uint64_t timeout_event = 0, window_event = 0, started = 0;
    bool window_after_unlock = false;

    void setup();
    void reset();
    bool enabled() const { return v[oSTCTRLH] & WDOGEN; }
    double clock_hz(double bus_hz) const { return (v[oSTCTRLH] & CLKSRC) ? bus_hz : lpo_hz; }
    uint32_t prescale() const;
    double timeout_s(double bus_hz) const;
    void power_on(Core& c, double core_hz, double bus_hz);
    void arm_timeout(Core& c, double bus_hz);
    void expired(Core& c);
    void window(Core& c);
    uint32_t count(const Core& c) const;
    void write_once(Core& c, uint32_t offset, uint32_t value);
    void ignore(Core& c, uint32_t offset, uint32_t value, std::string why);
    uint32_t read_reg(Core& c, uint32_t offset);
    void write_reg(Core& c, uint32_t offset, uint32_t value);
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// The flash memory module (FTFE) and the program flash it erases and programs (sim/chip/ftfe.py's
// notes describe the model). The flash's bytes are unicorn's memory at 0: a command changes
// them when it completes; the program itself can never store there. While a command runs
// (CCIF = 0), an instruction fetched from program flash is a read collision: the run stops
// with a fault (Core::on_block checks every block against `busy`).
struct Ftfe {
    Layout L;
    bool ready = false;
    uint32_t oFSTAT, oFCNFG, oFSEC, oFOPT, oFPROT3, oFPROT2, oFPROT1, oFPROT0, oFEPROT, oFDPROT;
    uint32_t oFCCOB[12];                   // FCCOB0..FCCOBB
    uint32_t CCIF, RDCOLERR, ACCERR, FPVIOL, MGSTAT0, FCNFG_WRITABLE;
    std::vector<uint8_t> v;                // by register offset
    // The program flash at 0: its size, its sector (the erase unit), the flash configuration
    // field (FPROT, FSEC, FOPT, FEPROT, FDPROT are loaded from it at reset), and how long the
    // two commands take (model parameters, from the data sheet's typical figures).
    uint32_t flash_size = 0, sector = 0, config = 0;
    double erase_sector_s = 0.0, program_phrase_s = 0.0;
    bool busy = false;                     // a command runs: CCIF reads 0
    uint64_t done_event = 0;
    uint8_t command = 0;                   // the running command, applied when it completes
    uint32_t address = 0;
    uint8_t data[8] = {};
    uint64_t started = 0;
    uint64_t changes = 0;                  // commands that changed the flash, never reset
    struct Command { uint64_t start, end; uint8_t code; uint32_t address; uint8_t fstat; };
    std::vector<Command> log;              // until taken (Core::keep_records)
    std::vector<std::pair<uint64_t, std::string>> notes;   // documented misuse, until taken

    void setup();
    void reset(Core& c);
    bool protected_range(uint32_t lo, uint32_t n) const;
    uint8_t launch_check(uint8_t code, uint32_t at) const;
    void launch(Core& c);
    void complete(Core& c);
    std::string collision(uint32_t pc);
    uint32_t read_reg(Core& c, uint32_t offset);
    void write_reg(Core& c, uint32_t offset, uint8_t value);
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

// The GPIO ports' input registers (PDIR), read natively from the value the Python pin model
// (sim/chip/port.py) keeps here: it owns the pins and pushes a port's input word whenever a
// pin's level may have changed; every other GPIO and PORT access goes to it. An interrupt
// handler that reads a pin's level (the RC capture handler does at every edge) then costs no
// call into Python.
struct GpioInputs {
    // PDIR's address and value per port; the bits of `held` are the pins PinEdges drives
    // (their levels in `held_value`, over what Python publishes).
    struct Port { uint32_t address; uint32_t value; uint32_t held = 0, held_value = 0, published = 0; };
    std::vector<Port> ports;
    bool read(uint32_t address, unsigned size, uint64_t& out) const;
    void set(uint32_t address, uint32_t value);
    Port* port(uint32_t address);
    void hold(Port& p, uint32_t bit, bool level);
    void release(Port& p, uint32_t bit);
    void release_all();
};

// The GPIO ports' output registers (PDOR, PSOR, PCOR, PTOR): a 32-bit write that leaves the
// port's PDOR as it was (the image sets the LED to its level again every loop) is taken
// here, with nothing to do; one that changes it, or any other access, goes to the Python pin
// model (sim/chip/port.py), which owns the pins and keeps this copy of each port's PDOR.
struct GpioOutputs {
    struct Port { uint32_t base; uint32_t pdor; };
    std::vector<Port> ports;
    bool write(uint32_t address, unsigned size, uint64_t value) const;
    void set(uint32_t base, uint32_t pdor);
};

// Levels driven onto input pins from outside at given cycles, natively: an RC receiver's
// servo pulses on FTM3's capture pins (Teensy35.rc_capture_pulses). At an edge's cycle its
// pins' bits in their port's PDIR take its level and each pin on an FTM3 channel whose level
// changed gives that channel its edge, pin by pin, as the Python pin model does it. A pin's
// level is held here from its first scheduled edge to its last (over the input word Python
// publishes, which has the level the pin keeps after its last edge).
struct PinEdges {
    struct Pin { uint32_t pdir; uint32_t bit; int ftm3_channel; };    // -1: on no channel
    struct Edge { uint64_t cycle; bool level; std::vector<Pin> pins; };
    std::vector<Edge> edges;             // in cycle order (equal cycles: in scheduling order)
    uint64_t event = 0;                  // the event at edges.front()'s cycle (0: none)
    void add(Core& c, uint64_t cycle, bool level, std::vector<Pin> pins);
    void fire(Core& c);
    void reset(Core& c);
    void schedule(Core& c);
};

// USB0's registers, the SIE's answer to a bulk IN token, and the host's frames and bulk IN
// transfers (sim/chip/usb.py and usb_host.py describe the models). Python keeps the rest of
// both (the SIE's other tokens, control transfers, bulk OUT, attach, bus reset, the
// enumeration) and is called (Core::py_call_) when the host has work a poll is not (a control
// transfer or bulk OUT queued) or a poll's answer is not plainly a NAK or data from RAM.
struct Usb {
    Layout L;
    bool ready = false;
    int irq = 0;
    // The native path: the hot register accesses and the host's NAKed bulk IN polls here.
    // Off: Python makes them (the reference the native path is compared with).
    bool native = true;
    uint32_t oISTAT, oINTEN, oERRSTAT, oERREN, oSTAT, oCTL, oADDR, oBDTPAGE1, oBDTPAGE2,
        oBDTPAGE3, oFRMNUML, oFRMNUMH, oENDPT0, oUSBCTRL, oOBSERVE, oCONTROL, oUSBTRC0, oPERID,
        oIDCOMP, oREV, oADDINFO;
    uint32_t TOKDNE, SOFTOK, SLEEP, CTL_SE0, CTL_JSTATE, CTL_USBENSOFEN, CTL_BUSY, DPPULLUP,
        SUSP, PDE, DPPU, DPPD, DMPD, RESUME_INT, USBRESMEN, EPTXEN, EPSTALL, BDTBA;
    std::vector<uint8_t> v;                // by register offset
    uint8_t odd[16][2] = {};               // the ping-pong pointers, [endpoint][tx]
    uint16_t frame = 0;                    // FRMNUM
    bool in_reset = false;                 // the host holds SE0
    bool clock_ok = false;                 // the SIM's USB clock is 48 MHz (Python says)
    bool dma_reads_ram = false;            // the system MPU lets master 4 read all of SRAM
    bool dma_writes_ram = false;           // ... and write all of it
    uint32_t sram_base = 0, sram_size = 0;
    uint64_t sleep_event = 0;
    // The host (usb_host.py): what its bulk IN polling needs.
    struct Host {
        bool frames = false;               // a SOF every frame (the port is enabled)
        uint64_t frame_event = 0, next_sof = 0, sof_end = 0;
        uint16_t frame = 0;
        bool in_flight = false, waiting = false;
        // Python's last pump found nothing to do but the bulk IN poll, and nothing changed
        // that since (Python closes it whenever it queues work).
        bool gate = false;
        uint8_t address = 0, endpoint = 0;
        bool job = false;                  // a bulk IN job exists
        uint64_t generation = 0, flight_generation = 0;
        int64_t nak_frame = -1;
        bool in_nak = true;
        int64_t in_nak_cycle = -1;
        bool reading = true, toggle = false;     // the DATA0/1 the next IN packet should carry
        uint32_t max_packet = 64, silences = 0, toggle_errors = 0;
        std::string received;              // bulk IN bytes, until taken
        // the poll in flight made here: NAKed, or data (the BD's word and address, its data)
        bool flight_data = false;
        uint32_t flight_bd = 0, flight_word = 0, flight_ep = 0, flight_odd = 0;
        std::string flight_bytes;
    } host;

    void setup();
    void reset_registers();
    void reset(Core& c);
    bool attached(const Core& c) const;
    uint32_t bdt_base() const;
    bool enabled() const { return v[oCTL] & CTL_USBENSOFEN; }
    bool suspended() const { return v[oUSBCTRL] & SUSP; }
    void update_irq(Core& c);
    void flag(Core& c, uint32_t bits) { v[oISTAT] |= bits; update_irq(c); }
    void idle_watch(Core& c);
    void bus_activity(Core& c);
    void sof(Core& c, uint16_t number);
    void host_frame(Core& c);
    bool pump(Core& c);
    enum Answer { kPython, kNak, kData };
    Answer in_answer(Core& c, uint32_t& bd_at, uint32_t& word, uint32_t& buffer) const;
    bool in_ram(uint32_t address, uint32_t n) const {
        return address >= sram_base && uint64_t{address} + n <= uint64_t{sram_base} + sram_size;
    }
    void send_in(Core& c, uint32_t bd_at, uint32_t word, uint32_t buffer);
    void complete_in(Core& c);
    int finish(Core& c);
    int end_data(Core& c);
    void took_packet();
    void pump_soon(Core& c);
    void tokens_free(Core& c);
    bool reg_offset(uint32_t address, unsigned size, uint32_t& o) const;
    bool read(Core& c, uint32_t address, unsigned size, uint64_t& out);
    bool write(Core& c, uint32_t address, unsigned size, uint64_t value);
};

class Core {
public:
    enum Device : int {
        kNone = -1, kDwt = 0, kSysTick, kUart0, kI2c0, kFtm0, kFtm3, kWdog, kGpioIn, kFtfe,
        kNvic, kUsb0, kGpioOut, kDevices
    };
    // What a native event asks of Python: the USB host's pump; the check of a bulk IN BD's
    // write-back when the MPU changed while its packet was on the bus (then end_data).
    enum PyCall : int { kNoCall = 0, kUsbPump = 1, kUsbWriteBack = 2 };

    Core(const Uc& uc, const Regs& regs, const PyCallbacks& py,
         std::vector<std::string> exception_names);
    // The core with its own CPU, the engine (sim/chip/thumb.hpp), in place of unicorn: only
    // the read and write callbacks are used (the engine decodes itself and reports the first
    // FP instruction as a stop).
    Core(const PyCallbacks& py, std::vector<std::string> exception_names);
    Core(const Core&) = delete;
    Core& operator=(const Core&) = delete;

    // Installs the block and interrupt hooks and maps the peripheral spaces (MMIO).
    void install(uint32_t periph_base, uint32_t periph_size, uint32_t ppb_base, uint32_t ppb_size);
    // Fills unicorn's TLB (its virtual TLB mode, set before this) with the permissions of
    // the Cortex-M4's default memory map: everything identity-mapped; the peripheral and
    // system regions (0x40000000-0x5FFFFFFF, 0xA0000000-) execute-never; and SRAM
    // [sram_base, +sram_size) entered for data without the execute right until code is
    // fetched from one of its pages. The chip may run code from SRAM; what this buys is that
    // unicorn then lets stores to RAM take its fast path (it checks every store to a page it
    // may have translated code from for self-modifying code).
    void install_tlb(uint32_t sram_base, uint32_t sram_size);
    void reset(double core_hz);

    // -- blocks ---------------------------------------------------------------------------
    void add_block(Block b);
    void clear_blocks() {
        blocks_.clear();
        slots_.assign(kMinSlots, Slot{});
        used_slots_ = 0;
        cur_ = last_ = nullptr;
    }
    const Block* cur() const { return cur_; }
    const Block* last() const { return last_; }

    // -- time -----------------------------------------------------------------------------
    uint32_t pc() const;
    uint64_t now() const { return cur_ ? cycles_ + cur_->cycles_before(pc()) : cycles_; }
    uint64_t instructions_now() const {
        return cur_ ? instructions_ + cur_->index_of(pc()) : instructions_;
    }
    double seconds(uint64_t cycles) const {
        return epoch_seconds_ + static_cast<double>(static_cast<int64_t>(cycles - epoch_cycles_)) / core_hz_;
    }
    void set_clocks(double core_hz, double bus_hz);
    void set_fixed_hz(double hz) { fixed_hz_ = hz; }
    double core_hz() const { return core_hz_; }
    double bus_hz() const { return bus_hz_; }
    double fixed_hz() const { return fixed_hz_; }     // MCGFFCLK
    // The cycle `seconds` after `start` at the current core clock (Machine.cycles_after).
    uint64_t cycles_after(double seconds, uint64_t start) const;

    // -- events ---------------------------------------------------------------------------
    uint64_t at(uint64_t cycle, Ev kind, bool scaled = true);
    void cancel(uint64_t seq);
    bool live(uint64_t seq) const { return find_event(seq) >= 0; }
    bool event_due(uint64_t seq, uint64_t& due) const;
    void attention() {
        deadline_ = 0;
        if (eng_ && in_emu_) eng_->lower_deadline(0);
    }
    uint64_t next_event_due() const;
    // Time passes to `target` with no code running: native events due by then run in order;
    // a Python event due returns its number (0 when the target is reached).
    uint64_t advance(uint64_t target);

    // -- NVIC -----------------------------------------------------------------------------
    // Writes to the set-enable and clear-enable words and the priority bytes, where the
    // core routes them (sim/chip/scs.py: SystemControlSpace): as the Python model does them.
    bool nvic_write(uint32_t address, unsigned size, uint64_t value);
    void set_irq(int irq, bool level);
    void pend(int number) { pending_ |= bit(number); attention(); }
    void unpend(int number) { pending_ &= ~bit(number); }
    int pending_exception() const;
    int execution_priority(bool ignore_primask) const;
    void forget_masks() { masks_valid_ = false; }
    bool preempts(int number, bool ignore_primask = false) const {
        return group(priority_[number]) < execution_priority(ignore_primask);
    }

    // -- running --------------------------------------------------------------------------
    int run(uint64_t instr_limit);
    // The chip resets (a native model's cause): the run stops at once, returning kReset;
    // the first cause is kept until taken.
    void chip_reset(const char* source, std::string message);
    bool reset_pending() const { return reset_pending_; }
    std::pair<std::string, std::string> take_reset() {
        reset_pending_ = false;
        return {std::move(reset_source_), std::move(reset_message_)};
    }
    // A stop address (Machine.stop_at): the run returns kStopAt before the instruction there
    // executes, with no call into Python; the next run goes on through it. A native code hook
    // at that one address (unicorn syncs the PC there, so the stop is exact to the
    // instruction, as a breakpoint's).
    void add_stop_at(uint32_t address);
    uint32_t stop_at_pc() const { return stop_at_pc_; }
    void request_stop() {
        stop_ = true;
        if (eng_ && in_emu_) eng_->request_stop();
    }
    void clear_stop() { stop_ = false; }
    void request_error() { py_error_ = true; }
    void clear_error() { py_error_ = false; }
    void stop_now() {
        if (eng_) {
            if (in_emu_) eng_->request_stop();
        } else {
            uc_.emu_stop(uc_.handle);
        }
    }

    // -- memory ---------------------------------------------------------------------------
    bool read32(uint32_t address, uint32_t& out) const;
    bool mem_read(uint32_t address, void* out, size_t n) const {
        if (eng_) return eng_->read_memory(address, static_cast<uint8_t*>(out), n);
        return uc_.mem_read(uc_.handle, address, out, n) == 0;
    }
    // Flash and SRAM only (the engine's memory; unicorn's maps only those two): an owner's
    // write (DMA, flash programming, loading), which drops the engine's decoded code there.
    bool mem_write(uint32_t address, const void* data, size_t n) {
        if (eng_) {
            uint8_t probe = 0;
            if (n && (!eng_->read_memory(address, &probe, 1) ||
                      !eng_->read_memory(address + static_cast<uint32_t>(n - 1), &probe, 1))) {
                return false;
            }
            eng_->write_memory(address, static_cast<const uint8_t*>(data), n);
            return true;
        }
        return uc_.mem_write(uc_.handle, address, data, n) == 0;
    }
    uint32_t reg(int id) const;
    void set_reg(int id, uint32_t value);
    void set_pc(uint32_t value);
    void clear_restored_it_bits();

    // -- the devices ----------------------------------------------------------------------
    bool dev_read(int dev, uint32_t address, unsigned size, uint64_t& out);
    bool dev_write(int dev, uint32_t address, unsigned size, uint64_t value);
    void add_route(int dev, uint32_t lo, uint32_t hi) { routes_.push_back({lo, hi, dev}); }

    // State Python reads and sets (the views).
    Dwt dwt;
    SysTick systick;
    Uart uart0;
    I2c i2c0;
    Ftm ftm0, ftm3;
    Wdog wdog;
    Ftfe ftfe;
    Usb usb0;
    Ftm* ftm(int dev) { return dev == kFtm0 ? &ftm0 : dev == kFtm3 ? &ftm3 : nullptr; }
    std::vector<std::unique_ptr<MpuSlave>> owned_slaves;
    GpioInputs gpio_in;
    GpioOutputs gpio_out;
    PinEdges pin_edges;
    bool clocked[kDevices] = {true, true, false, false, false, false, true, true, true, true,
                              false, true};
    bool log_all = true;         // every peripheral access through Python (boot logs, traces)
    // Keep the I2C transfer records, the MPU6050's register log, the FTM captures and the
    // watchdog's write log until taken (for tests and inspection); a long lockstep run turns
    // them off instead of taking and dropping them.
    bool keep_records = true;
    bool inline_boundaries = true;   // attend to boundaries inside emu_start (off: always stop)

    uint64_t cycles_ = 0, instructions_ = 0, sleep_cycles_ = 0;
    uint64_t handler_instructions_ = 0, handler_cycles_ = 0;
    bool handler_since_valid_ = false;
    uint64_t handler_since_i_ = 0, handler_since_c_ = 0;
    u128 enabled_ = 0, pending_ = 0, irq_lines_ = 0;
    std::vector<int> priority_;
    int prigroup_ = 0;
    uint32_t vtor_ = 0, ccr_ = 0x200, fpccr_ = 0xC0000000u;
    std::vector<int> active_;
    struct Frame { uint32_t sp; bool fp; uint32_t exc_return; };
    std::vector<Frame> frames_;
    struct LogEntry { uint64_t cycle; bool enter; int number; };
    std::deque<LogEntry> exception_log_;
    std::vector<uint64_t> exception_counts_;
    bool sleeping_ = false, fpu_watch_ = true, time_up_ = false;
    // A run may end early, at the first boundary at which what a lockstep frame waits to
    // leave the board has left: the USB host's bulk IN poll NAKed after cycle drain_after_
    // (the board's IN queue is empty), or UART0 idle (nothing in its FIFO or shifter, and
    // its transmit interrupt off: the driver's own queue is empty too). kNoDrain: never.
    enum Drain : int { kNoDrain = 0, kDrainUsb = 1, kDrainUart = 2 };
    int drain_ = kNoDrain;
    uint64_t drain_after_ = 0;
    bool drained();
    uint64_t py_event_ = 0;
    int py_call_ = kNoCall;     // a native event needs Python (a Python event with no callback)
    int uc_error_ = 0;
    uint32_t intr_number_ = 0, intr_pc_ = 0, bkpt_pc_ = 0;
    FaultInfo fault_;
    // per-run counters for the benchmark (what the wall time is spent on)
    struct Counts {
        uint64_t blocks = 0, decodes = 0, native_accesses = 0, python_accesses = 0,
                 native_events = 0, python_events = 0, exceptions = 0, emu_starts = 0,
                 fpu_checks = 0, inline_boundaries = 0;
    } counts;

    static u128 bit(int n) { return static_cast<u128>(1) << n; }

    // unicorn callbacks (C functions; user data is the Core)
    static void on_block_cb(void* uc, uint64_t address, uint32_t size, void* user);
    static void on_intr_cb(void* uc, uint32_t intno, void* user);
    static void on_stop_at_cb(void* uc, uint64_t address, uint32_t size, void* user);
    static bool grant_cb(void* uc, int type, uint64_t address, int size, int64_t value,
                         void* user);
    struct TlbEntry { uint64_t paddr; int perms; };
    static bool tlb_fill_cb(void* uc, uint64_t vaddr, int type, TlbEntry* e, void* user);
    uint32_t xn_fetch_ = 0;         // the address of a fetch the memory map forbids
    bool xn_fetched_ = false;
    static uint64_t mmio_read_cb(void* uc, uint64_t offset, unsigned size, void* user);
    static void mmio_write_cb(void* uc, uint64_t offset, unsigned size, uint64_t value, void* user);

    const std::string& exception_name(int n) const;

    // -- the engine as the CPU (mk64_engine.cpp) -------------------------------------------
    bool has_engine() const { return eng_ != nullptr; }
    thumb::Thumb* engine() { return eng_.get(); }
    // The FPU as the engine sees it: off until Python has judged the first FP instruction
    // (the kCpuStop "no_fpu"); the ISB watch while Python waits for the ISB after a grant.
    bool engine_fpu_ = false, engine_watch_isb_ = false;
    CpuStop cpu_stop_;

private:
    struct HeapEntry {
        uint64_t due, seq;
        Ev kind;
        bool scaled;
        bool before(const HeapEntry& o) const {
            return due != o.due ? due < o.due : seq < o.seq;
        }
    };
    struct Route { uint32_t lo, hi; int dev; };
    // The scheduled events not yet run or cancelled: a handful at any time (one or two per
    // device), so an unordered flat list with the earliest's index kept (found again by a
    // scan only after the list changed) costs less at every boundary than a heap, whose
    // cancelled entries had to be skipped against a live set at its head.
    ptrdiff_t find_event(uint64_t seq) const {
        for (size_t i = 0; i < events_.size(); ++i) {
            if (events_[i].seq == seq) return static_cast<ptrdiff_t>(i);
        }
        return -1;
    }
    void remove_event(size_t i) {
        events_[i] = events_.back();
        events_.pop_back();
        earliest_valid_ = false;
    }

    int group(int prio) const { return prio < 0 ? prio : prio >> (prigroup_ + 1); }
    // PRIMASK, FAULTMASK and BASEPRI as last read. Only an instruction of a block with a
    // mask operation (CPS, MSR) changes them while the core runs: the copy is dropped when
    // such a block is entered and when it retires, and at every run() (Python may have
    // written them between runs).
    struct Masks { uint32_t primask, faultmask, basepri; };
    mutable Masks masks_{};
    mutable bool masks_valid_ = false;
    const Masks& masks() const;
    // Registers read and written in one call each (an exception's frame).
    void read_regs(const int* ids, uint64_t* out, int n) const;
    void write_regs(const int* ids, const uint64_t* values, int n);
    void on_block(uint64_t address, uint32_t size);
    void on_intr(uint32_t intno);
    uint64_t mmio_read(uint32_t address, unsigned size);
    void mmio_write(uint32_t address, unsigned size, uint64_t value);
    int route(uint32_t address, unsigned size) const;
    const HeapEntry* head();
    void pop();
    void update_deadline();
    int service();
    bool sleep();
    int execute();
    void commit();
    void dispatch(const HeapEntry& e);
    bool masked_pending() const;
    void read_fp_frame(uint32_t* words) const;
    bool take_exception(int number, uint32_t return_pc);
    bool continue_inline();
    bool return_from_exception(uint32_t exc_return);
    void log_exception(bool enter, int number);
    void fault(const char* kind, std::string message, uint32_t pc, bool has_address = false,
               uint32_t address = 0);
    // engine mode (mk64_engine.cpp)
    friend class EngineBus;
    int execute_engine();
    int engine_stopped(thumb::Stop s);
    int cpu_stop(const char* reason, std::string detail, uint32_t address);
    bool engine_access(bool write, uint32_t address, unsigned size, uint32_t& value);
    uint64_t engine_reg(int id) const;
    void set_engine_reg(int id, uint64_t value);

    Uc uc_;
    Regs r_;
    uint32_t sram_base_ = 0, sram_size_ = 0;
    PyCallbacks py_;
    std::vector<std::string> names_;
    std::unordered_map<uint32_t, Block> blocks_;
    // The blocks by start address, open-addressed (linear probing, at most half full), each
    // slot with the key and the costs a boundary needs beside the pointer: a block is found
    // and counted at every boundary from one cache line, without hashing into blocks_ or
    // touching the Block (the memory latency of those two dominated the block hook), and hot
    // blocks never evict each other. Node pointers stay valid as blocks_ grows; a block
    // decoded again at the same start keeps its node and its slot is brought up to date.
    struct Slot {
        uint32_t start = 0, size = 0, n = 0, flags = 0;
        uint64_t cycles = 0;
        const Block* block = nullptr;
    };
    static constexpr size_t kMinSlots = size_t{1} << 13;
    std::vector<Slot> slots_ = std::vector<Slot>(kMinSlots);
    size_t used_slots_ = 0;
    // by address (code runs in order: neighbours share cache lines), linear probing past a
    // slot taken
    static size_t slot_hash(uint32_t start) { return start >> 1; }
    Slot& slot_for(uint32_t start) {
        const size_t mask = slots_.size() - 1;
        for (size_t i = slot_hash(start) & mask;; i = (i + 1) & mask) {
            Slot& s = slots_[i];
            if (!s.block || s.start == start) return s;
        }
    }
    static Slot slot_of(const Block& b) { return {b.start, b.size, b.n, b.flags, b.cycles, &b}; }
    void grow_slots();
    // The slot of the block at `start` of `size` bytes, or nullptr (not decoded, or decoded
    // with another size). The pointer is good until the next lookup.
    const Slot* find_block(uint32_t start, uint32_t size) {
        Slot& slot = slot_for(start);
        if (slot.block) return slot.size == size ? &slot : nullptr;
        auto it = blocks_.find(start);
        if (it == blocks_.end() || it->second.size != size) return nullptr;
        slot = slot_of(it->second);
        if (2 * ++used_slots_ <= slots_.size()) return &slot;
        grow_slots();
        return &slot_for(start);
    }
    // The block running now and its costs (copied from its slot: no Block touched).
    const Block* cur_ = nullptr;
    uint32_t cur_n_ = 0, cur_flags_ = 0;
    uint64_t cur_cycles_ = 0;
    const Block* last_ = nullptr;
    std::vector<Route> routes_;
    std::vector<HeapEntry> events_;
    size_t earliest_ = 0;               // index of the earliest event, while earliest_valid_
    bool earliest_valid_ = false;
    uint64_t seq_ = 0;
    uint64_t deadline_ = 0, instr_limit_ = 0;
    uint64_t epoch_cycles_ = 0;
    double epoch_seconds_ = 0.0, core_hz_ = 20971520.0, bus_hz_ = 20971520.0, fixed_hz_ = 0.0;
    bool watch_mask_ = false, budget_hit_ = false, stop_ = false, py_error_ = false;
    bool svc_ = false, bkpt_ = false, intr_fault_ = false, inline_fault_ = false;
    bool inline_taken_ = false;     // continue_inline() took an exception (the PC moved)
    bool in_block_hook_ = false;
    bool in_emu_ = false;           // inside emu_start
    bool reset_pending_ = false;
    std::string reset_source_, reset_message_;
    bool stop_at_hit_ = false;
    uint32_t stop_at_pc_ = 0;
    int64_t stop_at_resume_ = -1;   // the stop address the next run goes on through, or -1
    uint32_t pending_pc_ = 0;       // the return address of an exception taken inline

    std::unique_ptr<thumb::Thumb> eng_;         // the CPU when it is not unicorn
    std::unique_ptr<EngineBus> eng_bus_;

public:
    struct Space { Core* core; uint32_t base; };
    Space spaces_[2] = {{nullptr, 0}, {nullptr, 0}};   // the MMIO callbacks' user data
    uint32_t space_sizes_[2] = {0, 0};
};

}  // namespace hqsim::mk64
