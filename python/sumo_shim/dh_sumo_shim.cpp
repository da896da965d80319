// The native SUMO backend: a C ABI around libsumo's C++ API (libsumocpp), loaded at runtime by
// the Rust core (python/src/sumo_native.rs) so that a co-simulated tick never enters Python.
//
// Built by python/build.rs as `drivehierarchy/_dh_sumo_shim.so` when SUMO's headers are found.
// It links `libsumocpp.so` by its soname; Rust dlopens libsumocpp (RTLD_LOCAL) first, so SUMO's
// symbols stay out of the process's global scope and cannot clash with the `libsumo` Python module.
//
// Every entry point returns 0 on success and -1 on a C++ exception, whose message
// `dh_sumo_error()` then returns. State is per process: libsumo holds one simulation per process.
//
// Semantics mirror the Python backend (envs/traffic/sumo.py): vehicles are tracked from their
// departure to their arrival, read in id order (libsumo's subscription-result order), their
// type's size, class and colour read once per type; keys count departures from 0 (warm-up
// departures included) so both backends hand the world the same keys.

#include <libsumo/libsumo.h>

#include <cstdint>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

namespace {

struct TypeInfo {
    double length, width, height;
    std::string vclass;
    int32_t color[4];
};

struct Tracked {
    uint64_t key;
    const TypeInfo* type;  // points into g_types (node-based: stable)
};

std::string g_error;
std::map<std::string, Tracked> g_vehicles;
std::unordered_map<std::string, TypeInfo> g_types;
uint64_t g_next_key = 0;
std::vector<std::pair<uint64_t, const TypeInfo*>> g_new;  // departed since the last take
std::vector<std::string> g_tls;
std::vector<std::string> g_tl_states;

template <class F>
int guarded(F f) {
    try {
        f();
        return 0;
    } catch (const std::exception& e) {
        g_error = e.what();
    } catch (...) {
        g_error = "unknown C++ exception from libsumo";
    }
    return -1;
}

void reset_state() {
    g_vehicles.clear();
    g_types.clear();
    g_new.clear();
    g_next_key = 0;
    g_tls.clear();
    g_tl_states.clear();
}

const TypeInfo* type_of(const std::string& vid) {
    const std::string vtype = libsumo::Vehicle::getTypeID(vid);
    auto it = g_types.find(vtype);
    if (it == g_types.end()) {
        TypeInfo t;
        t.length = libsumo::VehicleType::getLength(vtype);
        t.width = libsumo::VehicleType::getWidth(vtype);
        t.height = libsumo::VehicleType::getHeight(vtype);
        t.vclass = libsumo::VehicleType::getVehicleClass(vtype);
        const libsumo::TraCIColor c = libsumo::VehicleType::getColor(vtype);
        t.color[0] = c.r;
        t.color[1] = c.g;
        t.color[2] = c.b;
        t.color[3] = c.a;
        it = g_types.emplace(vtype, std::move(t)).first;
    }
    return &it->second;
}

// Departures and arrivals of the step just done. Our own vehicles (ego, mirrors) are "dh_*".
void track() {
    for (const std::string& vid : libsumo::Simulation::getDepartedIDList()) {
        if (vid.rfind("dh_", 0) == 0) {
            continue;
        }
        const TypeInfo* t = type_of(vid);
        const uint64_t key = g_next_key++;
        g_vehicles[vid] = Tracked{key, t};
        g_new.emplace_back(key, t);
    }
    for (const std::string& vid : libsumo::Simulation::getArrivedIDList()) {
        g_vehicles.erase(vid);
    }
}

}  // namespace

#define DH_API __attribute__((visibility("default")))

extern "C" {

// One vehicle present now (SUMO's front-bumper position and angle, as libsumo reports them).
struct DhSumoVehicle {
    uint64_t key;
    double x, y, angle, speed;
    int32_t signals;
    int32_t _pad;
};

// A vehicle that departed: its type's attributes (read once per type).
struct DhSumoNew {
    uint64_t key;
    double length, width, height;
    int32_t color[4];
    char vclass[32];
};

DH_API const char* dh_sumo_error(void) { return g_error.c_str(); }

// `argv[0]` is the sumo binary (libsumo skips it), then SUMO's options.
DH_API int dh_sumo_start(const char* const* argv, int32_t argc) {
    return guarded([&] {
        reset_state();
        std::vector<std::string> cmd(argv, argv + argc);
        libsumo::Simulation::start(cmd);
        g_tls = libsumo::TrafficLight::getIDList();
        g_tl_states.assign(g_tls.size(), std::string());
    });
}

DH_API int dh_sumo_close(void) {
    const int rc = guarded([] {
        if (libsumo::Simulation::isLoaded()) {
            libsumo::Simulation::close();
        }
    });
    reset_state();
    return rc;
}

DH_API double dh_sumo_time(void) { return libsumo::Simulation::getTime(); }

DH_API int dh_sumo_add(const char* vid, const char* route, const char* vtype) {
    return guarded([&] { libsumo::Vehicle::add(vid, route, vtype, "now"); });
}

DH_API int dh_sumo_remove(const char* vid) {
    return guarded([&] { libsumo::Vehicle::remove(vid); });
}

// 1 (and the message in `dh_sumo_error()`) when SUMO cannot map the vehicle (a TraCIException:
// off its network, too far from a lane its class may use); -1 on other failures.
DH_API int dh_sumo_move(const char* vid, double x, double y, double angle, int32_t keep_route) {
    try {
        libsumo::Vehicle::moveToXY(vid, "", -1, x, y, angle, keep_route);
        return 0;
    } catch (const libsumo::TraCIException& e) {
        g_error = e.what();
        return 1;
    } catch (const std::exception& e) {
        g_error = e.what();
    } catch (...) {
        g_error = "unknown C++ exception from libsumo";
    }
    return -1;
}

DH_API int dh_sumo_step(void) {
    return guarded([] {
        libsumo::Simulation::step();
        track();
    });
}

DH_API size_t dh_sumo_vehicle_count(void) { return g_vehicles.size(); }

// Reads every tracked vehicle (id order) into `out` (room for `cap`); `*n` = how many.
DH_API int dh_sumo_read(DhSumoVehicle* out, size_t cap, size_t* n) {
    *n = 0;
    return guarded([&] {
        size_t i = 0;
        for (auto it = g_vehicles.begin(); it != g_vehicles.end() && i < cap;) {
            const std::string& vid = it->first;
            DhSumoVehicle& v = out[i];
            try {
                const libsumo::TraCIPosition p = libsumo::Vehicle::getPosition(vid);
                v.key = it->second.key;
                v.x = p.x;
                v.y = p.y;
                v.angle = libsumo::Vehicle::getAngle(vid);
                v.speed = libsumo::Vehicle::getSpeed(vid);
                v.signals = libsumo::Vehicle::getSignals(vid);
                v._pad = 0;
            } catch (const libsumo::TraCIException&) {
                // Gone without an arrival (as libsumo drops a vanished vehicle's subscription).
                it = g_vehicles.erase(it);
                continue;
            }
            ++i;
            ++it;
        }
        *n = i;
    });
}

DH_API size_t dh_sumo_new_count(void) { return g_new.size(); }

// Hands over the departures since the last take (oldest first; room for `cap`).
DH_API size_t dh_sumo_take_new(DhSumoNew* out, size_t cap) {
    const size_t n = g_new.size() < cap ? g_new.size() : cap;
    for (size_t i = 0; i < n; ++i) {
        const TypeInfo* t = g_new[i].second;
        DhSumoNew& o = out[i];
        o.key = g_new[i].first;
        o.length = t->length;
        o.width = t->width;
        o.height = t->height;
        std::memcpy(o.color, t->color, sizeof(o.color));
        std::memset(o.vclass, 0, sizeof(o.vclass));
        std::strncpy(o.vclass, t->vclass.c_str(), sizeof(o.vclass) - 1);
    }
    g_new.erase(g_new.begin(), g_new.begin() + static_cast<std::ptrdiff_t>(n));
    return n;
}

DH_API size_t dh_sumo_tl_count(void) { return g_tls.size(); }

DH_API const char* dh_sumo_tl_id(size_t i) { return i < g_tls.size() ? g_tls[i].c_str() : ""; }

// Refreshes every light's state string; `dh_sumo_tl_state(i)` then returns it.
DH_API int dh_sumo_read_lights(void) {
    return guarded([] {
        for (size_t i = 0; i < g_tls.size(); ++i) {
            g_tl_states[i] = libsumo::TrafficLight::getRedYellowGreenState(g_tls[i]);
        }
    });
}

DH_API const char* dh_sumo_tl_state(size_t i) { return i < g_tl_states.size() ? g_tl_states[i].c_str() : ""; }

DH_API int dh_sumo_set_phase(const char* tl, int32_t phase, double remaining_s) {
    return guarded([&] {
        libsumo::TrafficLight::setPhase(tl, phase);
        libsumo::TrafficLight::setPhaseDuration(tl, remaining_s);
    });
}

// Installs and switches to a replacement program (the scenario's `[[lights]] phases`).
DH_API int dh_sumo_set_program(const char* tl, size_t n, const char* const* states, const double* durations) {
    return guarded([&] {
        std::vector<std::shared_ptr<libsumo::TraCIPhase>> phases;
        for (size_t i = 0; i < n; ++i) {
            phases.push_back(std::make_shared<libsumo::TraCIPhase>(durations[i], std::string(states[i])));
        }
        libsumo::TrafficLight::setProgramLogic(tl, libsumo::TraCILogic("dh_override", 0, 0, phases));
        libsumo::TrafficLight::setProgram(tl, "dh_override");
    });
}

}  // extern "C"
