#include "learner/service/learner.h"

#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numeric>

#include "common/paths.h"
#include "common/proto/model.pb.h"
#include "policy/dense_kernels.h"
#include "protocol/config_files.h"

namespace perch {

namespace {

template <typename R>
bool FiniteRange(const R& r) {
  for (auto v : r) {
    if (!std::isfinite(static_cast<double>(v))) return false;
  }
  return true;
}

bool FiniteStats(const proto::RunningStats& s) {
  return std::isfinite(s.count()) && FiniteRange(s.mean()) && FiniteRange(s.var());
}

// The first part of a trainer state that is not finite ("" when all is): weights, normaliser,
// optimiser moments and reward-scaling statistics (issue 17: never publish or checkpoint NaN).
std::string FirstNonFinite(const proto::LearnerState& s) {
  if (!FiniteRange(s.model().params())) return "model.params";
  if (!FiniteStats(s.model().obs_stats())) return "model.obs_stats";
  if (!FiniteRange(s.adam().m()) || !FiniteRange(s.adam().v())) return "adam";
  if (!FiniteStats(s.return_stats())) return "return_stats";
  for (const proto::ReturnStream& r : s.return_streams()) {
    if (!std::isfinite(r.ret())) return "return_streams";
  }
  return "";
}

void MakeDir(const std::string& path) {
  std::string cur;
  for (size_t i = 0; i <= path.size(); ++i) {
    if (i == path.size() || path[i] == '/') {
      if (!cur.empty()) ::mkdir(cur.c_str(), 0755);
    }
    if (i < path.size()) cur.push_back(path[i]);
  }
  struct stat st;
  if (::stat(path.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    throw ConfigError("--run-dir " + path + ": cannot create directory");
  }
}

uint64_t FreshRunId(uint64_t seed) {
  // Identifies the run, not part of any result: mixing in time and pid is fine here.
  Rng r(seed ^ static_cast<uint64_t>(MonotonicSeconds() * 1e9) ^
        (static_cast<uint64_t>(::getpid()) << 32));
  return r.NextU64();
}

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
}

// On a resume: when the run's config.json differs from the config now in force, it is moved to
// config-to-<update>.json (the config of updates up to `update`) and the changed sections are
// logged. An unreadable config.json counts as changed and is kept as it is.
void KeepChangedConfig(const std::string& config_path, const Json& record, uint64_t update) {
  if (!std::filesystem::exists(config_path)) return;
  Json previous;
  try {
    previous = LoadJsonFile(config_path);
  } catch (const ConfigError& e) {
    previous = Json{{"unreadable", e.what()}};
  }
  if (previous == record) return;
  char name[64];
  std::snprintf(name, sizeof(name), "/config-to-%010llu.json",
                static_cast<unsigned long long>(update));
  const std::string kept = std::filesystem::path(config_path).parent_path().string() + name;
  // Already there: a resume at this update before, whose config made no updates of its own.
  if (!std::filesystem::exists(kept)) std::filesystem::rename(config_path, kept);
  std::string changed;
  auto add = [&](const std::string& key) { changed += (changed.empty() ? "" : ", ") + key; };
  for (const auto& [key, value] : record.items()) {
    if (!previous.contains(key) || previous[key] != value) add(key);
  }
  for (const auto& [key, value] : previous.items()) {
    if (!record.contains(key)) add(key);
  }
  spdlog::warn("learner: resumed with a changed config (sections: {}); the earlier one is {}",
               changed, kept);
}

}  // namespace

// A process killed mid-write leaves a last line without its newline; rows appended after a
// restart would be glued to it. Cut the torn tail (it never was a whole row).
void RepairMetricsFile(const std::string& path) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec || size == 0) return;
  std::string text;
  {
    std::ifstream in(path, std::ios::binary);
    text.assign(std::istreambuf_iterator<char>(in), {});
  }
  if (text.empty() || text.back() == '\n') return;
  const size_t keep = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
  std::filesystem::resize_file(path, keep, ec);
  if (ec) {
    spdlog::error("learner: {}: cannot cut its torn last line: {}", path, ec.message());
  } else {
    spdlog::warn("learner: {}: cut a torn last line ({} bytes, from a run stopped mid-write)", path,
                 text.size() - keep);
  }
}

LearnerService::LearnerService(zmq::context_t& ctx, const LearnerSetup& setup,
                               const LearnerOptions& options)
    : setup_(setup),
      options_(options),
      task_(TaskFromName(setup.cluster.task, "cluster.task")),
      frozen_(setup.frozen),
      store_(options.run_dir, setup.cluster.keep_last, setup.cluster.milestone_every),
      rng_(setup.seed),
      rollout_sock_(ctx, zmq::socket_type::pull),
      weights_sock_(ctx, zmq::socket_type::xpub) {
  if (options_.run_dir.empty()) throw ConfigError("--run-dir: required");
  limits_.max_message_bytes = static_cast<size_t>(setup.cluster.max_message_bytes);
  limits_.max_segment_steps = setup.cluster.max_segment_steps;
  limits_.max_abs_value = setup.cluster.max_wire_value;
  limits_.obs_dim = setup.policy.obs_dim;
  limits_.act_dim = setup.policy.action_size();
  if (setup.policy.kind == PolicyKind::kMeta) limits_.num_choices = setup.policy.num_choices;
  ppo_ = std::make_unique<PpoLearner>(setup.policy, setup.ppo, setup.seed);
  const int learners = setup.cluster.learners;
  if (options_.group_rank < 0 || options_.group_rank >= learners) {
    throw ConfigError("--rank: " + std::to_string(options_.group_rank) + " is not in 0.." +
                      std::to_string(learners - 1) + " (cluster.learners " +
                      std::to_string(learners) + ")");
  }
  // Same seed, same initial weights on every member; each shuffles its own batch differently.
  if (options_.group_rank > 0) ppo_->SeedShuffle(setup.seed, options_.group_rank);
  MakeDir(options_.run_dir);
  RepairMetricsFile(options_.run_dir + "/metrics.jsonl");
  Resume();

  // Every run (and every restart of it) records its resolved config and seed. A resume with a
  // changed config (say a lower learning rate for the last stretch) keeps the config the earlier
  // updates were made with as config-to-<update>.json, so the run's history stays reproducible.
  Json record = setup_.resolved_config;
  record["seed"] = setup_.seed;
  const std::string config_path = options_.run_dir + "/config.json";
  if (!resumed_from_.empty()) KeepChangedConfig(config_path, record, counters_.updates());
  SaveJsonFileAtomic(config_path, record);
  // What an actor without a config of its own builds from (half the message limit for files).
  config_json_ = record.dump();
  config_files_ = CollectConfigFiles(record, limits_.max_message_bytes / 2);

  // Bigger messages make ZeroMQ drop the sender's connection before they are read into memory.
  rollout_sock_.set(zmq::sockopt::maxmsgsize, static_cast<int64_t>(limits_.max_message_bytes));
  rollout_sock_.set(zmq::sockopt::rcvhwm, setup.cluster.learner_queue_segments);
  rollout_sock_.set(zmq::sockopt::linger, 0);
  weights_sock_.set(zmq::sockopt::xpub_verbose, 1);  // see every (re)subscription
  weights_sock_.set(zmq::sockopt::sndhwm, 100);
  weights_sock_.set(zmq::sockopt::linger, 0);
  // Only cluster members: CURVE with the authorized actor keys on sockets other processes reach.
  const bool curve = !setup.cluster.insecure &&
                     (NeedsCurve(options_.rollout_bind) || NeedsCurve(options_.weights_bind));
  const bool group_curve = !setup.cluster.insecure && learners > 1 &&
                           NeedsCurve(options_.group_address.empty() ? setup.cluster.group_address
                                                                     : options_.group_address);
  if (curve || group_curve) {
    keys_ = std::make_unique<CurveKeys>(ReadLearnerKeys(KeysDir(setup.cluster)));
    std::vector<std::string> authorized = keys_->authorized;
    // The other learners of a group connect with the learner's own pair.
    if (group_curve) authorized.push_back(keys_->learner_public);
    zap_ = std::make_unique<ZapAuthenticator>(ctx, authorized);
  }
  if (curve) {
    // Handshakes that fail before the ZAP handler is asked (a client without CURVE at all, a
    // wrong server key) are seen only by a socket monitor: count them too.
    for (zmq::socket_t* sock : {&rollout_sock_, &weights_sock_}) {
      const std::string ep =
          "inproc://perch-monitor-" + std::to_string(reinterpret_cast<uintptr_t>(sock));
      if (zmq_socket_monitor(sock->handle(), ep.c_str(),
                             ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL |
                                 ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                                 ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) == 0) {
        monitors_.emplace_back(ctx, zmq::socket_type::pair);
        monitors_.back().set(zmq::sockopt::linger, 0);
        monitors_.back().connect(ep);
      }
    }
    const CurveKeys& keys = *keys_;
    MakeCurveServer(rollout_sock_, keys);
    MakeCurveServer(weights_sock_, keys);
  } else if (setup.cluster.insecure) {
    spdlog::warn("learner: cluster.insecure: anyone who reaches {} / {} can train or read it",
                 options_.rollout_bind, options_.weights_bind);
  }
  rollout_sock_.bind(options_.rollout_bind);
  weights_sock_.bind(options_.weights_bind);
  if (options_.metrics_port >= 0) {
    metrics_ = std::make_unique<MetricsServer>(options_.metrics_port, options_.metrics_bind);
  }
  if (learners > 1) {
    // Joins after binding, so that this member's actors connect while the others start.
    GroupOptions g;
    g.rank = options_.group_rank;
    g.size = learners;
    g.address =
        options_.group_address.empty() ? setup.cluster.group_address : options_.group_address;
    g.timeout_s = setup.cluster.group_timeout_s;
    g.join_timeout_s = setup.cluster.group_timeout_s;
    g.fingerprint = GroupFingerprint();
    g.stop = options_.stop;
    g.keys = group_curve ? keys_.get() : nullptr;
    spdlog::info("learner: rank {} of {} joining the group at {} ({})", g.rank, g.size, g.address,
                 g.fingerprint);
    group_ = std::make_unique<ZmqGroup>(ctx, g);
    ppo_->SetCollective(group_.get());
    spdlog::info("learner: the group of {} learners is complete", learners);
  }
  spdlog::info(
      "learner: task {} obs_dim {} action_size {} batch {} samples; PPO on {} thread(s), {} "
      "kernels; rollouts on {}, weights on {}, metrics on {}",
      setup_.cluster.task, limits_.obs_dim, limits_.act_dim, setup_.ppo.steps_per_update,
      setup_.ppo.threads, ActiveDenseKernels().name, options_.rollout_bind, options_.weights_bind,
      metrics_ ? ":" + std::to_string(metrics_->port()) + "/metrics" : "off");
}

LearnerService::~LearnerService() = default;

std::string LearnerService::GroupFingerprint() const {
  const std::string config = setup_.compat_key + "\n" + setup_.resolved_config.dump();
  proto::ModelWeights w;
  ppo_->ExportWeights(&w);
  w.set_version(0);
  const std::string weights = w.SerializeAsString();
  return fmt::format("config={:08x} seed={} updates={} weights={:08x}",
                     Crc32(config.data(), config.size()), setup_.seed, ppo_->num_updates(),
                     Crc32(weights.data(), weights.size()));
}

void LearnerService::Resume() {
  const std::vector<uint64_t> present = store_.List();
  if (!options_.resume) {
    if (!present.empty()) {
      throw ConfigError("--run-dir " + options_.run_dir + ": holds checkpoints (latest " +
                        store_.PathFor(present.back()) +
                        "); pass --resume to continue that run or choose another --run-dir");
    }
    run_id_ = FreshRunId(setup_.seed);
    InitFrom();
    return;
  }
  if (present.empty()) {
    spdlog::warn("learner: --resume but no checkpoint in {}; starting a new run", store_.dir());
    run_id_ = FreshRunId(setup_.seed);
    InitFrom();
    return;
  }
  auto accept = [&](const proto::Checkpoint& c) {
    if (c.compat_key() != setup_.compat_key) {
      throw CheckpointError("checkpoint update " + std::to_string(c.counters().updates()) +
                            " was made with an incompatible config (task/dims/network): " +
                            c.compat_key() + " vs now " + setup_.compat_key);
    }
    try {
      ppo_->ImportState(c.trainer(), "checkpoint update " + std::to_string(c.counters().updates()));
    } catch (const ConfigError& e) {
      throw CheckpointError(e.what());
    }
  };
  proto::Checkpoint ckpt;
  std::vector<std::string> errors;
  if (!store_.LoadLatestGood(
          accept, [](const std::string& w) { spdlog::error("learner: {}", w); }, &ckpt,
          &resumed_from_, &errors)) {
    std::string all;
    for (const auto& e : errors) all += "\n  " + e;
    throw CheckpointError("--resume: no usable checkpoint in " + store_.dir() + ":" + all);
  }
  counters_ = ckpt.counters();
  run_id_ = ckpt.run_id();
  // The run goes on with the subtasks it trained with, whatever the files hold now.
  std::vector<proto::TaskPolicy> kept;
  for (const proto::TaskPolicy& p : ckpt.weights().policies()) {
    if (p.frozen()) kept.push_back(p);
  }
  if (!kept.empty()) {
    for (const proto::TaskPolicy& p : kept) {
      for (const proto::TaskPolicy& f : frozen_) {
        if (f.task() == p.task() && f.source() != p.source()) {
          spdlog::warn(
              "learner: resumed run keeps its frozen {} policy {} (the config now names {})",
              TaskName(p.task()), p.source(), f.source());
        }
      }
    }
    frozen_ = kept;
  }
  if (ckpt.rng().s_size() == 4) {
    Rng::State st{{ckpt.rng().s(0), ckpt.rng().s(1), ckpt.rng().s(2), ckpt.rng().s(3)},
                  ckpt.rng().has_spare(),
                  ckpt.rng().spare()};
    rng_.SetState(st);
  }
  train_time_base_s_ = counters_.train_time_s();
  last_checkpoint_update_ = static_cast<int64_t>(counters_.updates());
  last_checkpoint_path_ = resumed_from_;
  spdlog::info("learner: resumed from {} (update {}, {} samples)", resumed_from_,
               counters_.updates(), counters_.samples());
}

void CheckRunTimeConfig(const LearnerSetup& setup) {
  // The weights message every actor must accept (its SUB drops bigger ones unread) and the
  // biggest segment the learner must accept (its PULL drops the sender's connection).
  PpoLearner ppo(setup.policy, setup.ppo, setup.seed);
  // init_from exists and fits this run's policy (onto a throwaway learner).
  ApplyInitFrom(setup, &ppo);
  proto::LearnerMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  ppo.ExportWeights(m.mutable_weights()->add_policies()->mutable_model());
  for (const proto::TaskPolicy& f : setup.frozen) *m.mutable_weights()->add_policies() = f;
  const size_t weights = m.ByteSizeLong() + 256;  // + version, credit, run id
  const size_t per_step = 4 * (2 * static_cast<size_t>(setup.policy.obs_dim) +
                               static_cast<size_t>(setup.policy.action_size()) + 8);
  const size_t segment = per_step * setup.cluster.segment_steps + 4096;
  const size_t limit = static_cast<size_t>(setup.cluster.max_message_bytes);
  if (weights > limit || segment > limit) {
    throw ConfigError("cluster.max_message_bytes: " + std::to_string(limit) +
                      " bytes is too small: the weights message needs about " +
                      std::to_string(weights) + " and a segment of " +
                      std::to_string(setup.cluster.segment_steps) + " steps about " +
                      std::to_string(segment) + " (nothing would ever train)");
  }
}

void LearnerService::InitFrom() { ApplyInitFrom(setup_, ppo_.get()); }

void ApplyInitFrom(const LearnerSetup& setup, PpoLearner* ppo) {
  if (setup.cluster.init_from.empty()) return;
  const std::string path = ResolveProjectPath(setup.cluster.init_from);
  const std::string ctx = "cluster.init_from " + path;
  proto::Checkpoint c;
  try {
    c = ReadCheckpointFile(path);
  } catch (const CheckpointError& e) {
    throw ConfigError(ctx + ": " + e.what());
  }
  if (!c.has_trainer() || !c.trainer().has_model()) {
    throw ConfigError(ctx + ": holds no trained policy");
  }
  if (setup.cluster.init_state) {
    // A branch of the source run under a new config: its whole trainer state, counters at 0.
    if (setup.cluster.init_mirror) {
      throw ConfigError(ctx +
                        ": cluster.init_state takes the source's trainer state as it is; "
                        "not with cluster.init_mirror");
    }
    proto::LearnerState st = c.trainer();
    st.mutable_model()->set_version(0);
    st.set_num_updates(0);
    st.set_num_samples(0);
    try {
      ppo->ImportState(st, ctx);
    } catch (const ConfigError& e) {
      throw ConfigError(std::string(e.what()) +
                        " (cluster.init_state needs the source's network and observation)");
    }
    spdlog::info(
        "learner: new run initialised from {} with its trainer state (Adam, reward "
        "scaling, normaliser; cluster.init_state)",
        path);
    return;
  }
  // Weights and normalizer only; the new run counts its own updates from 0.
  proto::ModelWeights w = c.trainer().model();
  w.set_version(0);
  const PolicyConfig& mine = ppo->model().config();
  // A policy that observes more (walk: proprioceptive + goal) starts one that observes its prefix
  // (turn: proprioceptive), the authors' walk -> turn initialisation (notes 8.2).
  if (w.shape().obs_dim() > mine.obs_dim) {
    spdlog::info("learner: {}: its {} inputs mapped onto this run's first {} (the rest dropped)",
                 ctx, w.shape().obs_dim(), mine.obs_dim);
    w = DropTrailingInputs(w, mine.obs_dim, ctx);
  }
  if (setup.cluster.init_mirror) {
    if (setup.mirror.empty()) {
      throw ConfigError(ctx + ": cluster.init_mirror: this run's env has no left/right mirror map");
    }
    spdlog::info("learner: {}: mirrored left/right (cluster.init_mirror)", ctx);
    w = MirrorModelWeights(w, setup.mirror, ctx);
  }
  // A policy that observes more starts from one that did not, the new inputs with zero weights
  // (the same function at first): a meta controller with observe_active, a sit with
  // observe_chair_shape.
  if (w.shape().kind() == (mine.kind == PolicyKind::kMeta ? "meta" : "gaussian") &&
      w.shape().obs_dim() < mine.obs_dim) {
    spdlog::info("learner: {}: {} inputs widened to {} (the new ones with zero weights)", ctx,
                 w.shape().obs_dim(), mine.obs_dim);
    w = AppendZeroInputs(w, mine.obs_dim, ctx);
  }
  // The walk-only meta pre-training starts the full meta controller (notes 6).
  if (w.shape().kind() == "meta" && mine.kind == PolicyKind::kMeta &&
      w.shape().num_choices() < mine.num_choices) {
    spdlog::info("learner: {}: its {} switch classes widened to {} (the switch head starts anew)",
                 ctx, w.shape().num_choices(), mine.num_choices);
    w = WidenMetaChoices(w, mine, setup.seed, ctx);
  }
  // A run that freezes or frees sigma takes the source's policy with its own std mode.
  if (w.shape().std_mode() != StdModeName(mine.std_mode)) {
    w = ConvertStdMode(w, mine, ctx);
    spdlog::info(
        "learner: {}: sigma {} from here on{}", ctx, StdModeName(mine.std_mode),
        mine.std_mode == StdMode::kFixed
            ? fmt::format(" at exp({}) = {:.3f}", mine.init_log_std, std::exp(mine.init_log_std))
            : std::string(" (starting from the source's log-std)"));
  }
  // A run configured with wider hidden layers starts from the same function (Net2WiderNet).
  const auto& sh = w.shape();
  const std::vector<int> ph(sh.policy_hidden().begin(), sh.policy_hidden().end());
  const std::vector<int> vh(sh.value_hidden().begin(), sh.value_hidden().end());
  if (ph != mine.policy_net.hidden || vh != mine.value_net.hidden) {
    w = WidenModelWeights(w, mine, setup.seed, ctx);
    spdlog::info("learner: {} widened to this run's hidden layers (same policy and value)", ctx);
  }
  ppo->ImportWeights(w, ctx);  // ConfigError on another network shape or observation size
  spdlog::info("learner: new run initialised from {} (update {}, {} samples of training)", path,
               c.counters().updates(), c.counters().samples());
}

std::string LearnerService::SaveCheckpoint() {
  proto::Checkpoint c;
  c.set_wire_version(proto::WIRE_VERSION_CURRENT);
  c.set_run_id(run_id_);
  counters_.set_train_time_s(train_time_base_s_ + MonotonicSeconds() - start_s_);
  *c.mutable_counters() = counters_;
  proto::TaskPolicy* tp = c.mutable_weights()->add_policies();
  tp->set_task(task_);
  ppo_->ExportWeights(tp->mutable_model());
  for (const proto::TaskPolicy& f : frozen_) *c.mutable_weights()->add_policies() = f;
  c.mutable_weights()->set_version(version());
  c.mutable_weights()->set_run_id(run_id_);
  ppo_->ExportState(c.mutable_trainer());
  const Rng::State st = rng_.GetState();
  for (uint64_t w : st.s) c.mutable_rng()->add_s(w);
  c.mutable_rng()->set_has_spare(st.has_spare);
  c.mutable_rng()->set_spare(st.spare);
  // Never a checkpoint of a non-finite state: the newest good one stays the newest.
  if (const std::string bad = FirstNonFinite(c.trainer()); !bad.empty()) {
    spdlog::error("learner: not writing a checkpoint at update {}: {} is not finite",
                  counters_.updates(), bad);
    return last_checkpoint_path_;
  }
  Json record = setup_.resolved_config;
  record["seed"] = setup_.seed;
  c.set_resolved_config_json(record.dump());
  c.set_compat_key(setup_.compat_key);
  c.set_seed(setup_.seed);
  const std::string path = store_.Save(c);
  last_checkpoint_update_ = static_cast<int64_t>(counters_.updates());
  last_checkpoint_path_ = path;
  spdlog::info("learner: checkpoint {}", path);
  return path;
}

void LearnerService::Publish(bool republish) {
  // Frozen policies go once to everyone, then to each (re)subscription: new actors need them,
  // the others keep what they have.
  const bool with_frozen = !frozen_.empty() && (republish || !frozen_published_);
  const bool with_config = republish || !config_published_;
  if (!republish || weights_bytes_.empty()) {
    proto::LearnerMessage m;
    m.set_wire_version(proto::WIRE_VERSION_CURRENT);
    proto::Weights* w = m.mutable_weights();
    w->set_version(version());
    w->set_run_id(run_id_);
    w->set_credit_segments(credit_segments_);
    w->set_credit_epoch(credit_epoch_);
    proto::TaskPolicy* tp = w->add_policies();
    tp->set_task(task_);
    ppo_->ExportWeights(tp->mutable_model());
    weights_bytes_ = m.SerializeAsString();
  }
  if (with_frozen || with_config) {
    proto::LearnerMessage m;
    m.ParseFromString(weights_bytes_);
    if (with_frozen) {
      for (const proto::TaskPolicy& f : frozen_) *m.mutable_weights()->add_policies() = f;
      frozen_published_ = true;
    }
    m.mutable_weights()->set_experiment_config_json(config_json_);
    for (const proto::ConfigFile& f : config_files_) *m.mutable_weights()->add_config_files() = f;
    config_published_ = true;
    weights_sock_.send(zmq::buffer(m.SerializeAsString()), zmq::send_flags::dontwait);
  } else {
    weights_sock_.send(zmq::buffer(weights_bytes_), zmq::send_flags::dontwait);
  }
  (republish ? stats_.weights_republished : stats_.weights_published) += 1;
}

void LearnerService::Reject(WireReject kind, const std::string& why) {
  counters_.set_rejected(counters_.rejected() + 1);
  stats_.rejected_by_kind[WireRejectName(kind)] += 1;
  // Rate-limited: garbage on a socket must not flood the log either.
  const double now = MonotonicSeconds();
  if (now - rejects_logged_at_ >= 5.0) {
    spdlog::warn("learner: dropped a message ({}): {}{}", WireRejectName(kind), why,
                 rejects_unlogged_ ? " (+" + std::to_string(rejects_unlogged_) + " not logged)"
                                   : std::string());
    rejects_logged_at_ = now;
    rejects_unlogged_ = 0;
  } else {
    ++rejects_unlogged_;
  }
}

void LearnerService::SeeActor(uint64_t instance, double now) {
  auto it = actor_last_seen_.find(instance);
  if (it != actor_last_seen_.end()) {
    it->second = now;
    return;
  }
  // A flood of made-up instance ids must not grow memory without bound: forget the silent ones,
  // and past the cap track no new ones until some fall silent.
  if (actor_last_seen_.size() >= kMaxTrackedActors) PruneActors(now);
  if (actor_last_seen_.size() >= kMaxTrackedActors) return;
  actor_last_seen_[instance] = now;
}

void LearnerService::DrainMonitors() {
  for (zmq::socket_t& m : monitors_) {
    zmq::message_t event;
    while (m.recv(event, zmq::recv_flags::dontwait)) {
      if (event.size() >= 2) ++handshake_failures_;
      zmq::message_t endpoint;  // the second frame of every event
      if (event.more()) (void)m.recv(endpoint, zmq::recv_flags::dontwait);
    }
  }
}

void LearnerService::PruneActors(double now) {
  for (auto it = actor_last_seen_.begin(); it != actor_last_seen_.end();) {
    it = now - it->second > setup_.cluster.actor_timeout_s ? actor_last_seen_.erase(it) : ++it;
  }
}

void LearnerService::HandleRollout(const zmq::message_t& msg) {
  ++stats_.messages;
  proto::ActorMessage m;
  std::string why;
  const WireReject r = ParseActorMessage(msg.data(), msg.size(), limits_, &m, &why);
  if (r != WireReject::kOk) return Reject(r, why);
  const double now = MonotonicSeconds();
  switch (m.body_case()) {
    case proto::ActorMessage::kHello:
      ++stats_.hellos;
      SeeActor(m.hello().actor_instance(), now);
      credit_pending_ = setup_.cluster.credit_slack > 0;  // the share per actor changed
      spdlog::info("learner: actor {} ({}, {} envs of {}) joined", m.hello().actor_id(),
                   m.hello().hostname(), m.hello().num_envs(), m.hello().env_name());
      break;
    case proto::ActorMessage::kHeartbeat:
      ++stats_.heartbeats;
      SeeActor(m.heartbeat().actor_instance(), now);
      break;
    case proto::ActorMessage::kEndPoses:
      ++stats_.end_pose_batches;  // Stored by the transition fine-tuning stage (not yet used).
      break;
    case proto::ActorMessage::kSegment:
      SeeActor(m.segment().actor_instance(), now);
      if (HandleSegment(m.segment())) {
        wire_bytes_ += msg.size();
        wire_samples_ += m.segment().rollout().rewards_size();
      }
      break;
    default:
      break;
  }
}

bool LearnerService::HandleSegment(const proto::Segment& seg) {
  Rollout r;
  try {
    r = Rollout::FromProto(seg.rollout(), "segment");
  } catch (const ConfigError& e) {
    Reject(WireReject::kShape, e.what());
    return false;
  }
  const uint64_t v = version();
  // Observation statistics are valid data whatever the policy version was. A group merges them
  // inside the update, every member's in rank order, so that all keep the same normalizer.
  if (r.policy_version <= v) {
    if (group_) {
      if (pending_obs_delta_.dim() != r.obs_stats_delta.dim()) {
        pending_obs_delta_ = RunningMeanStd(r.obs_stats_delta.dim(), 0.0);
      }
      pending_obs_delta_.Merge(r.obs_stats_delta);
    } else {
      ppo_->AddObsStats(r.obs_stats_delta);
    }
  }
  // Merged here, once: PPO's Update() would merge the rollout's delta again (issue 17).
  r.obs_stats_delta.Reset(0.0);
  if (r.policy_version > v ||
      v - r.policy_version > static_cast<uint64_t>(setup_.cluster.max_policy_lag)) {
    // Too old, or from a version this learner never published (weights of a run past our last
    // checkpoint, before a restart).
    counters_.set_dropped_stale(counters_.dropped_stale() + 1);
    return false;
  }
  for (const auto& e : seg.episodes()) {
    batch_returns_.push_back(e.episode_return());
    batch_lengths_.push_back(e.length());
    batch_terminated_ += e.terminated();
    batch_judged_ += e.has_success();
    batch_succeeded_ += e.has_success() && e.success();
    if (progress_) progress_->AddEpisode(e.length(), e.terminated(), e.has_success(), e.success());
  }
  counters_.set_episodes(counters_.episodes() + seg.episodes_size());
  counters_.set_segments(counters_.segments() + 1);
  batch_lag_sum_ += static_cast<double>(v - r.policy_version);
  ++batch_segments_;
  last_segment_s_ = MonotonicSeconds();
  if (r.policy_version == v && granted_version_ == v) ++segments_at_version_;
  batch_samples_ += r.size();
  batch_.push_back(std::move(r));
  return true;
}

int LearnerService::ActorsAlive() const {
  const double now = MonotonicSeconds();
  int n = 0;
  for (const auto& [id, t] : actor_last_seen_) n += now - t <= setup_.cluster.actor_timeout_s;
  return n;
}

void LearnerService::Train() {
  const double t0 = MonotonicSeconds();
  UpdateStats u;
  // The state before the update, to fall back to should the update leave anything non-finite.
  proto::LearnerState before;
  ppo_->ExportState(&before);
  if (group_ && !batch_.empty()) {
    batch_[0].obs_stats_delta = pending_obs_delta_;
    pending_obs_delta_.Reset(0.0);
  }
  try {
    if (!setup_.ppo.lr_schedule.empty()) {
      ppo_->SetLearningRate(LearningRateAt(setup_.ppo, static_cast<int64_t>(counters_.samples())));
    }
    u = ppo_->Update(batch_);
    proto::LearnerState after;
    ppo_->ExportState(&after);
    if (const std::string bad = FirstNonFinite(after); !bad.empty()) {
      ppo_->ImportState(before, "the state before a non-finite update");
      ++nonfinite_updates_;
      throw ConfigError("the update left " + bad +
                        " non-finite; discarded, the last good weights "
                        "stay published");
    }
  } catch (const GroupStopped& e) {
    // Another member stopped (or this one is stopping): the update did not happen anywhere.
    ppo_->ImportState(before, "the state before the group stopped");
    group_end_ = "group_stopped";
    spdlog::warn("learner: {}; ending at update {}", e.what(), counters_.updates());
    return;
  } catch (const GroupError& e) {
    ppo_->ImportState(before, "the state before the group failed");
    group_end_ = "group_failed";
    group_error_ = e.what();
    spdlog::error("learner: {}; ending at update {}", e.what(), counters_.updates());
    return;
  } catch (const ConfigError& e) {
    // Every segment was validated on receipt; should PPO still refuse the batch, drop it rather
    // than stop the run.
    spdlog::error("learner: PPO refused a batch of {} segments, dropped: {}", batch_.size(),
                  e.what());
    counters_.set_rejected(counters_.rejected() + batch_.size());
    stats_.rejected_by_kind["ppo"] += batch_.size();
    ClearBatch();
    return;
  }
  // A group counts the whole group's samples, so budgets and rates are the group's.
  const uint64_t trained = group_ ? static_cast<uint64_t>(u.group_samples) : batch_samples_;
  counters_.set_updates(counters_.updates() + 1);
  counters_.set_samples(counters_.samples() + trained);
  const double now = MonotonicSeconds();
  if (progress_) progress_->OnUpdate(counters_.samples(), now);
  const double window = now - last_update_s_;
  last_samples_per_s_ = window > 0 ? trained / window : 0.0;
  last_lag_mean_ = batch_segments_ ? batch_lag_sum_ / batch_segments_ : 0.0;
  if (!batch_returns_.empty()) last_return_mean_ = Mean(batch_returns_);
  WriteMetrics(u, now - t0, batch_samples_);
  last_update_s_ = now;
  ClearBatch();
  // What arrived while training (stamped with the old version: lag 1 now) starts the next batch,
  // and the new credit counts it (flow control).
  DrainRollouts();
  GrantCredit();
  if (counters_.updates() % setup_.cluster.checkpoint_every == 0) SaveCheckpoint();
}

void LearnerService::ClearBatch() {
  batch_.clear();
  batch_samples_ = 0;
  batch_lag_sum_ = 0;
  batch_segments_ = 0;
  batch_returns_.clear();
  batch_lengths_.clear();
  batch_terminated_ = 0;
  batch_judged_ = 0;
  batch_succeeded_ = 0;
}

void LearnerService::DrainRollouts() {
  zmq::message_t msg;
  while (batch_samples_ < static_cast<uint64_t>(setup_.ppo.steps_per_update) &&
         rollout_sock_.recv(msg, zmq::recv_flags::dontwait)) {
    HandleRollout(msg);
  }
}

// The grant is a total per actor for the current version: an even share of what was already
// received at this version plus what the batch still needs, times (1 + slack). Recomputed when
// actors join and when the batch stalls, it then grows by the share still needed.
double LearnerService::CreditPerActor() const {
  if (setup_.cluster.credit_slack <= 0) return 0.0;  // no flow control
  const int alive = ActorsAlive();
  if (alive == 0) return 1.0;  // nobody known yet: the first hellos bring a real grant
  const double need = std::max(
      0.0, static_cast<double>(setup_.ppo.steps_per_update) - static_cast<double>(batch_samples_));
  const double segments = static_cast<double>(segments_at_version_) +
                          need * (1.0 + setup_.cluster.credit_slack) / setup_.cluster.segment_steps;
  // Never 0 (that reads "no limit"): a full batch still lets each actor finish a little.
  return std::clamp(segments / alive, 1e-3, 1e6);
}

void LearnerService::GrantCredit(bool stalled) {
  const double before = credit_segments_;
  const bool same_version = granted_version_ == version();
  if (!same_version) {
    granted_version_ = version();
    segments_at_version_ = 0;
  }
  credit_pending_ = false;
  credit_segments_ = CreditPerActor();
  if (stalled && same_version && before > 0) {
    // The even share of what arrived may already be spent by the live actors (a departed actor
    // made part of it): grow every actor's total by its share of what is still needed.
    const double need = std::max(0.0, static_cast<double>(setup_.ppo.steps_per_update) -
                                          static_cast<double>(batch_samples_));
    const double more = need * (1.0 + setup_.cluster.credit_slack) /
                        (std::max(1, ActorsAlive()) * setup_.cluster.segment_steps);
    credit_segments_ = std::max(credit_segments_, std::min(1e6, before + std::max(1.0, more)));
  }
  ++credit_epoch_;
  last_grant_s_ = MonotonicSeconds();
  Publish(false);
}

void LearnerService::WriteMetrics(const UpdateStats& u, double update_s, uint64_t samples) {
  Json j{
      {"update", counters_.updates()},
      {"samples", counters_.samples()},
      {"batch_samples", samples},
      {"samples_per_s", last_samples_per_s_},
      {"update_s", update_s},
      {"policy_lag_mean", last_lag_mean_},
      {"episodes", batch_returns_.size()},
      {"episodes_terminated", batch_terminated_},  // falls; the others hit the time limit
      // Episodes judged by the task's success test (turn, sit) and how many passed.
      {"episodes_judged", batch_judged_},
      {"episodes_succeeded", batch_succeeded_},
      {"return_mean", batch_returns_.empty() ? Json(nullptr) : Json(Mean(batch_returns_))},
      {"episode_length_mean", batch_lengths_.empty() ? Json(nullptr) : Json(Mean(batch_lengths_))},
      {"dropped_stale", counters_.dropped_stale()},
      {"segments", counters_.segments()},
      {"credit_segments", credit_segments_},
      {"rejected", counters_.rejected()},
      {"actors", ActorsAlive()},
      {"wire_bytes_per_sample",
       wire_samples_ ? static_cast<double>(wire_bytes_) / wire_samples_ : 0.0},
      {"time_s", train_time_base_s_ + MonotonicSeconds() - start_s_},
      {"ppo", ToJson(u)}};
  if (group_) {
    const GroupStats& g = group_->stats();
    j["group"] = Json{{"rank", group_->rank()},
                      {"size", group_->size()},
                      {"operations", g.operations},
                      {"bytes_sent", g.bytes_sent},
                      {"bytes_received", g.bytes_received},
                      {"wait_s", g.wait_s}};
  }
  std::ofstream out(options_.run_dir + "/metrics.jsonl", std::ios::app);
  out << j.dump() << "\n";
  UpdateGauges();
  static thread_local double last_console = -1e9;
  const double now = MonotonicSeconds();
  if (now - last_console >= options_.console_every_s) {
    last_console = now;
    // What a user judges progress by first; then what an operator debugs with.
    const std::string head =
        progress_ ? progress_->ConsoleLine(counters_.updates(), last_samples_per_s_)
                  : fmt::format("update {} | samples {}", counters_.updates(), counters_.samples());
    spdlog::info(
        "{} | return {} | lag {:.2f} | policy loss {:.4f} value loss {:.4f} | stale {} rejected {} "
        "| actors {}",
        head,
        j["return_mean"].is_null() ? std::string("-")
                                   : fmt::format("{:.1f}", j["return_mean"].get<double>()),
        last_lag_mean_, u.policy_loss, u.value_loss, counters_.dropped_stale(),
        counters_.rejected(), ActorsAlive());
  }
}

void LearnerService::UpdateGauges() {
  if (!metrics_) return;
  MetricsServer& m = *metrics_;
  m.Set("perch_updates_total", counters_.updates(), "PPO updates", "counter");
  // Written by `perch train` (its restarts of this learner and of the actors); absent otherwise.
  try {
    const std::string launcher = options_.run_dir + "/launcher.json";
    if (std::filesystem::exists(launcher)) {
      const Json j = LoadJsonFile(launcher);
      m.Set("perch_learner_restarts_total", j.value("learner_restarts", 0.0),
            "learner restarts by perch train", "counter");
      m.Set("perch_actor_restarts_total", j.value("actor_restarts", 0.0),
            "actor restarts by perch train", "counter");
      m.Set("perch_actors_given_up", j.value("actors_given_up", 0.0),
            "actors perch train stopped restarting (identical failures)");
    }
  } catch (const std::exception&) {
    // A file being replaced right now: next second.
  }
  m.Set("perch_samples_total", counters_.samples(), "env steps trained on", "counter");
  m.Set("perch_episodes_total", counters_.episodes(), "episodes finished", "counter");
  m.Set("perch_segments_total", counters_.segments(), "segments accepted", "counter");
  m.Set("perch_dropped_stale_total", counters_.dropped_stale(), "segments dropped for policy lag",
        "counter");
  m.Set("perch_rejected_total", counters_.rejected(), "messages that failed to parse/validate",
        "counter");
  for (const auto& [reason, n] : stats_.rejected_by_kind) {
    m.SetLabelled("perch_rejected_by_reason_total", "reason", reason, static_cast<double>(n),
                  "rejected messages (ppo: segments of a batch PPO refused), by reason", "counter");
  }
  m.Set("perch_samples_per_second", last_samples_per_s_, "samples/s over the last update");
  m.Set("perch_policy_lag", last_lag_mean_, "mean policy lag of the last batch, in versions");
  m.Set("perch_return_mean", last_return_mean_, "mean episode return of the last batch");
  m.Set("perch_actors", ActorsAlive(), "actors heard from within actor_timeout_s");
  m.Set("perch_hellos_total", stats_.hellos, "actor hellos (process starts)", "counter");
  m.Set("perch_heartbeats_total", stats_.heartbeats, "actor heartbeats", "counter");
  m.Set("perch_messages_total", stats_.messages, "messages received on the rollout socket",
        "counter");
  m.Set("perch_weights_republished_total", stats_.weights_republished,
        "weights resent to (re)subscribing actors", "counter");
  m.Set("perch_weights_version", static_cast<double>(version()), "published weights version");
  m.Set("perch_credit_segments", credit_segments_,
        "segments each actor may send per weights version (0: no flow control)");
  m.Set("perch_credit_regrants_total", stats_.credit_regrants,
        "fresh credit grants because the batch stopped filling", "counter");
  m.Set("perch_auth_refused_total", static_cast<double>(auth_refused()),
        "connections refused at the CURVE handshake (no authorized key)", "counter");
  m.Set("perch_handshake_failures_total", static_cast<double>(handshake_failures_),
        "failed handshakes on the rollout/weights sockets (no CURVE, wrong keys)", "counter");
  m.Set("perch_nonfinite_updates_total", static_cast<double>(nonfinite_updates_),
        "PPO updates discarded because they left a non-finite weight or statistic", "counter");
}

void LearnerService::Run() {
  start_s_ = MonotonicSeconds();
  last_update_s_ = start_s_;
  ProgressConfig pc;
  pc.max_samples = setup_.cluster.max_samples;
  pc.target_success = setup_.cluster.target_success;
  pc.target_window = setup_.cluster.target_window;
  pc.control_dt = setup_.control_dt;
  progress_ = std::make_unique<RunProgress>(pc, counters_.samples(), start_s_);
  stop_reason_ = "stopped";
  GrantCredit();
  UpdateGauges();
  zmq::pollitem_t items[] = {{rollout_sock_.handle(), 0, ZMQ_POLLIN, 0},
                             {weights_sock_.handle(), 0, ZMQ_POLLIN, 0}};
  double last_gauges = start_s_;
  const auto stopping = [&] { return options_.stop && options_.stop->load(); };
  while (!stopping()) {
    if (options_.max_updates > 0 &&
        counters_.updates() >= static_cast<uint64_t>(options_.max_updates)) {
      stop_reason_ = "max_updates";
      break;
    }
    // A budget or target reached (a resumed run may start past its budget): end by itself.
    if (const std::string why = progress_->StopReason(); !why.empty()) {
      stop_reason_ = why;
      break;
    }
    try {
      zmq::poll(items, 2, std::chrono::milliseconds(100));
    } catch (const zmq::error_t& e) {
      // A signal (Ctrl-C, SIGTERM) interrupts the poll: loop to see the stop flag, then write
      // the final checkpoint.
      if (e.num() != EINTR) throw;
      continue;
    }
    if (items[1].revents & ZMQ_POLLIN) {
      zmq::message_t sub;
      bool any_subscribe = false;
      while (weights_sock_.recv(sub, zmq::recv_flags::dontwait)) {
        any_subscribe |= sub.size() > 0 && static_cast<const char*>(sub.data())[0] == 1;
      }
      // A late joiner or a reconnecting actor gets the current weights now, not at the next
      // update; subscriptions within republish_min_interval_s share one resend.
      republish_pending_ |= any_subscribe;
    }
    if (republish_pending_) {
      const double now = MonotonicSeconds();
      if (now - last_republish_s_ >= options_.republish_min_interval_s) {
        Publish(true);
        last_republish_s_ = now;
        republish_pending_ = false;
      }
    }
    if (items[0].revents & ZMQ_POLLIN) {
      zmq::message_t msg;
      // Drain what is queued, but train as soon as a batch is full.
      while (batch_samples_ < static_cast<uint64_t>(setup_.ppo.steps_per_update) &&
             rollout_sock_.recv(msg, zmq::recv_flags::dontwait)) {
        HandleRollout(msg);
      }
    }
    // A drain after an update may fill the next batch at once: train it now, not after a poll.
    while (batch_samples_ >= static_cast<uint64_t>(setup_.ppo.steps_per_update) && !stopping() &&
           group_end_.empty() &&
           (options_.max_updates == 0 ||
            counters_.updates() < static_cast<uint64_t>(options_.max_updates))) {
      Train();
    }
    if (!group_end_.empty()) {
      stop_reason_ = stopping() ? "stopped" : group_end_;
      break;
    }
    const double now = MonotonicSeconds();
    // Flow control: a batch that stopped filling (an actor left with its credit, or the actors
    // counted alive are fewer than the grant assumed) gets a fresh grant.
    if (setup_.cluster.credit_slack > 0) {
      if (now - std::max(last_segment_s_, last_grant_s_) >= setup_.cluster.credit_regrant_s) {
        ++stats_.credit_regrants;
        GrantCredit(/*stalled=*/true);
      } else if (credit_pending_ && now - last_grant_s_ >= options_.republish_min_interval_s) {
        GrantCredit();  // actors joined; a flood of hellos costs one grant per interval
      }
    }
    if (now - last_gauges >= 1.0) {
      DrainMonitors();
      PruneActors(now);
      UpdateGauges();
      last_gauges = now;
    }
  }
  // The others stop at their next operation rather than wait for this one.
  if (group_) group_->Leave();
  if (static_cast<int64_t>(counters_.updates()) != last_checkpoint_update_) SaveCheckpoint();
  UpdateGauges();
  progress_->OnUpdate(counters_.samples(), MonotonicSeconds());
  spdlog::info("{}", progress_->Summary(counters_.updates(), stop_reason_, last_checkpoint_path_,
                                        train_time_base_s_ + MonotonicSeconds() - start_s_));
  // Why the run ended, for whoever drives it (perch recipe tells a finished stage from one that
  // was stopped). Only the group's rank 0 owns the run dir's files.
  if (options_.group_rank == 0) {
    try {
      SaveJsonFileAtomic(options_.run_dir + "/end.json",
                         Json{{"stop_reason", stop_reason_},
                              {"updates", counters_.updates()},
                              {"samples", counters_.samples()},
                              {"checkpoint", last_checkpoint_path_}});
    } catch (const std::exception& e) {
      spdlog::warn("learner: cannot write {}/end.json: {}", options_.run_dir, e.what());
    }
  }
  spdlog::info("learner: stopped at update {} ({} samples, {} stale, {} rejected)",
               counters_.updates(), counters_.samples(), counters_.dropped_stale(),
               counters_.rejected());
}

}  // namespace perch
