// perch: the one command-line program. Config is read here (by each subcommand's handler) and
// passed down in typed structs.
#include <exception>
#include <iostream>

#include <CLI/CLI.hpp>

#include "app/commands.h"
#include "common/json_util.h"

int main(int argc, char** argv) {
  CLI::App app{"Perch: distributed RL that teaches a simulated humanoid to sit on a chair"};
  app.require_subcommand(1);
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks (each prints JSON with --json)");
  bench->require_subcommand(1);
  perch::RegisterEnvCommands(app, *bench);
  perch::RegisterMotionCommands(app, *bench);
  perch::RegisterLearnerCommands(app, *bench);
  perch::RegisterClusterCommands(app, *bench);
  perch::RegisterVizCommands(app, *bench);
  perch::RegisterEvalCommands(app, *bench);
  perch::RegisterProfileCommands(app, *bench);
  perch::RegisterViewCommands(app, *bench);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const perch::ConfigError& e) {
    std::cerr << "perch: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "perch: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
