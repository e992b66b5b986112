#include "actor/role_setup.h"

namespace perch {

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
