#include "actor/actor.h"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <thread>

#include "common/proto/model.pb.h"
#include "protocol/clock.h"
#include "protocol/security.h"
#include "protocol/wire.h"

namespace perch {

namespace {
constexpr double kUnreachableLogS = 5.0;  // [s] between "cannot reach the learner" lines
}  // namespace

ActorService::ActorService(zmq::context_t& ctx, const ActorSetup& setup,
                           const ActorOptions& options)
    : setup_(setup),
      options_(options),
      task_(TaskFromName(setup.cluster.task, "cluster.task")),
      push_(ctx, zmq::socket_type::push),
      sub_(ctx, zmq::socket_type::sub),
      runner_(setup.policy, setup.obs_norm),
      // Same seed and actor id -> same stream of actions and env episodes.
      rng_(setup.seed * 0x9E3779B97F4A7C15ULL + options.actor_id + 1),
      lag_rng_(setup.seed * 0xD1B54A32D192ED03ULL + options.actor_id + 7) {
  if (options_.num_envs < 1) throw ConfigError("--envs: must be >= 1");
  // An identifier of this process start (not used for any result).
  Rng id_rng(static_cast<uint64_t>(MonotonicSeconds() * 1e9) ^
             (static_cast<uint64_t>(::getpid()) << 20) ^ options.actor_id);
  instance_ = id_rng.NextU64();
  credit_carry_ = id_rng.Uniform();  // flow control: actors on fractional grants take turns
  if (options_.replay && options_.replay->empty())
    throw ConfigError("actor: no segments to replay");
  for (int i = 0; i < options_.num_envs && !options_.replay; ++i) {
    envs_.push_back(setup_.make_env());
    Env* env = envs_.back().get();
    if (env->spec().obs_dim != setup_.policy.obs_dim) {
      throw ConfigError("actor: env obs_dim " + std::to_string(env->spec().obs_dim) +
                        " != policy obs_dim " + std::to_string(setup_.policy.obs_dim));
    }
    env->Seed(rng_.NextU64());
    const uint64_t stream = (uint64_t{options_.actor_id} << 20) | static_cast<uint64_t>(i);
    collectors_.push_back(std::make_unique<RolloutCollector>(env, stream));
    if (auto* f = dynamic_cast<FrozenPolicyEnv*>(env)) {
      frozen_envs_.push_back(f);
      frozen_ready_ = false;
    }
  }
  push_.set(zmq::sockopt::immediate, 1);  // queue only to a connected learner
  push_.set(zmq::sockopt::sndhwm, options_.num_envs);
  push_.set(zmq::sockopt::sndtimeo, 200);
  push_.set(zmq::sockopt::linger, 1000);
  push_.set(zmq::sockopt::reconnect_ivl, setup_.cluster.reconnect_ivl_ms);
  sub_.set(zmq::sockopt::reconnect_ivl, setup_.cluster.reconnect_ivl_ms);
  sub_.set(zmq::sockopt::maxmsgsize, static_cast<int64_t>(setup_.cluster.max_message_bytes));
  sub_.set(zmq::sockopt::subscribe, "");
  sub_.set(zmq::sockopt::linger, 0);
  if (!setup_.cluster.insecure &&
      (NeedsCurve(options_.rollout_connect) || NeedsCurve(options_.weights_connect))) {
    const CurveKeys keys = ReadActorKeys(KeysDir(setup_.cluster));
    MakeCurveClient(push_, keys);
    MakeCurveClient(sub_, keys);
  }
  push_.connect(options_.rollout_connect);
  sub_.connect(options_.weights_connect);
}

ActorService::~ActorService() = default;

void ActorService::TouchAliveFile() {
  if (options_.alive_file.empty()) return;
  const double now = MonotonicSeconds();
  if (now - last_alive_touch_s_ < 1.0) return;
  last_alive_touch_s_ = now;
  // Created if missing; an existing file gets a new mtime.
  std::ofstream(options_.alive_file, std::ios::app).flush();
  ::utimensat(AT_FDCWD, options_.alive_file.c_str(), nullptr, 0);
}

bool ActorService::Send(const std::string& bytes) {
  const double t0 = MonotonicSeconds();
  double last_log = t0;
  while (!Stopping()) {
    try {
      if (push_.send(zmq::buffer(bytes), zmq::send_flags::none)) {
        counters_.bytes_sent += bytes.size();
        if (MonotonicSeconds() - t0 >= kUnreachableLogS) {
          spdlog::info("actor: the learner at {} is reachable again after {:.0f} s",
                       options_.rollout_connect, MonotonicSeconds() - t0);
        }
        return true;
      }
    } catch (const zmq::error_t& e) {
      if (e.num() != EINTR) throw;
    }
    TouchAliveFile();  // waiting for the learner is not being stuck
    // An operator must see why nothing trains: say so every few seconds while it lasts.
    if (const double now = MonotonicSeconds(); now - last_log >= kUnreachableLogS) {
      last_log = now;
      spdlog::warn(
          "actor: cannot reach the learner at {} for {:.0f} s (not running, unreachable, or "
          "refusing this actor's key); a segment is waiting",
          options_.rollout_connect, now - t0);
    }
    // Timed out: the learner is away (restarting). Keep weights fresh meanwhile.
    PollWeights(0);
  }
  return false;
}

void ActorService::SendHello() {
  proto::ActorMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  proto::Hello* h = m.mutable_hello();
  h->set_actor_id(options_.actor_id);
  h->set_actor_instance(instance_);
  char host[256] = {0};
  ::gethostname(host, sizeof(host) - 1);
  h->set_hostname(host);
  h->set_num_envs(options_.num_envs);
  h->set_env_name(spec().name);
  h->set_obs_dim(spec().obs_dim);
  h->set_act_dim(spec().act_dim);
  Send(m.SerializeAsString());
}

void ActorService::MaybeHeartbeat() {
  const double now = MonotonicSeconds();
  if (now - last_heartbeat_s_ < setup_.cluster.heartbeat_s) return;
  last_heartbeat_s_ = now;
  proto::ActorMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  TouchAliveFile();
  proto::Heartbeat* h = m.mutable_heartbeat();
  h->set_actor_id(options_.actor_id);
  h->set_actor_instance(instance_);
  h->set_env_steps(counters_.env_steps);
  h->set_segments_sent(counters_.segments_sent);
  h->set_weights_version(runner_.version());
  h->set_uptime_s(now - start_s_);
  Send(m.SerializeAsString());
}

// A grant is what this actor may send stamped with the current version: a new version starts the
// count again, a new grant for the same version only moves the limit. Fractional grants add up
// across versions (credit_carry_): 0.25 is one segment every fourth version. The carry starts at
// a fraction drawn per process, so that many actors on small grants take turns.
void ActorService::TakeCredit(const proto::Weights& w) {
  const bool new_version = w.run_id() != credit_run_id_ || w.version() != credit_version_;
  if (new_version) {
    if (credit_run_id_ != 0 || credit_version_ != ~uint64_t{0}) {
      // What the last version's grant left unused is not carried (the learner has moved on);
      // only its fraction is.
      credit_carry_ = credit_base_ + credit_segments_ - std::floor(credit_base_ + credit_segments_);
    }
    credit_run_id_ = w.run_id();
    credit_version_ = w.version();
    credit_base_ = credit_carry_;
    sent_in_grant_ = 0;
  }
  credit_segments_ = w.credit_segments();
  credit_epoch_ = w.credit_epoch();
  credit_allowance_ =
      credit_segments_ > 0 ? static_cast<uint64_t>(std::floor(credit_base_ + credit_segments_)) : 0;
}

void ActorService::WaitForCredit() {
  if (credit_segments_ <= 0 || sent_in_grant_ < credit_allowance_) return;
  // The learner has all it will use from this version: wait for the next one (or a new grant)
  // rather than make samples that would be dropped as stale.
  ++counters_.credit_waits;
  const double t0 = MonotonicSeconds();
  while (!Stopping() && credit_segments_ > 0 && sent_in_grant_ >= credit_allowance_) {
    PollWeights(50);
    MaybeHeartbeat();
  }
  counters_.credit_wait_s += MonotonicSeconds() - t0;
}

bool ActorService::PollWeights(int timeout_ms) {
  zmq::message_t msg, newest;
  bool got = false;
  zmq::pollitem_t item{sub_.handle(), 0, ZMQ_POLLIN, 0};
  try {
    if (zmq::poll(&item, 1, std::chrono::milliseconds(timeout_ms)) <= 0) return false;
  } catch (const zmq::error_t& e) {
    if (e.num() != EINTR) throw;  // a stop signal: the caller sees the flag
    return false;
  }
  while (sub_.recv(msg, zmq::recv_flags::dontwait)) {
    ++counters_.weights_messages;
    counters_.weights_bytes += msg.size();
    newest.move(msg);
    got = true;
  }
  if (!got) return false;
  proto::LearnerMessage m;
  std::string why;
  if (ParseLearnerMessage(newest.data(), newest.size(), setup_.cluster.max_message_bytes, &m,
                          &why) != WireReject::kOk) {
    ++counters_.weights_rejected;
    spdlog::warn("actor {}: dropped weights message: {}", options_.actor_id, why);
    return false;
  }
  const proto::Weights& w = m.weights();
  // An actor built from the learner's config follows it: another config, or another run (whose
  // config may have gone by before this actor reconnected), means fetching it anew.
  if (options_.end_on_new_config &&
      ((!w.experiment_config_json().empty() && w.experiment_config_json() != setup_.config_json) ||
       (have_weights_ && w.run_id() != weights_run_id_))) {
    spdlog::info("actor {}: the learner's experiment changed; rebuilding", options_.actor_id);
    config_changed_ = true;
    return false;
  }
  TakeFrozen(w);
  if (have_weights_ && w.run_id() == weights_run_id_ && w.version() == runner_.version()) {
    // Same weights: a republish for someone else, or a fresh credit grant for this version.
    if (w.credit_epoch() != credit_epoch_) TakeCredit(w);
    return false;
  }
  for (const proto::TaskPolicy& p : w.policies()) {
    if (p.task() != task_ || p.frozen()) continue;
    try {
      runner_.LoadWeights(p.model());
    } catch (const ConfigError& e) {
      ++counters_.weights_rejected;
      spdlog::error("actor {}: weights do not fit this actor: {}", options_.actor_id, e.what());
      config_changed_ = options_.end_on_new_config;  // another experiment's: fetch it
      return false;
    }
    if (have_weights_ && w.run_id() != weights_run_id_) {
      spdlog::info("actor {}: learner run changed, now at version {}", options_.actor_id,
                   w.version());
    }
    if (setup_.cluster.simulated_lag > 0) {
      if (w.run_id() != weights_run_id_) lag_history_.clear();
      lag_history_.push_front(runner_);
      while (lag_history_.size() > static_cast<size_t>(setup_.cluster.simulated_lag) + 1) {
        lag_history_.pop_back();
      }
    }
    weights_run_id_ = w.run_id();
    have_weights_ = true;
    ++counters_.weights_loaded;
    TakeCredit(w);
    return true;
  }
  ++counters_.weights_rejected;
  spdlog::error("actor {}: weights hold no policy for task {}", options_.actor_id, TaskName(task_));
  config_changed_ = options_.end_on_new_config;  // another experiment's: fetch it
  return false;
}

void ActorService::TakeFrozen(const proto::Weights& w) {
  if (frozen_ready_) return;  // the first set is kept: a run's subtasks never change
  std::vector<FrozenPolicyData> frozen;
  for (const proto::TaskPolicy& p : w.policies()) {
    if (p.frozen()) frozen.push_back(FrozenPolicyFromProto(p));
  }
  if (frozen.empty()) return;
  try {
    for (FrozenPolicyEnv* e : frozen_envs_) e->SetFrozenPolicies(frozen);
  } catch (const ConfigError& e) {
    // Not this actor's to fix: the learner's subtasks do not fit this env (another build or
    // config). Said once per message; the actor keeps waiting rather than crash-looping.
    ++counters_.weights_rejected;
    spdlog::error("actor {}: the learner's frozen policies do not fit this env: {}",
                  options_.actor_id, e.what());
    return;
  }
  frozen_ready_ = true;
  std::string names;
  for (const FrozenPolicyData& f : frozen) names += (names.empty() ? "" : ", ") + f.name;
  spdlog::info("actor {}: frozen policies from the learner: {}", options_.actor_id, names);
}

void ActorService::Produce(size_t i, PolicyRunner* runner, Rollout* out, EpisodeStats* eps) {
  if (!options_.replay) {
    collectors_[i]->Collect(runner, rng_, setup_.cluster.segment_steps, out, eps);
    return;
  }
  const RecordedSegment& rec = (*options_.replay)[replay_next_++ % options_.replay->size()];
  *out = rec.rollout;
  out->policy_version = runner->version();
  out->stream_id = (uint64_t{options_.actor_id} << 20) | static_cast<uint64_t>(i);
  *eps = rec.episodes;
  if (options_.replay_samples_per_s > 0) {
    // Paced like an actor core that makes replay_samples_per_s; heartbeats and weights meanwhile.
    const double now = MonotonicSeconds();
    replay_due_s_ =
        std::max(replay_due_s_, now - 1.0) + out->size() / options_.replay_samples_per_s;
    while (!Stopping() && MonotonicSeconds() < replay_due_s_) {
      PollWeights(static_cast<int>(std::ceil(1e3 * (replay_due_s_ - MonotonicSeconds()))));
      MaybeHeartbeat();
    }
  }
}

bool FetchLearnerExperiment(zmq::context_t& ctx, const std::string& weights_connect,
                            const ClusterConfig& cluster, const std::atomic<bool>* stop,
                            LearnerExperiment* out) {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::reconnect_ivl, cluster.reconnect_ivl_ms);
  sub.set(zmq::sockopt::maxmsgsize, static_cast<int64_t>(cluster.max_message_bytes));
  sub.set(zmq::sockopt::subscribe, "");
  sub.set(zmq::sockopt::linger, 0);
  if (!cluster.insecure && NeedsCurve(weights_connect)) {
    MakeCurveClient(sub, ReadActorKeys(KeysDir(cluster)));
  }
  sub.connect(weights_connect);
  zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
  while (!(stop && stop->load())) {
    try {
      if (zmq::poll(&item, 1, std::chrono::milliseconds(200)) <= 0) continue;
    } catch (const zmq::error_t& e) {
      if (e.num() != EINTR) throw;
      continue;
    }
    zmq::message_t msg;
    while (sub.recv(msg, zmq::recv_flags::dontwait)) {
      proto::LearnerMessage m;
      std::string why;
      if (ParseLearnerMessage(msg.data(), msg.size(), cluster.max_message_bytes, &m, &why) !=
          WireReject::kOk) {
        spdlog::warn("actor: dropped a weights message: {}", why);
        continue;
      }
      if (m.weights().experiment_config_json().empty()) continue;
      out->config_json = m.weights().experiment_config_json();
      out->files.assign(m.weights().config_files().begin(), m.weights().config_files().end());
      return true;
    }
  }
  return false;
}

void ActorService::Run() {
  start_s_ = MonotonicSeconds();
  last_heartbeat_s_ = start_s_;
  SendHello();
  double waited_since = MonotonicSeconds();
  while ((!have_weights_ || !frozen_ready_) && !Stopping()) {
    PollWeights(200);
    const double now = MonotonicSeconds();
    if (have_weights_ && !frozen_ready_ && now - last_resubscribe_s_ > 2.0) {
      // The frozen policies come with the first weights and with every new subscription: one
      // missed (or refused) is asked for again by subscribing anew.
      sub_.set(zmq::sockopt::unsubscribe, "");
      sub_.set(zmq::sockopt::subscribe, "");
      last_resubscribe_s_ = now;
    }
    if ((!have_weights_ || !frozen_ready_) && now - waited_since > 10.0) {
      spdlog::info("actor {}: waiting for {} from {}", options_.actor_id,
                   have_weights_ ? "the frozen subtask policies" : "weights",
                   options_.weights_connect);
      waited_since = now;
    }
  }
  if (have_weights_) {
    spdlog::info("actor {}: {} envs, weights version {}", options_.actor_id, options_.num_envs,
                 runner_.version());
  }
  const size_t streams = options_.replay ? static_cast<size_t>(options_.num_envs) : envs_.size();
  std::vector<Rollout> rollouts(streams);
  proto::ActorMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  std::vector<uint64_t> segment_index(streams, 0);
  for (int64_t seg = 0; !Stopping() && (options_.max_segments == 0 || seg < options_.max_segments);
       ++seg) {
    // One segment per env with the same weights, then take new weights (between segments).
    for (size_t i = 0; i < streams && !Stopping(); ++i) {
      WaitForCredit();
      if (Stopping()) break;
      EpisodeStats eps;
      PolicyRunner* runner = &runner_;
      if (!lag_history_.empty()) {
        runner = &lag_history_[lag_rng_.UniformInt(lag_history_.size())];
      }
      Produce(i, runner, &rollouts[i], &eps);
      if (Stopping()) break;
      counters_.env_steps += rollouts[i].size();
      counters_.episodes += eps.returns.size();
      proto::Segment* s = m.mutable_segment();
      s->Clear();
      s->set_actor_id(options_.actor_id);
      s->set_actor_instance(instance_);
      s->set_env_index(static_cast<uint32_t>(i));
      s->set_segment_index(segment_index[i]++);
      s->set_task(task_);
      proto::PolicyVersion* pv = s->add_policy_versions();
      pv->set_task(task_);
      // (runner may be gone: replay pacing takes new weights, which can drop the oldest runner)
      pv->set_version(rollouts[i].policy_version);
      rollouts[i].ToProto(s->mutable_rollout());
      // Episodes ended, in order, at the steps flagged terminated or truncated.
      const bool has_success = spec().has_success;
      size_t e = 0;
      const Rollout& r = rollouts[i];
      for (int t = 0; t < r.size() && e < eps.returns.size(); ++t) {
        if (!r.terminated[t] && !r.truncated[t]) continue;
        proto::EpisodeStats* es = s->add_episodes();
        es->set_episode_return(eps.returns[e]);
        es->set_length(static_cast<uint32_t>(eps.lengths[e]));
        es->set_terminated(r.terminated[t] != 0);
        if (has_success) {
          es->set_has_success(true);
          es->set_success(e < eps.succeeded.size() && eps.succeeded[e] != 0);
        }
        ++e;
      }
      s->set_bootstrap_value(
          rollouts[i].bootstrap_values.empty() ? 0.0f : rollouts[i].bootstrap_values.back());
      if (!Send(m.SerializeAsString())) break;
      ++counters_.segments_sent;
      ++sent_in_grant_;
    }
    PollWeights(0);
    MaybeHeartbeat();
  }
  spdlog::info("actor {}: stopped after {} segments, {} env steps; waited {:.1f} s for credit",
               options_.actor_id, counters_.segments_sent, counters_.env_steps,
               counters_.credit_wait_s);
}

}  // namespace perch
