#include "envs/physics_profile.h"

#include <LinearMath/btQuickprof.h>

#include <chrono>
#include <map>
#include <unordered_map>
#include <utility>

namespace perch {
namespace {

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

struct Frame {
  const char* name;
  int64_t start_ns;
  int64_t child_ns;
};

struct Sums {
  int64_t self_ns = 0;
  int64_t calls = 0;
};

// A zone in its parent zone, by the names' addresses (Bullet passes literals).
using ZoneKey = std::pair<const char*, const char*>;  // parent (null: outermost), zone
struct ZoneKeyHash {
  size_t operator()(const ZoneKey& k) const {
    return std::hash<const void*>()(k.first) * 31 + std::hash<const void*>()(k.second);
  }
};

// Per thread: the open zones and the sums.
struct ThreadProfile {
  std::vector<Frame> stack;
  std::unordered_map<ZoneKey, Sums, ZoneKeyHash> sums;
  int64_t outermost_ns = 0;
};

ThreadProfile& Local() {
  static thread_local ThreadProfile p;
  return p;
}

void Enter(const char* name) { Local().stack.push_back({name, NowNs(), 0}); }

void Leave() {
  ThreadProfile& p = Local();
  if (p.stack.empty()) return;  // enabled inside a zone
  const Frame f = p.stack.back();
  p.stack.pop_back();
  const int64_t total = NowNs() - f.start_ns;
  Sums& s = p.sums[{p.stack.empty() ? nullptr : p.stack.back().name, f.name}];
  s.self_ns += total - f.child_ns;
  ++s.calls;
  if (p.stack.empty()) {
    p.outermost_ns += total;
  } else {
    p.stack.back().child_ns += total;
  }
}

void EnterNothing(const char*) {}
void LeaveNothing() {}

}  // namespace

void PhysicsProfile::Enable(bool on) {
  btSetCustomEnterProfileZoneFunc(on ? Enter : EnterNothing);
  btSetCustomLeaveProfileZoneFunc(on ? Leave : LeaveNothing);
}

void PhysicsProfile::Reset() {
  ThreadProfile& p = Local();
  p.sums.clear();
  p.outermost_ns = 0;
}

std::vector<PhysicsZone> PhysicsProfile::Zones() {
  // The same name may come from literals at different addresses: merge by text.
  std::map<std::pair<std::string, std::string>, PhysicsZone> by_name;
  for (const auto& [key, s] : Local().sums) {
    const std::string parent = key.first ? key.first : "";
    PhysicsZone& z = by_name[{parent, key.second}];
    z.name = key.second;
    z.parent = parent;
    z.self_s += 1e-9 * s.self_ns;
    z.calls += s.calls;
  }
  std::vector<PhysicsZone> out;
  for (auto& [name, z] : by_name) out.push_back(z);
  return out;
}

double PhysicsProfile::OutermostSeconds() { return 1e-9 * Local().outermost_ns; }

}  // namespace perch
