// Python bindings of the on-board log (host build only): the host build's loop in one
// object (LoggedFirmware: the FlightController, its telemetry link and the sim link's
// handler, as heliquad-fw-host wires them), its DataFlash log drained into RAM, so a test
// runs a flight and reads the same run's telemetry and log. Nothing here is compiled for
// the target.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "core/flight_controller.hpp"
#include "core/link/gcs_link.hpp"
#include "core/log/dataflash.hpp"
#include "core/log/log_sink.hpp"
#include "targets/host/clock.hpp"
#include "targets/host/i2c.hpp"
#include "targets/host/motors.hpp"
#include "targets/host/sim_link_handler.hpp"

namespace py = pybind11;
using namespace hq;

namespace {

// A card in RAM: one byte vector per log; `present` false is a missing card, and the card
// holds `room` bytes in all (a full card takes what still fits, then nothing).
class RamSink final : public LogSink {
public:
    bool begin_log() override {
        if (!present || room == 0) return false;
        logs.emplace_back();
        open = true;
        return true;
    }
    uint32_t write(const uint8_t* data, uint32_t n) override {
        if (!open) return 0;
        const uint32_t k = static_cast<uint32_t>(std::min<uint64_t>(n, room));
        logs.back().insert(logs.back().end(), data, data + k);
        room -= k;
        return k;
    }
    void end_log() override { open = false; }
    CardState state() const override {
        return !present ? CardState::NoCard : (room == 0 ? CardState::Full : CardState::Ok);
    }

    bool present = true, open = false;
    uint64_t room = UINT64_MAX;
    std::vector<std::vector<uint8_t>> logs;
};

// The telemetry link's bytes in RAM: what a ground station sent, what the firmware sent.
class RamSerial final : public SerialPort {
public:
    size_t read(uint8_t* data, size_t n) override {
        const size_t k = std::min(n, in.size() - at);
        std::memcpy(data, in.data() + at, k);
        at += k;
        if (at == in.size()) in.clear(), at = 0;
        return k;
    }
    size_t write(const uint8_t* data, size_t n) override {
        out.insert(out.end(), data, data + n);
        return n;
    }
    std::vector<uint8_t> in, out;
    size_t at = 0;
};

class Replies final : public SimLinkReplies {
public:
    bool reply(const uint8_t* packet, size_t n, bool) override {
        out.insert(out.end(), packet, packet + n);
        return true;
    }
    std::vector<uint8_t> out;
};

struct LoggedFirmware {
    HostClock clock;
    HostMotors motors;
    Mpu6050Emulator chip;
    HostI2cBus bus;
    LoopInbox inbox;
    RamSerial serial;
    RamSink sink;
    std::unique_ptr<FlightController> fc;
    std::unique_ptr<GcsLink> link;
    std::unique_ptr<SimLinkHandler> handler;

    explicit LoggedFirmware(float loop_hz) {
        FlightControllerConfig cfg;
        cfg.loop_rate_hz = loop_hz;
        GcsLinkConfig link_cfg;
        link_cfg.loop_rate_hz = loop_hz;
        bus.attach(mpu6050::kAddress, chip);
        fc = std::make_unique<FlightController>(cfg, bus, clock, motors);
        link_cfg.log = &fc->logger();
        link = std::make_unique<GcsLink>(link_cfg, serial, inbox);
        handler = std::make_unique<SimLinkHandler>(*fc, *link, clock, chip, motors,
                                                   link_cfg.system_id, link_cfg.component_id);
        fc->init();
        fc->set_card_state(sink.state());     // as the targets do once their card has started
        link->send_notices(fc->status());
    }
};

py::bytes as_bytes(std::vector<uint8_t>& v) {
    py::bytes b(reinterpret_cast<const char*>(v.data()), v.size());
    v.clear();
    return b;
}

}  // namespace

void bind_logger(py::module_& m) {
    m.attr("LOG_RING_BYTES") = Logger::kRingBytes;
    py::class_<LogCounters>(m, "LogCounters")
        .def_readonly("records", &LogCounters::records)
        .def_readonly("dropped", &LogCounters::dropped)
        .def_readonly("bytes_written", &LogCounters::bytes_written)
        .def_readonly("logs", &LogCounters::logs);
    py::class_<LoggedFirmware>(m, "LoggedFirmware",
                               "The host build's loop with its DataFlash log drained into RAM.")
        .def(py::init<float>(), py::arg("loop_rate_hz") = kLoopRateHz)
        .def("sim", [](LoggedFirmware& f, const py::bytes& data) {
            const std::string s = data;
            Replies r;
            f.handler->feed(reinterpret_cast<const uint8_t*>(s.data()), s.size(), r);
            return as_bytes(r.out);
        }, py::arg("frames"), "Sim-link bytes in (HQ_SENSOR_FRAMEs: one step each); the replies.")
        .def("telemetry_in", [](LoggedFirmware& f, const py::bytes& data) {
            const std::string s = data;
            f.serial.in.insert(f.serial.in.end(), s.begin(), s.end());
        }, py::arg("data"), "Bytes a ground station sent: read by the next step.")
        .def("telemetry_out", [](LoggedFirmware& f) { return as_bytes(f.serial.out); },
             "What the firmware sent on the telemetry link since the last call.")
        .def("service", [](LoggedFirmware& f) { f.fc->log_service(f.sink); },
             "The loop's spare time: the log's ring drained into the RAM card.")
        .def_property("card_present", [](const LoggedFirmware& f) { return f.sink.present; },
                      [](LoggedFirmware& f, bool v) { f.sink.present = v; })
        .def_property("card_room", [](const LoggedFirmware& f) { return f.sink.room; },
                      [](LoggedFirmware& f, uint64_t v) { f.sink.room = v; },
                      "Bytes the RAM card still takes (a full card: 0).")
        .def_property_readonly("logs", [](const LoggedFirmware& f) {
            py::list out;
            for (const auto& l : f.sink.logs) out.append(py::bytes(reinterpret_cast<const char*>(l.data()), l.size()));
            return out;
        }, "Every log the card holds, oldest first.")
        .def_property_readonly("log_open", [](const LoggedFirmware& f) { return f.sink.open; })
        .def_property_readonly("log_counters", [](const LoggedFirmware& f) { return f.fc->logger().counters(); })
        .def_property_readonly("log_queued_bytes", [](const LoggedFirmware& f) { return f.fc->logger().queued_bytes(); })
        .def_property_readonly("armed", [](const LoggedFirmware& f) { return f.fc->armed(); });
}
