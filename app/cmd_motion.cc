#include "app/commands.h"

namespace perch {

void RegisterMotionCommands(CLI::App& root, CLI::App& bench) {}

}  // namespace perch
