// Episode recordings (perch eval --record; docs/recording.md): every body's world pose, the
// chair, targets, the active subtask, contact flags and reward terms per control step, read from
// the env after each step (recording never changes an episode), in a framed, versioned file
// ("PERCHREC" + format + length + CRC-32 + perch.proto.Recording).
#pragma once

#include <cstdint>
#include <string>

#include "common/proto/recording.pb.h"
#include "envs/humanoid_env.h"
#include "motion/reference_motion.h"

namespace perch {

constexpr uint32_t kRecordingFormat = 1;

// "perch <git commit at configure time>" (recordings' perch_version).
const char* PerchVersion();

// Hierarchy fields of one frame (the chain and the meta controller); defaults: none.
struct RecordingExtras {
  int active_subtask = -1;
  int meta_step = -1;
  bool has_meta_target = false;
  Eigen::Vector2d meta_target = Eigen::Vector2d::Zero();
};

// Collects episodes into a proto::Recording. The first `max_episodes` episodes passed to Begin
// are kept (<= 0: all); calls for later episodes are ignored, so evaluation loops call it always.
class EpisodeRecorder {
 public:
  explicit EpisodeRecorder(int max_episodes = 0) : max_episodes_(max_episodes) {}
  // After the episode's Reset: the header (bodies, joints, control_dt) on the first call, the
  // episode's chair, and frame 0.
  void Begin(const HumanoidChairEnv& env, int index, uint64_t env_seed,
             const RecordingExtras& extras = {});
  // After each Step.
  void Step(const HumanoidChairEnv& env, const StepResult& r, const RecordingExtras& extras = {});
  // outcome: "success", "fell" or "time_limit".
  void End(bool success, bool fell);

  proto::Recording& recording() { return rec_; }
  const proto::Recording& recording() const { return rec_; }
  bool active() const { return active_; }

 private:
  void AddFrame(const HumanoidChairEnv& env, float reward, const RecordingExtras& extras);
  int max_episodes_;
  int begun_ = 0;
  bool active_ = false;
  proto::Recording rec_;
};

// Atomic write (temporary file + rename); refuses to overwrite unless `overwrite`.
void WriteRecording(const std::string& path, const proto::Recording& rec, bool overwrite);
// Refuses (ConfigError naming the file and the reason) a file without the magic, of another
// format, truncated, with a CRC mismatch, or whose payload does not parse.
proto::Recording ReadRecording(const std::string& path);

// The recorded episode with index `episode` as a humanoid motion (root = the root body's recorded
// pose, joint angles as recorded) at the control rate; ConfigError naming ctx when the episode is
// missing or the recording's humanoid is not `model`'s.
ReferenceMotion RecordedMotion(const proto::Recording& rec, int episode, const HumanoidModel& model,
                               const std::string& ctx);

}  // namespace perch
