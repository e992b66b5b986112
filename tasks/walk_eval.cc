#include "tasks/walk_eval.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <sstream>

#include "common/proto/wire.pb.h"
#include "common/rng.h"
#include "tasks/foot_sliding.h"

namespace perch {
namespace {}  // namespace

Json EvaluateWalk(const TaskEnvConfig& config_in, const proto::ModelWeights& weights,
                  const WalkEvalOptions& o, WalkEvalRecording* rec) {
  if (config_in.env.task != "walk")
    throw ConfigError("eval: config task is \"" + config_in.env.task + "\", not walk");
  if (o.episodes < 1) throw ConfigError("eval: --episodes must be >= 1");
  TaskEnvConfig config = config_in;
  const double dt = config.env.physics.physics_dt * config.env.physics.substeps;
  const int no_fall_steps = static_cast<int>(std::ceil(o.no_fall_s / dt - 1e-9));
  config.walk.max_episode_steps = std::max(config.walk.max_episode_steps, no_fall_steps);

  std::unique_ptr<HumanoidChairEnv> env = MakeTaskHumanoidEnv(config);
  const auto& task = dynamic_cast<const WalkTask&>(env->task());
  const EnvSpec& spec = env->spec();
  const PolicyConfig pc = PolicyConfigFromShape(weights.shape(), "model");
  if (pc.kind != PolicyKind::kGaussian || pc.obs_dim != spec.obs_dim ||
      pc.act_dim != spec.act_dim) {
    throw ConfigError("model: shape " + weights.shape().kind() + " obs " +
                      std::to_string(pc.obs_dim) + " act " + std::to_string(pc.act_dim) +
                      " does not fit the walk env (gaussian obs " + std::to_string(spec.obs_dim) +
                      " act " + std::to_string(spec.act_dim) + ")");
  }
  PolicyRunner runner(pc, NormalizerConfig());
  runner.LoadWeights(weights);
  runner.set_update_obs_stats(false);  // evaluation must not move the normaliser

  FootSlidingMeter sliding_meter(env->model(), o.foot_sliding);
  auto body_pose = [&](int b) { return env->world().BodyPose(b); };

  const bool target_mode = config.walk.stage == WalkStage::kTarget;
  std::vector<float> obs(spec.obs_dim), next(spec.obs_dim), action(spec.act_dim);
  int no_fall = 0, falls = 0, invalid = 0;
  int64_t steps_total = 0;
  double sum_return = 0, sum_sim = 0, sum_heading = 0, sum_forward = 0;
  // Where falls happen, to tell a balance problem from a steering one: the episode time, the time
  // since the current target was drawn and the heading error to it at the falling step.
  Json fall_times = Json::array(), fall_since_target = Json::array(), fall_heading = Json::array();
  // Which episodes fell and the reference phase they started from (a bad start phase shows up as
  // falls at similar times from similar phases; episode e can be rerun from (seed, e)).
  Json fall_episodes = Json::array(), fall_start_phase = Json::array();
  // Reached / resolved targets by their distance when drawn, bins of 1 m from 0 m: a target farther
  // than the walking speed times the re-draw time cannot be reached at all (docs/walk.md).
  constexpr int kDistBins = 6;
  std::array<int, kDistBins> bin_reached{}, bin_resolved{};
  auto target_bin = [&] {
    return std::clamp(static_cast<int>(task.target_drawn_distance_m()), 0, kDistBins - 1);
  };
  for (int e = 0; e < o.episodes; ++e) {
    // Episode e depends only on (seed, e): any subset of episodes can be rerun alone.
    // (Rng::Seed scrambles its seed, so nearby integers give unrelated streams.)
    const uint64_t episode_seed = o.seed * 1000003ULL + static_cast<uint64_t>(e);
    env->Seed(2 * episode_seed);
    Rng act_rng(2 * episode_seed + 1);
    env->Reset(obs.data());
    const double x0 = env->humanoid_state().root_pos.x();
    int open_bin = target_bin();
    sliding_meter.Start(body_pose);
    if (o.recorder != nullptr) o.recorder->Begin(*env, e, 2 * episode_seed);
    auto record = [&](int step) {
      if (e != 0 || rec == nullptr) return;
      rec->frames.push_back(PoseFrameOf(env->humanoid_state(), step * dt));
      if (target_mode &&
          (rec->targets.empty() || (rec->targets.back() - env->walk_target()).norm() > 1e-9)) {
        rec->targets.push_back(env->walk_target());
      }
    };
    record(0);
    int steps = 0, target_drawn_step = 0;
    double heading_err_deg = 0.0;
    bool fell = false;
    for (;;) {
      runner.Act(obs.data(), act_rng, !o.stochastic, nullptr, action.data());
      const StepResult r = env->Step(action.data(), next.data());
      ++steps;
      sum_return += r.reward;
      if (r.invalid) ++invalid;
      if (!r.invalid) {
        const WalkTerms& t = task.last_terms();
        sum_sim += t.similarity;
        // A re-draw resolves the open target: reached, or its 2.5 s ran out.
        if (t.target_redrawn) {
          ++bin_resolved[open_bin];
          if (t.target_reached) ++bin_reached[open_bin];
          open_bin = target_bin();
          target_drawn_step = steps;
        }
        if (target_mode) {
          const Eigen::Vector2d to = env->walk_target() - env->BodyXyz().head<2>();
          const double err = AngleDiff(std::atan2(to.y(), to.x()), env->RootRpy().z());
          heading_err_deg = std::abs(err) * 180.0 / M_PI;
          sum_heading += heading_err_deg;
        }
        sliding_meter.Observe(body_pose, dt);
      }
      if (o.recorder != nullptr) o.recorder->Step(*env, r);
      record(steps);
      obs.swap(next);
      if (r.terminated) {
        fell = true;
        break;
      }
      if (r.truncated) break;
    }
    if (fell) {
      ++falls;
      fall_times.push_back(steps * dt);
      fall_episodes.push_back(e);
      fall_start_phase.push_back(task.start_time());
      if (target_mode) {
        fall_since_target.push_back((steps - target_drawn_step) * dt);
        fall_heading.push_back(heading_err_deg);
      }
    }
    if (!fell || steps >= no_fall_steps) ++no_fall;
    if (o.recorder != nullptr) o.recorder->End(!fell || steps >= no_fall_steps, fell);
    steps_total += steps;
    sum_forward += (env->humanoid_state().root_pos.x() - x0) / (steps * dt);
  }
  const double n = o.episodes;
  const double secs = steps_total * dt;
  Json j{{"task", "walk"},
         {"stage", target_mode ? "target" : "forward"},
         {"reward_variant", config.walk.reward_variant},
         {"model_version", weights.version()},
         {"episodes", o.episodes},
         {"seed", o.seed},
         {"stochastic", o.stochastic},
         {"max_episode_steps", config.walk.max_episode_steps},
         {"no_fall_seconds", o.no_fall_s},
         {"no_fall_rate", no_fall / n},
         {"fall_rate", falls / n},
         {"invalid_episodes", invalid},
         {"mean_episode_steps", steps_total / n},
         {"mean_return", sum_return / n},
         {"mean_reward", sum_return / static_cast<double>(steps_total)},
         {"mean_imitation_reward", sum_sim / static_cast<double>(steps_total)},
         {"mean_forward_speed_mps", sum_forward / n},
         {"foot_sliding", sliding_meter.ToJson(secs)},
         {"fall_times_s", fall_times},
         {"fall_episodes", fall_episodes},
         {"fall_start_phase_s", fall_start_phase}};
  // The same meter on the imitated clip over the mean episode length: sliding a clean reference
  // walk itself scores (the swing foot counts while it is low).
  const double ref_s = std::max(dt, secs / n);
  const FootSlidingMeter ref =
      ReferenceFootSliding(env->model(), task.motion(), ref_s, dt, o.foot_sliding);
  j["foot_sliding"]["reference"] = ref.ToJson(ref_s);
  if (target_mode) {
    const int targets = std::accumulate(bin_reached.begin(), bin_reached.end(), 0);
    const int targets_missed =
        std::accumulate(bin_resolved.begin(), bin_resolved.end(), 0) - targets;
    j["targets_reached"] = targets;
    j["targets_reached_per_min"] = targets / (secs / 60.0);
    // Of the targets that were reached or ran out of time (not the one open at episode end).
    j["targets_missed"] = targets_missed;
    j["target_reach_fraction"] =
        targets + targets_missed ? static_cast<double>(targets) / (targets + targets_missed) : 0.0;
    j["mean_heading_error_deg"] = sum_heading / static_cast<double>(steps_total);
    j["fall_seconds_since_target"] = fall_since_target;
    Json by_dist = Json::array();
    for (int b = 0; b < kDistBins; ++b) {
      if (bin_resolved[b] == 0) continue;
      by_dist.push_back(
          {{"from_m", b},
           {"to_m", b + 1 < kDistBins ? Json(b + 1) : Json(nullptr)},
           {"resolved", bin_resolved[b]},
           {"reached", bin_reached[b]},
           {"reach_fraction", static_cast<double>(bin_reached[b]) / bin_resolved[b]}});
    }
    j["target_reach_by_distance"] = by_dist;
    j["fall_heading_error_deg"] = fall_heading;
  }
  return j;
}

}  // namespace perch
