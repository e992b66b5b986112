#include "app/commands.h"

namespace perch {

void RegisterClusterCommands(CLI::App& root, CLI::App& bench) {}

}  // namespace perch
