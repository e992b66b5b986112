#include "app/commands.h"

namespace perch {

void RegisterLearnerCommands(CLI::App& root, CLI::App& bench) {}

}  // namespace perch
