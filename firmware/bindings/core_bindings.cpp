// Python bindings of the firmware core (host build only), so pytest drives the real
// controller code (the Crazyflie approach). Nothing here is compiled for the target.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

#include "core/attitude.hpp"
#include "core/controllers.hpp"
#include "core/excitation.hpp"
#include "core/flight_controller.hpp"
#include "core/loop_load.hpp"
#include "core/allocation.hpp"
#include "core/mixer.hpp"
#include "core/mpu6050.hpp"
#include "core/params.hpp"
#include "core/pid.hpp"
#include "core/rc.hpp"
#include "core/supervisor.hpp"
#include "sensor/mpu6050_emulator.hpp"
#include "targets/host/pty_backlog.hpp"
#include "targets/teensy35/reset_cause_flags.hpp"
#include "targets/teensy35/usb_identity.hpp"

namespace py = pybind11;
using namespace hq;

void bind_logger(py::module_& m);    // log_bindings.cpp

namespace {

// Start-up waits are meaningless against the emulator: it is ready at once.
class InstantClock final : public Clock {
public:
    uint64_t micros() const override { return now_; }
    void delay_us(uint32_t us) override { now_ += us; }

private:
    uint64_t now_ = 0;
};

// The driver borrows its DMP firmware; this keeps the bytes alive next to it.
struct DriverHolder {
    std::vector<uint8_t> image, config, updates;
    Mpu6050 driver;
    InstantClock clock;
    explicit DriverHolder(const Mpu6050Config& cfg) : driver(cfg) {}
};

std::vector<uint8_t> byte_vector(const py::bytes& b) {
    const std::string data = b;
    return std::vector<uint8_t>(data.begin(), data.end());
}

std::unique_ptr<DriverHolder> make_driver(const py::bytes& image, const py::bytes& config,
                                          const py::bytes& updates, uint8_t dmp_rate_div) {
    Mpu6050Config cfg;
    cfg.dmp_rate_div = dmp_rate_div;
    auto holder = std::make_unique<DriverHolder>(cfg);
    holder->image = byte_vector(image);
    holder->config = byte_vector(config);
    holder->updates = byte_vector(updates);
    // Empty bytes are "not given" (nullptr), as in the firmware's configuration.
    if (!holder->image.empty()) {
        cfg.dmp_image = holder->image.data();
        cfg.dmp_image_size = static_cast<uint16_t>(holder->image.size());
    }
    if (!holder->config.empty()) {
        cfg.dmp_config = holder->config.data();
        cfg.dmp_config_size = static_cast<uint16_t>(holder->config.size());
    }
    if (!holder->updates.empty()) {
        cfg.dmp_updates = holder->updates.data();
        cfg.dmp_updates_size = static_cast<uint16_t>(holder->updates.size());
    }
    holder->driver = Mpu6050(cfg);
    return holder;
}

template <typename T>
std::array<float, 3> vec(const T& v) { return {v[0], v[1], v[2]}; }

void bind_rc_and_cascade(py::module_& m) {
    py::enum_<FlightMode>(m, "FlightMode").value("ANGLE", FlightMode::Angle)
        .value("RATE", FlightMode::Rate);
    py::class_<RcInput>(m, "RcInput")
        .def(py::init([](const std::array<uint16_t, kRcChannels>& us, uint32_t age_us) {
            RcInput in;
            for (int c = 0; c < kRcChannels; ++c) in.channel_us[c] = us[c];
            in.age_us = age_us;
            return in;
        }), py::arg("channel_us"), py::arg("age_us") = 0,
             "Pulse widths of channels 1-8 in us (0 = no signal) and the time since the last "
             "valid frame.")
        .def_property_readonly("channel_us", [](const RcInput& in) {
            std::array<uint16_t, kRcChannels> out{};
            for (int c = 0; c < kRcChannels; ++c) out[c] = in.channel_us[c];
            return out;
        })
        .def_readwrite("age_us", &RcInput::age_us);
    py::class_<StickLimits>(m, "StickLimits")
        .def(py::init<>())
        .def_readwrite("angle_rad", &StickLimits::angle_rad)
        .def_readwrite("rate_rad_s", &StickLimits::rate_rad_s)
        .def_readwrite("yaw_rate_rad_s", &StickLimits::yaw_rate_rad_s);
    py::class_<Sticks>(m, "Sticks")
        .def_readonly("angle", &Sticks::angle).def_readonly("rate", &Sticks::rate)
        .def_readonly("throttle", &Sticks::throttle);
    m.def("sticks", &sticks, py::arg("rc"), py::arg("limits") = StickLimits());

    py::class_<CascadeInput>(m, "CascadeInput")
        .def(py::init<>())
        .def_readwrite("mode", &CascadeInput::mode)
        .def_readwrite("angle_stick", &CascadeInput::angle_stick)
        .def_readwrite("rate_stick", &CascadeInput::rate_stick)
        .def_readwrite("axis", &CascadeInput::axis)
        .def_readwrite("injection", &CascadeInput::injection)
        .def_readwrite("excitation", &CascadeInput::excitation)
        .def_readwrite("attitude", &CascadeInput::attitude)
        .def_readwrite("rate", &CascadeInput::rate)
        .def_readwrite("dt_s", &CascadeInput::dt_s);
    py::class_<CascadeOutput>(m, "CascadeOutput")
        .def_readonly("angle_sp", &CascadeOutput::angle_sp)
        .def_readonly("rate_sp", &CascadeOutput::rate_sp)
        .def_readonly("torque", &CascadeOutput::torque);
    py::class_<Cascade>(m, "Cascade")
        .def(py::init<const CascadeGains&>(), py::arg("gains") = CascadeGains::paper_defaults())
        .def("update", &Cascade::update)
        .def("reset", &Cascade::reset);
}

void bind_supervisor(py::module_& m) {
    bind_rc_and_cascade(m);
    // Reasons cross as plain ints: their names are the dialect's HQ_REASON (the one
    // definition; flight_controller.cpp asserts the values match).
    m.def("reason_text", [](int r) { return reason_text(static_cast<Reason>(r)); },
          py::arg("reason"));
    py::enum_<ArmSource>(m, "ArmSource").value("NONE", ArmSource::None)
        .value("RC_SWITCH", ArmSource::RcSwitch).value("COMMAND", ArmSource::Command);
    py::enum_<Severity>(m, "Severity").value("CRITICAL", Severity::Critical)
        .value("WARNING", Severity::Warning).value("NOTICE", Severity::Notice)
        .value("INFO", Severity::Info);
    py::class_<Event>(m, "Event")
        .def_property_readonly("reason", [](const Event& e) { return static_cast<int>(e.reason); })
        .def_readonly("severity", &Event::severity);
    m.def("imu_timeout_for", &imu_timeout_for, py::arg("rate_hz"));

    py::class_<SafetyLimits>(m, "SafetyLimits")
        .def(py::init<>())
        .def_readwrite("rc_timeout_us", &SafetyLimits::rc_timeout_us)
        .def_readwrite("host_timeout_us", &SafetyLimits::host_timeout_us)
        .def_readwrite("imu_timeout_us", &SafetyLimits::imu_timeout_us)
        .def_readwrite("imu_retry_us", &SafetyLimits::imu_retry_us)
        .def_readwrite("abort_angle_rad", &SafetyLimits::abort_angle_rad)
        .def_readwrite("abort_rate_rad_s", &SafetyLimits::abort_rate_rad_s)
        .def_property("max_amplitude", [](const SafetyLimits& l) {
            return std::array<float, kInjectionBounds>{l.max_amplitude[0], l.max_amplitude[1],
                                                       l.max_amplitude[2], l.max_amplitude[3]};
        }, [](SafetyLimits& l, const std::array<float, kInjectionBounds>& a) {
            for (int i = 0; i < kInjectionBounds; ++i) l.max_amplitude[i] = a[i];
        }, "Largest amplitude per injection point: angle (rad), rate (rad/s), mixer, and one "
           "for every motor injection (thrust fraction).")
        .def_readwrite("min_freq_hz", &SafetyLimits::min_freq_hz)
        .def_readwrite("max_freq_fraction", &SafetyLimits::max_freq_fraction)
        .def_readwrite("max_duration_s", &SafetyLimits::max_duration_s)
        .def_readwrite("min_fade_cycles", &SafetyLimits::min_fade_cycles)
        .def_readwrite("gcs_sysid", &SafetyLimits::gcs_sysid);

    py::class_<SupervisorInputs>(m, "SupervisorInputs")
        .def(py::init([](uint64_t now_us, const RcInput& rc, bool imu_sample, const Euler& att,
                         const Vec3& rate) { return SupervisorInputs{now_us, rc, imu_sample, att, rate}; }),
             py::arg("now_us"), py::arg("rc"), py::arg("imu_sample") = true,
             py::arg("attitude") = Euler(), py::arg("rate") = Vec3());

    py::class_<SupervisorCounters>(m, "SupervisorCounters")
        .def_readonly("rc_failsafes", &SupervisorCounters::rc_failsafes)
        .def_readonly("host_failsafes", &SupervisorCounters::host_failsafes)
        .def_readonly("imu_stale", &SupervisorCounters::imu_stale)
        .def_readonly("imu_resets", &SupervisorCounters::imu_resets)
        .def_readonly("imu_reinits", &SupervisorCounters::imu_reinits)
        .def_readonly("non_finite", &SupervisorCounters::non_finite)
        .def_readonly("arm_refused", &SupervisorCounters::arm_refused)
        .def_readonly("exc_refused", &SupervisorCounters::exc_refused)
        .def_readonly("exc_stopped", &SupervisorCounters::exc_stopped)
        .def_readonly("events_dropped", &SupervisorCounters::events_dropped);

    m.def("station_id", &station_id, py::arg("sysid"), py::arg("compid"),
          "A ground station's identity as the Supervisor keeps it.");

    py::class_<Supervisor>(m, "Supervisor")
        .def(py::init<const SafetyLimits&, float>(), py::arg("limits") = SafetyLimits(),
             py::arg("loop_rate_hz") = kLoopRateHz)
        .def("host_heartbeat", &Supervisor::host_heartbeat, py::arg("now_us"),
             py::arg("station") = kAnyStation)
        .def("heartbeat", &Supervisor::heartbeat, py::arg("sysid"), py::arg("compid"),
             py::arg("mav_type"), py::arg("now_us"),
             "A HEARTBEAT from another system; True if it counted as the host's.")
        .def("arm_command", [](Supervisor& s, const RcInput& rc, uint64_t now, StationId who) {
            return static_cast<int>(s.arm_command(rc, now, who));
        }, py::arg("rc"), py::arg("now_us"), py::arg("station") = kAnyStation,
           "HQ_REASON_NONE (0) when armed, else why not.")
        .def("arm_check", [](const Supervisor& s, const RcInput& rc, uint64_t now) {
            return static_cast<int>(s.arm_check(rc, now));
        }, py::arg("rc"), py::arg("now_us"),
           "What an arm command from a live ground station would be answered now.")
        .def("set_limits", &Supervisor::set_limits, py::arg("limits"))
        .def("disarm_command", &Supervisor::disarm_command)
        .def("set_mode", [](Supervisor& s, uint32_t mode) { return static_cast<int>(s.set_mode(mode)); },
             py::arg("custom_mode"))
        .def("start_excitation", [](Supervisor& s, const ExcitationConfig& c, uint64_t now,
                                    StationId who) {
            return static_cast<int>(s.start_excitation(c, now, who));
        }, py::arg("config"), py::arg("now_us"), py::arg("station") = kAnyStation)
        .def_property_readonly("excitation_owner", &Supervisor::excitation_owner)
        .def("stop_excitation", &Supervisor::stop_excitation)
        .def("finish_excitation", &Supervisor::finish_excitation)
        .def("update", &Supervisor::update, py::arg("inputs"))
        .def("fault", [](Supervisor& s, int why) { s.fault(static_cast<Reason>(why)); }, py::arg("why"))
        .def("imu_initialised", &Supervisor::imu_initialised, py::arg("now_us"), py::arg("timeout_us"))
        .def("imu_recovery_due", &Supervisor::imu_recovery_due, py::arg("now_us"))
        .def("imu_recovery_result", [](Supervisor& s, int found, bool ok, uint64_t now) {
            s.imu_recovery_result(static_cast<Reason>(found), ok, now);
        }, py::arg("found"), py::arg("reinitialised"), py::arg("now_us"))
        .def_property_readonly("armed", &Supervisor::armed)
        .def_property_readonly("arm_source", &Supervisor::arm_source)
        .def_property_readonly("mode", &Supervisor::mode)
        .def_property_readonly("excitation_state", &Supervisor::excitation_state)
        .def_property_readonly("excitation", &Supervisor::excitation, py::return_value_policy::reference_internal)
        .def("imu_fresh", &Supervisor::imu_fresh, py::arg("now_us"))
        .def_property_readonly("imu_stale", &Supervisor::imu_stale)
        .def_property_readonly("last_reason", [](const Supervisor& s) { return static_cast<int>(s.last_reason()); })
        .def_property_readonly("counters", &Supervisor::counters)
        .def_property_readonly("limits", &Supervisor::limits)
        .def("events", [](Supervisor& s) {
            std::vector<Event> out;
            Event e;
            while (s.next_event(e)) out.push_back(e);
            return out;
        }, "Every event not yet taken, oldest first.")
        .def("take_excitation_end", [](Supervisor& s) -> py::object {
            Reason why;
            if (s.take_excitation_end(why)) return py::cast(static_cast<int>(why));
            return py::none();
        }, "Why an excitation ended since the last call, or None.");
}

}  // namespace

void bind_card(py::module_& m);   // card_bindings.cpp: the card-image file and the log files
void bind_allocation(py::module_& m);   // allocation_bindings.cpp: allocation from rotors

PYBIND11_MODULE(_firmware, m) {
    m.doc() = "heliquad firmware core (host build), for tests and the simulator";
    // The control loop's rate the firmware runs at unless configured otherwise, and the most
    // the host build takes, Hz.
    bind_card(m);
    m.attr("LOOP_RATE_HZ") = kLoopRateHz;
    m.attr("MAX_LOOP_RATE_HZ") = kMaxLoopRateHz;
    // The most a host pty's backlog bound can be (--telemetry-backlog-bytes), bytes.
    m.attr("MAX_PTY_BACKLOG_BYTES") = kMaxPtyBacklogBytes;
    // The Teensy image's USB identity (usb_identity.hpp): what --port auto matches.
    m.attr("USB_VID") = kUsbVendorId;
    m.attr("USB_PID") = kUsbProductId;
    m.attr("USB_MANUFACTURER") = kUsbManufacturer;
    m.attr("USB_PRODUCT") = kUsbProduct;
    m.def("usb_serial_number", [](uint32_t uidh, uint32_t uidmh, uint32_t uidml, uint32_t uidl) {
        const uint32_t uid[4] = {uidh, uidmh, uidml, uidl};
        char digits[kUsbSerialDigits] = {};
        usb_serial_number(uid, digits);
        return std::string(digits, kUsbSerialDigits);
    }, "The USB serial number of a chip whose SIM_UIDH..UIDL are these words.");
    // The Teensy's reset cause from its RCM_SRS0 and RCM_SRS1 (reset_cause_flags.hpp).
    py::enum_<ResetCause>(m, "ResetCause")
        .value("POWER_ON", ResetCause::PowerOn).value("PIN", ResetCause::Pin)
        .value("WATCHDOG", ResetCause::Watchdog).value("LOCKUP", ResetCause::Lockup)
        .value("SOFTWARE", ResetCause::Software).value("LOW_VOLTAGE", ResetCause::LowVoltage)
        .value("CLOCK_LOSS", ResetCause::ClockLoss).value("DEBUGGER", ResetCause::Debugger)
        .value("OTHER", ResetCause::Other);
    m.def("reset_cause_from", &reset_cause_from, py::arg("srs0"), py::arg("srs1"),
          "Why the MK64 last reset, from its RCM_SRS0 and RCM_SRS1.");

    // The parameter table (params.hpp), in param_index order, with each default.
    struct ParamRow {
        std::string name, units;
        float minimum, maximum, default_value;
        bool integer, armed_ok;
        float floor;          // a time constant's least value but 0 (off); 0 for the others
    };
    py::class_<ParamRow>(m, "ParamRow")
        .def_readonly("name", &ParamRow::name)
        .def_readonly("units", &ParamRow::units)
        .def_readonly("minimum", &ParamRow::minimum)
        .def_readonly("maximum", &ParamRow::maximum)
        .def_readonly("default", &ParamRow::default_value)
        .def_readonly("integer", &ParamRow::integer)
        .def_readonly("armed_ok", &ParamRow::armed_ok)
        .def_readonly("floor", &ParamRow::floor);
    m.def("param_table", []() {
        const Params defaults;
        std::vector<ParamRow> rows;
        for (int i = 0; i < kParamCount; ++i) {
            const ParamInfo& p = param_info(i);
            rows.push_back({p.name, p.units, p.min, p.max, defaults.get(i),
                            (p.flags & kParamInteger) != 0, (p.flags & kParamArmedOk) != 0,
                            (p.flags & kParamTimeConstant) ? kMinTimeConstantS : 0.0f});
        }
        return rows;
    });
    m.def("decode_param_value", [](int index, float raw, uint8_t type) -> py::object {
        float value = 0.0f;
        if (index < 0 || index >= kParamCount ||
            !decode_param_value(param_info(index), raw, type, value)) {
            return py::none();
        }
        return py::float_(value);
    }, py::arg("index"), py::arg("raw"), py::arg("param_type"),
       "A PARAM_SET's value as the firmware reads it by the type it names; None when the type "
       "does not fit the parameter.");

    py::enum_<Axis>(m, "Axis").value("ROLL", Axis::Roll).value("PITCH", Axis::Pitch)
        .value("YAW", Axis::Yaw);
    {
        auto injection = py::enum_<Injection>(m, "Injection").value("ANGLE", Injection::Angle)
            .value("RATE", Injection::Rate).value("MIXER", Injection::Mixer)
            .value("MOTORS", Injection::Motors);
        for (int i = 0; i < kMaxRotors; ++i) {
            const std::string name = "MOTOR" + std::to_string(i + 1);
            injection.value(name.c_str(), static_cast<Injection>(static_cast<int>(Injection::Motor1) + i));
        }
    }

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
    py::class_<LoopLoad>(m, "LoopLoad")
        .def(py::init<>())
        .def_readonly_static("capacity", &LoopLoad::kCapacity)
        .def("record", &LoopLoad::record, py::arg("cycles"), py::arg("overruns_total"))
        .def("take", [](LoopLoad& l) {
            const LoopLoad::Report r = l.take();
            return py::make_tuple(r.median, r.max, r.overruns);
        });
    py::class_<AttitudeFilterConfig>(m, "AttitudeFilterConfig")
        .def(py::init<>())
        .def_readwrite("kp_ground", &AttitudeFilterConfig::kp_ground)
        .def_readwrite("kp_flight", &AttitudeFilterConfig::kp_flight)
        .def_readwrite("accel_band_g", &AttitudeFilterConfig::accel_band_g)
        .def_readwrite("rate_limit_rad_s", &AttitudeFilterConfig::rate_limit_rad_s)
        .def_readwrite("tilt_limit_rad", &AttitudeFilterConfig::tilt_limit_rad);
    py::class_<ComplementaryFilter>(m, "ComplementaryFilter")
        .def(py::init<const AttitudeFilterConfig&>(), py::arg("config") = AttitudeFilterConfig())
        .def("update", &ComplementaryFilter::update, py::arg("gyro_rad_s"), py::arg("accel_m_s2"),
             py::arg("dt_s"), py::arg("in_flight"))
        .def_property_readonly("accel_weight", &ComplementaryFilter::accel_weight)
        .def_property_readonly("config", &ComplementaryFilter::config)
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
    m.attr("MIN_TIME_CONSTANT_S") = kMinTimeConstantS;
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
        .def("angle", [](const CascadeGains& g, Axis a) {
            const int i = static_cast<int>(a);
            if (i >= kAngleAxes) throw py::value_error("yaw has no angle loop");
            return g.angle[i];
        });
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
        .def_readonly("saturated", &MixerOutput::saturated)
        .def_readonly("torque_limited", &MixerOutput::torque_limited)
        .def_readonly("collective_limited", &MixerOutput::collective_limited);
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
    bind_allocation(m);

    py::enum_<Signal>(m, "Signal").value("SINE", Signal::Sine)
        .value("MULTISINE", Signal::Multisine)
        .value("CHIRP", Signal::Chirp)
        .value("CHIRP_LINEAR", Signal::ChirpLinear);
    m.attr("MAX_HARMONICS") = kMaxHarmonics;
    m.attr("MAX_PROGRAM_STEPS") = kMaxProgramSteps;
    py::enum_<ExcitationState>(m, "ExcitationState").value("IDLE", ExcitationState::Idle)
        .value("FADING", ExcitationState::Fading).value("RUNNING", ExcitationState::Running);
    py::class_<ExcitationConfig>(m, "ExcitationConfig")
        .def(py::init<>())
        .def_readwrite("axis", &ExcitationConfig::axis)
        .def_readwrite("injection", &ExcitationConfig::injection)
        .def_readwrite("freq_hz", &ExcitationConfig::freq_hz)
        .def_readwrite("amplitude", &ExcitationConfig::amplitude)
        .def_readwrite("cycles", &ExcitationConfig::cycles)
        .def_readwrite("fade_cycles", &ExcitationConfig::fade_cycles)
        .def_readwrite("signal", &ExcitationConfig::signal)
        .def_readwrite("freq_stop_hz", &ExcitationConfig::freq_stop_hz)
        .def_readwrite("sweep_s", &ExcitationConfig::sweep_s)
        .def_property("harmonics",
            [](const ExcitationConfig& c) {
                py::list out;
                for (int i = 0; i < c.harmonics; ++i) {
                    out.append(py::make_tuple(c.harmonic[i].order, c.harmonic[i].amplitude,
                                              c.harmonic[i].phase_rad));
                }
                return out;
            },
            [](ExcitationConfig& c, const std::vector<std::tuple<uint16_t, float, float>>& hs) {
                if (hs.size() > static_cast<size_t>(kMaxHarmonics)) {
                    throw py::value_error("at most 16 harmonics");
                }
                c.harmonics = static_cast<uint8_t>(hs.size());
                for (size_t i = 0; i < hs.size(); ++i) {
                    c.harmonic[i] = Harmonic{std::get<0>(hs[i]), std::get<1>(hs[i]), std::get<2>(hs[i])};
                }
            },
            "[(order, amplitude, phase_rad), ...] of a multisine");
    py::class_<Excitation>(m, "Excitation")
        .def(py::init<>())
        .def("start", &Excitation::start)
        .def("stop", &Excitation::stop)
        .def("finish", &Excitation::finish)
        .def_property_readonly("config", [](const Excitation& e) { return e.config(); })
        .def("next", [](Excitation& e) { return e.next(); })
        .def("next_groups", [](Excitation& e, int groups) {
            if (groups < 1 || groups > kMaxRotors) throw py::value_error("1 to 8 groups");
            std::array<float, kMaxRotors> part{};
            const float sum = e.next(part.data(), groups);
            return std::make_pair(sum, std::vector<float>(part.begin(), part.begin() + groups));
        }, py::arg("groups"),
           "The value and each group's part (harmonic i to group i mod groups), then advance.")
        .def_property_readonly("active", &Excitation::active)
        .def_property_readonly("measuring", &Excitation::measuring)
        .def_property_readonly("period_samples", &Excitation::period_samples)
        .def_property_readonly("actual_freq_hz", &Excitation::actual_freq_hz)
        .def_property_readonly("frequency_hz", &Excitation::frequency_hz)
        .def_property_readonly("output_frequency_hz", &Excitation::output_frequency_hz)
        .def_property_readonly("total_samples", &Excitation::total_samples)
        .def_property_readonly("fade_samples", &Excitation::fade_samples)
        .def_property_readonly("peak_exceeded", &Excitation::peak_exceeded)
        .def_property_readonly("state", &Excitation::state);

    py::enum_<InitResult>(m, "InitResult")
        .value("OK_DMP", InitResult::OkDmp).value("OK_RAW", InitResult::OkRaw)
        .value("OK_RAW_FALLBACK", InitResult::OkRawFallback)
        .value("NO_DEVICE", InitResult::NoDevice).value("BUS_ERROR", InitResult::BusError);
    py::enum_<DmpStep>(m, "DmpStep").value("NONE", DmpStep::None).value("TABLES", DmpStep::Tables)
        .value("IMAGE", DmpStep::Image).value("CONFIG", DmpStep::Config)
        .value("REGISTERS", DmpStep::Registers).value("UPDATES", DmpStep::Updates);
    py::enum_<SensorMode>(m, "SensorMode").value("NONE", SensorMode::None)
        .value("DMP", SensorMode::Dmp).value("RAW", SensorMode::Raw);
    py::enum_<ImuHealth>(m, "ImuHealth").value("CONFIGURED", ImuHealth::Configured)
        .value("UNCONFIGURED", ImuHealth::Unconfigured).value("NO_ANSWER", ImuHealth::NoAnswer);
    py::class_<ImuSample>(m, "ImuSample")
        .def(py::init<>())
        .def_readonly("attitude", &ImuSample::attitude)
        .def_readonly("gyro_rad_s", &ImuSample::gyro_rad_s)
        .def_readonly("accel_m_s2", &ImuSample::accel_m_s2)
        .def_readonly("has_attitude", &ImuSample::has_attitude)
        .def_readonly("gyro_clipped", &ImuSample::gyro_clipped)
        .def_readonly("accel_clipped", &ImuSample::accel_clipped);
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
        .def("set_dmp_reference", [](Mpu6050Emulator& e, const py::bytes& image,
                                     const py::bytes& config, const py::bytes& updates) {
            const std::vector<uint8_t> i = byte_vector(image), c = byte_vector(config),
                                       u = byte_vector(updates);
            return e.set_dmp_reference(i.data(), static_cast<uint16_t>(i.size()), c.data(),
                                       static_cast<uint16_t>(c.size()), u.data(),
                                       static_cast<uint16_t>(u.size()));
        }, py::arg("image"), py::arg("config"), py::arg("updates"),
             "The DMP firmware the chip is to run (copied); False when it does not parse.")
        .def_property_readonly("dmp_configured", &Mpu6050Emulator::dmp_configured)
        .def_property_readonly("dmp_status", [](const Mpu6050Emulator& e) {
            return std::string(e.dmp_status());
        })
        .def_property_readonly("dmp_progress", [](const Mpu6050Emulator& e) {
            const Mpu6050Emulator::DmpProgress& p = e.dmp_progress();
            return py::make_tuple(p.image_bytes, p.config_entries, p.updates);
        }, "(image bytes, configuration entries, updates) applied in order since the last reset")
        .def_property_readonly("dmp_config_entries", &Mpu6050Emulator::dmp_config_entries)
        .def("set_stuck_memory_byte", &Mpu6050Emulator::set_stuck_memory_byte, py::arg("address"))
        .def("set_present", &Mpu6050Emulator::set_present)
        .def("set_silent", &Mpu6050Emulator::set_silent)
        .def("power_on_reset", &Mpu6050Emulator::power_on_reset)
        .def("force_overflow", &Mpu6050Emulator::force_overflow)
        .def_property_readonly("fifo_count", &Mpu6050Emulator::fifo_count)
        .def_property_readonly("dmp_enabled", &Mpu6050Emulator::dmp_enabled)
        .def_property_readonly("raw_fifo_enabled", &Mpu6050Emulator::raw_fifo_enabled);

    py::class_<DriverHolder>(m, "Mpu6050")
        .def(py::init(&make_driver), py::arg("dmp_image") = py::bytes(),
             py::arg("dmp_config") = py::bytes(), py::arg("dmp_updates") = py::bytes(),
             py::arg("dmp_rate_div") = 0)
        .def("init", [](DriverHolder& h, Mpu6050Emulator& bus) { return h.driver.init(bus, h.clock); })
        .def("poll", [](DriverHolder& h, Mpu6050Emulator& bus) -> py::object {
            ImuSample s;
            if (h.driver.poll(bus, s)) return py::cast(s);
            return py::none();
        })
        .def("probe", [](DriverHolder& h, Mpu6050Emulator& bus) { return h.driver.probe(bus); })
        .def_property_readonly("sample_rate_hz", [](const DriverHolder& h) { return h.driver.sample_rate_hz(); })
        .def_property_readonly("mode", [](const DriverHolder& h) { return h.driver.mode(); })
        .def_property_readonly("dmp_failure", [](const DriverHolder& h) { return h.driver.dmp_failure(); })
        .def_property_readonly("packet_size", [](const DriverHolder& h) { return h.driver.packet_size(); })
        .def_property_readonly("counters", [](const DriverHolder& h) { return h.driver.counters(); })
        .def_static("parse_dmp_packet", [](const py::bytes& data) -> py::object {
            std::string s = data;
            if (s.size() != mpu6050::kDmpPacketSize) throw py::value_error("a DMP packet is 42 bytes");
            ImuSample out;
            if (!Mpu6050::parse_dmp_packet(reinterpret_cast<const uint8_t*>(s.data()), out)) return py::none();
            return py::cast(out);
        });

    bind_supervisor(m);
    bind_logger(m);
}
