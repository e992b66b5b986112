// Each component registers its subcommands of `perch` here. `bench` is the `perch bench`
// subcommand; components add their benchmarks under it (perch bench env, perch bench ppo, ...).
// A subcommand that measures something has --json.
#pragma once

#include <CLI/CLI.hpp>

namespace perch {

void RegisterEnvCommands(CLI::App& root, CLI::App& bench);      // app/cmd_env.cc
void RegisterMotionCommands(CLI::App& root, CLI::App& bench);   // app/cmd_motion.cc
void RegisterLearnerCommands(CLI::App& root, CLI::App& bench);  // app/cmd_ppo.cc
void RegisterClusterCommands(CLI::App& root, CLI::App& bench);  // app/cmd_cluster.cc
void RegisterVizCommands(CLI::App& root, CLI::App& bench);      // app/cmd_viz.cc
void RegisterEvalCommands(CLI::App& root, CLI::App& bench);     // app/cmd_eval.cc
void RegisterProfileCommands(CLI::App& root, CLI::App& bench);  // app/cmd_profile.cc
void RegisterViewCommands(CLI::App& root, CLI::App& bench);     // app/cmd_view.cc
void RegisterInfoCommands(CLI::App& root, CLI::App& bench);     // app/cmd_info.cc
void RegisterMetaCommands(CLI::App& root, CLI::App& bench);     // app/cmd_meta.cc
void RegisterFuzzCommand(CLI::App& root);                       // app/cmd_fuzz.cc
void RegisterRecipeCommands(CLI::App& root, CLI::App& bench);   // app/cmd_recipe.cc
void RegisterBenchCommands(CLI::App& root, CLI::App& bench);    // app/cmd_bench.cc
void RegisterChairCommands(CLI::App& root, CLI::App& bench);    // app/cmd_chair.cc

}  // namespace perch
