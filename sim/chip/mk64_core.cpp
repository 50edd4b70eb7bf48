// The emulated core's hot path: block accounting, events, the NVIC, exception entry and
// return, WFI, and the MMIO dispatch (mk64_core.hpp says what and why). Every rule here is the
// one sim/chip/machine.py documented when it did this in Python; the order of the checks at a
// block boundary is kept, so instruction and cycle counts are the same.
#include "chip/mk64_core.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>

namespace hqsim::mk64 {

namespace {
constexpr int UC_HOOK_INTR = 1 << 0;
constexpr int UC_HOOK_CODE = 1 << 2;
constexpr int UC_HOOK_BLOCK = 1 << 3;
constexpr int UC_HOOK_MEM_READ_PROT = 1 << 7, UC_HOOK_MEM_WRITE_PROT = 1 << 8;
constexpr int UC_HOOK_TLB_FILL = 1 << 17;
constexpr int UC_MEM_FETCH = 18;
constexpr int UC_PROT_READ = 1, UC_PROT_WRITE = 2, UC_PROT_EXEC = 4;
constexpr uint32_t kExcReturnTrap = 8;     // QEMU's EXCP_EXCEPTION_EXIT
constexpr uint32_t kIntrSvc = 2, kIntrBkpt = 7;
constexpr uint32_t kControlSpsel = 1u << 1, kControlFpca = 1u << 2;
constexpr uint32_t kXpsrAlign = 1u << 9;
constexpr int kThreadPriority = 1 << 16;
constexpr uint64_t kEntryCycles = 12, kReturnCycles = 12;   // timing.py's figures
constexpr size_t kExceptionLog = 4096;
constexpr uint64_t kFar = uint64_t{1} << 62;
}  // namespace

std::string hex8(uint32_t v) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "0x%08X", v);
    return buf;
}

Core::Core(const Uc& uc, const Regs& regs, const PyCallbacks& py,
           std::vector<std::string> exception_names)
    : uc_(uc), r_(regs), py_(py), names_(std::move(exception_names)) {
    priority_.assign(kExceptions, 0);
    exception_counts_.assign(kExceptions, 0);
    spaces_[0].core = spaces_[1].core = this;
}

double py_floordiv(double a, double b) {
    double mod = std::fmod(a, b);
    double div = (a - mod) / b;
    if (mod != 0.0) {
        if ((b < 0) != (mod < 0)) div -= 1.0;
    }
    if (div == 0.0) return std::copysign(0.0, a / b);
    double floordiv = std::floor(div);
    if (div - floordiv > 0.5) floordiv += 1.0;
    return floordiv;
}

const std::string& Core::exception_name(int n) const {
    static const std::string unknown = "exception";
    return n >= 0 && static_cast<size_t>(n) < names_.size() ? names_[n] : unknown;
}

void Core::install(uint32_t periph_base, uint32_t periph_size, uint32_t ppb_base,
                   uint32_t ppb_size) {
    spaces_[0].base = periph_base;
    spaces_[1].base = ppb_base;
    space_sizes_[0] = periph_size;
    space_sizes_[1] = ppb_size;
    if (eng_) return;                // the engine's bus is engine_access (mk64_engine.cpp)
    size_t h = 0;
    uc_.hook_add(uc_.handle, &h, UC_HOOK_BLOCK, reinterpret_cast<void*>(&Core::on_block_cb),
                 this, uint64_t{1}, uint64_t{0});
    uc_.hook_add(uc_.handle, &h, UC_HOOK_INTR, reinterpret_cast<void*>(&Core::on_intr_cb), this,
                 uint64_t{1}, uint64_t{0});
    uc_.mmio_map(uc_.handle, periph_base, periph_size,
                 reinterpret_cast<void*>(&Core::mmio_read_cb), &spaces_[0],
                 reinterpret_cast<void*>(&Core::mmio_write_cb), &spaces_[0]);
    uc_.mmio_map(uc_.handle, ppb_base, ppb_size, reinterpret_cast<void*>(&Core::mmio_read_cb),
                 &spaces_[1], reinterpret_cast<void*>(&Core::mmio_write_cb), &spaces_[1]);
    // The PC must be exact at every peripheral access (the time of an access is the cycle of
    // its instruction). Unicorn brings the PC up to date before it calls a memory hook, but
    // any UC_HOOK_MEM_READ/WRITE hook sends every load and store of the program through its
    // slow path; a protection hook does not. So the peripheral spaces are mapped without
    // access rights (machine.py protects them) and this hook grants each access: unicorn
    // syncs the PC, calls it, and then performs the access through the MMIO callbacks.
    uc_.hook_add(uc_.handle, &h, UC_HOOK_MEM_READ_PROT | UC_HOOK_MEM_WRITE_PROT,
                 reinterpret_cast<void*>(&Core::grant_cb), this, uint64_t{periph_base},
                 uint64_t{periph_base} + periph_size - 1);
    uc_.hook_add(uc_.handle, &h, UC_HOOK_MEM_READ_PROT | UC_HOOK_MEM_WRITE_PROT,
                 reinterpret_cast<void*>(&Core::grant_cb), this, uint64_t{ppb_base},
                 uint64_t{ppb_base} + ppb_size - 1);
}

void Core::add_stop_at(uint32_t address) {
    if (eng_) {
        eng_->add_stop_address(address);
        return;
    }
    size_t h = 0;
    uc_.hook_add(uc_.handle, &h, UC_HOOK_CODE, reinterpret_cast<void*>(&Core::on_stop_at_cb),
                 this, uint64_t{address}, uint64_t{address});
}

void Core::on_stop_at_cb(void*, uint64_t address, uint32_t, void* user) {
    Core* c = static_cast<Core*>(user);
    if (static_cast<int64_t>(address) == c->stop_at_resume_) {     // the run resumes here
        c->stop_at_resume_ = -1;
        return;
    }
    c->stop_at_hit_ = true;
    c->stop_at_pc_ = static_cast<uint32_t>(address);
    c->stop_now();
}

void Core::reset(double core_hz) {
    cycles_ = instructions_ = sleep_cycles_ = 0;
    epoch_cycles_ = 0;
    epoch_seconds_ = 0.0;
    core_hz_ = core_hz;
    events_.clear();
    earliest_valid_ = false;
    cur_ = last_ = nullptr;
    deadline_ = 0;
    instr_limit_ = 0;
    stop_ = py_error_ = budget_hit_ = watch_mask_ = false;
    stop_at_hit_ = false;
    stop_at_resume_ = -1;
    reset_pending_ = false;
    reset_source_.clear();
    reset_message_.clear();
    svc_ = bkpt_ = intr_fault_ = false;
    sleeping_ = false;
    time_up_ = false;
    fpu_watch_ = true;
    enabled_ = pending_ = irq_lines_ = 0;
    priority_.assign(kExceptions, 0);
    priority_[1] = -3;
    priority_[2] = -2;
    priority_[3] = -1;
    prigroup_ = 0;
    vtor_ = 0;
    active_.clear();
    frames_.clear();
    ccr_ = 0x200;
    fpccr_ = 0xC0000000u;
    exception_log_.clear();
    exception_counts_.assign(kExceptions, 0);
    handler_instructions_ = handler_cycles_ = 0;
    handler_since_valid_ = false;
    dwt.reset();
    systick.reset();
    if (i2c0.ready) i2c0.reset();
    if (uart0.ready) uart0.reset(*this);
    if (ftm0.ready) ftm0.reset();
    if (ftm3.ready) ftm3.reset();
    if (wdog.ready) wdog.reset();
    if (ftfe.ready) ftfe.reset(*this);
    if (usb0.ready) usb0.reset(*this);
    pin_edges.reset(*this);
    py_call_ = kNoCall;
    if (eng_) {
        engine_fpu_ = engine_watch_isb_ = false;
        eng_->primask = eng_->faultmask = eng_->basepri = 0;
        eng_->set_control(0);
        eng_->set_xpsr(1u << 24);
        eng_->set_fpscr(0);
    }
}

void Core::add_block(Block b) {
    const uint32_t start = b.start;
    Block& kept = blocks_[start] = std::move(b);     // a block decoded again keeps its node
    Slot& slot = slot_for(start);
    if (slot.block) slot = slot_of(kept);
}

void Core::grow_slots() {
    std::vector<Slot> old(2 * slots_.size());
    old.swap(slots_);
    for (const Slot& s : old) {
        if (s.block) slot_for(s.start) = s;
    }
}

void Core::install_tlb(uint32_t sram_base, uint32_t sram_size) {
    sram_base_ = sram_base;
    sram_size_ = sram_size;
    if (eng_) return;
    size_t h = 0;
    uc_.hook_add(uc_.handle, &h, UC_HOOK_TLB_FILL, reinterpret_cast<void*>(&Core::tlb_fill_cb),
                 this, uint64_t{1}, uint64_t{0});
}

// Unicorn 2.1.4 rolls the CPU state back to the accessing instruction before it calls a
// protection or TLB-fill hook (cpu_restore_state: the PC, and the IT bits of an instruction
// inside an IT block), and on a granted access the translated block goes on. The translation
// tracks the IT state itself and keeps the CPU's copy at zero inside a block (QEMU writes it
// only when a block leaves mid-IT-block), so a copy left set outlives the IT block: the next
// block is looked up as if still inside one and its first instructions run conditionally (an
// instruction after the return from a switch's table lookup was skipped: the Teensy image's
// STATUSTEXTs went out empty). These hooks put the copy back to zero, the Thumb bit kept;
// a fault that follows restores it again itself. tests/teensy35_boot_test.py has the case.
void Core::clear_restored_it_bits() {
    if (eng_) return;
    const uint64_t thumb_only = uint64_t{1} << 24;     // EPSR: T set, ICI/IT clear
    uc_.reg_write(uc_.handle, r_.epsr, &thumb_only);
}

bool Core::grant_cb(void*, int, uint64_t, int, int64_t, void* user) {
    static_cast<Core*>(user)->clear_restored_it_bits();
    return true;
}

bool Core::tlb_fill_cb(void*, uint64_t vaddr, int type, TlbEntry* e, void* user) {
    Core* c = static_cast<Core*>(user);
    const uint32_t a = static_cast<uint32_t>(vaddr);
    e->paddr = vaddr;
    const bool fetch = type == UC_MEM_FETCH;
    // The top page is where a return to an EXC_RETURN value goes; unicorn recognises it when
    // it translates the fetch, so that fetch must be allowed (nothing is mapped there).
    const bool xn = (a >= 0x40000000u && a < 0x60000000u) || (a >= 0xA0000000u && a < 0xFFFFF000u);
    if (fetch && xn) {
        c->xn_fetch_ = a;
        c->xn_fetched_ = true;
        return false;                       // unicorn stops the run (UC_ERR_EXCEPTION)
    }
    // A data access fills from inside a running block (see clear_restored_it_bits); a fetch
    // fills while a block is translated, before its block hook reads the IT bits to stack.
    if (!fetch) c->clear_restored_it_bits();
    const bool sram = a - c->sram_base_ < c->sram_size_;
    e->perms = UC_PROT_READ | UC_PROT_WRITE | ((sram && !fetch) || xn ? 0 : UC_PROT_EXEC);
    return true;
}

// -- registers and memory --------------------------------------------------------------------
uint32_t Core::reg(int id) const {
    if (eng_) return static_cast<uint32_t>(engine_reg(id));
    uint64_t v = 0;
    uc_.reg_read(uc_.handle, id, &v);
    return static_cast<uint32_t>(v);
}

void Core::set_reg(int id, uint32_t value) {
    if (eng_) {
        set_engine_reg(id, value);
        return;
    }
    uint64_t v = value;
    size_t size = sizeof v;
    uc_.reg_write2(uc_.handle, id, &v, &size);
}

uint32_t Core::pc() const { return reg(r_.pc); }

// A PC written while unicorn runs makes it continue there. How it must be written depends on
// where (unicorn 2.1): in a block hook, the exit check that follows the hook would restore the
// PC from the block unless uc_reg_write's skip_sync_pc_on_exit tells it not to (the check
// consumes the flag); anywhere else (the interrupt hook, between runs) that flag would stay set
// and turn off the PC sync at peripheral accesses until the next uc_emu_start, so
// uc_reg_write2, which leaves it alone, is used there. Bit 0 keeps unicorn in Thumb state.
void Core::set_pc(uint32_t value) {
    if (eng_) {
        eng_->jump(value);              // exception entry and return, BKPT: not the owner's
        return;
    }
    uint64_t v = value | 1u;
    if (in_block_hook_) {
        uc_.reg_write(uc_.handle, r_.pc, &v);
    } else {
        size_t size = sizeof v;
        uc_.reg_write2(uc_.handle, r_.pc, &v, &size);
    }
}

bool Core::read32(uint32_t address, uint32_t& out) const {
    uint8_t b[4];
    if (!mem_read(address, b, 4)) return false;
    out = uint32_t{b[0]} | uint32_t{b[1]} << 8 | uint32_t{b[2]} << 16 | uint32_t{b[3]} << 24;
    return true;
}

// -- time and events -------------------------------------------------------------------------
void Core::set_clocks(double core_hz, double bus_hz) {
    bus_hz_ = bus_hz;
    if (core_hz == core_hz_) return;
    const uint64_t t = now();
    epoch_seconds_ = seconds(t);
    epoch_cycles_ = t;
    const double ratio = core_hz / core_hz_;
    core_hz_ = core_hz;
    // Events in seconds keep their time: their cycle counts move with the clock.
    for (HeapEntry& e : events_) {
        if (e.scaled && e.due > t) {
            const double moved = std::nearbyint(static_cast<double>(e.due - t) * ratio);
            e.due = t + std::max<uint64_t>(1, static_cast<uint64_t>(moved));
        }
    }
    earliest_valid_ = false;
    update_deadline();
}

uint64_t Core::cycles_after(double seconds, uint64_t start) const {
    const double cycles = -py_floordiv(-seconds * core_hz_, 1.0);
    return start + static_cast<uint64_t>(std::max<int64_t>(1, static_cast<int64_t>(cycles)));
}

uint64_t Core::at(uint64_t cycle, Ev kind, bool scaled) {
    const HeapEntry e{std::max(cycle, now()), ++seq_, kind, scaled};
    events_.push_back(e);
    if (earliest_valid_ && e.before(events_[earliest_])) earliest_ = events_.size() - 1;
    if (e.due < deadline_) deadline_ = e.due;
    if (eng_ && in_emu_) eng_->lower_deadline(e.due);     // due before the run's deadline
    return e.seq;
}

void Core::cancel(uint64_t seq) {
    const ptrdiff_t i = find_event(seq);
    if (i >= 0) remove_event(static_cast<size_t>(i));
}

bool Core::event_due(uint64_t seq, uint64_t& due) const {
    const ptrdiff_t i = find_event(seq);
    if (i < 0) return false;
    due = events_[static_cast<size_t>(i)].due;
    return true;
}

// The earliest event (by cycle, then by the order scheduled), or nullptr: good until the
// list next changes.
const Core::HeapEntry* Core::head() {
    if (events_.empty()) return nullptr;
    if (!earliest_valid_) {
        earliest_ = 0;
        for (size_t i = 1; i < events_.size(); ++i) {
            if (events_[i].before(events_[earliest_])) earliest_ = i;
        }
        earliest_valid_ = true;
    }
    return &events_[earliest_];
}

// Removes the earliest event (head() first).
void Core::pop() { remove_event(earliest_); }

uint64_t Core::next_event_due() const {
    uint64_t best = kFar;
    for (const HeapEntry& e : events_) best = std::min(best, e.due);
    return best;
}

uint64_t Core::advance(uint64_t target) {
    for (;;) {
        const HeapEntry* h = head();
        if (!h || h->due > target) {
            cycles_ = std::max(cycles_, target);
            return 0;
        }
        const HeapEntry e = *h;
        pop();
        cycles_ = std::max(cycles_, e.due);
        if (e.kind == Ev::Python) return e.seq;
        dispatch(e);
        if (reset_pending_) return 0;
        if (py_call_) return e.seq;
    }
}

void Core::update_deadline() {
    const HeapEntry* h = head();
    deadline_ = h ? h->due : kFar;
}

void Core::dispatch(const HeapEntry& e) {
    ++counts.native_events;
    switch (e.kind) {
        case Ev::TimeLimit: time_up_ = true; break;
        case Ev::SysTick: systick.on_zero(*this); break;
        case Ev::UartTx: uart0.shifted(*this); break;
        case Ev::UartRx: uart0.arrived(*this); break;
        case Ev::UartIdle: uart0.idle(*this); break;
        case Ev::I2cByte: i2c0.finish_byte(*this); break;
        case Ev::I2cFree: i2c0.bus_free(*this); break;
        case Ev::Ftm0Tof: ftm0.on_tof(*this); break;
        case Ev::Ftm3Tof: ftm3.on_tof(*this); break;
        case Ev::WdogTimeout: wdog.expired(*this); break;
        case Ev::WdogWindow: wdog.window(*this); break;
        case Ev::FtfeDone: ftfe.complete(*this); break;
        case Ev::UsbFrame:
            usb0.host_frame(*this);
            if (!usb0.pump(*this)) py_call_ = kUsbPump;
            break;
        case Ev::UsbPump:
            if (!usb0.pump(*this)) py_call_ = kUsbPump;
            break;
        case Ev::UsbFinish: py_call_ = usb0.finish(*this); break;
        case Ev::UsbSleep:
            usb0.sleep_event = 0;
            usb0.flag(*this, usb0.SLEEP);
            break;
        case Ev::PinEdge: pin_edges.fire(*this); break;
        case Ev::Python: break;
    }
}

// -- NVIC -----------------------------------------------------------------------------------
void Core::set_irq(int irq, bool level) {
    const int n = irq + 16;
    const u128 b = bit(n);
    if (level) {
        if (!(irq_lines_ & b)) {
            irq_lines_ |= b;
            if (std::find(active_.begin(), active_.end(), n) == active_.end()) {
                pending_ |= b;
                attention();
            }
        }
    } else {
        irq_lines_ &= ~b;
    }
}

int Core::pending_exception() const {
    u128 ready = pending_ & (enabled_ | u128{0xFFFF});
    if (!ready) return -1;
    // The pending numbers low to high (the lowest wins a tie), each found by a bit scan.
    int best = -1;
    for (int half = 0; half < 2; ++half) {
        uint64_t word = static_cast<uint64_t>(ready >> (64 * half));
        while (word) {
            const int n = 64 * half + __builtin_ctzll(word);
            word &= word - 1;
            if (best < 0 || priority_[n] < priority_[best]) best = n;
        }
    }
    return best;
}

int Core::execution_priority(bool ignore_primask) const {
    int prio = kThreadPriority;
    for (int n : active_) prio = std::min(prio, group(priority_[n]));
    const Masks& m = masks();
    if (!ignore_primask) {
        if (m.faultmask & 1) prio = std::min(prio, -1);
        if (m.primask & 1) prio = std::min(prio, 0);
    }
    const int basepri = static_cast<int>(m.basepri & 0xF0);
    if (basepri) prio = std::min(prio, group(basepri));
    return prio;
}

const Core::Masks& Core::masks() const {
    if (!masks_valid_) {
        const int ids[3] = {r_.primask, r_.faultmask, r_.basepri};
        uint64_t v[3];
        read_regs(ids, v, 3);
        masks_ = {static_cast<uint32_t>(v[0]), static_cast<uint32_t>(v[1]),
                  static_cast<uint32_t>(v[2])};
        masks_valid_ = true;
    }
    return masks_;
}

void Core::read_regs(const int* ids, uint64_t* out, int n) const {
    if (eng_) {
        for (int i = 0; i < n; ++i) out[i] = engine_reg(ids[i]);
        return;
    }
    void* ptrs[32];
    for (int i = 0; i < n; ++i) {
        out[i] = 0;                 // a 32-bit register fills the low word only
        ptrs[i] = &out[i];
    }
    uc_.reg_read_batch(uc_.handle, ids, ptrs, n);
}

void Core::write_regs(const int* ids, const uint64_t* values, int n) {
    if (eng_) {
        for (int i = 0; i < n; ++i) set_engine_reg(ids[i], values[i]);
        return;
    }
    void* ptrs[32];
    for (int i = 0; i < n; ++i) ptrs[i] = const_cast<uint64_t*>(&values[i]);
    uc_.reg_write_batch(uc_.handle, ids, ptrs, n);
}

bool Core::masked_pending() const {
    const int n = pending_exception();
    return n >= 0 && !preempts(n) && preempts(n, true);
}

// -- exceptions -----------------------------------------------------------------------------
void Core::fault(const char* kind, std::string message, uint32_t pc, bool has_address,
                 uint32_t address) {
    fault_.kind = kind;
    fault_.message = std::move(message);
    fault_.pc = pc;
    fault_.has_address = has_address;
    fault_.address = address;
}

void Core::log_exception(bool enter, int number) {
    if (exception_log_.size() == kExceptionLog) exception_log_.pop_front();
    exception_log_.push_back({cycles_, enter, number});
}

// S0-S15 and FPSCR, as a frame's words 8-24 (S0-S15 read as D0-D7, in one call).
void Core::read_fp_frame(uint32_t* words) const {
    int ids[9];
    for (int i = 0; i < 8; ++i) ids[i] = r_.d[i];
    ids[8] = r_.fpscr;
    uint64_t v[9];
    read_regs(ids, v, 9);
    for (int i = 0; i < 8; ++i) {
        words[2 * i] = static_cast<uint32_t>(v[i]);
        words[2 * i + 1] = static_cast<uint32_t>(v[i] >> 32);
    }
    words[16] = static_cast<uint32_t>(v[8]);
}

bool Core::take_exception(int number, uint32_t return_pc) {
    ++counts.exceptions;
    // CONTROL, SP, xPSR and the basic frame's registers in one call
    const int ids[9] = {r_.control, r_.sp, r_.xpsr, r_.r0, r_.r1, r_.r2, r_.r3, r_.r12, r_.lr};
    uint64_t got[9];
    read_regs(ids, got, 9);
    const uint32_t control = static_cast<uint32_t>(got[0]);
    if ((control & kControlSpsel) && active_.empty()) {
        fault("UsageFault", "thread mode on the process stack (CONTROL.SPSEL) is not modelled",
              return_pc);
        return false;
    }
    const bool fp = (control & kControlFpca) && (fpccr_ & (1u << 31));
    const uint32_t sp = static_cast<uint32_t>(got[1]);
    uint32_t xpsr = static_cast<uint32_t>(got[2]);
    uint32_t new_sp = sp - (fp ? 0x68 : 0x20);
    if ((ccr_ & 0x200) || fp) {
        if (new_sp & 4) {
            new_sp -= 4;
            xpsr |= kXpsrAlign;
        } else {
            xpsr &= ~kXpsrAlign;
        }
    }
    uint32_t words[26];
    for (int i = 0; i < 6; ++i) words[i] = static_cast<uint32_t>(got[3 + i]);
    words[6] = return_pc;
    words[7] = xpsr;
    int n = 8;
    if (fp) {
        // Lazy stacking reserves this space and fills it when the handler first uses the FPU;
        // it is filled at once here, which the program cannot tell apart.
        read_fp_frame(words + 8);
        words[25] = 0;
        n = 26;
    }
    if (!mem_write(new_sp, words, 4u * n)) {
        fault("BusFault", "stacking a " + exception_name(number) + " frame at " + hex8(new_sp) +
                              " failed (stack overflow?)",
              return_pc, true, new_sp);
        return false;
    }
    const bool thread = active_.empty();
    if (thread) {
        handler_since_valid_ = true;
        handler_since_i_ = instructions_;
        handler_since_c_ = cycles_;
    }
    const uint32_t exc_return = (thread ? 0xFFFFFFF9u : 0xFFFFFFF1u) & ~(fp ? 0x10u : 0u);
    active_.push_back(number);
    frames_.push_back({new_sp, fp, exc_return});
    pending_ &= ~bit(number);
    uint32_t handler = 0;
    read32(vtor_ + 4u * static_cast<uint32_t>(number), handler);
    const int set_ids[4] = {r_.sp, r_.lr, r_.control, r_.xpsr};
    const uint64_t set[4] = {new_sp, exc_return, control & ~kControlFpca,
                             (1u << 24) | static_cast<uint32_t>(number)};
    write_regs(set_ids, set, 4);
    if (eng_) eng_->enter_exception(handler);
    else set_pc(handler);
    cycles_ += kEntryCycles;
    log_exception(true, number);
    ++exception_counts_[number];
    if (!(handler & 1)) {
        fault("UsageFault", "vector " + std::to_string(number) + " (" + exception_name(number) +
                                ") = " + hex8(handler) + " has no Thumb bit (INVSTATE)",
              return_pc);
        return false;
    }
    return true;
}

bool Core::return_from_exception(uint32_t exc_return) {
    if (active_.empty()) {
        fault("UsageFault", "EXC_RETURN " + hex8(exc_return) + " in thread mode (INVPC)",
              exc_return);
        return false;
    }
    const int number = active_.back();
    if (exc_return != 0xFFFFFFF1u && exc_return != 0xFFFFFFF9u && exc_return != 0xFFFFFFE1u &&
        exc_return != 0xFFFFFFE9u) {
        fault("UsageFault", "EXC_RETURN " + hex8(exc_return) + " from " + exception_name(number) +
                                ": only main-stack returns are modelled",
              exc_return);
        return false;
    }
    const bool to_thread = exc_return & 0x8;
    if (to_thread != (active_.size() == 1)) {
        fault("UsageFault", "EXC_RETURN " + hex8(exc_return) + " from " + exception_name(number) +
                                " names the wrong mode (INVPC)",
              exc_return);
        return false;
    }
    const bool fp = !(exc_return & 0x10);
    const uint32_t sp = reg(r_.sp);
    const int n = fp ? 26 : 8;
    uint32_t words[26];
    if (!mem_read(sp, words, 4u * n)) {
        fault("BusFault", "unstacking a " + exception_name(number) + " frame at " + hex8(sp) +
                              " failed",
              exc_return, true, sp);
        return false;
    }
    const uint32_t xpsr = words[7];
    const uint32_t new_sp = sp + 4u * n + ((xpsr & kXpsrAlign) ? 4u : 0u);
    active_.pop_back();
    frames_.pop_back();
    const uint32_t control = reg(r_.control);
    // The registers in the order they were written one at a time: the basic frame's, the FP
    // frame's, SP, CONTROL, xPSR; in one call.
    int ids[6 + 9 + 3] = {r_.r0, r_.r1, r_.r2, r_.r3, r_.r12, r_.lr};
    uint64_t values[6 + 9 + 3];
    for (int i = 0; i < 6; ++i) values[i] = words[i];
    int k = 6;
    if (fp) {
        for (int i = 0; i < 8; ++i) {
            ids[k] = r_.d[i];
            values[k++] = uint64_t{words[8 + 2 * i]} | uint64_t{words[9 + 2 * i]} << 32;
        }
        ids[k] = r_.fpscr;
        values[k++] = words[24];
    }
    ids[k] = r_.sp;
    values[k++] = new_sp;
    ids[k] = r_.control;
    values[k++] = fp ? (control | kControlFpca) : (control & ~kControlFpca);
    ids[k] = r_.xpsr;
    values[k++] = xpsr & ~kXpsrAlign;
    write_regs(ids, values, k);
    if (eng_) eng_->return_from_exception(words[6]);
    else set_pc(words[6]);
    cycles_ += kReturnCycles;
    log_exception(false, number);
    if (active_.empty() && handler_since_valid_) {
        handler_instructions_ += instructions_ - handler_since_i_;
        handler_cycles_ += cycles_ - handler_since_c_;
        handler_since_valid_ = false;
    }
    if (irq_lines_ & bit(number)) pending_ |= bit(number);   // a level still asserted pends again
    return true;
}

// -- the run loop ---------------------------------------------------------------------------
void Core::chip_reset(const char* source, std::string message) {
    if (!reset_pending_) {
        reset_pending_ = true;
        reset_source_ = source;
        reset_message_ = std::move(message);
    }
    if (in_emu_) stop_now();
}

int Core::run(uint64_t instr_limit) {
    instr_limit_ = instr_limit;
    masks_valid_ = false;                // Python may have written them since
    for (;;) {
        if (reset_pending_) return kReset;
        const int s = service();
        if (s) return s;
        if (drain_ != kNoDrain && drained()) return kDrained;
        if (stop_) return kStop;
        if (instructions_ >= instr_limit) return kBudget;
        if (time_up_) return kTime;
        if (sleeping_) {
            if (!sleep()) return kSleepForever;
            continue;
        }
        const int e = execute();
        if (e) return e;
    }
}

// At a boundary: due events in order, then the exception the NVIC presents, if it preempts.
int Core::service() {
    for (;;) {
        if (py_call_) {             // a native event dispatched here or inline needs Python
            ++counts.python_events;
            py_event_ = 0;
            return kPyEvent;
        }
        const HeapEntry* h = head();
        if (!h || h->due > cycles_) break;
        const HeapEntry e = *h;
        pop();
        if (e.kind == Ev::Python) {
            ++counts.python_events;
            py_event_ = e.seq;
            return kPyEvent;
        }
        dispatch(e);
        if (reset_pending_) return kReset;
    }
    const int number = pending_exception();
    if (number >= 0 && preempts(number)) {
        sleeping_ = false;
        if (!take_exception(number, pc())) return kFault;
    }
    return 0;
}

// At a block boundary inside emu_start that needs attention (an event due, an interrupt to
// take, a mask lifted, an exception return): what run() would do before its next emu_start,
// done here when nothing in it needs Python, so the run goes on without leaving unicorn (a PC
// written from a hook makes unicorn continue there). False: stop, and let run() see to it
// (a Python event due, a stop, the budget or the time limit, a fault).
bool Core::continue_inline() {
    inline_taken_ = false;
    if (!inline_boundaries) return false;
    ++counts.inline_boundaries;
    for (;;) {
        const HeapEntry* h = head();
        if (!h || h->due > cycles_) break;
        if (h->kind == Ev::Python) return false;
        const HeapEntry e = *h;
        pop();
        dispatch(e);
        if (reset_pending_ || py_call_) return false;
    }
    const int number = pending_exception();
    if (number >= 0 && preempts(number)) {
        sleeping_ = false;
        if (!take_exception(number, pending_pc_)) {
            inline_fault_ = true;
            return false;
        }
        inline_taken_ = true;
    }
    if (stop_ || instructions_ >= instr_limit_ || time_up_) return false;
    if (drain_ != kNoDrain && drained()) return false;
    update_deadline();
    budget_hit_ = false;
    watch_mask_ = masked_pending();
    return true;
}

bool Core::drained() {
    if (drain_ == kDrainUsb) {
        return usb0.host.in_nak_cycle >= 0 &&
               static_cast<uint64_t>(usb0.host.in_nak_cycle) > drain_after_;
    }
    if (!uart0.ready) return false;
    uart0.catch_up(*this, cycles_);
    return uart0.tc() && !(uart0.v[uart0.oC2] & uart0.TIE);
}

// WFI: wake on an exception that would preempt were PRIMASK clear; else time passes to the
// next event. False when nothing will ever wake the core.
bool Core::sleep() {
    const int number = pending_exception();
    if (number >= 0 && preempts(number, true)) {
        sleeping_ = false;
        return true;
    }
    update_deadline();
    const HeapEntry* h = head();
    if (!h) return false;
    if (h->due > cycles_) {
        sleep_cycles_ += h->due - cycles_;
        cycles_ = h->due;
    }
    return true;
}

// One emu_start: until a block boundary that needs attention.
int Core::execute() {
    if (eng_) return execute_engine();
    update_deadline();
    budget_hit_ = false;
    watch_mask_ = masked_pending();
    const uint32_t start = pc();
    cur_ = nullptr;
    xn_fetched_ = false;
    stop_at_hit_ = false;
    ++counts.emu_starts;
    in_emu_ = true;
    const int err = uc_.emu_start(uc_.handle, start | 1u, 0xFFFFFFFFu, 0, 0);
    in_emu_ = false;
    commit();
    if (py_error_) return kPyError;
    if (reset_pending_) return kReset;
    if (inline_fault_) {
        inline_fault_ = false;
        return kFault;
    }
    if (intr_fault_) {
        intr_fault_ = false;
        return kIntrFault;
    }
    if (err != 0) {
        uc_error_ = err;
        return kUcError;
    }
    if (budget_hit_) {
        budget_hit_ = false;
        return kBudget;
    }
    if (svc_) {
        svc_ = false;
        pend(11);
    } else if (bkpt_) {
        bkpt_ = false;
        set_pc(bkpt_pc_ + 2);
        return kBkpt;
    } else if (stop_) {
        return kStop;
    } else if (stop_at_hit_) {
        stop_at_hit_ = false;
        stop_at_resume_ = stop_at_pc_;
        return kStopAt;
    } else if (last_ && (last_->flags & Block::kWfi) && pc() == last_->start + last_->size) {
        sleeping_ = true;
    }
    return 0;
}

// After unicorn returns: count what retired of the block it was in.
void Core::commit() {
    last_ = cur_;
    if (!cur_) return;
    if (cur_flags_ & Block::kMaskOp) masks_valid_ = false;
    const uint32_t p = pc();
    const uint32_t done = cur_->index_of(p);
    instructions_ += done;
    cycles_ += done < cur_->n ? cur_->cycles_before(p) : cur_->cycles;
    cur_ = nullptr;
}

// Unicorn is about to run the block at `address`: the previous one retired. The boundary needs
// attention when an event is due or an interrupt waits on a mask the previous block may have
// lifted; it is attended to here (continue_inline) when nothing there needs Python, and the
// block then runs, or the handler of an exception taken there runs instead. Otherwise, and when
// the budget would be exceeded, the run stops before the block (it does not run). The PC unicorn
// holds inside a block hook may be stale (chained blocks do not store it), so the block's
// address is the return address of an exception taken here. A block in program flash while the
// flash module runs a command is a read collision: the run stops with a fault before it.
// The common boundary, inline in the hook: the previous block retires with no mask operation
// in it, and the next is in the table, within the budget and before the deadline, with no
// flash command running and the FPU watch over. Anything else takes on_block's whole
// sequence (the same checks in the same order).
void Core::on_block_cb(void*, uint64_t address, uint32_t size, void* user) {
    Core* c = static_cast<Core*>(user);
    const uint32_t a = static_cast<uint32_t>(address);
    if (!(c->cur_flags_ & Block::kMaskOp) && !c->ftfe.busy && !c->fpu_watch_) {
        const Slot& s = c->slot_for(a);
        const uint64_t instructions = c->instructions_ + (c->cur_ ? c->cur_n_ : 0);
        const uint64_t cycles = c->cycles_ + (c->cur_ ? c->cur_cycles_ : 0);
        if (s.block && s.size == size && !(s.flags & Block::kMaskOp) &&
            instructions + s.n <= c->instr_limit_ && cycles < c->deadline_) {
            ++c->counts.blocks;
            c->instructions_ = instructions;
            c->cycles_ = cycles;
            c->cur_ = s.block;
            c->cur_n_ = s.n;
            c->cur_flags_ = s.flags;
            c->cur_cycles_ = s.cycles;
            return;
        }
    }
    c->in_block_hook_ = true;
    c->on_block(address, size);
    c->in_block_hook_ = false;
}

void Core::on_block(uint64_t address, uint32_t size) {
    ++counts.blocks;
    const uint32_t a = static_cast<uint32_t>(address);
    if (cur_) {
        instructions_ += cur_n_;
        cycles_ += cur_cycles_;
        const bool mask_op = cur_flags_ & Block::kMaskOp;
        if (mask_op) masks_valid_ = false;
        const bool unmasked = mask_op && watch_mask_;
        cur_ = nullptr;
        if (unmasked) {
            pending_pc_ = a;
            if (!continue_inline()) {
                stop_now();
                return;
            }
            if (inline_taken_) return;
        }
    }
    const Slot* found = find_block(a, size);
    Slot b;
    if (found) {
        b = *found;             // copied: the pointer is good until the next lookup
    } else {
        ++counts.decodes;
        if (py_.decode(address, size) != 0) {       // Python has flagged the error and stopped
            return;
        }
        auto it = blocks_.find(a);
        if (it == blocks_.end()) {
            py_error_ = true;
            stop_now();
            return;
        }
        b = slot_of(it->second);
    }
    if (instructions_ + b.n > instr_limit_) {
        budget_hit_ = true;
        stop_now();
        return;
    }
    if (cycles_ >= deadline_) {
        pending_pc_ = a;
        if (!continue_inline()) {
            stop_now();
            return;
        }
        if (inline_taken_) {
            return;
        }
    }
    if (ftfe.busy && a < ftfe.flash_size) {        // a fetch from flash while it is programmed
        fault("ReadCollision", ftfe.collision(a), a, true, a);
        inline_fault_ = true;
        stop_now();
        return;
    }
    if (fpu_watch_ && (b.flags & (Block::kVfp | Block::kIsb))) {
        ++counts.fpu_checks;
        if (py_.fpu_check(address) == 0) {        // the chip would take a NOCP UsageFault
            stop_now();
            return;
        }
    }
    if (b.flags & Block::kMaskOp) masks_valid_ = false;
    cur_ = b.block;
    cur_n_ = b.n;
    cur_flags_ = b.flags;
    cur_cycles_ = b.cycles;
}

void Core::on_intr(uint32_t intno) {
    const uint32_t p = pc();
    if (intno == kExcReturnTrap) {
        // The handler's return: unstack here and go on (as run() would after a stop).
        commit();
        if (!return_from_exception(p | 1u)) {
            inline_fault_ = true;
            stop_now();
            return;
        }
        pending_pc_ = pc();
        if (!continue_inline()) stop_now();
        return;
    } else if (intno == kIntrSvc) {
        svc_ = true;
    } else if (intno == kIntrBkpt) {
        bkpt_ = true;
        bkpt_pc_ = p;
    } else {
        intr_fault_ = true;
        intr_number_ = intno;
        intr_pc_ = p;
    }
    (void)kIntrUndef;
    stop_now();
}

// -- NVIC writes ----------------------------------------------------------------------------
// NVIC_ISER0, NVIC_ICER0 and NVIC_IPR0's addresses (ARMv7-M ARM, B3.4.3) and the priority bits
// the MK64F12 implements (its SVD's nvicPrioBits, 4: the top four of each byte). An interrupt
// handler that masks its own IRQ around a critical section and sets its priority again (the
// USB port's dcd_int_disable/enable) then costs no call into Python.
constexpr uint32_t kNvicIser = 0xE000E100, kNvicIcer = 0xE000E180, kNvicIpr = 0xE000E400;
constexpr uint64_t kNvicPriorityMask = 0xF0;

bool Core::nvic_write(uint32_t address, unsigned size, uint64_t value) {
    if (address >= kNvicIpr) {              // a priority byte per exception 16 + n
        for (unsigned i = 0; i < size; ++i)
            priority_.at(16 + address - kNvicIpr + i) = static_cast<int>((value >> (8 * i)) &
                                                                         kNvicPriorityMask);
        attention();
        return true;
    }
    // Bits past the 128 exceptions the state holds name no interrupt: a write there is lost.
    const bool clear = address >= kNvicIcer;
    const uint32_t shift = 16 + 8 * (address - (clear ? kNvicIcer : kNvicIser));
    const u128 bits = shift < 128 ? static_cast<u128>(value) << shift : 0;
    if (clear) {
        enabled_ &= ~bits;
        return true;
    }
    enabled_ |= bits;
    attention();
    return true;
}

// -- MMIO -----------------------------------------------------------------------------------
int Core::route(uint32_t address, unsigned size) const {
    for (const Route& r : routes_) {
        if (r.lo <= address && address + size <= r.hi) return clocked[r.dev] ? r.dev : kNone;
    }
    return kNone;
}

bool Core::dev_read(int dev, uint32_t address, unsigned size, uint64_t& out) {
    switch (dev) {
        case kDwt: return dwt.read(*this, address, size, out);
        case kSysTick: return systick.read(*this, address, size, out);
        case kUart0: return uart0.read(*this, address, size, out);
        case kI2c0: return i2c0.read(*this, address, size, out);
        case kFtm0: return ftm0.read(*this, address, size, out);
        case kFtm3: return ftm3.read(*this, address, size, out);
        case kWdog: return wdog.read(*this, address, size, out);
        case kGpioIn: return gpio_in.read(address, size, out);
        case kFtfe: return ftfe.read(*this, address, size, out);
        case kUsb0: return usb0.read(*this, address, size, out);
        default: return false;
    }
}

bool Core::dev_write(int dev, uint32_t address, unsigned size, uint64_t value) {
    switch (dev) {
        case kDwt: return dwt.write(*this, address, size, value);
        case kSysTick: return systick.write(*this, address, size, value);
        case kUart0: return uart0.write(*this, address, size, value);
        case kI2c0: return i2c0.write(*this, address, size, value);
        case kFtm0: return ftm0.write(*this, address, size, value);
        case kFtm3: return ftm3.write(*this, address, size, value);
        case kWdog: return wdog.write(*this, address, size, value);
        case kFtfe: return ftfe.write(*this, address, size, value);
        case kUsb0: return usb0.write(*this, address, size, value);
        case kNvic: return nvic_write(address, size, value);
        case kGpioOut: return gpio_out.write(address, size, value);
        default: return false;
    }
}

// A native device takes the access when it is clocked and has the register; anything else
// (another device, a gated one, an offset no register occupies, or logging on) goes to
// Python, which logs it, models it or raises the bus fault.
uint64_t Core::mmio_read(uint32_t address, unsigned size) {
    if (!log_all) {
        const int dev = route(address, size);
        uint64_t v = 0;
        if (dev != kNone && dev_read(dev, address, size, v)) {
            ++counts.native_accesses;
            return v;
        }
    }
    ++counts.python_accesses;
    return py_.read(address, size);
}

void Core::mmio_write(uint32_t address, unsigned size, uint64_t value) {
    if (!log_all) {
        const int dev = route(address, size);
        if (dev != kNone) {
            const uint64_t masked = size >= 8 ? value : value & ((uint64_t{1} << (8 * size)) - 1);
            if (dev_write(dev, address, size, masked)) {
                ++counts.native_accesses;
                return;
            }
        }
    }
    ++counts.python_accesses;
    py_.write(address, size, value);
}

void Core::on_intr_cb(void*, uint32_t intno, void* user) {
    static_cast<Core*>(user)->on_intr(intno);
}

uint64_t Core::mmio_read_cb(void*, uint64_t offset, unsigned size, void* user) {
    auto* s = static_cast<Space*>(user);
    return s->core->mmio_read(s->base + static_cast<uint32_t>(offset), size);
}

void Core::mmio_write_cb(void*, uint64_t offset, unsigned size, uint64_t value, void* user) {
    auto* s = static_cast<Space*>(user);
    s->core->mmio_write(s->base + static_cast<uint32_t>(offset), size, value);
}

}  // namespace hqsim::mk64
