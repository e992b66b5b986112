// tasks/track_clip.h: a clip played with PD tracking only, the library behind `perch motion track`.
#include "tasks/track_clip.h"

#include <gtest/gtest.h>

namespace perch {
namespace {

TEST(TrackClip, TheWalkClipIsFollowedCloselyAndTheFallHeightFollowsTheClip) {
  TrackClipOptions o;
  o.name = "walk";
  o.seconds = 0.5;
  const Json w = TrackClip(o);
  const double dt = w["control_dt_s"].get<double>();
  EXPECT_EQ(w["fall_z_m"].get<double>(), o.walk_fall_z);
  ASSERT_FALSE(w["fell"].get<bool>()) << w.dump();
  EXPECT_NEAR(w["seconds_up"].get<double>(), 0.5, dt);
  // PD tracking of the clip's own first half second: joints within a few degrees, root within
  // centimetres (a broken placement or a wrong clip is off by far more).
  EXPECT_LT(w["mean_joint_rms_err_rad"].get<double>(), 0.2);
  EXPECT_LT(w["mean_root_pos_err_m"].get<double>(), 0.1);
  o.name = "sit";
  o.seconds = 0.25;
  const Json s = TrackClip(o);
  EXPECT_EQ(s["fall_z_m"].get<double>(), o.sit_fall_z);
  EXPECT_TRUE(s.contains("pelvis_seat_contact_at_end"));
  o.name = "no_such_clip";
  EXPECT_THROW(TrackClip(o), ConfigError);
}

}  // namespace
}  // namespace perch
