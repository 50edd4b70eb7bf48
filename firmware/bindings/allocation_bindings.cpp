// Python bindings of the control allocation from a rotor geometry (core/allocation.hpp), for
// the tests: the geometry, the matrices it gives, and the allocation itself. Host build only.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <map>
#include <string>
#include <vector>

#include "core/allocation.hpp"
#include "core/params.hpp"

namespace py = pybind11;
using namespace hq;

namespace {

Vec3 vec3(const std::array<float, 3>& v) { return Vec3{v[0], v[1], v[2]}; }

AllocationGeometry geometry_of(const std::vector<RotorGeometry>& rotors, float hover_thrust_n) {
    if (rotors.size() > static_cast<size_t>(kMaxRotors))
        throw py::value_error("at most " + std::to_string(kMaxRotors) + " rotors");
    AllocationGeometry g;
    g.count = static_cast<int>(rotors.size());
    g.hover_thrust_n = hover_thrust_n;
    for (size_t i = 0; i < rotors.size(); ++i) g.rotor[i] = rotors[i];
    return g;
}

std::vector<RotorGeometry> rotors_of(const AllocationGeometry& g) {
    const int n = g.count < kMaxRotors ? g.count : kMaxRotors;
    return std::vector<RotorGeometry>(g.rotor, g.rotor + n);
}

}  // namespace

void bind_allocation(py::module_& m) {
    m.attr("MIN_ROTORS") = kMinRotors;
    m.attr("MAX_ROTORS") = kMaxRotors;
    py::class_<RotorGeometry>(m, "RotorGeometry")
        .def(py::init([](std::array<float, 3> position_m, std::array<float, 3> axis,
                         float max_thrust_n, float moment_ratio_m, int spin) {
                 RotorGeometry r;
                 r.position_m = vec3(position_m);
                 r.axis = vec3(axis);
                 r.max_thrust_n = max_thrust_n;
                 r.moment_ratio_m = moment_ratio_m;
                 r.spin = spin;
                 return r;
             }),
             py::arg("position_m"), py::arg("axis"), py::arg("max_thrust_n"),
             py::arg("moment_ratio_m") = 0.0f, py::arg("spin") = 1)
        .def_property("position_m", [](const RotorGeometry& r) {
            return std::array<float, 3>{r.position_m.x, r.position_m.y, r.position_m.z};
        }, [](RotorGeometry& r, std::array<float, 3> v) { r.position_m = vec3(v); })
        .def_property("axis", [](const RotorGeometry& r) {
            return std::array<float, 3>{r.axis.x, r.axis.y, r.axis.z};
        }, [](RotorGeometry& r, std::array<float, 3> v) { r.axis = vec3(v); })
        .def_readwrite("max_thrust_n", &RotorGeometry::max_thrust_n)
        .def_readwrite("moment_ratio_m", &RotorGeometry::moment_ratio_m)
        .def_readwrite("spin", &RotorGeometry::spin);
    py::class_<AllocationGeometry>(m, "AllocationGeometry")
        .def(py::init(&geometry_of), py::arg("rotors"), py::arg("hover_thrust_n"))
        .def_property_readonly("rotors", &rotors_of)
        .def_readonly("count", &AllocationGeometry::count)
        .def_readonly("hover_thrust_n", &AllocationGeometry::hover_thrust_n);
    m.def("canted_arms_geometry", &canted_arms_geometry, py::arg("geometry") = MixerGeometry(),
          py::arg("arms") = 4,
          "The mixer's vehicle as rotors: the central one and `arms` canted arm rotors.");
    m.def("params_geometry", [](const std::map<std::string, float>& values) {
        Params params;
        for (const auto& [name, value] : values) {
            const int index = param_index(name.c_str(), name.size());
            if (index < 0) throw py::key_error("no parameter " + name);
            const SetResult r = params.set(index, value, false, false);
            if (r != SetResult::Ok && r != SetResult::Unchanged) {
                char text[64];
                set_result_text(r, index, text, sizeof text);
                throw py::value_error(text);
            }
        }
        return allocation_geometry(params.values().geometry);
    }, py::arg("values") = std::map<std::string, float>{},
       "The geometry the firmware's CA_* parameters give: the defaults, with `values` (name to "
       "value) set as a ground station would set them (refused values raise ValueError).");
    py::class_<AllocationOutput>(m, "AllocationOutput")
        .def_property_readonly("motor", [](const AllocationOutput& o) {
            return std::vector<float>(o.motor, o.motor + kMaxRotors);
        })
        .def_readonly("saturated", &AllocationOutput::saturated)
        .def_readonly("torque_limited", &AllocationOutput::torque_limited)
        .def_readonly("collective_limited", &AllocationOutput::collective_limited);
    py::class_<Allocation>(m, "Allocation")
        .def(py::init<const AllocationGeometry&>(),
             py::arg("geometry") = canted_arms_geometry(MixerGeometry()))
        .def("configure", &Allocation::configure)
        .def_property_readonly("ok", &Allocation::ok)
        .def_property_readonly("reason", &Allocation::reason)
        .def_property_readonly("count", &Allocation::count)
        .def("allocate", &Allocation::allocate)
        .def("achieved", [](const Allocation& a, const std::vector<float>& motor) {
            if (motor.size() != static_cast<size_t>(a.count()))
                throw py::value_error("one thrust fraction per rotor");
            return a.achieved(motor.data());
        })
        .def_property_readonly("effectiveness", [](const Allocation& a) {
            std::vector<std::vector<float>> b(kAllocationRows);
            for (int k = 0; k < kAllocationRows; ++k)
                for (int i = 0; i < a.count(); ++i) b[k].push_back(a.effectiveness(k, i));
            return b;
        }, "B, rows vertical force (N) and roll, pitch, yaw (N m) per unit thrust fraction.")
        .def_property_readonly("allocation", [](const Allocation& a) {
            std::vector<std::vector<float>> p(a.count());
            for (int i = 0; i < a.count(); ++i)
                for (int k = 0; k < kAllocationRows; ++k) p[i].push_back(a.allocation(i, k));
            return p;
        }, "A, per rotor the thrust fraction per unit of collective, roll, pitch, yaw.")
        .def_property_readonly("units", [](const Allocation& a) {
            return std::array<float, kAllocationRows>{a.unit(0), a.unit(1), a.unit(2), a.unit(3)};
        }, "One unit of collective, roll, pitch, yaw: N, then N m.")
        .def_property_readonly("hover_fractions", [](const Allocation& a) {
            std::vector<float> h;
            for (int i = 0; i < a.count(); ++i) h.push_back(a.hover_fraction(i));
            return h;
        });
}
