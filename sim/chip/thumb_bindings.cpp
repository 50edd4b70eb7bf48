// heliquad._simcore.ThumbEngine: the engine's CPU (thumb.hpp) for its tests and benchmark.
// Thin: every rule lives in thumb*.cpp; this file converts arguments and adapts Python
// callables to the engine's Bus.
#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <stdexcept>
#include <string>

#include "chip/thumb.hpp"

namespace py = pybind11;
using namespace hqsim::thumb;

namespace {

// The owner's bus as two Python callables: read(address, size) -> int or None (nothing
// there), write(address, size, value) -> bool or None (None: accepted).
class PyBus : public Bus {
public:
    PyBus(py::function read, py::function write) : read_(std::move(read)), write_(std::move(write)) {}
    bool read(uint32_t address, unsigned size, uint32_t& value) override {
        const py::object r = read_(address, size);
        if (r.is_none()) return false;
        value = r.cast<uint32_t>();
        return true;
    }
    bool write(uint32_t address, unsigned size, uint32_t value) override {
        const py::object r = write_(address, size, value);
        return r.is_none() || r.cast<bool>();
    }

private:
    py::function read_, write_;
};

struct Engine {
    Thumb cpu;
    std::unique_ptr<PyBus> bus;
};

// The least a unicorn block hook costs (benchmarks/thumb_speed.py): a native callback that
// counts the blocks unicorn runs, installed through the library's uc_hook_add (its address
// and the engine handle taken from the unicorn binding, as sim/chip/machine.py does).
struct BlockCounter {
    uint64_t blocks = 0;
};
void count_block(void*, uint64_t, uint32_t, void* user) {
    ++static_cast<BlockCounter*>(user)->blocks;
}
using HookAdd = int (*)(void*, size_t*, int, void*, void*, uint64_t, uint64_t, ...);
constexpr int kUcHookBlock = 1 << 3;

}  // namespace

void bind_thumb(py::module_& m) {
    py::class_<BlockCounter>(m, "UnicornBlockCounter",
                             "Counts unicorn's blocks from a native block hook")
        .def(py::init<>())
        .def_readwrite("blocks", &BlockCounter::blocks)
        .def("install", [](BlockCounter& c, uintptr_t uc_hook_add, uintptr_t handle) {
            size_t hook = 0;
            const int err = reinterpret_cast<HookAdd>(uc_hook_add)(
                reinterpret_cast<void*>(handle), &hook, kUcHookBlock,
                reinterpret_cast<void*>(&count_block), &c, uint64_t{1}, uint64_t{0});
            if (err) throw std::runtime_error("uc_hook_add failed: " + std::to_string(err));
        });
    py::class_<Engine>(m, "ThumbEngine",
                       "The engine's Cortex-M4F CPU (sim/chip/thumb.hpp): flash and SRAM it "
                       "owns, a bus of Python callables for everything else")
        .def(py::init<>())
        .def("set_bus", [](Engine& e, py::function read, py::function write) {
            e.bus = std::make_unique<PyBus>(std::move(read), std::move(write));
            e.cpu.set_bus(e.bus.get());
        })
        .def("run", [](Engine& e, uint64_t deadline, uint64_t max_instructions) {
            return std::string(stop_name(e.cpu.run(deadline, max_instructions)));
        }, py::arg("deadline_cycles"), py::arg("max_instructions"))
        .def("request_stop", [](Engine& e) { e.cpu.request_stop(); })
        .def("lower_deadline", [](Engine& e, uint64_t c) { e.cpu.lower_deadline(c); })
        .def("jump", [](Engine& e, uint32_t pc) { e.cpu.jump(pc); },
             "move the PC as exception entry and return do (keeps the stop address reported)")
        .def("reg", [](Engine& e, unsigned n) { return e.cpu.reg(n & 15); })
        .def("set_reg", [](Engine& e, unsigned n, uint32_t v) { e.cpu.set_reg(n & 15, v); })
        .def("sreg", [](Engine& e, unsigned n) { return e.cpu.sreg(n & 31); })
        .def("set_sreg", [](Engine& e, unsigned n, uint32_t v) { e.cpu.set_sreg(n & 31, v); })
#define HQ_PROP(name) \
        .def_property(#name, [](Engine& e) { return e.cpu.name(); }, \
                      [](Engine& e, uint32_t v) { e.cpu.set_##name(v); })
        HQ_PROP(apsr) HQ_PROP(xpsr) HQ_PROP(itstate) HQ_PROP(msp) HQ_PROP(psp) HQ_PROP(control)
        HQ_PROP(ipsr) HQ_PROP(fpscr)
#undef HQ_PROP
#define HQ_FIELD(name) \
        .def_property(#name, [](Engine& e) { return e.cpu.name; }, \
                      [](Engine& e, decltype(Thumb::name) v) { e.cpu.name = v; })
        HQ_FIELD(primask) HQ_FIELD(faultmask) HQ_FIELD(basepri) HQ_FIELD(fpu_enabled)
        HQ_FIELD(div0_trap) HQ_FIELD(unalign_trap) HQ_FIELD(aspen) HQ_FIELD(fpdscr)
        HQ_FIELD(stop_on_isb) HQ_FIELD(flash_fetch_limit)
#undef HQ_FIELD
        .def_property("cycles", [](Engine& e) { return e.cpu.cycles(); },
                      [](Engine& e, uint64_t v) { e.cpu.set_cycles(v); })
        .def_property("instructions", [](Engine& e) { return e.cpu.instructions(); },
                      [](Engine& e, uint64_t v) { e.cpu.set_instructions(v); })
        .def_property_readonly("pc", [](Engine& e) { return e.cpu.pc(); })
        .def_property_readonly("handler_mode", [](Engine& e) { return e.cpu.handler_mode(); })
        .def_property_readonly("fault_address", [](Engine& e) { return e.cpu.fault_address(); })
        .def_property_readonly("exc_return", [](Engine& e) { return e.cpu.exc_return(); })
        .def_property_readonly("svc_number", [](Engine& e) { return e.cpu.svc_number(); })
        .def_property_readonly("stop_detail", [](Engine& e) { return e.cpu.stop_detail(); })
        .def("write", [](Engine& e, uint32_t address, py::bytes data) {
            const std::string s = data;
            e.cpu.write_memory(address, reinterpret_cast<const uint8_t*>(s.data()), s.size());
        })
        .def("read", [](Engine& e, uint32_t address, size_t n) {
            std::string s(n, '\0');
            if (!e.cpu.read_memory(address, reinterpret_cast<uint8_t*>(s.data()), n)) {
                throw std::out_of_range("not flash or SRAM");
            }
            return py::bytes(s);
        })
        .def("invalidate", [](Engine& e, uint32_t a, uint32_t n) { e.cpu.invalidate(a, n); })
        .def("add_stop_address", [](Engine& e, uint32_t a) { e.cpu.add_stop_address(a); })
        .def("clear_stop_addresses", [](Engine& e) { e.cpu.clear_stop_addresses(); })
        .def("cost", [](Engine& e, uint32_t address) {
            const Op* op = e.cpu.decoded(address);
            if (!op) throw std::out_of_range("not flash or SRAM");
            return py::make_tuple(op->size, op->cyc, op->cyc_it, (op->flags & kFp) != 0);
        }, "(size, cycles, cycles inside an IT block, is FP) of the instruction decoded there");
}
