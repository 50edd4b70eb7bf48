// The emulated chip's core with its own CPU (sim/chip/thumb.hpp) in place of unicorn: the
// bus the engine sends every access outside flash and SRAM to, its registers under the
// numbers the core uses for exception entry and return, and one run of it between two
// boundaries that need the core (an event due, an interrupt pended, a mask changed, an
// exception return, WFI, SVC, a stop address, a fault, the first FP instruction).
//
// What differs from the unicorn path (mk64_core.cpp) is only how the instructions run:
// the event queue, the NVIC, exception entry and return, sleep and the device models are
// the same code. The engine knows the exact PC and cycle at every instruction, so an event
// is taken at the first instruction boundary at or after its cycle (unicorn's at the next
// translated block's), and a peripheral access costs a call, not a rollback of the CPU's
// state.
#include <cstdio>
#include <string>

#include "chip/mk64_core.hpp"

namespace hqsim::mk64 {

namespace {
constexpr uint32_t kEpsrBits = 0x0600FC00u | (1u << 24);    // ICI/IT and T
constexpr uint32_t kCcrUnalignTrp = 1u << 3, kCcrDiv0Trp = 1u << 4;

// The core's register numbers when the engine is the CPU (in place of unicorn's).
Regs engine_regs() {
    Regs r{0, 1, 2, 3, 12, kEngLr, kEngPc, kEngSp, kEngXpsr, kEngEpsr, kEngControl,
           kEngFpscr, kEngPrimask, kEngBasepri, kEngFaultmask, {}};
    for (int i = 0; i < 8; ++i) r.d[i] = kEngD0 + i;
    return r;
}
}  // namespace

bool EngineBus::read(uint32_t address, unsigned size, uint32_t& value) {
    return core_.engine_access(false, address, size, value);
}

bool EngineBus::write(uint32_t address, unsigned size, uint32_t value) {
    return core_.engine_access(true, address, size, value);
}

Core::Core(const PyCallbacks& py, std::vector<std::string> exception_names)
    : Core(Uc{}, engine_regs(), py, std::move(exception_names)) {
    eng_ = std::make_unique<thumb::Thumb>();
    eng_bus_ = std::make_unique<EngineBus>(*this);
    eng_->set_bus(eng_bus_.get());
}

// An access outside flash and SRAM: the peripheral spaces go to the devices as unicorn's
// MMIO callbacks do, with the time brought up to the accessing instruction (cycles and
// instructions before it); anything else is nothing (a bus fault). A Python model that
// deferred an error, or a reset the access caused, makes it fail too (the run stops before
// the instruction, which does not retire, and run() reports the error or the reset).
bool Core::engine_access(bool write, uint32_t address, unsigned size, uint32_t& value) {
    const bool mapped = (address - spaces_[0].base < space_sizes_[0] &&
                         address - spaces_[0].base + size <= space_sizes_[0]) ||
                        (address - spaces_[1].base < space_sizes_[1] &&
                         address - spaces_[1].base + size <= space_sizes_[1]);
    if (!mapped) return false;
    cycles_ = eng_->cycles();
    instructions_ = eng_->instructions();
    if (write) {
        mmio_write(address, size, value);
        // a flash command launched: fetches from flash are read collisions until it ends
        eng_->flash_fetch_limit = ftfe.busy ? 0 : thumb::kFlashSize;
    } else {
        value = static_cast<uint32_t>(mmio_read(address, size));
    }
    return !py_error_ && !reset_pending_;     // a reset: the access's instruction does not retire
}

uint64_t Core::engine_reg(int id) const {
    const thumb::Thumb& t = *eng_;
    if (id >= 0 && id < 16) return t.reg(static_cast<unsigned>(id));
    if (id >= kEngS0 && id < kEngEnd) return t.sreg(static_cast<unsigned>(id - kEngS0));
    if (id >= kEngD0 && id < kEngD0 + 16) {
        const unsigned n = 2 * static_cast<unsigned>(id - kEngD0);
        return uint64_t{t.sreg(n)} | uint64_t{t.sreg(n + 1)} << 32;
    }
    switch (id) {
        case kEngXpsr: return t.xpsr();
        case kEngEpsr: return t.xpsr() & kEpsrBits;
        case kEngApsr: return t.apsr();
        case kEngIpsr: return t.ipsr();
        case kEngControl: return t.control();
        case kEngFpscr: return t.fpscr();
        case kEngPrimask: return t.primask;
        case kEngBasepri: return t.basepri;
        case kEngFaultmask: return t.faultmask;
        case kEngMsp: return t.msp();
        case kEngPsp: return t.psp();
        default: return 0;
    }
}

void Core::set_engine_reg(int id, uint64_t value) {
    thumb::Thumb& t = *eng_;
    const uint32_t v = static_cast<uint32_t>(value);
    if (id >= 0 && id < 16) return t.set_reg(static_cast<unsigned>(id), v);
    if (id >= kEngS0 && id < kEngEnd) return t.set_sreg(static_cast<unsigned>(id - kEngS0), v);
    if (id >= kEngD0 && id < kEngD0 + 16) {
        const unsigned n = 2 * static_cast<unsigned>(id - kEngD0);
        t.set_sreg(n, v);
        t.set_sreg(n + 1, static_cast<uint32_t>(value >> 32));
        return;
    }
    switch (id) {
        case kEngXpsr: t.set_xpsr(v); break;
        case kEngEpsr: t.set_xpsr((t.xpsr() & ~kEpsrBits) | (v & kEpsrBits)); break;
        case kEngApsr: t.set_apsr(v); break;
        case kEngIpsr: t.set_ipsr(v); break;
        case kEngControl: t.set_control(v); break;
        case kEngFpscr: t.set_fpscr(v); break;
        case kEngPrimask: t.primask = v & 1; break;
        case kEngBasepri: t.basepri = v & 0xFF; break;
        case kEngFaultmask: t.faultmask = v & 1; break;
        case kEngMsp: t.set_msp(v); break;
        case kEngPsp: t.set_psp(v); break;
        default: break;
    }
}

// One run of the engine, from this boundary to the next that needs the core: the deadline
// is the next event's cycle, the limit what is left of the run's instruction budget.
int Core::execute_engine() {
    update_deadline();
    thumb::Thumb& t = *eng_;
    t.set_cycles(cycles_);
    t.set_instructions(instructions_);
    t.flash_fetch_limit = ftfe.busy ? 0 : thumb::kFlashSize;
    t.fpu_enabled = engine_fpu_;
    t.stop_on_isb = engine_watch_isb_;
    t.aspen = fpccr_ >> 31;
    t.div0_trap = ccr_ & kCcrDiv0Trp;
    t.unalign_trap = ccr_ & kCcrUnalignTrp;
    stop_at_hit_ = false;
    ++counts.emu_starts;
    in_emu_ = true;
    const uint64_t left = instr_limit_ > instructions_ ? instr_limit_ - instructions_ : 0;
    const thumb::Stop s = t.run(deadline_, left);
    in_emu_ = false;
    cycles_ = t.cycles();
    instructions_ = t.instructions();
    if (py_error_) return kPyError;
    if (reset_pending_) return kReset;
    return engine_stopped(s);
}

int Core::engine_stopped(thumb::Stop s) {
    thumb::Thumb& t = *eng_;
    const uint32_t pc = t.pc();
    switch (s) {
        case thumb::Stop::Deadline:
        case thumb::Stop::Requested:
            return 0;                     // run() sees to what is due or asked
        case thumb::Stop::Limit:
            return kBudget;
        case thumb::Stop::Wfi:
            sleeping_ = true;
            return 0;
        case thumb::Stop::Svc:
            pend(11);
            return 0;
        case thumb::Stop::MaskChanged:
            masks_valid_ = false;
            return 0;
        case thumb::Stop::ExcReturn:
            return return_from_exception(t.exc_return()) ? 0 : kFault;
        case thumb::Stop::Bkpt:
            bkpt_pc_ = pc;
            set_pc(pc + 2);
            return kBkpt;
        case thumb::Stop::StopAddress:
            stop_at_pc_ = pc;
            return kStopAt;
        case thumb::Stop::Undefined:
            intr_number_ = kIntrUndef;
            intr_pc_ = pc;
            return kIntrFault;
        case thumb::Stop::BusFault:
            if (ftfe.busy && t.fault_address() == pc && pc < ftfe.flash_size) {
                fault("ReadCollision", ftfe.collision(pc), pc, true, pc);
                return kFault;
            }
            return cpu_stop("bus_fault", t.stop_detail(), t.fault_address());
        case thumb::Stop::Unaligned:
            return cpu_stop("unaligned", t.stop_detail(), t.fault_address());
        case thumb::Stop::DivByZero:
            return cpu_stop("div_by_zero", t.stop_detail(), 0);
        case thumb::Stop::InvState:
            return cpu_stop("inv_state", "interworking branch to " + hex8(t.fault_address()),
                            t.fault_address());
        case thumb::Stop::NoFpu:
            return cpu_stop("no_fpu", "", pc);
        case thumb::Stop::Isb:
            return cpu_stop("isb", "", pc);
    }
    return cpu_stop("unknown", thumb::stop_name(s), pc);
}

int Core::cpu_stop(const char* reason, std::string detail, uint32_t address) {
    cpu_stop_.reason = reason;
    cpu_stop_.detail = std::move(detail);
    cpu_stop_.pc = eng_->pc();
    cpu_stop_.address = address;
    return kCpuStop;
}

}  // namespace hqsim::mk64
