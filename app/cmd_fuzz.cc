// perch fuzz (issue 17): bounded random-mutation fuzzing of the readers that take outside input —
// the wire decoder (actor and learner messages, then the rollout a segment carries), the
// checkpoint reader, the BVH reader and the config loader. Each case mutates a valid seed input
// (bit flips, byte overwrites with edge values, truncation, duplication, insertion, splicing) and
// feeds it to the reader. A reader must accept the input or refuse it with its documented error;
// any other exception is a finding, and a crash ends the process (the test sees the exit status).
// scripts/test.sh runs each target for a few seconds; `perch fuzz --seconds 3600` for longer.
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "app/commands.h"
#include "common/config_file.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "common/proto/model.pb.h"
#include "common/proto/wire.pb.h"
#include "common/rng.h"
#include "experiment/experiment.h"
#include "learner/ppo.h"
#include "learner/service/checkpoint.h"
#include "motion/bvh.h"
#include "policy/rollout.h"
#include "protocol/wire.h"

namespace perch {
namespace {

double NowS() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct FuzzFlags {
  std::vector<std::string> targets = {"wire", "checkpoint", "bvh", "config"};
  double seconds = 5.0;  // per target
  uint64_t cases = 0;    // per target: stop after this many mutated inputs (0: only --seconds)
  uint64_t seed = 1;
  bool json = false;
};

// One mutation of `in` (never empty output for a non-empty input unless truncated to 0).
std::string Mutate(const std::string& in, const std::vector<std::string>& corpus, Rng& rng) {
  std::string s = in;
  const int rounds = 1 + static_cast<int>(rng.NextU64() % 4);
  for (int k = 0; k < rounds; ++k) {
    const size_t n = s.size();
    const uint64_t op = rng.NextU64() % 7;
    const size_t at = n ? rng.NextU64() % n : 0;
    switch (op) {
      case 0:  // flip a bit
        if (n) s[at] = static_cast<char>(s[at] ^ (1 << (rng.NextU64() % 8)));
        break;
      case 1: {  // an edge value
        static const unsigned char kEdge[] = {0x00, 0xff, 0x7f, 0x80, 0x01,
                                              '9',  '-',  '"',  '{',  '['};
        if (n) s[at] = static_cast<char>(kEdge[rng.NextU64() % sizeof(kEdge)]);
        break;
      }
      case 2:  // truncate
        s.resize(at);
        break;
      case 3: {  // duplicate a chunk
        const size_t len = n ? 1 + rng.NextU64() % std::min<size_t>(n - at, 64) : 0;
        s.insert(at, s.substr(at, len));
        break;
      }
      case 4: {  // random bytes
        const size_t len = 1 + rng.NextU64() % 16;
        std::string r(len, '\0');
        for (char& c : r) c = static_cast<char>(rng.NextU64());
        s.insert(at, r);
        break;
      }
      case 5:  // erase a chunk
        if (n) s.erase(at, 1 + rng.NextU64() % std::min<size_t>(n - at, 64));
        break;
      default: {  // splice with another seed
        const std::string& o = corpus[rng.NextU64() % corpus.size()];
        if (!o.empty()) s = s.substr(0, at) + o.substr(rng.NextU64() % o.size());
        break;
      }
    }
  }
  return s;
}

proto::ActorMessage SegmentMessage(int obs_dim, int act, int steps) {
  Rollout r(obs_dim, act);
  std::vector<float> o(obs_dim, 0.5f), a(act, -0.25f);
  for (int t = 0; t < steps; ++t) {
    r.Add(o.data(), a.data(), -1.0f, 0.1f * t, 1.0f, t == steps - 1, false, 0.0f);
  }
  r.obs_stats_delta = RunningMeanStd(obs_dim, 0.0);
  r.obs_stats_delta.Update(o.data());
  proto::ActorMessage m;
  m.set_wire_version(proto::WIRE_VERSION_CURRENT);
  proto::Segment* seg = m.mutable_segment();
  seg->set_actor_instance(7);
  r.ToProto(seg->mutable_rollout());
  proto::EpisodeStats* e = seg->add_episodes();
  e->set_length(steps);
  e->set_episode_return(steps);
  return m;
}

struct Target {
  std::vector<std::string> seeds;
  // Feeds one input; returns "" when accepted or refused as documented, else the finding.
  std::function<std::string(const std::string&)> run;
};

Target WireTarget() {
  Target t;
  const int obs = 6, act = 3;
  t.seeds.push_back(SegmentMessage(obs, act, 5).SerializeAsString());
  proto::ActorMessage hb;
  hb.set_wire_version(proto::WIRE_VERSION_CURRENT);
  hb.mutable_heartbeat()->set_actor_instance(3);
  t.seeds.push_back(hb.SerializeAsString());
  proto::ActorMessage hello;
  hello.set_wire_version(proto::WIRE_VERSION_CURRENT);
  hello.mutable_hello()->set_hostname("pod-1");
  hello.mutable_hello()->set_num_envs(4);
  t.seeds.push_back(hello.SerializeAsString());
  PpoLearner learner(PolicyConfig::Subtask(act), PpoConfig{}, 1);
  proto::LearnerMessage lm;
  lm.set_wire_version(proto::WIRE_VERSION_CURRENT);
  learner.ExportWeights(lm.mutable_weights()->add_policies()->mutable_model());
  t.seeds.push_back(lm.SerializeAsString());
  t.run = [obs, act](const std::string& bytes) -> std::string {
    WireLimits limits;
    limits.obs_dim = obs;
    limits.act_dim = act;
    std::string why;
    proto::ActorMessage m;
    if (ParseActorMessage(bytes.data(), bytes.size(), limits, &m, &why) == WireReject::kOk &&
        m.has_segment()) {
      try {
        Rollout::FromProto(m.segment().rollout(), "segment");  // what the learner does next
      } catch (const ConfigError&) {
      }
    }
    proto::LearnerMessage lm;
    ParseLearnerMessage(bytes.data(), bytes.size(), 1 << 20, &lm, &why);
    return "";
  };
  return t;
}

Target CheckpointTarget(const std::string& dir) {
  Target t;
  PpoLearner learner(PolicyConfig::Subtask(3), PpoConfig{}, 1);
  proto::Checkpoint c;
  c.set_wire_version(proto::WIRE_VERSION_CURRENT);
  c.mutable_counters()->set_updates(12);
  learner.ExportState(c.mutable_trainer());
  c.set_resolved_config_json("{\"seed\": 1}");
  t.seeds.push_back(FrameCheckpoint(c));
  const std::string path = dir + "/fuzz.ckpt";
  t.run = [path](const std::string& bytes) -> std::string {
    {
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out << bytes;
    }
    try {
      ReadCheckpointFile(path);
    } catch (const CheckpointError&) {
    }
    return "";
  };
  return t;
}

Target BvhTarget() {
  Target t;
  t.seeds.push_back(
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition "
      "Zrotation Xrotation Yrotation\n  JOINT Spine\n  {\n    OFFSET 0 10 0\n    CHANNELS 3 "
      "Zrotation Xrotation Yrotation\n    End Site\n    {\n      OFFSET 0 5 0\n    }\n  }\n}\n"
      "MOTION\nFrames: 3\nFrame Time: 0.0083333\n0 90 0 0 0 0 1 2 3\n0 91 1 0 5 0 2 3 4\n"
      "0 92 2 0 10 0 3 4 5\n");
  t.run = [](const std::string& text) -> std::string {
    try {
      ParseBvh(text, "fuzz.bvh");
    } catch (const ConfigError&) {
    }
    return "";
  };
  return t;
}

Target ConfigTarget(const std::string& dir) {
  Target t;
  for (const char* name : {"configs/default.json", "configs/mock.json"}) {
    std::ifstream in(ResolveProjectPath(name));
    t.seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::string path = dir + "/fuzz_config.json";
  t.run = [path](const std::string& text) -> std::string {
    {
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out << text;
    }
    try {
      LoadExperimentConfig(path);
    } catch (const ConfigError&) {
    }
    return "";
  };
  return t;
}

int RunFuzz(const FuzzFlags& f) {
  if (!(f.seconds > 0)) throw ConfigError("--seconds: must be > 0");
  // Readers log refusals; thousands of them per second are noise here.
  spdlog::set_level(spdlog::level::off);
  char tmpl[] = "/tmp/perch-fuzz-XXXXXX";
  const char* d = ::mkdtemp(tmpl);
  if (d == nullptr) throw std::runtime_error("mkdtemp failed");
  const std::string dir = d;
  Json out{{"bench", "fuzz"},
           {"seconds_per_target", f.seconds},
           {"cases_per_target", f.cases},
           {"seed", f.seed}};
  Json results = Json::object();
  int findings_total = 0;
  for (const std::string& name : f.targets) {
    Target t;
    if (name == "wire") {
      t = WireTarget();
    } else if (name == "checkpoint") {
      t = CheckpointTarget(dir);
    } else if (name == "bvh") {
      t = BvhTarget();
    } else if (name == "config") {
      t = ConfigTarget(dir);
    } else {
      throw ConfigError("--target: unknown '" + name + "' (wire, checkpoint, bvh, config)");
    }
    Rng rng(f.seed * 0x9E3779B97F4A7C15ULL + std::hash<std::string>()(name));
    uint64_t cases = 0;
    std::vector<std::string> findings;
    const double t0 = NowS();
    // The seeds themselves must pass.
    for (const std::string& s : t.seeds) {
      if (std::string why = t.run(s); !why.empty()) findings.push_back("seed: " + why);
    }
    // A case count makes the run the same on any machine (tests); seconds bound it in time.
    while (NowS() - t0 < f.seconds && (f.cases == 0 || cases < f.cases)) {
      const std::string input = Mutate(t.seeds[rng.NextU64() % t.seeds.size()], t.seeds, rng);
      std::string why;
      try {
        why = t.run(input);
      } catch (const std::exception& e) {
        why = std::string("unexpected exception: ") + e.what();
      }
      ++cases;
      if (!why.empty() && findings.size() < 5) {
        findings.push_back(why);
        std::ofstream(dir + "/finding-" + name + "-" + std::to_string(findings.size()) + ".bin",
                      std::ios::binary)
            << input;
      }
    }
    findings_total += static_cast<int>(findings.size());
    results[name] = Json{{"cases", cases},
                         {"cases_per_s", cases / std::max(1e-9, NowS() - t0)},
                         {"findings", Json(findings)}};
  }
  out["targets"] = results;
  out["findings"] = findings_total;
  out["findings_dir"] = findings_total ? Json(dir) : Json(nullptr);
  if (!findings_total) std::filesystem::remove_all(dir);
  std::cout << (f.json ? out.dump() : out.dump(2)) << std::endl;
  return findings_total ? 1 : 0;
}

}  // namespace

void RegisterFuzzCommand(CLI::App& root) {
  auto f = std::make_shared<FuzzFlags>();
  CLI::App* c = root.add_subcommand(
      "fuzz", "Random-mutation fuzzing of the wire, checkpoint, BVH and config readers");
  c->add_option("--target", f->targets, "wire, checkpoint, bvh, config (default: all)")
      ->delimiter(',');
  c->add_option("--seconds", f->seconds, "per target (default 5)");
  c->add_option("--cases", f->cases,
                "per target: stop after this many mutated inputs (0: run for --seconds)");
  c->add_option("--seed", f->seed, "mutation seed");
  c->add_flag("--json", f->json, "print one JSON object");
  c->callback([f] {
    const int rc = RunFuzz(*f);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace perch
