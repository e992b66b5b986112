#include "learner/toy_train.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <memory>
#include <vector>

#include "common/file_util.h"
#include "common/proto/model.pb.h"
#include "learner/ppo.h"
#include "learner/toy_envs.h"
#include "policy/policy.h"
#include "policy/rollout.h"

namespace perch {

PpoConfig ToyPpoConfig(const std::string& task) {
  PpoConfig c;
  if (task == "point_mass") {
    c.steps_per_update = 2048;
    c.num_minibatches = 32;
    c.num_epochs = 10;
    c.learning_rate = 3e-4f;
  } else {
    c.steps_per_update = 512;
    c.num_minibatches = 8;
    c.num_epochs = 4;
    c.learning_rate = 1e-3f;
    c.gamma = 0.0f;  // one-step episodes
  }
  return c;
}

Json TrainToy(const ToyTrainOptions& o) {
  std::unique_ptr<Env> env, eval_env;
  PolicyConfig pc;
  if (o.task == "point_mass") {
    env = std::make_unique<PointMassEnv>();
    eval_env = std::make_unique<PointMassEnv>();
    pc = PolicyConfig::Subtask(6);
    pc.act_dim = 2;
  } else if (o.task == "choice_target") {
    env = std::make_unique<ChoiceTargetEnv>();
    eval_env = std::make_unique<ChoiceTargetEnv>();
    pc = PolicyConfig::Meta(6);
  } else {
    throw ConfigError("ppo toy: --task must be point_mass or choice_target, got '" + o.task + "'");
  }
  PpoConfig cfg = ToyPpoConfig(o.task);
  if (!o.config_path.empty()) {
    const Json j = LoadJsonFile(o.config_path);
    CheckKnownKeys(j, {"policy", "ppo"}, o.config_path);
    if (j.contains("policy")) {
      Json merged = ToJson(pc);
      merged.update(j["policy"]);
      pc = PolicyConfigFromJson(merged, o.config_path + ".policy");
    }
    if (j.contains("ppo")) {
      Json merged = ToJson(cfg);
      merged.update(j["ppo"]);
      cfg = PpoConfigFromJson(merged, o.config_path + ".ppo");
    }
  }
  const int updates = o.updates > 0 ? o.updates : (o.task == "point_mass" ? 40 : 30);
  const Json resolved{{"task", o.task},
                      {"seed", o.seed},
                      {"updates", updates},
                      {"policy", ToJson(pc)},
                      {"ppo", ToJson(cfg)}};
  if (!o.out_dir.empty()) {
    std::filesystem::create_directories(o.out_dir);
    SaveJsonFileAtomic(o.out_dir + "/config.json", resolved);
  }
  env->Seed(o.seed);
  eval_env->Seed(o.seed + 1000);
  PpoLearner learner(pc, cfg, o.seed);
  PolicyRunner runner(pc, cfg.obs_norm);
  RolloutCollector collector(env.get(), 0);
  Rng rng(o.seed + 7);
  std::vector<Rollout> batch(1);
  Json curve = Json::array();
  for (int u = 0; u < updates; ++u) {
    runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(),
                      learner.num_updates());
    EpisodeStats es;
    collector.Collect(&runner, rng, cfg.steps_per_update, &batch[0], &es);
    const UpdateStats st = learner.Update(batch);
    double mean_ret = 0;
    for (double x : es.returns) mean_ret += x;
    if (!es.returns.empty()) mean_ret /= es.returns.size();
    Json row = ToJson(st);
    row["update"] = u + 1;
    row["episode_return"] = mean_ret;
    curve.push_back(row);
    spdlog::info("update {}/{}: return {:.3f} kl {:.4f} clip {:.3f} ev {:.2f}", u + 1, updates,
                 mean_ret, st.approx_kl, st.clip_fraction, st.explained_variance);
  }
  // Deterministic evaluation on fresh episodes.
  runner.SetWeights(learner.model().params(), learner.obs_normalizer().stats(),
                    learner.num_updates());
  runner.set_update_obs_stats(false);
  RolloutCollector eval(eval_env.get(), 1);
  eval.set_deterministic(true);
  Rollout ro;
  EpisodeStats es;
  eval.Collect(&runner, rng, cfg.steps_per_update, &ro, &es);
  double mean_ret = 0;
  for (double x : es.returns) mean_ret += x;
  if (!es.returns.empty()) mean_ret /= es.returns.size();
  if (!o.out_dir.empty()) {
    proto::LearnerState state;
    learner.ExportState(&state);
    std::string bytes;
    state.SerializeToString(&bytes);
    WriteFileAtomic(o.out_dir + "/learner_state.pb", bytes);
  }
  return Json{{"config", resolved},
              {"curve", curve},
              {"final_deterministic_return", mean_ret},
              {"episodes", es.returns.size()}};
}

}  // namespace perch
