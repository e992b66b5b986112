#include "tasks/state_bank.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <thread>

#include "common/file_util.h"
#include "common/paths.h"
#include "policy/policy.h"
#include "tasks/episode_loop.h"

namespace perch {
namespace {

constexpr char kMagic[8] = {'P', 'E', 'R', 'C', 'H', 'B', 'N', 'K'};
proto::Vec3 V(const Eigen::Vector3d& v) {
  proto::Vec3 p;
  p.set_x(v.x());
  p.set_y(v.y());
  p.set_z(v.z());
  return p;
}
Eigen::Vector3d V(const proto::Vec3& p) { return Eigen::Vector3d(p.x(), p.y(), p.z()); }
proto::Quat Q(const Eigen::Quaterniond& q) {
  proto::Quat p;
  p.set_w(q.w());
  p.set_x(q.x());
  p.set_y(q.y());
  p.set_z(q.z());
  return p;
}
Eigen::Quaterniond Q(const proto::Quat& p) {
  return Eigen::Quaterniond(p.w(), p.x(), p.y(), p.z());
}

}  // namespace

void WriteStateBank(const std::string& path, const proto::StateBank& bank, bool overwrite) {
  if (!overwrite && std::filesystem::exists(path)) {
    throw ConfigError(path + ": exists; not overwritten (a bank is an experiment's input)");
  }
  const std::string out = FramePayload(kMagic, kStateBankFormat, bank.SerializeAsString());
  WriteFileAtomic(path, out);
}

proto::StateBank ReadStateBank(const std::string& path, const HumanoidModel* model) {
  const std::string payload = UnframePayload(ReadFileBytes(path), path, kMagic, kStateBankFormat,
                                             "state bank", " (resample it with this build)");
  proto::StateBank bank;
  if (!bank.ParseFromString(payload))
    throw ConfigError(path + ": state bank payload does not parse");
  if (bank.format_version() != kStateBankFormat) {
    throw ConfigError(path + ": state bank message version " +
                      std::to_string(bank.format_version()) + " (expected " +
                      std::to_string(kStateBankFormat) + ")");
  }
  if (bank.states_size() == 0) throw ConfigError(path + ": state bank holds no states");
  const int nj = bank.joint_names_size();
  if (model != nullptr) {
    bool same = nj == model->num_joints();
    for (int j = 0; same && j < nj; ++j) same = bank.joint_names(j) == model->joint(j).name;
    if (!same) {
      throw ConfigError(path + ": state bank joint layout (" + std::to_string(nj) +
                        " joints) differs from the humanoid's (" +
                        std::to_string(model->num_joints()) + "): sampled from another model");
    }
  }
  for (int i = 0; i < bank.states_size(); ++i) {
    const proto::BankState& s = bank.states(i);
    if (s.q_size() != nj || s.qd_size() != nj) {
      throw ConfigError(path + ": state " + std::to_string(i) + " has " +
                        std::to_string(s.q_size()) + " joint angles, the bank's layout " +
                        std::to_string(nj));
    }
    const Eigen::Quaterniond q = Q(s.root_quat());
    if (!V(s.root_pos()).allFinite() || !std::isfinite(q.norm()) || std::abs(q.norm() - 1) > 1e-3) {
      throw ConfigError(path + ": state " + std::to_string(i) +
                        " has a non-finite position or "
                        "a non-unit orientation");
    }
  }
  return bank;
}

proto::BankState CaptureState(const HumanoidChairEnv& env) {
  const EnvState es = env.GetState();
  const HumanoidState& h = es.world.humanoid;
  proto::BankState b;
  *b.mutable_root_pos() = V(h.root_pos);
  *b.mutable_root_quat() = Q(h.root_quat);
  *b.mutable_root_lin_vel() = V(h.root_lin_vel);
  *b.mutable_root_ang_vel() = V(h.root_ang_vel);
  for (int j = 0; j < HumanoidModel::kNumJoints; ++j) {
    b.add_q(h.q[j]);
    b.add_qd(h.qd[j]);
  }
  b.set_has_chair(env.world().has_chair());
  if (b.has_chair()) {
    *b.mutable_chair_pos() = V(es.world.chair.pos);
    *b.mutable_chair_quat() = Q(es.world.chair.quat);
    *b.mutable_chair_lin_vel() = V(es.world.chair.lin_vel);
    *b.mutable_chair_ang_vel() = V(es.world.chair.ang_vel);
  }
  b.set_foot_right(es.foot_flags[0]);
  b.set_foot_left(es.foot_flags[1]);
  b.set_step(es.step);
  b.set_walk_target_x(es.walk_target.x());
  b.set_walk_target_y(es.walk_target.y());
  b.set_task_memory_json(env.task().SaveMemory().dump());
  return b;
}

HumanoidState HumanoidStateOf(const proto::BankState& b) {
  HumanoidState h;
  h.root_pos = V(b.root_pos());
  h.root_quat = Q(b.root_quat()).normalized();
  h.root_lin_vel = V(b.root_lin_vel());
  h.root_ang_vel = V(b.root_ang_vel());
  for (int j = 0; j < HumanoidModel::kNumJoints && j < b.q_size(); ++j) {
    h.q[j] = b.q(j);
    h.qd[j] = b.qd(j);
  }
  return h;
}

EnvState EnvStateOf(const proto::BankState& b) {
  EnvState es;
  es.world.humanoid = HumanoidStateOf(b);
  if (b.has_chair()) {
    es.world.chair.pos = V(b.chair_pos());
    es.world.chair.quat = Q(b.chair_quat()).normalized();
    es.world.chair.lin_vel = V(b.chair_lin_vel());
    es.world.chair.ang_vel = V(b.chair_ang_vel());
  }
  es.foot_flags = {b.foot_right(), b.foot_left()};
  es.step = b.step();
  es.walk_target = Eigen::Vector2d(b.walk_target_x(), b.walk_target_y());
  return es;
}

namespace {

// An end-pose sampling episode in the shared loop (tasks/episode_loop.h): the policy acts; the
// state after exactly o.steps steps is kept (its episode must then survive o.survive more).
class SampleDriver : public EpisodeDriver {
 public:
  SampleDriver(HumanoidChairEnv* env, PolicyRunner* runner, const SampleEndPosesOptions& o)
      : env_(env), runner_(runner), o_(o) {}
  void Begin(int, uint64_t, const float*) override { kept.reset(); }
  bool Act(const float* obs, Rng& rng, float* action) override {
    runner_->Act(obs, rng, !o_.stochastic, nullptr, action);
    return true;
  }
  void Stepped(const StepResult& r, int steps) override {
    if (!r.terminated && steps == o_.steps) {
      kept = std::make_unique<proto::BankState>(CaptureState(*env_));
    }
  }
  std::unique_ptr<proto::BankState> kept;

 private:
  HumanoidChairEnv* env_;
  PolicyRunner* runner_;
  const SampleEndPosesOptions& o_;
};

}  // namespace

proto::StateBank SampleEndPoses(const TaskEnvConfig& config, const proto::ModelWeights& weights,
                                const SampleEndPosesOptions& o) {
  if (o.steps < 1 || o.survive < 0 || o.count < 1 || o.workers < 1) {
    throw ConfigError("sample-end-poses: need steps >= 1, survive >= 0, count >= 1, workers >= 1");
  }
  const PolicyConfig pc = PolicyConfigFromShape(weights.shape(), "model");
  std::vector<std::unique_ptr<HumanoidChairEnv>> envs;
  for (int w = 0; w < o.workers; ++w) envs.push_back(MakeTaskHumanoidEnv(config));
  const EnvSpec& spec = envs[0]->spec();
  if (pc.kind != PolicyKind::kGaussian || pc.obs_dim != spec.obs_dim ||
      pc.act_dim != spec.act_dim) {
    throw ConfigError("model: obs " + std::to_string(pc.obs_dim) + " act " +
                      std::to_string(pc.act_dim) + " does not fit the " + config.env.task +
                      " env (obs " + std::to_string(spec.obs_dim) + ")");
  }
  const int horizon = o.steps + o.survive;
  if (horizon > spec.max_episode_steps) {
    throw ConfigError("sample-end-poses: --steps + --survive = " + std::to_string(horizon) +
                      " exceeds the task's time limit of " +
                      std::to_string(spec.max_episode_steps) + " steps");
  }
  std::mutex mu;
  std::map<int64_t, std::unique_ptr<proto::BankState>> done;  // episode -> state (null: fell)
  std::atomic<int64_t> next{0};
  std::atomic<bool> stop{false};
  int64_t prefix = 0;  // episodes [0, prefix) are all done
  int prefix_ok = 0;   // survivors among them
  auto worker = [&](int w) {
    HumanoidChairEnv& env = *envs[w];
    PolicyRunner runner(pc, NormalizerConfig());
    runner.LoadWeights(weights);
    runner.set_update_obs_stats(false);  // the policy's own saved normaliser
    SampleDriver driver(&env, &runner, o);
    while (!stop.load()) {
      const int64_t e = next.fetch_add(1);
      const EpisodeEnd end =
          RunEpisode(&env, static_cast<int>(e), o.seed, {horizon, false}, &driver);
      const bool ok = !end.fell;
      std::unique_ptr<proto::BankState> kept = std::move(driver.kept);
      if (kept) kept->set_episode(static_cast<uint64_t>(e));
      std::lock_guard<std::mutex> lock(mu);
      done[e] = ok ? std::move(kept) : nullptr;
      for (auto it = done.find(prefix); it != done.end(); it = done.find(prefix)) {
        prefix_ok += it->second != nullptr;
        ++prefix;
      }
      if (prefix_ok >= o.count) stop = true;
    }
  };
  std::vector<std::thread> threads;
  for (int w = 0; w < o.workers; ++w) threads.emplace_back(worker, w);
  auto last = std::chrono::steady_clock::now();
  while (!stop.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (o.progress && std::chrono::steady_clock::now() - last > std::chrono::seconds(1)) {
      last = std::chrono::steady_clock::now();
      std::lock_guard<std::mutex> lock(mu);
      o.progress(prefix_ok, prefix);
    }
  }
  for (auto& t : threads) t.join();
  proto::StateBank bank =
      NewStateBank(config.env.task, envs[0]->model(), o.seed, o.stochastic, config.ToJson());
  bank.set_model_version(weights.version());
  bank.set_steps(o.steps);
  bank.set_survive(o.survive);
  bank.set_count(o.count);
  // The first `count` survivors by episode index: the same whatever the workers did beyond.
  int64_t episodes = 0;
  for (auto& [e, s] : done) {
    if (bank.states_size() >= o.count) break;
    episodes = e + 1;
    if (s) *bank.add_states() = std::move(*s);
  }
  bank.set_episodes_run(episodes);
  if (o.progress) o.progress(bank.states_size(), episodes);
  return bank;
}

proto::StateBank NewStateBank(const std::string& task, const HumanoidModel& model, uint64_t seed,
                              bool stochastic, const Json& env_config) {
  proto::StateBank bank;
  bank.set_format_version(kStateBankFormat);
  bank.set_task(task);
  for (int j = 0; j < model.num_joints(); ++j) bank.add_joint_names(model.joint(j).name);
  bank.set_seed(seed);
  bank.set_stochastic(stochastic);
  bank.set_env_config_json(env_config.dump());
  return bank;
}

std::shared_ptr<const StartBank> LoadStartBanks(const std::vector<std::string>& paths,
                                                const HumanoidModel& model) {
  static std::mutex mu;
  static std::map<std::string, std::weak_ptr<const StartBank>> cache;
  std::string key;
  for (const std::string& p : paths) key += p + "\n";
  std::lock_guard<std::mutex> lock(mu);
  if (auto hit = cache[key].lock()) return hit;
  auto bank = std::make_shared<StartBank>();
  for (const std::string& p : paths) {
    const std::string path = ResolveProjectPath(p);
    const proto::StateBank b = ReadStateBank(path, &model);
    bank->states.insert(bank->states.end(), b.states().begin(), b.states().end());
    bank->path += (bank->path.empty() ? "" : ", ") + path;
  }
  cache[key] = bank;
  return bank;
}

void WriteHandOverBank(const std::string& file, const std::string& task,
                       const TaskEnvConfig& config, const std::string& model_path, uint64_t seed,
                       bool stochastic, int episodes_run, std::vector<proto::BankState>& states,
                       bool overwrite) {
  const HumanoidModel model = HumanoidModel::Load(config.env.HumanoidPath());
  proto::StateBank bank = NewStateBank(task, model, seed, stochastic, config.ToJson());
  bank.set_model_path(model_path);
  bank.set_count(static_cast<int>(states.size()));
  bank.set_episodes_run(episodes_run);
  for (proto::BankState& b : states) *bank.add_states() = std::move(b);
  WriteStateBank(file, bank, overwrite);
}

}  // namespace perch
