// Python bindings of the card and its file layer (host build only): a card-image file with
// faults (targets/host/block_device.hpp), the log files on it (core/log/log_files.hpp) and
// card-image making (targets/host/card_image.hpp), for `heliquad sd-image` and the tests.
#include <pybind11/pybind11.h>

#include <memory>
#include <string>

#include "core/flight_controller.hpp"
#include "core/log/log_files.hpp"
#include "targets/host/block_device.hpp"
#include "targets/host/card_image.hpp"

namespace py = pybind11;
using namespace hq;

namespace {

// The lockstep clock the card's busy time is measured in. Each busy poll is one wait-hook
// call; here a hook call stands for one loop step, so it moves the clock one loop period.
class SteppedClock final : public Clock, public CardWait {
public:
    uint64_t micros() const override { return now_us_; }
    void delay_us(uint32_t us) override { now_us_ += us; }
    void card_busy() override {
        now_us_ += kStepUs;
        ++busy_polls_;
    }
    void advance(uint64_t us) { now_us_ += us; }
    uint64_t busy_polls() const { return busy_polls_; }

private:
    static constexpr uint64_t kStepUs = static_cast<uint64_t>(1e6f / kLoopRateHz);
    uint64_t now_us_ = 0, busy_polls_ = 0;
};

// A card image and its files, as the firmware holds them.
struct CardFiles {
    SteppedClock clock;
    FileBlockDevice card;
    LogFiles files;
    explicit CardFiles(const std::string& path) : card(path, clock), files(card, clock, &clock) {}
};

// set_faults(no_card=True, busy_after_write_us=250000, ...): the faults named, the rest off.
void set_faults(CardFiles& c, const py::kwargs& kw) {
    CardFaults f;
    for (const auto& item : kw) {
        const std::string name = py::cast<std::string>(item.first);
        if (!set_card_fault(f, name, py::cast<uint64_t>(item.second))) {
            throw py::value_error("unknown card fault " + name);
        }
    }
    c.card.set_faults(f);
}

py::object read_log(CardFiles& c, uint16_t id, uint32_t offset, uint32_t n) {
    std::string buf(n, '\0');
    const int32_t got = c.files.read(id, offset, reinterpret_cast<uint8_t*>(buf.data()), n);
    if (got < 0) return py::none();
    return py::bytes(buf.data(), static_cast<size_t>(got));
}

}  // namespace

void bind_card(py::module_& m) {
    m.attr("DEFAULT_CARD_IMAGE_BYTES") = kDefaultCardImageBytes;
    m.attr("MIN_CARD_IMAGE_BYTES") = kMinCardImageBytes;
    m.attr("MAX_CARD_IMAGE_BYTES") = kMaxCardImageBytes;
    m.attr("LOG_SYNC_PERIOD_US") = LogSink::kSyncPeriodUs;
    m.def("make_card_image", &make_card_image, py::arg("path"), py::arg("size_bytes"),
          "Formats a FAT32 card image; returns '' or the one-line reason it could not.");
    py::enum_<CardState>(m, "CardState")
        .value("OK", CardState::Ok)
        .value("NO_CARD", CardState::NoCard)
        .value("WRITE_PROTECTED", CardState::WriteProtected)
        .value("FULL", CardState::Full)
        .value("FAILED", CardState::Failed);
    py::class_<CardFiles>(m, "CardFiles")
        .def(py::init<const std::string&>(), py::arg("path"))
        .def("set_faults", &set_faults)
        .def("mount", [](CardFiles& c) { return c.files.mount(); })
        .def("begin_log", [](CardFiles& c) { return c.files.begin_log(); })
        .def("write", [](CardFiles& c, const py::bytes& data) {
            const std::string s = data;
            return c.files.write(reinterpret_cast<const uint8_t*>(s.data()),
                                 static_cast<uint32_t>(s.size()));
        })
        .def("end_log", [](CardFiles& c) { c.files.end_log(); })
        .def("service", [](CardFiles& c) { c.files.service(); })
        .def_property_readonly("state", [](CardFiles& c) { return c.files.state(); })
        .def_property_readonly("last_log", [](CardFiles& c) { return c.files.last_log(); })
        .def("count", [](CardFiles& c) { return c.files.count(); })
        .def("info", [](CardFiles& c, uint16_t index) -> py::object {
            LogInfo info;
            if (!c.files.info(index, info)) return py::none();
            return py::make_tuple(info.id, info.size_bytes, info.time_utc_s);
        })
        .def("read", &read_log, py::arg("id"), py::arg("offset"), py::arg("n"))
        .def("erase_all", [](CardFiles& c) { return c.files.erase_all(); })
        .def("advance_us", [](CardFiles& c, uint64_t us) { c.clock.advance(us); })
        .def_property_readonly("now_us", [](CardFiles& c) { return c.clock.micros(); })
        .def_property_readonly("busy_polls", [](CardFiles& c) { return c.clock.busy_polls(); })
        .def_property_readonly("blocks_written", [](CardFiles& c) { return c.card.blocks_written(); });
}
