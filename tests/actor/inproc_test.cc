// Every role in one process over ZeroMQ inproc://: the same LearnerService and ActorService code
// as the processes, only the addresses differ.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <zmq.hpp>

#include "actor/actor.h"
#include "actor/experiment.h"
#include "learner/service/learner.h"
#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

struct InprocRun {
  std::vector<Json> rows;
  uint64_t actor_segments = 0;
  uint64_t actor_weights_loaded = 0;
  uint64_t learner_updates = 0;
};

InprocRun RunInproc(const std::string& tag, int updates, int num_actors) {
  const Json j = MockConfig();
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "inproc");
  std::unique_ptr<Env> env = MakeExperimentEnv(cfg);
  LearnerSetup ls;
  ls.seed = cfg.seed;
  ls.policy = ResolvePolicyConfig(cfg, env->spec());
  ls.ppo = cfg.ppo;
  ls.cluster = cfg.cluster;
  ls.resolved_config = ToJson(cfg);
  ls.compat_key = CompatKey(cfg, ls.policy);
  LearnerOptions lo;
  lo.rollout_bind = "inproc://rollouts-" + tag;
  lo.weights_bind = "inproc://weights-" + tag;
  lo.metrics_port = -1;
  lo.run_dir = TempDir("inproc") + "/run";
  lo.max_updates = updates;
  zmq::context_t ctx(1);
  // inproc: bind before connect.
  LearnerService learner(ctx, ls, lo);
  std::atomic<bool> stop_actors{false};
  std::vector<std::unique_ptr<ActorService>> actors;
  for (int i = 0; i < num_actors; ++i) {
    ActorSetup as;
    as.seed = cfg.seed;
    as.policy = ls.policy;
    as.obs_norm = cfg.ppo.obs_norm;
    as.cluster = cfg.cluster;
    as.make_env = [cfg] { return MakeExperimentEnv(cfg); };
    ActorOptions ao;
    ao.rollout_connect = lo.rollout_bind;
    ao.weights_connect = lo.weights_bind;
    ao.actor_id = static_cast<uint32_t>(i);
    ao.num_envs = 2;
    ao.stop = &stop_actors;
    actors.push_back(std::make_unique<ActorService>(ctx, as, ao));
  }
  std::vector<std::thread> threads;
  for (auto& a : actors) threads.emplace_back([&a] { a->Run(); });
  learner.Run();
  stop_actors = true;
  for (auto& t : threads) t.join();
  InprocRun out;
  out.rows = ReadMetrics(lo.run_dir);
  out.learner_updates = learner.counters().updates();
  for (auto& a : actors) {
    out.actor_segments += a->counters().segments_sent;
    out.actor_weights_loaded += a->counters().weights_loaded;
  }
  return out;
}

TEST(InprocTest, LearnerAndTwoActorsInOneProcessLearnTheMockTask) {
  const InprocRun r = RunInproc("learn", 30, 2);
  ASSERT_EQ(r.learner_updates, 30u);
  ASSERT_EQ(r.rows.size(), 30u);
  // Actors took new weights between segments, more than once.
  EXPECT_GT(r.actor_weights_loaded, 4u);
  EXPECT_GE(r.actor_segments, 30u * 512 / 64);
  // The mock task is learnable: the mean return of the last updates beats the first ones.
  auto mean_return = [&](size_t from, size_t to) {
    double s = 0;
    int n = 0;
    for (size_t i = from; i < to; ++i) {
      if (r.rows[i]["return_mean"].is_number()) {
        s += r.rows[i]["return_mean"].get<double>();
        ++n;
      }
    }
    return n ? s / n : 0.0;
  };
  EXPECT_GT(mean_return(25, 30), mean_return(0, 5) + 2.0);
}

}  // namespace
}  // namespace perch
