#include "recipe/recipe.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <regex>
#include <set>

#include "common/field_text.h"
#include "common/file_util.h"

namespace perch {
namespace {

const std::set<std::string>& Kinds() {
  static const std::set<std::string> k = {"train", "sample", "mirror", "clone", "eval", "run"};
  return k;
}

bool ValidName(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  for (char c : s) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  }
  return s != "out" && s != "dir";
}

// Sets are written in the recipe as an object {"section.field": VALUE} (easier to read than
// "k=v" strings); VALUE is any JSON.
std::vector<std::string> SetsFromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object {\"section.field\": VALUE}");
  std::vector<std::string> out;
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (it.key().empty()) throw ConfigError(ctx + ": an empty field name");
    out.push_back(it.key() + "=" + (it->is_string() ? it->get<std::string>() : it->dump()));
  }
  return out;
}

// The cross-field rules of a stage (its fields' own ranges are in the table).
std::string StageRules(const RecipeStage& s, const std::string& c) {
  if (s.shards > 1) {
    if (s.kind != "eval" || !s.counts.count("--trials")) {
      return c +
             ".shards: only an eval stage of --trials (perch eval --task sit_chair) runs in "
             "shards";
    }
    if (!s.outputs.empty()) {
      return c +
             ".shards: a sharded evaluation writes only its result (a hand-over bank needs "
             "every trial in one run)";
    }
  }
  for (const auto& [flag, n] : s.counts) {
    if (flag.rfind("--", 0) != 0) return c + ".counts: \"" + flag + "\" is not a --flag";
    if (n < 1) return c + ".counts." + flag + ": must be >= 1";
  }
  if (s.kind == "train") {
    if (s.config.empty()) return c + ": a train stage needs \"config\"";
    if (s.max_samples == 0 && s.target_success == 0) {
      return c + ": a train stage needs a stop rule (max_samples and/or target_success)";
    }
    if (s.max_samples == 0) {
      return c +
             ".max_samples: a train stage needs a budget (target_success alone may never be "
             "reached)";
    }
    if (!s.command.empty()) return c + ".command: a train stage runs perch train";
  } else {
    if (s.max_samples || s.target_success || s.target_window || s.select.last_k) {
      return c + ": max_samples, target_success, target_window and select are for train stages";
    }
    if (s.kind == "run" && s.command.empty()) {
      return c + ": a run stage needs \"command\" (a perch subcommand)";
    }
  }
  for (const std::string& o : s.optional_outputs) {
    if (!s.outputs.count(o)) return c + ".optional_outputs: \"" + o + "\" is not in outputs";
  }
  for (const auto& [name, file] : s.outputs) {
    if (!ValidName(name)) return c + ".outputs: bad output name \"" + name + "\"";
    if (file.empty() || file.find('/') != std::string::npos || file[0] == '.') {
      return c + ".outputs." + name + ": a plain file name inside the stage's directory";
    }
  }
  return "";
}

// A `set`/`toy_set` object {"section.field": VALUE} as a field (SetsFromJson): held as the
// "section.field=VALUE" strings `--set` takes.
template <class T>
void AddSets(FieldTable<T>& t, const char* name, std::vector<std::string> T::*member,
             const char* doc) {
  const std::string key = name;
  t.Custom(
      name, doc,
      [key, member](const Json& j, T& v, const std::string& ctx) {
        v.*member = SetsFromJson(j.at(key), ctx + "." + key);
      },
      [key, member](const T& v, Json& j) {
        if ((v.*member).empty()) return;
        Json o = Json::object();
        for (const std::string& kv : v.*member) {
          const size_t eq = kv.find('=');
          const std::string value = kv.substr(eq + 1);
          o[kv.substr(0, eq)] = Json::accept(value) ? Json::parse(value) : Json(value);
        }
        j[key] = o;
      });
}

}  // namespace

const FieldTable<StageSelect>& StageSelectFields() {
  static const FieldTable<StageSelect> t =
      FieldTable<StageSelect>()
          .Add("last_k", &StageSelect::last_k,
               "evaluate the newest K checkpoints and deliver the best (0: the newest, unjudged)",
               InRange(0, 50, "must be in 0..50"))
          .Custom(
              "milestones", "also evaluate every milestone checkpoint the run kept",
              [](const Json& j, StageSelect& s, const std::string& ctx) {
                GetOptional(j, "milestones", s.milestones, ctx);
              },
              // Written only when on, so that the recipes before it keep their fingerprints.
              [](const StageSelect& s, Json& j) {
                if (s.milestones) j["milestones"] = true;
              })
          .Custom(
              "include_init", "the policy the run started from (cluster.init_from) competes too",
              [](const Json& j, StageSelect& s, const std::string& ctx) {
                GetOptional(j, "include_init", s.include_init, ctx);
              },
              // Written only when on, as milestones.
              [](const StageSelect& s, Json& j) {
                if (s.include_init) j["include_init"] = true;
              })
          .Add("episodes", &StageSelect::episodes, "episodes per candidate",
               Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1"))
          .Add("seed", &StageSelect::seed, "the selection seed (figures are reported on another)")
          .Add("metric", &StageSelect::metric, "the perch eval --json key ranked")
          .Add("lower_is_better", &StageSelect::lower_is_better, "rank the metric ascending")
          .Add("args", &StageSelect::args, "further perch eval flags")
          .Rule([](const StageSelect& s, const std::string& ctx) {
            if (s.milestones && s.last_k < 1) {
              return ctx + ".milestones: needs last_k >= 1 (a selection by evaluation)";
            }
            if (s.include_init && s.last_k < 1) {
              return ctx + ".include_init: needs last_k >= 1 (a selection by evaluation)";
            }
            return std::string();
          });
  return t;
}

const FieldTable<RecipeStage>& RecipeStageFields() {
  static const FieldTable<RecipeStage> t = [] {
    FieldTable<RecipeStage> t;
    t.Custom(
         "name", "the stage's name (required): letters, digits, '_', '-'",
         [](const Json& j, RecipeStage& s, const std::string& ctx) {
           GetRequired(j, "name", s.name, ctx);
         },
         [](const RecipeStage& s, Json& j) { j["name"] = s.name; })
        .Custom(
            "kind", "train, sample, mirror, clone, eval or run (required)",
            [](const Json& j, RecipeStage& s, const std::string& ctx) {
              GetRequired(j, "kind", s.kind, ctx);
            },
            [](const RecipeStage& s, Json& j) { j["kind"] = s.kind; })
        .Add("command", &RecipeStage::command, "the perch subcommand (default per kind)")
        .Add("doc", &RecipeStage::doc, "why the stage is there, shown when it starts")
        .Add("config", &RecipeStage::config, "the base config file (train stages)");
    AddSets(t, "set", &RecipeStage::sets, "overrides of the config: {\"section.field\": VALUE}");
    t.Add("args", &RecipeStage::args, "further flags of the command")
        .Custom(
            "toy_args", "replace args in a toy run (--scale < 1)",
            [](const Json& j, RecipeStage& s, const std::string& ctx) {
              GetOptional(j, "toy_args", s.toy_args, ctx);
              s.has_toy_args = true;
            },
            [](const RecipeStage& s, Json& j) {
              if (s.has_toy_args) j["toy_args"] = s.toy_args;
            });
    AddSets(t, "toy_set", &RecipeStage::toy_sets, "added to set in a toy run");
    t.Add("counts", &RecipeStage::counts,
          "{\"--flag\": N}: episodes, trials or states, multiplied by --scale")
        .Add("min_count", &RecipeStage::min_count, "the floor of a scaled count",
             Satisfies<int64_t>([](const int64_t& v) { return v >= 1; }, "must be >= 1"))
        .Add("max_samples", &RecipeStage::max_samples, "a train stage's sample budget",
             Satisfies<int64_t>([](const int64_t& v) { return v >= 0; }, "must be >= 0"))
        .Add("target_success", &RecipeStage::target_success,
             "end a train stage earlier at this success rate (0: off)",
             Satisfies<double>([](const double& v) { return v >= 0 && v <= 1; },
                               "must be in [0, 1]"))
        .Add("target_window", &RecipeStage::target_window,
             "episodes the target success is judged over (0: the config's)")
        .Add("actors", &RecipeStage::actors, "actor processes (0: the runner's --actors)",
             InRange(0, 256, "must be in 0..256"))
        .Nested("select", &RecipeStage::select, StageSelectFields(),
                "how a train stage's delivered checkpoint is chosen")
        .Add("outputs", &RecipeStage::outputs,
             "{NAME: FILE} outputs beyond the kind's own (docs/recipe.md)")
        .Add("optional_outputs", &RecipeStage::optional_outputs,
             "outputs the command may rightly leave unwritten")
        .Add("figures", &RecipeStage::figures, "keys copied from the stage's JSON result")
        .Add("est_wall_s", &RecipeStage::est_wall_s, "full-scale wall time on 2 cores [s] (ETA)")
        .Add("shards", &RecipeStage::shards, "an eval stage of --trials in this many shards",
             InRange(1, 1000, "must be in 1..1000"));
    return t;
  }();
  return t;
}

std::string RecipeFieldsText(bool json) {
  const Json stage = RecipeStageFields().Describe();
  if (json) return Json{{"stage", stage}}.dump(2) + "\n";
  return DescribedFieldsText({{"stages[]", stage}});
}

namespace {

Json ToJson(const StageSelect& s) { return StageSelectFields().Write(s); }

RecipeStage StageFromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  RecipeStage s;
  GetRequired(j, "name", s.name, ctx);
  GetRequired(j, "kind", s.kind, ctx);
  const std::string c = ctx + " (" + s.name + ")";
  if (!ValidName(s.name)) {
    throw ConfigError(c + ".name: letters, digits, '_' or '-', at most 64, not 'out' or 'dir'");
  }
  if (!Kinds().count(s.kind)) {
    throw ConfigError(c + ".kind: \"" + s.kind +
                      "\" is not one of train, sample, mirror, clone, eval, run");
  }
  s = RecipeStageFields().Read(j, c);
  const std::string e = StageRules(s, c);
  if (!e.empty()) throw ConfigError(e);
  return s;
}

std::vector<std::string> AllRefStrings(const RecipeStage& s) {
  std::vector<std::string> all = s.sets;
  all.insert(all.end(), s.args.begin(), s.args.end());
  all.insert(all.end(), s.select.args.begin(), s.select.args.end());
  all.insert(all.end(), s.toy_args.begin(), s.toy_args.end());
  all.insert(all.end(), s.toy_sets.begin(), s.toy_sets.end());
  if (!s.config.empty()) all.push_back(s.config);
  return all;
}

}  // namespace

std::vector<TrialShard> TrialShards(int64_t trials, int shards) {
  std::vector<TrialShard> out;
  for (int k = 0; k < shards; ++k) {
    const int64_t a = trials * k / shards, b = trials * (k + 1) / shards;
    if (b > a) out.push_back(TrialShard{k, a, b - a});
  }
  return out;
}

std::vector<std::string> SelectionCandidates(const std::vector<std::string>& checkpoints,
                                             const StageSelect& select) {
  if (select.milestones) return checkpoints;
  const size_t k = std::min<size_t>(checkpoints.size(), std::max(1, select.last_k));
  return std::vector<std::string>(checkpoints.end() - k, checkpoints.end());
}

int Recipe::Index(const std::string& stage) const {
  for (size_t i = 0; i < stages.size(); ++i) {
    if (stages[i].name == stage) return static_cast<int>(i);
  }
  return -1;
}

std::vector<std::pair<std::string, std::string>> FindRefs(const std::string& s) {
  static const std::regex re(R"(\$\{([A-Za-z0-9_-]+)(?:\.([A-Za-z0-9_-]+))?\})");
  std::vector<std::pair<std::string, std::string>> out;
  for (auto it = std::sregex_iterator(s.begin(), s.end(), re); it != std::sregex_iterator(); ++it) {
    out.emplace_back((*it)[1].str(), (*it)[2].str());
  }
  return out;
}

std::string SubstituteRefs(
    const std::string& s,
    const std::function<std::string(const std::string&, const std::string&)>& lookup) {
  static const std::regex re(R"(\$\{([A-Za-z0-9_-]+)(?:\.([A-Za-z0-9_-]+))?\})");
  std::string out;
  auto last = s.cbegin();
  for (auto it = std::sregex_iterator(s.begin(), s.end(), re); it != std::sregex_iterator(); ++it) {
    out.append(last, s.cbegin() + it->position());
    out += lookup((*it)[1].str(), (*it)[2].str());
    last = s.cbegin() + it->position() + it->length();
  }
  out.append(last, s.cend());
  return out;
}

std::map<std::string, std::string> StageOutputs(const RecipeStage& s) {
  std::map<std::string, std::string> o;
  if (s.kind == "train" || s.kind == "mirror") o["policy"] = "policy.bin";
  if (s.kind == "clone") {
    o["policy"] = "policy.bin";
  }
  if (s.kind == "sample") o["bank"] = "bank.bin";
  if (s.kind == "eval") o["result"] = "eval.json";
  for (const auto& [k, v] : s.outputs) o[k] = v;
  return o;
}

std::string StageCommand(const RecipeStage& s) {
  if (!s.command.empty()) return s.command;
  if (s.kind == "train") return "train";
  if (s.kind == "sample") return "sample-end-poses";
  if (s.kind == "mirror") return "mirror-model";
  if (s.kind == "clone") return "meta-clone";
  if (s.kind == "eval") return "eval";
  return s.command;
}

Recipe RecipeFromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected a JSON object");
  CheckKnownKeys(j, {"name", "doc", "stages"}, ctx);
  Recipe r;
  GetRequired(j, "name", r.name, ctx);
  GetOptional(j, "doc", r.doc, ctx);
  if (!j.contains("stages") || !j["stages"].is_array() || j["stages"].empty()) {
    throw ConfigError(ctx + ".stages: expected a non-empty list of stages");
  }
  for (size_t i = 0; i < j["stages"].size(); ++i) {
    r.stages.push_back(StageFromJson(j["stages"][i], ctx + ".stages[" + std::to_string(i) + "]"));
  }
  std::map<std::string, int> seen;
  for (size_t i = 0; i < r.stages.size(); ++i) {
    RecipeStage& s = r.stages[i];
    const std::string c = ctx + ": stage " + s.name;
    if (seen.count(s.name)) throw ConfigError(c + ": the name is used twice");
    seen[s.name] = static_cast<int>(i);
    const auto own = StageOutputs(s);
    std::set<std::string> deps;
    for (const std::string& str : AllRefStrings(s)) {
      for (const auto& [a, b] : FindRefs(str)) {
        if (a == "dir" && b.empty()) continue;
        if (a == "out") {
          if (!own.count(b))
            throw ConfigError(c + ": ${out." + b + "}: the stage has no such output");
          continue;
        }
        if (b.empty()) throw ConfigError(c + ": ${" + a + "}: write ${STAGE.OUTPUT}");
        if (a == s.name)
          throw ConfigError(c + ": ${" + a + "." + b + "}: a stage cannot read itself");
        auto it = seen.find(a);
        if (it == seen.end()) {
          throw ConfigError(c + ": ${" + a + "." + b + "}: no earlier stage \"" + a +
                            "\" (stages run in the order listed)");
        }
        if (!StageOutputs(r.stages[it->second]).count(b)) {
          throw ConfigError(c + ": ${" + a + "." + b + "}: stage " + a + " has no output \"" + b +
                            "\"");
        }
        deps.insert(a);
      }
    }
    for (const RecipeStage& e : r.stages) {
      if (deps.count(e.name)) s.deps.push_back(e.name);
    }
  }
  return r;
}

namespace {

// A recipe file with "base": the base recipe's stages, where a stage of the same name replaces the
// base's in place and a new one goes just before the first stage that reads it (else at the end,
// in its order); "name" and "doc" are the variant's own.
Json ComposedRecipeJson(const std::string& path, int depth) {
  Json j = LoadJsonFile(path);
  if (!j.is_object() || !j.contains("base")) return j;
  if (depth >= 8) throw ConfigError(path + ".base: more than 8 levels of base (a cycle?)");
  std::string rel;
  GetRequired(j, "base", rel, path);
  namespace fs = std::filesystem;
  const std::string base_path = (fs::path(path).parent_path() / rel).lexically_normal().string();
  if (!fs::exists(base_path)) {
    throw ConfigError(path + ".base: " + base_path + " does not exist");
  }
  Json b = ComposedRecipeJson(base_path, depth + 1);
  if (!b.is_object() || !b.contains("stages") || !b["stages"].is_array()) {
    throw ConfigError(path + ".base: " + base_path + " has no list of stages");
  }
  if (j.contains("stages")) {
    if (!j["stages"].is_array()) throw ConfigError(path + ".stages: expected a list of stages");
    auto& list = b["stages"];
    // Replacements first, so that a new stage is placed by what the replaced ones read.
    std::vector<const Json*> added;
    for (const Json& st : j["stages"]) {
      bool replaced = false;
      if (st.is_object() && st.contains("name")) {
        for (Json& mine : list) {
          if (mine.is_object() && mine.value("name", Json()) == st["name"]) {
            mine = st;
            replaced = true;
          }
        }
      }
      if (!replaced) added.push_back(&st);
    }
    // A new stage goes just before the first stage that reads it (a step put into the lineage),
    // else at the end.
    for (const Json* st : added) {
      const std::string ref =
          "${" + (st->is_object() ? st->value("name", std::string()) : std::string()) + ".";
      auto at = list.end();
      for (auto it = list.begin(); it != list.end(); ++it) {
        if (it->dump().find(ref) != std::string::npos) {
          at = it;
          break;
        }
      }
      list.insert(at, *st);
    }
  }
  for (const char* k : {"name", "doc"}) {
    if (j.contains(k)) b[k] = j[k];
  }
  for (const auto& [k, v] : j.items()) {
    if (k != "base" && k != "stages" && k != "name" && k != "doc") b[k] = v;  // refused below
  }
  return b;
}

}  // namespace

Recipe LoadRecipe(const std::string& path) {
  Recipe r = RecipeFromJson(ComposedRecipeJson(path, 0), path);
  r.path = path;
  return r;
}

int64_t ScaledCount(int64_t n, double scale, int64_t floor) {
  const int64_t v = std::llround(static_cast<double>(n) * scale);
  return std::min(n, std::max(v, floor));
}

RecipeStage ScaledStage(const RecipeStage& s, const RecipeRunOptions& o) {
  RecipeStage r = s;
  for (auto& [flag, n] : r.counts) n = ScaledCount(n, o.scale, s.min_count);
  // At least one update: the learner ends its run after the first update past the budget.
  if (r.max_samples > 0) r.max_samples = ScaledCount(s.max_samples, o.scale, 1);
  r.select.episodes = static_cast<int>(ScaledCount(s.select.episodes, o.scale, s.min_count));
  r.est_wall_s = s.est_wall_s * o.scale;
  if (o.scale < 1.0) {
    if (s.has_toy_args) r.args = s.toy_args;
    r.sets.insert(r.sets.end(), s.toy_sets.begin(), s.toy_sets.end());
  }
  r.sets.insert(r.sets.end(), o.sets.begin(), o.sets.end());
  if (r.actors == 0) r.actors = o.actors;
  return r;
}

std::string StageFingerprint(const RecipeStage& scaled, const Json& composed_config,
                             const std::map<std::string, std::string>& input_sha256) {
  Json def{{"kind", scaled.kind},
           {"command", StageCommand(scaled)},
           {"args", scaled.args},
           {"counts", scaled.counts},
           {"max_samples", scaled.max_samples},
           {"target_success", scaled.target_success},
           {"target_window", scaled.target_window},
           {"select", ToJson(scaled.select)},
           {"outputs", StageOutputs(scaled)},
           {"config", composed_config},
           {"inputs", input_sha256}};
  // Fields added to the format later enter only when used, so that older runs stay valid.
  if (!scaled.optional_outputs.empty()) def["optional_outputs"] = scaled.optional_outputs;
  // Not in it: doc, est_wall_s, figures and actors (how many processes step the envs does not
  // change what a run means; a resumed stage may use another count).
  return Sha256Hex(def.dump());
}

Json ToJson(const StageRecord& r) {
  Json j{{"state", r.state},
         {"fingerprint", r.fingerprint},
         {"samples", r.samples},
         {"wall_s", r.wall_s},
         {"attempts", r.attempts},
         {"outputs", r.outputs},
         {"output_sha256", r.output_sha256},
         {"figures", r.figures},
         {"error", r.error},
         {"started_at", r.started_at},
         {"finished_at", r.finished_at}};
  if (r.attempt_started_unix > 0) j["attempt_started_unix"] = r.attempt_started_unix;
  return j;
}

StageRecord StageRecordFromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected an object");
  CheckKnownKeys(
      j,
      {"state", "fingerprint", "samples", "wall_s", "attempts", "outputs", "output_sha256",
       "figures", "error", "started_at", "finished_at", "attempt_started_unix"},
      ctx);
  StageRecord r;
  GetOptional(j, "state", r.state, ctx);
  GetOptional(j, "fingerprint", r.fingerprint, ctx);
  GetOptional(j, "samples", r.samples, ctx);
  GetOptional(j, "wall_s", r.wall_s, ctx);
  GetOptional(j, "attempts", r.attempts, ctx);
  GetOptional(j, "outputs", r.outputs, ctx);
  GetOptional(j, "output_sha256", r.output_sha256, ctx);
  if (j.contains("figures")) r.figures = j["figures"];
  GetOptional(j, "error", r.error, ctx);
  GetOptional(j, "started_at", r.started_at, ctx);
  GetOptional(j, "attempt_started_unix", r.attempt_started_unix, ctx);
  GetOptional(j, "finished_at", r.finished_at, ctx);
  static const std::set<std::string> states = {"pending", "running", "done", "failed"};
  if (!states.count(r.state)) throw ConfigError(ctx + ".state: \"" + r.state + "\" is not a state");
  return r;
}

Json ToJson(const RecipeState& s) {
  Json stages = Json::object();
  for (const auto& [k, v] : s.stages) stages[k] = ToJson(v);
  return Json{{"format", "perch-recipe-state/1"},
              {"recipe", s.recipe_path},
              {"name", s.recipe_name},
              {"scale", s.scale},
              {"stages", stages}};
}

RecipeState RecipeStateFromJson(const Json& j, const std::string& ctx) {
  if (!j.is_object()) throw ConfigError(ctx + ": expected a JSON object");
  CheckKnownKeys(j, {"format", "recipe", "name", "scale", "stages"}, ctx);
  std::string format;
  GetRequired(j, "format", format, ctx);
  if (format != "perch-recipe-state/1") {
    throw ConfigError(ctx + ".format: \"" + format + "\" (this build reads perch-recipe-state/1)");
  }
  RecipeState s;
  GetOptional(j, "recipe", s.recipe_path, ctx);
  GetOptional(j, "name", s.recipe_name, ctx);
  GetOptional(j, "scale", s.scale, ctx);
  if (j.contains("stages")) {
    if (!j["stages"].is_object()) throw ConfigError(ctx + ".stages: expected an object");
    for (auto it = j["stages"].begin(); it != j["stages"].end(); ++it) {
      s.stages[it.key()] = StageRecordFromJson(*it, ctx + ".stages." + it.key());
    }
  }
  return s;
}

std::string StatePath(const std::string& dir) { return dir + "/recipe-state.json"; }

RecipeState LoadRecipeState(const std::string& dir) {
  const std::string p = StatePath(dir);
  std::error_code ec;
  if (!std::filesystem::exists(p, ec)) return RecipeState{};
  return RecipeStateFromJson(LoadJsonFile(p), p);
}

void SaveRecipeState(const std::string& dir, const RecipeState& s) {
  SaveJsonFileAtomic(StatePath(dir), ToJson(s));
}

std::vector<std::string> InvalidatedStages(const Recipe& r, const RecipeState& s,
                                           const std::map<std::string, std::string>& fingerprints) {
  std::set<std::string> bad;
  std::vector<std::string> out;
  for (const RecipeStage& st : r.stages) {
    bool invalid = false;
    auto rec = s.stages.find(st.name);
    const bool recorded = rec != s.stages.end() && !rec->second.fingerprint.empty();
    if (recorded) {
      auto f = fingerprints.find(st.name);
      if (f != fingerprints.end() && f->second != rec->second.fingerprint) invalid = true;
    }
    for (const std::string& d : st.deps) {
      if (bad.count(d)) invalid = true;
    }
    if (invalid) {
      bad.insert(st.name);
      // Only a stage with something recorded has anything to redo.
      if (rec != s.stages.end() && rec->second.state != "pending") out.push_back(st.name);
    }
  }
  return out;
}

std::vector<std::string> StagesReading(const Recipe& r, const std::string& name) {
  std::set<std::string> reached{name};
  std::vector<std::string> out;
  for (const RecipeStage& st : r.stages) {
    for (const std::string& d : st.deps) {
      if (reached.count(d) && !reached.count(st.name)) {
        reached.insert(st.name);
        out.push_back(st.name);
      }
    }
  }
  return out;
}

namespace {

// "section.field" -> value; arrays are values (an lr_schedule is compared whole).
void Flatten(const Json& j, const std::string& prefix, std::map<std::string, Json>* out) {
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) {
      Flatten(it.value(), prefix.empty() ? it.key() : prefix + "." + it.key(), out);
    }
  } else {
    (*out)[prefix] = j;
  }
}

// The learning rate at `samples` as the learner reads it (protocol/ppo_config.cc
// LearningRateAt): ppo.learning_rate, then each [from, rate] of ppo.lr_schedule from `from` on.
double RateAt(const std::map<std::string, Json>& c, int64_t samples) {
  auto lr = c.find("ppo.learning_rate");
  double rate = lr != c.end() && lr->second.is_number() ? lr->second.get<double>() : 0.0;
  auto sched = c.find("ppo.lr_schedule");
  if (sched != c.end() && sched->second.is_array()) {
    for (const Json& e : sched->second) {
      if (e.is_array() && e.size() == 2 && e[0].is_number() && samples >= e[0].get<double>()) {
        rate = e[1].get<double>();
      }
    }
  }
  return rate;
}

std::vector<int64_t> Breakpoints(const std::map<std::string, Json>& c) {
  std::vector<int64_t> out;
  auto sched = c.find("ppo.lr_schedule");
  if (sched == c.end() || !sched->second.is_array()) return out;
  for (const Json& e : sched->second) {
    if (e.is_array() && e.size() == 2 && e[0].is_number()) {
      out.push_back(static_cast<int64_t>(std::ceil(e[0].get<double>())));
    }
  }
  return out;
}

}  // namespace

std::string ExtensionMismatch(const Json& prev, const Json& next, int64_t samples) {
  std::map<std::string, Json> a, b;
  Flatten(prev, "", &a);
  Flatten(next, "", &b);
  std::set<std::string> keys;
  for (const auto& [k, v] : a) keys.insert(k);
  for (const auto& [k, v] : b) keys.insert(k);
  for (const std::string& k : keys) {
    auto x = a.find(k);
    auto y = b.find(k);
    const Json vx = x == a.end() ? Json() : x->second;
    const Json vy = y == b.end() ? Json() : y->second;
    if (vx == vy || k == "ppo.learning_rate" || k == "ppo.lr_schedule") continue;
    if (k == "cluster.max_samples") {
      if (!vy.is_number_integer() || vy.get<int64_t>() < samples) {
        return "its new budget (cluster.max_samples " + vy.dump() + ") is below the " +
               std::to_string(samples) + " samples it has trained";
      }
      continue;
    }
    return k + " changed (" + vx.dump() + " -> " + vy.dump() + ")";
  }
  // The rate is piecewise constant: equal at 0 and at every breakpoint below `samples` means
  // equal on the whole of [0, samples).
  std::vector<int64_t> at{0};
  for (int64_t p : Breakpoints(a)) at.push_back(p);
  for (int64_t p : Breakpoints(b)) at.push_back(p);
  for (int64_t p : at) {
    if (p >= samples) continue;
    const double ra = RateAt(a, p), rb = RateAt(b, p);
    if (ra != rb) {
      return "the learning rate at " + std::to_string(p) + " samples changed (" + Json(ra).dump() +
             " -> " + Json(rb).dump() + "), before the " + std::to_string(samples) +
             " samples it has trained";
    }
  }
  return "";
}

}  // namespace perch
