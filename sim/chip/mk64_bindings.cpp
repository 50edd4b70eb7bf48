// heliquad._simcore.Mk64Core: the emulated MK64FX512's native hot path (mk64_core.hpp) as
// sim/chip's Machine and its device views use it. Thin: every rule lives in mk64_core.cpp and
// mk64_devices.cpp; this file converts arguments.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "chip/mk64_core.hpp"
#include "chip/pil_frames.hpp"
#include "sensor/mpu6050_emulator.hpp"

namespace py = pybind11;
using namespace hqsim::mk64;

namespace {

template <typename F>
F function(const py::dict& d, const char* name) {
    if (!d.contains(name)) throw std::invalid_argument(std::string("no address for ") + name);
    const uintptr_t a = d[name].cast<uintptr_t>();
    if (!a) throw std::invalid_argument(std::string("null address for ") + name);
    return reinterpret_cast<F>(a);
}

py::int_ to_int(u128 v) {
    py::int_ hi(static_cast<uint64_t>(v >> 64)), lo(static_cast<uint64_t>(v));
    return py::reinterpret_steal<py::int_>(
        PyNumber_Or(PyNumber_Lshift(hi.ptr(), py::int_(64).ptr()), lo.ptr()));
}

u128 from_int(const py::int_& v) {
    const py::int_ mask(~uint64_t{0});
    const py::object lo = v & mask;
    const py::object hi = (v >> py::int_(64)) & mask;
    return (static_cast<u128>(hi.cast<uint64_t>()) << 64) | lo.cast<uint64_t>();
}

Layout layout(const py::dict& d) {
    Layout L;
    L.base = d["base"].cast<uint32_t>();
    L.span = d["span"].cast<uint32_t>();
    L.reg_at = d["reg_at"].cast<std::vector<int>>();
    L.width = d["width"].cast<std::vector<uint8_t>>();
    L.reset = d["reset"].cast<std::vector<uint32_t>>();
    L.k = d["k"].cast<std::unordered_map<std::string, uint32_t>>();
    if (L.reg_at.size() != L.span || L.width.size() != L.span || L.reset.size() != L.span) {
        throw std::invalid_argument("register layout: reg_at, width and reset need one entry a "
                                    "byte");
    }
    for (uint32_t at = 0; at < L.span; ++at) {
        const int reg = L.reg_at[at];
        if (reg >= 0 && (static_cast<uint32_t>(reg) > at || at - reg >= L.width[reg])) {
            throw std::invalid_argument("register layout: a byte outside its register");
        }
    }
    return L;
}

Ftm& ftm_of(Core& c, int dev) {
    Ftm* f = c.ftm(dev);
    if (!f) throw std::invalid_argument("no FTM is native device " + std::to_string(dev));
    return *f;
}

int channel(int ch) {
    if (ch < 0 || ch >= Ftm::kChannels) throw py::index_error("no FTM channel " + std::to_string(ch));
    return ch;
}

py::object optional_double(bool known, double value) {
    return known ? py::object(py::float_(value)) : py::object(py::none());
}

py::object optional_cycle(int64_t c) { return c < 0 ? py::object(py::none()) : py::int_(c); }

py::tuple transfer_tuple(const I2c::Transfer& t) {
    return py::make_tuple(t.address, t.read, t.acked, t.start_cycle,
                          py::bytes(reinterpret_cast<const char*>(t.data.data()), t.data.size()),
                          optional_cycle(t.end_cycle), t.start_s);
}

}  // namespace

// A pin for Mk64Core.pin_edge and PilFrames: (PDIR address, bit number, FTM3 channel or -1).
static PinEdges::Pin edge_pin(const py::handle& pin) {
    const auto [pdir, n, ch] = pin.cast<std::tuple<uint32_t, int, int>>();
    if (pdir == 0 || n < 0 || n > 31 || ch < -1 || ch >= Ftm::kChannels) {
        throw py::value_error("a pin is (its PDIR address, its bit 0..31, its FTM3 channel "
                              "0..7 or -1)");
    }
    return {pdir, uint32_t{1} << n, ch};
}

// The drop-in's plain frames (pil_frames.hpp; sim/chip/pil/drop_in.py drives them).
static void bind_pil_frames(py::module_& m) {
    using P = PilFrames;
    py::class_<P>(m, "PilFrames", "The processor-in-the-loop drop-in's plain frames, natively.")
        .def(py::init([](Core& c) {
                 auto p = std::make_unique<P>(c);
                 p->before_wait = [] { return static_cast<void*>(PyEval_SaveThread()); };
                 p->after_wait = [](void* s) { PyEval_RestoreThread(static_cast<PyThreadState*>(s)); };
                 return p;
             }),
             py::keep_alive<1, 2>())
        .def("configure", [](P& p, const py::dict& d) {
            P::Config c;
            c.sim_fd = d["sim_fd"].cast<int>();
            c.tel_fd = d["tel_fd"].cast<int>();
            c.outputs_at = d["outputs_at"].cast<uint32_t>();
            c.wait_at = d["wait_at"].cast<uint32_t>();
            c.card_wait_at = d["card_wait_at"].cast<uint32_t>();
            c.report_address = d["report_address"].cast<uint32_t>();
            c.mpu = d["mpu"].cast<size_t>();
            c.usb = d["usb"].cast<bool>();
            c.esc_lo = d["esc_lo"].cast<uint32_t>();
            c.esc_hi = d["esc_hi"].cast<uint32_t>();
            c.loop_limit_s = d["loop_limit_s"].cast<double>();
            c.drain_limit_s = d["drain_limit_s"].cast<double>();
            c.drain_margin_s = d["drain_margin_s"].cast<double>();
            c.system_id = d["system_id"].cast<uint8_t>();
            c.component_id = d["component_id"].cast<uint8_t>();
            c.telemetry_chunk = d["telemetry_chunk"].cast<size_t>();
            c.quiet_ms = d["quiet_ms"].cast<int>();
            const py::object pins = d["rc_pins"];
            c.rc_native = !pins.is_none();
            if (c.rc_native) {
                // One per RC channel: (PDIR address, bit, FTM3 channel), or None for a pin
                // the pin model drives (PDIR address 0 here).
                for (const py::handle pin : pins.cast<py::list>()) {
                    c.rc_pins.push_back(pin.is_none() ? PinEdges::Pin{0, 0, -1} : edge_pin(pin));
                    if (!pin.is_none() && c.rc_pins.back().ftm3_channel < 0) {
                        throw py::value_error("rc_pins: an RC pin is on an FTM3 channel");
                    }
                }
                if (c.rc_pins.size() != 7) throw py::value_error("rc_pins: one per RC channel, 7");
            }
            p.config = std::move(c);
        })
        .def("serve", &P::serve, py::arg("wait_ms"), py::arg("max_frames"))
        .def_readwrite("last_frame", &P::last_frame)
        .def_readwrite("frames", &P::frames)
        .def_readonly("bytes_read", &P::bytes_read)
        .def_readwrite("seq", &P::seq)
        .def_readwrite("rc_last", &P::rc_last)
        .def_readwrite("rc_age", &P::rc_age)
        .def_readwrite("ftfe_changes", &P::ftfe_changes)
        .def_readwrite("waits", &P::waits)
        .def_readwrite("in_card_wait", &P::in_card_wait)
        .def_readonly("phase", &P::phase)
        .def_readonly("code", &P::code)
        .def_readonly("frame_time_us", &P::frame_time_us)
        .def_readonly("frame_sync", &P::frame_sync)
        .def_readonly("drain_until", &P::drain_until)
        .def_readonly("drain_after", &P::drain_after)
        .def_property("input", [](const P& p) { return py::bytes(p.input); },
                      [](P& p, const py::bytes& b) { p.input = b; })
        .def_property("telemetry", [](const P& p) { return py::bytes(p.telemetry); },
                      [](P& p, const py::bytes& b) { p.telemetry = b; })
        .def_property("reply", [](const P& p) { return py::bytes(p.reply); },
                      [](P& p, const py::bytes& b) { p.reply = b; })
        .def("take_step_cycles", [](P& p) {
            std::vector<uint32_t> out;
            out.swap(p.step_cycles);
            return out;
        });
}

void bind_mk64(py::module_& m) {
    py::class_<Usb::Host>(m, "Mk64UsbHost",
                          "The USB host's state its native bulk IN polls share with usb_host.py.")
        .def_readwrite("frame", &Usb::Host::frame)
        .def_readwrite("next_sof", &Usb::Host::next_sof)
        .def_readwrite("sof_end", &Usb::Host::sof_end)
        .def_readwrite("in_flight", &Usb::Host::in_flight)
        .def_readwrite("waiting", &Usb::Host::waiting)
        .def_readwrite("gate", &Usb::Host::gate)
        .def_readwrite("address", &Usb::Host::address)
        .def_readwrite("endpoint", &Usb::Host::endpoint)
        .def_readwrite("nak_frame", &Usb::Host::nak_frame)
        .def_readwrite("in_nak", &Usb::Host::in_nak)
        .def_readwrite("in_nak_cycle", &Usb::Host::in_nak_cycle)
        .def_readonly("job", &Usb::Host::job)
        .def_readonly("flight_bd", &Usb::Host::flight_bd)
        .def_readonly("flight_data", &Usb::Host::flight_data)
        .def_readwrite("reading", &Usb::Host::reading)
        .def_readwrite("toggle", &Usb::Host::toggle)
        .def_readwrite("max_packet", &Usb::Host::max_packet)
        .def_readwrite("silences", &Usb::Host::silences)
        .def_readwrite("toggle_errors", &Usb::Host::toggle_errors)
        .def("receive", [](Usb::Host& h, const py::bytes& data) {
            h.received += static_cast<std::string>(data);
        })
        .def("take_received", [](Usb::Host& h) {
            py::bytes out(h.received);
            h.received.clear();
            return out;
        })
        .def("new_job", [](Usb::Host& h) {
            h.job = true;
            ++h.generation;
            h.nak_frame = -1;
        })
        .def("drop_job", [](Usb::Host& h) { h.job = false; });
    bind_pil_frames(m);
    py::class_<Usb>(m, "Mk64Usb", "USB0's registers and SIE state the native path keeps.")
        .def_readwrite("native", &Usb::native)
        .def_readwrite("frame", &Usb::frame)
        .def_readwrite("in_reset", &Usb::in_reset)
        .def_readwrite("clock_ok", &Usb::clock_ok)
        .def_readwrite("dma_reads_ram", &Usb::dma_reads_ram)
        .def_readwrite("dma_writes_ram", &Usb::dma_writes_ram)
        .def_readonly("host", &Usb::host)
        .def("reg", [](const Usb& u, uint32_t offset) { return u.v.at(offset); })
        .def("set_reg", [](Usb& u, uint32_t offset, uint8_t value) { u.v.at(offset) = value; })
        .def("reset_registers", &Usb::reset_registers)
        .def("odd", [](const Usb& u, int ep, int tx) { return u.odd[ep & 15][tx & 1]; })
        .def("set_odd", [](Usb& u, int ep, int tx, int value) {
            u.odd[ep & 15][tx & 1] = static_cast<uint8_t>(value & 1);
        })
        .def("reset_odd", [](Usb& u) { for (auto& e : u.odd) e[0] = e[1] = 0; });
    py::class_<Core>(m, "Mk64Core",
                     "The emulated MK64FX512's hot path (sim/chip): block accounting, events, "
                     "NVIC, exceptions, WFI and the DWT/SysTick/UART0/I2C0/FTM0/FTM3/WDOG models.")
        .def(py::init([](const py::dict& uc, const py::dict& regs, const py::dict& callbacks,
                         std::vector<std::string> names) {
                 Uc u;
                 u.handle = reinterpret_cast<void*>(uc["handle"].cast<uintptr_t>());
                 u.emu_start = function<decltype(u.emu_start)>(uc, "uc_emu_start");
                 u.emu_stop = function<decltype(u.emu_stop)>(uc, "uc_emu_stop");
                 u.reg_read = function<decltype(u.reg_read)>(uc, "uc_reg_read");
                 u.reg_write = function<decltype(u.reg_write)>(uc, "uc_reg_write");
                 u.reg_write2 = function<decltype(u.reg_write2)>(uc, "uc_reg_write2");
                 u.reg_read_batch = function<decltype(u.reg_read_batch)>(uc, "uc_reg_read_batch");
                 u.reg_write_batch =
                     function<decltype(u.reg_write_batch)>(uc, "uc_reg_write_batch");
                 u.mem_read = function<decltype(u.mem_read)>(uc, "uc_mem_read");
                 u.mem_write = function<decltype(u.mem_write)>(uc, "uc_mem_write");
                 u.hook_add = function<decltype(u.hook_add)>(uc, "uc_hook_add");
                 u.mmio_map = function<decltype(u.mmio_map)>(uc, "uc_mmio_map");
                 Regs r{};
                 r.r0 = regs["R0"].cast<int>(); r.r1 = regs["R1"].cast<int>();
                 r.r2 = regs["R2"].cast<int>(); r.r3 = regs["R3"].cast<int>();
                 r.r12 = regs["R12"].cast<int>(); r.lr = regs["LR"].cast<int>();
                 r.pc = regs["PC"].cast<int>(); r.sp = regs["SP"].cast<int>();
                 r.xpsr = regs["XPSR"].cast<int>(); r.epsr = regs["EPSR"].cast<int>(); r.control = regs["CONTROL"].cast<int>();
                 r.fpscr = regs["FPSCR"].cast<int>(); r.primask = regs["PRIMASK"].cast<int>();
                 r.basepri = regs["BASEPRI"].cast<int>();
                 r.faultmask = regs["FAULTMASK"].cast<int>();
                 for (int i = 0; i < 8; ++i) r.d[i] = regs[("D" + std::to_string(i)).c_str()].cast<int>();
                 PyCallbacks p;
                 p.decode = function<decltype(p.decode)>(callbacks, "decode");
                 p.fpu_check = function<decltype(p.fpu_check)>(callbacks, "fpu_check");
                 p.read = function<decltype(p.read)>(callbacks, "read");
                 p.write = function<decltype(p.write)>(callbacks, "write");
                 return new Core(u, r, p, std::move(names));
             }),
             py::arg("uc"), py::arg("regs"), py::arg("callbacks"), py::arg("exception_names"))
        .def_static("with_engine", [](const py::dict& callbacks, std::vector<std::string> names) {
            PyCallbacks p;
            p.read = function<decltype(p.read)>(callbacks, "read");
            p.write = function<decltype(p.write)>(callbacks, "write");
            return std::make_unique<Core>(p, std::move(names));
        }, py::arg("callbacks"), py::arg("exception_names"),
           "The core with its own CPU (the engine, sim/chip/thumb.hpp) in place of unicorn")
        .def_property_readonly("has_engine", &Core::has_engine)
        .def_static("engine_registers", []() {
            py::dict d;
            const char* special[] = {"XPSR", "EPSR", "CONTROL", "FPSCR", "PRIMASK", "BASEPRI",
                                     "FAULTMASK", "MSP", "PSP", "APSR", "IPSR"};
            for (int i = 0; i < 13; ++i) d[py::str("R" + std::to_string(i))] = i;
            d["SP"] = static_cast<int>(kEngSp); d["LR"] = static_cast<int>(kEngLr);
            d["PC"] = static_cast<int>(kEngPc);
            for (int i = 0; i < 11; ++i) d[special[i]] = static_cast<int>(kEngXpsr) + i;
            for (int i = 0; i < 16; ++i) d[py::str("D" + std::to_string(i))] = kEngD0 + i;
            for (int i = 0; i < 32; ++i) d[py::str("S" + std::to_string(i))] = kEngS0 + i;
            return d;
        }, "register name -> number for reg()/set_reg() when the engine is the CPU")
        .def("reg", [](const Core& c, int id) { return c.reg(id); })
        .def("set_reg", [](Core& c, int id, uint32_t v) { c.set_reg(id, v); })
        .def("mem_read", [](const Core& c, uint32_t address, size_t n) {
            std::string s(n, '\0');
            if (!c.mem_read(address, s.data(), n)) throw py::index_error("not flash or SRAM");
            return py::bytes(s);
        })
        .def("mem_write", [](Core& c, uint32_t address, const py::bytes& data) {
            const std::string s = data;
            if (!c.mem_write(address, s.data(), s.size())) throw py::index_error("not flash or SRAM");
        })
        .def_property("engine_fpu", [](const Core& c) { return c.engine_fpu_; },
                      [](Core& c, bool on) {
                          c.engine_fpu_ = on;
                          if (c.has_engine()) c.engine()->fpu_enabled = on;
                      }, "the engine runs FP instructions (False until the first is judged)")
        .def_property("engine_watch_isb", [](const Core& c) { return c.engine_watch_isb_; },
                      [](Core& c, bool on) {
                          c.engine_watch_isb_ = on;
                          if (c.has_engine()) c.engine()->stop_on_isb = on;
                      }, "the engine stops after each ISB (kCpuStop 'isb')")
        .def("cpu_stop", [](const Core& c) {
            const CpuStop& s = c.cpu_stop_;
            return py::make_tuple(s.reason, s.pc, s.address, s.detail);
        }, "(reason, pc, address, detail) of the engine's last kCpuStop")
        .def("install", &Core::install)
        .def("install_tlb", &Core::install_tlb)
        .def_readonly("xn_fetched", &Core::xn_fetched_)
        .def_readonly("xn_fetch", &Core::xn_fetch_)
        .def("reset", &Core::reset, py::arg("core_hz"))
        // blocks
        .def("add_block", [](Core& c, uint32_t start, uint32_t size, uint32_t n, uint64_t cycles,
                             uint32_t flags, std::vector<uint32_t> addrs, std::vector<uint32_t> cum) {
            Block b;
            b.start = start; b.size = size; b.n = n; b.cycles = cycles; b.flags = flags;
            b.addrs = std::move(addrs); b.cum = std::move(cum);
            c.add_block(std::move(b));
        })
        .def("clear_blocks", &Core::clear_blocks)
        .def("cur_start", [](const Core& c) -> int64_t { return c.cur() ? c.cur()->start : -1; })
        // time
        .def_readwrite("cycles", &Core::cycles_)
        .def_readwrite("instructions", &Core::instructions_)
        .def_readwrite("sleep_cycles", &Core::sleep_cycles_)
        .def_readonly("handler_instructions", &Core::handler_instructions_)
        .def_readonly("handler_cycles", &Core::handler_cycles_)
        .def_property_readonly("core_hz", &Core::core_hz)
        .def_property_readonly("bus_hz", &Core::bus_hz)
        .def("pc", &Core::pc)
        .def("now", &Core::now)
        .def("instructions_now", &Core::instructions_now)
        .def("seconds", &Core::seconds)
        .def("set_clocks", &Core::set_clocks)
        .def_property("fixed_hz", &Core::fixed_hz, &Core::set_fixed_hz,
                      "MCGFFCLK, the FTMs' fixed-frequency clock (the chip sets it)")
        // events
        .def("at", [](Core& c, uint64_t cycle, bool scaled) { return c.at(cycle, Ev::Python, scaled); })
        .def("time_limit", [](Core& c, uint64_t cycle) { return c.at(cycle, Ev::TimeLimit, true); })
        .def_readwrite("time_up", &Core::time_up_)
        .def("set_drain", [](Core& c, int mode, uint64_t after) {
            if (mode < Core::kNoDrain || mode > Core::kDrainUart) {
                throw std::invalid_argument("drain: 0 none, 1 USB, 2 UART0");
            }
            c.drain_ = mode;
            c.drain_after_ = after;
        }, "end runs once the board's USB IN queue (1: a bulk IN poll NAKed after `after`) or "
           "UART0 (2) has drained; 0: never")
        .def("cancel", &Core::cancel)
        .def("live", &Core::live)
        .def("event_due", [](const Core& c, uint64_t seq) -> py::object {
            uint64_t due = 0;
            return c.event_due(seq, due) ? py::object(py::int_(due)) : py::object(py::none());
        })
        .def("next_event_due", &Core::next_event_due)
        .def("advance", &Core::advance)
        .def("attention", &Core::attention)
        // running
        .def("run", &Core::run, py::arg("instr_limit"), py::call_guard<py::gil_scoped_release>())
        .def_readonly("py_event", &Core::py_event_)
        .def("request_stop", &Core::request_stop)
        .def("clear_stop", &Core::clear_stop)
        .def("request_error", &Core::request_error)
        .def("clear_error", &Core::clear_error)
        .def("stop_now", &Core::stop_now)
        .def_readonly("uc_error", &Core::uc_error_)
        .def_property_readonly("reset_pending", &Core::reset_pending)
        .def("take_reset", [](Core& c) -> py::object {
            if (!c.reset_pending()) return py::none();
            auto r = c.take_reset();
            return py::make_tuple(r.first, r.second);
        }, "(source, message) of the reset a native model caused, forgotten; None if none")
        .def("fault", [](const Core& c) {
            const FaultInfo& f = c.fault_;
            return py::make_tuple(f.kind, f.message, f.pc,
                                  f.has_address ? py::object(py::int_(f.address)) : py::object(py::none()));
        })
        .def_readonly("intr_number", &Core::intr_number_)
        .def_readonly("intr_pc", &Core::intr_pc_)
        .def_readonly("bkpt_pc", &Core::bkpt_pc_)
        .def("add_stop_at", &Core::add_stop_at)
        .def_property_readonly("stop_at_pc", &Core::stop_at_pc)
        .def_readwrite("sleeping", &Core::sleeping_)
        .def_readwrite("fpu_watch", &Core::fpu_watch_)
        .def_readwrite("log_all", &Core::log_all)
        .def_readwrite("keep_records", &Core::keep_records)
        .def_readwrite("inline_boundaries", &Core::inline_boundaries,
                       "attend to block boundaries inside emu_start (False: stop at each, as "
                       "a reference for tests)")
        .def("counts", [](const Core& c) {
            const Core::Counts& k = c.counts;
            py::dict d;
            d["blocks"] = k.blocks; d["decodes"] = k.decodes;
            d["native_accesses"] = k.native_accesses; d["python_accesses"] = k.python_accesses;
            d["native_events"] = k.native_events; d["python_events"] = k.python_events;
            d["exceptions"] = k.exceptions; d["emu_starts"] = k.emu_starts;
            d["fpu_checks"] = k.fpu_checks; d["inline_boundaries"] = k.inline_boundaries;
            return d;
        })
        // NVIC
        .def_property("enabled", [](const Core& c) { return to_int(c.enabled_); },
                      [](Core& c, const py::int_& v) { c.enabled_ = from_int(v); })
        .def_property("pending", [](const Core& c) { return to_int(c.pending_); },
                      [](Core& c, const py::int_& v) { c.pending_ = from_int(v); })
        .def_property("irq_lines", [](const Core& c) { return to_int(c.irq_lines_); },
                      [](Core& c, const py::int_& v) { c.irq_lines_ = from_int(v); })
        .def("priority", [](const Core& c, int n) { return c.priority_.at(n); })
        .def("set_priority", [](Core& c, int n, int p) { c.priority_.at(n) = p; })
        .def("priorities", [](const Core& c) { return c.priority_; })
        .def_readwrite("prigroup", &Core::prigroup_)
        .def_readwrite("vtor", &Core::vtor_)
        .def_readwrite("ccr", &Core::ccr_)
        .def_readwrite("fpccr", &Core::fpccr_)
        .def_property_readonly("active", [](const Core& c) { return c.active_; })
        .def("set_irq", &Core::set_irq)
        .def("pend", &Core::pend)
        .def("unpend", &Core::unpend)
        .def("pending_exception", [](const Core& c) -> py::object {
            const int n = c.pending_exception();
            return n < 0 ? py::object(py::none()) : py::object(py::int_(n));
        })
        .def("preempts", [](Core& c, int number, bool ignore_primask) {
            c.forget_masks();                    // Python may have written them
            return c.preempts(number, ignore_primask);
        }, py::arg("number"), py::arg("ignore_primask") = false)
        .def("execution_priority", [](Core& c, bool ignore_primask) {
            c.forget_masks();                    // Python may have written them
            return c.execution_priority(ignore_primask);
        }, py::arg("ignore_primask") = false)
        .def("exception_log", [](const Core& c) {
            py::list out;
            for (const auto& e : c.exception_log_) {
                out.append(py::make_tuple(e.cycle, e.enter ? "enter" : "return", e.number));
            }
            return out;
        })
        .def("exception_counts", [](const Core& c) { return c.exception_counts_; })
        // devices
        .def("add_route", &Core::add_route)
        .def("set_clocked", [](Core& c, int dev, bool on) { c.clocked[dev] = on; })
        .def("set_gpio_input", [](Core& c, uint32_t address, uint32_t value) {
            c.gpio_in.set(address, value);
        })
        .def("set_gpio_output", [](Core& c, uint32_t base, uint32_t pdor) {
            c.gpio_out.set(base, pdor);
        })
        // An edge driven onto input pins at `cycle` (unscaled): pins as (PDIR address, bit
        // number, FTM3 channel or -1).
        .def("pin_edge", [](Core& c, uint64_t cycle, bool level, const py::list& pins) {
            std::vector<PinEdges::Pin> list;
            for (const py::handle pin : pins) list.push_back(edge_pin(pin));
            c.pin_edges.add(c, cycle, level, std::move(list));
        })
        .def_property_readonly("pin_edges_pending", [](const Core& c) {
            return c.pin_edges.edges.size();
        })
        .def("dev_read", [](Core& c, int dev, uint32_t address, unsigned size) -> py::object {
            uint64_t v = 0;
            return c.dev_read(dev, address, size, v) ? py::object(py::int_(v)) : py::object(py::none());
        })
        .def("dev_write", &Core::dev_write)
        // DWT
        .def("dwt_setup", [](Core& c, uint32_t ctrl, uint32_t cyccnt, uint32_t ctrl_reset) {
            c.dwt.ctrl_address = ctrl; c.dwt.cyccnt_address = cyccnt; c.dwt.ctrl_reset = ctrl_reset;
            c.dwt.reset();
        })
        .def("dwt_state", [](const Core& c) {
            return py::make_tuple(c.dwt.ctrl, c.dwt.base_value, optional_cycle(c.dwt.since),
                                  c.dwt.trcena);
        })
        .def("dwt_cyccnt", [](const Core& c, uint64_t now) { return c.dwt.cyccnt(now); })
        .def("dwt_trace", [](Core& c, bool trcena, uint64_t now) {
            c.dwt.trcena = trcena;
            c.dwt.sync(now);
        })
        // SysTick
        .def("systick_setup", [](Core& c, uint32_t base, uint32_t calib, uint32_t csr_reset) {
            c.systick.base = base; c.systick.calib = calib; c.systick.csr_reset = csr_reset;
            c.systick.reset();
        })
        .def("systick_state", [](const Core& c) {
            const SysTick& s = c.systick;
            return py::make_tuple(s.csr, s.rvr, optional_cycle(s.zero_at), s.stopped_value,
                                  std::vector<uint64_t>(s.wraps.begin(), s.wraps.end()));
        })
        .def("systick_value", [](const Core& c, uint64_t now) { return c.systick.value(now); })
        // UART0
        .def("uart_setup", [](Core& c, const py::dict& d) {
            Uart& u = c.uart0;
            u.L = layout(d);
            u.irq_rxtx = d["irq_rxtx"].cast<int>();
            u.irq_err = d["irq_err"].cast<int>();
            u.depth = d["depth"].cast<int>();
            u.setup();
            u.reset(c);
        })
        .def("uart_reg", [](const Core& c, uint32_t offset) { return c.uart0.v.at(offset); })
        .def("uart_state", [](Core& c) {
            Uart& u = c.uart0;
            u.catch_up(c, c.now());
            py::dict d;
            d["tx"] = std::vector<uint8_t>(u.tx.begin(), u.tx.end());
            d["rx"] = std::vector<uint8_t>(u.rx.begin(), u.rx.end());
            d["rx_queue"] = u.rx_queue.size();
            d["shifting"] = u.shifting < 0 ? py::object(py::none())
                            : u.shifting == Uart::kPreamble ? py::object(py::str("preamble"))
                                                            : py::object(py::int_(u.shifting));
            d["overruns"] = u.overruns; d["tx_overflows"] = u.tx_overflows;
            d["rdrf"] = u.rdrf; d["flags"] = u.flags; d["s1"] = u.s1();
            d["tdre"] = u.tdre(); d["tc"] = u.tc();
            return d;
        })
        .def("uart_take_sent", [](Core& c) {
            std::vector<std::pair<uint64_t, uint8_t>> out;
            c.uart0.catch_up(c, c.now());
            out.swap(c.uart0.sent);
            return out;
        })
        .def("uart_take_sent_bytes", [](Core& c) {
            c.uart0.catch_up(c, c.now());
            return py::bytes(c.uart0.take_sent_bytes());
        })
        .def("uart_receive", [](Core& c, const py::bytes& data) {
            const std::string s = data;
            c.uart0.receive(c, reinterpret_cast<const uint8_t*>(s.data()), s.size());
        })
        .def("uart_take_notes", [](Core& c) {
            auto out = std::move(c.uart0.notes);
            c.uart0.notes.clear();
            return out;
        })
        .def("uart_frame_cycles", [](const Core& c) { return c.uart0.frame_cycles(c); })
        .def("uart_baud", [](const Core& c) { return c.uart0.baud(c); })
        .def("uart_frame_bits", [](const Core& c) { return c.uart0.frame_bits(); })
        // I2C0
        .def("i2c_setup", [](Core& c, const py::dict& d) {
            I2c& i = c.i2c0;
            i.L = layout(d);
            i.irq = d["irq"].cast<int>();
            i.scl_divider = d["scl_divider"].cast<std::vector<uint32_t>>();
            i.setup();
            i.reset();
        })
        .def("i2c_reg", [](const Core& c, uint32_t offset) { return c.i2c0.v.at(offset); })
        .def("i2c_take_transfers", [](Core& c) {
            I2c& i = c.i2c0;
            const size_t done = i.transfers.size() - (i.open ? 1 : 0);
            py::list out;
            for (size_t k = 0; k < done; ++k) out.append(transfer_tuple(i.transfers[k]));
            i.transfers.erase(i.transfers.begin(), i.transfers.begin() + static_cast<long>(done));
            return out;
        })
        .def("i2c_open_transfer", [](const Core& c) -> py::object {
            const I2c& i = c.i2c0;
            return i.open ? py::object(transfer_tuple(i.transfers.back())) : py::object(py::none());
        })
        .def("i2c_take_errors", [](Core& c) {
            auto out = std::move(c.i2c0.errors);
            c.i2c0.errors.clear();
            return out;
        })
        .def("i2c_hold_scl", [](Core& c, bool held) { c.i2c0.hold_scl(c, held); })
        .def_property_readonly("i2c_scl_held", [](const Core& c) { return c.i2c0.scl_held; })
        .def_property("i2c_pins_connected", [](const Core& c) { return c.i2c0.pins_connected; },
                      [](Core& c, bool v) { c.i2c0.pins_connected = v; })
        .def("i2c_scl_hz", [](const Core& c) { return c.i2c0.scl_hz(c); })
        .def("i2c_byte_in_flight", [](const Core& c) { return c.i2c0.event != 0; })
        // FTM0, FTM3 (by native device number)
        .def("ftm_setup", [](Core& c, int dev, const py::dict& d) {
            Ftm& f = ftm_of(c, dev);
            f.L = layout(d);
            f.irq = d["irq"].cast<int>();
            f.tof_kind = dev == Core::kFtm0 ? Ev::Ftm0Tof : Ev::Ftm3Tof;
            f.setup();
            f.reset();
        })
        .def("ftm_reg", [](Core& c, int dev, uint32_t offset) { return ftm_of(c, dev).v.at(offset); })
        .def("ftm_count", [](Core& c, int dev) { return ftm_of(c, dev).count(c, c.now()); })
        .def("ftm_clock_hz", [](Core& c, int dev) { return ftm_of(c, dev).clock_hz(c); })
        .def("ftm_cycles_per_tick", [](Core& c, int dev) {
            const double rate = ftm_of(c, dev).ticks_per_cycle(c);
            return rate != 0.0 ? 1 / rate : 0.0;
        })
        .def("ftm_next_tick", [](Core& c, int dev, uint64_t cycle) -> py::object {
            uint64_t tick = 0;
            return ftm_of(c, dev).next_tick(c, cycle, tick) ? py::object(py::int_(tick))
                                                             : py::object(py::none());
        })
        .def("ftm_mode", [](Core& c, int dev, int ch) { return ftm_of(c, dev).mode(channel(ch)); })
        .def("ftm_period_s", [](Core& c, int dev) {
            double s = 0.0;
            const bool known = ftm_of(c, dev).period_s(c, s);
            return optional_double(known, s);
        })
        .def("ftm_pulse_s", [](Core& c, int dev, int ch) {
            double s = 0.0;
            const bool known = ftm_of(c, dev).pulse_s(c, channel(ch), s);
            return optional_double(known, s);
        })
        .def("ftm_commanded_value", [](Core& c, int dev, int ch) -> py::object {
            uint32_t value = 0;
            return ftm_of(c, dev).commanded_value(c, channel(ch), value) ? py::object(py::int_(value))
                                                                   : py::object(py::none());
        })
        .def("ftm_commanded_values", [](Core& c, int dev) {
            Ftm& f = ftm_of(c, dev);
            py::list out;
            for (int ch = 0; ch < Ftm::kChannels; ++ch) {
                uint32_t value = 0;
                out.append(f.commanded_value(c, ch, value) ? py::object(py::int_(value))
                                                           : py::object(py::none()));
            }
            return out;
        })
        .def("ftm_edge", [](Core& c, int dev, int ch, bool rising) {
            ftm_of(c, dev).edge(c, channel(ch), rising);
        })
        .def("ftm_take_captures", [](Core& c, int dev) {
            Ftm& f = ftm_of(c, dev);
            py::list out;
            for (const auto& k : f.captures) out.append(py::make_tuple(k.cycle, k.channel, k.value));
            f.captures.clear();
            return out;
        })
        .def("ftm_take_unmodelled", [](Core& c, int dev) {
            auto out = std::move(ftm_of(c, dev).unmodelled);
            ftm_of(c, dev).unmodelled.clear();
            return out;
        })
        .def("ftm_state", [](Core& c, int dev) {
            const Ftm& f = ftm_of(c, dev);
            py::dict d;
            d["anchor"] = f.anchored ? py::object(py::make_tuple(f.anchor_cycle, f.anchor_count))
                                     : py::object(py::none());
            py::dict pending, written_at;
            for (const auto& p : f.pending) {
                pending[py::int_(p.reg)] = p.value;
                written_at[py::int_(p.reg)] = p.written_at;
            }
            d["pending"] = pending;
            d["written_at"] = written_at;
            d["line"] = f.line;
            return d;
        })
        // WDOG
        .def("wdog_setup", [](Core& c, const py::dict& d) {
            Wdog& w = c.wdog;
            w.L = layout(d);
            w.wct = d["wct"].cast<uint32_t>();
            w.gap = d["gap"].cast<uint32_t>();
            const auto unlock = d["unlock"].cast<std::pair<uint32_t, uint32_t>>();
            const auto refresh = d["refresh"].cast<std::pair<uint32_t, uint32_t>>();
            w.unlock[0] = unlock.first; w.unlock[1] = unlock.second;
            w.refresh[0] = refresh.first; w.refresh[1] = refresh.second;
            w.lpo_hz = d["lpo_hz"].cast<double>();
            w.setup();
            w.reset();
        })
        .def("wdog_reg", [](const Core& c, uint32_t offset) { return c.wdog.v.at(offset); })
        .def("wdog_power_on", [](Core& c, double core_hz, double bus_hz) {
            c.wdog.power_on(c, core_hz, bus_hz);
        }, py::arg("core_hz"), py::arg("bus_hz"))
        .def("wdog_timeout_s", [](const Core& c) { return c.wdog.timeout_s(c.bus_hz()); })
        .def("wdog_state", [](const Core& c) {
            const Wdog& w = c.wdog;
            py::dict d;
            d["first_unlock"] = optional_cycle(w.first_unlock);
            d["unlocked_at"] = optional_cycle(w.unlocked_at);
            d["first_refresh"] = optional_cycle(w.first_refresh);
            d["written"] = w.written;
            d["disabled_at"] = w.disabled ? py::object(py::make_tuple(w.disabled_instruction,
                                                                      w.disabled_cycle))
                                          : py::object(py::none());
            py::list ignored;
            for (const auto& i : w.ignored) {
                ignored.append(py::make_tuple(i.instruction, i.reg, i.value, i.why));
            }
            d["ignored"] = ignored;
            return d;
        })
        .def("wdog_take_log", [](Core& c) {
            py::list out;
            for (const auto& e : c.wdog.log) {
                out.append(py::make_tuple(e.instruction, e.cycle, e.reg, e.value));
            }
            c.wdog.log.clear();
            return out;
        })
        // FTFE
        .def("ftfe_setup", [](Core& c, const py::dict& d) {
            Ftfe& f = c.ftfe;
            f.L = layout(d);
            f.flash_size = d["flash_size"].cast<uint32_t>();
            f.sector = d["sector"].cast<uint32_t>();
            f.config = d["config"].cast<uint32_t>();
            f.erase_sector_s = d["erase_sector_s"].cast<double>();
            f.program_phrase_s = d["program_phrase_s"].cast<double>();
            if (!f.flash_size || !f.sector || (f.sector & (f.sector - 1)) || f.flash_size % 32) {
                throw std::invalid_argument("FTFE: flash size and sector size");
            }
            f.setup();
            f.reset(c);
        })
        .def("ftfe_reg", [](const Core& c, uint32_t offset) { return c.ftfe.v.at(offset); })
        .def("ftfe_times", [](const Core& c) {
            return py::make_tuple(c.ftfe.erase_sector_s, c.ftfe.program_phrase_s);
        })
        .def("ftfe_set_times", [](Core& c, double erase_sector_s, double program_phrase_s) {
            c.ftfe.erase_sector_s = erase_sector_s;
            c.ftfe.program_phrase_s = program_phrase_s;
        }, py::arg("erase_sector_s"), py::arg("program_phrase_s"))
        .def("ftfe_state", [](const Core& c) {
            const Ftfe& f = c.ftfe;
            py::dict d;
            d["busy"] = f.busy;
            d["command"] = f.command;
            d["address"] = f.address;
            d["started"] = f.started;
            d["changes"] = f.changes;
            return d;
        })
        .def("ftfe_take_log", [](Core& c) {
            py::list out;
            for (const auto& e : c.ftfe.log) {
                out.append(py::make_tuple(e.start, e.end, e.code, e.address, e.fstat));
            }
            c.ftfe.log.clear();
            return out;
        })
        .def("ftfe_take_notes", [](Core& c) {
            auto out = std::move(c.ftfe.notes);
            c.ftfe.notes.clear();
            return out;
        })
        // the MPU6050 slaves: the register model is the Python object's (heliquad._firmware)
        .def("mpu_new", [](Core& c, py::object emu, int address) {
            auto s = std::make_unique<MpuSlave>();
            s->emu = emu.cast<hq::Mpu6050Emulator*>();
            s->address = static_cast<uint8_t>(address);
            c.owned_slaves.push_back(std::move(s));
            return c.owned_slaves.size() - 1;
        }, py::arg("emu"), py::arg("address"), py::keep_alive<1, 2>())
        // USB0 and its host's bulk IN polls (mk64_usb.cpp)
        .def("usb_setup", [](Core& c, const py::dict& d) {
            Usb& u = c.usb0;
            u.L = layout(d);
            u.irq = d["irq"].cast<int>();
            u.sram_base = d["sram_base"].cast<uint32_t>();
            u.sram_size = d["sram_size"].cast<uint32_t>();
            u.setup();
            u.reset(c);
        })
        .def_property_readonly("usb0", [](Core& c) -> Usb& { return c.usb0; },
                               py::return_value_policy::reference_internal)
        .def("usb_sof", [](Core& c, int frame) { c.usb0.sof(c, static_cast<uint16_t>(frame)); })
        .def("usb_idle_watch", [](Core& c) { c.usb0.idle_watch(c); })
        .def("usb_host_frame", [](Core& c) { c.usb0.host_frame(c); })
        .def("usb_host_stop_frames", [](Core& c) {
            if (c.usb0.host.frame_event) c.cancel(c.usb0.host.frame_event);
            c.usb0.host.frame_event = 0;
        })
        .def("usb_pump_soon", [](Core& c) { c.usb0.pump_soon(c); })
        .def("usb_tokens_free", [](Core& c) { c.usb0.tokens_free(c); })
        .def("usb_end_data", [](Core& c) { return c.usb0.end_data(c) == Core::kNoCall; })
        .def("take_py_call", [](Core& c) {
            const int call = c.py_call_;
            c.py_call_ = Core::kNoCall;
            return call;
        })
        .def("mpu_attach", [](Core& c, size_t k) { c.i2c0.slaves.push_back(c.owned_slaves.at(k).get()); })
        .def("mpu_set_present", [](Core& c, size_t k, bool p) { c.owned_slaves.at(k)->present = p; })
        .def("mpu_present", [](const Core& c, size_t k) { return c.owned_slaves.at(k)->present; })
        .def("mpu_take_log", [](Core& c, size_t k) {
            MpuSlave* s = c.owned_slaves.at(k).get();
            py::list out;
            for (const auto& e : s->log) {
                out.append(py::make_tuple(e.seconds, std::string(1, e.kind),
                                          e.reg < 0 ? py::object(py::none()) : py::object(py::int_(e.reg)),
                                          py::bytes(reinterpret_cast<const char*>(e.data.data()),
                                                    e.data.size())));
            }
            s->log.clear();
            return out;
        });
}
