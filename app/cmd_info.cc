// `perch version`: what this binary is and where it finds its data (issue 18: an installed
// binary must not depend on a source checkout).
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "app/commands.h"
#include "common/config_file.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "experiment/experiment.h"
#include "policy/dense_kernels.h"
#include "tasks/recording.h"

namespace perch {

void RegisterInfoCommands(CLI::App& root, CLI::App& /*bench*/) {
  auto json = std::make_shared<bool>(false);
  CLI::App* v = root.add_subcommand("version", "This binary's version and where it finds its data");
  v->add_flag("--json", *json, "print one JSON object on stdout");
  v->callback([json] {
    const DataRootInfo d = FindDataRoot();
    const Json j{{"version", PerchVersion()},
                 {"executable", ExecutablePath()},
                 {"data_root", d.root},
                 {"data_origin", d.origin},
                 // The MLP kernels the learner uses on this CPU (PERCH_SIMD forces one).
                 {"simd", ActiveDenseKernels().name}};
    if (*json) {
      std::cout << j.dump() << "\n";
    } else {
      std::cout << "perch " << PerchVersion() << "\nexecutable: " << ExecutablePath()
                << "\ndata: " << d.root << " (" << d.origin
                << ")\nsimd: " << ActiveDenseKernels().name << "\n";
    }
  });

  // perch config: what a config composes to (its bases and --set applied), or with --resolved
  // every field with its default, as the run dir's config.json will hold it.
  struct ConfigArgs {
    std::string config;
    std::vector<std::string> sets;
    bool resolved = false;
    std::string fields;
    bool json = false;
  };
  auto c = std::make_shared<ConfigArgs>();
  CLI::App* cc =
      root.add_subcommand("config", "Print a config as composed (base, --set) or fully resolved");
  cc->add_option("--config", c->config, "experiment config (JSON)");
  cc->add_option("--set", c->sets, "override a config field: section.field=VALUE (repeatable)");
  cc->add_flag("--resolved", c->resolved,
               "validate and fill in every default (as a run records it)");
  cc->add_option("--fields", c->fields,
                 "print a section's fields instead (env, ppo, cluster, policy, mock_env, a task's "
                 "section such as walk "
                 "or sit_chair, or all): name, default, "
                 "range, doc");
  cc->add_flag("--json", c->json, "--fields: as JSON");
  cc->callback([c] {
    if (!c->fields.empty()) {
      std::cout << ConfigFieldsText(c->fields, c->json);
      return;
    }
    if (c->config.empty()) throw CLI::ValidationError("--config", "required (or --fields)");
    if (c->resolved) {
      std::cout << ToJson(LoadExperimentConfig(c->config, c->sets)).dump(2) << "\n";
    } else {
      std::cout << LoadComposedConfig(c->config, c->sets).dump(2) << "\n";
    }
  });
}

}  // namespace perch
