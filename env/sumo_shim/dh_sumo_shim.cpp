// A C ABI over SUMO's C++ client API, loaded at runtime by `dh-env` (env/src/world/sumo/shim.rs):
// the transport of the Rust SUMO orchestration. Built twice by env/build.rs from this one file:
//
// - `_dh_sumo_shim.so` against libsumo (`libsumocpp.so`): SUMO inside this process, one
//   simulation per process (libsumo's state is global);
// - `_dh_sumo_traci.so` (`-DDH_LIBTRACI`) against libtraci (`libtracicpp.so`): SUMO as a
//   subprocess (the `sumo` binary) spoken to over TraCI on 127.0.0.1, one connection per
//   simulation, so any number of simulations run in one process.
//
// Both libraries have the same API (namespace `libsumo` / `libtraci`); the Rust side loads the
// library first (RTLD_LOCAL), then this shim, which links it by its soname.
//
// The shim only transports: what to add, move, step, read. The orchestration (command line,
// warm-up, light sync, mirrors, departure keys, type cache) lives once, in Rust.
//
// Every entry point returns 0 on success and -1 on a C++ exception, whose message
// `dh_sumo_error()` then returns. The state of each simulation lives in a `Session`, chosen by
// `dh_sumo_switch(label)` (libtraci's connection label; libsumo has one, "default").

#ifdef DH_LIBTRACI
#include <libsumo/libtraci.h>
namespace api = libtraci;
#else
#include <libsumo/libsumo.h>
namespace api = libsumo;
#endif

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <string>
#include <vector>

#ifdef DH_LIBTRACI
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

extern char** environ;
#endif

namespace {

struct Session {
    std::map<std::string, uint64_t> tracked;  // id order = libsumo's subscription-result order
    std::vector<std::string> departed;         // of the last step
    std::vector<std::string> tls;
    std::vector<std::string> tl_states;
    std::string scratch;                       // returned strings live here until the next call
    int pid = -1;                              // TraCI: the `sumo` subprocess (ours to reap)
};

std::string g_error;
std::map<std::string, Session> g_sessions;
Session* g_cur = nullptr;
std::string g_label;

template <class F>
int guarded(F f) {
    try {
        f();
        return 0;
    } catch (const std::exception& e) {
        g_error = e.what();
    } catch (...) {
        g_error = "unknown C++ exception from SUMO";
    }
    return -1;
}

Session& cur() {
    if (g_cur == nullptr) {
        throw std::runtime_error("no SUMO session selected");
    }
    return *g_cur;
}

#ifdef DH_LIBTRACI
const std::vector<int> kVars = {libsumo::VAR_POSITION, libsumo::VAR_ANGLE, libsumo::VAR_SPEED,
                                libsumo::VAR_SIGNALS};

// We start `sumo` ourselves instead of `libtraci::Simulation::start`: that one connects the
// moment it has spawned SUMO, which is still loading its network, and on the refused connection
// prints "Could not connect ... Retrying in 1 second" and sleeps a whole second, on every start.
// Here the connection is made once SUMO listens. (Polling with libtraci's own connect is not an
// option: a failed `Connection` deletes whichever connection is active, another session's.)

int free_port() {
    const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) {
        throw std::runtime_error(std::string("socket(): ") + std::strerror(errno));
    }
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t n = sizeof a;
    const bool ok = bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
                    getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n) == 0;
    const int err = errno;
    close(fd);
    if (!ok) {
        throw std::runtime_error(std::string("no free TCP port on 127.0.0.1: ") + std::strerror(err));
    }
    return ntohs(a.sin_port);
}

// Whether a socket of this network namespace listens on `port` (the kernel's table, so that
// probing never takes SUMO's one client connection).
bool listening(int port) {
    for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
        std::ifstream in(table);
        std::string line;
        std::getline(in, line);  // header
        while (std::getline(in, line)) {
            std::istringstream fields(line);
            std::string slot, local, remote, state;
            fields >> slot >> local >> remote >> state;
            const auto colon = local.rfind(':');
            if (state == "0A" && colon != std::string::npos &&
                std::strtol(local.c_str() + colon + 1, nullptr, 16) == port) {
                return true;
            }
        }
    }
    return false;
}

// Waits for the child `pid` up to `grace`; then kills it. Never leaves a zombie.
void reap(int pid, std::chrono::milliseconds grace) {
    if (pid <= 0) {
        return;
    }
    const auto until = std::chrono::steady_clock::now() + grace;
    while (waitpid(pid, nullptr, WNOHANG) == 0) {
        if (std::chrono::steady_clock::now() >= until) {
            kill(pid, SIGKILL);
            waitpid(pid, nullptr, 0);
            return;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
}

// Starts `cmd` (the sumo binary and its options) with a TraCI server on a free port, and
// connects to it as `label` once it listens. `pid` is SUMO's from the moment it runs.
void start_sumo(std::vector<std::string> cmd, const std::string& label, int& pid) {
    const int port = free_port();
    cmd.push_back("--remote-port");
    cmd.push_back(std::to_string(port));
    std::vector<char*> argv;
    for (std::string& arg : cmd) {
        argv.push_back(arg.data());
    }
    argv.push_back(nullptr);
    pid_t child = -1;
    const int rc = posix_spawn(&child, argv[0], nullptr, nullptr, argv.data(), environ);
    if (rc != 0) {
        throw std::runtime_error("cannot start " + cmd[0] + ": " + std::strerror(rc));
    }
    pid = child;
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    auto pause = std::chrono::microseconds(500);
    while (!listening(port)) {
        int status = 0;
        const pid_t done = waitpid(pid, &status, WNOHANG);
        if (done == pid || (done < 0 && errno == ECHILD)) {  // ECHILD: someone else reaped it
            const std::string how = done != pid ? "early"
                                    : WIFEXITED(status) ? "with status " + std::to_string(WEXITSTATUS(status))
                                                        : "on signal " + std::to_string(WTERMSIG(status));
            throw std::runtime_error("SUMO (" + cmd[0] + ") exited " + how + " before it accepted TraCI");
        }
        if (std::chrono::steady_clock::now() >= until) {
            reap(pid, std::chrono::milliseconds(0));
            throw std::runtime_error("SUMO (" + cmd[0] + ") did not open its TraCI port within 120 s");
        }
        std::this_thread::sleep_for(pause);
        pause = std::min(pause * 2, std::chrono::microseconds(20000));
    }
    api::Simulation::init(port, libsumo::DEFAULT_NUM_RETRIES, "localhost", label);
}
#endif

}  // namespace

#define DH_API __attribute__((visibility("default")))

extern "C" {

// One tracked vehicle present now (SUMO's front-bumper position and angle).
struct DhSumoVehicle {
    uint64_t key;
    double x, y, angle, speed;
    int32_t signals;
    int32_t _pad;
};

// A vehicle type's attributes.
struct DhSumoType {
    double length, width, height;
    int32_t color[4];
    char vclass[32];
};

DH_API const char* dh_sumo_error(void) { return g_error.c_str(); }

// Selects the session (connection) `label` for the calls that follow.
DH_API int dh_sumo_switch(const char* label) {
    return guarded([&] {
        if (g_cur != nullptr && g_label == label) {
            return;
        }
        auto it = g_sessions.find(label);
        if (it == g_sessions.end()) {
            throw std::runtime_error(std::string("no SUMO session ") + label);
        }
#ifdef DH_LIBTRACI
        api::Simulation::switchConnection(label);
#endif
        g_cur = &it->second;
        g_label = label;
    });
}

// `argv[0]` is the sumo binary, then SUMO's options. Over TraCI it runs as our subprocess with
// its server on a free port of 127.0.0.1, connected as `label` (`start_sumo`).
DH_API int dh_sumo_start(const char* const* argv, int32_t argc, const char* label) {
    int pid = -1;
    const int rc = guarded([&] {
        std::vector<std::string> cmd(argv, argv + argc);
        g_cur = nullptr;
#ifdef DH_LIBTRACI
        auto old = g_sessions.find(label);
        if (old != g_sessions.end()) {
            reap(old->second.pid, std::chrono::milliseconds(0));
        }
#endif
        g_sessions.erase(label);
#ifdef DH_LIBTRACI
        start_sumo(cmd, label, pid);
#else
        api::Simulation::start(cmd);
#endif
        Session& s = g_sessions[label];
        s.pid = pid;
        g_cur = &s;
        g_label = label;
        s.tls = api::TrafficLight::getIDList();
        s.tl_states.assign(s.tls.size(), std::string());
    });
#ifdef DH_LIBTRACI
    // SUMO may open its port and then fail loading its inputs: it ends itself, and its error log
    // is complete only once it has, so wait for it before the caller reads that log.
    if (rc != 0 && pid > 0) {
        reap(pid, std::chrono::milliseconds(30000));  // a guard: SUMO exits at once
        auto it = g_sessions.find(label);
        if (it != g_sessions.end()) {
            it->second.pid = -1;
        }
    }
#endif
    return rc;
}

// Closes the selected session (its SUMO stops).
DH_API int dh_sumo_close(const char* label) {
    const int rc = guarded([&] {
        if (g_sessions.count(label) == 0) {
            return;
        }
#ifdef DH_LIBTRACI
        api::Simulation::switchConnection(label);
        api::Simulation::close();
#else
        if (api::Simulation::isLoaded()) {
            api::Simulation::close();
        }
#endif
    });
#ifdef DH_LIBTRACI
    // After CMD_CLOSE, SUMO ends its run and exits; a SUMO that no longer answers is killed.
    auto it = g_sessions.find(label);
    if (it != g_sessions.end()) {
        reap(it->second.pid, std::chrono::milliseconds(rc == 0 ? 10000 : 0));
    }
#endif
    g_sessions.erase(label);
    g_cur = nullptr;
    g_label.clear();
    return rc;
}

DH_API int dh_sumo_time(double* t) {
    return guarded([&] { *t = api::Simulation::getTime(); });
}

DH_API int dh_sumo_add(const char* vid, const char* route, const char* vtype) {
    return guarded([&] { api::Vehicle::add(vid, route, vtype, "now"); });
}

DH_API int dh_sumo_remove(const char* vid) {
    return guarded([&] { api::Vehicle::remove(vid); });
}

// 1 (and the message in `dh_sumo_error()`) when SUMO cannot map the vehicle (a TraCIException:
// off its network, too far from a lane its class may use); -1 on other failures.
DH_API int dh_sumo_move(const char* vid, double x, double y, double angle, int32_t keep_route) {
    try {
        api::Vehicle::moveToXY(vid, "", -1, x, y, angle, keep_route);
        return 0;
    } catch (const libsumo::TraCIException& e) {
        g_error = e.what();
        return 1;
    } catch (const std::exception& e) {
        g_error = e.what();
    } catch (...) {
        g_error = "unknown C++ exception from SUMO";
    }
    return -1;
}

// One step; then the departures of the step (`dh_sumo_departed*`) and tracked vehicles that
// arrived leave the tracking.
DH_API int dh_sumo_step(void) {
    return guarded([] {
        Session& s = cur();
        api::Simulation::step();
        s.departed = api::Simulation::getDepartedIDList();
        for (const std::string& vid : api::Simulation::getArrivedIDList()) {
            s.tracked.erase(vid);
        }
    });
}

DH_API size_t dh_sumo_departed_count(void) { return g_cur ? g_cur->departed.size() : 0; }

DH_API const char* dh_sumo_departed_id(size_t i) {
    return g_cur && i < g_cur->departed.size() ? g_cur->departed[i].c_str() : "";
}

// The vehicle's type id (valid until the next call).
DH_API int dh_sumo_vehicle_type(const char* vid, const char** out) {
    return guarded([&] {
        Session& s = cur();
        s.scratch = api::Vehicle::getTypeID(vid);
        *out = s.scratch.c_str();
    });
}

DH_API int dh_sumo_type_info(const char* vtype, DhSumoType* t) {
    return guarded([&] {
        t->length = api::VehicleType::getLength(vtype);
        t->width = api::VehicleType::getWidth(vtype);
        t->height = api::VehicleType::getHeight(vtype);
        const std::string vclass = api::VehicleType::getVehicleClass(vtype);
        std::memset(t->vclass, 0, sizeof(t->vclass));
        std::strncpy(t->vclass, vclass.c_str(), sizeof(t->vclass) - 1);
        const libsumo::TraCIColor c = api::VehicleType::getColor(vtype);
        t->color[0] = c.r;
        t->color[1] = c.g;
        t->color[2] = c.b;
        t->color[3] = c.a;
    });
}

// From now on `dh_sumo_read` reports the vehicle under `key` (until it arrives or vanishes).
DH_API int dh_sumo_track(const char* vid, uint64_t key) {
    return guarded([&] {
        cur().tracked[vid] = key;
#ifdef DH_LIBTRACI
        api::Vehicle::subscribe(vid, kVars);
#endif
    });
}

DH_API size_t dh_sumo_tracked_count(void) { return g_cur ? g_cur->tracked.size() : 0; }

// Reads every tracked vehicle (id order) into `out` (room for `cap`); `*n` = how many. A vehicle
// gone without an arrival is dropped (as libsumo drops a vanished vehicle's subscription).
DH_API int dh_sumo_read(DhSumoVehicle* out, size_t cap, size_t* n) {
    *n = 0;
    return guarded([&] {
        Session& s = cur();
#ifdef DH_LIBTRACI
        const libsumo::SubscriptionResults all = api::Vehicle::getAllSubscriptionResults();
#endif
        size_t i = 0;
        for (auto it = s.tracked.begin(); it != s.tracked.end() && i < cap;) {
            const std::string& vid = it->first;
            DhSumoVehicle& v = out[i];
            v.key = it->second;
            v._pad = 0;
#ifdef DH_LIBTRACI
            const auto found = all.find(vid);
            if (found == all.end()) {
                it = s.tracked.erase(it);
                continue;
            }
            const libsumo::TraCIResults& r = found->second;
            const auto& p = std::dynamic_pointer_cast<libsumo::TraCIPosition>(r.at(libsumo::VAR_POSITION));
            v.x = p->x;
            v.y = p->y;
            v.angle = std::dynamic_pointer_cast<libsumo::TraCIDouble>(r.at(libsumo::VAR_ANGLE))->value;
            v.speed = std::dynamic_pointer_cast<libsumo::TraCIDouble>(r.at(libsumo::VAR_SPEED))->value;
            v.signals = std::dynamic_pointer_cast<libsumo::TraCIInt>(r.at(libsumo::VAR_SIGNALS))->value;
#else
            try {
                const libsumo::TraCIPosition p = api::Vehicle::getPosition(vid);
                v.x = p.x;
                v.y = p.y;
                v.angle = api::Vehicle::getAngle(vid);
                v.speed = api::Vehicle::getSpeed(vid);
                v.signals = api::Vehicle::getSignals(vid);
            } catch (const libsumo::TraCIException&) {
                it = s.tracked.erase(it);
                continue;
            }
#endif
            ++i;
            ++it;
        }
        *n = i;
    });
}

DH_API size_t dh_sumo_tl_count(void) { return g_cur ? g_cur->tls.size() : 0; }

DH_API const char* dh_sumo_tl_id(size_t i) { return g_cur && i < g_cur->tls.size() ? g_cur->tls[i].c_str() : ""; }

// Refreshes every light's state string; `dh_sumo_tl_state(i)` then returns it.
DH_API int dh_sumo_read_lights(void) {
    return guarded([] {
        Session& s = cur();
        for (size_t i = 0; i < s.tls.size(); ++i) {
            s.tl_states[i] = api::TrafficLight::getRedYellowGreenState(s.tls[i]);
        }
    });
}

DH_API const char* dh_sumo_tl_state(size_t i) {
    return g_cur && i < g_cur->tl_states.size() ? g_cur->tl_states[i].c_str() : "";
}

DH_API int dh_sumo_set_phase(const char* tl, int32_t phase, double remaining_s) {
    return guarded([&] {
        api::TrafficLight::setPhase(tl, phase);
        api::TrafficLight::setPhaseDuration(tl, remaining_s);
    });
}

// Installs and switches to a replacement program (the scenario's `[[lights]] phases`).
DH_API int dh_sumo_set_program(const char* tl, size_t n, const char* const* states, const double* durations) {
    return guarded([&] {
        std::vector<std::shared_ptr<libsumo::TraCIPhase>> phases;
        for (size_t i = 0; i < n; ++i) {
            phases.push_back(std::make_shared<libsumo::TraCIPhase>(durations[i], std::string(states[i])));
        }
        api::TrafficLight::setProgramLogic(tl, libsumo::TraCILogic("dh_override", 0, 0, phases));
        api::TrafficLight::setProgram(tl, "dh_override");
    });
}

}  // extern "C"
