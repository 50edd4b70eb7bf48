// Python bindings of the firmware core (host build only), so pytest drives the real
// controller code (the Crazyflie approach). Nothing here is compiled for the target.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "core/attitude.hpp"
#include "core/controllers.hpp"
#include "core/excitation.hpp"
#include "core/mixer.hpp"
#include "core/mpu6050.hpp"
#include "core/pid.hpp"
#include "targets/host/mpu6050_emulator.hpp"

namespace py = pybind11;
using namespace hq;

namespace {

// Start-up waits are meaningless against the emulator: it is ready at once.
class InstantClock final : public Clock {
public:
    uint64_t micros() const override { return now_; }
    void delay_us(uint32_t us) override { now_ += us; }

private:
    uint64_t now_ = 0;
};

// The driver borrows its DMP image; this keeps the bytes alive next to it.
struct DriverHolder {
    std::vector<uint8_t> image;
    Mpu6050 driver;
    InstantClock clock;
    explicit DriverHolder(const Mpu6050Config& cfg) : driver(cfg) {}
};

std::unique_ptr<DriverHolder> make_driver(const py::bytes& image, uint8_t dmp_rate_div) {
    std::string data = image;
    Mpu6050Config cfg;
    cfg.dmp_rate_div = dmp_rate_div;
    auto holder = std::make_unique<DriverHolder>(cfg);
    holder->image.assign(data.begin(), data.end());
    if (!holder->image.empty()) {
        cfg.dmp_image = holder->image.data();
        cfg.dmp_image_size = static_cast<uint16_t>(holder->image.size());
        holder->driver = Mpu6050(cfg);
    }
    return holder;
}

template <typename T>
std::array<float, 3> vec(const T& v) { return {v[0], v[1], v[2]}; }

}  // namespace

PYBIND11_MODULE(_firmware, m) {
    m.doc() = "heliquad firmware core (host build), for tests and the simulator";

    py::enum_<Axis>(m, "Axis").value("ROLL", Axis::Roll).value("PITCH", Axis::Pitch)
        .value("YAW", Axis::Yaw);
    py::enum_<Injection>(m, "Injection").value("ANGLE", Injection::Angle)
        .value("RATE", Injection::Rate).value("MIXER", Injection::Mixer);

    py::class_<Vec3>(m, "Vec3")
        .def(py::init([](float x, float y, float z) { return Vec3{x, y, z}; }),
             py::arg("x") = 0.0f, py::arg("y") = 0.0f, py::arg("z") = 0.0f)
        .def_readwrite("x", &Vec3::x).def_readwrite("y", &Vec3::y).def_readwrite("z", &Vec3::z)
        .def("to_list", [](const Vec3& v) { return vec(v); });
    py::class_<Quat>(m, "Quat")
        .def(py::init([](float w, float x, float y, float z) { return Quat{w, x, y, z}; }),
             py::arg("w") = 1.0f, py::arg("x") = 0.0f, py::arg("y") = 0.0f, py::arg("z") = 0.0f)
        .def_readwrite("w", &Quat::w).def_readwrite("x", &Quat::x)
        .def_readwrite("y", &Quat::y).def_readwrite("z", &Quat::z)
        .def("to_list", [](const Quat& q) { return std::array<float, 4>{q.w, q.x, q.y, q.z}; });
    py::class_<Euler>(m, "Euler")
        .def(py::init([](float r, float p, float y) { return Euler{r, p, y}; }),
             py::arg("roll") = 0.0f, py::arg("pitch") = 0.0f, py::arg("yaw") = 0.0f)
        .def_readwrite("roll", &Euler::roll).def_readwrite("pitch", &Euler::pitch)
        .def_readwrite("yaw", &Euler::yaw);

    m.def("to_euler", &to_euler);
    m.def("from_euler", &from_euler);
    m.def("dmp_to_frd", &dmp_to_frd);
    m.def("chip_to_frd", &chip_to_frd);
    py::class_<ComplementaryFilter>(m, "ComplementaryFilter")
        .def(py::init<float>(), py::arg("kp") = 1.0f)
        .def("update", &ComplementaryFilter::update)
        .def("reset", &ComplementaryFilter::reset, py::arg("q") = Quat())
        .def_property_readonly("quaternion", &ComplementaryFilter::quaternion);

    py::class_<PidGains>(m, "PidGains")
        .def(py::init<>())
        .def_readwrite("kc", &PidGains::kc).def_readwrite("tau_i_s", &PidGains::tau_i_s)
        .def_readwrite("tau_d_s", &PidGains::tau_d_s)
        .def_readwrite("derivative_filter_n", &PidGains::derivative_filter_n)
        .def_readwrite("output_min", &PidGains::output_min)
        .def_readwrite("output_max", &PidGains::output_max)
        .def_readwrite("integral_limit", &PidGains::integral_limit);
    py::class_<Pid>(m, "Pid")
        .def(py::init<const PidGains&>())
        .def("update", &Pid::update, py::arg("setpoint"), py::arg("measurement"), py::arg("dt_s"))
        .def("reset", &Pid::reset)
        .def_property_readonly("p_term", &Pid::p_term)
        .def_property_readonly("i_term", &Pid::i_term)
        .def_property_readonly("d_term", &Pid::d_term)
        .def_property_readonly("output", &Pid::output)
        .def_property_readonly("saturated", &Pid::saturated);

    py::class_<CascadeGains>(m, "CascadeGains")
        .def_static("paper_defaults", &CascadeGains::paper_defaults)
        .def("rate", [](const CascadeGains& g, Axis a) { return g.rate[static_cast<int>(a)]; })
        .def("angle", [](const CascadeGains& g, Axis a) { return g.angle[static_cast<int>(a)]; });
    py::class_<AttitudeController>(m, "AttitudeController")
        .def(py::init<const CascadeGains&>())
        .def("update", &AttitudeController::update)
        .def("reset", &AttitudeController::reset);
    py::class_<RateController>(m, "RateController")
        .def(py::init<const CascadeGains&>())
        .def("update", &RateController::update)
        .def("reset", &RateController::reset);

    py::class_<MixerGeometry>(m, "MixerGeometry")
        .def(py::init<>())
        .def_readwrite("arm_length_m", &MixerGeometry::arm_length_m)
        .def_readwrite("cant_deg", &MixerGeometry::cant_deg)
        .def_readwrite("central_max_thrust_n", &MixerGeometry::central_max_thrust_n)
        .def_readwrite("arm_max_thrust_n", &MixerGeometry::arm_max_thrust_n)
        .def_readwrite("central_torque_per_thrust_m", &MixerGeometry::central_torque_per_thrust_m)
        .def_readwrite("hover_thrust_n", &MixerGeometry::hover_thrust_n);
    py::class_<MixerCommand>(m, "MixerCommand")
        .def(py::init([](float c, float r, float p, float y) { return MixerCommand{c, r, p, y}; }),
             py::arg("collective") = 0.0f, py::arg("roll") = 0.0f, py::arg("pitch") = 0.0f,
             py::arg("yaw") = 0.0f)
        .def_readwrite("collective", &MixerCommand::collective)
        .def_readwrite("roll", &MixerCommand::roll).def_readwrite("pitch", &MixerCommand::pitch)
        .def_readwrite("yaw", &MixerCommand::yaw);
    py::class_<MixerOutput>(m, "MixerOutput")
        .def_property_readonly("motor", [](const MixerOutput& o) {
            return std::array<float, kMotors>{o.motor[0], o.motor[1], o.motor[2], o.motor[3], o.motor[4]};
        })
        .def_readonly("saturated", &MixerOutput::saturated);
    py::class_<Mixer>(m, "Mixer")
        .def(py::init<const MixerGeometry&>(), py::arg("geometry") = MixerGeometry())
        .def("mix", &Mixer::mix)
        .def("achieved", [](const Mixer& mx, const std::array<float, kMotors>& motor) {
            return mx.achieved(motor.data());
        })
        .def_property_readonly("max_vertical_thrust_n", &Mixer::max_vertical_thrust_n)
        .def_property_readonly("roll_pitch_torque_unit_nm", &Mixer::roll_pitch_torque_unit_nm)
        .def_property_readonly("yaw_torque_unit_nm", &Mixer::yaw_torque_unit_nm)
        .def_property_readonly("hover_arm_thrust_n", &Mixer::hover_arm_thrust_n);

    py::class_<ExcitationConfig>(m, "ExcitationConfig")
        .def(py::init<>())
        .def_readwrite("axis", &ExcitationConfig::axis)
        .def_readwrite("injection", &ExcitationConfig::injection)
        .def_readwrite("freq_hz", &ExcitationConfig::freq_hz)
        .def_readwrite("amplitude", &ExcitationConfig::amplitude)
        .def_readwrite("cycles", &ExcitationConfig::cycles)
        .def_readwrite("fade_cycles", &ExcitationConfig::fade_cycles);
    py::class_<Excitation>(m, "Excitation")
        .def(py::init<>())
        .def("start", &Excitation::start)
        .def("stop", &Excitation::stop)
        .def("next", &Excitation::next)
        .def_property_readonly("active", &Excitation::active)
        .def_property_readonly("measuring", &Excitation::measuring)
        .def_property_readonly("period_samples", &Excitation::period_samples)
        .def_property_readonly("actual_freq_hz", &Excitation::actual_freq_hz)
        .def_property_readonly("total_samples", &Excitation::total_samples);

    py::enum_<InitResult>(m, "InitResult")
        .value("OK_DMP", InitResult::OkDmp).value("OK_RAW", InitResult::OkRaw)
        .value("OK_RAW_FALLBACK", InitResult::OkRawFallback)
        .value("NO_DEVICE", InitResult::NoDevice).value("BUS_ERROR", InitResult::BusError);
    py::enum_<SensorMode>(m, "SensorMode").value("NONE", SensorMode::None)
        .value("DMP", SensorMode::Dmp).value("RAW", SensorMode::Raw);
    py::class_<ImuSample>(m, "ImuSample")
        .def(py::init<>())
        .def_readonly("attitude", &ImuSample::attitude)
        .def_readonly("gyro_rad_s", &ImuSample::gyro_rad_s)
        .def_readonly("accel_m_s2", &ImuSample::accel_m_s2)
        .def_readonly("has_attitude", &ImuSample::has_attitude);
    py::class_<Mpu6050Counters>(m, "Mpu6050Counters")
        .def_readonly("packets", &Mpu6050Counters::packets)
        .def_readonly("dropped", &Mpu6050Counters::dropped)
        .def_readonly("overflows", &Mpu6050Counters::overflows)
        .def_readonly("resyncs", &Mpu6050Counters::resyncs)
        .def_readonly("bad_packets", &Mpu6050Counters::bad_packets)
        .def_readonly("bus_errors", &Mpu6050Counters::bus_errors);

    py::class_<Mpu6050Emulator>(m, "Mpu6050Emulator")
        .def(py::init<>())
        .def("push_fifo", [](Mpu6050Emulator& e, const py::bytes& data, bool dmp) {
            std::string s = data;
            return e.push_fifo(reinterpret_cast<const uint8_t*>(s.data()), s.size(), dmp);
        })
        .def("read", [](Mpu6050Emulator& e, uint8_t reg, size_t n) {
            std::string out(n, '\0');
            e.read(mpu6050::kAddress, reg, reinterpret_cast<uint8_t*>(&out[0]), n);
            return py::bytes(out);
        })
        .def("write", [](Mpu6050Emulator& e, uint8_t reg, const py::bytes& data) {
            std::string s = data;
            return e.write(mpu6050::kAddress, reg, reinterpret_cast<const uint8_t*>(s.data()), s.size());
        })
        .def("memory", [](const Mpu6050Emulator& e, size_t start, size_t n) {
            return py::bytes(reinterpret_cast<const char*>(e.memory() + start), n);
        })
        .def("set_present", &Mpu6050Emulator::set_present)
        .def_property_readonly("fifo_count", &Mpu6050Emulator::fifo_count)
        .def_property_readonly("dmp_enabled", &Mpu6050Emulator::dmp_enabled)
        .def_property_readonly("raw_fifo_enabled", &Mpu6050Emulator::raw_fifo_enabled);

    py::class_<DriverHolder>(m, "Mpu6050")
        .def(py::init(&make_driver), py::arg("dmp_image") = py::bytes(), py::arg("dmp_rate_div") = 0)
        .def("init", [](DriverHolder& h, Mpu6050Emulator& bus) { return h.driver.init(bus, h.clock); })
        .def("poll", [](DriverHolder& h, Mpu6050Emulator& bus) -> py::object {
            ImuSample s;
            if (h.driver.poll(bus, s)) return py::cast(s);
            return py::none();
        })
        .def_property_readonly("mode", [](const DriverHolder& h) { return h.driver.mode(); })
        .def_property_readonly("packet_size", [](const DriverHolder& h) { return h.driver.packet_size(); })
        .def_property_readonly("counters", [](const DriverHolder& h) { return h.driver.counters(); })
        .def_static("parse_dmp_packet", [](const py::bytes& data) -> py::object {
            std::string s = data;
            if (s.size() != mpu6050::kDmpPacketSize) throw py::value_error("a DMP packet is 42 bytes");
            ImuSample out;
            if (!Mpu6050::parse_dmp_packet(reinterpret_cast<const uint8_t*>(s.data()), out)) return py::none();
            return py::cast(out);
        });
}
