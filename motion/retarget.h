// Retargeting CMU BVH clips onto the humanoid (issue 3; method in docs/motion.md):
//  1. Key points of the source (pelvis, hips, knees, ankles, toes, shoulders, elbows, wrists,
//     head) are rebuilt with the humanoid's segment lengths ("the scaled source"): limb segments
//     keep the source's direction; the pelvis->hip, ankle->toe and trunk offsets follow the
//     source segment's rotation relative to the cgspeed T-pose, where both skeletons stand alike.
//  2. The key points are resampled to the output frame time (Catmull-Rom in position space).
//  3. Each output frame is solved by damped-least-squares IK (motion/ik.h) for root position,
//     root orientation and the 21 joint angles, warm-started from the previous frame, within the
//     joint limits; the root is lifted where any geom would be below the ground.
//  4. Walk: one gait cycle is cut out and blended into a seamless loop.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

#include "common/json_util.h"
#include "envs/humanoid_model.h"
#include "motion/bvh.h"
#include "motion/ik.h"
#include "motion/reference_motion.h"

namespace perch {

// The CMU acknowledgement every clip file carries (shared/mocap/README.md, Licence).
extern const char* const kCmuAcknowledgement;

struct ClipSpec {
  std::string name;  // output file data/motions/<name>.json
  std::string bvh;   // source file name (matched against the BVH paths given)
  std::string description;
  int first_frame = 1;  // inclusive source frame range (frame 0 is the T-pose in cgspeed)
  int last_frame = -1;  // -1: the last frame
  double source_frame_time_s = 0.0;  // 0: the header's Frame Time
  bool mirror = false;               // left/right mirror of the source skeleton and motion
  bool loop = false;                 // cut one cycle and make it loop (walk)

  Json ToJson() const;
  static ClipSpec FromJson(const Json& j, const std::string& ctx);
};

struct RetargetConfig {
  double frame_time_s = 1.0 / 60.0;   // output frame time (policies run at 60 Hz)
  double bvh_unit_m = 0.0254 / 0.45;  // cgspeed units to metres (mocap README)
  double foot_weight = 4.0;           // IK weight of ankle and toe points (others 1)
  double contact_height_m = 0.05;     // foot counts as on the ground below this clearance
  double loop_min_period_s = 0.8;     // gait-cycle search window
  double loop_max_period_s = 1.6;
  int first_frame_iters = 400;  // IK iterations for the cold-started first frame
  IkOptions ik;
  std::vector<ClipSpec> clips;  // defaults: walk, turn_left, turn_right, sit

  RetargetConfig();
  Json ToJson() const;
  static RetargetConfig FromJson(const Json& j, const std::string& ctx);
};

// Key points in IK order; "right_*" then "left_*" per limb. Besides the key joints, each
// foot has a heel and an outer-toe point so that the foot's roll is determined (flat feet).
constexpr int kNumKeyPoints = 20;
extern const char* const kKeyPointNames[kNumKeyPoints];

// The humanoid as an IK model whose key points correspond to the source's.
class HumanoidKeyPoints : public IkModel {
 public:
  explicit HumanoidKeyPoints(const HumanoidModel& model);
  int num_joints() const override { return model_.num_joints(); }
  int num_points() const override { return kNumKeyPoints; }
  double lower(int j) const override { return model_.joint(j).lower; }
  double upper(int j) const override { return model_.joint(j).upper; }
  void KeyPoints(const IkPose& pose, Eigen::Matrix3Xd* points) const override;
  void FromFk(const FkResult& fk, Eigen::Matrix3Xd* points) const;
  const HumanoidModel& model() const { return model_; }

 private:
  const HumanoidModel& model_;
  struct Def {
    int body = -1;   // a body point (body frame offset) ...
    int joint = -1;  // ... or a joint anchor
    Eigen::Vector3d local = Eigen::Vector3d::Zero();
  };
  std::vector<Def> defs_;
};

// The scaled source: key-point targets per source frame, in the humanoid's world axes (z up,
// x = the source's forward +Z) [m], with the ground at z = 0.
struct SourceTargets {
  double source_frame_time = 0.0;        // [s] per frame below
  std::vector<Eigen::Matrix3Xd> frames;  // [3, kNumKeyPoints] per source frame in the range
  double scale = 1.0;                    // humanoid/source leg length
  double ground_offset_m = 0.0;          // added to z so the feet stand on z = 0
};
SourceTargets ComputeSourceTargets(const BvhClip& bvh, const ClipSpec& spec,
                                   const HumanoidModel& model, const RetargetConfig& cfg);
// Catmull-Rom resampling at times t_i = i * frame_time, i = 0.. while t_i <= source duration.
std::vector<Eigen::Matrix3Xd> ResampleTargets(const SourceTargets& src, double frame_time);

// Left/right mirror of a cgspeed skeleton and motion in the BVH's lateral axis (X): swaps the
// Left*/Right* (and L*/R*) joints' offsets and channels, negates X offsets and positions and the
// Y and Z Euler angles. Throws ConfigError if a joint has no counterpart.
BvhClip MirrorBvh(const BvhClip& clip, const std::string& source);

struct RetargetOutput {
  ReferenceMotion motion;
  std::vector<Eigen::Matrix3Xd> targets;  // per motion frame, in the motion's coordinates
};
// Retargets one clip. `progress(done, total)` is called while solving.
RetargetOutput RetargetClip(const BvhClip& bvh, const std::string& bvh_path, const ClipSpec& spec,
                            const HumanoidModel& model, const RetargetConfig& cfg,
                            const std::function<void(int, int)>& progress = nullptr);

// Re-creates the targets of a committed motion from its source (using the alignment recorded in
// its metadata), for --check.
std::vector<Eigen::Matrix3Xd> TargetsForMotion(const ReferenceMotion& motion, const BvhClip& bvh,
                                               const HumanoidModel& model,
                                               const RetargetConfig& cfg);

// Errors and foot measurements of a motion against its targets: name, mean_err_m, max_err_m,
// per-key-point mean, foot sliding (source and result) and ground penetration.
Json EvaluateMotion(const ReferenceMotion& motion, const std::vector<Eigen::Matrix3Xd>& targets,
                    const HumanoidModel& model, const RetargetConfig& cfg);

}  // namespace perch
