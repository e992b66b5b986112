#include "learner/local/local_train.h"

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "common/file_util.h"
#include "common/proto/model.pb.h"
#include "common/rng.h"
#include "policy/rollout.h"

namespace perch {
namespace {}  // namespace

Json TrainLocal(const TaskEnvConfig& config, const LocalTrainOptions& o,
                const std::function<void(const Json&)>& progress) {
  if (o.out_dir.empty()) throw ConfigError("train-local: --out is required");
  if (o.samples < 1) throw ConfigError("train-local: --samples must be >= 1");
  std::filesystem::create_directories(o.out_dir);
  std::unique_ptr<Env> env = MakeTaskEnv(config);
  env->Seed(2 * o.seed);
  const EnvSpec& spec = env->spec();
  const PolicyConfig pc = PolicyConfig::Subtask(spec.obs_dim);
  PpoLearner learner(pc, o.ppo, o.seed);
  PolicyRunner runner(pc, o.ppo.obs_norm);
  RolloutCollector collector(env.get(), 0);
  Rng rng(2 * o.seed + 1);

  Json resolved{{"env", config.ToJson()},
                {"ppo", ToJson(o.ppo)},
                {"policy", ToJson(pc)},
                {"seed", o.seed},
                {"samples", o.samples}};
  WriteFileAtomic(o.out_dir + "/config.json", resolved.dump(2) + "\n");

  const std::string csv_path = o.out_dir + "/curve.csv";
  std::string csv =
      "update,samples,episodes,mean_episode_return,mean_episode_steps,fall_fraction,mean_reward,"
      "policy_loss,value_loss,approx_kl,entropy,explained_variance\n";
  std::vector<Rollout> batch(1);
  const int per_update = o.ppo.steps_per_update;
  const int64_t updates = (o.samples + per_update - 1) / per_update;
  Json last;
  for (int64_t u = 0; u < updates; ++u) {
    proto::ModelWeights w;
    learner.ExportWeights(&w);
    runner.LoadWeights(w);
    EpisodeStats stats;
    collector.Collect(&runner, rng, per_update, &batch[0], &stats);
    const UpdateStats us = learner.Update(batch);
    double ret = 0, len = 0;
    for (size_t i = 0; i < stats.returns.size(); ++i)
      ret += stats.returns[i], len += stats.lengths[i];
    const double ne = static_cast<double>(stats.returns.size());
    const double mean_ret = ne > 0 ? ret / ne : 0.0, mean_len = ne > 0 ? len / ne : 0.0;
    const double falls = ne > 0 ? stats.terminated / ne : 0.0;
    char row[512];
    std::snprintf(row, sizeof(row), "%lld,%lld,%d,%.6g,%.6g,%.4g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g\n",
                  static_cast<long long>(u + 1), static_cast<long long>(learner.num_samples()),
                  static_cast<int>(ne), mean_ret, mean_len, falls, us.mean_reward, us.policy_loss,
                  us.value_loss, us.approx_kl, us.entropy, us.explained_variance);
    csv += row;
    WriteFileAtomic(csv_path, csv);  // the curve so far survives an interrupted run
    last = Json{{"update", u + 1},
                {"samples", learner.num_samples()},
                {"episodes", static_cast<int>(ne)},
                {"mean_episode_return", mean_ret},
                {"mean_episode_steps", mean_len},
                {"fall_fraction", falls},
                {"mean_reward", us.mean_reward}};
    if (progress) progress(last);
  }
  proto::LearnerState state;
  learner.ExportState(&state);
  WriteFileAtomic(o.out_dir + "/learner_state.bin", state.SerializeAsString());
  proto::ModelWeights w;
  learner.ExportWeights(&w);
  WriteFileAtomic(o.out_dir + "/weights.bin", w.SerializeAsString());
  return Json{{"out_dir", o.out_dir},
              {"updates", updates},
              {"samples", learner.num_samples()},
              {"last", last},
              {"weights", o.out_dir + "/weights.bin"},
              {"learner_state", o.out_dir + "/learner_state.bin"},
              {"curve", csv_path}};
}

}  // namespace perch
