// heliquad._simcore, the module itself: the Python binding of the simulator's per-frame work,
// each part beside the Python of its concept (plant/: the plants; sensor/: FIFO packets;
// rig/: the sim link, the lockstep engine, the telemetry tap; chip/: the emulated MK64,
// bound by chip/mk64_bindings.cpp). Python owns configuration, random numbers, truth and
// logging; see docs/architecture.md.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "plant/tf_axis.hpp"
#include "plant/vehicle_model.hpp"
#include "rig/rig_engine.hpp"
#include "rig/sim_link.hpp"
#include "rig/telemetry_tap.hpp"
#include "sensor/fifo_packets.hpp"

namespace py = pybind11;
using namespace hqsim;

void bind_mk64(py::module_& m);     // mk64_bindings.cpp
void bind_thumb(py::module_& m);    // chip/thumb_bindings.cpp

namespace {

using DArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// A flat copy of `a` (or empty for None), checked to hold `rows` x `cols` values.
std::vector<double> rows_of(const py::object& a, size_t rows, size_t cols, const char* name) {
    if (a.is_none()) return {};
    DArray arr = DArray::ensure(a);
    if (!arr || static_cast<size_t>(arr.size()) != rows * cols) {
        throw std::invalid_argument(std::string(name) + " must have " + std::to_string(rows) +
                                    " x " + std::to_string(cols) + " values");
    }
    return std::vector<double>(arr.data(), arr.data() + arr.size());
}

// Pointer to `n` doubles of an optional vector argument (nullptr for None).
const double* optional(const std::vector<double>& v) { return v.empty() ? nullptr : v.data(); }

py::tuple sample_tuple(const SensorSample& s) {
    return py::make_tuple(s.q, s.gyro_rad_s, s.accel_m_s2);
}

py::bytes packet(FifoKind kind, const SensorSample& s) {
    uint8_t out[kDmpPacketSize];
    const size_t n = encode_fifo(kind, s, out);
    return py::bytes(reinterpret_cast<const char*>(out), n);
}

// One thrust fraction per rotor of the plant, as the firmware's kMaxRotors-wide array.
std::array<float, kMaxRotors> motors(const RigPlant& p, const std::vector<double>& m) {
    if (m.size() != static_cast<size_t>(p.rotors())) {
        throw std::invalid_argument(std::to_string(p.rotors()) +
                                    " motor commands expected, one per rotor");
    }
    std::array<float, kMaxRotors> f{};
    for (size_t r = 0; r < m.size(); ++r) f[r] = static_cast<float>(m[r]);
    return f;
}

// The tap's messages as [(msgid, payload bytes)].
py::list tapped_list(const std::vector<TappedMessage>& got) {
    py::list out;
    for (const auto& m : got) {
        out.append(py::make_tuple(
            m.msgid, py::bytes(reinterpret_cast<const char*>(m.payload.data()), m.payload.size())));
    }
    return out;
}

// The model's state values in use (the body's and one per rotor) as an array, and back.
py::array_t<double> to_array(const VehicleModel& v, const State& s) {
    py::array_t<double> a(v.states());
    std::memcpy(a.mutable_data(), s.data(), sizeof(double) * v.states());
    return a;
}

State to_state(const VehicleModel& v, const DArray& a) {
    if (a.size() != v.states()) {
        throw std::invalid_argument("the state has " + std::to_string(v.states()) +
                                    " values: 13 and one per rotor");
    }
    State s{};
    std::memcpy(s.data(), a.data(), sizeof(double) * v.states());
    return s;
}

// The model's thrust fractions, one per rotor.
void check_rotor_commands(const VehicleModel& v, const std::vector<double>& u) {
    if (u.size() != static_cast<size_t>(v.config().rotors)) {
        throw std::invalid_argument(std::to_string(v.config().rotors) +
                                    " rotor commands expected");
    }
}

}  // namespace

PYBIND11_MODULE(_simcore, m) {
    bind_mk64(m);
    bind_thumb(m);
    m.doc() = "heliquad simulator core: plants, MPU6050 FIFO packets, sim link, lockstep engine";
    // The chip's scales and packet sizes (the firmware driver's) and the sensor frame's FIFO
    // capacity and RC channels (the dialect's), for Python.
    m.attr("GRAVITY_M_S2") = kGravity;
    m.attr("MAX_ROTORS") = kMaxRotors;          // the vehicle model's room: the firmware's
    m.attr("FIRMWARE_MOTORS") = kMotors;        // the rotors the firmware flies by default
    m.attr("GYRO_LSB_PER_DEG_S") = kGyroLsbPerDegS;
    m.attr("ACCEL_LSB_PER_G") = kAccelLsbPerG;
    m.attr("QUAT_SCALE") = kQuatScale;
    m.attr("DMP_PACKET_SIZE") = kDmpPacketSize;
    m.attr("RAW_PACKET_SIZE") = kRawPacketSize;
    m.attr("FIFO_CAPACITY") = kFifoCapacity;
    m.attr("RC_CHANNELS") = kRcChannels;

    m.def("dmp_packet", [](std::array<double, 4> q, std::array<double, 3> gyro,
                           std::array<double, 3> accel) {
        return packet(FifoKind::Dmp, SensorSample{q, gyro, accel});
    }, py::arg("q_frd"), py::arg("gyro_rad_s_frd"), py::arg("accel_m_s2_frd"),
       "One 42-byte DMP packet, quantised as the chip quantises.");
    m.def("raw_packet", [](std::array<double, 3> gyro, std::array<double, 3> accel) {
        return packet(FifoKind::Raw, SensorSample{{1, 0, 0, 0}, gyro, accel});
    }, py::arg("gyro_rad_s_frd"), py::arg("accel_m_s2_frd"),
       "One 12-byte raw FIFO sample: accel x, y, z then gyro x, y, z.");

    py::class_<RigPlant>(m, "RigPlant")
        .def("sensor", [](RigPlant& p, py::object noise) {
            const auto n = rows_of(noise, 1, 6, "noise");
            return sample_tuple(p.sensor(optional(n)));
        }, py::arg("noise") = py::none(), "(q, gyro, accel) the firmware reads this frame")
        .def("fifo", [](RigPlant& p, int kind, py::object noise) {
            const auto n = rows_of(noise, 1, 6, "noise");
            return packet(static_cast<FifoKind>(kind), p.sensor(optional(n)));
        }, py::arg("kind"), py::arg("noise") = py::none(),
           "This frame's FIFO bytes of the given HQ_SENSOR_KIND")
        .def("step_motors", [](RigPlant& p, const std::vector<double>& motor, py::object gust) {
            const auto g = rows_of(gust, 1, 6, "gust");
            const auto f = motors(p, motor);
            p.step(f.data(), optional(g));
        }, py::arg("motor"), py::arg("gust") = py::none())
        .def_property_readonly("rotors", &RigPlant::rotors, "the thrust fractions step takes");

    py::class_<TfAxis, RigPlant>(m, "TfAxis")
        .def(py::init<std::vector<double>, std::vector<double>, std::vector<double>, double, int>(),
             py::arg("a"), py::arg("b"), py::arg("c"), py::arg("dt_s"), py::arg("axis"))
        .def("step_command", &TfAxis::step_command, py::arg("u"))
        .def_property_readonly("rate_rad_s", &TfAxis::rate_rad_s)
        .def_property_readonly("angle_rad", &TfAxis::angle_rad)
        .def_property_readonly("quaternion", &TfAxis::quaternion)
        .def_property_readonly("rates", &TfAxis::rates);

    py::class_<VehicleConfig>(m, "VehicleConfig")
        .def(py::init<>())
        .def_readwrite("mass_kg", &VehicleConfig::mass_kg)
        .def_readwrite("inertia_kg_m2", &VehicleConfig::inertia_kg_m2)
        .def_readwrite("drag_n_s_m", &VehicleConfig::drag_n_s_m)
        .def_readwrite("gravity_m_s2", &VehicleConfig::gravity_m_s2)
        .def_readwrite("hinge_damping_n_m_s_rad", &VehicleConfig::hinge_damping_n_m_s_rad)
        .def_readwrite("hinge_friction_n_m", &VehicleConfig::hinge_friction_n_m)
        .def_readwrite("free_axis", &VehicleConfig::free_axis)
        .def_readwrite("substeps", &VehicleConfig::substeps)
        .def_readwrite("rotors", &VehicleConfig::rotors)
        .def_readwrite("thrust_dir", &VehicleConfig::thrust_dir)
        .def_readwrite("thrust_moment", &VehicleConfig::thrust_moment)
        .def_readwrite("spin_axis", &VehicleConfig::spin_axis)
        .def_readwrite("k_thrust", &VehicleConfig::k_thrust)
        .def_readwrite("c_torque", &VehicleConfig::c_torque)
        .def_readwrite("j_rotor", &VehicleConfig::j_rotor)
        .def_readwrite("tau_s", &VehicleConfig::tau_s)
        .def_readwrite("w_max_rad_s", &VehicleConfig::w_max_rad_s);

    py::class_<VehicleModel>(m, "VehicleModel")
        .def(py::init<const VehicleConfig&>(), py::arg("config"))
        // A view of the state: writing into it (x[10:13] = ...) sets the model's state.
        .def_property("x", [](py::object self) {
            VehicleModel& v = self.cast<VehicleModel&>();
            return py::array_t<double>(v.states(), v.x.data(), self);
        }, [](VehicleModel& v, const DArray& a) { v.x = to_state(v, a); })
        .def("derivative", [](const VehicleModel& v, const DArray& x, const std::vector<double>& u,
                              py::object force, py::object moment) {
            check_rotor_commands(v, u);
            const auto f = rows_of(force, 1, 3, "force_ned");
            const auto mo = rows_of(moment, 1, 3, "moment_body");
            return to_array(v, v.derivative(to_state(v, x), u.data(), optional(f), optional(mo)));
        }, py::arg("x"), py::arg("u"), py::arg("force_ned") = py::none(),
           py::arg("moment_body") = py::none())
        .def("step", [](VehicleModel& v, const std::vector<double>& u, double dt_s,
                        py::object force, py::object moment) {
            check_rotor_commands(v, u);
            const auto f = rows_of(force, 1, 3, "force_ned");
            const auto mo = rows_of(moment, 1, 3, "moment_body");
            v.step(u.data(), dt_s, optional(f), optional(mo));
        }, py::arg("u"), py::arg("dt_s"), py::arg("force_ned") = py::none(),
           py::arg("moment_body") = py::none());

    py::class_<ImuConfig>(m, "ImuConfig")
        .def(py::init<>())
        .def_readwrite("enabled", &ImuConfig::enabled)
        .def_readwrite("gyro_bias_rad_s", &ImuConfig::gyro_bias_rad_s)
        .def_readwrite("latency_samples", &ImuConfig::latency_samples);

    py::class_<VehicleRig, RigPlant>(m, "VehicleRig")
        .def(py::init<VehicleModel&, double, const ImuConfig&, double>(), py::arg("model"),
             py::arg("dt_s"), py::arg("imu"), py::arg("rotational_damping_n_m_s_rad"),
             py::keep_alive<1, 2>())
        .def("specific_force", &VehicleRig::specific_force);

    py::enum_<LinkStatus>(m, "LinkStatus")
        .value("OK", LinkStatus::Ok)
        .value("WRITE_FAILED", LinkStatus::WriteFailed)
        .value("CLOSED", LinkStatus::Closed)
        .value("TIMEOUT", LinkStatus::Timeout)
        .value("WRONG_FRAME", LinkStatus::WrongFrame)
        .value("CANCELLED", LinkStatus::Cancelled)
        .value("ROTOR_COUNT", LinkStatus::RotorCount);

    py::class_<Reply>(m, "Reply")
        .def_readonly("time_us", &Reply::time_us)
        .def_readonly("frame", &Reply::frame)
        .def_property_readonly("motor", [](const Reply& r) {      // the rotors flown
            const int n = r.motor_count < kMaxRotors ? r.motor_count : kMaxRotors;
            return std::vector<double>(r.motor.begin(), r.motor.begin() + n);
        })
        .def_readonly("motor_count", &Reply::motor_count)
        .def_property_readonly("armed", [](const Reply& r) { return r.armed != 0; })
        .def_readonly("mode", &Reply::mode)
        .def_readonly("sensor_kind", &Reply::sensor_kind);

    py::class_<SimLinkPort>(m, "SimLinkPort")
        .def(py::init<int, int>(), py::arg("fd"), py::arg("timeout_ms"))
        .def("exchange", [](SimLinkPort& p, uint64_t time_us, uint32_t frame, uint8_t kind,
                            const py::bytes& fifo, const std::array<uint16_t, kRcChannels>& rc,
                            bool sync, uint8_t imu_fault) {
            const std::string data = fifo;
            if (data.size() > kFifoCapacity) {
                throw std::invalid_argument("at most " + std::to_string(kFifoCapacity) +
                                            " FIFO bytes per frame");
            }
            Reply reply;
            LinkStatus st;
            {
                py::gil_scoped_release release;
                st = p.exchange(time_us, frame, kind,
                                reinterpret_cast<const uint8_t*>(data.data()), data.size(),
                                rc.data(), sync, imu_fault, &reply);
            }
            return py::make_tuple(st, reply, p.error());
        }, py::arg("time_us"), py::arg("frame"), py::arg("kind"), py::arg("fifo"), py::arg("rc_us"),
           py::arg("sync") = true, py::arg("imu_fault") = uint8_t{HQ_IMU_FAULT_NONE},
           "One sensor frame out, its reply in: (status, reply, errno).");

    py::class_<BatchResult>(m, "BatchResult")
        .def_readonly("status", &BatchResult::status)
        .def_readonly("frames_done", &BatchResult::frames_done)
        .def_readonly("failed_frame", &BatchResult::failed_frame)
        .def_readonly("last", &BatchResult::last);

    py::class_<TelemetryTap>(m, "TelemetryTap")
        .def(py::init<int, int, std::vector<uint32_t>, uint64_t>(), py::arg("tel_fd"),
             py::arg("tlog_fd"), py::arg("wanted"), py::arg("offset_us") = 0,
             "offset_us: added to every record's stamp (the run's start, us since 1970); "
             "last_time_us stays simulated time.")
        .def("read", [](TelemetryTap& t) {
            std::vector<TappedMessage> got;
            {
                py::gil_scoped_release release;
                got = t.read();
            }
            return tapped_list(got);
        }, "Read, frame and log what has arrived; [(msgid, payload)] of the wanted messages.")
        .def("drain", [](TelemetryTap& t) {
            std::vector<TappedMessage> got;
            {
                py::gil_scoped_release release;
                got = t.drain();
            }
            return tapped_list(got);
        }, "read(), then log the packets still waiting for a loop's sample with the last "
           "loop's time; for the end of a session.")
        .def_property_readonly("last_time_us", &TelemetryTap::last_time_us)
        .def_property_readonly("offset_us", &TelemetryTap::offset_us)
        .def_property_readonly("packets", &TelemetryTap::packets)
        .def_property_readonly("write_failed", &TelemetryTap::write_failed)
        .def_property_readonly("write_errno", &TelemetryTap::write_errno);

    py::class_<RigEngine>(m, "RigEngine")
        .def(py::init<SimLinkPort&, RigPlant&>(), py::arg("port"), py::arg("plant"),
             py::keep_alive<1, 2>(), py::keep_alive<1, 3>())
        .def("start", [](RigEngine& e, uint32_t first, uint32_t n, uint32_t dt_us, uint8_t kind,
                         py::array_t<uint16_t, py::array::c_style | py::array::forcecast> rc,
                         py::object noise, py::object gust, py::object imu_faults) {
            std::vector<uint16_t> r(rc.data(), rc.data() + rc.size());
            std::vector<uint8_t> faults;
            if (!imu_faults.is_none()) {
                auto f = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>::ensure(imu_faults);
                if (!f) throw std::invalid_argument("imu_faults must be n HQ_IMU_FAULT values");
                faults.assign(f.data(), f.data() + f.size());
            }
            e.start(first, n, dt_us, kind, std::move(r), rows_of(noise, n, 6, "noise"),
                    rows_of(gust, n, 6, "gust"), std::move(faults));
        }, py::arg("first"), py::arg("n"), py::arg("dt_us"), py::arg("kind"), py::arg("rc"),
           py::arg("noise") = py::none(), py::arg("gust") = py::none(),
           py::arg("imu_faults") = py::none())
        .def("finished", &RigEngine::finished)
        .def("running", &RigEngine::running,
             "Whether a batch was started and not yet waited for (it may have finished).")
        .def("wait_finished", &RigEngine::wait_finished, py::arg("timeout_s"),
             py::call_guard<py::gil_scoped_release>(),
             "Sleep until the batch is finished or the timeout passes; True if finished.")
        .def("cancel", &RigEngine::cancel)
        .def("wait", &RigEngine::wait, py::call_guard<py::gil_scoped_release>());
}
