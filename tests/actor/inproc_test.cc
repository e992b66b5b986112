// Every role in one process over ZeroMQ inproc://: the same LearnerService and ActorService code
// as the processes, only the addresses differ.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>
#include <zmq.hpp>

#include "actor/actor.h"
#include "actor/role_setup.h"
#include "common/proto/model.pb.h"
#include "experiment/experiment.h"
#include "learner/service/learner.h"
#include "learner/service/learner_setup.h"
#include "tests/actor/cluster_fixture.h"

namespace perch {
namespace {

using namespace testing_util;

struct InprocRun {
  std::vector<Json> rows;
  uint64_t actor_segments = 0;
  uint64_t actor_credit_waits = 0;
  uint64_t learner_segments = 0;
  uint64_t learner_stale = 0;
  uint64_t actor_weights_loaded = 0;
  uint64_t learner_updates = 0;
};

LearnerOptions InprocOptions(const std::string& tag, const std::string& run_dir) {
  LearnerOptions lo;
  lo.rollout_bind = "inproc://rollouts-" + tag;
  lo.weights_bind = "inproc://weights-" + tag;
  lo.metrics_port = -1;
  lo.run_dir = run_dir;
  return lo;
}

InprocRun RunInproc(const std::string& tag, int updates, int num_actors,
                    std::string* run_dir_out = nullptr, const Json& j = MockConfig()) {
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "inproc");
  const LearnerSetup ls = MakeLearnerSetup(cfg);
  LearnerOptions lo = InprocOptions(tag, TempDir("inproc") + "/run");
  lo.max_updates = updates;
  if (run_dir_out) *run_dir_out = lo.run_dir;
  zmq::context_t ctx(1);
  // inproc: bind before connect.
  LearnerService learner(ctx, ls, lo);
  std::atomic<bool> stop_actors{false};
  std::vector<std::unique_ptr<ActorService>> actors;
  for (int i = 0; i < num_actors; ++i) {
    const ActorSetup as = MakeActorSetup(cfg);
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
  out.learner_segments = learner.counters().segments();
  out.learner_stale = learner.counters().dropped_stale();
  for (auto& a : actors) {
    out.actor_segments += a->counters().segments_sent;
    out.actor_credit_waits += a->counters().credit_waits;
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
  // Falls are counted apart from time limits: the mock's time limit is 32 steps, so a batch whose
  // episodes average fewer steps had falls, and one without falls averages exactly 32.
  int falls = 0;
  for (const Json& row : r.rows) {
    const int n = row["episodes"].get<int>(), f = row["episodes_terminated"].get<int>();
    EXPECT_LE(f, n);
    falls += f;
    if (n == 0) continue;
    const double len = row["episode_length_mean"].get<double>();
    if (f == 0) {
      EXPECT_DOUBLE_EQ(len, 32.0);
    }
    if (len < 32.0) {
      EXPECT_GT(f, 0);
    }
  }
  EXPECT_GT(falls, 0);
}

// Flow control (issue 20): actors far faster than the learner (mock env; 40 epochs per update)
// make only what the learner uses. Without credit they run ahead and their surplus goes stale.
TEST(InprocTest, CreditKeepsFastActorsFromMakingStaleSegments) {
  auto run = [](const std::string& tag, double slack) {
    Json j = MockConfig(
        Json{{"credit_slack", slack}, {"max_policy_lag", 1}, {"learner_queue_segments", 64}});
    j["ppo"]["num_epochs"] = 40;
    return RunInproc(tag, 12, 6, nullptr, j);
  };
  const InprocRun on = run("credit-on", 1.0);
  ASSERT_EQ(on.learner_updates, 12u);
  EXPECT_GT(on.actor_credit_waits, 0u);  // the actors did wait
  const double drop_on =
      static_cast<double>(on.learner_stale) / (on.learner_segments + on.learner_stale);
  EXPECT_LE(drop_on, 0.05) << on.learner_stale << " stale of " << on.learner_segments;
  // What the actors sent was used or is the last version's surplus (at most one batch with
  // slack 1: 2 x 512 samples / 64 per segment), not a growing backlog.
  EXPECT_LE(on.actor_segments, on.learner_segments + on.learner_stale + 2 * 512 / 64 + 6 * 2);

  const InprocRun off = run("credit-off", 0.0);
  ASSERT_EQ(off.learner_updates, 12u);
  EXPECT_EQ(off.actor_credit_waits, 0u);
  EXPECT_GT(off.actor_segments, on.actor_segments);  // ran ahead
}

// cluster.simulated_lag (issue 20): each segment acts with one of the newest lag + 1 weights
// versions, so batches hold lagged segments; without it flow control keeps them (nearly) all
// current. V-trace's counters see them.
TEST(InprocTest, SimulatedLagMakesLaggedSegments) {
  auto run = [](const std::string& tag, int lag) {
    Json j = MockConfig(Json{{"simulated_lag", lag}, {"max_policy_lag", 4}});
    j["ppo"]["vtrace"] = true;
    return RunInproc(tag, 16, 1, nullptr, j);
  };
  auto late_lag = [](const InprocRun& r, const char* key) {
    double s = 0;
    int n = 0;
    for (size_t i = r.rows.size() / 2; i < r.rows.size(); ++i, ++n)
      s += r.rows[i][key].get<double>();
    return n ? s / n : 0.0;
  };
  const InprocRun lagged = run("simlag-3", 3);
  ASSERT_EQ(lagged.learner_updates, 16u);
  // Uniform over 0..3 once four versions were seen: mean 1.5 (plus any natural lag).
  EXPECT_GT(late_lag(lagged, "policy_lag_mean"), 0.9);
  EXPECT_LT(late_lag(lagged, "policy_lag_mean"), 3.0);
  int corrected = 0;
  for (const Json& row : lagged.rows) corrected += row["ppo"]["lagged_samples"].get<int>();
  EXPECT_GT(corrected, 0);
  const InprocRun plain = run("simlag-0", 0);
  ASSERT_EQ(plain.learner_updates, 16u);
  EXPECT_LT(late_lag(plain, "policy_lag_mean"), 0.9);
}

TEST(InprocTest, ObservationStatisticsCountEachSampleOnce) {
  // The learner merges a segment's observation statistics on receipt; PPO's update must not merge
  // them again (it did: a checkpoint after N samples held count 2N, issue 17).
  std::string dir;
  const InprocRun r = RunInproc("obs-once", 8, 1, &dir);
  std::string newest;
  for (const auto& e : std::filesystem::directory_iterator(dir + "/checkpoints")) {
    newest = std::max(newest, e.path().string());
  }
  const proto::Checkpoint c = ReadCheckpointFile(newest);
  const double count = c.trainer().model().obs_stats().count();
  const double trained = static_cast<double>(c.counters().samples());
  ASSERT_GT(trained, 0.0);
  EXPECT_GE(count, trained);  // every trained sample was seen
  EXPECT_LE(count, static_cast<double>(r.actor_segments) * 64 + 1.0);  // none counted twice
  EXPECT_LT(count, 1.5 * trained);
}

TEST(InprocTest, AnUpdateThatLeavesNonFiniteWeightsIsDiscarded) {
  // A learning rate of 1e38 overflows the weights within a few updates. Each such update is
  // undone: the published weights and every checkpoint stay finite, and it is counted (issue 17).
  Json j = MockConfig();
  j["ppo"]["learning_rate"] = 1e38;
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "nonfinite");
  LearnerOptions lo = InprocOptions("nonfinite", TempDir("nonfinite") + "/run");
  std::atomic<bool> stop{false};
  lo.stop = &stop;
  zmq::context_t ctx(1);
  LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
  ActorOptions ao;
  ao.rollout_connect = lo.rollout_bind;
  ao.weights_connect = lo.weights_bind;
  ao.num_envs = 2;
  ao.stop = &stop;
  ActorService actor(ctx, MakeActorSetup(cfg), ao);
  std::thread actor_thread([&] { actor.Run(); });
  std::thread watchdog([&] {
    for (int i = 0; i < 600 && learner.nonfinite_updates() < 2; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    stop = true;
  });
  learner.Run();
  watchdog.join();
  actor_thread.join();
  EXPECT_GE(learner.nonfinite_updates(), 2u);
  // The actor kept receiving weights it could load (a non-finite set would be refused).
  EXPECT_GT(actor.counters().weights_loaded, 0u);
  for (const auto& e : std::filesystem::directory_iterator(lo.run_dir + "/checkpoints")) {
    const proto::Checkpoint c = ReadCheckpointFile(e.path().string());
    for (float p : c.trainer().model().params()) ASSERT_TRUE(std::isfinite(p)) << e.path();
  }
}

TEST(InprocTest, ASubscriptionFloodCostsOneWeightResendPerInterval) {
  // Thousands of (re)subscriptions in about a second: the learner resends its weights at most
  // every republish_min_interval_s (0.2 s), not once per subscription (issue 17).
  const ExperimentConfig cfg = ExperimentConfigFromJson(MockConfig(), "flood");
  LearnerOptions lo = InprocOptions("flood", TempDir("flood") + "/run");
  std::atomic<bool> stop{false};
  lo.stop = &stop;
  zmq::context_t ctx(1);
  LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
  std::thread run([&] { learner.Run(); });
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.connect(lo.weights_bind);
  const auto t0 = std::chrono::steady_clock::now();
  int subscriptions = 0;
  while (std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(1000)) {
    sub.set(zmq::sockopt::subscribe, "");
    sub.set(zmq::sockopt::unsubscribe, "");
    ++subscriptions;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  stop = true;
  run.join();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_GT(subscriptions, 1000);
  EXPECT_GE(learner.stats().weights_republished, 1u);  // subscribers still get the weights
  EXPECT_LE(static_cast<double>(learner.stats().weights_republished), seconds / 0.2 + 2)
      << subscriptions;
}

// Fine-tuning (walk stage 2 from stage 1): a new run takes the policy weights and normalizer of
// another run's checkpoint, and counts its own updates from 0 with a fresh optimizer.
TEST(InprocTest, NewRunStartsFromInitFromCheckpointWeights) {
  std::string src_dir;
  const InprocRun src = RunInproc("init-src", 6, 1, &src_dir);
  ASSERT_EQ(src.learner_updates, 6u);
  const std::string src_ckpt = src_dir + "/checkpoints/ckpt-0000000006.bin";
  const proto::Checkpoint source = ReadCheckpointFile(src_ckpt);
  ASSERT_GT(source.trainer().adam().step(), 0);

  Json j = MockConfig(Json{{"init_from", src_ckpt}});
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "init");
  EXPECT_EQ(cfg.cluster.init_from, src_ckpt);
  zmq::context_t ctx(1);
  const std::string dst_dir = TempDir("init-dst") + "/run";
  std::string saved;
  {
    LearnerService learner(ctx, MakeLearnerSetup(cfg), InprocOptions("init-dst", dst_dir));
    EXPECT_EQ(learner.version(), 0u);
    EXPECT_EQ(learner.counters().updates(), 0u);
    saved = learner.SaveCheckpoint();
  }
  const proto::Checkpoint fresh = ReadCheckpointFile(saved);
  const proto::ModelWeights& a = source.trainer().model();
  const proto::ModelWeights& b = fresh.trainer().model();
  ASSERT_EQ(a.params_size(), b.params_size());
  for (int i = 0; i < a.params_size(); ++i) ASSERT_EQ(a.params(i), b.params(i)) << i;
  ASSERT_EQ(a.obs_stats().mean_size(), b.obs_stats().mean_size());
  EXPECT_EQ(a.obs_stats().count(), b.obs_stats().count());
  for (int i = 0; i < a.obs_stats().mean_size(); ++i) {
    EXPECT_EQ(a.obs_stats().mean(i), b.obs_stats().mean(i));
  }
  EXPECT_EQ(fresh.trainer().adam().step(), 0);
  EXPECT_EQ(fresh.trainer().num_updates(), 0);
  EXPECT_EQ(fresh.counters().samples(), 0u);
  // The config that made the run records where it started.
  EXPECT_EQ(LoadJsonFile(dst_dir + "/config.json")["cluster"]["init_from"], src_ckpt);

  // Without init_from a new run starts elsewhere (the weights above were not a coincidence).
  const ExperimentConfig scratch = ExperimentConfigFromJson(MockConfig(), "scratch");
  {
    LearnerService learner(ctx, MakeLearnerSetup(scratch),
                           InprocOptions("init-scratch", TempDir("init-scratch") + "/run"));
    const proto::Checkpoint c = ReadCheckpointFile(learner.SaveCheckpoint());
    int same = 0;
    for (int i = 0; i < a.params_size(); ++i) same += c.trainer().model().params(i) == a.params(i);
    EXPECT_LT(same, a.params_size());
  }
}

// cluster.init_state: a new run takes the source's whole trainer state (Adam, reward scaling,
// normaliser, RNG) with its counters at 0; without it only the weights and normaliser.
TEST(InprocTest, InitStateCarriesTheSourcesTrainerStateWithCountersAtZero) {
  std::string src_dir;
  ASSERT_EQ(RunInproc("state-src", 2, 1, &src_dir).learner_updates, 2u);
  const std::string src_ckpt = src_dir + "/checkpoints/ckpt-0000000002.bin";
  const proto::LearnerState a = ReadCheckpointFile(src_ckpt).trainer();
  ASSERT_GT(a.adam().step(), 0);
  zmq::context_t ctx(1);
  auto start = [&](bool state, const std::string& name) {
    Json j = MockConfig(Json{{"init_from", src_ckpt}, {"init_state", state}});
    LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(j, name)),
                           InprocOptions(name, TempDir(name) + "/run"));
    return ReadCheckpointFile(learner.SaveCheckpoint());
  };
  const proto::Checkpoint with = start(true, "state-with");
  const proto::Checkpoint without = start(false, "state-without");
  EXPECT_EQ(with.trainer().adam().step(), a.adam().step());
  ASSERT_EQ(with.trainer().adam().m_size(), a.adam().m_size());
  for (int i = 0; i < a.adam().m_size(); i += 97) {
    EXPECT_EQ(with.trainer().adam().m(i), a.adam().m(i)) << i;
  }
  EXPECT_EQ(with.trainer().return_stats().count(), a.return_stats().count());
  EXPECT_EQ(with.trainer().num_updates(), 0);
  EXPECT_EQ(with.trainer().num_samples(), 0);
  EXPECT_EQ(with.counters().updates(), 0u);
  for (int i = 0; i < a.model().params_size(); i += 97) {
    EXPECT_EQ(with.trainer().model().params(i), a.model().params(i)) << i;
  }
  EXPECT_EQ(without.trainer().adam().step(), 0);
  EXPECT_NE(without.trainer().return_stats().count(), a.return_stats().count());
  // Not with a mirror: the state is taken as it is.
  Json j = MockConfig(Json{{"init_from", src_ckpt}, {"init_state", true}, {"init_mirror", true}});
  try {
    LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(j, "state-mirror")),
                           InprocOptions("state-mirror", TempDir("state-mirror") + "/run"));
    ADD_FAILURE() << "init_state with init_mirror was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("init_state"), std::string::npos) << e.what();
  }
}

// A run configured with wider hidden layers starts from another run's policy widened
// (Net2WiderNet: the same function, more units); a narrower one is refused by name.
TEST(InprocTest, InitFromIntoWiderLayersKeepsThePolicy) {
  std::string src_dir;
  ASSERT_EQ(RunInproc("widen-src", 2, 1, &src_dir).learner_updates, 2u);
  const std::string src_ckpt = src_dir + "/checkpoints/ckpt-0000000002.bin";
  const proto::ModelWeights a = ReadCheckpointFile(src_ckpt).trainer().model();
  Json j = MockConfig(Json{{"init_from", src_ckpt}});
  j["policy"] = {{"policy_net", {{"hidden", {96, 64}}}}, {"value_net", {{"hidden", {64, 80}}}}};
  zmq::context_t ctx(1);
  proto::ModelWeights b;
  {
    LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(j, "wide")),
                           InprocOptions("widen-dst", TempDir("widen-dst") + "/run"));
    b = ReadCheckpointFile(learner.SaveCheckpoint()).trainer().model();
  }
  ASSERT_EQ(b.shape().policy_hidden_size(), 2);
  EXPECT_EQ(b.shape().policy_hidden(0), 96);
  EXPECT_EQ(b.shape().value_hidden(1), 80);
  EXPECT_GT(b.params_size(), a.params_size());
  // Same function: equal deterministic actions and values on a few observations.
  PolicyRunner ra(PolicyConfigFromShape(a.shape(), "a"), NormalizerConfig());
  PolicyRunner rb(PolicyConfigFromShape(b.shape(), "b"), NormalizerConfig());
  ra.LoadWeights(a);
  rb.LoadWeights(b);
  ra.set_update_obs_stats(false);
  rb.set_update_obs_stats(false);
  Rng rng(4), r1(0), r2(0);
  const int obs_dim = a.shape().obs_dim(), act = a.shape().act_dim();
  std::vector<float> obs(obs_dim), xa(act), xb(act);
  for (int t = 0; t < 5; ++t) {
    for (float& x : obs) x = static_cast<float>(rng.Normal());
    EXPECT_NEAR(ra.Act(obs.data(), r1, true, nullptr, xa.data()).value,
                rb.Act(obs.data(), r2, true, nullptr, xb.data()).value, 1e-4);
    for (int k = 0; k < act; ++k) EXPECT_NEAR(xa[k], xb[k], 1e-5) << k;
  }

  j["policy"] = {{"policy_net", {{"hidden", {32, 64}}}}};
  try {
    LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(j, "narrow")),
                           InprocOptions("widen-narrow", TempDir("widen-narrow") + "/run"));
    FAIL() << "a narrower network was initialised from a wider one";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot widen"), std::string::npos) << e.what();
  }
}

// A fine-tune that freezes sigma (std_mode fixed) starts from the source's policy with the
// run's own sigma; the means and values are the source's.
TEST(InprocTest, InitFromIntoFixedSigmaTakesTheRunsSigma) {
  std::string src_dir;
  ASSERT_EQ(RunInproc("fix-src", 2, 1, &src_dir).learner_updates, 2u);
  const std::string src_ckpt = src_dir + "/checkpoints/ckpt-0000000002.bin";
  const proto::ModelWeights a = ReadCheckpointFile(src_ckpt).trainer().model();
  Json j = MockConfig(Json{{"init_from", src_ckpt}});
  j["policy"] = {{"std_mode", "fixed"}, {"init_log_std", -2.5}};
  zmq::context_t ctx(1);
  LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(j, "fixed")),
                         InprocOptions("fix-dst", TempDir("fix-dst") + "/run"));
  const proto::ModelWeights b = ReadCheckpointFile(learner.SaveCheckpoint()).trainer().model();
  EXPECT_EQ(b.shape().std_mode(), "fixed");
  ASSERT_EQ(b.params_size(), a.params_size());
  const int off = ActorCritic(PolicyConfigFromShape(b.shape(), "b"), 0).log_std_offset();
  const int act = b.shape().act_dim();
  for (int k = 0; k < b.params_size(); ++k) {
    if (k >= off && k < off + act) {
      EXPECT_FLOAT_EQ(b.params(k), -2.5f) << k;
    } else {
      EXPECT_EQ(b.params(k), a.params(k)) << k;
    }
  }
}

// A resume with the same config rewrites config.json in place; one with a changed config (a lower
// learning rate for the last stretch) keeps the earlier config under the update it ended at.
TEST(InprocTest, ResumeWithAChangedConfigKeepsTheEarlierOne) {
  std::string dir;
  ASSERT_EQ(RunInproc("cfg-hist", 2, 1, &dir).learner_updates, 2u);
  const Json before = LoadJsonFile(dir + "/config.json");
  zmq::context_t ctx(1);
  LearnerOptions lo = InprocOptions("cfg-hist-same", dir);
  lo.resume = true;
  {
    LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(MockConfig(), "same")),
                           lo);
    ASSERT_EQ(learner.counters().updates(), 2u);
  }
  EXPECT_EQ(LoadJsonFile(dir + "/config.json"), before);
  EXPECT_FALSE(std::filesystem::exists(dir + "/config-to-0000000002.json"));

  Json changed = MockConfig();
  changed["ppo"]["learning_rate"] = 1e-5;
  lo.rollout_bind += "-lr";
  lo.weights_bind += "-lr";
  {
    LearnerService learner(ctx, MakeLearnerSetup(ExperimentConfigFromJson(changed, "lr")), lo);
    ASSERT_EQ(learner.counters().updates(), 2u);
  }
  const Json now = LoadJsonFile(dir + "/config.json");
  EXPECT_FLOAT_EQ(now["ppo"]["learning_rate"].get<float>(), 1e-5f);
  ASSERT_TRUE(std::filesystem::exists(dir + "/config-to-0000000002.json"));
  EXPECT_EQ(LoadJsonFile(dir + "/config-to-0000000002.json"), before);
}

TEST(InprocTest, InitFromRefusesMissingCorruptOrMismatchedCheckpoints) {
  std::string src_dir;
  RunInproc("init-bad-src", 2, 1, &src_dir);
  const std::string src_ckpt = src_dir + "/checkpoints/ckpt-0000000002.bin";
  zmq::context_t ctx(1);
  auto expect_refused = [&](const Json& cluster, const std::string& tag,
                            const std::string& needle) {
    const ExperimentConfig cfg = ExperimentConfigFromJson(MockConfig(cluster), tag);
    LearnerSetup ls = MakeLearnerSetup(cfg);
    if (tag == "shape") ls.policy.policy_net.hidden = {32};
    try {
      LearnerService learner(ctx, ls, InprocOptions(tag, TempDir(tag) + "/run"));
      ADD_FAILURE() << tag << ": accepted";
    } catch (const ConfigError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("cluster.init_from"), std::string::npos) << what;
      EXPECT_NE(what.find(needle), std::string::npos) << what;
    }
  };
  expect_refused(Json{{"init_from", src_dir + "/nope.bin"}}, "missing", "nope.bin");
  const std::string corrupt = TempDir("init-corrupt") + "/ckpt.bin";
  {
    std::ifstream in(src_ckpt, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    bytes[bytes.size() / 2] ^= 0x5a;
    std::ofstream(corrupt, std::ios::binary) << bytes;
  }
  expect_refused(Json{{"init_from", corrupt}}, "corrupt", "ckpt.bin");
  expect_refused(Json{{"init_from", src_ckpt}}, "shape", "ckpt-0000000002.bin");
  // Mirroring needs an env with a left/right symmetry (the mock env has none) and a source.
  expect_refused(Json{{"init_from", src_ckpt}, {"init_mirror", true}}, "mirror", "mirror map");
  EXPECT_THROW(ExperimentConfigFromJson(MockConfig(Json{{"init_mirror", true}}), "nosrc"),
               ConfigError);
  // The source run is untouched.
  EXPECT_EQ(ReadCheckpointFile(src_ckpt).counters().updates(), 2u);
}

// A heartbeat flood with made-up instance ids (issue 17) must not grow the learner's memory without
// bound, and silent instances are forgotten after actor_timeout_s.
TEST(InprocTest, AHeartbeatFloodIsBoundedAndForgotten) {
  Json j = MockConfig(Json{{"actor_timeout_s", 0.5}, {"learner_queue_segments", 100000}});
  const ExperimentConfig cfg = ExperimentConfigFromJson(j, "flood");
  LearnerOptions lo = InprocOptions("flood", TempDir("flood") + "/run");
  std::atomic<bool> stop{false};
  lo.stop = &stop;
  zmq::context_t ctx(1);
  LearnerService learner(ctx, MakeLearnerSetup(cfg), lo);
  std::thread run([&] { learner.Run(); });
  zmq::socket_t push(ctx, zmq::socket_type::push);
  push.set(zmq::sockopt::sndhwm, 0);
  push.connect(lo.rollout_bind);
  const size_t n = LearnerService::kMaxTrackedActors + 5000;
  for (size_t i = 0; i < n; ++i) {
    proto::ActorMessage m;
    m.set_wire_version(proto::WIRE_VERSION_CURRENT);
    m.mutable_heartbeat()->set_actor_instance(0x1234567800000000ULL + i);
    push.send(zmq::buffer(m.SerializeAsString()), zmq::send_flags::none);
  }
  EXPECT_TRUE(WaitUntil([&] { return learner.stats().heartbeats >= n; }, 60.0))
      << learner.stats().heartbeats;
  EXPECT_LE(learner.tracked_actors(), LearnerService::kMaxTrackedActors);
  // Silent for longer than actor_timeout_s: pruned (once a second).
  EXPECT_TRUE(WaitUntil([&] { return learner.tracked_actors() == 0; }, 5.0))
      << learner.tracked_actors();
  stop = true;
  run.join();
}

}  // namespace
}  // namespace perch

namespace perch {
namespace {

using namespace testing_util;

// The meta controller over the real sit_chair env: the learner reads the frozen walker named in
// the config and ships it; the actors (which read no model file) can only step, and the learner
// can only update, once it arrived. The checkpoint keeps it.
TEST(InprocTest, MetaRunShipsItsFrozenSubtasksAndCheckpointsThem) {
  Json j = LoadJsonFile(std::string(PERCH_SOURCE_DIR) + "/configs/meta_walk.json");
  j["ppo"]["steps_per_update"] = 16;
  j["ppo"]["num_minibatches"] = 2;
  j["cluster"]["segment_steps"] = 8;
  j["cluster"]["insecure"] = true;
  j["cluster"]["checkpoint_every"] = 1;
  j["cluster"]["heartbeat_s"] = 0.2;
  std::string run_dir;
  const InprocRun r = RunInproc("meta", 3, 2, &run_dir, j);
  EXPECT_EQ(r.learner_updates, 3u);
  EXPECT_GE(r.actor_segments, 6u);
  const CheckpointStore store(run_dir, 3, 0);
  ASSERT_FALSE(store.List().empty());
  const proto::Checkpoint c = ReadCheckpointFile(store.PathFor(store.List().back()));
  int frozen = 0;
  for (const proto::TaskPolicy& p : c.weights().policies()) {
    if (!p.frozen()) {
      EXPECT_EQ(p.task(), proto::TASK_META);
      EXPECT_EQ(p.model().shape().kind(), "meta");
      continue;
    }
    ++frozen;
    EXPECT_EQ(p.task(), proto::TASK_WALK);
    EXPECT_NE(p.source().find("walk_stage2_fallrestart"), std::string::npos) << p.source();
    EXPECT_NE(p.source().find("sha256"), std::string::npos);
    EXPECT_EQ(p.model().shape().obs_dim(), 52);
  }
  EXPECT_EQ(frozen, 1);
}

}  // namespace
}  // namespace perch
