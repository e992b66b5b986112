#include "recipe/runner.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include "actor/process.h"
#include "common/config_file.h"
#include "common/file_util.h"
#include "common/paths.h"

namespace perch {
namespace {

namespace fs = std::filesystem;

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
// Wall-clock seconds since the epoch: what another process (status) can compare with.
double UnixNow() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string UtcStamp() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

std::string Duration(double s) {
  if (!(s >= 0) || !std::isfinite(s)) return "?";
  const int64_t t = std::llround(s);
  char buf[32];
  if (t >= 3600) {
    std::snprintf(buf, sizeof(buf), "%lldh%02lldm", static_cast<long long>(t / 3600),
                  static_cast<long long>(t / 60 % 60));
  } else if (t >= 60) {
    std::snprintf(buf, sizeof(buf), "%lldm%02llds", static_cast<long long>(t / 60),
                  static_cast<long long>(t % 60));
  } else {
    std::snprintf(buf, sizeof(buf), "%llds", static_cast<long long>(t));
  }
  return buf;
}

std::string Count(double n) {
  char buf[32];
  if (n >= 1e6) {
    std::snprintf(buf, sizeof(buf), "%.2fM", n / 1e6);
  } else if (n >= 1e3) {
    std::snprintf(buf, sizeof(buf), "%.1fk", n / 1e3);
  } else {
    std::snprintf(buf, sizeof(buf), "%.0f", n);
  }
  return buf;
}

// The newest metrics row of a run: its sample count (0 when none yet). Reads only the file's end.
int64_t RunSamples(const std::string& run_dir) {
  std::ifstream in(run_dir + "/metrics.jsonl", std::ios::binary);
  if (!in) return 0;
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  const std::streamoff take = std::min<std::streamoff>(size, 16384);
  in.seekg(size - take);
  std::string tail(static_cast<size_t>(take), '\0');
  in.read(tail.data(), take);
  std::istringstream lines(tail);
  int64_t samples = 0;
  for (std::string l; std::getline(lines, l);) {
    if (l.empty() || l[0] != '{') continue;
    const Json j = Json::parse(l, nullptr, false);
    if (j.is_object() && j.contains("samples") && j["samples"].is_number()) {
      samples = j["samples"].get<int64_t>();
    }
  }
  return samples;
}

std::vector<std::string> Checkpoints(const std::string& run_dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (fs::directory_iterator it(run_dir + "/checkpoints", ec), end; !ec && it != end;
       it.increment(ec)) {
    const std::string n = it->path().filename().string();
    if (n.rfind("ckpt-", 0) == 0 && n.size() > 9 && n.substr(n.size() - 4) == ".bin") {
      out.push_back(it->path().string());
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Figures of a JSON result: the named fields, or every top-level number, string or bool plus
// success_ci95 when none are named.
Json FiguresOf(const Json& result, const std::vector<std::string>& names) {
  Json f = Json::object();
  if (!result.is_object()) return f;
  if (!names.empty()) {
    for (const std::string& n : names) {
      if (result.contains(n)) f[n] = result[n];
    }
    return f;
  }
  for (auto it = result.begin(); it != result.end(); ++it) {
    if (it->is_number() || it->is_boolean() ||
        (it->is_string() && it->get<std::string>().size() < 200)) {
      f[it.key()] = *it;
    }
  }
  if (result.contains("success_ci95")) f["success_ci95"] = result["success_ci95"];
  return f;
}

// An exclusive lock on D held for the runner's life: two runners on one directory would write
// the same files. Status probes it to tell a live run from an interrupted one.
class DirLock {
 public:
  explicit DirLock(const std::string& dir) {
    path_ = dir + "/.recipe.lock";
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);  // not held by children
    if (fd_ < 0) throw ConfigError(path_ + ": cannot open the lock file");
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd_);
      fd_ = -1;
      throw ConfigError(dir + ": another `perch recipe run` is running in this directory");
    }
  }
  ~DirLock() {
    if (fd_ >= 0) ::close(fd_);
  }
  static bool Held(const std::string& dir) {
    const int fd = ::open((dir + "/.recipe.lock").c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return false;
    const bool held = ::flock(fd, LOCK_SH | LOCK_NB) != 0;
    ::close(fd);
    return held;
  }

 private:
  std::string path_;
  int fd_ = -1;
};

struct Live {
  std::string phase;    // what the stage is doing now
  int64_t samples = 0;  // train: samples so far
  // The first sample count this attempt read, and when: the rate counts from there, so a
  // resumed run's earlier samples (or a missing metrics file read as 0) do not inflate it.
  int64_t samples0 = -1;
  double ts0 = 0.0;
  double t0 = 0.0;  // this attempt's start
  std::atomic<bool> finished{false};
  std::atomic<int> code{0};  // 0 done, 1 failed, 130 stopped
};

// ---- eval shards: a file-claim queue in the stage's shards/ directory ---------------------------
// plan.json lists each shard's perch eval arguments and files; a shard is done when its result
// (its --json) is there; whoever runs it holds shard-K.claim ("host pid"), touched every few
// seconds. The runner and any `perch recipe worker` on the same directory take shards from it.

std::string HostName() {
  char h[256] = {0};
  if (gethostname(h, sizeof(h) - 1) != 0) return "host";
  return h;
}

std::string ClaimOwner() { return HostName() + " " + std::to_string(getpid()); }

// A claim is stale when its holder stopped touching it (stale_s), or on this host its process is
// gone (a killed runner's shard is taken over at once).
bool StaleClaim(const std::string& claim, double stale_s) {
  struct stat st;
  if (stat(claim.c_str(), &st) != 0) return false;
  if (std::difftime(std::time(nullptr), st.st_mtime) > stale_s) return true;
  std::istringstream in(ReadFileBytes(claim));
  std::string host;
  long pid = 0;
  if (!(in >> host >> pid)) return false;
  return host == HostName() && pid > 0 && kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
}

// Takes a shard: creates its claim exclusively, or takes over a stale one.
bool TryClaim(const std::string& claim, double stale_s) {
  int fd = open(claim.c_str(), O_CREAT | O_EXCL | O_WRONLY, 0644);
  if (fd < 0 && errno == EEXIST && StaleClaim(claim, stale_s)) {
    const std::string aside = claim + ".stale-" + std::to_string(getpid());
    if (rename(claim.c_str(), aside.c_str()) != 0) return false;  // another one took it over
    unlink(aside.c_str());
    fd = open(claim.c_str(), O_CREAT | O_EXCL | O_WRONLY, 0644);
  }
  if (fd < 0) return false;
  const std::string who = ClaimOwner() + "\n";
  const bool ok = write(fd, who.data(), who.size()) == static_cast<ssize_t>(who.size());
  close(fd);
  return ok;
}

void TouchClaim(const std::string& claim) { utimensat(AT_FDCWD, claim.c_str(), nullptr, 0); }

constexpr double kClaimStaleS = 60.0;

// Runs one shard of a plan (`exe` its perch): its result committed when it succeeds, and
// shard-K.ran-by naming who ran it. False when stopped or failed (status in *status).
bool RunClaimedShard(const std::string& exe, const Json& shard, const std::string& log,
                     const std::string& claim, const std::atomic<bool>* stop, int* status) {
  std::vector<std::string> argv = {exe};
  for (const Json& a : shard["args"]) argv.push_back(a.get<std::string>());
  const std::string result = shard["result"].get<std::string>();
  {
    std::ofstream l(log, std::ios::app);
    l << "\n== " << UtcStamp() << " perch recipe (shard " << shard["index"].get<int>() << ", "
      << ClaimOwner() << "):";
    for (const std::string& a : argv) l << " " << a;
    l << "\n";
  }
  const pid_t pid = Spawn(argv, log, result + ".tmp");
  double since_touch = 0;
  for (;;) {
    if (WaitFor(pid, 0.5, status)) break;
    since_touch += 0.5;
    if (since_touch >= 5) {
      TouchClaim(claim);
      since_touch = 0;
    }
    if (stop != nullptr && stop->load()) {
      *status = Stop(pid, 10.0);
      return false;
    }
  }
  if (!WIFEXITED(*status) || WEXITSTATUS(*status) != 0) return false;
  CommitFileAtomic(result + ".tmp", result);
  WriteFileAtomic(result.substr(0, result.size() - 5) + ".ran-by", ClaimOwner() + "\n");
  std::remove(claim.c_str());
  return true;
}

std::string ClaimOf(const Json& shard) {
  const std::string r = shard["result"].get<std::string>();
  return r.substr(0, r.size() - 5) + ".claim";  // shard-K.json -> shard-K.claim
}

class Runner {
 public:
  Runner(const RecipeRunFlags& f, Recipe r) : f_(f), r_(std::move(r)) {
    exe_ = f.exe.empty() ? SelfExe() : f.exe;
    dir_ = fs::absolute(f.dir).lexically_normal().string();
  }

  int Run();

 private:
  // The stages asked for (--from .. --until), as indices into r_.stages.
  int from_ = 0, until_ = -1;
  std::string StageDir(const std::string& name) const { return dir_ + "/" + name; }
  std::string OutputPath(const std::string& stage, const std::string& out) const {
    const int i = r_.Index(stage);
    return StageDir(stage) + "/" + StageOutputs(r_.stages[i]).at(out);
  }
  // References resolved to files: an earlier stage's output, this stage's own, its directory.
  // An optional output its stage did not write resolves to "".
  std::string Resolve(const RecipeStage& s, const std::string& str) const {
    return SubstituteRefs(str, [&](const std::string& a, const std::string& b) {
      if (a == "dir") return StageDir(s.name);
      if (a == "out") return StageDir(s.name) + "/" + StageOutputs(s).at(b);
      auto rec = state_.stages.find(a);
      if (rec != state_.stages.end() && rec->second.state == "done" &&
          !rec->second.outputs.count(b)) {
        return std::string();
      }
      return OutputPath(a, b);
    });
  }
  // A --set assignment resolved; in a list value, an element that resolves to "" (an optional
  // output not written) is dropped.
  std::string ResolveSet(const RecipeStage& s, const std::string& set) const {
    const size_t eq = set.find('=');
    if (eq == std::string::npos) return Resolve(s, set);
    const Json v = Json::parse(set.substr(eq + 1), nullptr, false);
    if (!v.is_array()) return Resolve(s, set);
    Json out = Json::array();
    for (const Json& e : v) {
      if (!e.is_string()) {
        out.push_back(e);
        continue;
      }
      const std::string r = Resolve(s, e.get<std::string>());
      if (!r.empty() || e.get<std::string>().empty()) out.push_back(r);
    }
    return set.substr(0, eq + 1) + out.dump();
  }
  Json ComposeConfig(const RecipeStage& scaled, bool resolve) const;
  std::string Fingerprint(const RecipeStage& s);
  std::set<std::string> Forced() const;
  void Save();
  void Progress();
  void RunStage(const RecipeStage& s, Live* live);
  // Runs one child to its end; false when stopped. Sets *status.
  bool RunChild(const std::vector<std::string>& argv, const std::string& log,
                const std::string& stdout_path, Live* live, const std::string& run_dir,
                int* status);
  void Train(const RecipeStage& s, Live* live, StageRecord* rec);
  bool SelectCheckpoint(const RecipeStage& s, const std::vector<std::string>& cand,
                        const std::string& init, Live* live, std::string* chosen, Json* figures);
  void Extend(const std::string& name);
  void Adopt();
  // Run()'s steps: every done stage's outputs still as recorded; the changed stages said (and
  // with --force-from, the stages to redo returned); --from/--until checked; the loop.
  void VerifyOutputs();
  std::vector<std::string> AcceptChanges();
  void SetRange();
  int RunLoop();
  // The loop's two halves: start the ready stages; reap the finished ones (the run's code).
  bool StartReadyStages(std::map<std::string, std::thread>* threads, int code);
  int ReapFinished(std::map<std::string, std::thread>* threads, int code);
  void MoveAside(const std::vector<std::string>& names);
  void Other(const RecipeStage& s, Live* live, StageRecord* rec);
  // A sharded eval stage: its plan, its shards (here and by workers), their merge.
  void RunShards(const RecipeStage& s, const std::vector<std::string>& argv, Live* live,
                 StageRecord* rec);

  RecipeRunFlags f_;
  Recipe r_;
  std::string exe_, dir_;
  RecipeState state_;
  std::mutex mu_;  // state_ and live_
  std::map<std::string, Live> live_;
  std::map<std::string, std::string> fingerprints_;
};

Json Runner::ComposeConfig(const RecipeStage& scaled, bool resolve) const {
  std::vector<std::string> sets;
  for (const std::string& s : scaled.sets) sets.push_back(resolve ? ResolveSet(scaled, s) : s);
  if (scaled.kind == "train") {
    sets.push_back("cluster.max_samples=" + std::to_string(scaled.max_samples));
    sets.push_back("cluster.target_success=" + Json(scaled.target_success).dump());
    if (scaled.target_window > 0) {
      sets.push_back("cluster.target_window=" + std::to_string(scaled.target_window));
    }
  }
  Json c = LoadComposedConfig(ResolveProjectPath(scaled.config), sets);
  if (scaled.kind == "train" && scaled.select.last_k > 0) {
    // The selection needs the newest K checkpoints on disk.
    int keep = 3;
    if (c.contains("cluster") && c["cluster"].contains("keep_last") &&
        c["cluster"]["keep_last"].is_number_integer()) {
      keep = c["cluster"]["keep_last"].get<int>();
    }
    c["cluster"]["keep_last"] = std::max(keep, scaled.select.last_k);
  }
  return c;
}

std::string Runner::Fingerprint(const RecipeStage& st) {
  const RecipeStage s = ScaledStage(st, f_.options);
  std::map<std::string, std::string> inputs;
  for (const std::string& d : s.deps) {
    auto it = state_.stages.find(d);
    if (it == state_.stages.end() || it->second.state != "done") return "";
    for (const auto& [name, sha] : it->second.output_sha256) inputs[d + "." + name] = sha;
  }
  const Json cfg = s.config.empty() ? Json() : ComposeConfig(s, false);
  return StageFingerprint(s, cfg, inputs);
}

void Runner::Save() {
  state_.recipe_path = r_.path;
  state_.recipe_name = r_.name;
  state_.scale = f_.options.scale;
  SaveRecipeState(dir_, state_);
}

bool Runner::RunChild(const std::vector<std::string>& argv, const std::string& log,
                      const std::string& stdout_path, Live* live, const std::string& run_dir,
                      int* status) {
  {
    std::ofstream l(log, std::ios::app);
    l << "\n== " << UtcStamp() << " perch recipe:";
    for (const std::string& a : argv) l << " " << a;
    l << "\n";
  }
  // The child lives no longer than this thread (PR_SET_PDEATHSIG): the thread waits for it.
  const pid_t pid = Spawn(argv, log, stdout_path);
  for (;;) {
    if (WaitFor(pid, 0.5, status)) return true;
    if (!run_dir.empty()) {
      const int64_t n = RunSamples(run_dir);
      std::lock_guard<std::mutex> g(mu_);
      live->samples = n;
      if (live->samples0 < 0 && n > 0) {
        live->samples0 = n;
        live->ts0 = Now();
      }
    }
    if (f_.stop && f_.stop->load()) {
      // perch train writes a final checkpoint on SIGTERM; give it time.
      *status = Stop(pid, 60.0);
      return false;
    }
  }
}

// The delivered checkpoint of a finished run: each candidate evaluated on the selection seed
// (cached in the stage's select/), the best by select.metric into *chosen, the table into
// *figures. `init` (select.include_init: the policy the run started from), when given, is the
// oldest candidate, named "init". False when stopped.
bool Runner::SelectCheckpoint(const RecipeStage& s, const std::vector<std::string>& checkpoints,
                              const std::string& init, Live* live, std::string* chosen,
                              Json* figures) {
  std::vector<std::string> cand, names;
  if (!init.empty()) {
    cand.push_back(init);
    names.push_back("init");
  }
  for (const std::string& c : checkpoints) {
    cand.push_back(c);
    names.push_back(fs::path(c).stem().string());
  }
  const std::string sd = StageDir(s.name);
  const std::string log = sd + "/stage.log";
  std::error_code ec;
  int status = 0;
  fs::create_directories(sd + "/select", ec);
  Json table = Json::array();
  double best = 0;
  bool have = false;
  for (size_t i = 0; i < cand.size(); ++i) {
    const std::string& name = names[i];
    const std::string out = sd + "/select/" + name + ".json";
    Json result;
    if (fs::exists(out)) result = Json::parse(ReadFileBytes(out), nullptr, false);
    // A result of another selection (other episodes or seed, e.g. after --extend) is redone.
    const bool current = result.is_object() && result.contains(s.select.metric) &&
                         result.value("episodes", -1) == s.select.episodes &&
                         result.value("seed", Json()) == Json(s.select.seed);
    if (!current) {
      {
        std::lock_guard<std::mutex> g(mu_);
        live->phase = "selecting: " + name + " (" + std::to_string(i + 1) + " of " +
                      std::to_string(cand.size()) + ")";
      }
      std::vector<std::string> a = {exe_,         "eval",
                                    "--model",    cand[i],
                                    "--episodes", std::to_string(s.select.episodes),
                                    "--seed",     std::to_string(s.select.seed),
                                    "--json"};
      for (const std::string& x : s.select.args) a.push_back(Resolve(s, x));
      if (!RunChild(a, log, out + ".tmp", live, "", &status)) return false;
      if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        throw std::runtime_error("selection eval of " + cand[i] + " " + DescribeStatus(status) +
                                 "; " + log + ":\n" + LastLines(log, 15));
      }
      CommitFileAtomic(out + ".tmp", out);
      result = Json::parse(ReadFileBytes(out), nullptr, false);
    }
    if (!result.is_object() || !result.contains(s.select.metric) ||
        !result[s.select.metric].is_number()) {
      throw std::runtime_error(out + ": no number \"" + s.select.metric + "\" (select.metric)");
    }
    const double v = result[s.select.metric].get<double>();
    table.push_back(Json{{"checkpoint", name}, {s.select.metric, v}});
    // Ties go to the newer checkpoint (later in the list).
    const bool better = !have || (s.select.lower_is_better ? v <= best : v >= best);
    if (better) {
      best = v;
      *chosen = cand[i];
      have = true;
    }
  }
  (*figures)["selection"] = table;
  (*figures)["selection_seed"] = s.select.seed;
  (*figures)["selection_episodes"] = s.select.episodes;
  (*figures)[s.select.metric] = best;
  return true;
}

void Runner::Train(const RecipeStage& s, Live* live, StageRecord* rec) {
  const std::string sd = StageDir(s.name);
  const std::string run = sd + "/run";
  const std::string log = sd + "/stage.log";
  const std::string cfg_path = sd + "/config.json";
  SaveJsonFileAtomic(cfg_path, ComposeConfig(s, true));
  std::error_code ec;
  fs::remove(run + "/end.json", ec);
  // A local run's ports are picked afresh; one taken between the pick and the bind ("Address
  // already in use") is picked again, a few times, rather than failing the recipe.
  int status = 0;
  for (int attempt = 1;; ++attempt) {
    const bool resume = !Checkpoints(run).empty();
    std::vector<std::string> argv;
    if (f_.cluster) {
      const std::string b = "tcp://" + f_.bind + ":";
      argv = {exe_,
              "learner",
              "--config",
              cfg_path,
              "--run-dir",
              run,
              "--rollout-bind",
              b + std::to_string(f_.rollout_port),
              "--weights-bind",
              b + std::to_string(f_.weights_port),
              "--metrics-bind",
              f_.bind,
              "--metrics-port",
              std::to_string(f_.metrics_port)};
    } else {
      argv = {exe_,        "train", "--config", cfg_path,
              "--run-dir", run,     "--actors", std::to_string(s.actors)};
      argv.insert(argv.end(), {"--rollout-port", std::to_string(PickFreePort()), "--weights-port",
                               std::to_string(PickFreePort()), "--metrics-port",
                               std::to_string(PickFreePort())});
    }
    if (resume) argv.push_back("--resume");
    {
      std::lock_guard<std::mutex> g(mu_);
      live->phase = resume ? "training (resumed from its newest checkpoint)" : "training";
    }
    // On a cluster, local actors (if any) join the learner as remote ones do: without a config.
    std::vector<pid_t> local;
    if (f_.cluster) {
      for (int i = 0; i < s.actors; ++i) {
        local.push_back(Spawn({exe_, "actor", "--learner-host", "127.0.0.1", "--rollout-port",
                               std::to_string(f_.rollout_port), "--weights-port",
                               std::to_string(f_.weights_port), "--actor-id", std::to_string(i)},
                              sd + "/actor-" + std::to_string(i) + ".log"));
      }
    }
    const bool ran = RunChild(argv, log, "", live, run, &status);
    for (pid_t p : local) Stop(p, 5.0);
    if (!ran) {
      live->code = 130;
      return;
    }
    const bool failed = !WIFEXITED(status) || WEXITSTATUS(status) != 0;
    if (!failed || f_.cluster || attempt >= 3 ||
        LastLines(log, 15).find("Address already in use") == std::string::npos) {
      break;
    }
  }
  rec->samples = RunSamples(run);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    throw std::runtime_error("perch train " + DescribeStatus(status) + "; " + log + ":\n" +
                             LastLines(log, 15));
  }
  // A run that ended short of its stop rule was stopped from outside (a Ctrl-C reaches the
  // whole process group): it resumes next time.
  std::string reason;
  try {
    reason = LoadJsonFile(run + "/end.json").value("stop_reason", "");
  } catch (const ConfigError&) {
  }
  if (reason != "max_samples" && reason != "target_success") {
    if (f_.stop && f_.stop->load()) {
      live->code = 130;
      return;
    }
    throw std::runtime_error("perch train ended without reaching its stop rule (stop reason \"" +
                             reason + "\"); " + log + ":\n" + LastLines(log, 15));
  }
  // The delivered checkpoint: the best of the newest K (and the milestones) on the selection
  // seed, or the newest.
  const std::vector<std::string> ck = Checkpoints(run);
  if (ck.empty()) throw std::runtime_error(run + ": the run left no checkpoint");
  const std::vector<std::string> cand = SelectionCandidates(ck, s.select);
  std::string chosen = ck.back();
  // select.include_init: the policy the run started from competes too, so a fine-tune that does
  // not beat its input on the selection seed delivers the input.
  std::string init;
  if (s.select.include_init) {
    const Json c = LoadJsonFile(cfg_path);
    if (c.contains("cluster") && c["cluster"].is_object()) {
      init = c["cluster"].value("init_from", "");
    }
    if (init.empty()) {
      throw ConfigError(s.name + ": select.include_init needs cluster.init_from in its config");
    }
  }
  Json figures{{"stop_reason", reason}};
  if (s.select.last_k > 0 && !SelectCheckpoint(s, cand, init, live, &chosen, &figures)) {
    live->code = 130;
    return;
  }
  figures["chosen"] =
      !init.empty() && chosen == init ? "init" : fs::path(chosen).filename().string();
  if (rec->figures.contains("extended_from_samples")) {
    figures["extended_from_samples"] = rec->figures["extended_from_samples"];
  }
  WriteFileAtomic(sd + "/" + StageOutputs(s).at("policy"), ReadFileBytes(chosen));
  rec->figures = figures;
}

void Runner::Other(const RecipeStage& s, Live* live, StageRecord* rec) {
  const std::string sd = StageDir(s.name);
  const std::string log = sd + "/stage.log";
  const auto outs = StageOutputs(s);
  // A half-done attempt's outputs are not results (the commands refuse to overwrite).
  std::error_code ec;
  for (const auto& [k, v] : outs) fs::remove(sd + "/" + v, ec);
  const std::string cmd = StageCommand(s);
  std::vector<std::string> argv = {exe_};
  // "eval" can be "eval" or a family ("motion track"): split on spaces.
  std::istringstream words(cmd);
  for (std::string w; words >> w;) argv.push_back(w);
  if (!s.config.empty()) {
    const std::string cfg_path = sd + "/config.json";
    SaveJsonFileAtomic(cfg_path, ComposeConfig(s, true));
    argv.push_back("--config");
    argv.push_back(cfg_path);
  }
  for (const std::string& a : s.args) argv.push_back(Resolve(s, a));
  for (const auto& [flag, n] : s.counts) {
    argv.push_back(flag);
    argv.push_back(std::to_string(n));
  }
  if (s.kind == "eval" && s.shards > 1) {
    RunShards(s, argv, live, rec);
    return;
  }
  std::string stdout_path;
  const auto own_out = [&](const char* flag, const std::string& name) {
    // The kind's output flag, unless the stage's args already name it.
    if (std::find(s.args.begin(), s.args.end(), flag) == s.args.end()) {
      argv.push_back(flag);
      argv.push_back(sd + "/" + outs.at(name));
    }
  };
  if (s.kind == "sample") own_out("--out", "bank");
  if (s.kind == "mirror" || s.kind == "clone") own_out("--out", "policy");
  if (s.kind == "eval" || s.kind == "clone" || s.kind == "sample") {
    argv.push_back("--json");
    stdout_path = sd + "/result.json.tmp";
  }
  {
    std::lock_guard<std::mutex> g(mu_);
    live->phase = "perch " + cmd;
  }
  int status = 0;
  if (!RunChild(argv, log, stdout_path, live, "", &status)) {
    live->code = 130;
    return;
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    if (f_.stop && f_.stop->load()) {
      live->code = 130;
      return;
    }
    throw std::runtime_error("perch " + cmd + " " + DescribeStatus(status) + "; " + log + ":\n" +
                             LastLines(log, 15));
  }
  if (!stdout_path.empty()) {
    // The --json result: the last line that is a JSON object.
    std::istringstream in(ReadFileBytes(stdout_path));
    Json result;
    for (std::string l; std::getline(in, l);) {
      if (!l.empty() && l[0] == '{') {
        const Json j = Json::parse(l, nullptr, false);
        if (j.is_object()) result = j;
      }
    }
    if (!result.is_object()) throw std::runtime_error("perch " + cmd + " printed no JSON result");
    if (s.kind == "eval") {
      WriteFileAtomic(sd + "/" + outs.at("result"), result.dump(2) + "\n");
    }
    rec->figures = FiguresOf(result, s.figures);
    fs::remove(stdout_path, ec);
  }
}

void Runner::RunShards(const RecipeStage& s, const std::vector<std::string>& argv, Live* live,
                       StageRecord* rec) {
  const std::string sd = StageDir(s.name);
  const std::string log = sd + "/stage.log";
  const std::string shard_dir = sd + "/shards";
  std::error_code ec;
  fs::create_directories(shard_dir, ec);
  // The plan: the stage's perch eval without --trials, each shard with its trials and records.
  std::vector<std::string> base;
  int64_t trials = 0;
  for (size_t i = 1; i < argv.size(); ++i) {
    if (argv[i] == "--trials" && i + 1 < argv.size()) {
      trials = std::stoll(argv[++i]);
      continue;
    }
    base.push_back(argv[i]);
  }
  Json shards = Json::array();
  std::vector<std::string> records;
  for (const TrialShard& t : TrialShards(trials, s.shards)) {
    const std::string stem = shard_dir + "/shard-" + std::to_string(t.index);
    std::vector<std::string> a = base;
    a.insert(a.end(), {"--first-trial", std::to_string(t.first), "--trials",
                       std::to_string(t.count), "--records", stem + ".jsonl", "--json"});
    shards.push_back(Json{{"index", t.index}, {"args", a}, {"result", stem + ".json"}});
    records.push_back(stem + ".jsonl");
  }
  WriteFileAtomic(shard_dir + "/plan.json",
                  Json{{"stage", s.name}, {"log", log}, {"shards", shards}}.dump(2) + "\n");
  // Take shards here (unless --local-shards 0) while workers take others; wait for the rest.
  for (;;) {
    if (f_.stop && f_.stop->load()) {
      live->code = 130;
      return;
    }
    int done = 0;
    const Json* mine = nullptr;
    for (const Json& sh : shards) {
      if (fs::exists(sh["result"].get<std::string>())) {
        ++done;
      } else if (mine == nullptr && f_.local_shards > 0 && TryClaim(ClaimOf(sh), kClaimStaleS)) {
        mine = &sh;
      }
    }
    {
      std::lock_guard<std::mutex> g(mu_);
      live->phase = "shards: " + std::to_string(done) + " of " + std::to_string(shards.size()) +
                    " done" + (mine ? ", running shard " + (*mine)["index"].dump() : "");
    }
    if (done == static_cast<int>(shards.size())) break;
    if (mine == nullptr) {
      std::this_thread::sleep_for(std::chrono::seconds(1));
      continue;
    }
    int status = 0;
    if (!RunClaimedShard(exe_, *mine, log, ClaimOf(*mine), f_.stop, &status)) {
      if (f_.stop && f_.stop->load()) {
        live->code = 130;
        return;
      }
      std::remove(ClaimOf(*mine).c_str());
      throw std::runtime_error("perch eval (shard " + (*mine)["index"].dump() + ") " +
                               DescribeStatus(status) + "; " + log + ":\n" + LastLines(log, 15));
    }
  }
  // The merge: the JSON one evaluation of all the trials gives.
  std::vector<std::string> merge = {exe_, "eval-merge"};
  merge.insert(merge.end(), records.begin(), records.end());
  merge.push_back("--json");
  const std::string out = sd + "/result.json.tmp";
  int status = 0;
  if (!RunChild(merge, log, out, live, "", &status)) {
    live->code = 130;
    return;
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    throw std::runtime_error("perch eval-merge " + DescribeStatus(status) + "; " + log + ":\n" +
                             LastLines(log, 15));
  }
  Json result;
  std::istringstream in(ReadFileBytes(out));
  for (std::string l; std::getline(in, l);) {
    if (!l.empty() && l[0] == '{') {
      const Json j = Json::parse(l, nullptr, false);
      if (j.is_object()) result = j;
    }
  }
  if (!result.is_object()) throw std::runtime_error("perch eval-merge printed no JSON result");
  result["shards"] = static_cast<int>(shards.size());
  WriteFileAtomic(sd + "/" + StageOutputs(s).at("result"), result.dump(2) + "\n");
  rec->figures = FiguresOf(result, s.figures);
  fs::remove(out, ec);
}

void Runner::RunStage(const RecipeStage& st, Live* live) {
  const RecipeStage s = ScaledStage(st, f_.options);
  StageRecord rec;
  {
    std::lock_guard<std::mutex> g(mu_);
    rec = state_.stages[s.name];
  }
  const double t0 = Now();
  try {
    std::error_code ec;
    fs::create_directories(StageDir(s.name), ec);
    if (ec) throw std::runtime_error(StageDir(s.name) + ": cannot create: " + ec.message());
    if (s.kind == "train") {
      Train(s, live, &rec);
    } else {
      Other(s, live, &rec);
    }
    if (live->code == 0) {
      for (const auto& [name, file] : StageOutputs(s)) {
        const std::string p = StageDir(s.name) + "/" + file;
        if (!fs::exists(p)) {
          if (std::find(s.optional_outputs.begin(), s.optional_outputs.end(), name) !=
              s.optional_outputs.end()) {
            continue;
          }
          throw std::runtime_error("the stage left no output " + name + " (" + p + ")");
        }
        rec.outputs[name] = s.name + "/" + file;
        rec.output_sha256[name] = FileSha256(p);
      }
    }
  } catch (const std::exception& e) {
    live->code = 1;
    rec.error = e.what();
  }
  std::lock_guard<std::mutex> g(mu_);
  StageRecord& r = state_.stages[s.name];
  const double spent = Now() - t0;
  r.wall_s += spent;
  r.attempt_started_unix = 0.0;
  if (s.kind == "train") r.samples = std::max(rec.samples, RunSamples(StageDir(s.name) + "/run"));
  if (live->code == 0) {
    r.state = "done";
    r.outputs = rec.outputs;
    r.output_sha256 = rec.output_sha256;
    r.figures = rec.figures;
    r.error.clear();
    r.finished_at = UtcStamp();
  } else if (live->code == 1) {
    r.state = "failed";
    r.error = rec.error;
  } else {
    r.state = "running";  // interrupted: resumes
  }
  live->finished = true;
}

void Runner::Progress() {
  std::lock_guard<std::mutex> g(mu_);
  const double now = Now();
  double eta_total = 0.0;
  int done = 0;
  for (int i = from_; i <= until_; ++i) {
    const RecipeStage s = ScaledStage(r_.stages[i], f_.options);
    auto rec = state_.stages.find(s.name);
    if (rec != state_.stages.end() && rec->second.state == "done") {
      ++done;
      continue;
    }
    auto lv = live_.find(s.name);
    if (lv != live_.end() && !lv->second.finished) {
      const Live& l = lv->second;
      const double el = now - l.t0;
      std::string line = "[recipe] " + s.name + " (" + s.kind + "): " + l.phase;
      double eta = std::max(0.0, s.est_wall_s - el);
      if (s.kind == "train" && s.max_samples > 0) {
        const double since = now - l.ts0;
        const double rate = l.samples0 >= 0 && since > 5 ? (l.samples - l.samples0) / since : 0.0;
        line += ", " + Count(static_cast<double>(l.samples)) + " / " +
                Count(static_cast<double>(s.max_samples)) + " samples (" +
                std::to_string(std::min<int64_t>(100, 100 * l.samples / s.max_samples)) + "%)";
        if (rate > 0) {
          line += ", " + Count(rate) + "/s";
          eta = std::max(0.0, (s.max_samples - l.samples) / rate);
        }
      }
      line += ", " + Duration(el) + " in, stage ETA " + Duration(eta);
      std::cerr << line << "\n";
      eta_total = std::max(eta_total, eta);  // running stages overlap
    } else {
      eta_total += s.est_wall_s;
    }
  }
  const int asked = until_ - from_ + 1;
  std::cerr << "[recipe] " << done << " of " << asked << " stages"
            << (asked == static_cast<int>(r_.stages.size()) ? "" : " asked for") << " done; ETA "
            << Duration(eta_total) << "\n";
}

void Runner::MoveAside(const std::vector<std::string>& names) {
  if (names.empty()) return;  // no empty superseded/<time>/ folders
  std::error_code ec;
  const std::string old = dir_ + "/superseded/" + UtcStamp();
  fs::create_directories(old, ec);
  for (const std::string& n : names) {
    std::cerr << "[recipe] " << n << ": redone (its files move to " << old << "/" << n << ")\n";
    if (fs::exists(StageDir(n))) fs::rename(StageDir(n), old + "/" + n, ec);
    if (ec) throw ConfigError(StageDir(n) + ": cannot move aside: " + ec.message());
    state_.stages.erase(n);
  }
}

// --extend S: a training stage trained on past its recorded end when only its budget (and the
// learning rate beyond what it trained) changed, so its first samples stay what they were; or,
// its budget unchanged, its delivered checkpoint chosen again when only its select changed.
void Runner::Extend(const std::string& name) {
  const int i = r_.Index(name);
  if (i < 0) throw ConfigError("--extend: no stage \"" + name + "\" in " + r_.path);
  const RecipeStage& st = r_.stages[i];
  if (st.kind != "train") {
    throw ConfigError("--extend " + name + ": a " + st.kind +
                      " stage; only a training stage continues (--force-from " + name +
                      " runs it again)");
  }
  auto rec = state_.stages.find(name);
  const std::string run = StageDir(name) + "/run";
  if (rec == state_.stages.end() || rec->second.state == "pending" || Checkpoints(run).empty()) {
    throw ConfigError("--extend " + name + ": it has not trained yet (no checkpoint in " + run +
                      "); a plain run starts it");
  }
  const std::string fp = Fingerprint(st);
  if (fp == rec->second.fingerprint) {
    std::cerr << "[recipe] " << name << ": unchanged; --extend has nothing to do\n";
    return;
  }
  const int64_t trained = RunSamples(run);
  const Json prev = LoadJsonFile(StageDir(name) + "/config.json");
  const Json next = ComposeConfig(ScaledStage(st, f_.options), true);
  const std::string why = ExtensionMismatch(prev, next, trained);
  if (!why.empty()) {
    throw ConfigError("--extend " + name + ": the new definition does not continue the run: " +
                      why + " (--force-from " + name + " trains it again from the start)");
  }
  std::vector<std::string> readers;
  for (const std::string& n : StagesReading(r_, name)) {
    auto it = state_.stages.find(n);
    if (it != state_.stages.end() && it->second.state != "pending") readers.push_back(n);
  }
  if (next["cluster"]["max_samples"].get<int64_t>() <= trained) {
    // The same budget: only the choice of its checkpoint changed (select).
    std::cerr << "[recipe] " << name << ": its run is complete (" << trained
              << " samples); its delivered checkpoint is chosen again; " << readers.size()
              << " stage(s) that read it are redone\n";
  } else {
    std::cerr << "[recipe] " << name << ": extended: continues from its newest checkpoint ("
              << trained << " samples) to " << next["cluster"]["max_samples"].dump() << " samples; "
              << readers.size() << " stage(s) that read it are redone\n";
  }
  if (f_.check) {
    for (const std::string& n : readers) state_.stages.erase(n);  // in memory only: the plan
  } else {
    MoveAside(readers);
  }
  StageRecord& r = state_.stages[name];
  r.state = "running";  // interrupted: the next loop resumes it from its newest checkpoint
  r.fingerprint.clear();
  r.outputs.clear();
  r.output_sha256.clear();
  r.figures = Json{{"extended_from_samples", trained}};
  r.finished_at.clear();
  if (f_.check) return;
  std::ofstream(StageDir(name) + "/stage.log", std::ios::app)
      << "\n== " << UtcStamp() << " perch recipe: --extend from " << trained << " samples\n";
  Save();
}

void Runner::VerifyOutputs() {
  // What was recorded still holds: every done stage's outputs are there, unchanged.
  for (const RecipeStage& s : r_.stages) {
    auto it = state_.stages.find(s.name);
    if (it == state_.stages.end() || it->second.state != "done") continue;
    for (const auto& [name, rel] : it->second.outputs) {
      const std::string p = dir_ + "/" + rel;
      std::string sha;
      try {
        sha = FileSha256(p);
      } catch (const std::exception&) {
        sha = "(missing)";
      }
      if (sha != it->second.output_sha256[name]) {
        if (Forced().count(s.name)) continue;
        throw ConfigError("stage " + s.name + ": output " + name + " (" + p + ") " +
                          (sha == "(missing)" ? "is missing" : "changed since it was recorded") +
                          "; --force-from " + s.name +
                          " runs it (and the stages that read it) again");
      }
    }
  }
}

// --adopt-from E: in recipe order up to --until, each stage that E finished with the fingerprint it
// has here (its inputs' recorded SHA-256 included, so a stage follows only adopted or identical
// inputs) and that is not done here with that fingerprint is copied from E; what this directory had
// of it moves to superseded/.
void Runner::Adopt() {
  if (f_.adopt_from.empty()) return;
  const std::string from = fs::absolute(f_.adopt_from).lexically_normal().string();
  std::error_code same_ec;
  if (fs::equivalent(from, dir_, same_ec)) {
    throw ConfigError("--adopt-from: " + from + " is --dir itself");
  }
  if (!fs::exists(from + "/recipe-state.json")) {
    throw ConfigError("--adopt-from: " + from +
                      " has no recipe-state.json (not a recipe directory)");
  }
  const RecipeState other = LoadRecipeState(from);
  int adopted = 0;
  // Up to --until: the stages this run is asked for (and those before them).
  const int until = f_.until.empty() || r_.Index(f_.until) < 0
                        ? static_cast<int>(r_.stages.size()) - 1
                        : r_.Index(f_.until);
  for (int i = 0; i <= until; ++i) {
    const RecipeStage& s = r_.stages[i];
    const std::string fp = Fingerprint(s);
    if (fp.empty()) continue;  // an input not done here
    auto mine = state_.stages.find(s.name);
    if (mine != state_.stages.end() && mine->second.state == "done" &&
        mine->second.fingerprint == fp) {
      continue;
    }
    auto theirs = other.stages.find(s.name);
    if (theirs == other.stages.end() || theirs->second.state != "done" ||
        theirs->second.fingerprint != fp) {
      continue;
    }
    StageRecord rec = theirs->second;
    for (const auto& [name, rel] : rec.outputs) {
      const std::string p = from + "/" + rel;
      if (!fs::exists(p) || FileSha256(p) != rec.output_sha256[name]) {
        throw ConfigError("--adopt-from: stage " + s.name + ": output " + name + " (" + p +
                          ") is missing or changed since " + from + " recorded it");
      }
    }
    if (f_.check) {
      std::cerr << "[recipe] " << s.name << ": would be adopted from " << from << "\n";
      continue;
    }
    if (mine != state_.stages.end() && mine->second.state != "pending") MoveAside({s.name});
    std::error_code ec;
    fs::remove_all(StageDir(s.name), ec);
    fs::copy(from + "/" + s.name, StageDir(s.name), fs::copy_options::recursive, ec);
    if (ec) {
      throw ConfigError("--adopt-from: cannot copy " + from + "/" + s.name + ": " + ec.message());
    }
    rec.figures["adopted_from"] = from;
    state_.stages[s.name] = rec;
    Save();
    ++adopted;
    std::cerr << "[recipe] " << s.name << ": adopted from " << from
              << " (the same definition and inputs; not run here)\n";
  }
  std::cerr << "[recipe] --adopt-from " << from << ": " << adopted << " stage(s) adopted\n";
}

// --force-from S: S and the stages that read it, transitively; the stages after S that read
// nothing of it keep what they made.
std::set<std::string> Runner::Forced() const {
  std::set<std::string> out;
  if (f_.force_from.empty() || r_.Index(f_.force_from) < 0) return out;
  out.insert(f_.force_from);
  for (const std::string& n : StagesReading(r_, f_.force_from)) out.insert(n);
  return out;
}

// Stages whose config, inputs or scale changed, said before anything runs.
std::vector<std::string> Runner::AcceptChanges() {
  for (const RecipeStage& s : r_.stages) fingerprints_[s.name] = Fingerprint(s);
  std::vector<std::string> changed;
  for (const std::string& n : InvalidatedStages(r_, state_, fingerprints_)) {
    const StageRecord& rec = state_.stages[n];
    // An unfinished stage that keeps nothing between attempts (all but training) simply starts
    // again under its new definition: that is how a fix to a failed stage's flags takes effect.
    if (rec.state != "done" && r_.stages[r_.Index(n)].kind != "train") {
      std::cerr << "[recipe] " << n << ": changed since its unfinished attempt; it starts again\n";
      state_.stages[n].fingerprint.clear();
      continue;
    }
    changed.push_back(n);
  }
  const std::set<std::string> forced = Forced();
  std::vector<std::string> redo;
  for (const std::string& n : changed) {
    if (!forced.count(n)) {
      std::string list;
      for (const std::string& m : changed) list += (list.empty() ? "" : ", ") + m;
      throw ConfigError("stage " + n +
                        " changed since it ran (config, inputs or --scale); it and "
                        "the stages after it that read it must run again: " +
                        list + ". Pass --force-from " + n + " to accept (their files move to " +
                        dir_ + "/superseded/)" +
                        (r_.stages[r_.Index(n)].kind == "train"
                             ? ", or --extend " + n + " if only its budget grew"
                             : ""));
    }
  }
  for (const RecipeStage& s : r_.stages) {  // in the file's order
    if (!forced.count(s.name)) continue;
    auto it = state_.stages.find(s.name);
    if (it != state_.stages.end() && it->second.state != "pending") redo.push_back(it->first);
  }
  if (!redo.empty() && !f_.check) {
    MoveAside(redo);
    for (const RecipeStage& s : r_.stages) fingerprints_[s.name] = Fingerprint(s);
  }
  return redo;
}

void Runner::SetRange() {
  const int from = f_.from.empty() ? 0 : r_.Index(f_.from);
  const int until = f_.until.empty() ? static_cast<int>(r_.stages.size()) - 1 : r_.Index(f_.until);
  if (from < 0) throw ConfigError("--from: no stage \"" + f_.from + "\" in " + r_.path);
  if (until < 0) throw ConfigError("--until: no stage \"" + f_.until + "\" in " + r_.path);
  if (until < from) throw ConfigError("--until " + f_.until + " comes before --from " + f_.from);
  from_ = from;
  until_ = until;
  for (int i = from; i <= until; ++i) {
    for (const std::string& d : r_.stages[i].deps) {
      const int di = r_.Index(d);
      auto it = state_.stages.find(d);
      if (di < from && (it == state_.stages.end() || it->second.state != "done")) {
        throw ConfigError("stage " + r_.stages[i].name + " reads " + d +
                          ", which is not done and is before --from " + f_.from);
      }
    }
  }
}

// Ready stages (every input done) start, up to --parallel at once. True when every stage in the
// range is done.
bool Runner::StartReadyStages(std::map<std::string, std::thread>* threads, int code) {
  bool all_done = true;
  {
    std::lock_guard<std::mutex> g(mu_);
    for (int i = from_; i <= until_ && code == 0; ++i) {
      const RecipeStage& s = r_.stages[i];
      StageRecord& rec = state_.stages[s.name];
      if (rec.state == "done") continue;
      all_done = false;
      if (threads->count(s.name)) continue;
      bool ready = true;
      for (const std::string& d : s.deps) ready = ready && state_.stages[d].state == "done";
      if (!ready || static_cast<int>(threads->size()) >= f_.parallel) continue;
      if (f_.stop && f_.stop->load()) continue;
      rec.state = "running";
      rec.attempt_started_unix = UnixNow();
      rec.attempts += 1;
      rec.fingerprint = fingerprints_[s.name].empty() ? Fingerprint(s) : fingerprints_[s.name];
      if (rec.started_at.empty()) rec.started_at = UtcStamp();
      Live& l = live_[s.name];
      l.samples = 0;
      l.samples0 = -1;
      l.finished = false;
      l.code = 0;
      l.t0 = Now();
      l.phase = "starting";
      SaveRecipeState(dir_, state_);
      std::cerr << "[recipe] stage " << s.name << " (" << s.kind << ", " << (i + 1) << " of "
                << r_.stages.size() << ")" << (rec.attempts > 1 ? ": continuing" : ": starting")
                << (s.doc.empty() ? "" : " — " + s.doc) << "\n";
      (*threads)[s.name] = std::thread([this, &s, &l] { RunStage(s, &l); });
    }
  }
  return all_done;
}

int Runner::ReapFinished(std::map<std::string, std::thread>* threads, int code) {
  for (auto it = threads->begin(); it != threads->end();) {
    bool fin;
    int c;
    {
      std::lock_guard<std::mutex> g(mu_);
      fin = live_[it->first].finished;
      c = live_[it->first].code;
    }
    if (!fin) {
      ++it;
      continue;
    }
    it->second.join();
    std::lock_guard<std::mutex> g(mu_);
    StageRecord& rec = state_.stages[it->first];
    try {
      SaveRecipeState(dir_, state_);
    } catch (const std::exception& e) {
      std::cerr << "[recipe] cannot save " << StatePath(dir_) << ": " << e.what()
                << " (the stage's files are kept; the same command continues once fixed)\n";
      code = 1;
    }
    if (c == 0) {
      std::cerr << "[recipe] stage " << it->first << ": done in " << Duration(rec.wall_s)
                << (rec.samples ? ", " + Count(static_cast<double>(rec.samples)) + " samples" : "")
                << "; figures " << rec.figures.dump() << "\n";
    } else if (c == 1) {
      std::cerr << "[recipe] stage " << it->first << " FAILED: " << rec.error
                << "\n[recipe] fix the cause and run the same command again: it continues at "
                << it->first << "\n";
      code = 1;
      if (f_.stop) f_.stop->store(true);  // others stop at a checkpoint, resumable
    } else if (code == 0) {
      code = 130;
    }
    it = threads->erase(it);
  }
  return code;
}

int Runner::RunLoop() {
  std::map<std::string, std::thread> threads;
  int code = 0;
  double last_progress = Now();
  for (;;) {
    const bool all_done = StartReadyStages(&threads, code);
    if (all_done && threads.empty()) break;
    if (threads.empty() && code != 0) break;
    if (threads.empty() && f_.stop && f_.stop->load()) {
      code = 130;
      break;
    }
    if (threads.empty() && !all_done) {
      // Nothing runs and nothing can start: a dependency outside the range is not done.
      throw ConfigError("no stage can start: an input of a stage in range is not done");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    code = ReapFinished(&threads, code);
    if (Now() - last_progress >= f_.progress_s && !threads.empty()) {
      Progress();
      last_progress = Now();
    }
  }
  if (code == 130) {
    std::cerr << "[recipe] stopped; the same command continues where it stopped\n";
  } else if (code == 0) {
    std::cerr << "[recipe] stages " << r_.stages[from_].name << " .. " << r_.stages[until_].name
              << " done (perch recipe status --dir " << f_.dir << ")\n";
  }
  return code;
}

int Runner::Run() {
  std::error_code ec;
  std::unique_ptr<DirLock> lock;
  if (!f_.check) {
    fs::create_directories(dir_, ec);
    if (ec) throw ConfigError(dir_ + ": cannot create: " + ec.message());
    lock = std::make_unique<DirLock>(dir_);
  }
  state_ = LoadRecipeState(dir_);
  VerifyOutputs();
  if (!f_.force_from.empty() && r_.Index(f_.force_from) < 0) {
    throw ConfigError("--force-from: no stage \"" + f_.force_from + "\" in " + r_.path);
  }
  if (!f_.extend.empty()) Extend(f_.extend);
  Adopt();
  const std::vector<std::string> redo = AcceptChanges();
  SetRange();
  // Every stage has a record (pending until it starts), so the state file lists them all.
  for (const RecipeStage& s : r_.stages) state_.stages.emplace(s.name, StageRecord{});
  if (f_.check) {
    int done = 0;
    for (const RecipeStage& s : r_.stages) done += state_.stages[s.name].state == "done";
    std::string redone;
    for (const std::string& n : redo) redone += (redone.empty() ? "" : ", ") + n;
    // What a run would do: the stages of the range that are not done (done ones are skipped).
    std::vector<std::string> todo;
    for (int i = from_; i <= until_; ++i) {
      if (state_.stages[r_.stages[i].name].state != "done") todo.push_back(r_.stages[i].name);
    }
    const std::string would = todo.empty() ? "nothing to run"
                                           : "would run " + std::to_string(todo.size()) +
                                                 " stage(s), " + todo.front() +
                                                 (todo.size() > 1 ? " .. " + todo.back() : "");
    std::cerr << "perch recipe: " << r_.path << " OK: " << r_.stages.size() << " stages, " << done
              << " done in " << dir_ << "; " << would
              << (redo.empty() ? "" : "; would redo " + redone + " (--force-from/--extend)")
              << "\n";
    return 0;
  }
  // The recipe as run, beside its state (status reads it; a copy is not a path into a checkout),
  // once it is accepted: a refused change leaves the last one.
  WriteFileAtomic(dir_ + "/recipe.json", LoadJsonFile(r_.path).dump(2) + "\n");
  Save();
  std::cerr << "[recipe] " << r_.name << " in " << dir_ << " (scale " << f_.options.scale
            << ", up to " << f_.parallel << " stage(s) at once)\n";

  return RunLoop();
}

}  // namespace

int RunRecipe(const RecipeRunFlags& f) {
  if (!(f.options.scale > 0 && f.options.scale <= 1)) {
    throw ConfigError("--scale: must be in (0, 1]");
  }
  if (f.parallel < 1 || f.parallel > 16) throw ConfigError("--parallel: must be in 1..16");
  if (f.options.actors < (f.cluster ? 0 : 1)) {
    throw ConfigError(f.cluster ? "--actors: must be >= 0"
                                : "--actors: must be >= 1 (0 with --cluster)");
  }
  if (f.cluster && f.parallel > 1) {
    throw ConfigError("--parallel: one stage at a time with --cluster (one learner address)");
  }
  if (f.dir.empty()) throw ConfigError("--dir: required");
  // recipes/... is found in the data root too (an installed binary, a pod).
  Runner r(f, LoadRecipe(ResolveProjectPath(f.recipe)));
  return r.Run();
}

Json RecipeStatus(const std::string& dir) {
  const RecipeState st = LoadRecipeState(dir);
  if (!fs::exists(StatePath(dir)))
    throw ConfigError(dir + ": no recipe-state.json (no recipe ran here)");
  Recipe r;
  try {
    r = RecipeFromJson(LoadJsonFile(dir + "/recipe.json"), dir + "/recipe.json");
  } catch (const ConfigError&) {
    // Without the recipe's copy: the stages in the state file's order.
    for (const auto& [k, v] : st.stages) {
      RecipeStage s;
      s.name = k;
      s.kind = "?";
      r.stages.push_back(s);
    }
  }
  const bool alive = DirLock::Held(dir);
  Json stages = Json::array();
  int64_t total_samples = 0;
  double total_wall = 0;
  for (const RecipeStage& s : r.stages) {
    auto it = st.stages.find(s.name);
    const StageRecord rec = it == st.stages.end() ? StageRecord{} : it->second;
    int64_t samples = rec.samples;
    if (s.kind == "train" && rec.state == "running") {
      samples = std::max(samples, RunSamples(dir + "/" + s.name + "/run"));
    }
    // A running stage's wall time: earlier attempts plus the one under way.
    double wall_s = rec.wall_s;
    if (rec.state == "running" && alive && rec.attempt_started_unix > 0) {
      wall_s += std::max(0.0, UnixNow() - rec.attempt_started_unix);
    }
    Json outputs = Json::object();
    for (const auto& [k, v] : rec.outputs) {
      outputs[k] =
          Json{{"path", v}, {"sha256", rec.output_sha256.count(k) ? rec.output_sha256.at(k) : ""}};
    }
    Json o{{"name", s.name},     {"kind", s.kind},        {"state", rec.state},
           {"samples", samples}, {"wall_s", wall_s},      {"attempts", rec.attempts},
           {"outputs", outputs}, {"figures", rec.figures}};
    if (rec.figures.contains("chosen")) o["chosen"] = rec.figures["chosen"];
    if (!rec.error.empty()) o["error"] = rec.error;
    if (rec.state == "running" && !alive) o["interrupted"] = true;
    if (!rec.finished_at.empty()) o["finished_at"] = rec.finished_at;
    stages.push_back(o);
    total_samples += samples;
    total_wall += wall_s;
  }
  return Json{{"name", st.recipe_name},         {"dir", dir},
              {"recipe", st.recipe_path},       {"scale", st.scale},
              {"runner_alive", alive},          {"stages", stages},
              {"total_samples", total_samples}, {"total_wall_s", total_wall}};
}

std::string RecipeStatusText(const Json& s) {
  std::ostringstream o;
  o << "recipe " << s.value("name", "") << " in " << s.value("dir", "") << " (scale "
    << s.value("scale", 1.0) << (s.value("runner_alive", false) ? ", running now" : "") << ")\n";
  char buf[256];
  std::snprintf(buf, sizeof(buf), "%-26s %-7s %-9s %10s %9s  %s\n", "stage", "kind", "state",
                "samples", "wall", "figures");
  o << buf;
  for (const Json& st : s["stages"]) {
    std::string fig;
    const Json& f = st["figures"];
    for (const char* k : {"chosen", "success_rate", "no_fall_rate", "fall_rate",
                          "seated_position_error_cm_mean", "min_dist_mean_m"}) {
      if (f.contains(k)) fig += std::string(fig.empty() ? "" : ", ") + k + " " + f[k].dump();
    }
    std::string state = st.value("state", "");
    if (st.value("interrupted", false)) state += "*";
    std::snprintf(buf, sizeof(buf), "%-26s %-7s %-9s %10s %9s  %s\n", st.value("name", "").c_str(),
                  st.value("kind", "").c_str(), state.c_str(),
                  Count(st.value("samples", 0.0)).c_str(),
                  Duration(st.value("wall_s", 0.0)).c_str(), fig.c_str());
    o << buf;
    if (st.contains("error"))
      o << "    error: " << st["error"].get<std::string>().substr(0, 400) << "\n";
  }
  o << "total: " << Count(s.value("total_samples", 0.0)) << " samples, "
    << Duration(s.value("total_wall_s", 0.0)) << " of stage wall time";
  o << "   (* interrupted: the same `perch recipe run` continues it)\n";
  return o.str();
}

int RunRecipeWorker(const RecipeWorkerFlags& f) {
  const std::string exe = f.exe.empty() ? SelfExe() : f.exe;
  if (!fs::is_directory(f.dir)) throw ConfigError("--dir " + f.dir + ": no such directory");
  std::cerr << "[recipe worker] " << ClaimOwner() << " takes evaluation shards in " << f.dir
            << "\n";
  auto idle_since = std::chrono::steady_clock::now();
  int ran = 0;
  for (;;) {
    if (f.stop && f.stop->load()) return 130;
    bool worked = false;
    std::error_code ec;
    for (fs::directory_iterator it(f.dir, ec), e; !ec && it != e; it.increment(ec)) {
      const std::string plan_path = it->path().string() + "/shards/plan.json";
      if (!fs::exists(plan_path)) continue;
      Json plan;
      try {
        plan = LoadJsonFile(plan_path);
      } catch (const ConfigError&) {
        continue;  // being written
      }
      for (const Json& sh : plan["shards"]) {
        if (fs::exists(sh["result"].get<std::string>())) continue;
        if (!TryClaim(ClaimOf(sh), kClaimStaleS)) continue;
        std::cerr << "[recipe worker] " << plan["stage"].get<std::string>() << ": shard "
                  << sh["index"].get<int>() << "\n";
        int status = 0;
        const bool ok =
            RunClaimedShard(exe, sh, plan["log"].get<std::string>(), ClaimOf(sh), f.stop, &status);
        if (!ok) {
          std::remove(ClaimOf(sh).c_str());
          if (f.stop && f.stop->load()) return 130;
          std::cerr << "[recipe worker] shard " << sh["index"].get<int>() << " "
                    << DescribeStatus(status) << " (" << plan["log"].get<std::string>() << ")\n";
        } else {
          ++ran;
        }
        worked = true;
      }
    }
    const auto now = std::chrono::steady_clock::now();
    if (worked) idle_since = now;
    if (f.exit_when_idle_s > 0 &&
        std::chrono::duration<double>(now - idle_since).count() >= f.exit_when_idle_s) {
      std::cerr << "[recipe worker] idle for " << f.exit_when_idle_s << " s; ran " << ran
                << " shard(s)\n";
      return 0;
    }
    if (!worked) std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
}

}  // namespace perch
