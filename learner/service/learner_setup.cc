#include "learner/service/learner_setup.h"

#include "protocol/wire.h"

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

}  // namespace perch
