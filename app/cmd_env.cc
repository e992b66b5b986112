#include "app/commands.h"

namespace perch {

void RegisterEnvCommands(CLI::App& root, CLI::App& bench) {}

}  // namespace perch
