// perch: the one command-line program. Config is read here (by each subcommand's handler) and
// passed down in typed structs.
#include <CLI/CLI.hpp>
#include <cstdlib>
#include <exception>
#include <iostream>

#include "app/cli_check.h"
#include "app/commands.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "hierarchy/hierarchy.h"
#include "protocol/wire.h"

int main(int argc, char** argv) {
  // The program's tasks: the subtasks (tasks/registry.cc) and the hierarchy's sit_chair.
  perch::RegisterHierarchyTasks();
  CLI::App app{"Perch: distributed RL that teaches a simulated humanoid to sit on a chair"};
  // Every option's help shows its default (set before any option is added; subcommands inherit).
  app.option_defaults()->always_capture_default();
  app.require_subcommand(1);
  app.footer(
      "Global: --data-dir DIR  where data/, configs/ and models/ are (default: $PERCH_DATA_DIR, "
      "else ../share/perch beside the binary, else the source tree of a dev build).\n"
      "Each subcommand has --help.");
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks (each prints JSON with --json)");
  bench->require_subcommand(1);
  perch::RegisterEnvCommands(app, *bench);
  perch::RegisterMotionCommands(app, *bench);
  perch::RegisterLearnerCommands(app, *bench);
  perch::RegisterClusterCommands(app, *bench);
  perch::RegisterBenchCommands(app, *bench);
  perch::RegisterVizCommands(app, *bench);
  perch::RegisterChairCommands(app, *bench);
  perch::RegisterEvalCommands(app, *bench);
  perch::RegisterProfileCommands(app, *bench);
  perch::RegisterViewCommands(app, *bench);
  perch::RegisterInfoCommands(app, *bench);
  perch::RegisterMetaCommands(app, *bench);
  perch::RegisterFuzzCommand(app);
  perch::RegisterRecipeCommands(app, *bench);
  perch::RateLimitProtobufLogs();
  try {
    const std::string data_dir = perch::TakeDataDirFlag(&argc, argv);
    if (!data_dir.empty()) {
      perch::SetDataRoot(data_dir);
      // Processes this one starts (perch train's learner and actors) find the same data.
      ::setenv("PERCH_DATA_DIR", perch::FindDataRoot().root.c_str(), 1);
    }
    if (const std::string problem = perch::CheckCommandLine(app, argc, argv); !problem.empty()) {
      std::cerr << "perch: error: " << problem << "\n";
      return 2;
    }
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
