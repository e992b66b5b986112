#include "tasks/episode_loop.h"

#include <vector>

namespace perch {

EpisodeSeeds EvalEpisodeSeeds(uint64_t seed, int episode) {
  // (Rng::Seed scrambles its seed, so nearby integers give unrelated streams.)
  const uint64_t s = seed * 1000003ULL + static_cast<uint64_t>(episode);
  return {2 * s, 2 * s + 1};
}

EpisodeEnd RunEpisode(Env* env, int episode, uint64_t seed, const EpisodeLimits& limits,
                      EpisodeDriver* driver) {
  const EnvSpec& spec = env->spec();
  const EpisodeSeeds seeds = EvalEpisodeSeeds(seed, episode);
  std::vector<float> obs(spec.obs_dim), next(spec.obs_dim), action(spec.act_dim);
  env->Seed(seeds.env);
  Rng act_rng(seeds.actions);
  env->Reset(obs.data());
  driver->Begin(episode, seeds.env, obs.data());
  EpisodeEnd end;
  while (end.steps < limits.max_steps) {
    if (!driver->Act(obs.data(), act_rng, action.data())) break;
    const StepResult r = env->Step(action.data(), next.data());
    ++end.steps;
    driver->Stepped(r, end.steps);
    obs.swap(next);
    if (r.terminated) {
      end.fell = true;
      break;
    }
    if (r.truncated && limits.stop_at_truncation) break;
  }
  return end;
}

}  // namespace perch
