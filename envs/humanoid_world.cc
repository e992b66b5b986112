#include "envs/humanoid_world.h"

#include <BulletDynamics/Featherstone/btMultiBody.h>
#include <BulletDynamics/Featherstone/btMultiBodyConstraintSolver.h>
#include <BulletDynamics/Featherstone/btMultiBodyDynamicsWorld.h>
#include <BulletDynamics/Featherstone/btMultiBodyJointLimitConstraint.h>
#include <BulletDynamics/Featherstone/btMultiBodyLink.h>
#include <BulletDynamics/Featherstone/btMultiBodyLinkCollider.h>
#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <cmath>

#include "envs/pd_controller.h"

namespace perch {
namespace {

// Tags in btCollisionObject::userIndex, to classify contacts.
enum ObjectKind { kFloor = 1, kChair = 2, kHumanoid = 3 };
constexpr double kChairHullMargin = 0.001;  // [m] collision margin of a mesh chair's convex parts

btVector3 Bt(const Eigen::Vector3d& v) { return btVector3(v.x(), v.y(), v.z()); }
Eigen::Vector3d Ei(const btVector3& v) { return Eigen::Vector3d(v.x(), v.y(), v.z()); }
btQuaternion Bt(const Eigen::Quaterniond& q) { return btQuaternion(q.x(), q.y(), q.z(), q.w()); }
Eigen::Quaterniond Ei(const btQuaternion& q) {
  return Eigen::Quaterniond(q.w(), q.x(), q.y(), q.z());
}
btTransform Bt(const Eigen::Isometry3d& t) {
  return btTransform(Bt(Eigen::Quaterniond(t.rotation())), Bt(Eigen::Vector3d(t.translation())));
}
Eigen::Isometry3d Ei(const btTransform& t) {
  Eigen::Isometry3d r = Eigen::Isometry3d::Identity();
  r.translate(Ei(t.getOrigin()));
  r.rotate(Ei(t.getRotation()).normalized());
  return r;
}

// A body's link frame (Bullet's: at the com, along the principal axes) in its body frame.
Eigen::Isometry3d InertialFrame(const Body& b) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(b.com);
  t.rotate(b.principal_rot);
  return t;
}

Eigen::Isometry3d Translation(const Eigen::Vector3d& v) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(v);
  return t;
}

// The plane z = 0 with finite broadphase bounds (PhysicsConfig::floor_half_extent). Bullet gives
// a plane infinite bounds, so every body overlaps it and reaches the narrowphase at every step;
// here only bodies within the slab do. Contacts still come from the plane algorithm.
class FloorShape : public btStaticPlaneShape {
 public:
  explicit FloorShape(double half_extent)
      : btStaticPlaneShape(btVector3(0, 0, 1), 0), half_extent_(half_extent) {}
  // The floor's transform is the identity.
  void getAabb(const btTransform&, btVector3& aabb_min, btVector3& aabb_max) const override {
    aabb_min.setValue(-half_extent_, -half_extent_, -kFloorSlabDepth);
    aabb_max.setValue(half_extent_, half_extent_, 0);
  }

 private:
  btScalar half_extent_;
};

btDefaultCollisionConstructionInfo PoolInfo(int pool_size) {
  btDefaultCollisionConstructionInfo info;
  info.m_defaultMaxPersistentManifoldPoolSize = pool_size;
  info.m_defaultMaxCollisionAlgorithmPoolSize = pool_size;
  return info;
}

}  // namespace

ChairBody ChairBodyFromName(const std::string& name, const std::string& ctx) {
  if (name == "static") return ChairBody::kStatic;
  if (name == "dynamic") return ChairBody::kDynamic;
  if (name == "sleeping") return ChairBody::kSleeping;
  throw ConfigError(ctx + ": expected \"static\", \"dynamic\" or \"sleeping\", got \"" + name +
                    "\"");
}

std::string ChairBodyName(ChairBody body) {
  switch (body) {
    case ChairBody::kStatic:
      return "static";
    case ChairBody::kDynamic:
      return "dynamic";
    case ChairBody::kSleeping:
      return "sleeping";
  }
  return "?";
}

const FieldTable<PhysicsConfig>& PhysicsConfigFields() {
  using C = PhysicsConfig;
  auto at_least_one = Satisfies<int>([](const int& v) { return v >= 1; }, "must be >= 1");
  static const FieldTable<C> t =
      FieldTable<C>()
          .Add("physics_dt", &C::physics_dt, "physics step [s] (240 Hz)",
               Satisfies<double>([](const double& v) { return v > 0.0 && v < 0.1; },
                                 "must be in (0, 0.1) s"))
          .Add("substeps", &C::substeps, "physics steps per control step", at_least_one)
          .Add("gravity", &C::gravity, "[m/s^2], along -z")
          .Add("solver_iterations", &C::solver_iterations, "PGS iterations", at_least_one)
          .Add("contact_erp", &C::contact_erp, "Bullet erp2 for contacts",
               Satisfies<double>([](const double& v) { return v > 0.0 && v <= 1.0; },
                                 "must be in (0, 1]"))
          .Add("floor_friction", &C::floor_friction, "lateral friction")
          .Add("humanoid_friction", &C::humanoid_friction, "lateral friction")
          .Add("chair_friction", &C::chair_friction, "lateral friction")
          .Add("linear_damping", &C::linear_damping, "btMultiBody damping [1/s]")
          .Add("angular_damping", &C::angular_damping, "btMultiBody damping [1/s]")
          .Add("contact_distance", &C::contact_distance, "contact below this distance [m]")
          .Add("max_joint_speed", &C::max_joint_speed, "Bullet's joint speed clamp [rad/s]",
               Positive<double>())
          .Add("limit_margin", &C::limit_margin, "limit constraints within this of a limit [rad]",
               NonNegative<double>())
          .Add("joint_damping", &C::joint_damping, "passive damping [N m s/rad]",
               NonNegative<double>())
          .Add("damping_speed", &C::damping_speed,
               "full torque alone cannot spin a joint faster [rad/s]",
               Satisfies<double>([](const double& v) { return v >= 0.0; }, "must be >= 0 (0: off)"))
          .Add("helper_link_inertia", &C::helper_link_inertia, "massless links' inertia",
               Positive<double>())
          .Add("floor_half_extent", &C::floor_half_extent, "[m] (0: infinite bounds)",
               Satisfies<double>([](const double& v) { return v >= 0.0; },
                                 "must be >= 0 (0: infinite bounds)"))
          .Add("collision_pool_size", &C::collision_pool_size, "Bullet's collision pools",
               at_least_one)
          .Custom(
              "chair_body", "static, dynamic or file (the chair file says)",
              [](const Json& j, C& c, const std::string& ctx) {
                std::string name = ChairBodyName(c.chair_body);
                GetOptional(j, "chair_body", name, ctx);
                c.chair_body = ChairBodyFromName(name, ctx + ".chair_body");
              },
              [](const C& c, Json& j) { j["chair_body"] = ChairBodyName(c.chair_body); })
          .Rule([](const C& c, const std::string& ctx) {
            for (double f : {c.floor_friction, c.humanoid_friction, c.chair_friction}) {
              if (!(f >= 0.0)) return ctx + ": frictions must be >= 0";
            }
            return std::string();
          });
  return t;
}

PhysicsConfig PhysicsConfig::FromJson(const Json& j, const std::string& ctx) {
  return PhysicsConfigFields().Read(j, ctx);
}

Json PhysicsConfig::ToJson() const { return PhysicsConfigFields().Write(*this); }

Eigen::Isometry3d ChairPlacement::Transform() const {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translate(Eigen::Vector3d(x, y, 0.0));
  t.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  return t;
}

HumanoidState StateFromQpos(const double* qpos) {
  HumanoidState s;
  for (int j = 0; j < HumanoidModel::kNumJoints; ++j) {
    s.q[j] = qpos[2 * j];
    s.qd[j] = qpos[2 * j + 1];
  }
  s.root_pos = Eigen::Vector3d(qpos[42], qpos[43], qpos[44]);
  s.root_quat = QuatFromRpy(qpos[45], qpos[46], qpos[47]);
  s.root_lin_vel = Eigen::Vector3d(qpos[48], qpos[49], qpos[50]);
  s.root_ang_vel.setZero();
  return s;
}

void QposFromState(const HumanoidState& s, double* qpos) {
  for (int j = 0; j < HumanoidModel::kNumJoints; ++j) {
    qpos[2 * j] = s.q[j];
    qpos[2 * j + 1] = s.qd[j];
  }
  const Eigen::Vector3d rpy = RpyFromQuat(s.root_quat);
  for (int i = 0; i < 3; ++i) {
    qpos[42 + i] = s.root_pos[i];
    qpos[45 + i] = rpy[i];
    qpos[48 + i] = s.root_lin_vel[i];
  }
}

// Everything Bullet owns. Rebuilt from scratch on every SetState, as the authors reload the whole
// world at every reset; this also makes a restored state independent of solver caches.
struct World::Scene {
  explicit Scene(int pool_size) : collision_config(PoolInfo(pool_size)) {}
  btDefaultCollisionConfiguration collision_config;
  btCollisionDispatcher dispatcher{&collision_config};
  btDbvtBroadphase broadphase;
  btMultiBodyConstraintSolver solver;
  btMultiBodyDynamicsWorld world{&dispatcher, &broadphase, &solver, &collision_config};
  std::vector<std::unique_ptr<btCollisionShape>> shapes;
  std::vector<std::unique_ptr<btCollisionObject>> objects;          // colliders, floor, chair
  std::vector<std::unique_ptr<btMultiBodyConstraint>> constraints;  // [num_joints] joint limits
  std::vector<char> limit_active;  // [num_joints] constraint currently in the world
  std::unique_ptr<btMultiBody> body;
  btRigidBody* chair = nullptr;                 // owned by `objects`
  std::vector<int> joint_link;                  // [num_joints] link index of each joint
  std::vector<int> body_link;                   // [num_bodies] link carrying each body (-1: base)
  std::vector<Eigen::Isometry3d> inertial_inv;  // [num_bodies] body frame in its link frame
  btAlignedObjectArray<btQuaternion> scratch_q;
  btAlignedObjectArray<btVector3> scratch_m;

  ~Scene() {
    for (size_t j = 0; j < constraints.size(); ++j) {
      if (limit_active[j]) world.removeMultiBodyConstraint(constraints[j].get());
    }
    if (body) world.removeMultiBody(body.get());
    for (auto& o : objects) {
      if (auto* rb = btRigidBody::upcast(o.get())) {
        world.removeRigidBody(rb);
      } else {
        world.removeCollisionObject(o.get());
      }
    }
  }

  btCollisionShape* Keep(btCollisionShape* s) {
    shapes.emplace_back(s);
    return s;
  }
};

World::World(const HumanoidModel& model, const Chair* chair, const ChairPlacement& placement,
             const PhysicsConfig& config)
    : model_(model), chair_(chair), placement_(placement), config_(config) {
  damping_.resize(model.num_joints());
  for (int j = 0; j < model.num_joints(); ++j) {
    damping_[j] =
        config.joint_damping +
        (config.damping_speed > 0.0 ? model.joint(j).max_torque / config.damping_speed : 0.0);
  }
  HumanoidState standing;
  standing.root_pos = Eigen::Vector3d(0, 0, model.standing_root_height());
  HumanoidState upright = standing;  // the joint-space inertia's pose: angles 0 clipped to limits
  for (int j = 0; j < model.num_joints(); ++j) {
    upright.q[j] = std::clamp(0.0, model.joint(j).lower, model.joint(j).upper);
  }
  // Backward Euler for the damping of all joints together, with the free-floating inverse
  // joint-space inertia of the upright pose (docs/env.md "Joint damping"):
  // qd' = qd + h Minv (tau - C qd')  =>  qd' = B (qd + h Minv tau), B = (1 + h Minv C)^-1.
  const int nj = model.num_joints();
  if (*std::max_element(damping_.begin(), damping_.end()) > 0.0) {
    const Eigen::MatrixXd minv = InverseJointInertia(upright);
    const Eigen::MatrixXd c = Eigen::Map<const Eigen::VectorXd>(damping_.data(), nj).asDiagonal();
    damp_push_ = config.physics_dt * minv;
    damp_push_unit_ = damp_push_;
    damp_solve_ = (Eigen::MatrixXd::Identity(nj, nj) + damp_push_ * c).inverse();
  }
  SetState(standing);
}

void World::SetDynamicsScales(double friction, double mass) {
  friction_scale_ = friction;
  if (mass != mass_scale_ && damp_push_unit_.size() > 0) {
    // Every mass and inertia x mass: the inverse joint-space inertia / mass, exactly.
    const int nj = model_.num_joints();
    const Eigen::MatrixXd c = Eigen::Map<const Eigen::VectorXd>(damping_.data(), nj).asDiagonal();
    damp_push_ = damp_push_unit_ / mass;
    damp_solve_ = (Eigen::MatrixXd::Identity(nj, nj) + damp_push_ * c).inverse();
  }
  mass_scale_ = mass;
}

Eigen::MatrixXd World::InverseJointInertia(HumanoidState s) {
  s.root_pos.z() += 100.0;  // out of reach of the floor and chair
  s.root_lin_vel.setZero();
  s.root_ang_vel.setZero();
  for (double& v : s.qd) v = 0.0;
  SetState(s);
  Scene& sc = *scene_;
  const std::array<double, HumanoidModel::kNumJoints> zero{};
  SetJointTorques(zero.data());
  for (int j = 0; j < model_.num_joints(); ++j) {
    if (sc.limit_active[j]) sc.world.removeMultiBodyConstraint(sc.constraints[j].get());
    sc.limit_active[j] = 0;
  }
  // One step computes the articulated-body inertias that calcAccelerationDeltasMultiDof uses.
  sc.world.stepSimulation(config_.physics_dt, 0, config_.physics_dt);
  btMultiBody* mb = sc.body.get();
  const int n = 6 + mb->getNumDofs();
  std::vector<btScalar> force(n, 0), accel(n, 0);
  btAlignedObjectArray<btScalar> scratch_r;
  btAlignedObjectArray<btVector3> scratch_v;
  const int nj = model_.num_joints();
  Eigen::MatrixXd minv(nj, nj);
  for (int j = 0; j < nj; ++j) {
    const int dof = 6 + mb->getLink(sc.joint_link[j]).m_dofOffset;
    force[dof] = 1;
    mb->calcAccelerationDeltasMultiDof(force.data(), accel.data(), scratch_r, scratch_v);
    force[dof] = 0;
    for (int k = 0; k < nj; ++k) minv(k, j) = accel[6 + mb->getLink(sc.joint_link[k]).m_dofOffset];
  }
  return minv;
}

World::~World() = default;

void World::AddFloor(Scene& sc) {
  // Floor: the plane z = 0, with finite or (0) infinite broadphase bounds.
  btCollisionShape* shape = config_.floor_half_extent > 0.0
                                ? sc.Keep(new FloorShape(config_.floor_half_extent))
                                : sc.Keep(new btStaticPlaneShape(btVector3(0, 0, 1), 0));
  btRigidBody::btRigidBodyConstructionInfo ci(0, nullptr, shape);
  auto* floor = new btRigidBody(ci);
  floor->setFriction(config_.floor_friction * friction_scale_);
  floor->setUserIndex(kFloor);
  sc.objects.emplace_back(floor);
  sc.world.addRigidBody(floor);
}

struct World::MeshShapes {
  const MeshChair* source = nullptr;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();
  std::unique_ptr<btTriangleMesh> tris;
  std::unique_ptr<btBvhTriangleMeshShape> static_shape;
  std::vector<std::unique_ptr<btConvexHullShape>> hulls;
};

const World::MeshShapes& World::ChairMeshShapes() {
  // Building the triangle BVH costs more than a step, and SetState rebuilds the scene often.
  const MeshChair* m = chair_->mesh.get();
  if (mesh_shapes_ && mesh_shapes_->source == m && mesh_shapes_->com == chair_->com) {
    return *mesh_shapes_;
  }
  auto ms = std::make_unique<MeshShapes>();
  ms->source = m;
  ms->com = chair_->com;
  ms->tris = std::make_unique<btTriangleMesh>();
  const TriMesh& t = m->collision_static;
  for (const auto& tri : t.triangles) {
    ms->tris->addTriangle(Bt(t.vertices[tri[0]] - ms->com), Bt(t.vertices[tri[1]] - ms->com),
                          Bt(t.vertices[tri[2]] - ms->com), /*removeDuplicateVertices=*/false);
  }
  ms->static_shape = std::make_unique<btBvhTriangleMeshShape>(ms->tris.get(), true);
  for (const TriMesh& part : m->convex_parts) {
    if (part.vertices.empty()) continue;
    auto hull = std::make_unique<btConvexHullShape>();
    for (const Eigen::Vector3d& v : part.vertices) hull->addPoint(Bt(v - ms->com), false);
    // Bullet pads a hull by a 4 cm margin by default: a chair standing on the floor would start
    // 4 cm inside it, and a seat would hold the pelvis 4 cm above its surface.
    hull->setMargin(kChairHullMargin);
    hull->recalcLocalAabb();
    ms->hulls.push_back(std::move(hull));
  }
  mesh_shapes_ = std::move(ms);  // only SetState calls this, after the old scene is gone
  return *mesh_shapes_;
}

void World::AddChair(Scene& sc, const ChairState* chair_state) {
  // Chair: one rigid body with a compound of boxes or convex parts (or, static, a triangle mesh),
  // frame at its com.
  if (!chair_) return;
  const bool dynamic = chair_->dynamic && config_.chair_body != ChairBody::kStatic;
  btCollisionShape* shape = nullptr;
  if (chair_->mesh) {
    const MeshShapes& ms = ChairMeshShapes();
    if (dynamic) {
      auto* compound = new btCompoundShape();
      sc.Keep(compound);
      for (const auto& hull : ms.hulls) {
        compound->addChildShape(btTransform::getIdentity(), hull.get());
      }
      shape = compound;
    } else {
      shape = ms.static_shape.get();  // concave: Bullet allows it on a static body only
    }
  } else {
    auto* compound = new btCompoundShape();
    sc.Keep(compound);
    for (const ChairBox& b : chair_->boxes) {
      auto* box = sc.Keep(new btBoxShape(Bt(b.half_extents())));
      compound->addChildShape(
          btTransform(btQuaternion::getIdentity(), Bt(b.center() - chair_->com)), box);
    }
    shape = compound;
  }
  const double mass = dynamic ? chair_->mass : 0.0;
  btVector3 inertia = dynamic ? Bt(chair_->inertia) : btVector3(0, 0, 0);
  btRigidBody::btRigidBodyConstructionInfo ci(mass, nullptr, shape, inertia);
  ci.m_friction = config_.chair_friction * friction_scale_;
  auto* rb = new btRigidBody(ci);
  Eigen::Isometry3d frame = placement_.Transform();
  if (chair_state) {
    frame = Eigen::Isometry3d::Identity();
    frame.translate(chair_state->pos);
    frame.rotate(chair_state->quat.normalized());
  }
  rb->setWorldTransform(Bt(frame * Translation(chair_->com)));
  bool moving = false;
  if (dynamic && chair_state) {
    rb->setLinearVelocity(Bt(chair_state->lin_vel));
    rb->setAngularVelocity(Bt(chair_state->ang_vel));
    moving = !chair_state->lin_vel.isZero(0.0) || !chair_state->ang_vel.isZero(0.0);
  }
  // Sleeping: Bullet wakes the chair when a body's bounds overlap it (they share an island).
  const bool sleeping = dynamic && config_.chair_body == ChairBody::kSleeping;
  if (!sleeping) rb->setActivationState(DISABLE_DEACTIVATION);
  rb->setUserIndex(kChair);
  sc.chair = rb;
  sc.objects.emplace_back(rb);
  sc.world.addRigidBody(rb);  // makes a static body ISLAND_SLEEPING
  if (sleeping && !moving) rb->setActivationState(ISLAND_SLEEPING);
}

void World::BuildHumanoid(Scene& sc) {
  // Humanoid: link order = bodies in file order, each body's hinges in application order.
  const int nb = model_.num_bodies();
  sc.joint_link.assign(model_.num_joints(), -1);
  sc.body_link.assign(nb, -1);
  sc.inertial_inv.resize(nb);
  const Body& root = model_.body(0);
  const double ms = mass_scale_;  // env.randomize: every mass and inertia x ms
  sc.body = std::make_unique<btMultiBody>(model_.num_joints(), root.mass * ms,
                                          Bt(root.principal_inertia * ms),
                                          /*fixedBase=*/false, /*canSleep=*/false);
  btMultiBody* mb = sc.body.get();
  // Link frames at q = 0 with the root at the origin; only relative frames matter here.
  const std::vector<double> zeros(model_.num_joints(), 0.0);
  const FkResult fk0 = ForwardKinematics(model_, Eigen::Vector3d::Zero(),
                                         Eigen::Quaterniond::Identity(), zeros.data());
  std::vector<Eigen::Isometry3d> link_frame(model_.num_joints());  // by link index
  std::vector<Eigen::Isometry3d> body_frame(nb);                   // body's carrying link frame
  body_frame[0] = fk0.body_world[0] * InertialFrame(root);
  sc.inertial_inv[0] = InertialFrame(root).inverse();
  int link = 0;
  for (int bi = 1; bi < nb; ++bi) {
    const Body& b = model_.body(bi);
    const Eigen::Isometry3d& bw = fk0.body_world[bi];
    int parent_link = sc.body_link[b.parent];
    Eigen::Isometry3d parent_frame = body_frame[b.parent];
    for (size_t k = 0; k < b.joints.size(); ++k) {
      const Joint& jt = model_.joint(b.joints[k]);
      const bool carrier = k + 1 == b.joints.size();
      const Eigen::Isometry3d frame = carrier ? bw * InertialFrame(b) : bw * Translation(jt.anchor);
      const Eigen::Vector3d pivot = bw * jt.anchor;
      const Eigen::Vector3d parent_to_pivot = parent_frame.inverse() * pivot;
      const Eigen::Vector3d pivot_to_com = -(frame.inverse() * pivot);
      const Eigen::Quaterniond rot_parent_to_this(frame.rotation().transpose() *
                                                  parent_frame.rotation());
      const Eigen::Vector3d axis = frame.rotation().transpose() * (bw.rotation() * jt.axis);
      const double hm = model_.helper_link_mass();
      const double mass = (carrier ? b.mass : hm) * ms;
      const Eigen::Vector3d inertia =
          (carrier ? b.principal_inertia : Eigen::Vector3d::Constant(config_.helper_link_inertia)) *
          ms;
      mb->setupRevolute(link, mass, Bt(inertia), parent_link, Bt(rot_parent_to_this.normalized()),
                        Bt(axis), Bt(parent_to_pivot), Bt(pivot_to_com), true);
      mb->getLink(link).m_flags |= BT_MULTIBODYLINKFLAGS_DISABLE_ALL_PARENT_COLLISION;
      sc.joint_link[b.joints[k]] = link;
      link_frame[link] = frame;
      parent_link = link;
      parent_frame = frame;
      ++link;
    }
    sc.body_link[bi] = parent_link;
    body_frame[bi] = parent_frame;
    sc.inertial_inv[bi] = InertialFrame(b).inverse();
  }
  mb->finalizeMultiDof();
  mb->setHasSelfCollision(true);
  mb->setLinearDamping(config_.linear_damping);
  mb->setAngularDamping(config_.angular_damping);
  mb->setMaxCoordinateVelocity(config_.max_joint_speed);
  mb->setCanSleep(false);
}

void World::PlaceHumanoid(Scene& sc, const HumanoidState& hs) {
  btMultiBody* mb = sc.body.get();
  const Body& root = model_.body(0);
  // Pose and velocities. Bullet's base is the torso's inertial frame.
  const Eigen::Isometry3d root_pose =
      Translation(hs.root_pos) * Eigen::Isometry3d(hs.root_quat.normalized());
  const Eigen::Isometry3d base = root_pose * InertialFrame(root);
  mb->setBaseWorldTransform(Bt(base));
  const Eigen::Vector3d com_offset = base.translation() - hs.root_pos;
  mb->setBaseVel(Bt(hs.root_lin_vel + hs.root_ang_vel.cross(com_offset)));
  mb->setBaseOmega(Bt(hs.root_ang_vel));
  for (int j = 0; j < model_.num_joints(); ++j) {
    mb->setJointPos(sc.joint_link[j], hs.q[j]);
    mb->setJointVel(sc.joint_link[j], hs.qd[j]);
  }
  sc.world.addMultiBody(mb);
}

void World::AddColliders(Scene& sc) {
  btMultiBody* mb = sc.body.get();
  const int nb = model_.num_bodies();
  // Colliders: base and carrier links get the body's geoms; a lone capsule centred at the com
  // (lwaist, pelvis, thighs, shins, upper arms) is used directly, since compound shapes cost a
  // compound-compound collision algorithm per pair.
  for (int bi = 0; bi < nb; ++bi) {
    const Body& b = model_.body(bi);
    btCollisionShape* body_shape = nullptr;
    if (b.geoms.size() == 1 && b.geoms[0].type == Geom::Type::kCapsule) {
      const Geom& g = b.geoms[0];
      const Eigen::Vector3d seg = g.to - g.from;
      const Eigen::Vector3d centre = sc.inertial_inv[bi] * (0.5 * (g.from + g.to));
      const Eigen::Vector3d dir = sc.inertial_inv[bi].rotation() * seg.normalized();
      int axis = -1;
      for (int k = 0; k < 3; ++k) {
        if (std::abs(std::abs(dir[k]) - 1.0) < 1e-9) axis = k;
      }
      if (axis >= 0 && centre.norm() < 1e-9) {
        const double h = seg.norm();
        body_shape = axis == 0   ? static_cast<btCollisionShape*>(new btCapsuleShapeX(g.radius, h))
                     : axis == 1 ? static_cast<btCollisionShape*>(new btCapsuleShape(g.radius, h))
                                 : static_cast<btCollisionShape*>(new btCapsuleShapeZ(g.radius, h));
        sc.Keep(body_shape);
      }
    }
    if (!body_shape) {
      auto* compound = new btCompoundShape();
      sc.Keep(compound);
      for (const Geom& g : b.geoms) {
        Eigen::Isometry3d gt = Translation(0.5 * (g.from + g.to));
        btCollisionShape* shape;
        if (g.type == Geom::Type::kCapsule) {
          const Eigen::Vector3d seg = g.to - g.from;
          gt.rotate(RotationZTo(seg.normalized()));
          shape = sc.Keep(new btCapsuleShapeZ(g.radius, seg.norm()));
        } else {
          shape = sc.Keep(new btSphereShape(g.radius));
        }
        compound->addChildShape(Bt(sc.inertial_inv[bi] * gt), shape);
      }
      body_shape = compound;
    }
    const int l = sc.body_link[bi];
    auto* col = new btMultiBodyLinkCollider(mb, l);
    col->setCollisionShape(body_shape);
    col->setFriction(config_.humanoid_friction);
    col->setUserIndex(kHumanoid);
    col->setUserIndex2(bi);
    sc.objects.emplace_back(col);
    sc.world.addCollisionObject(col, btBroadphaseProxy::DefaultFilter,
                                btBroadphaseProxy::AllFilter);
    if (l < 0) {
      mb->setBaseCollider(col);
    } else {
      mb->getLink(l).m_collider = col;
    }
  }
}

void World::AddJointLimits(Scene& sc) {
  btMultiBody* mb = sc.body.get();
  sc.limit_active.assign(model_.num_joints(), 0);
  for (int j = 0; j < model_.num_joints(); ++j) {
    const Joint& jt = model_.joint(j);
    sc.constraints.emplace_back(
        new btMultiBodyJointLimitConstraint(mb, sc.joint_link[j], jt.lower, jt.upper));
  }
  UpdateJointLimits();
}

void World::SetState(const HumanoidState& hs, const ChairState* chair_state) {
  scene_.reset();  // destroy the old world before building the new one
  root_force_.setZero();
  scene_ = std::make_unique<Scene>(config_.collision_pool_size);
  Scene& sc = *scene_;
  sc.world.setGravity(btVector3(0, 0, -config_.gravity));
  btContactSolverInfo& info = sc.world.getSolverInfo();
  info.m_numIterations = config_.solver_iterations;
  info.m_erp2 = config_.contact_erp;

  AddFloor(sc);
  AddChair(sc, chair_state);
  BuildHumanoid(sc);
  PlaceHumanoid(sc, hs);
  AddColliders(sc);
  AddJointLimits(sc);
  btMultiBody* mb = sc.body.get();
  mb->forwardKinematics(sc.scratch_q, sc.scratch_m);
  mb->updateCollisionObjectWorldTransforms(sc.scratch_q, sc.scratch_m);
  // Contacts are known right after a reset, before the first step.
  sc.world.performDiscreteCollisionDetection();
}

WorldState World::GetState() const {
  const Scene& sc = *scene_;
  const btMultiBody* mb = sc.body.get();
  WorldState s;
  HumanoidState& h = s.humanoid;
  const Eigen::Isometry3d base = Ei(mb->getBaseWorldTransform());
  const Eigen::Isometry3d root = base * sc.inertial_inv[0];
  h.root_pos = root.translation();
  h.root_quat = Eigen::Quaterniond(root.rotation()).normalized();
  h.root_ang_vel = Ei(mb->getBaseOmega());
  h.root_lin_vel = Ei(mb->getBaseVel()) + h.root_ang_vel.cross(h.root_pos - base.translation());
  ReadJoints(h.q.data(), h.qd.data());
  if (sc.chair) {
    const Eigen::Isometry3d com = Ei(sc.chair->getWorldTransform());
    s.chair.pos = (com * Translation(-chair_->com)).translation();
    s.chair.quat = Eigen::Quaterniond(com.rotation()).normalized();
    s.chair.lin_vel = Ei(sc.chair->getLinearVelocity());
    s.chair.ang_vel = Ei(sc.chair->getAngularVelocity());
  }
  return s;
}

void World::SetJointTorques(const double* tau) {
  for (int j = 0; j < model_.num_joints(); ++j) tau_[j] = tau[j];
}

void World::UpdateJointLimits() {
  // Only joints that can reach a limit within this step carry their limit constraint. Bullet
  // makes a row only for a joint at or past its limit, so this changes no rows; it saves the
  // constraint's fixed per-step cost (about 2% of a step).
  Scene& sc = *scene_;
  const btMultiBody* mb = sc.body.get();
  for (int j = 0; j < model_.num_joints(); ++j) {
    const Joint& jt = model_.joint(j);
    const int l = sc.joint_link[j];
    const double q = mb->getJointPos(l);
    const double reach =
        config_.limit_margin + 2.0 * std::abs(mb->getJointVel(l)) * config_.physics_dt;
    const bool near = q < jt.lower + reach || q > jt.upper - reach;
    if (near != static_cast<bool>(sc.limit_active[j])) {
      if (near) {
        sc.world.addMultiBodyConstraint(sc.constraints[j].get());
      } else {
        sc.world.removeMultiBodyConstraint(sc.constraints[j].get());
      }
      sc.limit_active[j] = near;
    }
  }
}

void World::StepPhysics() {
  Scene& sc = *scene_;
  UpdateJointLimits();
  AddJointTorques(tau_.data());
  if (!root_force_.isZero()) {
    sc.body->addBaseForce(btVector3(root_force_.x(), root_force_.y(), root_force_.z()));
  }
  // maxSubSteps = 0: exactly one step of physics_dt (Bullet clears the torques afterwards).
  sc.world.stepSimulation(config_.physics_dt, 0, config_.physics_dt);
}

void World::RawControlStepsPd(int n, const PdController& pd, const float* action) {
  Scene& sc = *scene_;
  double q[HumanoidModel::kNumJoints], qd[HumanoidModel::kNumJoints],
      tau[HumanoidModel::kNumJoints];
  for (int i = 0; i < n; ++i) {
    for (int s = 0; s < config_.substeps; ++s) {
      UpdateJointLimits();
      ReadJoints(q, qd);
      pd.Torques(action, q, qd, tau);
      AddJointTorques(tau);
      sc.world.stepSimulation(config_.physics_dt, 0, config_.physics_dt);
    }
  }
}

void World::AddJointTorques(const double* tau) {
  btMultiBody* mb = scene_->body.get();
  const int nj = model_.num_joints();
  if (damp_solve_.size() == 0) {
    for (int j = 0; j < nj; ++j) mb->addJointTorque(scene_->joint_link[j], tau[j]);
    return;
  }
  Eigen::Matrix<double, HumanoidModel::kNumJoints, 1> t, v;
  for (int j = 0; j < nj; ++j) {
    t[j] = tau[j];
    v[j] = mb->getJointVel(scene_->joint_link[j]);
  }
  // Damp the speeds the joints will have after this step (coupled backward Euler), so that
  // strong damping stays stable on the light feet and hands.
  const Eigen::Matrix<double, HumanoidModel::kNumJoints, 1> next =
      damp_solve_ * (v + damp_push_ * t);
  for (int j = 0; j < nj; ++j)
    mb->addJointTorque(scene_->joint_link[j], t[j] - damping_[j] * next[j]);
}

void World::ReadJoints(double* q, double* qd) const {
  const btMultiBody* mb = scene_->body.get();
  for (int j = 0; j < model_.num_joints(); ++j) {
    q[j] = mb->getJointPos(scene_->joint_link[j]);
    qd[j] = mb->getJointVel(scene_->joint_link[j]);
  }
}

Eigen::Isometry3d World::BodyPose(int body) const {
  const Scene& sc = *scene_;
  const int l = sc.body_link[body];
  const btCollisionObject* col =
      l < 0 ? sc.body->getBaseCollider() : sc.body->getLink(l).m_collider;
  return Ei(col->getWorldTransform()) * sc.inertial_inv[body];
}

Eigen::Vector3d World::CenterOfMass() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double mass = 0.0;
  for (int b = 0; b < model_.num_bodies(); ++b) {
    const Body& body = model_.body(b);
    sum += body.mass * (BodyPose(b) * body.com);
    mass += body.mass;
  }
  return sum / mass;
}

Contacts World::ReadContacts() const {
  Contacts c;
  btCollisionDispatcher& d = scene_->dispatcher;
  const int pelvis = model_.pelvis_body();
  const int n = d.getNumManifolds();
  for (int i = 0; i < n; ++i) {
    const btPersistentManifold* m = d.getManifoldByIndexInternal(i);
    bool touching = false;
    for (int p = 0; p < m->getNumContacts() && !touching; ++p) {
      touching = m->getContactPoint(p).getDistance() < config_.contact_distance;
    }
    if (!touching) continue;
    const btCollisionObject* a = m->getBody0();
    const btCollisionObject* b = m->getBody1();
    if (a->getUserIndex() != kHumanoid) std::swap(a, b);
    if (a->getUserIndex() != kHumanoid || b->getUserIndex() == kHumanoid) continue;
    const int body = a->getUserIndex2();
    if (b->getUserIndex() == kFloor) {
      for (int f = 0; f < 2; ++f)
        c.foot_floor[f] = c.foot_floor[f] || body == model_.foot_bodies()[f];
    } else if (b->getUserIndex() == kChair) {
      c.humanoid_chair = true;
      c.pelvis_chair = c.pelvis_chair || body == pelvis;
    }
  }
  return c;
}

int World::NumContactPoints(int* self_points) const {
  btCollisionDispatcher& d = scene_->dispatcher;
  int total = 0, self = 0;
  for (int i = 0; i < d.getNumManifolds(); ++i) {
    const btPersistentManifold* m = d.getManifoldByIndexInternal(i);
    total += m->getNumContacts();
    if (m->getBody0()->getUserIndex() == kHumanoid && m->getBody1()->getUserIndex() == kHumanoid) {
      self += m->getNumContacts();
    }
  }
  if (self_points) *self_points = self;
  return total;
}

int World::NumManifolds(int* floor_manifolds) const {
  btCollisionDispatcher& d = scene_->dispatcher;
  int floor = 0;
  for (int i = 0; i < d.getNumManifolds(); ++i) {
    const btPersistentManifold* m = d.getManifoldByIndexInternal(i);
    floor += m->getBody0()->getUserIndex() == kFloor || m->getBody1()->getUserIndex() == kFloor;
  }
  if (floor_manifolds) *floor_manifolds = floor;
  return d.getNumManifolds();
}

bool World::ChairAwake() const {
  const btRigidBody* c = scene_->chair;
  return c != nullptr && !c->isStaticObject() && c->isActive();
}

Eigen::Vector3d World::SeatTargetWorld() const {
  return chair_ ? Eigen::Vector3d(placement_.Transform() * chair_->seat_target)
                : Eigen::Vector3d(placement_.Transform() * Eigen::Vector3d::Zero());
}

}  // namespace perch
