#include "actor/role_setup.h"

#include "learner/service/wire.h"

namespace perch {

LearnerSetup MakeLearnerSetup(const ExperimentConfig& cfg) {
  std::unique_ptr<Env> env = MakeExperimentEnv(cfg);
  LearnerSetup s;
  s.seed = cfg.seed;
  s.policy = ResolvePolicyConfig(cfg, env->spec());
  s.ppo = cfg.ppo;
  s.cluster = cfg.cluster;
  s.resolved_config = ToJson(cfg);
  s.control_dt = env->spec().control_dt;
  s.mirror = env->spec().mirror;
  s.compat_key = CompatKey(cfg, s.policy);
  for (const FrozenPolicyData& f : ExperimentFrozenPolicies(cfg)) {
    s.frozen.push_back(FrozenPolicyToProto(f));
  }
  return s;
}

ActorSetup MakeActorSetup(const ExperimentConfig& cfg) {
  std::unique_ptr<Env> env = MakeExperimentEnv(cfg);
  ActorSetup s;
  s.seed = cfg.seed;
  s.policy = ResolvePolicyConfig(cfg, env->spec());
  s.obs_norm = cfg.ppo.obs_norm;
  s.cluster = cfg.cluster;
  s.make_env = [cfg] { return MakeExperimentEnv(cfg); };
  return s;
}

}  // namespace perch
