// Where Bullet's time goes: sums of the time spent in each of Bullet's profile zones (BT_PROFILE),
// per thread, for `perch bench profile`. Off by default; while on, a process-wide hook
// (btSetCustomEnterProfileZoneFunc) reads the clock twice per zone, a few percent of a step.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace perch {

struct PhysicsZone {
  std::string name;     // Bullet's zone name, e.g. "solveGroupCacheFriendlySetup"
  std::string parent;   // the zone it was entered in ("" at the outermost level)
  double self_s = 0.0;  // inside the zone but not in a zone nested in it [s]
  int64_t calls = 0;
};

class PhysicsProfile {
 public:
  // Installs (true) or removes the hooks, for every thread.
  static void Enable(bool on);
  // Clears this thread's sums.
  static void Reset();
  // This thread's sums since Reset, by zone name and parent zone name.
  static std::vector<PhysicsZone> Zones();
  // Time inside outermost zones, i.e. in Bullet's stepping and collision detection [s].
  static double OutermostSeconds();
};

}  // namespace perch
