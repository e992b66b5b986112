// perch bench profile: where an actor's control step goes, per phase (Bullet's solver, dynamics,
// collision; the env's own code; the policy; the wire), in one process with the actor's pieces
// (experiment env, PolicyRunner, RolloutCollector, segment serialisation).
#include <time.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "actor/role_setup.h"
#include "app/commands.h"
#include "common/json_util.h"
#include "common/proto/model.pb.h"
#include "envs/physics_profile.h"
#include "experiment/experiment.h"
#include "policy/policy.h"
#include "policy/rollout.h"
#include "tasks/walk_eval.h"

namespace perch {
namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Times Reset and Step of the env it wraps.
class TimedEnv : public Env {
 public:
  explicit TimedEnv(std::unique_ptr<Env> env) : env_(std::move(env)) {}
  const EnvSpec& spec() const override { return env_->spec(); }
  void Seed(uint64_t seed) override { env_->Seed(seed); }
  void Reset(float* obs) override {
    const double t0 = Now();
    env_->Reset(obs);
    reset_s += Now() - t0;
    ++resets;
  }
  StepResult Step(const float* action, float* obs) override {
    const double t0 = Now();
    const StepResult r = env_->Step(action, obs);
    step_s += Now() - t0;
    ++steps;
    return r;
  }
  double step_s = 0.0, reset_s = 0.0;
  int64_t steps = 0, resets = 0;

 private:
  std::unique_ptr<Env> env_;
};

// Bullet's zones by phase (own time of each zone; unlisted zones count as physics_other).
const std::map<std::string, std::string>& ZonePhases() {
  static const std::map<std::string, std::string> m = {
      {"setupMultiBodyContactConstraint", "solver_contact_rows"},
      {"addMultiBodyFrictionConstraint", "solver_friction_rows"},
      {"addMultiBodyRollingFrictionConstraint", "solver_friction_rows"},
      {"setupMultiBodyRollingFrictionConstraint", "solver_friction_rows"},
      {"solveGroupCacheFriendlySetup", "solver_other_setup"},  // joint-limit rows, bodies
      {"convertBodies", "solver_other_setup"},
      {"convertJoints", "solver_other_setup"},
      {"solveGroupCacheFriendlyIterations", "solver_iterations"},
      {"solveSingleIteration", "solver_iterations"},
      {"solveGroupCacheFriendlySplitImpulseIterations", "solver_iterations"},
      {"solveGroupCacheFriendlyFinish", "solver_finish"},
      {"btMultiBodyConstraintSolver::solveGroupCacheFriendlyFinish", "solver_finish"},
      {"warm starting write back", "solver_finish"},
      {"multi body joint feedback", "solver_finish"},
      {"btMultiBody addForce", "dynamics"},
      {"btMultiBody addGravity", "dynamics"},
      {"btMultiBody stepVelocities", "dynamics"},
      {"btMultiBody stepPositions", "dynamics"},
      {"integrateTransforms", "dynamics"},
      {"predictUnconstraintMotion", "dynamics"},
      {"dispatchAllCollisionPairs", "narrowphase"},
      {"processAllOverlappingPairs", "narrowphase"},
      {"btHashedOverlappingPairCache::processAllOverlappingPairs", "narrowphase"},
      {"calculateOverlappingPairs", "broadphase"},
      {"updateAabbs", "broadphase"},
  };
  return m;
}

struct ProfileArgs {
  std::string config = "configs/default.json";
  std::string model;  // empty: the config's freshly initialised policy
  int steps = 3000;
  uint64_t seed = 0;
  bool json = false;
};

double ThreadCpuSeconds() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

struct PassTimes {
  double cpu_s = 0;  // thread CPU time of the whole pass
  double collect_s = 0, wire_s = 0;
  int64_t steps = 0, resets = 0;
  double env_step_s = 0, env_reset_s = 0;
};

// Collects `steps` control steps in segments as an actor does and serialises each segment.
PassTimes RunPass(const ExperimentConfig& cfg, const ProfileArgs& a, bool profile) {
  const ActorSetup setup = MakeActorSetup(cfg);
  TimedEnv env(setup.make_env());
  env.Seed(a.seed);
  std::unique_ptr<PolicyRunner> runner;
  if (a.model.empty()) {
    runner = std::make_unique<PolicyRunner>(setup.policy, setup.obs_norm);
  } else {
    const proto::ModelWeights w = LoadModelFile(a.model);
    runner = std::make_unique<PolicyRunner>(PolicyConfigFromShape(w.shape(), a.model),
                                            NormalizerConfig());
    runner->LoadWeights(w);
  }
  if (runner->model().config().obs_dim != env.spec().obs_dim) {
    throw ConfigError(a.model + ": the policy's observation does not fit the config's env");
  }
  RolloutCollector collector(&env, 0);
  Rng rng(a.seed);
  Rollout r;
  EpisodeStats stats;
  proto::RolloutSegment seg;
  const int segment = setup.cluster.segment_steps;
  PhysicsProfile::Enable(profile);
  PhysicsProfile::Reset();
  PassTimes t;
  size_t bytes = 0;
  const double c0 = ThreadCpuSeconds();
  for (int done = 0; done < a.steps; done += segment) {
    const double t0 = Now();
    collector.Collect(runner.get(), rng, std::min(segment, a.steps - done), &r, &stats);
    const double t1 = Now();
    seg.Clear();
    r.ToProto(&seg);
    bytes += seg.SerializeAsString().size();
    t.wire_s += Now() - t1;
    t.collect_s += t1 - t0;
  }
  t.cpu_s = ThreadCpuSeconds() - c0;
  PhysicsProfile::Enable(false);
  t.steps = env.steps;
  t.resets = env.resets;
  t.env_step_s = env.step_s;
  t.env_reset_s = env.reset_s;
  return t;
}

void RunProfile(const ProfileArgs& a) {
  if (a.steps < 1) throw ConfigError("--steps: must be >= 1");
  const ExperimentConfig cfg = LoadExperimentConfig(a.config);
  if (cfg.env_backend != "bullet") throw ConfigError(a.config + ": env_backend must be bullet");
  // Same seeds, hence the same episodes, with and without the zone hooks: their cost shows.
  const PassTimes plain = RunPass(cfg, a, false);
  const PassTimes t = RunPass(cfg, a, true);
  const std::vector<PhysicsZone> zones = PhysicsProfile::Zones();
  const double physics = PhysicsProfile::OutermostSeconds();
  const double per = 1e6 / t.steps;  // s -> us per control step
  std::map<std::string, double> phase;
  Json zone_json = Json::object();
  for (const PhysicsZone& z : zones) {
    const auto it = ZonePhases().find(z.name);
    std::string ph = it == ZonePhases().end() ? "physics_other" : it->second;
    // A friction row is set up like a contact row, inside addMultiBodyFrictionConstraint.
    if (ph == "solver_contact_rows" && z.parent.find("Friction") != std::string::npos) {
      ph = "solver_friction_rows";
    }
    phase[ph] += z.self_s;
    Json& zj = zone_json[z.parent.empty() ? z.name : z.parent + " / " + z.name];
    zj["us_per_step"] = per * z.self_s;
    zj["calls_per_step"] = 1.0 * z.calls / t.steps;
  }
  double solver = 0;
  for (const auto& [k, v] : phase) solver += k.rfind("solver_", 0) == 0 ? v : 0.0;
  const double env_total = t.env_step_s + t.env_reset_s;
  const double total = t.collect_s + t.wire_s;
  Json phases = Json::object();
  for (const auto& [k, v] : phase) phases[k] = per * v;
  phases["solver"] = per * solver;
  phases["collision"] = per * (phase["narrowphase"] + phase["broadphase"]);
  phases["physics"] = per * physics;
  phases["env_own"] = per * (env_total - physics);
  phases["reset_total"] = per * t.env_reset_s;
  phases["policy_and_collector"] = per * (t.collect_s - env_total);
  phases["wire"] = per * t.wire_s;
  phases["total"] = per * total;
  Json share = Json::object();
  for (const char* k : {"solver", "dynamics", "collision", "narrowphase", "broadphase",
                        "physics_other", "physics", "env_own", "policy_and_collector", "wire"}) {
    share[k] = phases[k].get<double>() / phases["total"].get<double>();
  }
  const Json out{{"config", a.config},
                 {"model", a.model},
                 {"control_steps", t.steps},
                 {"resets", t.resets},
                 {"us_per_step", phases},
                 {"share", share},
                 {"zones", zone_json},
                 {"cpu_us_per_step", 1e6 * t.cpu_s / t.steps},
                 {"cpu_us_per_step_unprofiled", 1e6 * plain.cpu_s / plain.steps},
                 {"profiling_overhead", t.cpu_s / plain.cpu_s},
                 {"timing",
                  "phases: wall clock of one thread (shares are meaningful on a busy "
                  "machine, absolute times less so); Bullet phases are the zones' own "
                  "time (nested zones excluded); env_own = env Reset/Step minus Bullet; "
                  "policy_and_collector = RolloutCollector minus the env; wire = "
                  "RolloutSegment conversion and serialisation. cpu_us_per_step: thread "
                  "CPU time, with and without the zone hooks (same episodes)"}};
  std::cout << (a.json ? out.dump() : out.dump(2)) << "\n";
}

}  // namespace

void RegisterProfileCommands(CLI::App& root, CLI::App& bench) {
  auto args = std::make_shared<ProfileArgs>();
  CLI::App* p = bench.add_subcommand(
      "profile",
      "Per-phase cost of an actor's control step (solver, dynamics, collision, env, "
      "policy, wire)");
  p->add_option("--config", args->config, "experiment config (default: configs/default.json)");
  p->add_option("--model", args->model, "policy (checkpoint or ModelWeights; default: fresh)");
  p->add_option("--steps", args->steps, "control steps");
  p->add_option("--seed", args->seed, "env and action seed");
  p->add_flag("--json", args->json, "print one JSON object");
  p->callback([args] { RunProfile(*args); });
}

}  // namespace perch
