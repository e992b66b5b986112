#include "tasks/recording.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "common/file_util.h"
#include "common/json_util.h"

namespace perch {
namespace {

constexpr char kMagic[8] = {'P', 'E', 'R', 'C', 'H', 'R', 'E', 'C'};
template <typename Field>
void Put3(Field* f, const Eigen::Vector3d& v) {
  for (int i = 0; i < 3; ++i) f->Add(static_cast<float>(v[i]));
}
template <typename Field>
void PutQuat(Field* f, const Eigen::Quaterniond& q) {
  f->Add(static_cast<float>(q.w()));
  f->Add(static_cast<float>(q.x()));
  f->Add(static_cast<float>(q.y()));
  f->Add(static_cast<float>(q.z()));
}

void FillHeader(const HumanoidChairEnv& env, proto::Recording* rec) {
  rec->set_format_version(kRecordingFormat);
  rec->set_control_dt(static_cast<float>(env.spec().control_dt));
  const HumanoidModel& m = env.model();
  for (const Body& b : m.bodies()) {
    proto::RecBody* rb = rec->add_bodies();
    rb->set_name(b.name);
    rb->set_parent(b.parent);
    for (const Geom& g : b.geoms) {
      proto::RecGeom* rg = rb->add_geoms();
      rg->set_type(g.type == Geom::Type::kCapsule ? "capsule" : "sphere");
      Put3(rg->mutable_from(), g.from);
      Put3(rg->mutable_to(), g.to);
      rg->set_radius(static_cast<float>(g.radius));
    }
  }
  for (const Joint& j : m.joints()) rec->add_joint_names(j.name);
}

void FillChair(const Chair& c, proto::RecChair* rc) {
  rc->set_name(c.name);
  for (const ChairBox& b : c.boxes) {
    proto::RecChairBox* rb = rc->add_boxes();
    rb->set_role(b.role);
    Put3(rb->mutable_min(), b.min);
    Put3(rb->mutable_max(), b.max);
  }
  Put3(rc->mutable_seat_target(), c.seat_target);
  if (c.mesh) {
    for (const Eigen::Vector3d& v : c.mesh->visual.vertices) Put3(rc->mutable_mesh_vertices(), v);
    for (const auto& t : c.mesh->visual.triangles) {
      for (int i : t) rc->add_mesh_triangles(static_cast<uint32_t>(i));
    }
    rc->set_source(c.source);
  }
}

}  // namespace

void EpisodeRecorder::Begin(const HumanoidChairEnv& env, int index, uint64_t env_seed,
                            const RecordingExtras& extras) {
  active_ = max_episodes_ <= 0 || begun_ < max_episodes_;
  ++begun_;
  if (!active_) return;
  if (rec_.bodies_size() == 0) FillHeader(env, &rec_);
  proto::RecEpisode* ep = rec_.add_episodes();
  ep->set_index(index);
  ep->set_seed(env_seed);
  if (env.chair() != nullptr) FillChair(*env.chair(), ep->mutable_chair());
  AddFrame(env, 0.0f, extras);
}

void EpisodeRecorder::Step(const HumanoidChairEnv& env, const StepResult& r,
                           const RecordingExtras& extras) {
  if (!active_) return;
  AddFrame(env, r.reward, extras);
}

void EpisodeRecorder::End(bool success, bool fell) {
  if (!active_) return;
  proto::RecEpisode* ep = rec_.mutable_episodes(rec_.episodes_size() - 1);
  ep->set_success(success);
  ep->set_fell(fell);
  ep->set_outcome(success ? "success" : fell ? "fell" : "time_limit");
  active_ = false;
}

void EpisodeRecorder::AddFrame(const HumanoidChairEnv& env, float reward,
                               const RecordingExtras& extras) {
  proto::RecFrame* f = rec_.mutable_episodes(rec_.episodes_size() - 1)->add_frames();
  const int step = env.episode_step();
  f->set_step(step);
  f->set_time_s(static_cast<float>(step * env.spec().control_dt));
  const int nb = static_cast<int>(env.model().bodies().size());
  for (int b = 0; b < nb; ++b) {
    const Eigen::Isometry3d T = env.world().BodyPose(b);
    Put3(f->mutable_body_pos(), T.translation());
    PutQuat(f->mutable_body_quat(), Eigen::Quaterniond(T.rotation()));
  }
  for (double q : env.humanoid_state().q) f->add_q(static_cast<float>(q));
  if (env.world().has_chair()) {
    const ChairState c = env.world().GetState().chair;
    Put3(f->mutable_chair_pos(), c.pos);
    PutQuat(f->mutable_chair_quat(), c.quat);
  }
  if (env.config().task != "stand") {
    f->add_walk_target(static_cast<float>(env.walk_target().x()));
    f->add_walk_target(static_cast<float>(env.walk_target().y()));
  }
  f->set_active_subtask(extras.active_subtask);
  f->set_meta_step(extras.meta_step);
  if (extras.has_meta_target) {
    f->add_meta_target(static_cast<float>(extras.meta_target.x()));
    f->add_meta_target(static_cast<float>(extras.meta_target.y()));
  }
  f->set_foot_contact_right(env.contacts().foot_floor[0]);
  f->set_foot_contact_left(env.contacts().foot_floor[1]);
  f->set_pelvis_seat_contact(env.chair() != nullptr && env.PelvisSeatContact());
  f->set_reward(reward);
  if (step > 0) {
    const Json terms = env.task().LastRewardTerms();
    for (auto it = terms.begin(); it != terms.end(); ++it) {
      if (it.value().is_number()) {
        (*f->mutable_reward_terms())[it.key()] = it.value().get<float>();
      }
    }
  }
}

void WriteRecording(const std::string& path, const proto::Recording& rec, bool overwrite) {
  if (!overwrite && std::filesystem::exists(path)) {
    throw ConfigError(path + ": exists; not overwritten (pass --force to replace it)");
  }
  const std::string out = FramePayload(kMagic, kRecordingFormat, rec.SerializeAsString());
  WriteFileAtomic(path, out);
}

proto::Recording ReadRecording(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot open recording");
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  const std::string payload = UnframePayload(bytes, path, kMagic, kRecordingFormat, "recording");
  proto::Recording rec;
  if (!rec.ParseFromString(payload)) throw ConfigError(path + ": recording payload does not parse");
  if (rec.format_version() != kRecordingFormat) {
    throw ConfigError(path + ": recording message version " + std::to_string(rec.format_version()) +
                      " (expected " + std::to_string(kRecordingFormat) + ")");
  }
  const int nb = rec.bodies_size();
  for (const proto::RecEpisode& ep : rec.episodes()) {
    for (const proto::RecFrame& f : ep.frames()) {
      if (f.body_pos_size() != 3 * nb || f.body_quat_size() != 4 * nb ||
          f.q_size() != rec.joint_names_size()) {
        throw ConfigError(path + ": episode " + std::to_string(ep.index()) + " frame " +
                          std::to_string(f.step()) + ": array sizes do not match the header");
      }
    }
  }
  return rec;
}

ReferenceMotion RecordedMotion(const proto::Recording& rec, int episode, const HumanoidModel& model,
                               const std::string& ctx) {
  const proto::RecEpisode* ep = nullptr;
  for (const proto::RecEpisode& e : rec.episodes()) {
    if (e.index() == episode) ep = &e;
  }
  if (ep == nullptr) {
    std::string have;
    for (const proto::RecEpisode& e : rec.episodes()) {
      have += (have.empty() ? "" : ", ") + std::to_string(e.index());
    }
    throw ConfigError(ctx + ": no episode " + std::to_string(episode) + " (recorded: " + have +
                      ")");
  }
  if (rec.joint_names_size() != model.num_joints() || rec.bodies_size() != model.num_bodies()) {
    throw ConfigError(ctx + ": recorded humanoid has " + std::to_string(rec.bodies_size()) +
                      " bodies / " + std::to_string(rec.joint_names_size()) +
                      " joints, the model " + std::to_string(model.num_bodies()) + " / " +
                      std::to_string(model.num_joints()));
  }
  for (int j = 0; j < model.num_joints(); ++j) {
    if (rec.joint_names(j) != model.joint(j).name) {
      throw ConfigError(ctx + ": joint " + std::to_string(j) + " is \"" + rec.joint_names(j) +
                        "\", the model's \"" + model.joint(j).name + "\"");
    }
  }
  const int root = model.root_body();
  std::vector<MotionPose> frames;
  for (const proto::RecFrame& f : ep->frames()) {
    MotionPose p;
    p.root_pos =
        Eigen::Vector3d(f.body_pos(3 * root), f.body_pos(3 * root + 1), f.body_pos(3 * root + 2));
    p.root_rot = Eigen::Quaterniond(f.body_quat(4 * root), f.body_quat(4 * root + 1),
                                    f.body_quat(4 * root + 2), f.body_quat(4 * root + 3))
                     .normalized();
    p.q.resize(f.q_size());
    for (int j = 0; j < f.q_size(); ++j) p.q[j] = f.q(j);
    frames.push_back(p);
  }
  if (frames.size() < 2) throw ConfigError(ctx + ": episode has fewer than 2 frames");
  return ReferenceMotion("episode" + std::to_string(episode), rec.control_dt(), frames, false);
}

}  // namespace perch
