#include "tasks/state_bank.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "learner/ppo.h"
#include "tasks/turn.h"
#include "tasks/walk.h"
#include "tests/support/untrained.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

proto::StateBank SmallWalkBank(int workers, uint64_t seed = 3) {
  SampleEndPosesOptions o;
  o.steps = 6;
  o.survive = 4;
  o.count = 5;
  o.seed = seed;
  o.workers = workers;
  return SampleEndPoses(TaskEnvConfig::Defaults("walk"), Untrained(52, 1), o);
}

std::string Temp(const std::string& name) {
  const std::string p = ::testing::TempDir() + "/" + name;
  fs::remove(p);
  return p;
}

std::string ErrorOf(const std::string& path, const HumanoidModel* model) {
  try {
    ReadStateBank(path, model);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(StateBank, SamplingIsDeterministicWhateverTheWorkers) {
  const proto::StateBank a = SmallWalkBank(1), b = SmallWalkBank(3);
  ASSERT_EQ(a.states_size(), 5);
  EXPECT_EQ(a.SerializeAsString(), b.SerializeAsString());
  EXPECT_NE(SmallWalkBank(1, 4).SerializeAsString(), a.SerializeAsString());
  EXPECT_EQ(a.steps(), 6);
  EXPECT_GE(a.episodes_run(), 5);
  for (const proto::BankState& s : a.states()) EXPECT_EQ(s.step(), 6);  // after exactly N steps
}

TEST(StateBank, FileRoundTripAndEveryDamageRefusedWithTheReason) {
  const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
  const proto::StateBank bank = SmallWalkBank(2);
  const std::string path = Temp("bank.bin");
  WriteStateBank(path, bank, false);
  EXPECT_EQ(ReadStateBank(path, &model).SerializeAsString(), bank.SerializeAsString());
  // Never overwritten by accident.
  EXPECT_THROW(WriteStateBank(path, bank, false), ConfigError);
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string bytes = ss.str();
  auto write = [&](const std::string& name, const std::string& b) {
    const std::string p = Temp(name);
    std::ofstream(p, std::ios::binary) << b;
    return p;
  };
  std::string e = ErrorOf(write("trunc.bin", bytes.substr(0, bytes.size() - 10)), &model);
  EXPECT_NE(e.find("truncated"), std::string::npos) << e;
  EXPECT_NE(e.find("trunc.bin"), std::string::npos) << e;
  std::string flipped = bytes;
  flipped[flipped.size() / 2] ^= 0x5a;
  e = ErrorOf(write("flip.bin", flipped), &model);
  EXPECT_NE(e.find("CRC"), std::string::npos) << e;
  std::string v2 = bytes;
  v2[8] = 2;  // format version field
  e = ErrorOf(write("v2.bin", v2), &model);
  EXPECT_NE(e.find("format 2"), std::string::npos) << e;
  e = ErrorOf(write("junk.bin", "hello"), &model);
  EXPECT_NE(e.find("not a state bank"), std::string::npos) << e;
  // Another joint layout (a model whose joints are named otherwise).
  proto::StateBank other = bank;
  other.set_joint_names(0, "tail");
  const std::string op = Temp("other.bin");
  WriteStateBank(op, other, false);
  e = ErrorOf(op, &model);
  EXPECT_NE(e.find("joint layout"), std::string::npos) << e;
  EXPECT_EQ(ErrorOf(op, nullptr), "");  // without a model to compare, the layout is not judged
}

// A captured state continues the episode exactly: same observations and rewards as the original.
TEST(StateBank, CapturedStateAndTaskMemoryContinueTheEpisodeExactly) {
  TaskEnvConfig c = TaskEnvConfig::Defaults("walk");
  c.walk.stage = WalkStage::kTarget;
  auto a = MakeTaskHumanoidEnv(c), b = MakeTaskHumanoidEnv(c);
  std::vector<float> obs(52), oa(52), ob(52), act(21);
  Rng rng(9);
  a->Seed(4);
  a->Reset(obs.data());
  for (int k = 0; k < 20; ++k) {
    for (float& x : act) x = static_cast<float>(rng.Normal() * 0.3);
    a->Step(act.data(), oa.data());
  }
  const proto::BankState s = CaptureState(*a);
  // Both continue from a rebuilt world (Bullet's contact caches are not part of any state): the
  // original through its own capture, the other after another episode.
  a->SetState(EnvStateOf(s));
  b->Seed(77);
  b->Reset(obs.data());  // another episode, then restored
  b->SetState(EnvStateOf(s));
  const_cast<Task&>(b->task()).LoadMemory(Json::parse(s.task_memory_json()));
  for (int k = 0; k < 15; ++k) {
    for (float& x : act) x = static_cast<float>(rng.Normal() * 0.3);
    const StepResult ra = a->Step(act.data(), oa.data());
    const StepResult rb = b->Step(act.data(), ob.data());
    ASSERT_EQ(ra.reward, rb.reward) << k;
    for (int i = 0; i < 52; ++i) ASSERT_EQ(oa[i], ob[i]) << k << " " << i;
  }
}

TEST(StateBank, TurnFromWalkStartsFromABankPoseTurnedToTheClipsHeading) {
  const proto::StateBank bank = SmallWalkBank(2);
  const std::string path = Temp("walk_bank.bin");
  WriteStateBank(path, bank, false);
  auto env = MakeTaskHumanoidEnv(TaskEnvConfig::FromJson(
      {{"task", "turn_left"}, {"chair", "none"}, {"turn_left", {{"start", {{"banks", {path}}}}}}},
      "t"));
  const auto& task = dynamic_cast<const TurnTask&>(env->task());
  std::vector<float> obs(50);
  for (int seed = 0; seed < 4; ++seed) {
    env->Seed(seed);
    env->Reset(obs.data());
    EXPECT_TRUE(task.started_from_bank());
    const HumanoidState& h = env->humanoid_state();
    // Joints of one of the bank's states; root over the origin; heading = the placed clip's.
    bool found = false;
    for (const proto::BankState& s : bank.states()) {
      bool same = true;
      for (int j = 0; j < 21; ++j) same = same && std::abs(s.q(j) - h.q[j]) < 1e-6;
      found = found || same;
    }
    EXPECT_TRUE(found);
    EXPECT_NEAR(h.root_pos.head<2>().norm(), 0.0, 1e-6);
    const double ref_yaw = RpyFromQuat(task.ReferenceAt(0).root_rot).z();
    EXPECT_NEAR(AngleDiff(env->RootRpy().z(), ref_yaw), 0.0, 1e-6);
  }
  // A bank that is not there is refused when the config is read, naming the field.
  try {
    TaskEnvConfig::FromJson(
        {{"task", "turn_left"}, {"turn_left", {{"start", {{"banks", {"/nonexistent.bin"}}}}}}},
        "f.json");
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("f.json.turn_left.start.banks"), std::string::npos)
        << e.what();
  }
}

TEST(StateBank, SitBankStartsMoveByTheExtraOffsetAndCanDropTheSpin) {
  const proto::StateBank bank = SmallWalkBank(2);
  const std::string path = Temp("walk_bank_sit.bin");
  WriteStateBank(path, bank, false);
  auto make = [&](const Json& extra) {
    Json sit{{"start", {{"banks", {path}}, {"prob", 1.0}}}};
    for (auto it = extra.begin(); it != extra.end(); ++it) sit[it.key()] = it.value();
    if (extra.contains("zero_root_ang_vel")) {
      sit.erase("zero_root_ang_vel");
      sit["start"]["zero_root_ang_vel"] = true;
    }
    return MakeTaskHumanoidEnv(
        TaskEnvConfig::FromJson({{"task", "sit"}, {"chair", "authors"}, {"sit", sit}}, "t"));
  };
  auto plain = make(Json::object());
  auto moved = make({{"start_extra_along_m", {0.3, 0.3}}, {"start_extra_across_m", 0.0}});
  auto turned = make({{"start_extra_yaw_deg", 30.0}});
  auto still = make({{"zero_root_ang_vel", true}});
  std::vector<float> obs(57);
  double max_turn = 0.0;
  for (int seed = 0; seed < 6; ++seed) {
    for (auto* e : {plain.get(), moved.get(), turned.get(), still.get()}) {
      e->Seed(seed);
      e->Reset(obs.data());
    }
    const HumanoidState &p = plain->humanoid_state(), &m = moved->humanoid_state();
    // The authors' chair faces +x: 0.3 m further from the seat, nothing across (Bullet keeps
    // the pose in single precision).
    EXPECT_NEAR(m.root_pos.x() - p.root_pos.x(), 0.3, 1e-5) << seed;
    EXPECT_NEAR(m.root_pos.y() - p.root_pos.y(), 0.0, 1e-5) << seed;
    EXPECT_NEAR(AngleDiff(moved->RootRpy().z(), plain->RootRpy().z()), 0.0, 1e-5) << seed;
    const double turn = std::abs(AngleDiff(turned->RootRpy().z(), plain->RootRpy().z()));
    EXPECT_LE(turn, 30.0 * M_PI / 180.0 + 1e-5) << seed;
    max_turn = std::max(max_turn, turn);
    EXPECT_NEAR((turned->humanoid_state().root_pos - p.root_pos).head<2>().norm(), 0.0, 1e-5);
    EXPECT_EQ(still->humanoid_state().root_ang_vel.norm(), 0.0) << seed;
    EXPECT_GT(p.root_ang_vel.norm(), 0.0) << seed;  // walk end poses spin
  }
  EXPECT_GT(max_turn, 2.0 * M_PI / 180.0);
  EXPECT_THROW(make({{"start_extra_along_m", {0.5, 0.1}}}), ConfigError);
  EXPECT_THROW(make({{"start_extra_yaw_deg", -1.0}}), ConfigError);
}

TEST(StateBank, KeepPoseRestoresAStateWhereItWasRelativeToItsChair) {
  // A state captured beside a chair placed elsewhere and turned (as the chain's are)...
  auto src = MakeTaskHumanoidEnv(
      TaskEnvConfig::FromJson({{"task", "sit"},
                               {"chair", "authors"},
                               {"chair_placement", {{"x", 0.7}, {"y", -0.4}, {"yaw_deg", 40.0}}}},
                              "t"));
  std::vector<float> obs(57), next(57), act(21, 0.0f);
  src->Seed(3);
  src->Reset(obs.data());
  for (int k = 0; k < 5; ++k) src->Step(act.data(), next.data());
  proto::StateBank bank = SmallWalkBank(1);
  bank.clear_states();
  *bank.add_states() = CaptureState(*src);
  ASSERT_TRUE(bank.states(0).has_chair());
  const std::string path = Temp("chain_like_bank.bin");
  WriteStateBank(path, bank, false);
  // ...starts a sit episode at the same place relative to this env's chair.
  auto dst = MakeTaskHumanoidEnv(TaskEnvConfig::FromJson(
      {{"task", "sit"},
       {"chair", "authors"},
       {"sit", {{"start", {{"banks", {path}}, {"prob", 1.0}, {"keep_pose", true}}}}}},
      "t"));
  dst->Seed(1);
  dst->Reset(obs.data());
  auto relative = [](const HumanoidChairEnv& e) {
    const proto::BankState st = CaptureState(e);
    const Eigen::Vector3d c(st.chair_pos().x(), st.chair_pos().y(), 0.0);
    const double cy = RpyFromQuat(Eigen::Quaterniond(st.chair_quat().w(), st.chair_quat().x(),
                                                     st.chair_quat().y(), st.chair_quat().z()))
                          .z();
    const Eigen::Vector3d d =
        Eigen::AngleAxisd(-cy, Eigen::Vector3d::UnitZ()) * (e.humanoid_state().root_pos - c);
    return Eigen::Vector3d(d.x(), d.y(), AngleDiff(e.RootRpy().z(), cy));
  };
  const Eigen::Vector3d a = relative(*src), b = relative(*dst);
  EXPECT_NEAR((a - b).norm(), 0.0, 2e-3) << a.transpose() << " vs " << b.transpose();
  EXPECT_GT(a.head<2>().norm(), 0.2);  // not trivially at the chair's origin
  // Bank states without a chair cannot be kept relative to one: refused when the config is read.
  const std::string walk = Temp("walk_bank_keep.bin");
  WriteStateBank(walk, SmallWalkBank(1), false);
  EXPECT_THROW(TaskEnvConfig::FromJson(
                   {{"task", "sit"},
                    {"chair", "authors"},
                    {"sit", {{"start", {{"banks", {walk}}, {"prob", 1.0}, {"keep_pose", true}}}}}},
                   "t"),
               ConfigError);
}

TEST(StateBank, WalkFromHandBacksStartsFromABankStateWithItsOwnHeadingAndTheNearestPhase) {
  // Hand-backs face anywhere: each state turned by its own angle before it is banked.
  proto::StateBank bank = SmallWalkBank(1);
  std::vector<double> yaws;
  for (int i = 0; i < bank.states_size(); ++i) {
    proto::BankState* st = bank.mutable_states(i);
    const Eigen::Quaterniond q0(st->root_quat().w(), st->root_quat().x(), st->root_quat().y(),
                                st->root_quat().z());
    const Eigen::Quaterniond q =
        Eigen::Quaterniond(Eigen::AngleAxisd(0.9 * (i + 1), Eigen::Vector3d::UnitZ())) * q0;
    st->mutable_root_quat()->set_w(q.w());
    st->mutable_root_quat()->set_x(q.x());
    st->mutable_root_quat()->set_y(q.y());
    st->mutable_root_quat()->set_z(q.z());
    st->mutable_root_pos()->set_x(3.0 + i);  // far from the origin it is moved to
    yaws.push_back(RpyFromQuat(q).z());
  }
  const std::string path = Temp("walk_handbacks.bin");
  WriteStateBank(path, bank, false);
  auto make = [&](double prob) {
    return MakeTaskHumanoidEnv(TaskEnvConfig::FromJson(
        {{"task", "walk"},
         {"chair", "none"},
         {"walk", {{"stage", "target"}, {"start", {{"banks", {path}}, {"prob", prob}}}}}},
        "t"));
  };
  auto env = make(1.0);
  const auto& task = dynamic_cast<const WalkTask&>(env->task());
  std::vector<float> obs(env->spec().obs_dim);
  std::set<int> drawn;
  for (int seed = 0; seed < 8; ++seed) {
    env->Seed(seed);
    env->Reset(obs.data());
    ASSERT_TRUE(task.started_from_bank());
    const HumanoidState& h = env->humanoid_state();
    int which = -1;
    for (int i = 0; i < bank.states_size(); ++i) {
      bool same = true;
      for (int j = 0; j < 21; ++j) same = same && std::abs(bank.states(i).q(j) - h.q[j]) < 1e-6;
      if (same) which = i;
    }
    ASSERT_GE(which, 0) << seed;
    drawn.insert(which);
    // Its own heading, its root over the origin, its height as banked.
    EXPECT_NEAR(AngleDiff(env->RootRpy().z(), yaws[which]), 0.0, 1e-5) << seed;
    EXPECT_NEAR(h.root_pos.head<2>().norm(), 0.0, 1e-6) << seed;
    EXPECT_NEAR(h.root_pos.z(), bank.states(which).root_pos().z(), 1e-5) << seed;
    // The reference goes on from the clip's nearest pose, under the root.
    const MotionPose ref = task.ReferenceAt(0);
    auto dist = [&](const MotionPose& p) {
      double d = 0.0;
      for (int j = 0; j < 21; ++j) d += (p.q[j] - h.q[j]) * (p.q[j] - h.q[j]);
      return d;
    };
    for (double t = 0.0; t < task.motion().duration(); t += 0.05) {
      EXPECT_LE(dist(ref), dist(task.motion().At(t)) + 1e-3) << seed << " t " << t;
    }
    EXPECT_NEAR((ref.root_pos - h.root_pos).head<2>().norm(), 0.0, 1e-6) << seed;
  }
  EXPECT_GE(drawn.size(), 3u);
  // prob 0: the clip's first frame, as without a bank.
  auto never = make(0.0);
  const auto& plain = dynamic_cast<const WalkTask&>(never->task());
  never->Seed(1);
  never->Reset(obs.data());
  EXPECT_FALSE(plain.started_from_bank());
  EXPECT_EQ(plain.start_time(), 0.0);
  // The walk has no chair frame to keep a pose in, and a missing bank names the field.
  EXPECT_THROW(
      TaskEnvConfig::FromJson(
          {{"task", "walk"}, {"walk", {{"start", {{"banks", {path}}, {"keep_pose", true}}}}}}, "t"),
      ConfigError);
  try {
    TaskEnvConfig::FromJson(
        {{"task", "walk"}, {"walk", {{"start", {{"banks", {"/nonexistent.bin"}}}}}}}, "f.json");
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("f.json.walk.start.banks"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace perch
